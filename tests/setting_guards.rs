//! Guards on what a register write may make the unit believe (issue 31, item 7, found by a
//! hostile printer): a park distance or a filament per revolution that parks a tip inside the
//! merge, a threshold no reading reaches, a tension dead band inside the sensor's noise, and a
//! stall stop that came after the stall rule's bound. Each as a user meets it: the printer's
//! write, then what the filament and the motors do.

mod common;

use common::{Rig, finished, t};
use mmu_firmware::config::Version;
use mmu_firmware::guards::Rule;
use mmu_firmware::persist::Snapshot;
use mmu_firmware::unit::Lane;
use mmu_firmware::{App, Config, MotorCommand};
use mmu_model::{Fault, ModelConfig};
use mmu_protocol::{ParamCode, Request, RequestCode};

/// Where the model's slot paths join, mm from the hub sensor: a tip in front of it blocks the
/// other slots.
const MERGE_MM: f32 = -8.0;
/// Where the model's slot sensors sit, mm from the hub sensor.
const SLOT_SENSOR_MM: f32 = -95.0;

/// The register that names the rule of the last refusal.
const REFUSED_RULE: u8 = 0x8f;

/// What the printer's `W` got back.
fn answer<const N: usize>(rig: &mut Rig<N>, address: u8, value: u16) -> Option<ParamCode> {
    rig.send(Request::write(address, value)).map(|a| a.param)
}

/// Every slot's tip the unit records as parked rests behind the merge and in front of its slot
/// sensor.
fn parked_tips_rest_between_merge_and_slot_sensor<const N: usize>(rig: &Rig<N>, context: &str) {
    for slot in 0..N {
        if rig.app.lanes()[slot] != Lane::Parked {
            continue;
        }
        let tip = rig.model.tip_mm(slot).unwrap();
        assert!(
            (SLOT_SENSOR_MM..MERGE_MM).contains(&tip),
            "{context}: slot {slot} recorded parked with its tip at {tip} mm (merge at {MERGE_MM})"
        );
    }
}

/// Finding: `W41 1` (a 1 mm park) or `W42 5000` (50 mm a revolution) and the unit recorded
/// Parked with the tip 1.9 to 8.4 mm before the hub sensor, inside the merge at 8 mm, where it
/// blocks the next slot. The old register ranges took less blatant values to the same end: at
/// 10 mm or 4 mm a revolution (the drive moves 2) a preload parked a tip inside the merge too,
/// and at 50 mm it stopped the feed (`8001`) with the tip there. Every one is refused (`R`,
/// nothing changed, register 0x8f names the rule); preloads, a load and an unload then park
/// every tip behind the merge, out of the next slot's way.
#[test]
fn a_park_inside_the_merge_is_refused_and_the_parked_tip_rests_behind_the_merge() {
    let writes = [
        (0x41, 1, Rule::ParkClearsMerge),
        (0x41, 8, Rule::ParkClearsMerge),
        (0x42, 5000, Rule::RevolutionFitsDrive),
        (0x42, 1000, Rule::RevolutionFitsDrive),
        (0x42, 400, Rule::RevolutionFitsDrive),
    ];
    for (address, value, rule) in writes {
        let mut rig = Rig::<3>::new();
        rig.boot();
        let context = format!("W{address:x} {value}");
        let before = rig.app.config().clone();
        let written = answer(&mut rig, address, value);
        for slot in 0..2 {
            let preload = Request::new(RequestCode::Load, slot);
            assert_eq!(rig.command(preload).last, finished(preload), "{context}");
            assert_eq!(rig.app.lanes()[usize::from(slot)], Lane::Parked, "{context}");
            parked_tips_rest_between_merge_and_slot_sensor(&rig, &context);
        }
        assert_eq!(rig.command(t(0)).last, finished(t(0)), "{context}");
        let unload = Request::new(RequestCode::Unload, 0);
        assert_eq!(rig.command(unload).last, finished(unload), "{context}");
        assert_eq!(rig.app.lanes()[0], Lane::Parked, "{context}");
        parked_tips_rest_between_merge_and_slot_sensor(&rig, &context);
        assert_eq!(written, Some(ParamCode::Rejected), "{context}");
        assert!(
            rig.app.config() == &before,
            "{context}: the refused write changed nothing"
        );
        assert_eq!(rig.read(REFUSED_RULE), Some(rule.code().into()), "{context}");
    }
}

