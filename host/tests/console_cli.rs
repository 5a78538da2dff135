//! End-to-end tests of `mmu console` and `mmu calibrate`: scripted sessions through a pipe, as a
//! user scripts them, against the in-process simulator and against `mmu sim --pty` over its
//! pseudo-terminal.

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::Duration;

mod common;

use common::{mmu_with_input as mmu_with_script, text};

/// The README's example: one line loads slot 1 and says so in words.
#[test]
fn a_piped_tool_change_loads_the_slot_and_says_so() {
    let output = mmu_with_script(&["console", "--sim"], "t 1\nquit\n");
    let out = text(&output);
    assert!(output.status.success(), "{out}");
    assert!(out.contains("mmu> t 1"), "the script is echoed: {out}");
    assert!(
        out.contains("slot 1 is loaded: its filament is in the printer's extruder"),
        "{out}"
    );
}

/// `status` after a tool change and a print: the slot's filament left, with its uncertainty, and
/// its health; the spool length set by name.
#[test]
fn status_shows_filament_left_and_lane_health() {
    let output = mmu_with_script(
        &["console", "--sim"],
        "set spool_m.slot1 500\nt 1\nwait 60\nstatus\nquit\n",
    );
    let out = text(&output);
    assert!(output.status.success(), "{out}");
    assert!(
        out.contains("slot 0: 330 m left of a 330 m spool (± 1 m)"),
        "{out}"
    );
    assert!(
        out.contains("slot 1: 500 m left of a 500 m spool (± 1 m)"),
        "{out}"
    );
    assert!(out.contains("slot 1 health: drag "), "{out}");
    assert!(
        out.contains("100 % of the last tool change without help"),
        "{out}"
    );
}

/// A session a maker scripts: a tool change, registers read by name and address and set, then a
/// jam (injected in the simulator) that stops a tool change on an explained error, is cleared,
/// and Retry finishes it.
#[test]
fn a_scripted_session_reads_sets_and_retries_an_error() {
    let script = "\
t 1
read bowden
set bowden 355
read 0x22
read hub.filament
sim fault jam:2
t 2
sim clear
retry
status
quit
";
    let output = mmu_with_script(&["console", "--sim"], script);
    let out = text(&output);
    assert!(output.status.success(), "{out}");
    assert!(out.contains("slot 1 is loaded"), "{out}");
    assert!(out.contains("bowden_mm (0x22) = 360"), "{out}");
    assert!(out.contains("bowden_mm (0x22) = 355: accepted"), "{out}");
    assert!(out.contains("mmu> read 0x22\nbowden_mm (0x22) = 355"), "{out}");
    assert!(out.contains("filtered.hub.filament (0x70) = "), "{out}");
    // The jam: the printer retries by itself, then the person is told what happened and what to do.
    assert!(out.contains("T2: auto Retry (0 left)"), "{out}");
    assert!(out.contains("T2 stopped: STALLED_PULLEY"), "{out}");
    assert!(out.contains("what to do: "), "{out}");
    assert!(
        out.contains("the printer shows PULLEY CANNOT MOVE (prusa.io/04105) with retry (B1)"),
        "{out}"
    );
    assert!(
        out.contains("error> retry"),
        "the answer comes from the script: {out}"
    );
    assert!(
        out.contains("slot 2 is loaded"),
        "Retry finished the tool change: {out}"
    );
    assert!(out.contains("slot 2: loaded in the printer's extruder"), "{out}");
}

/// A script whose command fails ends with a non-zero exit status and says why.
#[test]
fn a_failed_scripted_command_fails_the_session() {
    let output = mmu_with_script(&["console", "--sim"], "t 7\nread nothing\nt 0\n");
    let out = text(&output);
    assert!(!output.status.success(), "{out}");
    assert!(out.contains("the unit has no slot 7 (it has 3)"), "{out}");
    assert!(out.contains("no register named \"nothing\""), "{out}");
    assert!(
        out.contains("slot 0 is loaded"),
        "the script goes on after a failure: {out}"
    );
    assert!(out.contains("2 command(s) of the script failed"), "{out}");
}

/// `mmu calibrate --sim` finds the simulated unit's true values (2.00 mm per revolution within
/// one revolution over the 95 mm slot-to-hub path, the 360 mm Bowden within two revolutions)
/// and saves them, on several seeds (the sensors' noise and the motors' Hall phases differ).
#[test]
fn calibrate_finds_the_simulator_s_values() {
    for seed in ["1", "2", "5"] {
        calibrate_on_seed(seed);
    }
}

