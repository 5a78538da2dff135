//! Filament left on each spool (`src/lanes`): what the extruder pulls off while printing is
//! counted as well as the unit's own moves, against a spool length set per slot (a 1 kg spool of
//! PLA by default), counted again from the full spool when a filament is inserted into an
//! empty slot, and kept across a restart. Read through the registers, as the printer's `M707`
//! does. Across a real power cut in the simulator: `sim/tests/lanes.rs`.

mod common;

use common::{Rig, finished};
use mmu_firmware::registers::{LANE_WARNINGS, LEFT, SPOOL};
use mmu_firmware::{App, Config};
use mmu_protocol::{Request, RequestCode};

/// A 1 kg spool of 1.75 mm PLA, m.
const DEFAULT_SPOOL_M: u16 = 330;

#[test]
fn every_slot_starts_with_a_full_default_spool() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    for slot in 0..3 {
        assert_eq!(rig.read(SPOOL + slot), Some(DEFAULT_SPOOL_M), "slot {slot}");
        assert_eq!(rig.read(LEFT + slot), Some(DEFAULT_SPOOL_M), "slot {slot}");
    }
    assert_eq!(rig.read(LANE_WARNINGS), Some(0));
    // A 3-slot unit has no slot 3.
    assert_eq!(rig.read(LEFT + 3), None);
}

#[test]
fn printing_counts_what_the_extruder_pulls_off_the_spool() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let tail = rig.model.tail_mm(0).unwrap();
    rig.tool_change_loads(0);
    // 3.6 m at 12 mm/s: the motor coasts or follows, the printer pulls.
    rig.model.set_printing(Some(12.0));
    rig.idle(300_000);
    rig.model.set_printing(None);
    rig.idle(1000);
    let pulled_mm = rig.model.tail_mm(0).unwrap() - tail;
    assert!(pulled_mm > 3500.0, "{pulled_mm}");
    let truth_m = (f32::from(DEFAULT_SPOOL_M) * 1000.0 - pulled_mm) / 1000.0;
    let left = f32::from(rig.read(LEFT).unwrap());
    // To the nearest metre.
    assert!((left - truth_m).abs() <= 0.5, "left {left} m, truth {truth_m} m");
}

#[test]
fn the_spool_length_is_set_per_slot_and_a_new_filament_starts_it_again() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.write(SPOOL + 1, 100);
    assert_eq!(rig.read(LEFT + 1), Some(100));
    assert_eq!(rig.read(LEFT), Some(DEFAULT_SPOOL_M), "slot 0 keeps its own");
    // A spool already in use: the user says what is left.
    rig.write(LEFT + 1, 40);
    assert_eq!(rig.read(LEFT + 1), Some(40));
    // Out of range: refused.
    assert_eq!(
        rig.send(Request::write(SPOOL + 1, 0)).map(|a| a.param),
        Some(mmu_protocol::ParamCode::Rejected)
    );
    // The filament runs out while the unit is off; it restarts with the slot empty.
    rig.model.remove_filament(1);
    let kept = rig.app.snapshot();
    rig.app = App::new(Config::default());
    rig.app.restore(&kept);
    rig.boot();
    assert_eq!(rig.read(SPOOL + 1), Some(100), "the spool length is a setting");
    let left = rig.read(LEFT + 1).unwrap();
    assert!((39..=40).contains(&left), "{left}");
    // A new spool: inserted, preloaded to the park position.
    rig.model.insert_filament(1, -90.0);
    rig.idle(100);
    let load = Request::new(RequestCode::Load, 1);
    assert_eq!(rig.command(load).last, finished(load));
    assert_eq!(rig.read(LEFT + 1), Some(100));
}

#[test]
fn filament_left_and_the_spool_length_survive_a_restart() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.write(SPOOL + 2, 250);
    rig.write(LEFT + 2, 120);
    let kept = rig.app.snapshot();
    rig.app = App::new(Config::default());
    rig.app.restore(&kept);
    rig.boot();
    assert_eq!(rig.read(SPOOL + 2), Some(250));
    // Kept in whole metres, restored to the middle of the metre.
    let left = rig.read(LEFT + 2).unwrap();
    assert!((119..=120).contains(&left), "{left}");
}

#[test]
fn a_slot_with_little_left_is_warned() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.write(LEFT + 2, 5);
    assert_eq!(rig.read(LANE_WARNINGS), Some(1 << (8 + 2)));
}
