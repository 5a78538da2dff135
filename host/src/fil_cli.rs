//! `mmu fil`: the firmware-in-the-loop scenarios on a firmware image.
//!
//! The image built by `cargo fw` / `cargo fw-n20` / `cargo fw-pico` / `cargo fw-bmcu` runs
//! unchanged on its board's emulated chip (the benches in `fil/`), wired to the simulated unit and
//! driven by the simulated printer; the simulated lanes sense as the image's hardware profile says
//! (its bench names it), as many as the image has (a scenario needs at most three; a fourth lane
//! stays empty). The scenarios are the ones the host-built logic passes in `cargo test`
//! ([`mmu_sim::scenarios`]). Boards run side by side, one thread each. One line per scenario,
//! then a summary line per board and its real-time contract: the busiest millisecond of the
//! control loop within [`BUSIEST_PERCENT`] of the period (on the Pico not counting those that
//! program the flash, the documented exception), no erase while a motor was driven, and at most
//! [`UNCOMMANDED_UM`] of filament moved uncommanded by one step's flash operations at the chip's
//! longest stalls. A bench that paints its stack (the BMCU-C's) adds the deepest the stack
//! reached over the scenarios. With `FIL_WORN_STORE=1` in the environment the benches start with the store's
//! pages written, as on a unit that has saved for a while, so that pages are erased during the
//! scenarios; the contract then also wants an erase to have happened. Exit status 1 when a
//! scenario failed or the contract did not hold (with `--contract report`, only when a scenario
//! failed: for an image known to break the contract, whose scenarios are still to be held).

use std::error::Error;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::Instant;

use clap::Args;
use mmu_firmware::Config;
use mmu_sim::Sim;
use mmu_sim::firmware::{Board, FirmwareUnit, default_fil_dir};
use mmu_sim::flash::FlashWear;
use mmu_sim::scenarios::{SCENARIOS, run_all};

use crate::usage::usage;

/// `mmu fil` options.
#[derive(Debug, Args)]
pub struct FilArgs {
    /// The board whose image runs: g071 (NUCLEO-G071RB, Unicorn with register models), pico
    /// (Raspberry Pi Pico, rp2040js) or bmcu (the BMCU-C's CH32V203, Unicorn's RV32 with register
    /// models); may be repeated. All three by default, side by side.
    #[arg(long = "board", value_name = "BOARD", value_parser = parse_board)]
    pub boards: Vec<Board>,
    /// The firmware image (ELF), with one --board; by default `dist/mmu-firmware-<BOARD>.elf`,
    /// where `scripts/build-firmware.sh <BOARD> dist` puts it. The G071's N20 encoder build runs
    /// as `--board g071 --image dist/mmu-firmware-g071-n20.elf`.
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
    /// What a broken real-time contract does: `enforce` fails the run (exit status 1), `report`
    /// prints it all the same and fails only on a scenario (for an image known to break the
    /// contract: the BMCU-C's, book: The firmware in the loop).
    #[arg(long, value_enum, default_value_t = ContractMode::Enforce)]
    pub contract: ContractMode,
}

/// What `mmu fil` does with a broken real-time contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ContractMode {
    /// Fail the run.
    Enforce,
    /// Print it, and fail only on a scenario.
    Report,
}

/// The busiest millisecond of the control loop may take this much of the period, %.
pub const BUSIEST_PERCENT: f64 = 50.0;
/// The most filament a step's flash operations may move uncommanded, µm.
pub const UNCOMMANDED_UM: u64 = 1_000;

