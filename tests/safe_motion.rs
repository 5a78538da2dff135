//! No motion on a wrong belief: every drive is supervised, the tension follower included, and no
//! motor moves while the unit holds an error.

mod common;

use common::{Rig, t};
use mmu_firmware::persist::Snapshot;
use mmu_firmware::phases::UnloadStuck;
use mmu_firmware::registers::UNLOAD_STUCK;
use mmu_firmware::unit::Lane;
use mmu_firmware::{App, Config, HubSamples, Instant, Samples, SlotSamples};
use mmu_model::Fault;
use mmu_protocol::{ErrorCode, ParamCode, Request, RequestCode};

/// The last time (ms) slot `slot`'s motor was driven, from the rig's motor log.
fn last_driven(rig: &Rig<3>, slot: usize) -> Option<u64> {
    rig.motor_log
        .iter()
        .rposition(|motors| motors[slot].is_driving())
        .map(|step| step as u64)
}

#[test]
fn a_jam_while_printing_stops_the_motor_within_5_s_and_retry_resumes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.model.set_printing(Some(4.0));
    rig.idle(5_000);

    rig.inject(Fault::Jam { slot: 0 });
    let jammed_at = rig.now;
    rig.idle(60_000);
    let stopped_at = last_driven(&rig, 0).expect("the motor helped against the jam");
    assert!(stopped_at > jammed_at, "the tube went taut and the motor helped");
    assert!(
        stopped_at < jammed_at + 5_000,
        "the motor was driven {} ms after the jam",
        stopped_at - jammed_at
    );
    let answer = rig.query();
    assert_eq!(
        (answer.code, answer.value, answer.param),
        (RequestCode::Tool, 0, ParamCode::Error)
    );

    // The user clears the jam and presses Retry: printing goes on, the motor assists again.
    assert!(rig.model.clear(mmu_model::FaultKind::Jam(0)));
    rig.send(Request::new(RequestCode::Button, 1));
    let tail = rig.model.tail_mm(0).unwrap();
    rig.idle(10_000);
    assert_eq!(rig.query().param, ParamCode::Finished);
    let fed = rig.model.tail_mm(0).unwrap() - tail;
    assert!(fed > 30.0, "printing goes on: {fed} mm fed in 10 s at 4 mm/s");
    assert!(last_driven(&rig, 0) > Some(stopped_at), "the follower is back");
}

/// Raw readings: every sensor mid-scale (healthy) but the ones given.
fn samples(hub_filament: u16, tension: u16) -> Samples<3> {
    Samples {
        slots: [SlotSamples {
            motion: 2048,
            filament: 3000,
            tension: 2048,
        }; 3],
        hub: HubSamples {
            filament: hub_filament,
            tension,
            cutter: 2048,
        },
    }
}

#[test]
fn a_slot_restored_as_loaded_does_not_move_while_the_start_up_check_reports_8008() {
    let mut app = App::<3>::new(Config::default());
    app.restore(&Snapshot {
        lanes: [Lane::Loaded, Lane::Parked, Lane::Parked],
        ..Snapshot::default()
    });
    // The hub sensor sees nothing, the Bowden tube reads taut (as if an extruder pulled).
    let taut = samples(1000, 2048 + 400);
    let mut answers = Vec::new();
    for ms in 0..3000 {
        let rx: &[u8] = if ms % 500 == 499 { b"Q0*ea\n" } else { b"" };
        let out = app.step(Instant::from_millis(ms), &taut, rx);
        assert!(
            out.motors.iter().all(|m| !m.is_driving()),
            "motor driven at {ms} ms: {:?}",
            out.motors
        );
        answers.extend_from_slice(&out.tx);
    }
    let answers = String::from_utf8(answers).unwrap();
    assert!(answers.contains("X0 E8008"), "{answers}");
    assert_eq!(ErrorCode::FINDA_VS_EEPROM_DISREPANCY.0, 0x8008);
}

