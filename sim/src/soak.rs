//! Soak runs: many tool changes across all slots with random faults injected and later cleared,
//! recovered as the printer and its user would, and the figures that come out.
//!
//! (Contract only; the run itself is being written.)

use crate::printer::PrinterOptions;
use crate::sim::SimOptions;

/// What a soak run does.
#[derive(Debug, Clone)]
pub struct SoakOptions {
    /// Tool changes to run.
    pub changes: u32,
    /// Inject random faults.
    pub random_faults: bool,
    /// Seed of the run (the simulator's and the fault schedule's).
    pub seed: u64,
    /// The simulated unit.
    pub sim: SimOptions,
    /// The printer.
    pub printer: PrinterOptions,
}

/// What a soak run found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SoakReport {
    /// Tool changes run.
    pub changes: u32,
    /// Faults injected.
    pub faults_injected: u32,
    /// Faults after which the tool change completed.
    pub recovered: u32,
    /// Faults after which the tool change failed even once the fault was cleared and Retry pressed.
    pub unrecovered: u32,
    /// Commands that never ended, or a link that never came back.
    pub stuck: u32,
    /// Panics caught in the unit logic or the simulator.
    pub panics: u32,
}

impl SoakReport {
    /// The summary line, exactly:
    /// `soak: <N> tool changes, <F> faults injected, <R> recovered, <U> unrecovered, <S> stuck, <P> panics`.
    pub fn summary_line(&self) -> String {
        format!(
            "soak: {} tool changes, {} faults injected, {} recovered, {} unrecovered, {} stuck, {} panics",
            self.changes, self.faults_injected, self.recovered, self.unrecovered, self.stuck, self.panics
        )
    }

    /// Nothing unrecovered, stuck or panicked.
    pub fn passed(&self) -> bool {
        self.unrecovered == 0 && self.stuck == 0 && self.panics == 0
    }
}
