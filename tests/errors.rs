//! Errors that name the first cause, and Retries that lead out of them (issue 12 #12, #11, #7).
//! Each test plays the printer against the physical model and is named after what a user sees.

mod common;

use common::{FsensorReports, Rig, error, finished, press, t};
use mmu_model::Fault;
use mmu_protocol::{ButtonCode, ErrorCode, ParamCode, Request, RequestCode, Response};

/// A printer that never co-feeds (its extruder stays idle): `Q0` every 100 ms until the command
/// ends; the last answer.
fn follow_without_cofeed(rig: &mut Rig<3>, request: Request) -> Response {
    for _ in 0..1200 {
        rig.idle(100);
        let answer = rig.query();
        if answer.param != ParamCode::Processing {
            return answer;
        }
    }
    panic!("{request:?} did not end");
}

// ---- #12: errors that name the wrong part -----------------------------------------------------

/// A jam in the Bowden tube stops the filament on its way to the printer's sensor: the screen
/// must send the user to the tube and the printer's sensor (`8003` FSENSOR DIDNT TRIGG.), not
/// to the slot motor (`8047` PULLEY CANNOT MOVE).
#[test]
fn a_bowden_jam_is_reported_as_the_printer_sensor_not_triggering() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::BowdenJam);
    let run = rig.command(t(1));
    assert_eq!(
        run.last,
        error(t(1), ErrorCode::FSENSOR_DIDNT_SWITCH_ON),
        "{:?}",
        run.progress
    );
    rig.idle(10);
    assert!(rig.motors_stopped());
}

/// The printer's sensor never triggers and the printer does not co-feed: the tip runs into the
/// idle extruder's gears and the motor stalls there. The first cause is the sensor that did not
/// trigger (`8003`), not the slot motor.
#[test]
fn the_printer_sensor_never_triggering_is_8003_even_when_the_motor_stalls_at_the_idle_extruder() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.fsensor = FsensorReports::Stuck(0);
    rig.send(t(1));
    assert_eq!(
        follow_without_cofeed(&mut rig, t(1)),
        error(t(1), ErrorCode::FSENSOR_DIDNT_SWITCH_ON)
    );
    rig.idle(10);
    assert!(rig.motors_stopped());
}

/// After `8003` the user clears the jam and pulls the filament back to look: just past the hub
/// sensor, or out of the hub. Retry searches the whole bounded distance again (from where the tip
/// is, or from the park position), instead of counting on from where the first attempt stopped.
#[test]
fn retry_after_8003_searches_the_full_distance_again() {
    for pulled_back_to in [5.0, -20.0] {
        let mut rig = Rig::<3>::new();
        rig.boot();
        rig.inject(Fault::BowdenJam);
        let run = rig.command(t(1));
        assert_eq!(run.last, error(t(1), ErrorCode::FSENSOR_DIDNT_SWITCH_ON));
        rig.model.clear_all();
        assert!(rig.model.insert_filament(1, pulled_back_to));
        rig.idle(100);
        press(&mut rig, ButtonCode::MIDDLE);
        let run = rig.follow(t(1), 120_000);
        assert_eq!(run.last, finished(t(1)), "{pulled_back_to}: {:?}", run.progress);
        assert_eq!(rig.model.loaded_slot(), Some(1));
    }
}

/// With the printer's sensor stuck on, the load stops at once with `8009` (FSENSOR TOO EARLY).
/// The printer's automatic Retries (three `B1`) must keep that first cause on the screen, moving
/// nothing, instead of unloading into `8004` (FSENSOR FIL. STUCK). Once the sensor works, Retry
/// loads.
#[test]
fn a_printer_sensor_stuck_on_keeps_8009_through_the_automatic_retries() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.fsensor = FsensorReports::Stuck(1);
    let run = rig.command(t(2));
    assert_eq!(run.last, error(t(2), ErrorCode::FSENSOR_TOO_EARLY));
    rig.idle(300);
    let before = rig.motor_log.len();
    for _ in 0..3 {
        press(&mut rig, ButtonCode::MIDDLE);
        rig.idle(500);
        assert_eq!(rig.query(), error(t(2), ErrorCode::FSENSOR_TOO_EARLY));
    }
    assert!(
        rig.nothing_moved_since(before),
        "nothing moves while the sensor still reads filament"
    );
    rig.fsensor = FsensorReports::Truthful;
    // The printer reports its sensor's change at once (`f0`), then the user presses Retry.
    rig.retry();
    let run = rig.follow(t(2), 120_000);
    assert_eq!(run.last, finished(t(2)), "{:?}", run.progress);
    assert_eq!(rig.model.loaded_slot(), Some(2));
}

