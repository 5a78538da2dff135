//! `mmu printer soak`: many tool changes on the simulator, with random faults if asked, and the
//! report; Ctrl-C stops the run after the change in progress and the report covers what ran.

use std::error::Error;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use clap::ValueEnum;
use mmu_sim::SimOptions;
use mmu_sim::soak::{SoakOptions, SoakReport};

use super::console::{Console, JsonLine};
use super::{Details, PrinterArgs, personality, printer_options};
use crate::usage::{Interrupted, usage};

/// `mmu printer soak` options.
#[derive(Debug, clap::Args)]
pub struct SoakArgs {
    /// Tool changes to run.
    #[arg(long, value_name = "N", default_value_t = 100)]
    pub changes: u32,
    /// Faults to inject.
    #[arg(long, value_enum, default_value_t = Faults::None)]
    pub faults: Faults,
    /// Seed of the run (default: the simulator's --seed).
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
}

/// Faults of a soak run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Faults {
    /// None: every change must simply work.
    None,
    /// Random faults, injected and later cleared.
    Random,
    /// A fault while printing after every change: a spool end, or a tangle, a jam or another
    /// print fault, one in two (the figures: spool ends handled, false spool ends).
    SpoolEnds,
    /// A power loss in every change, at a random moment of it: how the changes end after the
    /// printer's recovery, by the phase the power went in.
    PowerLoss,
}

/// `mmu printer soak`: the report, and a failure when it did not pass.
pub(super) fn run_soak(
    args: &PrinterArgs,
    soak: &SoakArgs,
    mut console: Console,
) -> Result<(), Box<dyn Error>> {
    if args.port.is_some() {
        return Err(usage("soak runs on the simulator: drop --port"));
    }
    if !args.sim_options.faults.is_empty() {
        return Err(usage(
            "soak injects its own faults (--faults random): drop --fault",
        ));
    }
    let seed = soak.seed.unwrap_or(args.sim_options.seed);
    let options = SoakOptions {
        changes: soak.changes,
        random_faults: soak.faults == Faults::Random,
        spool_ends: soak.faults == Faults::SpoolEnds,
        power_losses: soak.faults == Faults::PowerLoss,
        seed,
        sim: SimOptions {
            slots: args.sim_options.slots,
            seed,
            extruder: args.sim_options.extruder,
            ..SimOptions::for_hardware(args.sim_options.hardware)
        },
        printer: printer_options(args),
        personality: personality(args),
    };
    let bar = console.progress_bar(u64::from(soak.changes), "tool changes");
    let stop = ctrl_c_flag()?;
    let report = mmu_sim::soak::run_until(
        &options,
        &mut |done| {
            if let Some(bar) = &bar {
                bar.set_position(u64::from(done));
            }
        },
        &|| stop.load(Ordering::Relaxed),
    );
    if let Some(bar) = bar {
        bar.finish_and_clear();
    }
    console.close();
    console.say(&report.to_string());
    for note in &report.notes {
        console.say(note);
    }
    console.emit(&JsonLine::Result {
        action: "soak",
        ok: report.passed(),
        details: soak_details(&report, seed),
    });
    if stop.load(Ordering::Relaxed) {
        Err(Box::new(Interrupted(format!(
            "soak stopped by Ctrl-C: {}",
            report.summary_line()
        ))))
    } else if report.passed() {
        Ok(())
    } else {
        Err(format!("soak failed: {}", report.summary_line()).into())
    }
}

/// A flag Ctrl-C raises (instead of ending the process), for a long run to stop and report.
pub fn ctrl_c_flag() -> Result<Arc<AtomicBool>, Box<dyn Error>> {
    let flag = Arc::new(AtomicBool::new(false));
    let raised = Arc::clone(&flag);
    ctrlc::set_handler(move || raised.store(true, Ordering::Relaxed))
        .map_err(|error| format!("cannot catch Ctrl-C: {error}"))?;
    Ok(flag)
}

fn soak_details(report: &SoakReport, seed: u64) -> Details {
    let mut details = Details::new();
    details.insert("seed".into(), seed.into());
    details.insert("summary".into(), report.summary_line().into());
    details.insert("report".into(), report.to_string().into());
    details.insert("changes".into(), report.changes.into());
    details.insert("faults_injected".into(), report.faults_injected.into());
    details.insert("recovered".into(), report.recovered.into());
    details.insert("unrecovered".into(), report.unrecovered.into());
    details.insert("stuck".into(), report.stuck.into());
    details.insert("spool_ends".into(), report.spool_ends.injected.into());
    details.insert("spool_ends_reported".into(), report.spool_ends.reported.into());
    details.insert("spool_ends_handled".into(), report.spool_ends.handled.into());
    details.insert("false_spool_ends".into(), report.spool_ends.false_total().into());
    details.insert("panics".into(), report.panics.into());
    let restarts = &report.restarts;
    if restarts.struck() > 0 {
        details.insert("power_losses_mid_change".into(), restarts.struck().into());
        details.insert("completed_after_recovery".into(), restarts.completed().into());
        details.insert("unload_manually".into(), restarts.unload_manually().into());
    }
    details
}
