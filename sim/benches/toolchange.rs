//! Tool-change benchmark: fault-free tool changes in the in-process simulator, timed against the
//! physical minimum of [`mmu_sim::timing`], and how much virtual time the simulator runs per
//! second of wall time.
//!
//! `cargo bench -p mmu-sim --bench toolchange` (release profile). `BENCH_CHANGES` sets how many
//! tool changes run (default 30). Exits non-zero when the mean tool change is more than 10 %
//! above the physical minimum or a change failed.

use std::process::ExitCode;

use mmu_sim::soak::{self, SoakOptions};
use mmu_sim::{Personality, PrinterOptions, SimOptions};

/// The mean tool change may exceed the physical minimum by this factor.
const TARGET_RATIO: f64 = 1.10;

fn main() -> ExitCode {
    // `cargo bench` passes `--bench`; a plain run of the binary works the same.
    let changes = std::env::var("BENCH_CHANGES")
        .ok()
        .and_then(|text| text.parse().ok())
        .unwrap_or(30);
    let options = SoakOptions {
        changes,
        random_faults: false,
        spool_ends: false,
        power_losses: false,
        seed: 1,
        sim: SimOptions::default(),
        printer: PrinterOptions::default(),
        personality: Personality::default(),
    };
    let report = soak::run(&options, &mut |_| {});
    println!("{report}");
    for note in &report.notes {
        println!("  {note}");
    }
    let times = report.tool_change_times;
    let Some(ratio) = times.ratio_to_minimum() else {
        println!("toolchange: FAILED, no tool change was timed");
        return ExitCode::FAILURE;
    };
    println!(
        "toolchange: {} changes, mean {:.3} s vs physical minimum {:.3} s: {:+.1} % (target within {:.0} %); {:.0} sim s per wall s",
        times.changes,
        times.mean_s,
        times.physical_minimum_mean_s,
        (ratio - 1.0) * 100.0,
        (TARGET_RATIO - 1.0) * 100.0,
        report.speed()
    );
    if ratio > TARGET_RATIO || !report.passed() {
        println!("toolchange: FAILED");
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}
