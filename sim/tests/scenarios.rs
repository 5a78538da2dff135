//! The firmware-in-the-loop scenarios (`mmu_sim::scenarios`) pass on the host-built logic: the
//! reference the firmware images are held to (`mmu fil`).

use mmu_firmware::profile::{self, Profile};
use mmu_sim::scenarios::run_all;
use mmu_sim::{Sim, SimOptions};

fn every_scenario_passes_on(hardware: &'static Profile) {
    every_scenario_passes_on_lanes(hardware, None);
}

/// As the scenarios run on `hardware` with `slots` lanes (the scenario's own count when None):
/// `mmu fil` gives a unit all the lanes of its image.
fn every_scenario_passes_on_lanes(hardware: &'static Profile, slots: Option<usize>) {
    let mut new_unit = |options: SimOptions| {
        let slots = slots.unwrap_or(options.slots);
        Sim::new(SimOptions { slots, ..options }.on_hardware(hardware)).map_err(|e| e.to_string())
    };
    let verdicts = run_all(&mut new_unit, None, &mut |_| {});
    let failed: Vec<_> = verdicts.iter().filter(|v| v.result.is_err()).collect();
    assert!(failed.is_empty(), "{}: {failed:#?}", hardware.name);
    assert_eq!(verdicts.len(), mmu_sim::scenarios::SCENARIOS.len());
}

#[test]
fn every_scenario_passes_on_the_host_logic() {
    every_scenario_passes_on(&profile::THESIS);
}

#[test]
fn every_scenario_passes_on_lanes_of_n20_encoder_motors() {
    every_scenario_passes_on(&profile::N20_QUADRATURE);
}

#[test]
fn every_scenario_passes_on_the_bmcu_c_without_a_hub_sensor() {
    every_scenario_passes_on(&profile::BMCU_C);
}

/// The BMCU-C image has four lanes: `mmu fil --board bmcu` runs every scenario on all four.
#[test]
fn every_scenario_passes_on_the_bmcu_c_with_its_four_lanes() {
    every_scenario_passes_on_lanes(&profile::BMCU_C, Some(4));
}

/// Lanes of N20 motors with one encoder channel wired: pulses that cannot tell the direction,
/// counted the way the motor was last driven.
static N20_ONE_CHANNEL: Profile = Profile {
    name: "n20-one-channel",
    motion: profile::MotionSensor::Pulses {
        counts_per_rev: 2 * 7 * 100,
    },
    ..profile::N20_QUADRATURE
};

#[test]
fn every_scenario_passes_on_lanes_counting_one_encoder_channel() {
    every_scenario_passes_on(&N20_ONE_CHANNEL);
}
