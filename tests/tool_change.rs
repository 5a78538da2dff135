//! ToolChange (`T<n>`, `src/commands/tool_change.rs`): the loaded slot comes out
//! (UnloadFromNozzle) and slot *n* goes in to the nozzle (LoadToNozzle), as the printer drives it
//! against the physical model. Every happy path with its progress sequence, and every error of
//! the command's recovery tables (its own, the unload's, the load's and the shared motion rows)
//! raised on the rig, with what the printer's button then does.
//!
//! Also testing `T`: `tests/printer_truth.rs` (a `T` sent over a waiting error, Retry after an
//! error raised before anything moved), `tests/safe_motion.rs` (a jam while printing after the
//! change), `tests/properties.rs` (random commands and faults).

mod common;

use common::{
    FsensorReports, LOAD_PROGRESS, PARK_MM, Rig, UNLOAD_PROGRESS, assert_parked, error, finished, t,
};
use mmu_model::{Fault, Rail, SensorId};
use mmu_protocol::{ErrorCode, ParamCode, ProgressCode as P};

#[test]
fn tool_change_loads_to_the_nozzle_with_the_mmu3_progress_sequence() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let run = rig.command(t(0));
    assert_eq!(run.progress, LOAD_PROGRESS);
    assert_eq!(run.last, finished(t(0)));
    assert!(
        rig.model.fsensor_state() >= 1,
        "the filament reached the printer's sensor"
    );
    assert_eq!(rig.model.loaded_slot(), Some(0));
    // The slot motor follows the extruder's last push, then rests.
    rig.idle(2000);
    assert!(rig.motors_stopped());
    // Register 0x07 says InNozzle, the selector register says slot 0.
    assert_eq!(rig.read(7), Some(8));
    assert_eq!(rig.read(0x1b), Some(0));
}

#[test]
fn tool_change_to_another_slot_unloads_first_and_parks_the_old_one() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    let run = rig.command(t(2));
    assert_eq!(run.progress, [&UNLOAD_PROGRESS[..], &LOAD_PROGRESS].concat());
    assert_eq!(run.last, finished(t(2)));
    assert_parked(&rig, 0);
    assert_eq!(rig.model.loaded_slot(), Some(2));
}

#[test]
fn tool_change_to_the_loaded_slot_finishes_at_once() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(1));
    rig.idle(3000);
    let tip = rig.model.tip_mm(1).unwrap();
    let run = rig.command(t(1));
    assert!(run.progress.is_empty());
    assert_eq!(run.last, finished(t(1)));
    assert!((rig.model.tip_mm(1).unwrap() - tip).abs() < 1.0);
}

#[test]
fn a_slot_the_unit_does_not_have_is_accepted_then_reported_invalid() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    assert_eq!(rig.send(t(3)).unwrap().encode().as_bytes(), b"T3 A*75\n");
    assert_eq!(rig.query(), error(t(3), ErrorCode::INVALID_TOOL));
    assert!(rig.motors_stopped());
    // The printer stops the print or resets the unit: the next command is not refused forever.
    assert_eq!(rig.send(t(0)).unwrap().param, ParamCode::Accepted);
}

#[test]
fn hub_never_sees_the_tip() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    // A hub threshold above the filament's reading (3,000; one no reading reaches at all, at the
    // rail, is refused): the tip passes unseen.
    rig.write(0x90, 4000);
    rig.command_fails_with(t(0), ErrorCode::FINDA_DIDNT_SWITCH_ON);
    // Before a preload the unit does not know where the tip is: the bound is the preload distance.
    let tip = rig.model.tip_mm(0).unwrap();
    let bound = PARK_MM + f32::from(rig.app.config().preload_max_mm) + 5.0;
    assert!(
        tip < bound,
        "the search is bounded: tip at {tip} mm, bound {bound} mm"
    );
}

