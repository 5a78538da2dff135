//! The user's book (`book/src/`) and the README say what a maker can do; this file holds them to
//! it. Every link must lead somewhere (a page, a heading on it, a file of the repository); every
//! page is in the book's table of contents; and every command shown in a code block is run here,
//! or by CI (`.ci/run` must hold the same line), or is named below with the reason it cannot run
//! on a CI machine. A command run here must end as the book says, and where a block shows its
//! output (`$ command` then the lines it prints) the output must be what the tool prints. The
//! `mmu` commands named in the prose's inline code must at least parse (subcommands, options).
//!
//! How a command is run: `cargo <alias>` and `cargo run ... --bin mmu --` are the `mmu` binary
//! (the aliases are checked against `.cargo/config.toml`); a real unit's port (`/dev/ttyUSB0`,
//! `/dev/pts/7`) is a `mmu sim --pty` started for the command, as a unit behind a USB-serial
//! adapter; files the examples read (`serial.log`, `requests`) come from `host/tests/book/`.

use std::collections::{BTreeMap, BTreeSet};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::thread;
use std::time::{Duration, Instant};

mod common;

use common::{documentation, interrupt_when_ready};

/// The repository's root.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

// ------------------------------------------------------------------------------------------------
// Links

/// The id mdBook gives a heading (`mdbook-html`'s `normalize_id`): letters and digits lowercased,
/// `-` and `_` kept, white space turned into `-`, everything else dropped. Code spans count by
/// their text.
fn heading_id(heading: &str) -> String {
    heading
        .chars()
        .filter_map(|ch| {
            if ch.is_alphanumeric() || ch == '_' || ch == '-' {
                Some(ch.to_ascii_lowercase())
            } else if ch.is_whitespace() {
                Some('-')
            } else {
                None
            }
        })
        .collect()
}

/// A page's lines outside fenced code blocks, with their line numbers.
fn prose_lines(text: &str) -> Vec<(usize, &str)> {
    let mut fenced = false;
    let mut lines = Vec::new();
    for (index, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if !fenced {
            lines.push((index + 1, line));
        }
    }
    lines
}

/// The ids of a page's headings, numbered as mdBook numbers repeated ones (`-1`, `-2`, ...).
fn heading_ids(text: &str) -> BTreeSet<String> {
    let mut seen: BTreeMap<String, usize> = BTreeMap::new();
    let mut ids = BTreeSet::new();
    for (_, line) in prose_lines(text) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if hashes == 0 || !line[hashes..].starts_with(' ') {
            continue;
        }
        let id = heading_id(line[hashes..].trim());
        let count = seen.entry(id.clone()).or_insert(0);
        ids.insert(if *count == 0 {
            id.clone()
        } else {
            format!("{id}-{count}")
        });
        *count += 1;
    }
    ids
}

/// A line without its inline code spans (`` `[x](y)` `` is no link).
fn without_code_spans(line: &str) -> String {
    line.split('`')
        .enumerate()
        .filter(|(index, _)| index % 2 == 0)
        .map(|(_, part)| part)
        .collect::<Vec<_>>()
        .join(" ")
}

/// The targets of a line's Markdown links, `[text](target)`.
fn link_targets(line: &str) -> Vec<String> {
    let line = without_code_spans(line);
    let mut targets = Vec::new();
    let mut rest = line.as_str();
    while let Some(start) = rest.find("](") {
        let after = &rest[start + 2..];
        let Some(end) = after.find(')') else { break };
        targets.push(after[..end].trim().to_string());
        rest = &after[end..];
    }
    targets
}