// ---- #11: a wrong Bowden length cannot be fixed from the screen --------------------------------

/// Register 0x22 says 420 mm on a 360 mm tube (and on a 330 mm one): the printer's sensor
/// triggers during the fast feed (`8009`). The printer cannot write 0x22 while `T` runs, so Retry
/// must fix it: the unit measured where the sensor triggered (from where the hub sensor saw the
/// tip), keeps that as the Bowden length (a setting: it survives a restart), says so in register
/// 0x53, and finishes the load.
#[test]
fn retry_after_8009_learns_the_bowden_length_and_finishes() {
    for tube in [360.0, 330.0] {
        let config = mmu_firmware::Config {
            bowden_mm: 420,
            ..mmu_firmware::Config::default()
        };
        let model = mmu_model::ModelConfig {
            bowden_length_mm: tube,
            extruder_gears_mm: tube + 4.0,
            nozzle_mm: tube + 60.0,
            ..mmu_model::ModelConfig::default()
        };
        let mut rig = Rig::<3>::with(config, model);
        rig.boot();
        let run = rig.command(t(0));
        assert_eq!(run.last, error(t(0), ErrorCode::FSENSOR_TOO_EARLY), "{tube}");
        assert_eq!(rig.read(0x53), Some(0), "nothing learned yet");
        let revision = rig.app.settings_revision();
        press(&mut rig, ButtonCode::MIDDLE);
        let run = rig.follow(t(0), 120_000);
        assert_eq!(run.last, finished(t(0)), "{tube}: {:?}", run.progress);
        assert_eq!(rig.model.loaded_slot(), Some(0));
        let learned = rig.read(0x22).unwrap();
        assert!(
            (f32::from(learned) - tube).abs() <= 8.0,
            "0x22 learned {learned} mm on a {tube} mm tube"
        );
        assert_eq!(rig.read(0x53), Some(learned));
        // The persistence keeper snapshots the settings only when their revision moved.
        assert_ne!(
            rig.app.settings_revision(),
            revision,
            "{tube}: a learned setting is a change"
        );
        // What the persistence keeper saves brings it back after a restart.
        let mut restarted = mmu_firmware::App::<3>::new(mmu_firmware::Config::default());
        restarted.restore(&rig.app.snapshot());
        assert_eq!(restarted.read_register(0x22), Some(learned), "{tube}");
        // The next load uses it: no 8009 any more.
        assert_eq!(rig.command(t(1)).last, finished(t(1)), "{tube}");
    }
}

/// The same Bowden length too long (500 mm on a 360 mm tube) on a printer whose extruder gears
/// come before its sensor (the Nextruder's order, Buddy 6.5.3): the fast feed meets the idle
/// gears, 10 mm short of the sensor, which never triggers. That stop ends the fast feed; the slow
/// feed with the printer's co-feed takes the tip through its gears to its sensor, and the length
/// measured from the hub sensor is kept: no error, the next change as well (issue 34 finding 3:
/// `8003` on every change, 0x22 stayed 500).
#[test]
fn a_fast_feed_that_meets_the_gears_first_learns_the_bowden_length_without_an_error() {
    let config = mmu_firmware::Config {
        bowden_mm: 500,
        ..mmu_firmware::Config::default()
    };
    let model = mmu_model::ModelConfig {
        extruder_gears_mm: 350.0,
        ..mmu_model::ModelConfig::default()
    };
    let mut rig = Rig::<3>::with(config, model);
    rig.wants_revision = 4;
    rig.boot();
    let run = rig.command(t(0));
    assert_eq!(run.last, finished(t(0)), "{:?}", run.progress);
    let learned = rig.read(0x22).unwrap();
    assert!(
        (355..=368).contains(&learned),
        "0x22 learned {learned} mm on a 360 mm tube"
    );
    assert_eq!(rig.read(0x53), Some(learned));
    let run = rig.command(t(1));
    assert_eq!(run.last, finished(t(1)), "{:?}", run.progress);
    assert_eq!(rig.model.loaded_slot(), Some(1));
}

/// The length is never learned longer than the old value, nor from a sensor that reads filament
/// where no tube could end (stuck on at the hub): then `8009` stays, as above.
#[test]
fn a_sensor_on_at_the_hub_teaches_nothing() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.fsensor = FsensorReports::Stuck(1);
    assert_eq!(rig.command(t(0)).last, error(t(0), ErrorCode::FSENSOR_TOO_EARLY));
    press(&mut rig, ButtonCode::MIDDLE);
    rig.idle(500);
    assert_eq!(rig.query(), error(t(0), ErrorCode::FSENSOR_TOO_EARLY));
    assert_eq!(rig.read(0x22), Some(360));
}