#[test]
fn printer_sensor_never_triggers_then_retry_recovers() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.fsensor = FsensorReports::Stuck(0);
    rig.command_fails_with(t(1), ErrorCode::FSENSOR_DIDNT_SWITCH_ON);
    // The sensor works again (the printer reports it at once); the printer (or the user)
    // presses Retry.
    rig.fsensor = FsensorReports::Truthful;
    rig.retry_finishes(t(1));
    assert_eq!(rig.model.loaded_slot(), Some(1));
}

#[test]
fn printer_sensor_triggering_too_early() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.fsensor = FsensorReports::Stuck(1);
    rig.command_fails_with(t(2), ErrorCode::FSENSOR_TOO_EARLY);
}

#[test]
fn stalled_motor() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::Jam { slot: 1 });
    rig.command_fails_with(t(1), ErrorCode::STALLED_PULLEY);
}

#[test]
fn empty_slot_fails_without_moving() {
    let mut rig = Rig::<3>::new();
    rig.model.remove_filament(2);
    rig.boot();
    rig.command_fails_with(t(2), ErrorCode::FINDA_DIDNT_SWITCH_ON);
    assert!(
        rig.motor_log.iter().all(|motors| !motors[2].is_driving()),
        "slot 2's motor never ran"
    );
}

#[test]
fn disconnected_hub_sensor_is_reported_not_believed() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.disconnect(SensorId::HubFilament, Rail::High);
    rig.command_fails_with(t(0), ErrorCode::FINDA_FLICKERS);
    assert_eq!(rig.read(0x50), Some(1));
}

#[test]
fn disconnected_motor_hall_sensor() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.disconnect(SensorId::MotorHall(0), Rail::Low);
    rig.command_fails_with(t(0), ErrorCode::MOVE_PULLEY_FAILED);
}

// ---- recovery: every row of the tool change's tables, raised on the rig ---------------------
//
// `8008` before anything moved (ToolChange's own row): `tests/printer_truth.rs`
// `retry_after_a_plan_error_plans_again_instead_of_finishing`. `8003`:
// `printer_sensor_never_triggers_then_retry_recovers` above. `INTERNAL` (a motion without a
// budget) cannot be raised on the model: no fault reaches it.

#[test]
fn printer_sensor_never_clears_on_the_unload_half_then_retry_unloads_and_loads() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.fsensor = FsensorReports::Stuck(1);
    rig.command_fails_with(t(1), ErrorCode::FSENSOR_DIDNT_SWITCH_OFF);
    rig.fsensor = FsensorReports::Truthful;
    let run = rig.retry_finishes(t(1));
    assert_eq!(run.progress, [&UNLOAD_PROGRESS[..], &LOAD_PROGRESS].concat());
    assert_parked(&rig, 0);
    assert_eq!(rig.model.loaded_slot(), Some(1));
}

#[test]
fn hub_never_clears_on_the_unload_half_then_retry_unloads_and_loads() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    // An "off" threshold no reading goes below: the hub seems to hold filament forever.
    rig.hub_never_clears_then_retry(t(2));
    assert_eq!(rig.model.loaded_slot(), Some(2));
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(tip < 0.0, "slot 0 is out of the hub path: tip at {tip} mm");
}

#[test]
fn empty_slot_then_retry_after_the_user_inserts_filament_loads_it() {
    let mut rig = Rig::<3>::new();
    rig.model.remove_filament(2);
    rig.boot();
    rig.command_fails_with(t(2), ErrorCode::FINDA_DIDNT_SWITCH_ON);
    rig.model.insert_filament(2, PARK_MM);
    rig.idle(100);
    rig.retry();
    let run = rig.tool_change_goes_on_and_loads(2);
    assert_eq!(run.progress, LOAD_PROGRESS);
}

