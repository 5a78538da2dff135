//! End-to-end tests of `mmu printer` and `mmu demo` against the in-process simulator, as a user
//! runs them. The simulator runs in virtual time, so each run takes a fraction of a second.

use std::process::{Command, Output};

use serde_json::Value;

mod common;

use common::mmu;

fn stdout(output: &Output) -> String {
    String::from_utf8(output.stdout.clone()).expect("stdout is UTF-8")
}

fn stderr(output: &Output) -> String {
    String::from_utf8(output.stderr.clone()).expect("stderr is UTF-8")
}

/// `mmu printer --sim args...`, which must succeed; its stdout.
fn printer_ok(args: &[&str]) -> String {
    let mut full = vec!["printer", "--sim"];
    full.extend_from_slice(args);
    let output = mmu(&full);
    assert!(
        output.status.success(),
        "{args:?} failed:\n{}{}",
        stdout(&output),
        stderr(&output)
    );
    stdout(&output)
}

/// `mmu printer --sim args...`, which must fail; its stdout and stderr together.
fn printer_fails(args: &[&str]) -> String {
    let mut full = vec!["printer", "--sim"];
    full.extend_from_slice(args);
    let output = mmu(&full);
    let text = format!("{}{}", stdout(&output), stderr(&output));
    assert!(!output.status.success(), "{args:?} should fail:\n{text}");
    text
}

/// The JSON objects of `mmu printer --sim --json args...`, one per line, and whether it succeeded.
fn printer_json(args: &[&str]) -> (Vec<Value>, bool) {
    let mut full = vec!["printer", "--sim", "--json"];
    full.extend_from_slice(args);
    let output = mmu(&full);
    let lines = stdout(&output)
        .lines()
        .map(|line| serde_json::from_str(line).unwrap_or_else(|e| panic!("{line:?}: {e}")))
        .collect();
    (lines, output.status.success())
}

fn events<'a>(lines: &'a [Value], kind: &str) -> Vec<&'a Value> {
    lines.iter().filter(|line| line["event"] == kind).collect()
}

#[test]
fn a_tool_change_names_its_phases_and_finishes() {
    let out = printer_ok(&["tool", "1"]);
    assert!(out.contains("connected: unit firmware 3.0.3"), "{out}");
    assert!(out.contains("T1: FeedingToFSensor"), "{out}");
    assert!(out.contains("T1: finished OK"), "{out}");
}

#[test]
fn json_output_is_one_object_per_line_ending_in_the_result() {
    let (lines, ok) = printer_json(&["tool", "1"]);
    assert!(ok);
    assert_eq!(events(&lines, "connected").len(), 1, "{lines:?}");
    let progress = events(&lines, "progress");
    assert!(
        progress
            .iter()
            .any(|p| p["name"] == "FeedingToFSensor" && p["code"] == 28)
    );
    let finished = events(&lines, "finished");
    assert_eq!(finished.len(), 1, "{lines:?}");
    assert_eq!(finished[0]["request"], "T1");
    assert_eq!(finished[0]["result"], "OK");
    assert!(finished[0]["duration_ms"].as_u64().is_some_and(|ms| ms > 1000));
    let last = lines.last().expect("some output");
    assert_eq!(last["event"], "result");
    assert_eq!(last["action"], "tool");
    assert_eq!(last["ok"], true);
}

#[test]
fn a_slot_the_unit_lacks_is_rejected() {
    let text = printer_fails(&["tool", "7"]);
    assert!(text.contains("T7: rejected by the unit"), "{text}");
    assert!(text.contains("INVALID_TOOL (printer screen 04502)"), "{text}");
    // Only the protocol's limit is checked before asking the unit.
    let output = mmu(&["printer", "--sim", "tool", "256"]);
    assert_eq!(output.status.code(), Some(2));
    assert!(stderr(&output).contains("too large"));
}

#[test]
fn eject_shows_the_dialog_and_continues() {
    let out = printer_ok(&["eject", "1"]);
    assert!(out.contains("FILAMENT_EJECTED (screen 04507)"), "{out}");
    assert!(out.contains("[Continue]"), "{out}");
    assert!(out.contains("pulls the filament out of slot 1"), "{out}");
    assert!(out.contains("Continue pressed (B1)"), "{out}");
    assert!(out.contains("E1: finished OK"), "{out}");
}

#[test]
fn cut_with_nothing_in_finda_goes_straight_to_k() {
    // Each run has a fresh simulator with nothing in FINDA, so no `U0` first; the demo shows the
    // unload before an eject.
    let out = printer_ok(&["cut", "2"]);
    assert!(!out.contains("unloads first"), "{out}");
    assert!(out.contains("K2: finished OK"), "{out}");
}

