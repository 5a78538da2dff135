//! Tool-change benchmark: fault-free tool changes in the in-process simulator on every printer
//! the simulator plays, each timed against its floor ([`mmu_sim::timing::tool_change_floor`]: the
//! unit's motion at its configured speeds, plus what the printer's own sequence forces between
//! the unit accepting the `T` and its `F`), and how much virtual time the simulator runs per
//! second of wall time.
//!
//! `cargo bench -p mmu-sim --bench toolchange` (release profile). `BENCH_CHANGES` sets how many
//! tool changes run per printer (default 30). Prints per printer, exactly,
//! `toolchange <printer>: <S> s per change, <R>x its floor`, after the soak's summary. Exits
//! non-zero when a printer's mean tool change is more than [`TARGET_RATIO`] times its floor or a
//! change failed.

use std::process::ExitCode;

use mmu_sim::soak::{self, SoakOptions, ToolChangeTimes};
use mmu_sim::{Personality, PrinterOptions, SimOptions};

/// A printer's mean tool change may take this many times its floor.
const TARGET_RATIO: f64 = 1.20;

/// The bench's line for `printer`, exactly `toolchange <printer>: <S> s per change, <R>x its
/// floor` (two decimals each); `None` without timed changes.
fn bench_line(printer: Personality, times: &ToolChangeTimes) -> Option<(String, f64)> {
    let ratio = times.ratio_to_floor()?;
    let line = format!(
        "toolchange {printer}: {:.2} s per change, {ratio:.2}x its floor",
        times.mean_s
    );
    Some((line, ratio))
}

fn main() -> ExitCode {
    // `cargo bench` passes `--bench`; a plain run of the binary works the same.
    let changes = std::env::var("BENCH_CHANGES")
        .ok()
        .and_then(|text| text.parse().ok())
        .unwrap_or(30);
    let mut failed = Vec::new();
    let mut lines = Vec::new();
    for printer in Personality::ALL {
        let options = SoakOptions {
            changes,
            random_faults: false,
            spool_ends: false,
            power_losses: false,
            seed: 1,
            sim: SimOptions::default(),
            printer: PrinterOptions::of(printer),
            personality: printer,
        };
        let report = soak::run(&options, &mut |_| {});
        println!("{printer}: {report}");
        for note in &report.notes {
            println!("  {note}");
        }
        let times = report.tool_change_times;
        let Some((line, ratio)) = bench_line(printer, &times) else {
            failed.push(format!("{printer}: no tool change was timed"));
            continue;
        };
        println!("{line}");
        lines.push(line);
        if !report.passed() {
            failed.push(format!("{printer}: {}", report.summary_line()));
        }
        if ratio > TARGET_RATIO {
            failed.push(format!(
                "{printer}: {ratio:.2}x its floor, above {TARGET_RATIO:.2}x"
            ));
        }
    }
    println!();
    for line in &lines {
        println!("{line}");
    }
    if failed.is_empty() {
        ExitCode::SUCCESS
    } else {
        for why in &failed {
            println!("toolchange: FAILED, {why}");
        }
        ExitCode::FAILURE
    }
}