#[test]
fn bowden_shorter_than_configured_then_retry_goes_on_from_the_printer_sensor() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    // The unit believes in a 420 mm Bowden tube; the printer's sensor is at 360 mm.
    rig.write(0x22, 420);
    let run = rig.command_fails_with(t(1), ErrorCode::FSENSOR_TOO_EARLY);
    assert_eq!(run.progress, [P::FEEDING_TO_FINDA, P::FEEDING_TO_BONDTECH]);
    // Retry: the tip is at the printer's sensor, the load goes on from there (the printer cannot
    // write 0x22 while `T` runs; the unit learned the length: tests/errors.rs).
    let run = rig.retry_finishes(t(1));
    assert!(
        !run.progress.contains(&P::UNLOADING_TO_FINDA),
        "no unload and reload: {:?}",
        run.progress
    );
    assert_eq!(rig.model.loaded_slot(), Some(1));
}

#[test]
fn stalled_motor_then_retry_after_the_jam_is_cleared_loads() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::Jam { slot: 1 });
    rig.command_fails_with(t(1), ErrorCode::STALLED_PULLEY);
    rig.model.clear_all();
    rig.retry();
    let run = rig.tool_change_goes_on_and_loads(1);
    assert_eq!(run.progress, LOAD_PROGRESS);
}

#[test]
fn hub_sensor_disconnected_in_the_bowden_feed_then_retry_goes_on_from_there() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command_until(t(0), P::FEEDING_TO_BONDTECH);
    rig.disconnect(SensorId::HubFilament, Rail::Low);
    rig.fails_then_retry_finishes(t(0), ErrorCode::FINDA_FLICKERS, &LOAD_PROGRESS[1..]);
    assert_eq!(rig.model.loaded_slot(), Some(0));
}

#[test]
fn motor_hall_sensor_disconnected_while_parking_the_old_slot_then_retry_parks_and_loads() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.command_until(t(2), P::RETRACTING_FROM_FINDA);
    rig.disconnect(SensorId::MotorHall(0), Rail::Low);
    rig.fails_then_retry_finishes(
        t(2),
        ErrorCode::MOVE_PULLEY_FAILED,
        &[&[P::RETRACTING_FROM_FINDA][..], &LOAD_PROGRESS].concat(),
    );
    assert_eq!(rig.model.loaded_slot(), Some(2));
    // The motor ran blind until the fault was recognised, so slot 0 may rest a few mm further
    // back than the park position, but within the distance the next load searches the hub.
    let tip = rig.model.tip_mm(0).unwrap();
    let search = f32::from(rig.app.config().hub_search_mm);
    assert!(
        (-search..PARK_MM + 5.0).contains(&tip),
        "slot 0 parked: tip at {tip} mm"
    );
}

#[test]
fn hub_threshold_fixed_then_retry_loads() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.write(0x90, 4000);
    rig.command_fails_with(t(0), ErrorCode::FINDA_DIDNT_SWITCH_ON);
    rig.write(0x90, 2600);
    rig.idle(100);
    rig.retry_finishes(t(0));
    assert_eq!(rig.model.loaded_slot(), Some(0));
}

/// The board defers its save piece after a step that begins a phase (the costliest steps on the
/// MCU, `Outputs::phase_began`): each phase of a tool change says so once, in the step it
/// begins, and no other step does.
#[test]
fn each_phase_of_a_tool_change_says_once_that_it_began() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    let before = rig.phase_began_log.len();
    let run = rig.command(t(1));
    let began = rig.phase_began_log[before..]
        .iter()
        .filter(|&&began| began)
        .count();
    // Unload to the slot sensor, retract, park; feed to the hub, to the printer's sensor, to the
    // nozzle: a progress code each.
    assert_eq!(run.progress.len(), 6, "{:?}", run.progress);
    assert_eq!(began, run.progress.len());
    rig.idle(2000);
    assert!(
        !rig.phase_began_log[rig.phase_began_log.len() - 2000..].contains(&true),
        "an idle unit begins no phase"
    );
}
