//! Crash consistency of the persisted state on a flash that behaves like the STM32G0's: random
//! lives of the unit (lanes, counters, settings written by the printer, `X0`, `X42`, power
//! losses, the region wrapping and filling), driven through the App and the firmware's save
//! policy (`persist::Keeper`), cut at every double-word program and every page erase under every
//! cut model (`mmu_sim::cut`). After each cut every record is the old or the new one, saving goes
//! on, the save loop does not erase in circles and `X42` works.
//!
//! More seeds (release build, about a second per seed and model set):
//! `MMU_CUT_SEEDS=100 cargo test -p mmu-sim --release --test power_cut -- --ignored --nocapture`.

use mmu_firmware::Instant;
use mmu_sim::cut::{Action, CutReport, Flash, Plan, Unit, life, study};
use mmu_sim::flash::CutModel;

fn check(reports: &[CutReport]) {
    let failures: Vec<&String> = reports.iter().flat_map(|r| &r.failures).collect();
    let cuts = reports
        .iter()
        .fold([0; 3], |total, r| core::array::from_fn(|m| total[m] + r.cuts[m]));
    assert!(
        failures.is_empty(),
        "{} failures of {cuts:?} cuts (clean, torn, torn with unreadable), first:\n{}",
        failures.len(),
        failures
            .iter()
            .take(8)
            .map(|f| f.as_str())
            .collect::<Vec<_>>()
            .join("\n")
    );
}

/// A life of 600 actions on 3 pages: the region has wrapped twice when the cuts start (action
/// 450); from there every operation is cut under every model.
fn plan() -> Plan {
    Plan {
        first_cut_action: 450,
        ..Plan::every_cut(3, 600)
    }
}

#[test]
fn every_cut_of_a_random_life_leaves_old_or_new_records_and_a_working_store() {
    let reports: Vec<CutReport> = (1..=2).map(|seed| study(seed, &plan())).collect();
    for (seed, report) in (1..).zip(&reports) {
        assert!(report.erases_cut >= 1, "seed {seed}: page erases are cut too");
        assert!(report.cuts[0] >= 400, "seed {seed}: {:?} cuts", report.cuts);
    }
    check(&reports);
}

/// A cut during the recovery from a cut: after each cut (every operation of the last 40 actions
/// of a life, torn with unreadable double words), the first save after the restart (a fresh
/// page opened when the head was torn) is cut again at each of its operations.
#[test]
fn a_cut_during_the_first_save_after_a_cut_leaves_old_or_new_records_too() {
    let plan = Plan {
        first_cut_action: 560,
        second_cuts: 24,
        models: vec![CutModel::TornUnreadable],
        ..Plan::every_cut(3, 600)
    };
    let report = study(3, &plan);
    assert!(report.second_cuts >= 500, "{} second cuts", report.second_cuts);
    check(&[report]);
}

/// A save runs a bounded piece per 1 ms step: the power may also go between two steps of a save
/// in progress (an entry half programmed, a fresh page checked or copied but not committed). A
/// life of 400 actions on 3 pages, the flash looked at between every two steps of every save:
/// each record restores as it was before the action or as the action left it; no step programs
/// more than 2 double words or erases more than one page.
#[test]
fn the_power_going_between_two_steps_of_a_save_leaves_old_or_new_records() {
    const PAGES: usize = 3;
    let mut unit = Unit::boot(Flash::new(PAGES), PAGES, Instant::ZERO);
    let (mut observed, mut failures) = (0, Vec::new());
    for (index, (wait, action)) in life(5, 400).iter().enumerate() {
        let before = unit.stored();
        let after = unit.clone().act(*wait, action).stored();
        let mut between = |unit: &mut Unit| {
            observed += 1;
            let restored = unit.stored();
            let lanes = [&before.lanes, &after.lanes].contains(&&restored.lanes);
            let counters = [&before.counters, &after.counters].contains(&&restored.counters);
            let settings = [&before.settings, &after.settings].contains(&&restored.settings);
            if !(lanes && counters && settings) {
                failures.push(format!(
                    "action {index} {action:?}: restored {restored:?}, expected {before:?} or {after:?}"
                ));
            }
        };
        unit = unit.act_with(*wait, action, &mut between);
        assert!(!matches!(action, Action::PowerCycle) || !unit.keeper.is_saving());
    }
    let worst = unit.worst_save;
    assert!(
        failures.is_empty(),
        "{} failures, first: {}",
        failures.len(),
        failures[0]
    );
    assert!(observed >= 300, "{observed} steps between");
    // A fresh page's erased check alone takes 16 steps (128 bytes each): some saves opened one.
    assert!(
        worst.steps >= 12,
        "a fresh page was opened over many steps: {worst:?}"
    );
    assert!(worst.programs_per_step <= 2, "{worst:?}");
    assert!(worst.erases_per_step <= 1, "{worst:?}");
}

/// The soak: `MMU_CUT_SEEDS` lives (default 20) of 700 actions on 3 pages, every operation cut
/// under every model, and with `MMU_CUT_SECOND=24` each first save after a restart cut again at
/// each of its first 24 operations; prints the counts the README quotes.
#[test]
#[ignore = "minutes in a debug build: run with --release"]
fn soak_every_cut_of_many_lives() {
    let seeds: u64 = std::env::var("MMU_CUT_SEEDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20);
    let second_cuts: u64 = std::env::var("MMU_CUT_SECOND")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let plan = Plan {
        second_cuts,
        ..Plan::every_cut(3, 700)
    };
    let reports: Vec<CutReport> = (1..=seeds).map(|seed| study(seed, &plan)).collect();
    let total = |f: fn(&CutReport) -> usize| reports.iter().map(f).sum::<usize>();
    let worst = |f: fn(&CutReport) -> u64| reports.iter().map(f).max().unwrap_or(0);
    println!(
        "cut soak: {seeds} lives of 700 actions, {} flash operations ({} page erases); cuts: clean {}, torn {}, torn with unreadable double words {}; second cuts {}; failures {}; the largest save: {} double-word programs, {} page erases, {} steps; the most in one step: {} double-word programs, {} page erases",
        total(|r| r.operations as usize),
        total(|r| r.erases_cut),
        total(|r| r.cuts[0]),
        total(|r| r.cuts[1]),
        total(|r| r.cuts[2]),
        total(|r| r.second_cuts),
        total(|r| r.failures.len()),
        worst(|r| r.worst_save.programs),
        worst(|r| r.worst_save.erases),
        worst(|r| r.worst_save.steps),
        worst(|r| r.worst_save.programs_per_step),
        worst(|r| r.worst_save.erases_per_step),
    );
    check(&reports);
}
