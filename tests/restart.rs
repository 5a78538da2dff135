//! After a restart the unit either proves which slot holds the hub path before it moves it far,
//! by a motion safe whichever slot it is (a pull the slot sensor stops, the filament still in its
//! drive gear; a push short of the merge), or refuses (`8008`): whatever the stored lanes say
//! (right, stale, wiped or impossible) and wherever the filaments really are. Every case: stored
//! lanes x the slot that really holds the path, then the printer's next tool change; then the
//! cases of a restart mid tool change that are proved, and those the sensors cannot tell.

mod common;

use common::{FsensorReports, Rig, assert_parked, loaded, press, t};
use mmu_firmware::drive::FEEL_DUTY;
use mmu_firmware::persist::Snapshot;
use mmu_firmware::unit::Lane;
use mmu_firmware::{App, Config};
use mmu_hal_port::{Duty, MotorCommand};
use mmu_model::ModelConfig;
use mmu_protocol::{ButtonCode, ErrorCode, ParamCode, Request, RequestCode, Response};

/// Lanes a store can hold for one slot.
const STORED: [Lane; 4] = [Lane::Unknown, Lane::Parked, Lane::InHub, Lane::Loaded];

/// How far behind its slot sensor a filament that does not hold the path may end, mm: a pull
/// back that proves a stored belief stops at the slot sensor, which sits 5 mm after the drive
/// gear (`ModelConfig::slot_sensor_mm`, `drive_gear_mm`), so the tip stays in the gear's grip
/// whichever slot was pulled. (The proof of a belief about a tip deep in the Bowden tube pulls
/// a slot that turns out not to hold the path back to that sensor: 80 mm from its park position,
/// where the proof used to stop after the hub search distance.)
const PAST_SLOT_SENSOR_MM: f32 = 2.0;

/// Set `MMU_RESTART_ALL=1` to run every case (256) instead of every fourth.
fn cases() -> impl Iterator<Item = ([Lane; 3], Option<usize>)> {
    let stride = if std::env::var_os("MMU_RESTART_ALL").is_some() {
        1
    } else {
        4
    };
    (0..STORED.len().pow(3) * 4).step_by(stride).map(|i| {
        let lanes = [STORED[i % 4], STORED[i / 4 % 4], STORED[i / 16 % 4]];
        let owner = match i / 64 {
            0 => None,
            slot => Some(slot - 1),
        };
        (lanes, owner)
    })
}

