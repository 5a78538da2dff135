//! Soak runs end to end: fault-free tool changes close to the physical minimum, random faults
//! counted consistently, and the summary line in its exact format.
//!
//! `soak_from_environment` is a developer's tool, ignored by default, that fails when the soak
//! does not pass: in release,
//! `SOAK_CHANGES=300 SOAK_SEED=7 cargo test --release -p mmu-sim --test soak -- --ignored --nocapture`
//! runs a random-fault soak and prints its report and notes (`SOAK_PRINTER=buddy-6.5` plays
//! another printer; `SOAK_POWER_LOSSES=1 SOAK_FAULTS=0` cuts the power once in every change).

use mmu_sim::soak::{self, SoakOptions, SoakReport};
use mmu_sim::{Personality, PrinterOptions, SimOptions};

fn options(changes: u32, random_faults: bool, seed: u64) -> SoakOptions {
    SoakOptions {
        personality: Personality::default(),
        changes,
        random_faults,
        spool_ends: false,
        power_losses: false,
        seed,
        sim: SimOptions::default(),
        printer: PrinterOptions {
            // A stuck change costs this much virtual time; debug builds run ~100x real time.
            command_timeout_ms: 120_000,
            ..PrinterOptions::default()
        },
    }
}

#[test]
fn fault_free_changes_all_finish_near_the_physical_minimum() {
    let mut seen = Vec::new();
    let report = soak::run(&options(6, false, 3), &mut |done| seen.push(done));
    assert_eq!(seen, [1, 2, 3, 4, 5, 6]);
    assert!(report.passed(), "{report}\n{:#?}", report.notes);
    assert_eq!(
        (report.changes, report.faults_injected, report.recovered),
        (6, 0, 0)
    );
    assert_eq!(report.rig_restarts, 0);
    let times = report.tool_change_times;
    assert_eq!(times.changes, 6, "{report}");
    let ratio = times.ratio_to_minimum().expect("timed changes");
    // The logic accelerates, filters its sensors and hands phases over: a little above the
    // physical minimum, never below it.
    assert!((1.0..1.10).contains(&ratio), "{report}");
    assert!(times.max_s >= times.mean_s);
    assert!(
        report.simulated_s >= 6.0 * times.physical_minimum_mean_s,
        "{report}"
    );
    assert!(report.wall_s > 0.0 && report.speed() > 0.0);
}

#[test]
fn random_fault_soak_runs_to_its_end_and_its_counters_add_up() {
    let report = soak::run(&options(8, true, 11), &mut |_| {});
    assert_eq!(report.changes, 8, "{report}");
    assert!(report.aborted.is_none(), "{report}");
    assert!(
        report.faults_injected >= 1,
        "seed 11 strikes at least once:\n{report}"
    );
    assert!(report.recovered <= report.faults_injected, "{report}");
    assert!(report.failed_without_fault <= report.unrecovered, "{report}");
    assert!(
        report.recovered + report.unrecovered - report.failed_without_fault <= report.faults_injected,
        "{report}"
    );
    assert!(
        report.recovered + report.unrecovered + report.stuck + report.panics <= report.changes,
        "{report}"
    );
    let sum = |field: fn(&soak::FaultKindTally) -> u32| report.by_fault_kind.iter().map(field).sum::<u32>();
    assert_eq!(sum(|t| t.injected), report.faults_injected);
    assert_eq!(sum(|t| t.recovered), report.recovered);
    assert_eq!(
        sum(|t| t.unrecovered),
        report.unrecovered - report.failed_without_fault
    );
    assert!(sum(|t| t.stuck) <= report.stuck && sum(|t| t.panics) <= report.panics);
    let failures = report.unrecovered + report.stuck + report.panics;
    assert_eq!(
        report.notes.len() as u32,
        failures,
        "one note per failure: {:#?}",
        report.notes
    );
    assert!(report.rig_restarts <= failures);
    assert_eq!(report.fault_log.len() as u32, report.faults_injected);
    // The same seed gives the same run.
    let again = soak::run(&options(8, true, 11), &mut |_| {});
    assert_eq!(again.summary_line(), report.summary_line());
    assert_eq!(again.notes, report.notes);
}