/// The guards' edges are safe: at the shortest park they take for the shortest, the nominal and
/// the longest revolution they take (whose distances the model, at 2.00 mm, makes longer or
/// shorter than the unit counts), every preload parks its tip behind the merge, and the next slot
/// passes. At the longest park they take, each tip still rests in front of its slot sensor, which
/// sees it. One millimetre beyond each edge is refused.
#[test]
fn at_the_guards_edges_every_parked_tip_rests_between_the_merge_and_the_slot_sensor() {
    // (filament per revolution, 1/100 mm; park, mm; the park one beyond): two revolutions past
    // the merge at 8 mm, or two in front of the slot sensor at 95 mm.
    for (centi, park, beyond) in [(150, 11, 10), (200, 12, 11), (250, 13, 12), (200, 91, 92)] {
        let mut rig = Rig::<3>::new();
        rig.boot();
        let context = format!("{centi} / 100 mm a revolution, park {park} mm");
        // The hub search first: it must reach from the longer park.
        rig.write(0x47, 100);
        rig.write(0x42, centi);
        rig.write(0x41, park);
        assert_eq!(
            answer(&mut rig, 0x41, beyond),
            Some(ParamCode::Rejected),
            "{context}"
        );
        for slot in 0..3 {
            let preload = Request::new(RequestCode::Load, slot);
            assert_eq!(rig.command(preload).last, finished(preload), "{context}");
            assert_eq!(rig.app.lanes()[usize::from(slot)], Lane::Parked, "{context}");
            assert_eq!(
                rig.app.unit().feeders[usize::from(slot)].filament.present(),
                Some(true)
            );
            parked_tips_rest_between_merge_and_slot_sensor(&rig, &context);
        }
    }
}

/// Finding: the hub's "on" threshold took 4095, which no reading reaches (a reading at or above
/// 4055 is a sensor at the rail, never filtered): the hub sensor went blind and the next load
/// stopped with `8001`. Such thresholds are refused on every sensor, and the load goes on.
#[test]
fn a_threshold_no_reading_reaches_is_refused_and_the_hub_still_sees_the_tip() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let written = answer(&mut rig, 0x90, 4095);
    let run = rig.command(t(0));
    assert_eq!(run.last, finished(t(0)), "{:?}", run.progress);
    assert_eq!(written, Some(ParamCode::Rejected));
    assert_eq!(rig.read(0x90), Some(2600), "unchanged");
    assert_eq!(
        rig.read(REFUSED_RULE),
        Some(Rule::ThresholdsWithinRails.code().into())
    );
    // Every sensor with thresholds, both rails: the hub's, slot 0's filament sensor, slot 0's
    // motor Hall sensor ("on" at 0x90 + i, "off" at 0xa0 + i).
    for sensor in [0, 3, 4] {
        for (address, value) in [
            (0x90 + sensor, 4055),
            (0x90 + sensor, 4095),
            (0xa0 + sensor, 40),
            (0xa0 + sensor, 0),
        ] {
            assert_eq!(
                answer(&mut rig, address, value),
                Some(ParamCode::Rejected),
                "{address:#x} = {value}"
            );
        }
    }
    // Just inside the rails: taken (slot 2's sensor, whose filament the unit has not seen:
    // nothing holds its "on" to a reading).
    rig.write(0xa7, 41);
    rig.write(0x97, 4054);
}

/// Finding: with the tension dead band written to 0 the follower acted on the sensor's noise: with
/// the printer idle and its gears holding the filament, the loaded slot's motor was driven on and
/// off, pushing into the idle extruder. The write is refused, and the follower rests.
#[test]
fn a_dead_band_inside_the_tension_noise_is_refused_and_the_follower_rests() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    assert_eq!(rig.command(t(0)).last, finished(t(0)));
    rig.idle(1000);
    let written = answer(&mut rig, 0x4d, 0);
    let from = rig.motor_log.len();
    rig.idle(3000);
    let driven = rig.motor_log[from..]
        .iter()
        .filter(|motors| motors[0].is_driving())
        .count();
    assert_eq!(
        driven, 0,
        "slot 0 driven in {driven} of 3000 steps with the printer idle"
    );
    assert_eq!(written, Some(ParamCode::Rejected));
    assert_eq!(rig.read(0x4d), Some(60), "unchanged");
    assert_eq!(
        rig.read(REFUSED_RULE),
        Some(Rule::DeadBandAboveNoise.code().into())
    );
}