#[test]
fn a_restart_proves_or_refuses_and_never_moves_the_wrong_slot() {
    let mut failures = Vec::new();
    let mut cases_run = 0;
    for (lanes, owner) in cases() {
        cases_run += 1;
        let mut rig = Rig::<3>::new();
        rig.boot();
        if let Some(slot) = owner {
            rig.command(t(slot as u8));
        }
        let before: Vec<f32> = (0..3).map(|s| rig.model.tip_mm(s).unwrap()).collect();
        let (sensor, gear) = (
            rig.model.config().slot_sensor_mm,
            rig.model.config().drive_gear_mm,
        );
        rig.restart_with(lanes);
        let target = owner.map_or(0, |slot| (slot + 1) % 3);
        let answer = rig.send(t(target as u8)).map(|a| a.param);
        let run = match answer {
            Some(ParamCode::Accepted) => Some(rig.follow(t(target as u8), 120_000)),
            _ => None,
        };
        for slot in (0..3).filter(|&s| Some(s) != owner && s != target) {
            let tip = rig.model.tip_mm(slot).unwrap();
            if tip < sensor - PAST_SLOT_SENSOR_MM || tip <= gear {
                failures.push(format!(
                    "stored {lanes:?}, slot {owner:?} holds the path, T{target}: slot {slot} pulled back from {:.1} to {tip:.1} mm ({:?})",
                    before[slot],
                    run.as_ref().map(|r| r.last)
                ));
            }
        }
        if let (Some(run), Some(slot)) = (&run, owner)
            && run.last.param == ParamCode::Finished
            && rig.model.loaded_slot() != Some(target)
        {
            failures.push(format!(
                "stored {lanes:?}, slot {slot} held the path: T{target} finished but slot {:?} is loaded",
                rig.model.loaded_slot()
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{} of {cases_run} cases:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

// ---- where a restart mid tool change still asks for UNLOAD MANUALLY -----------------------------
//
// After a restart in a tool change the printer sends `U0` (`sim/tests/restart_mid_tool_change.rs`
// plays the whole recovery, phase by phase). The unit proves the stored slot by pulling it back
// and carries on; these are the cases where the sensors cannot say which slot holds the path.

/// The unit restarted with `lanes` stored, on the rig's model as it is, and the printer's `U0`.
fn restart_then_unload(rig: &mut Rig<3>, lanes: [Lane; 3]) -> Response {
    rig.restart_with(lanes);
    rig.command(Request::new(RequestCode::Unload, 0)).last
}

/// The printer's retract before its `U0` cleared its sensor, but its report (`f0`) comes only
/// after the `U0`, at its next look: the proof waits for it with the motor free, pulls nothing
/// while the printer's last word is "filament", then proves slot 0 and unloads it.
#[test]
fn the_printers_sensor_report_after_its_u0_is_waited_for_then_the_stored_slot_is_proved() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.app = App::new(Config::default());
    rig.app.restore(&Snapshot {
        lanes: [Lane::Loaded, Lane::Parked, Lane::Parked],
        ..Snapshot::default()
    });
    rig.fsensor = FsensorReports::Stuck(1);
    rig.boot();
    // The retract: the tip out of the printer, in the Bowden tube.
    rig.model.insert_filament(0, 300.0);
    let unload = Request::new(RequestCode::Unload, 0);
    rig.issue(unload);
    rig.idle(1_000);
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(
        (tip - 300.0).abs() < 0.5,
        "nothing pulled before the printer's f0: {tip} mm"
    );
    rig.fsensor = FsensorReports::Truthful;
    let run = rig.follow(unload, 120_000);
    assert_eq!(run.last.param, ParamCode::Finished, "{run:?}");
    let parked = -f32::from(rig.app.config().park_mm);
    assert!(rig.model.tip_mm(0).unwrap() <= parked + 1.0);
}

/// The store names slot 0, but slot 1 holds the path, its tip in the Bowden tube short of the
/// printer's sensor (a power loss while it was fed). Pulling slot 0 back clears its slot sensor
/// with the hub still seeing filament: the belief was wrong, but which other slot holds the path
/// (1 or 2, both slot sensors seeing filament, neither tip visible) the sensors cannot say.
/// Slot 0 stops at its slot sensor, still in its drive gear; slot 1 is not moved.
#[test]
fn a_wrong_stored_slot_is_disproved_at_its_slot_sensor_then_unload_manually() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.model.insert_filament(1, 200.0);
    rig.idle(100);
    let slot1 = rig.model.tip_mm(1).unwrap();
    let answer = restart_then_unload(&mut rig, [Lane::Loaded, Lane::Parked, Lane::Parked]);
    assert_eq!(
        answer.param_value,
        Some(ErrorCode::FINDA_VS_EEPROM_DISREPANCY.0),
        "{answer:?}"
    );
    let (sensor, gear) = (
        rig.model.config().slot_sensor_mm,
        rig.model.config().drive_gear_mm,
    );
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(
        tip >= sensor - PAST_SLOT_SENSOR_MM && tip > gear,
        "slot 0 stopped at its slot sensor: {tip} mm"
    );
    assert!(
        tip < sensor + 3.0,
        "slot 0 was pulled to its slot sensor: {tip} mm"
    );
    assert!((rig.model.tip_mm(1).unwrap() - slot1).abs() < 0.5);
}

/// The unit answered `8008` (UNLOAD MANUALLY) and no slot's tip moved from where it was `before`.
fn unload_manually_with_nothing_moved(rig: &Rig<3>, answer: &Response, before: &[f32]) {
    assert_eq!(
        answer.param_value,
        Some(ErrorCode::FINDA_VS_EEPROM_DISREPANCY.0),
        "{answer:?}"
    );
    for (slot, tip) in before.iter().enumerate() {
        let now = rig.model.tip_mm(slot).unwrap();
        assert!(
            (now - tip).abs() < 0.5,
            "slot {slot} moved from {tip} to {now} mm"
        );
    }
}

/// The stored slot 0 does hold the path, but its spool ran out: the tail is past its slot sensor,
/// which reads empty, exactly as a slot pulled back to its drive gear does. No pull can prove
/// the belief (the guard at the slot sensor has nothing to stop on): `8008`, nothing moved.
#[test]
fn a_stored_slot_whose_spool_ran_out_cannot_be_proved_unload_manually() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.model.inject(mmu_model::Fault::SpoolRunout { slot: 0 });
    rig.model.extruder_move(-120.0, 60.0);
    rig.idle(3_000);
    let before: Vec<f32> = (0..3).map(|s| rig.model.tip_mm(s).unwrap()).collect();
    let answer = restart_then_unload(&mut rig, [Lane::Loaded, Lane::Parked, Lane::Parked]);
    unload_manually_with_nothing_moved(&rig, &answer, &before);
}

/// Slot `owner` loaded, the printer's retract out of its gears leaving the tip between its sensor
/// and the gears (the MK3S's order, the rig's default: the sensor still reads filament); then a
/// restart with slot 0 stored as loaded, and the printer's `U0`, from a printer wanting 3.0.`revision`.
fn tip_left_at_the_printers_sensor(owner: u8, revision: u8) -> (Rig<3>, Response, Vec<f32>) {
    let mut rig = Rig::<3>::new();
    rig.wants_revision = revision;
    rig.boot();
    rig.command(t(owner));
    rig.model.extruder_move(-120.0, 60.0);
    rig.idle(3_000);
    assert_ne!(
        rig.model.fsensor_state(),
        0,
        "the tip rests at the printer's sensor"
    );
    let before: Vec<f32> = (0..3).map(|s| rig.model.tip_mm(s).unwrap()).collect();
    let answer = restart_then_unload(&mut rig, [Lane::Loaded, Lane::Parked, Lane::Parked]);
    (rig, answer, before)
}

/// The stored slot 0 holds the path and its tip rests at the printer's sensor when the `U0` comes.
/// The unit waits for the printer to report its sensor off, then pushes slot 0 forward a few
/// millimetres: the tip meets the printer's gears and the Bowden tube reads compressed, which
/// proves the belief; then it unloads slot 0 as every unload: felt free first, then pulled, the
/// printer's sensor clearing within `0x0c` mm.
#[test]
fn filament_at_the_printers_sensor_is_proved_by_a_push_against_its_gears() {
    let (rig, answer, _) = tip_left_at_the_printers_sensor(0, 3);
    assert_eq!(answer.param, ParamCode::Finished, "{answer:?}");
    let parked = -f32::from(rig.app.config().park_mm);
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(tip <= parked + 1.0 && tip > -30.0, "slot 0 parked: {tip} mm");
}

/// The tip may rest anywhere between the printer's sensor and its gears, and a Hall lane counts
/// its push in whole revolutions (2 mm): a push that counted its distance may have met the gears
/// only just. Wherever the tip rests, the push proves slot 0 and it unloads (seed 301 of the
/// power-loss soak ended in `8008` with the tip 0.34 mm past the sensor).
#[test]
fn filament_anywhere_between_the_printers_sensor_and_its_gears_is_proved() {
    let sensor = mmu_model::ModelConfig::default().bowden_length_mm;
    for (tenths, turn_ms) in [1, 5, 20, 39]
        .into_iter()
        .flat_map(|t| (0..60).step_by(4).map(move |ms| (t, ms)))
    {
        let tip = sensor + tenths as f32 / 10.0;
        let mut rig = Rig::<3>::new();
        rig.wants_revision = 3;
        rig.boot();
        rig.command(t(0));
        rig.model.extruder_move(-120.0, 60.0);
        rig.idle(3_000);
        // Where in its revision slot 0's motor rests: turned on for a moment, on air.
        rig.model.remove_filament(0);
        rig.model.step(turn_ms, &[MotorCommand::forward(Duty::MAX)]);
        rig.model.step(500, &[]);
        rig.model.insert_filament(0, tip);
        let answer = restart_then_unload(&mut rig, [Lane::Loaded, Lane::Parked, Lane::Parked]);
        assert_eq!(
            answer.param,
            ParamCode::Finished,
            "tip at {tip} mm, motor turned {turn_ms} ms: {answer:?}"
        );
    }
}

/// The same with slot 1 really holding the path, on either contract: the push moves slot 0 freely
/// a few millimetres forward, short of the merge, and the tube never reads compressed. That slot 0 is not the owner
/// the sensors show; which slot is, they cannot: `8008`, nothing pulled, slot 1 not moved.
#[test]
fn a_wrong_stored_slot_pushed_against_nothing_is_unload_manually() {
    for revision in [3, 4] {
        let (mut rig, answer, before) = tip_left_at_the_printers_sensor(1, revision);
        assert_eq!(
            answer.param_value,
            Some(ErrorCode::FINDA_VS_EEPROM_DISREPANCY.0),
            "3.0.{revision}: {answer:?}"
        );
        let slot0 = rig.model.tip_mm(0).unwrap();
        assert!(
            slot0 >= before[0] - 0.5 && slot0 < rig.model.config().merge_mm,
            "3.0.{revision}: slot 0 pushed from {} to {slot0} mm, short of the merge",
            before[0]
        );
        assert!((rig.model.tip_mm(1).unwrap() - before[1]).abs() < 0.5);
        // Retry (the printer presses it three times by itself) pushes no further.
        let unload = Request::new(RequestCode::Unload, 0);
        for _ in 0..3 {
            rig.send(Request::new(RequestCode::Button, 1));
            let run = rig.follow(unload, 60_000);
            assert_eq!(
                run.last.param_value,
                Some(ErrorCode::FINDA_VS_EEPROM_DISREPANCY.0),
                "3.0.{revision}"
            );
        }
        let after = rig.model.tip_mm(0).unwrap();
        assert!(
            (after - slot0).abs() < 0.5,
            "3.0.{revision}: Retry pushed slot 0 on from {slot0} to {after} mm"
        );
    }
}

/// A printer that accepted 3.0.4 gets the same proof: its sensor still reads the tip after its
/// report was waited for, so the push meets the gears and proves slot 0. Then the unload feels
/// (MMU 3.0.4 would pull nothing before the sensor clears): the tip is free between the sensor and
/// the gears, so it is pulled out and parked. (It used to end `8008` at once: an MK3.5 on Buddy
/// 6.5.3, `mmu printer --sim --printer buddy-6.5 --extruder sensor-first soak --faults random
/// --seed 7`, changes 34 and 173.)
#[test]
fn filament_at_the_sensor_of_a_printer_on_3_0_4_is_proved_then_felt_free() {
    let (rig, answer, _) = tip_left_at_the_printers_sensor(0, 4);
    assert_eq!(answer.param, ParamCode::Finished, "{answer:?}");
    assert_parked(&rig, 0);
}

/// Slot 0 loaded into the nozzle, the extruder's gears gripping it, then a restart with slot 0
/// stored and a `U0` from a printer that did not pull the filament out of its gears first (its
/// retract lost). The push proves slot 0, but the pull that follows would meet gripping gears: on
/// either contract it only feels, `8004` once the filament has been held still. The printer then
/// pulls the filament out of its gears (the retract it lost, and its Retry help) and the Retry
/// finishes the unload.
#[test]
fn a_proved_slot_still_in_the_gears_is_only_felt_then_8004_then_unloaded() {
    let unload = Request::new(RequestCode::Unload, 0);
    for revision in [3, 4] {
        let mut rig = loaded(revision, ModelConfig::default());
        rig.restart_with([Lane::Loaded, Lane::Parked, Lane::Parked]);
        assert_eq!(rig.send(unload).map(|a| a.param), Some(ParamCode::Accepted));
        let run = rig.follow(unload, 60_000);
        assert_eq!(
            run.last.param_value,
            Some(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF.0),
            "3.0.{revision}: {run:?}"
        );
        let grip = rig.model.max_pull_against_grip();
        assert!(
            grip.max_duty_permille <= FEEL_DUTY.permille(),
            "3.0.{revision}: pulled at {} per mille against gripping gears",
            grip.max_duty_permille
        );
        rig.unload_extruder();
        rig.help_unload();
        press(&mut rig, ButtonCode::MIDDLE);
        let run = rig.follow(unload, 60_000);
        assert_eq!(run.last.param, ParamCode::Finished, "3.0.{revision}: {run:?}");
        assert_parked(&rig, 0);
    }
}