fn calibrate_on_seed(seed: &str) {
    let output = mmu_with_script(&["calibrate", "--sim", "--seed", seed], "");
    let out = text(&output);
    assert!(output.status.success(), "{out}");
    let number_after = |prefix: &str| -> f64 {
        let line = out
            .lines()
            .find(|line| line.starts_with(prefix))
            .unwrap_or_else(|| panic!("no {prefix:?} line: {out}"));
        line[prefix.len()..]
            .split_whitespace()
            .next()
            .and_then(|n| n.parse().ok())
            .unwrap_or_else(|| panic!("no number in {line:?}"))
    };
    let mm_per_rev = number_after("mm per motor revolution: ");
    assert!((mm_per_rev - 2.0).abs() <= 0.06, "{mm_per_rev} mm/rev: {out}");
    let bowden = number_after("Bowden length: ");
    // In the unit's own mm; the odometry lags by up to a revolution at each end.
    let real = bowden * 2.0 / mm_per_rev;
    assert!(
        (real - 360.0).abs() <= 4.0,
        "{bowden} unit mm = {real:.1} mm: {out}"
    );
    assert!(out.contains("hub filament sensor: "), "{out}");
    assert!(out.contains("calibration saved in the unit"), "{out}");
}

/// A running `mmu sim`, killed when dropped.
struct SimProcess(Child);

impl Drop for SimProcess {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The console drives `mmu sim --pty` over its pseudo-terminal as over a serial port, the
/// printer's sensor following the simulator's events file.
#[test]
fn the_console_drives_the_simulator_over_a_pty() {
    let events: PathBuf =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("console-events-{}.jsonl", std::process::id()));
    File::create(&events).expect("the events file can be created");
    let events = events.to_str().expect("a UTF-8 path").to_string();
    let mut sim = SimProcess(
        Command::new(env!("CARGO_BIN_EXE_mmu"))
            .args([
                "sim",
                "--pty",
                "--time-scale",
                "5",
                "--quiet",
                "--events",
                &events,
            ])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the mmu binary runs"),
    );
    let stdout = sim.0.stdout.take().expect("stdout is piped");
    let (sender, receiver) = mpsc::channel();
    thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(stdout).read_line(&mut line);
        let _ = sender.send(line);
    });
    let path = receiver
        .recv_timeout(Duration::from_secs(10))
        .expect("mmu sim prints the pty's path");
    let path = path.trim_end();
    let output = mmu_with_script(
        &["console", "--port", path, "--fsensor-events", &events],
        "t 1\nread lane.slot1\nunload\neject 2\ncontinue\nquit\n",
    );
    let out = text(&output);
    assert!(output.status.success(), "{out}");
    assert!(out.contains("connected: unit firmware 3.0.3"), "{out}");
    assert!(out.contains("slot 1 is loaded"), "{out}");
    assert!(
        out.contains("lane.slot1 (0xb9) = 8 (loaded in the printer's extruder)"),
        "{out}"
    );
    assert!(
        out.contains("unloaded: the filament is back at its park position"),
        "{out}"
    );
    // Nobody can pull the filament out of a unit behind a serial port but the person: asked.
    assert!(
        out.contains("Pull the filament out of slot 2, then press Enter"),
        "{out}"
    );
    assert!(out.contains("eject> continue"), "{out}");
    assert!(out.contains("slot 2 is ejected"), "{out}");
    assert!(!out.contains("link lost"), "{out}");
}

/// The protocol is on USART1 (PB6/PB7; Pico: UART0, GP0/GP1), reached through a USB-serial adapter; the NUCLEO's
/// `/dev/ttyACM0` is its ST-LINK port, which the firmware leaves free. Neither the book's (and
/// the README's) examples nor the tool's help may send a user there.
#[test]
fn real_unit_examples_name_the_adapter_not_the_st_link_port() {
    let pages = common::documentation();
    for (page, text) in &pages {
        assert!(
            !text.contains("--port /dev/ttyACM0"),
            "{page} still says --port /dev/ttyACM0"
        );
    }
    assert!(pages.iter().any(|(_, text)| text.contains("--port /dev/ttyUSB0")));
    for command in ["printer", "console", "calibrate", "sensors"] {
        let output = Command::new(env!("CARGO_BIN_EXE_mmu"))
            .args([command, "--help"])
            .output()
            .expect("the mmu binary runs");
        let help = String::from_utf8_lossy(&output.stdout);
        let port_help = help
            .split("--port <DEV>")
            .nth(1)
            .and_then(|rest| rest.split("\n\n").next())
            .unwrap_or_else(|| panic!("mmu {command} --help has no --port: {help}"));
        assert!(port_help.contains("/dev/ttyUSB0"), "mmu {command}: {port_help}");
        assert!(
            !port_help.contains("e.g. /dev/ttyACM0"),
            "mmu {command}: {port_help}"
        );
    }
}
