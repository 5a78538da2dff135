//! After a restart the unit either proves which slot holds the hub path before it moves it, or
//! refuses (`8008`) and moves nothing: whatever the stored lanes say (right, stale, wiped or
//! impossible) and wherever the filaments really are. Every case: stored lanes x the slot that
//! really holds the path, then the printer's next tool change.

mod common;

use common::{Rig, t};
use mmu_firmware::persist::Snapshot;
use mmu_firmware::unit::Lane;
use mmu_firmware::{App, Config};
use mmu_protocol::ParamCode;

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
        rig.app = App::new(Config::default());
        rig.app.restore(&Snapshot {
            lanes,
            ..Snapshot::default()
        });
        rig.boot();
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