#[test]
fn a_jam_ends_in_its_named_error_after_three_automatic_retries() {
    let text = printer_fails(&["--fault", "jam:1", "tool", "1"]);
    assert!(text.contains("sim: fault jam:1 injected"), "{text}");
    assert!(
        text.contains("T1: error STALLED_PULLEY (printer screen 04105)"),
        "{text}"
    );
    for left in [2, 1, 0] {
        assert!(text.contains(&format!("T1: auto Retry ({left} left)")), "{text}");
    }
    assert_eq!(text.matches("auto Retry").count(), 3, "{text}");
    assert!(
        text.contains(
            "mmu: error: T1 (tool change slot 1) stopped on error STALLED_PULLEY (printer screen 04105)"
        ),
        "{text}"
    );

    let (lines, ok) = printer_json(&["--fault", "jam:1", "tool", "1"]);
    assert!(!ok);
    assert_eq!(events(&lines, "retry").len(), 3, "{lines:?}");
    let last = lines.last().expect("some output");
    assert_eq!(last["ok"], false);
    assert_eq!(last["error"], "STALLED_PULLEY");
    assert_eq!(last["screen"], "04105");
}

#[test]
fn registers_read_and_write() {
    let out = printer_ok(&["read", "0x00"]);
    assert!(out.contains("register 0x00 Project_Major = 3"), "{out}");
    let (lines, ok) = printer_json(&["read", "0"]);
    assert!(ok);
    assert_eq!(lines.last().expect("some output")["value"], 3);

    let out = printer_ok(&["write", "0x0b", "30"]);
    assert!(
        out.contains("write register 0x0b Extra_Load_Distance = 30: accepted"),
        "{out}"
    );
    let text = printer_fails(&["write", "0x99", "1"]);
    assert!(text.contains("rejected by the unit"), "{text}");
}

#[test]
fn status_shows_version_state_and_registers() {
    let out = printer_ok(&["status"]);
    for expected in [
        "unit firmware: 3.0.3, build 896",
        "state (Q0): X0 F0 (finished OK)",
        "hub filament sensor (FINDA): no filament",
        "register 0x08 FINDA_State = 0",
        "register 0x1b Selector_Slot",
    ] {
        assert!(out.contains(expected), "{expected:?} missing:\n{out}");
    }
}

#[test]
fn status_shows_each_spool_s_filament_left_and_lane_health() {
    let out = printer_ok(&["status"]);
    for expected in [
        "slot 0: 330 m left of a 330 m spool (± 1 m)",
        "slot 2: 330 m left of a 330 m spool (± 1 m)",
        "slot 1 health: no tool change yet, 0 stalls",
    ] {
        assert!(out.contains(expected), "{expected:?} missing:\n{out}");
    }
    let (lines, ok) = printer_json(&["status"]);
    assert!(ok);
    let result = events(&lines, "result");
    let lanes = result[0]["lanes"].as_array().unwrap();
    assert_eq!(lanes.len(), 3);
    assert_eq!(lanes[1]["left_m"], 330);
    assert_eq!(lanes[1]["spool_m"], 330);
    assert_eq!(lanes[1]["left_error_m"], 1);
    assert_eq!(lanes[1]["success_of"], 0);
    assert_eq!(result[0]["lane_warnings"], 0);
}

#[test]
fn reset_reconnects_and_shows_the_first_answer() {
    let out = printer_ok(&["reset"]);
    assert!(out.contains("link lost (timeout)"), "{out}");
    assert!(out.contains("after the reset, Q0: X0 F0"), "{out}");
}

#[test]
fn a_printer_expecting_another_version_stops() {
    // 3.0.0 to 3.0.2 are negotiated (the unit offers the next revision when S2 is asked again);
    // an MMU2S-era printer expecting 2.1.9 is not.
    printer_ok(&["--expect-version", "3.0.2", "status"]);
    let text = printer_fails(&["--expect-version", "2.1.9", "status"]);
    assert!(
        text.contains("MMU FW UPDATE NEEDED, printer screen 04504"),
        "{text}"
    );
}

#[test]
fn each_printer_is_played_with_its_version_and_its_poll() {
    for (printer, version, polls_bowden) in [
        ("buddy-6.5", "3.0.4", true),
        ("buddy-6.4", "3.0.3", true),
        ("mk3s", "3.0.2", false),
    ] {
        let out = printer_ok(&["--printer", printer, "status"]);
        assert!(
            out.contains(&format!("unit firmware: {version}")),
            "{printer}: {out}"
        );
        assert_eq!(out.contains("register 0x22"), polls_bowden, "{printer}: {out}");
    }
    let text = printer_fails(&["--printer", "mk4", "status"]);
    assert!(text.contains("buddy-6.5, buddy-6.4, mk3s"), "{text}");
}