/// The printer's sensor stuck reporting filament, the filament out of the printer's gears: each
/// attempt feels it free and pulls it at most the check distance (then waits for a late sensor
/// and reports `8004`), and however often Retry is pressed, the pull stops where the tip leaves
/// the hub: the filament never leaves its drive gear. Register 0xfc says the filament was free.
#[test]
fn retry_after_a_stuck_printer_sensor_never_pulls_the_filament_out_of_its_drive() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.idle(1000);
    // The printer's sensor is stuck reporting filament.
    rig.fsensor = common::FsensorReports::Stuck(1);
    let unload = Request::new(RequestCode::Unload, 0);
    let check = f32::from(rig.app.config().unload_check_mm);
    // The printer's own retract first; then what the unit pulls: the feel's few millimetres,
    // the check distance, and the motor's run-down.
    rig.issue(unload);
    let most = check + 10.0;
    let mut tip = rig.model.tip_mm(0).unwrap();
    let mut run = rig.follow(unload, 60_000);
    for attempt in 0..12 {
        assert_eq!(
            run_error(&run),
            Some(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF),
            "attempt {attempt}"
        );
        assert_eq!(
            rig.read(UNLOAD_STUCK),
            Some(UnloadStuck::SensorStillOn as u16),
            "attempt {attempt}: the unit says the filament came back free"
        );
        let now = rig.model.tip_mm(0).unwrap();
        assert!(
            tip - now <= most,
            "attempt {attempt} pulled {} mm with the printer's sensor stuck on (check distance {check} mm)",
            tip - now
        );
        tip = now;
        rig.send(Request::new(RequestCode::Button, 1));
        run = rig.follow(unload, 60_000);
    }
    let drive_gear = rig.model.config().slot_sensor_mm;
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(
        tip > -5.0 && tip > drive_gear,
        "the pull stopped where the tip left the hub: {tip}"
    );
}

fn run_error(run: &common::Run) -> Option<ErrorCode> {
    run.last.param_value.map(ErrorCode)
}

#[test]
fn stale_lanes_never_reverse_the_slot_that_does_not_hold_the_path() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(1));
    // The store says slot 0 is loaded; slot 1 really is. The hub sensor agrees with either.
    rig.restart_with([Lane::Loaded, Lane::Parked, Lane::Parked]);
    let slot0 = rig.model.tip_mm(0).unwrap();
    rig.model.extruder_move(-100.0, 40.0);
    rig.idle(3_000);
    let run = rig.command(t(2));
    let pulled = slot0 - rig.model.tip_mm(0).unwrap();
    assert!(
        pulled < 1.0,
        "slot 0 was pulled back {pulled} mm on a stale belief"
    );
    assert_eq!(
        run.last.param_value,
        Some(ErrorCode::FINDA_VS_EEPROM_DISREPANCY.0),
        "UNLOAD MANUALLY: {:?}",
        run.last
    );
}

#[test]
fn a_right_but_unproven_belief_is_proven_by_the_printers_own_unload() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(1));
    // The printer loads to the nozzle and prints a while.
    rig.model.extruder_move(50.0, 20.0);
    rig.idle(4_000);
    rig.restart_with([Lane::Parked, Lane::Loaded, Lane::Parked]);
    // The printer pulls its filament out of the extruder before the tool change (ramming and a
    // long retract): slot 1's coasting motor turns with it, which proves the stored lane.
    rig.model.extruder_move(-100.0, 40.0);
    rig.idle(3_000);
    let run = rig.command(t(2));
    assert_eq!(run.last.param, ParamCode::Finished, "{:?}", run.last);
    assert_eq!(rig.model.loaded_slot(), Some(2));
}

#[test]
fn after_the_lanes_are_wiped_a_tip_resting_in_the_merge_does_not_block_another_slot() {
    let mut rig = Rig::<3>::new();
    // Slot 0's tip rests 5 mm before the hub sensor, inside the merge; the hub sensor does not see
    // it, and the unit's lanes were wiped (X42, or a store wiped after a flash error).
    rig.model.insert_filament(0, -5.0);
    rig.boot();
    assert_eq!(rig.app.lanes(), [Lane::Unknown; 3]);
    let run = rig.command(t(1));
    assert_eq!(run.last.param, ParamCode::Finished, "{:?}", run.last);
    assert_eq!(rig.model.loaded_slot(), Some(1));
    let merge = rig.model.config().merge_mm;
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(tip < merge, "slot 0 was pulled out of the merge: tip at {tip} mm");
    assert!(
        tip > rig.model.config().drive_gear_mm + 50.0,
        "and no further than needed: {tip} mm"
    );
}

#[test]
fn a_slipping_drive_that_parks_inside_the_merge_does_not_block_the_next_slot() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    // Slot 0's drive slips: its park, counted by its motor, leaves the tip in the merge.
    rig.inject(Fault::Slip { slot: 0, ratio: 0.4 });
    let mut run = rig.command(t(1));
    // The slipping unload runs out of distance (8002): the printer presses Retry, as it does up to
    // three times by itself.
    for _ in 0..3 {
        if run.last.param != ParamCode::Error {
            break;
        }
        rig.send(Request::new(RequestCode::Button, 1));
        run = rig.follow(t(1), 120_000);
    }
    assert_eq!(
        run.last.param,
        ParamCode::Finished,
        "{:?} {:?}, tips {:?} {:?}",
        run.progress,
        run.last,
        rig.model.tip_mm(0),
        rig.model.tip_mm(1)
    );
    assert_eq!(rig.model.loaded_slot(), Some(1));
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(
        tip < rig.model.config().merge_mm,
        "slot 0 rests out of the merge: {tip} mm"
    );
}
