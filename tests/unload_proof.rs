//! The unload that proves itself (issue 34): before it pulls, the unit feels, too weakly to move
//! a filament the extruder's gears grip, and watches the lane's motion and the tube's tension.
//! It waits while the printer moves the filament, pulls once nothing holds it whatever the
//! printer's sensor says, and reports `8004` only with the filament held and still. MMU 3.0.4
//! waits blind for the sensor for 4 s instead (`unload_to_finda.cpp`), and MMU 3.0.3 pulls at
//! once.

mod common;

use common::{Rig, assert_parked, error, finished, loaded, press, t};
use mmu_firmware::drive::FEEL_DUTY;
use mmu_firmware::phases::UnloadStuck;
use mmu_firmware::registers::UNLOAD_STUCK;
use mmu_model::{Fault, ModelConfig};
use mmu_protocol::{ButtonCode, ErrorCode, Request, RequestCode};

fn u0() -> Request {
    Request::new(RequestCode::Unload, 0)
}

/// The printer's extruder retracts `mm` at `speed` while the unit runs nothing else.
fn retract_alone(rig: &mut Rig<3>, mm: f32, speed: f32) {
    rig.model.extruder_move(-mm, speed);
    while rig.model.extruder_busy() {
        rig.printer_step(None);
    }
}

/// Slot 0 loaded on a printer wanting 3.0.`revision` (the rig's default geometry, the sensor
/// before the gears), then its retract alone leaves the tip `short_mm` short of the gears: free,
/// the printer's sensor still reading it.
fn tip_short_of_the_gears(revision: u8, short_mm: f32) -> Rig<3> {
    let mut rig = loaded(revision, ModelConfig::default());
    let gears = rig.model.config().extruder_gears_mm;
    let tip = rig.model.tip_mm(0).unwrap();
    retract_alone(&mut rig, tip - (gears - short_mm), 40.0);
    assert_ne!(
        rig.model.fsensor_state(),
        0,
        "the tip rests at the printer's sensor"
    );
    rig
}

/// A 3.0.3 printer (Buddy 6.4.1), its retract leaving the tip free between its sensor and its
/// gears, slot 0's drive slipping: the pull counts its check distance without moving the
/// filament, `8004`. The slip cleared, the printer's Retry help (1 mm here, the tip stays at its
/// sensor) and `B1`: the Retry feels the filament free and pulls it out (issue 34 finding 2: it
/// used to report `8004` again at once, forever, counting the slipped pull against the check).
#[test]
fn a_retry_of_8004_pulls_once_the_slip_is_gone() {
    let mut rig = tip_short_of_the_gears(3, 2.0);
    rig.inject(Fault::Slip { slot: 0, ratio: 0.0 });
    rig.issue(u0());
    let run = rig.follow(u0(), 60_000);
    assert_eq!(run.last, error(u0(), ErrorCode::FSENSOR_DIDNT_SWITCH_OFF));
    // The motor's Hall sensor counted the pull: free as far as the unit can tell.
    assert_eq!(rig.read(UNLOAD_STUCK), Some(UnloadStuck::SensorStillOn as u16));
    rig.model.clear_all();
    rig.model.extruder_move(-1.0, 20.0);
    press(&mut rig, ButtonCode::MIDDLE);
    let run = rig.follow(u0(), 60_000);
    assert_eq!(run.last, finished(u0()), "{run:?}");
    assert_parked(&rig, 0);
    assert_eq!(rig.read(UNLOAD_STUCK), Some(0), "nothing to say once resolved");
}

/// A 3.0.4 printer whose sensor sits before its gears (the MK3S's order, the rig's default
/// geometry): its retract takes the tip out of the gears, but the sensor still reads it. MMU
/// 3.0.4 reports `8004` after 4 s ("fsensor still on after 4 s"); this unit feels the filament
/// come back freely and unloads it, never harder than a feel while the gears held it.
#[test]
fn a_3_0_4_tip_left_between_the_sensor_and_the_gears_is_felt_free_and_unloaded() {
    let mut rig = tip_short_of_the_gears(4, 1.0);
    let run = rig.command(u0());
    assert_eq!(run.last, finished(u0()), "{run:?}");
    assert_parked(&rig, 0);
}

/// The filament stuck in the extruder (the tip in the nozzle, the printer's sensor on, nothing
/// retracts it), on either contract: the unit pulls no harder than a feel, and reports `8004`
/// once the filament has been still for 4 s, and says in register 0xfc that it is held in the
/// extruder; the tip moved no more than the tube's give.
#[test]
fn a_filament_stuck_in_the_extruder_is_only_felt_then_8004() {
    for revision in [3, 4] {
        let mut rig = loaded(revision, ModelConfig::default());
        let tip = rig.model.tip_mm(0).unwrap();
        let before = rig.motor_log.len();
        // Sent as is: the printer's own retract never came.
        assert!(rig.send(u0()).is_some());
        let run = rig.follow(u0(), 60_000);
        assert_eq!(
            run.last,
            error(u0(), ErrorCode::FSENSOR_DIDNT_SWITCH_OFF),
            "3.0.{revision}"
        );
        assert_eq!(
            rig.read(UNLOAD_STUCK),
            Some(UnloadStuck::InExtruder as u16),
            "3.0.{revision}: the unit says which"
        );
        let hardest = rig.hardest_pull_since(0, before);
        assert!(
            hardest <= FEEL_DUTY.permille(),
            "3.0.{revision}: pulled at {hardest} per mille against the gears"
        );
        let moved = tip - rig.model.tip_mm(0).unwrap();
        assert!(
            moved.abs() < 0.5,
            "3.0.{revision}: the gripped tip moved {moved} mm"
        );
    }
}

/// A 3.0.4 printer that retracts slowly (4 mm/s; its gears let the tip go 14 s after its `T`):
/// MMU 3.0.4 reports `8004` at 4 s with the filament still in the gears; this unit sees the
/// filament move, waits, and changes the tool, never harder than a feel while the gears held it.
#[test]
fn a_printer_that_retracts_slowly_is_waited_for() {
    let mut rig = loaded(4, ModelConfig::default());
    let gears = rig.model.config().extruder_gears_mm;
    let before = rig.motor_log.len();
    assert!(rig.send(t(1)).is_some());
    rig.model.extruder_move(-80.0, 4.0);
    let mut hardest_gripped = 0;
    while rig.model.tip_mm(0).unwrap() >= gears {
        let from = rig.motor_log.len();
        rig.printer_step(None);
        if rig.now.is_multiple_of(100) {
            let _ = rig.query();
        }
        hardest_gripped = hardest_gripped.max(rig.hardest_pull_since(0, from));
        assert!(rig.motor_log.len() - before < 30_000, "the gears never let go");
    }
    assert!(
        hardest_gripped <= FEEL_DUTY.permille(),
        "pulled at {hardest_gripped} per mille against the gears"
    );
    let run = rig.follow(t(1), 120_000);
    assert_eq!(run.last, finished(t(1)), "{run:?}");
    assert_eq!(rig.model.loaded_slot(), Some(1));
}