#[test]
fn buddy_6_5_leaves_a_tool_change_early_and_says_so() {
    let (lines, ok) = printer_json(&["--printer", "buddy-6.5", "tool", "1"]);
    assert!(ok, "{lines:?}");
    let early = events(&lines, "premature_finish");
    assert_eq!(early.len(), 1, "{lines:?}");
    assert_eq!(early[0]["request"], "T1");
    let (lines, ok) = printer_json(&["--printer", "buddy-6.4", "tool", "1"]);
    assert!(ok && events(&lines, "premature_finish").is_empty(), "{lines:?}");
}

#[test]
fn soak_runs_each_printer() {
    for printer in ["buddy-6.4", "mk3s"] {
        let out = printer_ok(&["--printer", printer, "soak", "--changes", "3"]);
        assert!(out.starts_with("soak: 3 tool changes"), "{printer}: {out}");
    }
}

#[test]
fn soak_runs_buddy_6_5() {
    let out = printer_ok(&[
        "--printer",
        "buddy-6.5",
        "soak",
        "--changes",
        "20",
        "--faults",
        "random",
    ]);
    assert!(out.starts_with("soak: 20 tool changes"), "{out}");
}

#[test]
fn the_unit_must_be_chosen() {
    let output = mmu(&["printer", "status"]);
    assert!(!output.status.success());
    assert!(stderr(&output).contains("--port DEV"), "{}", stderr(&output));
}

#[test]
fn soak_prints_its_report() {
    let out = printer_ok(&["soak", "--changes", "2"]);
    assert!(out.starts_with("soak: 2 tool changes"), "{out}");
}

#[test]
fn the_demo_runs_its_script() {
    let output = mmu(&["demo", "--fast"]);
    let out = stdout(&output);
    assert!(output.status.success(), "{out}{}", stderr(&output));
    for expected in [
        "connected: unit firmware 3.0.3",
        "T2: finished OK",
        "the hub filament sensor (the printer's FINDA) sees filament: the printer unloads first",
        "E1: printer dialog FILAMENT_EJECTED",
        "L1: finished OK",
        "demo: 5 tool changes (T0 ",
    ] {
        assert!(out.contains(expected), "{expected:?} missing:\n{out}");
    }
    // Commands follow each other as on a printer: the link never times out.
    assert!(!out.contains("link lost"), "{out}");
}

/// Before: `S2 answered Some(2)`, a Rust `Option` in a user message, with no way out.
#[test]
fn a_version_mismatch_says_what_the_unit_reports_and_what_to_do() {
    // 3.0.0 to 3.0.4 are negotiated; a revision the unit does not speak fails.
    let text = printer_fails(&["--expect-version", "3.0.5", "status"]);
    assert!(!text.contains("Some("), "{text}");
    assert!(text.contains("the printer expects 3.0.5"), "{text}");
    assert!(text.contains("--expect-version 3.0."), "{text}");
    assert!(text.contains("speaks MMU 3.0.0 to 3.0.4"), "{text}");
}

/// Before: `printer --slots 9` exited 1, `sim --slots 9` 2; `--fault jam:7` on 3 slots was
/// accepted. Every usage mistake now exits 2, as clap's own do, and says why.
#[test]
fn usage_mistakes_exit_2_everywhere() {
    for (args, message) in [
        (
            &["printer", "--sim", "--slots", "9", "status"][..],
            "1 to 5 slots",
        ),
        (&["sim", "--stdio", "--slots", "9"], "1 to 5 slots"),
        (&["printer", "status"], "--port DEV"),
        (&["printer", "--sim", "--fault", "jam:7", "status"], "no slot 7"),
        (&["sim", "--stdio", "--fault", "jam:7"], "no slot 7"),
        (
            &["sim", "--stdio", "--fault", "disconnect:motor-hall-3"],
            "no slot 3",
        ),
        (
            &[
                "printer", "--sim", "--slots", "2", "--fault", "runout:2", "status",
            ],
            "no slot 2",
        ),
        (&["printer", "--port", "/dev/null", "soak"], "simulator"),
        (&["encode", "request", "W", "0xb"], "VALUE2"),
        (&["sensors"], "--port DEV"),
        (&["console"], "--port DEV"),
        (&["calibrate"], "--port DEV"),
    ] {
        let output = Command::new(env!("CARGO_BIN_EXE_mmu"))
            .args(args)
            .stdin(std::process::Stdio::null())
            .output()
            .expect("the mmu binary runs");
        let text = format!("{}{}", stdout(&output), stderr(&output));
        assert_eq!(output.status.code(), Some(2), "{args:?}: {text}");
        assert!(text.contains(message), "{args:?}: {text:?} lacks {message:?}");
    }
}