/// A board by name, for clap.
pub fn parse_board(name: &str) -> Result<Board, String> {
    Board::from_name(name).ok_or_else(|| format!("unknown board {name:?}: g071, pico or bmcu"))
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
                let contract = args.contract;
                scope.spawn(move || run_board(*board, image, fil_dir, &log, only, contract))
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

/// Every scenario on `board`'s `image`: its summary lines, and whether all passed within the
/// real-time contract.
fn run_board(
    board: Board,
    image: &Path,
    fil_dir: &Path,
    log: &Path,
    only: Option<&str>,
    mode: ContractMode,
) -> (String, bool) {
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
    let wear = Arc::new(Mutex::new(FlashWear::default()));
    let mut new_unit = |options: mmu_sim::SimOptions| {
        let bench_log = log_file
            .try_clone()
            .map_err(|e| format!("{}: {e}", log.display()))?;
        let mut unit = FirmwareUnit::start(board, image, fil_dir, Config::default(), bench_log.into())?;
        if unit.slots() < options.slots {
            return Err(format!(
                "the image has {} slots, the scenario {}",
                unit.slots(),
                options.slots
            ));
        }
        // The image's lanes, all of them: those the scenario does not use stay empty.
        let options = mmu_sim::SimOptions {
            slots: unit.slots(),
            ..options
        };
        unit.report_wear(Arc::clone(&wear));
        // The simulated lanes sense as the image's build does (its motion samples, its distance
        // per turn).
        let options = options.on_hardware(unit.profile());
        Ok(Sim::with_unit(options, Box::new(unit)))
    };
    let started = Instant::now();
    let name = board.name();
    let mut loads_seen = 0;
    let mut busiest = Busiest::default();
    let mut deepest_stack: Option<u64> = None;
    let verdicts = run_all(&mut new_unit, only, &mut |verdict| {
        let took = verdict.took.as_secs_f64();
        // The bench's `load:` line, written when the scenario's unit quit (fil/*/README).
        let loads = load_lines(log);
        let load = (loads.len() > loads_seen)
            .then(|| loads.last().cloned())
            .flatten();
        loads_seen = loads.len();
        if let Some(load) = &load {
            busiest.take(load);
        }
        deepest_stack = deepest_stack.max(stack_depth(log));
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
    let wear = wear.lock().map(|wear| *wear).unwrap_or_default();
    let worn = std::env::var("FIL_WORN_STORE").is_ok_and(|value| !value.is_empty() && value != "0");
    let (contract, kept) = contract(board, &busiest, &wear, worn);
    let reported = if !kept && mode == ContractMode::Report {
        " (reported, not enforced: --contract report)"
    } else {
        ""
    };
    let mut summary = format!(
        "firmware-in-the-loop ({name}): {passed}/{} scenarios passed in {:.0} s\n  {contract}{reported}",
        verdicts.len(),
        started.elapsed().as_secs_f64()
    );
    if let Some(deepest) = deepest_stack {
        summary += &format!(
            "\n  stack: the deepest it reached over the scenarios, {deepest} bytes below its top \
             (the bench's painted high-water mark)"
        );
    }
    (
        summary,
        passed == verdicts.len() && (kept || mode == ContractMode::Report),
    )
}

/// The busiest milliseconds of the control loop over the scenarios, % of the period.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
struct Busiest {
    /// Without a flash operation.
    plain: Option<f64>,
    /// With one.
    writing: Option<f64>,
}

impl Busiest {
    /// Takes a bench's `load:` line: `... busiest N (P % ...` for the milliseconds without a
    /// flash write, then `; K ms with one, busiest N (P %)` when there were such.
    fn take(&mut self, load: &str) {
        let (plain, writing) = load.split_once(" ms with one,").unwrap_or((load, ""));
        let most = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
        self.plain = most(self.plain, busiest_percent(plain));
        self.writing = most(self.writing, busiest_percent(writing));
    }
}

/// The percentage after the last `busiest N (` of `text`.
fn busiest_percent(text: &str) -> Option<f64> {
    let after = &text[text.rfind("busiest ")? + "busiest ".len()..];
    let inside = &after[after.find('(')? + 1..];
    inside[..inside.find(" %")?].trim().parse().ok()
}

/// The real-time contract's line for `board` and whether it held (see the module header);
/// `worn`: the store started worn, so an erase must have happened.
fn contract(board: Board, busiest: &Busiest, wear: &FlashWear, worn: bool) -> (String, bool) {
    let percent = |p: Option<f64>| p.map_or_else(|| String::from("-"), |p| format!("{p:.1} %"));
    // The Pico's milliseconds that program its flash run the boot ROM with interrupts off: the
    // contract's one exception, bounded by the flash's program time instead.
    let counted = match board {
        Board::G071 | Board::Bmcu => [busiest.plain, busiest.writing],
        Board::Pico => [busiest.plain, None],
    };
    let within = counted.iter().flatten().all(|&p| p <= BUSIEST_PERCENT) && busiest.plain.is_some();
    let uncommanded_ok = wear.erases_while_driven == 0
        && wear.most_uncommanded_um <= UNCOMMANDED_UM
        && (!worn || wear.erases > 0);
    let line = format!(
        "contract: busiest control millisecond {} without a flash operation, {} with one \
         (bound {BUSIEST_PERCENT:.0} %{}); {} erases, {} while a motor was driven; most filament \
         a flash operation could move uncommanded {:.3} mm (bound {:.1} mm): {}",
        percent(busiest.plain),
        percent(busiest.writing),
        if board == Board::Pico {
            ", not counting a flash program"
        } else {
            ""
        },
        wear.erases,
        wear.erases_while_driven,
        wear.most_uncommanded_um as f64 / 1000.0,
        UNCOMMANDED_UM as f64 / 1000.0,
        if within && uncommanded_ok {
            "kept"
        } else {
            "BROKEN"
        }
    );
    (line, within && uncommanded_ok)
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

/// The deepest the stack reached, bytes below its top, over the bench log at `path`'s `stack:`
/// lines (`stack: deepest N bytes below the top ...`, fil/bmcu/README.md); None without one.
fn stack_depth(path: &Path) -> Option<u64> {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    text.lines()
        .filter_map(|line| {
            let after = &line[line.find("stack: deepest ")? + "stack: deepest ".len()..];
            after.split_whitespace().next()?.parse().ok()
        })
        .max()
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

#[cfg(test)]
mod tests {
    use super::*;

    const G071_LOAD: &str = "load: 5123 ms without a flash write, instructions a millisecond: median 4516 (15.5 %), \
        99 % 5722 (19.7 %), 99.9 % 6000 (20.6 %), busiest 7250 (24.9 % of 1 ms at 64 MHz, 2.2 cycles an \
        instruction) at 1234 ms, 12 bytes received; 40 ms with one, busiest 6865 (23.6 %) at 999 ms";
    const PICO_LOAD: &str = "load: 5000 ms without a flash write, cycles a millisecond: median 23235 (18.6 %, \
        14107 instructions), 99 % 26000 (20.8 %, 15000 instructions), 99.9 % 27000 (21.6 %, 16000 \
        instructions), busiest 60000 (51.2 % of 1 ms at 125 MHz, 17573 instructions) at 88 ms, 0 bytes \
        received; 12 ms with one, busiest 74120 (59.3 %) at 77 ms";

    #[test]
    fn the_deepest_stack_is_read_from_the_bench_logs_stack_lines() {
        let path = std::env::temp_dir().join(format!("mmu-fil-stack-{}.log", std::process::id()));
        std::fs::write(
            &path,
            "load: 10 ms\nstack: deepest 4808 bytes below the top 0x20005000, of 14336 painted\n\
             stack: deepest 5120 bytes below the top 0x20005000, of 14336 painted\n",
        )
        .expect("a temporary file");
        assert_eq!(stack_depth(&path), Some(5120));
        std::fs::write(&path, "load: 10 ms\n").expect("a temporary file");
        assert_eq!(stack_depth(&path), None);
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn the_busiest_milliseconds_are_read_from_both_benches_load_lines() {
        let mut busiest = Busiest::default();
        busiest.take(G071_LOAD);
        assert_eq!((busiest.plain, busiest.writing), (Some(24.9), Some(23.6)));
        busiest.take("load: 10 ms without a flash write, ... busiest 8112 (27.9 % of 1 ms) at 5 ms");
        assert_eq!((busiest.plain, busiest.writing), (Some(27.9), Some(23.6)));
        let mut pico = Busiest::default();
        pico.take(PICO_LOAD);
        assert_eq!((pico.plain, pico.writing), (Some(51.2), Some(59.3)));
    }

    #[test]
    fn the_contract_breaks_on_a_busy_millisecond_an_erase_under_motion_or_too_much_motion() {
        let wear = FlashWear {
            erases: 3,
            most_uncommanded_um: 450,
            ..FlashWear::default()
        };
        let within = Busiest {
            plain: Some(24.9),
            writing: Some(23.6),
        };
        assert!(contract(Board::G071, &within, &wear, false).1);
        let (line, kept) = contract(
            Board::G071,
            &Busiest {
                writing: Some(50.1),
                ..within
            },
            &wear,
            false,
        );
        assert!(!kept && line.ends_with("BROKEN"), "{line}");
        // The Pico's flash programs are the exception; its other milliseconds are not.
        let programming = Busiest {
            plain: Some(22.0),
            writing: Some(59.3),
        };
        assert!(contract(Board::Pico, &programming, &wear, false).1);
        assert!(
            !contract(
                Board::Pico,
                &Busiest {
                    plain: Some(51.2),
                    ..programming
                },
                &wear,
                false,
            )
            .1
        );
        let driven = FlashWear {
            erases_while_driven: 1,
            ..wear
        };
        assert!(!contract(Board::G071, &within, &driven, false).1);
        let moved = FlashWear {
            most_uncommanded_um: 1_001,
            ..wear
        };
        assert!(!contract(Board::G071, &within, &moved, false).1);
        assert!(
            !contract(Board::G071, &Busiest::default(), &wear, false).1,
            "nothing measured"
        );
        let unused = FlashWear::default();
        assert!(contract(Board::G071, &within, &unused, false).1);
        assert!(
            !contract(Board::G071, &within, &unused, true).1,
            "a worn store not exercised"
        );
    }
}