/// Finding: the follower's stall stop came up to ~100 ms after the stall rule's bound (the motor
/// driven at or above the stall duty, 0x44, without a revolution for the stall timeout, 0x45).
/// The follower's duty rises with the tension, which is noisy: near the stall duty it dipped
/// below it, and every dip started the stall count again. Printing slowly and jammed, the stop
/// must come within the bound counted from the first step the motor was driven that hard.
#[test]
fn a_jammed_followers_stall_stop_comes_within_the_stall_rules_bound() {
    for printing in [2.0, 4.0] {
        let mut rig = Rig::<3>::new();
        rig.boot();
        assert_eq!(rig.command(t(0)).last, finished(t(0)));
        rig.model.set_printing(Some(printing));
        rig.idle(3000);
        rig.inject(Fault::Jam { slot: 0 });
        let config = rig.app.config().clone();
        let bound = u64::from(config.stall_timeout_ms) + 1;
        // Since when slot 0 is driven hard with no revolution since.
        let mut hard_since: Option<u64> = None;
        let mut stopped = None;
        for _ in 0..5000 {
            let now = rig.now;
            rig.step_with(&[]);
            let last_revolution = rig.app.unit().feeders[0].motion.last_mark().as_millis();
            if hard_since.is_some_and(|since| last_revolution >= since) {
                hard_since = None;
            }
            match rig.motor_log.last().unwrap()[0] {
                MotorCommand::Drive { duty, .. } if duty.permille() >= config.stall_min_duty => {
                    hard_since.get_or_insert(now);
                }
                MotorCommand::Brake if hard_since.is_some() => {
                    stopped = Some(now);
                    break;
                }
                _ => {}
            }
        }
        let (since, stopped) = (hard_since.expect("driven hard"), stopped.expect("stopped"));
        assert!(
            stopped - since <= bound,
            "printing at {printing} mm/s: stopped {} ms after the motor was first driven hard without turning (bound {bound} ms)",
            stopped - since
        );
        assert!(!rig.app.unit().drives[0].command().is_driving());
    }
}

/// Stored settings are outside input: a stored configuration the guards refuse (a park inside
/// the merge, from a firmware without them or a store damaged past its check sums) is dropped
/// whole. The unit runs on its defaults, keeping the revision a printer accepted (the identity,
/// which no rule concerns), and register 0x8f names the rule.
#[test]
fn stored_settings_the_guards_refuse_fall_back_to_the_defaults_keeping_the_identity() {
    let mut app = App::<3>::new(Config::default());
    let mut snapshot = Snapshot::<3>::default();
    for setting in [(0x22, 500), (0x41, 1), (0x52, 2)] {
        snapshot.settings.push(setting).unwrap();
    }
    app.restore(&snapshot);
    let expected = Config {
        version: Version {
            revision: 2,
            ..Config::default().version
        },
        ..Config::default()
    };
    assert!(app.config() == &expected, "{:?}", app.config());
    assert_eq!(app.refused_rule(), Some(Rule::ParkClearsMerge));
    assert_eq!(
        app.read_register(REFUSED_RULE),
        Some(Rule::ParkClearsMerge.code().into())
    );
    // What the unit keeps from now on: the defaults and the identity.
    assert_eq!(app.snapshot().settings.as_slice(), &[(0x52, 2)]);
}

/// Settings that only agree together (a longer park and the hub search that reaches from it)
/// are restored whatever their stored order, and out-of-range values alone are dropped.
#[test]
fn stored_settings_that_agree_only_together_are_restored() {
    let mut app = App::<3>::new(Config::default());
    let mut snapshot = Snapshot::<3>::default();
    for setting in [(0x41, 60), (0x47, 64), (0x22, 20)] {
        snapshot.settings.push(setting).unwrap();
    }
    app.restore(&snapshot);
    let expected = Config {
        park_mm: 60,
        hub_search_mm: 64,
        ..Config::default()
    };
    assert!(app.config() == &expected, "{:?}", app.config());
    assert_eq!(app.refused_rule(), None);
    assert_eq!(app.read_register(REFUSED_RULE), Some(0));
}

/// A unit built with a longer merge (another hub): the guards hold the park to its own geometry.
#[test]
fn the_rules_follow_the_builds_geometry() {
    let mut config = Config::default();
    config.hardware.merge_mm = 20;
    config.park_mm = 30;
    let mut rig = Rig::<3>::with(config, ModelConfig::default());
    rig.boot();
    assert_eq!(answer(&mut rig, 0x41, 23), Some(ParamCode::Rejected));
    assert_eq!(answer(&mut rig, 0x41, 24), Some(ParamCode::Accepted));
}

/// Every threshold a user tunes survives a restart: each slot's filament sensor and motor Hall
/// sensor, not only the hub's (the snapshot reads each setting through the register table).
#[test]
fn tuned_thresholds_of_every_sensor_are_kept_across_a_restart() {
    let mut app = App::<3>::new(Config::default());
    // Hub, slot 1's filament sensor, slot 2's motor Hall sensor: "on" thresholds.
    for (address, value) in [(0x90, 2700), (0x95, 2750), (0x98, 2400)] {
        assert!(app.write_register(address, value), "{address:#x}");
    }
    let snapshot = app.snapshot();
    let mut restarted = App::<3>::new(Config::default());
    restarted.restore(&snapshot);
    for (address, value) in [(0x90, 2700), (0x95, 2750), (0x98, 2400)] {
        assert_eq!(restarted.read_register(address), Some(value), "{address:#x}");
    }
}