/// Every relative link of the README and the book leads to a file of the repository, and a
/// `#fragment` to a heading of that page. Web links are not fetched (CI has no network to
/// spare), but must at least be `https://` addresses.
#[test]
fn every_link_leads_somewhere() {
    let pages = documentation();
    let ids: BTreeMap<PathBuf, BTreeSet<String>> = pages
        .iter()
        .map(|(page, text)| (normalize(&root().join(page)), heading_ids(text)))
        .collect();
    let mut broken = Vec::new();
    let mut checked = 0;
    for (page, text) in &pages {
        let folder = root()
            .join(page)
            .parent()
            .expect("a page has a folder")
            .to_path_buf();
        for (number, line) in prose_lines(text) {
            for target in link_targets(line) {
                checked += 1;
                if target.starts_with("http://") {
                    broken.push(format!("{page}:{number}: {target}: use https"));
                    continue;
                }
                if target.starts_with("https://") {
                    continue;
                }
                let (path, fragment) = match target.split_once('#') {
                    Some((path, fragment)) => (path, Some(fragment)),
                    None => (target.as_str(), None),
                };
                let file = if path.is_empty() {
                    normalize(&root().join(page))
                } else {
                    normalize(&folder.join(path))
                };
                if !file.exists() {
                    broken.push(format!("{page}:{number}: {target}: no such file"));
                    continue;
                }
                if let Some(fragment) = fragment {
                    let known = ids.get(&file);
                    if !known.is_some_and(|ids| ids.contains(fragment)) {
                        broken.push(format!(
                            "{page}:{number}: {target}: no heading with the id {fragment:?}"
                        ));
                    }
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
    assert!(checked > 100, "only {checked} links found: is the parser right?");
}

/// `a/b/../c` as `a/c`, without touching the file system.
fn normalize(path: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for part in path.components() {
        match part {
            std::path::Component::ParentDir => {
                if !out.pop() {
                    out.push("..");
                }
            }
            std::path::Component::CurDir => {}
            other => out.push(other),
        }
    }
    out
}

/// Every page of `book/src/` is in the table of contents (`SUMMARY.md`), so mdBook renders it
/// and a reader can find it.
#[test]
fn every_page_is_in_the_table_of_contents() {
    let pages = documentation();
    let summary = &pages
        .iter()
        .find(|(page, _)| page == "book/src/SUMMARY.md")
        .expect("the book has a SUMMARY.md")
        .1;
    let listed: BTreeSet<String> = summary
        .lines()
        .flat_map(link_targets)
        .map(|target| format!("book/src/{target}"))
        .collect();
    let missing: Vec<&str> = pages
        .iter()
        .map(|(page, _)| page.as_str())
        .filter(|page| page.starts_with("book/src/") && *page != "book/src/SUMMARY.md")
        .filter(|page| !listed.contains(*page))
        .collect();
    assert!(missing.is_empty(), "pages missing from SUMMARY.md: {missing:?}");
}

/// The README is the door, not the manual: short, the two commands near its top.
#[test]
fn the_readme_is_short_and_starts_with_the_two_commands() {
    let readme = std::fs::read_to_string(root().join("README.md")).expect("the README is readable");
    let lines = readme.lines().count();
    assert!(
        lines <= 250,
        "the README has {lines} lines; the book is the place for more"
    );
    let position = |what: &str| {
        readme
            .lines()
            .position(|line| line.starts_with(what))
            .unwrap_or_else(|| panic!("the README has no line starting with {what:?}"))
    };
    assert!(position("cargo demo") < 30);
    assert!(position("cargo test --workspace") < 30);
    assert!(readme.contains("cargo install --locked --path host"));
}

// ------------------------------------------------------------------------------------------------
// Commands

/// One command shown in a code block, and the output the block shows after it (`console` blocks).
#[derive(Debug, Clone)]
struct Shown {
    page: String,
    line: usize,
    /// The command as a reader would type it, without a trailing `# comment`.
    command: String,
    /// `mmu-console` blocks hold console commands, not shell commands.
    console: bool,
    output: Vec<String>,
}

/// The commands of a page: every line of a `sh` block, every `$ ` line of a `console` block
/// (with the lines under it as its output), every line of a `text mmu-console` block.
fn shown_commands(page: &str, text: &str) -> Vec<Shown> {
    let mut shown: Vec<Shown> = Vec::new();
    let mut block: Option<String> = None;
    // A `console` block's output belongs to the `$` command above it in the same block.
    let mut command_in_block = false;
    for (index, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        if let Some(info) = trimmed.strip_prefix("```") {
            block = match block {
                Some(_) => None,
                None => Some(info.trim().to_string()),
            };
            command_in_block = false;
            continue;
        }
        let Some(info) = &block else { continue };
        let console_block = info.split_whitespace().any(|word| word == "mmu-console");
        let kind = info.split_whitespace().next().unwrap_or("");
        let command = match kind {
            "sh" => Some(trimmed),
            "console" => match trimmed.strip_prefix("$ ") {
                Some(command) => Some(command),
                None => {
                    if let Some(last) = shown.last_mut().filter(|_| command_in_block) {
                        last.output.push(line.to_string());
                    }
                    None
                }
            },
            _ if console_block => Some(trimmed),
            _ => None,
        };
        let Some(command) = command else { continue };
        let command = strip_comment(command);
        if command.is_empty() {
            continue;
        }
        command_in_block = true;
        shown.push(Shown {
            page: page.to_string(),
            line: index + 1,
            command,
            console: console_block,
            output: Vec::new(),
        });
    }
    shown
}

/// `cmd   # what it does` as `cmd`; a `#` inside quotes is kept.
fn strip_comment(command: &str) -> String {
    let mut quote = None;
    let mut previous = ' ';
    for (index, ch) in command.char_indices() {
        match (quote, ch) {
            (None, '\'' | '"') => quote = Some(ch),
            (Some(open), _) if ch == open => quote = None,
            (None, '#') if previous.is_whitespace() => return command[..index].trim().to_string(),
            _ => {}
        }
        previous = ch;
    }
    command.trim().to_string()
}

/// How a command of the book is checked.
#[derive(Debug, Clone, Copy)]
enum Check {
    /// Run here; it must exit with this status (and print what the block shows, if it shows).
    Exits(i32),
    /// Run here against a `mmu sim --pty` in the port's place; it must exit with this status.
    OnPtyExits(i32),
    /// Run here, interrupted (Ctrl-C) after this many ms; it must exit 130 as the book says.
    Interrupted(u64),
    /// Run here against a `mmu sim --pty`, interrupted after this many ms; it must exit 130.
    OnPtyInterrupted(u64),
    /// `.ci/run` runs this very line.
    InCi,
    /// It needs what no CI machine has; the reason. Its arguments are still parsed: a `--port`
    /// command against a port that does not exist must fail to open it (exit 1), not on usage.
    NeedsHardware(&'static str),
    /// Not run anywhere, and why (root, Docker, a nightly toolchain, the network).
    NotRun(&'static str),
}

/// Every command the book shows, and how it is checked. A command added to the book must be
/// added here: the test says which.
const COMMANDS: &[(&str, Check)] = &[
    // The door and getting started.
    ("cargo demo", Check::InCi),
    ("cargo test --workspace", Check::InCi),
    ("cargo install --locked --path host", Check::InCi),
    ("mmu --version", Check::Exits(0)),
    ("mmu --help", Check::Exits(0)),
    (
        "cargo install --locked mdbook --version 0.5.4 --no-default-features --features search",
        Check::InCi,
    ),
    ("mdbook build book", Check::InCi),
    // Firmware and contributors.
    ("npm ci --prefix fil/pico", Check::InCi),
    ("bash scripts/build-firmware.sh g071 dist", Check::InCi),
    ("bash scripts/build-firmware.sh pico dist", Check::InCi),
    ("bash scripts/build-firmware.sh bmcu dist", Check::InCi),
    ("python3 -m pip install -r fil/g071/requirements.txt", Check::InCi),
    (
        "mmu fil",
        Check::NotRun(
            "all three boards, about 35 minutes; CI runs the G071 and the Pico in full and the BMCU-C's T1",
        ),
    ),
    ("mmu fil --board g071 --board pico", Check::InCi),
    (
        "FIL_WORN_STORE=1 mmu fil --board g071 --board pico --only T1",
        Check::InCi,
    ),
    ("bash scripts/build-firmware.sh bmcu dist", Check::InCi),
    ("python3 -m unittest discover -s fil/bmcu/tests", Check::InCi),
    (
        "mmu fil --board bmcu",
        Check::NotRun("14 minutes of emulated RISC-V; CI runs its T1"),
    ),
    ("FIL_WORN_STORE=1 mmu fil --board bmcu --only T1", Check::InCi),
    (
        "mmu sim --pty --firmware dist/mmu-firmware-pico.elf --board pico",
        Check::NotRun("serves until killed; host/tests/fil.rs serves both images with --stdio in CI"),
    ),
    ("cargo bench -p mmu-sim --bench toolchange", Check::InCi),
    (
        "cargo run --release -p mmu-sim --example unload_faults -- 200",
        Check::InCi,
    ),
    (
        "cargo run --release -p mmu-sim --example unload_faults -- 200 --longer-bowden",
        Check::NotRun("about 3 minutes; CI runs the table without the 2-5 m row"),
    ),
    (
        "bash scripts/soak-matrix.sh",
        Check::NotRun("about 20 minutes; sim/tests/soak.rs runs one seed of every combination in CI"),
    ),
    (
        "bash scripts/soak-matrix.sh --changes 200 --seeds 20 --hardware thesis",
        Check::NotRun("about 24 minutes; sim/tests/soak.rs runs one seed of every combination in CI"),
    ),
    (
        "bash scripts/soak-matrix.sh --changes 200 --seeds 20 --hardware thesis --extruders sensor-first,gears-first --jobs 2",
        Check::NotRun(
            "about 22 minutes; sim/tests/geometry.rs and restart_mid_tool_change.rs run both geometries in CI",
        ),
    ),
    (
        "bash scripts/soak-matrix.sh --changes 200 --seeds 20 --hardware n20-quadrature,bmcu-c --jobs 2",
        Check::NotRun("about 20 minutes; sim/tests/soak.rs runs one seed of every combination in CI"),
    ),
    (
        "bash scripts/soak-matrix.sh --changes 200 --seeds 20 --hardware thesis --faults power-loss --jobs 2",
        Check::NotRun("about 12 minutes; sim/tests/soak.rs cuts the power in every change of a short run"),
    ),
    (
        "cargo install cargo-fuzz",
        Check::NotRun("installs a tool; needs a nightly toolchain to use"),
    ),
    (
        "cargo +nightly fuzz run request_decoder  -- -max_total_time=60 -dict=fuzz/protocol.dict",
        Check::NotRun("needs a nightly toolchain and cargo-fuzz"),
    ),
    (
        "cargo +nightly fuzz run response_decoder -- -max_total_time=60 -dict=fuzz/protocol.dict",
        Check::NotRun("needs a nightly toolchain and cargo-fuzz"),
    ),
    (
        "cargo +nightly fuzz run app              -- -max_total_time=60",
        Check::NotRun("needs a nightly toolchain and cargo-fuzz"),
    ),
    (
        "curl -fsSL https://probe.rs/files/69-probe-rs.rules | sudo tee /etc/udev/rules.d/69-probe-rs.rules >/dev/null",
        Check::NotRun("installs udev rules: root and the network"),
    ),
    ("sudo udevadm control --reload", Check::NotRun("root, udev")),
    ("sudo udevadm trigger", Check::NotRun("root, udev")),
    ("docker build -t mmu-firmware .", Check::NotRun("needs Docker")),
    (
        "cargo install probe-rs-tools --locked",
        Check::NotRun("installs a tool (a compile of about 9 minutes)"),
    ),
    (
        "cargo fw-run",
        Check::NotRun("needs a NUCLEO-G071RB and probe-rs"),
    ),
    (
        "cargo fw-pico-run",
        Check::NotRun("needs a Pico, a debug probe and probe-rs"),
    ),
    (
        "cargo install --locked elf2uf2-rs --version 2.2.0 --no-default-features",
        Check::InCi,
    ),
    (
        "elf2uf2-rs dist/mmu-firmware-pico.elf dist/mmu-firmware-pico.uf2",
        Check::InCi,
    ),
    (
        "picocom --omap crlf --imap lfcrlf --echo /dev/pts/7",
        Check::NotRun("an interactive terminal program"),
    ),
    (
        "tio --map OCRNL,INLCRNL --local-echo /dev/pts/7",
        Check::NotRun("an interactive terminal program"),
    ),
    (
        "docker run --rm -it --privileged -v /dev/bus/usb:/dev/bus/usb mmu-firmware",
        Check::NotRun("needs Docker and a board"),
    ),
    (
        "DOCKER_BUILDKIT=1 docker build --target firmware --output dist .",
        Check::NotRun("needs Docker"),
    ),
    // Bring-up on the bench.
    ("mmu printer --port /dev/ttyUSB0 status", Check::OnPtyExits(0)),
    // Getting help.
    (
        "mmu printer --port /dev/ttyUSB0 settings save unit.txt",
        Check::OnPtyExits(0),
    ),
    ("mmu printer --port /dev/ttyUSB0 stats", Check::OnPtyExits(0)),
    ("mmu sensors --port /dev/ttyUSB0", Check::OnPtyInterrupted(500)),
    (
        "mmu sensors --port /dev/ttyUSB0 --plot hub.png --seconds 10",
        Check::OnPtyExits(0),
    ),
    ("t 1", Check::Exits(0)),
    ("read bowden", Check::Exits(0)),
    ("set bowden 410", Check::Exits(0)),
    ("status", Check::Exits(0)),
    ("motor 0", Check::Exits(0)),
    (
        "mmu calibrate --port /dev/ttyUSB0 --merge-mm 8",
        Check::NeedsHardware("a person presses Enter when the filament reaches the printer's sensor"),
    ),
    // A BMCU-C kit onto a Prusa printer.
    (
        "mmu printer --sim --hardware bmcu-c --slots 4 tool 3",
        Check::Exits(0),
    ),
    (
        "mmu printer --sim --hardware bmcu-c --slots 4 tool 4",
        Check::Exits(1),
    ),
    ("mmu console --port /dev/ttyUSB0", Check::OnPtyExits(0)),
    (
        "cargo install --locked wchisp --version 0.3.0",
        Check::NotRun("installs a tool from crates.io: the network"),
    ),
    (
        "wchisp --serial --port /dev/ttyUSB0 flash dist/mmu-firmware-bmcu.elf",
        Check::NotRun("needs a BMCU-C in its ROM bootloader"),
    ),
    // The simulator.
    (
        "cargo sim --pty --events /tmp/mmu-events.jsonl",
        Check::Interrupted(500),
    ),
    (
        "(sleep 0.2; cat requests; sleep 0.5) | cargo sim --stdio --time-scale 20 > answers",
        Check::Exits(0),
    ),
    (
        "(sleep 0.2; printf 'S0*c6\\nT1*00\\nR1b*9e\\n'; sleep 0.5) | cargo sim --stdio > /dev/null",
        Check::Exits(0),
    ),
    // The tool.
    ("mmu demo", Check::Exits(0)),
    ("mmu demo --fast", Check::Exits(0)),
    ("mmu printer --sim status", Check::Exits(0)),
    ("cargo printer --sim tool 1", Check::Exits(0)),
    ("cargo printer --sim --fault jam:1 tool 1", Check::Exits(1)),
    ("cargo printer --port /dev/ttyUSB0 status", Check::OnPtyExits(0)),
    (
        "cargo printer --port /dev/pts/7 --fsensor-events /tmp/mmu-events.jsonl eject 2",
        Check::OnPtyExits(0),
    ),
    ("cargo printer --port /dev/pts/7 stats", Check::OnPtyExits(0)),
    (
        "cargo printer --port /dev/ttyUSB0 settings save unit.txt",
        Check::OnPtyExits(0),
    ),
    (
        "cargo printer --port /dev/ttyUSB0 settings load unit.txt",
        Check::OnPtyExits(0),
    ),
    (
        "cargo printer --sim soak --changes 200 --faults random --seed 7",
        Check::InCi,
    ),
    (
        "cargo printer --sim --printer mk3s --spool-join soak --changes 40 --faults spool-ends --seed 1",
        Check::Exits(0),
    ),
    (
        "mmu sensors --port /dev/ttyUSB0 --csv > s.csv",
        Check::OnPtyInterrupted(500),
    ),
    (
        "mmu sensors --port /dev/ttyUSB0 --plot s.png --seconds 20",
        Check::OnPtyExits(0),
    ),
    (
        "mmu sensors --sim --fault noise:60 --plot s.png --seconds 5",
        Check::Exits(0),
    ),
    (
        "mmu sensors --port /dev/ttyUSB0 --sensor slot0.motion --every 1 --plot hall.png --seconds 2",
        Check::OnPtyExits(0),
    ),
    ("cargo console --sim", Check::Exits(0)),
    ("cargo console --port /dev/ttyUSB0", Check::OnPtyExits(0)),
    (
        "printf 't 1\\nread bowden\\nquit\\n' | cargo console --sim",
        Check::Exits(0),
    ),
    ("cargo calibrate --sim", Check::Exits(0)),
    (
        "cargo calibrate --port /dev/ttyUSB0 --merge-mm 8",
        Check::NeedsHardware("a person presses Enter when the filament reaches the printer's sensor"),
    ),
    (
        "cargo calibrate --port /dev/pts/7 --fsensor-events /tmp/mmu-events.jsonl bowden",
        Check::OnPtyExits(0),
    ),
    ("mmu motor --port /dev/ttyUSB0 0", Check::OnPtyExits(0)),
    ("mmu motor --sim 1", Check::Exits(0)),
    ("mmu motor --sim --fault motor-dead:0 0", Check::Exits(1)),
    ("mmu slots set 1 PETG red", Check::Exits(0)),
    ("mmu slots clear 1", Check::Exits(0)),
    ("mmu slots --port /dev/ttyUSB0", Check::OnPtyExits(0)),
    ("mmu slots --sim", Check::Exits(0)),
    ("mmu encode request T 1", Check::Exits(0)),
    ("mmu encode request X 42", Check::Exits(0)),
    ("mmu encode request W 0xb 5", Check::Exits(0)),
    ("mmu encode response T 0 E 0x8003", Check::Exits(0)),
    ("mmu encode response S 3 A 896", Check::Exits(0)),
    ("mmu encode response W 0x1b A", Check::Exits(0)),
    ("mmu encode request T 256", Check::Exits(2)),
    ("mmu encode request W 0xb", Check::Exits(2)),
    ("mmu decode < serial.log", Check::Exits(0)),
    ("mmu decode < octoprint-serial.log", Check::Exits(0)),
    ("mmu decode --frames-only < arduino-monitor.txt", Check::Exits(0)),
    (
        "printf 'T0*a4\\nX0 F0*86\\nhello\\n10:00:03.123 -> T1*cf\\n' | mmu decode --json",
        Check::Exits(0),
    ),
];

/// Every command of the README and the book.
fn all_shown() -> Vec<Shown> {
    documentation()
        .iter()
        .flat_map(|(page, text)| shown_commands(page, text))
        .collect()
}

/// Each command the book shows is in [`COMMANDS`], and each entry there is still in the book.
#[test]
fn every_command_in_the_book_has_a_check() {
    let shown = all_shown();
    let known: BTreeSet<&str> = COMMANDS.iter().map(|(command, _)| *command).collect();
    let unknown: Vec<String> = shown
        .iter()
        .filter(|s| !known.contains(s.command.as_str()))
        .map(|s| format!("{}:{}: {}", s.page, s.line, s.command))
        .collect();
    assert!(
        unknown.is_empty(),
        "commands in the book that no test or CI runs (add each to COMMANDS in host/tests/book.rs \
         with how it is checked):\n{}",
        unknown.join("\n")
    );
    // Say which are not run on this machine, and why.
    for (command, check) in COMMANDS {
        match check {
            Check::NotRun(why) => eprintln!("not run: `{command}`: {why}"),
            Check::NeedsHardware(why) => {
                eprintln!("arguments checked only (against a missing port): `{command}`: {why}")
            }
            _ => {}
        }
    }
    let in_book: BTreeSet<&str> = shown.iter().map(|s| s.command.as_str()).collect();
    let stale: Vec<&str> = known.iter().filter(|c| !in_book.contains(*c)).copied().collect();
    assert!(
        stale.is_empty(),
        "COMMANDS lists commands the book no longer shows: {stale:?}"
    );
}

/// The aliases the book uses run the `mmu` subcommand of the same name, built for release.
#[test]
fn the_cargo_aliases_are_the_mmu_subcommands() {
    let config = std::fs::read_to_string(root().join(".cargo/config.toml")).expect("readable");
    for alias in MMU_ALIASES {
        let line = format!("{alias} = \"run --release -p mmu-host --bin mmu -- {alias}\"");
        assert!(config.contains(&line), ".cargo/config.toml lacks {line}");
    }
}

/// The `cargo` aliases that run an `mmu` subcommand.
const MMU_ALIASES: &[&str] = &["demo", "sim", "printer", "console", "calibrate"];

/// The commands `.ci/run` must run itself.
#[test]
fn ci_runs_the_commands_the_book_leaves_to_it() {
    let ci = std::fs::read_to_string(root().join(".ci/run")).expect(".ci/run is readable");
    let ci_lines: BTreeSet<&str> = ci.lines().map(str::trim).collect();
    for (command, check) in COMMANDS {
        if matches!(check, Check::InCi) {
            let as_in_ci = command.replace("mdbook build book", "\"$MDBOOK\" build book");
            assert!(
                ci_lines.contains(command) || ci_lines.contains(as_in_ci.as_str()),
                ".ci/run does not run `{command}`, which the book leaves to CI"
            );
        }
    }
}

/// The shell command to run for `command`: the `mmu` binary for `cargo <alias>` and `cargo run
/// ... --bin mmu --`, the simulator's port and events file for a real unit's.
fn as_run_here(command: &str, port: Option<(&str, &Path)>) -> String {
    let mut command = command
        .replace("cargo run -p mmu-host --bin mmu -- ", "mmu ")
        .replace("cargo run --release -p mmu-host --bin mmu -- ", "mmu ");
    for alias in MMU_ALIASES {
        command = command.replace(&format!("cargo {alias}"), &format!("mmu {alias}"));
    }
    if let Some((pty, events)) = port {
        let events = events.to_str().expect("UTF-8 path");
        command = command
            .replace("/dev/ttyUSB0", pty)
            .replace("/dev/pts/7", pty)
            .replace("/tmp/mmu-events.jsonl", events);
    }
    command
}

/// A fresh working folder with the files the examples read.
fn workdir(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("book-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("the work folder can be made");
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/book");
    for entry in std::fs::read_dir(fixtures).expect("the fixtures are readable") {
        let path = entry.expect("a fixture").path();
        std::fs::copy(&path, dir.join(path.file_name().expect("a file"))).expect("copied");
    }
    dir
}

/// `bash -c COMMAND` in `dir` with the `mmu` under test first on the PATH.
fn shell(command: &str, dir: &Path) -> Command {
    let bin = Path::new(env!("CARGO_BIN_EXE_mmu")).parent().expect("a folder");
    let path = format!("{}:{}", bin.display(), std::env::var("PATH").unwrap_or_default());
    let mut shell = Command::new("bash");
    shell
        .args(["-c", command])
        .current_dir(dir)
        .env("PATH", path)
        // The console's files (slot map, statistics) stay in the work folder, not the user's.
        .env("MMU_CONFIG_DIR", dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped());
    shell
}

/// Wait for `child` at most `limit`; its output, or a panic naming `what`.
fn finish(mut child: Child, limit: Duration, what: &str) -> Output {
    let deadline = Instant::now() + limit;
    while child.try_wait().expect("waitable").is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("`{what}` did not end within {limit:?}");
        }
        thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().expect("its output")
}

/// Run `command` (a shell line) in `dir` and press Ctrl-C `ms` after it showed a sign of life:
/// the simulator's terminal, `mmu sensors` saying it reads until Ctrl-C, or the first rows in
/// the file it writes to.
fn run_interrupted(command: &str, dir: &Path, ms: u64) -> Output {
    let file = command.split("> ").nth(1).map(|name| dir.join(name.trim()));
    let ready = if command.contains("sim --pty") {
        "/dev/"
    } else {
        "Ctrl-C"
    };
    let shell = shell(&format!("exec {command}"), dir);
    let run = interrupt_when_ready(shell, None, ready, file.as_deref(), ms);
    Output {
        status: exit_status(run.code),
        stdout: run.stdout.into_bytes(),
        stderr: run.stderr.into_bytes(),
    }
}

/// An exit status with `code` (`None`: ended by a signal, as the simulator is).
fn exit_status(code: Option<i32>) -> std::process::ExitStatus {
    use std::os::unix::process::ExitStatusExt;
    match code {
        Some(code) => std::process::ExitStatus::from_raw(code << 8),
        None => std::process::ExitStatus::from_raw(2), // ended by SIGINT
    }
}

/// `mmu sim --pty` serving for one command, killed when dropped.
struct PtyUnit {
    child: Child,
    path: String,
    events: PathBuf,
}

impl PtyUnit {
    /// A unit at `time_scale` × real time.
    fn start(dir: &Path, time_scale: &str) -> PtyUnit {
        let events = dir.join("mmu-events.jsonl");
        let mut child = Command::new(env!("CARGO_BIN_EXE_mmu"))
            .args(["sim", "--pty", "--quiet", "--time-scale", time_scale, "--events"])
            .arg(&events)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("mmu sim runs");
        let mut path = String::new();
        BufReader::new(child.stdout.take().expect("piped"))
            .read_line(&mut path)
            .expect("mmu sim prints its terminal's path");
        // As a printer does, let the unit start before talking to it.
        thread::sleep(Duration::from_millis(200));
        PtyUnit {
            child,
            path: path.trim().to_string(),
            events,
        }
    }
}

impl Drop for PtyUnit {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// What a run printed, stdout then stderr, as lines.
fn printed(output: &Output) -> Vec<String> {
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    text.lines().map(str::to_string).collect()
}

/// Run one shown command as [`COMMANDS`] says; a description of what went wrong, if anything.
fn check(shown: &Shown, how: Check, index: usize) -> Option<String> {
    let dir = workdir(&index.to_string());
    let place = format!("{}:{}: `{}`", shown.page, shown.line, shown.command);
    let limit = Duration::from_secs(240);
    let (output, expected) = match how {
        Check::InCi | Check::NotRun(_) => return None,
        Check::NeedsHardware(_) => {
            let missing = dir.join("no-such-port");
            let command = as_run_here(&shown.command, None).replace("/dev/ttyUSB0", missing.to_str()?);
            let child = shell(&command, &dir).spawn().expect("bash runs");
            let output = finish(child, limit, &command);
            let text = printed(&output).join("\n");
            if output.status.code() != Some(1) || !text.contains("no-such-port") {
                return Some(format!(
                    "{place}: against a missing port it should fail to open it (exit 1), got {:?}:\n{text}",
                    output.status.code()
                ));
            }
            return None;
        }
        Check::Exits(code) if shown.console => {
            let script = format!("{}\nquit\n", shown.command);
            let command = format!("printf '%s' '{script}' | mmu console --sim");
            let child = shell(&command, &dir).spawn().expect("bash runs");
            (finish(child, limit, &command), Some(code))
        }
        Check::Exits(code) => {
            let command = as_run_here(&shown.command, None);
            let child = shell(&command, &dir).spawn().expect("bash runs");
            (finish(child, limit, &command), Some(code))
        }
        Check::Interrupted(ms) => {
            let events = dir.join("mmu-events.jsonl");
            let command = as_run_here(&shown.command, Some(("/dev/null", &events)));
            (run_interrupted(&command, &dir, ms), None)
        }
        Check::OnPtyExits(_) | Check::OnPtyInterrupted(_) => {
            // The motor test reads while the motor turns: at real time, as on a real unit.
            let time_scale = if shown.command.contains("motor") { "1" } else { "5" };
            let unit = PtyUnit::start(&dir, time_scale);
            let command = as_run_here(&shown.command, Some((&unit.path, &unit.events)));
            if command.contains("settings load") {
                let save = command.replace("settings load", "settings save");
                let child = shell(&save, &dir).spawn().expect("bash runs");
                finish(child, limit, &save);
            }
            match how {
                Check::OnPtyInterrupted(ms) => (run_interrupted(&command, &dir, ms), Some(130)),
                Check::OnPtyExits(code) => {
                    let child = shell(&command, &dir).spawn().expect("bash runs");
                    (finish(child, limit, &command), Some(code))
                }
                _ => unreachable!("matched above"),
            }
        }
    };
    let status = output.status.code();
    let lines = printed(&output);
    match expected {
        Some(code) if status != Some(code) => {
            return Some(format!(
                "{place}: exit status {status:?}, the book means {code}:\n{}",
                lines.join("\n")
            ));
        }
        // Interrupted: 130 from `mmu`, or ended by the signal itself (the simulator serves
        // until killed).
        None if !(status == Some(130) || status.is_none()) => {
            return Some(format!(
                "{place}: Ctrl-C gave exit status {status:?}:\n{}",
                lines.join("\n")
            ));
        }
        _ => {}
    }
    if !shown.output.is_empty() && !matches!(how, Check::OnPtyExits(_)) {
        let wanted: Vec<&str> = shown.output.iter().map(String::as_str).collect();
        let got: Vec<&str> = lines.iter().map(String::as_str).collect();
        let comparable = |line: &str| without_clock(line);
        let wanted: Vec<String> = wanted.iter().map(|l| comparable(l)).collect();
        let got: Vec<String> = got.iter().map(|l| comparable(l)).collect();
        if wanted != got {
            return Some(format!(
                "{place}: the book shows\n{}\nbut the tool printed\n{}",
                wanted.join("\n"),
                got.join("\n")
            ));
        }
    }
    None
}

/// A simulator log line without its clock (`mmu sim:     0.194 s  ...`), which moves a
/// millisecond from run to run; every other line as it is.
fn without_clock(line: &str) -> String {
    match line.strip_prefix("mmu sim: ") {
        Some(rest) if rest.split_whitespace().nth(1) == Some("s") => {
            let after = rest.trim_start().splitn(3, ' ').nth(2).unwrap_or("");
            format!("mmu sim: <t> s {}", after.trim_start())
        }
        _ => line.to_string(),
    }
}

/// Every command the book shows that can run here, runs and ends as the book says; where a block
/// shows the output, the tool prints exactly that.
#[test]
fn every_command_in_the_book_works() {
    let checks: BTreeMap<&str, Check> = COMMANDS.iter().copied().collect();
    let shown = all_shown();
    let runs: Vec<(usize, Shown, Check)> = shown
        .into_iter()
        .enumerate()
        .filter_map(|(index, s)| checks.get(s.command.as_str()).map(|&how| (index, s, how)))
        .collect();
    // All at once: most of them wait on a simulator's real-time clock, not on the CPU.
    let handles: Vec<_> = runs
        .into_iter()
        .map(|(index, s, how)| thread::spawn(move || check(&s, how, index)))
        .collect();
    let failures: Vec<String> = handles
        .into_iter()
        .filter_map(|handle| handle.join().expect("a check thread ends"))
        .collect();
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// The `mmu` commands the book's prose names in inline code (`mmu slots set 0 PLA white`): their
/// subcommands and options exist. Each is parsed with `--help` added (which prints the help
/// instead of running it): a misspelt option or subcommand fails with status 2. Placeholders
/// become examples (`DEV` a port, `N` and `S` numbers); mentions that stop at an option waiting
/// for its value (`mmu printer --port`) or elide arguments (`...`) are only mentions.
#[test]
fn every_mmu_command_named_in_the_prose_parses() {
    let mut checked = 0;
    let mut failures = Vec::new();
    for (page, text) in documentation() {
        for (number, line) in prose_lines(&text) {
            for (index, span) in line.split('`').enumerate() {
                if index % 2 == 0 {
                    continue;
                }
                let mut words: Vec<String> = span.split_whitespace().map(str::to_string).collect();
                let is_mmu = words.first().is_some_and(|w| w == "mmu");
                let is_alias = words.first().is_some_and(|w| w == "cargo")
                    && words.get(1).is_some_and(|w| MMU_ALIASES.contains(&w.as_str()));
                if !(is_mmu || is_alias) {
                    continue;
                }
                // `cargo demo ...` is `mmu demo ...`: drop `cargo`; `mmu ...`: drop `mmu`.
                words.remove(0);
                let mention = words.is_empty()
                    || span.contains("...")
                    || words
                        .last()
                        .is_some_and(|w| w.starts_with("--") && takes_a_value(w));
                if mention {
                    continue;
                }
                let args: Vec<String> = words
                    .iter()
                    .map(|w| match w.as_str() {
                        "DEV" => "/dev/ttyUSB0".to_string(),
                        "N" | "S" => "3".to_string(),
                        other => other.to_string(),
                    })
                    .chain(["--help".to_string()])
                    .collect();
                let output = Command::new(env!("CARGO_BIN_EXE_mmu"))
                    .args(&args)
                    .output()
                    .expect("mmu runs");
                checked += 1;
                if !output.status.success() {
                    failures.push(format!(
                        "{page}:{number}: `{span}`: {}",
                        String::from_utf8_lossy(&output.stderr).trim()
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert!(checked >= 10, "only {checked} commands found in the prose");
}

/// Whether option `flag` takes a value (so a mention ending with it names the option only).
fn takes_a_value(flag: &str) -> bool {
    !matches!(
        flag,
        "--sim"
            | "--pty"
            | "--stdio"
            | "--fast"
            | "--json"
            | "--csv"
            | "--frames-only"
            | "--verbose"
            | "--quiet"
            | "--help"
            | "--version"
    )
}
