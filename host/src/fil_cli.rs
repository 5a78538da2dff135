//! `mmu fil`: the firmware-in-the-loop scenarios on a firmware image.
//!
//! The image built by `cargo fw` / `cargo fw-pico` runs unchanged on its board's emulated chip
//! (the benches in `fil/`), wired to the simulated unit and driven by the simulated printer; the
//! scenarios are the ones the host-built logic passes in `cargo test`
//! ([`mmu_sim::scenarios`]). Boards run side by side, one thread each. One line per scenario,
//! then a summary line per board; exit status 1 when one failed.

use std::error::Error;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::thread;
use std::time::Instant;

use clap::Args;
use mmu_firmware::Config;
use mmu_sim::Sim;
use mmu_sim::firmware::{Board, FirmwareUnit, default_fil_dir};
use mmu_sim::scenarios::{SCENARIOS, run_all};

use crate::usage::usage;

/// `mmu fil` options.
#[derive(Debug, Args)]
pub struct FilArgs {
    /// The board whose image runs: g071 (NUCLEO-G071RB, Unicorn with register models) or pico
    /// (Raspberry Pi Pico, rp2040js); may be repeated. Both by default, side by side.
    #[arg(long = "board", value_name = "BOARD", value_parser = parse_board)]
    pub boards: Vec<Board>,
    /// The firmware image (ELF), with one --board; by default `dist/mmu-firmware-<BOARD>.elf`,
    /// where `scripts/build-firmware.sh <BOARD> dist` puts it.
    #[arg(long, value_name = "ELF")]
    pub image: Option<PathBuf>,
    /// Run only the scenarios whose name contains this text.
    #[arg(long, value_name = "TEXT")]
    pub only: Option<String>,
    /// Where the benches are (`fil/` of the source tree by default).
    #[arg(long, value_name = "DIR")]
    pub fil_dir: Option<PathBuf>,
    /// Where each board's bench log goes (`<DIR>/<BOARD>.log`, started afresh); the temporary
    /// directory's `mmu-fil/` by default. A failed scenario shows the end of it.
    #[arg(long, value_name = "DIR")]
    pub log_dir: Option<PathBuf>,
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
    let mut boards = if args.boards.is_empty() {
        Board::ALL.to_vec()
    } else {
        args.boards.clone()
    };
    boards.dedup();
    if args.image.is_some() && boards.len() != 1 {
        return Err(usage("--image needs exactly one --board"));
    }
    let mut images = Vec::new();
    for &board in &boards {
        let image = image_path(board, args.image.as_ref());
        if !image.is_file() {
            return Err(format!(
                "no firmware image at {} (build it: scripts/build-firmware.sh {} dist)",
                image.display(),
                board.name()
            )
            .into());
        }
        images.push((board, image));
    }
    let fil_dir = args.fil_dir.clone().unwrap_or_else(default_fil_dir);
    let only = args.only.as_deref();
    let log_dir = args
        .log_dir
        .clone()
        .unwrap_or_else(|| std::env::temp_dir().join("mmu-fil"));
    std::fs::create_dir_all(&log_dir).map_err(|e| format!("cannot create {}: {e}", log_dir.display()))?;
    println!("bench logs: {}", log_dir.display());
    let summaries: Vec<(String, bool)> = thread::scope(|scope| {
        let runs: Vec<_> = images
            .iter()
            .map(|(board, image)| {
                let log = log_dir.join(format!("{}.log", board.name()));
                let fil_dir = &fil_dir;
                scope.spawn(move || run_board(*board, image, fil_dir, &log, only))
            })
            .collect();
        runs.into_iter()
            .map(|run| {
                run.join()
                    .unwrap_or_else(|_| (String::from("a board's run panicked"), false))
            })
            .collect()
    });
    for (summary, _) in &summaries {
        println!("{summary}");
    }
    let failed = summaries.iter().filter(|(_, passed)| !passed).count();
    if failed == 0 {
        Ok(())
    } else {
        Err(format!("scenarios failed on {failed} of {} boards", summaries.len()).into())
    }
}

/// Every scenario on `board`'s `image`: its summary line, and whether all passed.
fn run_board(board: Board, image: &Path, fil_dir: &Path, log: &Path, only: Option<&str>) -> (String, bool) {
    let log_file = match File::create(log) {
        Ok(file) => file,
        Err(e) => {
            return (
                format!(
                    "firmware-in-the-loop ({}): cannot create {}: {e}",
                    board.name(),
                    log.display()
                ),
                false,
            );
        }
    };
    let mut new_unit = |options: mmu_sim::SimOptions| {
        let bench_log = log_file
            .try_clone()
            .map_err(|e| format!("{}: {e}", log.display()))?;
        let unit = FirmwareUnit::start(board, image, fil_dir, Config::default(), bench_log.into())?;
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
    let name = board.name();
    let mut loads_seen = 0;
    let verdicts = run_all(&mut new_unit, only, &mut |verdict| {
        let took = verdict.took.as_secs_f64();
        // The bench's `load:` line, written when the scenario's unit quit (fil/*/README).
        let loads = load_lines(log);
        let load = (loads.len() > loads_seen)
            .then(|| loads.last().cloned())
            .flatten();
        loads_seen = loads.len();
        match &verdict.result {
            Ok(()) => {
                println!("  ok    {name}: {} ({took:.1} s)", verdict.name);
                if let Some(load) = load {
                    println!("        {load}");
                }
            }
            Err(why) => {
                println!("  FAIL  {name}: {} ({took:.1} s): {why}", verdict.name);
                for line in last_lines(log, 15) {
                    println!("        | {line}");
                }
            }
        }
    });
    let passed = verdicts.iter().filter(|v| v.result.is_ok()).count();
    let summary = format!(
        "firmware-in-the-loop ({name}): {passed}/{} scenarios passed in {:.0} s",
        verdicts.len(),
        started.elapsed().as_secs_f64()
    );
    (summary, passed == verdicts.len())
}

/// The `load:` lines of the bench log at `path`: what each scenario's milliseconds cost the
/// image, from the bench's prefix on (none when it cannot be read).
fn load_lines(path: &Path) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.lines()
        .filter_map(|line| line.find("load: ").map(|at| line[at..].to_string()))
        .filter(|load| !load.contains("no millisecond"))
        .collect()
}

/// The last `n` lines of the file at `path` (none when it cannot be read).
fn last_lines(path: &Path, n: usize) -> Vec<String> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(n)..]
        .iter()
        .map(|l| l.to_string())
        .collect()
}
