//! The unload fault table's claims, on a few seeds (the book's table runs 200:
//! `cargo run --release -p mmu-sim --example unload_faults -- 200`).

use mmu_firmware::drive::FEEL_DUTY;
use mmu_sim::Personality;
use mmu_sim::unload_faults::{TrialSetup, UnloadFault, play};

fn setup(strict: bool) -> TrialSetup {
    TrialSetup {
        printer: Personality::Buddy65,
        extruder: None,
        strict,
    }
}

/// A printer sensor that clears late: MMU 3.0.4's blind 4 s wait reports `8004` where the delay
/// outlasts it; this unit, which feels the filament come back, reports nothing and strands nothing.
#[test]
fn a_late_sensor_costs_3_0_4_an_error_and_this_unit_none() {
    let strict = play(UnloadFault::LateSensor, setup(true), 0..4);
    let feel = play(UnloadFault::LateSensor, setup(false), 0..4);
    assert!(strict.errors > 0, "{strict:?}");
    assert_eq!((feel.errors, feel.stranded), (0, 0), "{feel:?}");
}

/// A stringy tip the gears keep gripping: the strict unload pulls at full duty against them; this
/// unit never pulls harder than a feel, and strands nothing.
#[test]
fn a_stringy_tip_is_never_pulled_harder_than_a_feel() {
    let strict = play(UnloadFault::StringyTip, setup(true), 0..2);
    let feel = play(UnloadFault::StringyTip, setup(false), 0..2);
    assert!(strict.hardest_pull_permille > FEEL_DUTY.permille(), "{strict:?}");
    assert!(feel.hardest_pull_permille <= FEEL_DUTY.permille(), "{feel:?}");
    assert_eq!(feel.stranded, 0, "{feel:?}");
}

/// A printer that retracts slowly: its finishing retract still turns its gears back when the new
/// filament reaches them (seeds 13 and 18 ended `8003` before the unit held the tip there until
/// the printer's co-feed turned them forward).
#[test]
fn a_new_filament_that_meets_gears_still_retracting_waits_for_them() {
    for seed in [13, 18] {
        let feel = play(UnloadFault::SlowRetract, setup(false), seed..seed + 1);
        assert_eq!((feel.errors, feel.stranded), (0, 0), "seed {seed}: {feel:?}");
    }
}

/// The printer's sensor before its gears (an MK3.5 on Buddy 6.5.3): no retract can clear it, so
/// MMU 3.0.4's blind wait reports `8004` on every change; this unit feels the filament free.
#[test]
fn a_sensor_before_the_gears_costs_3_0_4_an_error_every_change_and_this_unit_none() {
    let strict = play(UnloadFault::SensorFirst, setup(true), 0..2);
    let feel = play(UnloadFault::SensorFirst, setup(false), 0..2);
    assert_eq!(strict.errors, strict.trials, "{strict:?}");
    assert_eq!((feel.errors, feel.stranded), (0, 0), "{feel:?}");
}
