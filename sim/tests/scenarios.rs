//! The firmware-in-the-loop scenarios (`mmu_sim::scenarios`) pass on the host-built logic: the
//! reference the firmware images are held to (`mmu fil`).

use mmu_sim::Sim;
use mmu_sim::scenarios::run_all;

#[test]
fn every_scenario_passes_on_the_host_logic() {
    let mut new_unit = |options| Sim::new(options).map_err(|e| e.to_string());
    let verdicts = run_all(&mut new_unit, None, &mut |_| {});
    let failed: Vec<_> = verdicts.iter().filter(|v| v.result.is_err()).collect();
    assert!(failed.is_empty(), "{failed:#?}");
    assert_eq!(verdicts.len(), mmu_sim::scenarios::SCENARIOS.len());
}
