//! Crash consistency of the persisted state on a flash that behaves like the STM32G0's: random
//! lives of the unit (lanes, counters, settings, `X0`, `X42`, power losses, the region wrapping),
//! driven through the App and the firmware's save policy, cut at every double-word program and
//! every page erase under every cut model (`mmu_sim::cut`). More seeds: `cargo test -p mmu-sim
//! --release --test power_cut -- --ignored`.

use mmu_sim::cut::{CutReport, Plan, study};

fn check(report: &CutReport) {
    assert!(
        report.failures.is_empty(),
        "{} failures of {:?} cuts, first:\n{}",
        report.failures.len(),
        report.cuts,
        report
            .failures
            .iter()
            .take(8)
            .cloned()
            .collect::<Vec<_>>()
            .join("\n")
    );
}

#[test]
fn every_cut_of_a_random_life_leaves_old_or_new_records_and_a_working_store() {
    for seed in 1..=2 {
        let report = study(seed, &Plan::every_cut(3, 150));
        assert!(
            report.erases >= 3,
            "seed {seed}: the life wraps the region ({} erases)",
            report.erases
        );
        check(&report);
    }
}