/// Before: Ctrl-C during a soak lost the report.
#[cfg(target_os = "linux")]
#[test]
fn soak_prints_its_report_on_ctrl_c() {
    let child = Command::new(env!("CARGO_BIN_EXE_mmu"))
        .args(["printer", "--sim", "soak", "--changes", "1000000"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("the mmu binary runs");
    // Signal only once the tool catches SIGINT (Linux shows it in /proc), whatever the load.
    let caught = std::path::PathBuf::from(format!("/proc/{}/status", child.id()));
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
    let catches_sigint = || {
        std::fs::read_to_string(&caught).ok().is_some_and(|status| {
            status
                .lines()
                .find_map(|line| line.strip_prefix("SigCgt:"))
                .and_then(|mask| u64::from_str_radix(mask.trim(), 16).ok())
                .is_some_and(|mask| mask & (1 << (2 - 1)) != 0)
        })
    };
    while !catches_sigint() && caught.exists() {
        assert!(std::time::Instant::now() < deadline, "mmu never caught SIGINT");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    std::thread::sleep(std::time::Duration::from_millis(300));
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(status.success());
    let output = child.wait_with_output().expect("mmu finishes");
    let out = stdout(&output);
    assert!(out.starts_with("soak: "), "{out}{}", stderr(&output));
    assert!(out.contains("stopped after change"), "{out}");
    assert_eq!(output.status.code(), Some(130), "{}", stderr(&output));
}

/// Errors come with what they mean on this unit and what to check, in its own parts' words.
#[test]
fn errors_say_what_to_check_on_this_unit() {
    let text = printer_fails(&["--fault", "jam:1", "tool", "1"]);
    assert!(text.contains("slot 1"), "{text}");
    assert!(text.contains("check"), "{text}");
    assert!(text.contains("slot motor"), "{text}");
    assert!(!text.contains("pulley"), "MMU3 words on this hardware: {text}");
    let (lines, _) = printer_json(&["--fault", "jam:1", "tool", "1"]);
    let last = lines.last().expect("some output");
    assert!(last["check"].as_str().is_some_and(|c| !c.is_empty()), "{last}");
}

/// Registers by name, with this unit's names and values explained (register table).
#[test]
fn registers_by_name_with_their_values_explained() {
    let out = printer_ok(&["read", "filtered.hub.filament"]);
    assert!(out.contains("register 0x70 filtered.hub.filament = "), "{out}");
    let out = printer_ok(&["read", "0xb9"]);
    assert!(out.contains("lane.slot1 = 0 (none or not known)"), "{out}");
    let out = printer_ok(&["--fault", "disconnect:slot-filament-1", "read", "0x50"]);
    assert!(out.contains("stuck at a rail: slot1.filament"), "{out}");
    let out = printer_ok(&["write", "bowden_mm", "400"]);
    assert!(out.contains("register 0x22"), "{out}");
    let text = printer_fails(&["read", "elbow"]);
    assert!(text.contains("is no register"), "{text}");
}

/// Before: `write` and `settings load` said only "rejected" or "refused by the unit" where the
/// console says the register's range or the rule the value breaks. Now they say the same.
#[test]
fn a_refused_write_says_the_range_and_the_rule_as_the_console_does() {
    let text = printer_fails(&["write", "bowden_mm", "5"]);
    assert!(text.contains("5 is out of its range, 50 to 5000"), "{text}");
    let text = printer_fails(&["write", "park_mm", "1"]);
    assert!(
        text.contains(
            "rule 6 (park_clears_merge), the park distance must reach two revolutions past the merge"
        ),
        "{text}"
    );
    let text = printer_fails(&["write", "slots", "4"]);
    assert!(text.contains("it is read only"), "{text}");

    let file = std::env::temp_dir().join(format!("mmu-refused-{}.txt", std::process::id()));
    std::fs::write(&file, "0x22 5  # bowden_mm\n").expect("the settings file is written");
    let text = printer_fails(&["settings", "load", file.to_str().expect("UTF-8 path")]);
    assert!(text.contains("0x22 bowden_mm"), "{text}");
    assert!(text.contains("5 is out of its range, 50 to 5000"), "{text}");
    let _ = std::fs::remove_file(file);
}

/// Before: `mmu printer button 9` was sent to the unit; the protocol has three buttons, B0 to
/// B2. Now clap refuses any other at parse time (exit 2) and names the three.
#[test]
fn only_the_protocol_s_three_buttons_are_accepted() {
    let output = mmu(&["printer", "--sim", "button", "9"]);
    assert_eq!(output.status.code(), Some(2), "{}", stderr(&output));
    assert!(
        stderr(&output).contains("button 9: the printer's buttons are 0 (right), 1 (middle"),
        "{}",
        stderr(&output)
    );
    // B1 with nothing waiting: the unit takes it.
    printer_ok(&["button", "1"]);
}
