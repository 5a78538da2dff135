//! `mmu printer`: the printer's side, against a unit on a serial port or the simulator.

use std::error::Error;

/// `mmu printer` options.
#[derive(Debug, clap::Args)]
pub struct PrinterArgs {}

/// Run `mmu printer`.
pub fn run(_args: &PrinterArgs) -> Result<(), Box<dyn Error>> {
    Err("not written yet".into())
}
