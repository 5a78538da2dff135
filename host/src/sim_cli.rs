//! `mmu sim`: the simulated unit served on stdin/stdout or a pseudo-terminal.

use std::error::Error;

/// `mmu sim` options.
#[derive(Debug, clap::Args)]
pub struct SimArgs {}

/// Run `mmu sim`.
pub fn run(_args: &SimArgs) -> Result<(), Box<dyn Error>> {
    Err("not written yet".into())
}