#[test]
fn the_summary_line_has_its_exact_format_and_comes_first() {
    let report = SoakReport {
        changes: 300,
        faults_injected: 91,
        recovered: 80,
        unrecovered: 7,
        stuck: 3,
        panics: 1,
        ..SoakReport::default()
    };
    let expected =
        "soak: 300 tool changes, 91 faults injected, 80 recovered, 7 unrecovered, 3 stuck, 1 panics";
    assert_eq!(report.summary_line(), expected);
    let text = report.to_string();
    assert_eq!(text.lines().next(), Some(expected));
    assert!(
        text.lines()
            .nth(1)
            .is_some_and(|line| line.starts_with("tool change: ")),
        "{text}"
    );
    assert!(
        text.lines()
            .nth(2)
            .is_some_and(|line| line.starts_with("simulated ")),
        "{text}"
    );
    assert!(!report.passed());
    assert!(SoakReport::default().passed());
}

#[test]
fn options_the_simulator_refuses_abort_the_run_without_a_panic() {
    let mut bad = options(3, false, 1);
    bad.sim.slots = 0;
    let report = soak::run(&bad, &mut |_| {});
    assert_eq!((report.changes, report.panics), (0, 0));
    assert!(report.aborted.is_some() && !report.passed(), "{report}");
}

#[test]
fn a_change_that_does_not_end_in_time_is_stuck_and_the_rig_is_rebuilt() {
    let mut hasty = options(3, false, 5);
    hasty.printer.command_timeout_ms = 3000;
    let report = soak::run(&hasty, &mut |_| {});
    assert_eq!(
        (report.changes, report.stuck, report.unrecovered),
        (3, 3, 0),
        "{report}"
    );
    assert_eq!(report.rig_restarts, 2, "{report}");
    assert_eq!(report.notes.len(), 3);
    assert!(
        report.notes.iter().all(|note| note.contains("-> stuck: T")),
        "{:#?}",
        report.notes
    );
    assert!(report.aborted.is_none() && !report.passed());
    assert_eq!(report.tool_change_times.changes, 0);
    assert!(report.to_string().contains("rig restarted 2 times"), "{report}");
}

#[test]
fn a_single_slot_unit_unloads_before_each_change() {
    let mut single = options(3, false, 2);
    single.sim.slots = 1;
    let report = soak::run(&single, &mut |_| {});
    assert!(report.passed(), "{report}\n{:#?}", report.notes);
    assert_eq!(report.tool_change_times.changes, 3, "{report}");
}

/// A soak playing `personality`, its protocol and its mechanics, wanting its own version.
fn soak_of(
    personality: Personality,
    changes: u32,
    random_faults: bool,
    seed: u64,
    slots: usize,
) -> SoakReport {
    let mut options = options(changes, random_faults, seed);
    options.personality = personality;
    options.printer.version = personality.version();
    options.sim.slots = slots;
    soak::run(&options, &mut |_| {})
}

/// Each printer's fault-free changes against its floor: never below it, within the 1.2x the
/// bench holds them to; only Buddy 6.5.3, which sends `T` before its ramming and retract, adds
/// to the physical minimum.
#[test]
fn every_printer_changes_tools_within_1_2_times_its_floor() {
    for personality in Personality::ALL {
        let report = soak_of(personality, 4, false, 3, 3);
        assert!(report.passed(), "{personality}:\n{report}\n{:#?}", report.notes);
        let times = report.tool_change_times;
        assert_eq!(times.changes, 4, "{personality}:\n{report}");
        let ratio = times.ratio_to_floor().expect("timed changes");
        assert!((1.0..1.2).contains(&ratio), "{personality}:\n{report}");
        if personality.sends_tool_before_retract() {
            // The retract while the gears hold the tip (about a second in each change that
            // unloads; the first, from nothing loaded, has none).
            assert!(
                times.floor_mean_s > times.physical_minimum_mean_s + 0.25,
                "{personality}:\n{report}"
            );
        } else {
            assert_eq!(times.floor_mean_s, times.physical_minimum_mean_s, "{personality}");
        }
    }
}

#[test]
fn buddy_6_4_and_the_mk3s_soak_clean_with_1_3_and_5_slots() {
    for personality in [Personality::Buddy64, Personality::Mk3s] {
        for slots in [1, 3, 5] {
            let report = soak_of(personality, 6, true, 7, slots);
            assert!(
                report.passed(),
                "{personality}, {slots} slots:\n{report}\n{:#?}",
                report.notes
            );
        }
    }
}

#[test]
fn buddy_6_5_soaks_clean_with_1_3_and_5_slots() {
    for slots in [1, 3, 5] {
        let report = soak_of(Personality::Buddy65, 6, true, 7, slots);
        assert!(report.passed(), "{slots} slots:\n{report}\n{:#?}", report.notes);
    }
}