// ---- #7: link loss during the co-feed ------------------------------------------------------------

/// How long a silent printer may leave the unit pushing in `P1c`: the hold starts after
/// [`mmu_firmware::phases::PRINTER_SILENT_MS`] and the motor is braked in the same step; 10 ms
/// for the brake to take.
const HOLD_WITHIN_MS: u64 = mmu_firmware::phases::PRINTER_SILENT_MS + 10;

/// The printer goes silent during `P1c` (its request or the unit's answer was lost: it waits out
/// its 2 s link timeout, then handshakes again; its co-feed stops and no `f` can arrive). The
/// unit holds its motor until the printer speaks again, without failing and without the silence
/// counting against the phase's time bound (also for a silence longer than that bound), then the
/// change finishes.
#[test]
fn a_silent_printer_during_p1c_holds_the_motor_until_it_speaks_again() {
    for silence_ms in [3000, 20_000] {
        let mut rig = Rig::<3>::new();
        rig.boot();
        rig.send(t(1));
        play_until_p1c(&mut rig);
        let silent_from = rig.motor_log.len();
        rig.idle(silence_ms);
        let driven: Vec<usize> = rig.motor_log[silent_from..]
            .iter()
            .enumerate()
            .filter(|(_, motors)| motors.iter().any(|m| m.is_driving()))
            .map(|(ms, _)| ms)
            .collect();
        let last_driven = driven.last().copied().unwrap_or(0) as u64;
        assert!(
            last_driven < HOLD_WITHIN_MS,
            "{silence_ms} ms silence: driven {last_driven} ms into it"
        );
        assert!(!driven.is_empty(), "the unit went on for a heartbeat first");
        // The printer handshakes again and reports its sensor; the load goes on.
        rig.handshake();
        let resumed_from = rig.motor_log.len();
        let run = rig.follow(t(1), 120_000);
        assert_eq!(run.last, finished(t(1)), "{silence_ms}: {:?}", run.progress);
        assert_eq!(rig.model.loaded_slot(), Some(1));
        let resumed = rig.motor_log[resumed_from..]
            .iter()
            .position(|motors| motors[1].is_driving());
        assert!(resumed.is_some_and(|ms| ms < 20), "resumed after {resumed:?} ms");
    }
}

/// Play the printer for `T` until the unit reports `P1c`, and not a step longer.
fn play_until_p1c(rig: &mut Rig<3>) {
    loop {
        for _ in 0..10 {
            rig.step_with(&[]);
        }
        let answer = rig.query();
        assert_eq!(answer.param, ParamCode::Processing, "{answer:?}");
        if answer.param_value == Some(u16::from(mmu_protocol::ProgressCode::FEEDING_TO_FSENSOR.0)) {
            return;
        }
    }
}

/// A frame from the printer arrives broken during `P1c` (at 1 % byte errors, sometimes its `f1`).
/// The printer then waits out its link timeout and handshakes again, and on a noisy line its
/// handshakes may break too, each a heartbeat apart: never silent long enough for the silence
/// rule. The unit holds from the broken frame until the printer reports its sensor again (`f`, at
/// the end of a handshake that got through), then the change finishes.
#[test]
fn a_broken_frame_during_p1c_holds_the_motor_until_the_printer_reports_its_sensor() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.send(t(1));
    play_until_p1c(&mut rig);
    // `f1*..` with its CRC broken.
    let mut broken = Request::new(RequestCode::FilamentSensor, 1)
        .encode()
        .as_bytes()
        .to_vec();
    broken[1] ^= 0x02;
    assert_eq!(rig.send_bytes(&broken), None);
    let held_from = rig.motor_log.len();
    for _ in 0..4 {
        rig.idle(900);
        // A handshake that breaks after its first exchange.
        rig.send(Request::new(RequestCode::Version, 0));
    }
    rig.idle(900);
    let driven_ms = rig.motor_log[held_from..]
        .iter()
        .filter(|motors| motors.iter().any(|m| m.is_driving()))
        .count();
    assert_eq!(
        driven_ms, 0,
        "driven {driven_ms} ms while the printer's sensor was unknown"
    );
    rig.handshake();
    let run = rig.follow(t(1), 120_000);
    assert_eq!(run.last, finished(t(1)), "{:?}", run.progress);
    assert_eq!(rig.model.loaded_slot(), Some(1));
}
