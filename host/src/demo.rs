//! `mmu demo`: a scripted session against the in-process simulator.

use std::error::Error;

/// `mmu demo` options.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {}

/// Run `mmu demo`.
pub fn run(_args: &DemoArgs) -> Result<(), Box<dyn Error>> {
    Err("not written yet".into())
}
