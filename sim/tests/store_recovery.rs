//! A store that cannot be stuck: a torn page erase brings back no old state and never makes the
//! save loop erase in circles; `X42` and a damaged store keep the unit's identity (register 0x52,
//! the version an MK3S checks); the erase rate stays bounded whatever the flash does.

use mmu_sim::cut::{Plan, study};
use mmu_sim::flash::CutModel;

/// The study's finding, seed 4: a torn erase during `X42` on 4 pages made every later save fail,
/// and the save loop erased a page at every 1 ms step (1000 erases in a second). Other seeds
/// brought stale lanes and settings back. Every torn erase of 4 lives.
#[test]
fn a_torn_page_erase_brings_back_no_old_state_and_never_sticks_the_store() {
    let (mut cuts, mut failures) = (0, Vec::new());
    for seed in 1..=4 {
        let plan = Plan {
            pages: 4,
            length: 800,
            stride: 1,
            erases_only: true,
            models: vec![CutModel::Torn, CutModel::TornUnreadable],
        };
        let report = study(seed, &plan);
        cuts += report.cuts.iter().sum::<usize>();
        failures.extend(report.failures);
    }
    assert!(cuts >= 30, "{cuts} erases cut");
    assert!(
        failures.is_empty(),
        "{} failures of {cuts} cuts:\n{}",
        failures.len(),
        failures.join("\n")
    );
}
