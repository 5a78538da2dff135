//! Each lane's health (`src/lanes`): drag, slip, load time, the distance from the hub sensor to
//! the printer's sensor (warned when it drifts), stalls and the success rate of tool changes
//! with its denominator, read through the registers as the printer's `M707` does, and kept
//! across a restart.

mod common;

use common::{Rig, t};
use mmu_firmware::registers::{
    DRAG, LANE_WARNINGS, LOAD_DISTANCE, LOAD_TIME, SLIP, STALLS, SUCCESS, SUCCESS_OF,
};
use mmu_firmware::{App, Config};
use mmu_model::Fault;
use mmu_protocol::ErrorCode;

/// The model's Bowden tube, from the hub sensor to the printer's sensor, mm.
const BOWDEN_MM: u16 = 360;

fn changes(rig: &mut Rig<3>, rounds: usize) {
    for _ in 0..rounds {
        rig.tool_change_loads(1);
        rig.tool_change_loads(2);
    }
}

#[test]
fn tool_changes_give_each_lane_its_figures() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    changes(&mut rig, 3);
    for slot in [1, 2] {
        let distance = rig.read(LOAD_DISTANCE + slot).unwrap();
        assert!(distance.abs_diff(BOWDEN_MM) <= 15, "slot {slot}: {distance} mm");
        let load_ds = rig.read(LOAD_TIME + slot).unwrap();
        assert!((10..=600).contains(&load_ds), "slot {slot}: {load_ds} ds");
        let drag = rig.read(DRAG + slot).unwrap();
        assert!((50..=200).contains(&drag), "slot {slot}: drag {drag} %");
        let slip = rig.read(SLIP + slot).unwrap() as i16;
        assert!(slip.abs() <= 100, "slot {slot}: slip {slip} ‰");
        assert_eq!(rig.read(STALLS + slot), Some(0));
        assert_eq!(rig.read(SUCCESS + slot), Some(100));
        assert_eq!(rig.read(SUCCESS_OF + slot), Some(3));
    }
    // A change to the slot already loaded finishes at once: it measures nothing.
    let load_ds = rig.read(LOAD_TIME + 2);
    rig.tool_change_loads(2);
    assert_eq!(rig.read(SUCCESS_OF + 2), Some(3));
    assert_eq!(rig.read(LOAD_TIME + 2), load_ds);
    rig.tool_change_loads(1);
    assert_eq!(rig.read(SUCCESS + 2), Some(100), "nor counts as a failure");
    assert_eq!(rig.read(SUCCESS_OF + 2), Some(3));
    // Slot 0 never loaded: no figures yet.
    assert_eq!(rig.read(SUCCESS_OF), Some(0));
    assert_eq!(rig.read(LOAD_DISTANCE), Some(0));
    assert_eq!(rig.read(LANE_WARNINGS), Some(0));
}

#[test]
fn a_drive_gear_that_slips_makes_the_load_distance_drift_and_is_warned() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    changes(&mut rig, 2);
    let before = rig.read(LOAD_DISTANCE + 1).unwrap();
    rig.inject(Fault::Slip { slot: 1, ratio: 0.85 });
    rig.tool_change_loads(1);
    assert_eq!(rig.read(LANE_WARNINGS), Some(1 << 1), "slot 1 drifted");
    assert!(rig.read(LOAD_DISTANCE + 1).unwrap() > before);
    // Fixed: the next loads agree with the figure again and the warning goes.
    rig.model.clear_all();
    rig.tool_change_loads(2);
    for _ in 0..6 {
        rig.tool_change_loads(1);
        rig.tool_change_loads(2);
    }
    assert_eq!(rig.read(LANE_WARNINGS), Some(0));
}

#[test]
fn a_stall_is_counted_and_the_change_it_stopped_needed_help() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    changes(&mut rig, 1);
    rig.tool_change_loads(0);
    rig.inject(Fault::MotorDead { slot: 1 });
    rig.command_fails_with(t(1), ErrorCode::STALLED_PULLEY);
    assert_eq!(rig.read(STALLS + 1), Some(1));
    rig.model.clear_all();
    rig.idle(1000);
    rig.retry_finishes(t(1));
    assert_eq!(rig.read(SUCCESS + 1), Some(50));
    assert_eq!(rig.read(SUCCESS_OF + 1), Some(2));
    // Kept across a restart.
    let kept = rig.app.snapshot();
    rig.app = App::new(Config::default());
    rig.app.restore(&kept);
    rig.boot();
    assert_eq!(rig.read(STALLS + 1), Some(1));
    assert_eq!(rig.read(SUCCESS + 1), Some(50));
    assert_eq!(rig.read(SUCCESS_OF + 1), Some(2));
    assert!(rig.read(LOAD_DISTANCE + 1).unwrap() > 0);
}