/// Every hardware profile soaks clean with random faults on every printer family, with one
/// slot, three and the most it has: the thesis build, lanes of N20 encoder motors, the BMCU-C
/// (no hub sensor). The full matrix (ten seeds, 100 changes each) is `scripts/soak-matrix.sh`.
#[test]
fn every_hardware_profile_soaks_clean_on_every_printer() {
    for hardware in mmu_firmware::profile::ALL {
        for personality in Personality::ALL {
            for slots in [1, 3, hardware.max_slots] {
                let mut options = options(6, true, 7);
                options.personality = personality;
                options.printer.version = personality.version();
                options.sim = SimOptions {
                    slots,
                    ..options.sim.on_hardware(hardware)
                };
                let report = soak::run(&options, &mut |_| {});
                assert!(
                    report.passed(),
                    "{} on {personality}, {slots} slots:\n{report}\n{:#?}",
                    hardware.name,
                    report.notes
                );
            }
        }
    }
}

/// A power loss at a random moment of every change, on every printer family: after the printer's
/// recovery (`U0`, then the same `T`) each change completes, and none asks for UNLOAD MANUALLY
/// (`8008`): the unit proves its stored slot and carries on. The figures, by phase, in the report.
#[test]
fn a_power_loss_in_every_tool_change_ends_with_the_change_completed() {
    for personality in Personality::ALL {
        let mut options = options(16, false, 5);
        options.power_losses = true;
        options.personality = personality;
        options.printer.version = personality.version();
        let report = soak::run(&options, &mut |_| {});
        let restarts = &report.restarts;
        assert!(report.passed(), "{personality}:\n{report}\n{:#?}", report.notes);
        assert!(restarts.struck() >= 8, "{personality}:\n{report}");
        assert_eq!(
            restarts.unload_manually(),
            0,
            "{personality}:\n{report}\n{:#?}",
            report.fault_log
        );
        assert_eq!(
            restarts.completed(),
            restarts.struck(),
            "{personality}:\n{report}"
        );
    }
}

#[test]
#[ignore = "a developer's tool: long in debug builds, run it in release"]
fn soak_from_environment() {
    let number = |name: &str, default: u64| {
        std::env::var(name)
            .ok()
            .and_then(|text| text.parse().ok())
            .unwrap_or(default)
    };
    let mut options = options(
        number("SOAK_CHANGES", 100) as u32,
        number("SOAK_FAULTS", 1) != 0,
        number("SOAK_SEED", 1),
    );
    options.printer.command_timeout_ms = number("SOAK_TIMEOUT_MS", 600_000);
    options.spool_ends = number("SOAK_SPOOL_ENDS", 0) != 0;
    options.printer.spool_join = number("SOAK_SPOOL_JOIN", 0) != 0;
    options.power_losses = number("SOAK_POWER_LOSSES", 0) != 0;
    options.sim.slots = number("SOAK_SLOTS", 3) as usize;
    if let Ok(name) = std::env::var("SOAK_PRINTER") {
        options.personality = name.parse().expect("SOAK_PRINTER names a printer");
        options.printer.version = options.personality.version();
    }
    let report = soak::run(&options, &mut |_| {});
    println!("seed {}:\n{report}", options.seed);
    println!("notes (unrecovered, stuck, panicked):");
    for note in &report.notes {
        println!("  {note}");
    }
    if number("SOAK_FAULT_LOG", 0) != 0 {
        println!("fault log:");
        for line in &report.fault_log {
            println!("  {line}");
        }
    }
    assert!(report.passed(), "seed {}: {report}", options.seed);
}

#[test]
fn a_spool_end_soak_hands_every_fastened_end_to_the_printer_and_no_tangle() {
    // Seed 1, 40 changes: fastened ends (on spools counted 1 m from empty) and tangles (on spools
    // with plenty left) among the print faults, on each printer family.
    for personality in Personality::ALL {
        let mut options = options(40, false, 1);
        options.spool_ends = true;
        options.personality = personality;
        options.printer.version = personality.version();
        options.printer.spool_join = personality == Personality::Mk3s;
        let report = soak::run(&options, &mut |_| {});
        let ends = &report.spool_ends;
        let tangles = report
            .by_fault_kind
            .iter()
            .find(|t| t.kind == "jam (printing)")
            .map_or(0, |t| t.injected);
        assert!(ends.fastened > 0 && tangles > 0, "{personality}: {report}");
        assert_eq!(ends.fastened_reported, ends.fastened, "{personality}: {report}");
        assert_eq!(ends.fastened_handled, ends.fastened, "{personality}: {report}");
        assert_eq!(ends.false_total(), 0, "{personality}: {report}");
        assert!(report.passed(), "{personality}: {report}\n{:#?}", report.notes);
    }
}
