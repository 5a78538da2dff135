//! `mmu fil`: the firmware-in-the-loop scenarios on a firmware image.
//!
//! The image built by `cargo fw` / `cargo fw-pico` runs unchanged on its board's emulated chip
//! (the benches in `fil/`), wired to the simulated unit and driven by the simulated printer; the
//! scenarios are the ones the host-built logic passes in `cargo test`
//! ([`mmu_sim::scenarios`]). One line per scenario, then a summary line; exit status 1 when one
//! failed.

use std::error::Error;
use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use mmu_firmware::Config;
use mmu_sim::Sim;
use mmu_sim::firmware::{Board, FirmwareUnit, default_fil_dir};
use mmu_sim::scenarios::{SCENARIOS, run_all};

/// `mmu fil` options.
#[derive(Debug, Args)]
pub struct FilArgs {
    /// The board whose image runs: g071 (NUCLEO-G071RB, Unicorn with register models) or pico
    /// (Raspberry Pi Pico, rp2040js).
    #[arg(long, value_name = "BOARD", value_parser = parse_board)]
    pub board: Board,
    /// The firmware image (ELF); by default `dist/mmu-firmware-<BOARD>.elf`, where
    /// `scripts/build-firmware.sh <BOARD> dist` puts it.
    #[arg(long, value_name = "ELF")]
    pub image: Option<PathBuf>,
    /// Run only the scenarios whose name contains this text.
    #[arg(long, value_name = "TEXT")]
    pub only: Option<String>,
    /// Where the benches are (`fil/` of the source tree by default).
    #[arg(long, value_name = "DIR")]
    pub fil_dir: Option<PathBuf>,
    /// List the scenarios and exit.
    #[arg(long)]
    pub list: bool,
}

/// A board by name, for clap.
pub fn parse_board(name: &str) -> Result<Board, String> {
    Board::from_name(name).ok_or_else(|| format!("unknown board {name:?}: g071 or pico"))
}

/// The image of `board` at `image`, or where `scripts/build-firmware.sh` puts it.
pub fn image_path(board: Board, image: Option<&PathBuf>) -> PathBuf {
    image
        .cloned()
        .unwrap_or_else(|| PathBuf::from(format!("dist/mmu-firmware-{}.elf", board.name())))
}

/// Run `mmu fil`.
pub fn run(args: &FilArgs) -> Result<(), Box<dyn Error>> {
    if args.list {
        for scenario in SCENARIOS {
            println!("{}", scenario.name);
        }
        return Ok(());
    }
    let image = image_path(args.board, args.image.as_ref());
    if !image.is_file() {
        return Err(format!(
            "no firmware image at {} (build it: scripts/build-firmware.sh {} dist)",
            image.display(),
            args.board.name()
        )
        .into());
    }
    let fil_dir = args.fil_dir.clone().unwrap_or_else(default_fil_dir);
    let board = args.board;
    let mut new_unit = |options: mmu_sim::SimOptions| {
        let unit = FirmwareUnit::start(board, &image, &fil_dir, Config::default())?;
        if unit.slots() != options.slots {
            return Err(format!(
                "the image has {} slots, the scenario {}",
                unit.slots(),
                options.slots
            ));
        }
        Ok(Sim::with_unit(options, Box::new(unit)))
    };
    let started = Instant::now();
    let verdicts = run_all(&mut new_unit, args.only.as_deref(), &mut |verdict| {
        let took = verdict.took.as_secs_f64();
        match &verdict.result {
            Ok(()) => println!("  ok    {} ({took:.1} s)", verdict.name),
            Err(why) => println!("  FAIL  {} ({took:.1} s): {why}", verdict.name),
        }
    });
    let passed = verdicts.iter().filter(|v| v.result.is_ok()).count();
    println!(
        "firmware-in-the-loop ({}): {passed}/{} scenarios passed in {:.0} s",
        board.name(),
        verdicts.len(),
        started.elapsed().as_secs_f64()
    );
    if passed == verdicts.len() {
        Ok(())
    } else {
        Err(format!(
            "{} of {} scenarios failed",
            verdicts.len() - passed,
            verdicts.len()
        )
        .into())
    }
}
