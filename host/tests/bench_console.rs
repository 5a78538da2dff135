//! The bench as a maker meets it in `mmu console`, `mmu calibrate`, `mmu motor` and `mmu slots`:
//! each test is a friction a maker hit (said in its comment) or a bench feature, run as the maker
//! runs it, a script piped into the tool against the simulator (or `mmu sim --pty`).

use std::io::{BufRead, BufReader, Write};
use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};
use std::thread;
use std::time::Duration;

mod common;

use common::{interrupt_when_ready, text};

/// A folder of its own for the console's files (slot map, statistics), so tests do not share one
/// and never touch the user's.
fn config_dir(name: &str) -> PathBuf {
    let dir =
        PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("console-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// `mmu ARGS` with `script` on stdin and the console's files in `config`.
fn run(args: &[&str], script: &str, config: &PathBuf) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mmu"))
        .args(args)
        .env("MMU_CONFIG_DIR", config)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mmu runs");
    child
        .stdin
        .take()
        .expect("piped")
        .write_all(script.as_bytes())
        .expect("the script goes in");
    child.wait_with_output().expect("mmu ends")
}

/// Before: a command sent while the unit waited on an earlier error failed at once with that
/// error, and the console blamed the new command ("pull the filament out of slot 2" for slot 1's
/// dialog). Now it is not sent, and the console says which command's error waits.
#[test]
fn a_waiting_error_is_not_blamed_on_the_next_command() {
    let config = config_dir("waiting");
    let script = "sim fault jam:1\nt 1\nabort\nload 2\nsim clear\nretry\nquit\n";
    let output = run(&["console", "--sim"], script, &config);
    let all = text(&output);
    assert!(
        all.contains("not sent: the unit still waits on STALLED_PULLEY")
            && all.contains("from T1 (tool change slot 1)"),
        "{all}"
    );
    assert!(!all.contains("L2 stopped"), "the preload is not blamed: {all}");
    assert!(all.contains("slot 1 is loaded"), "Retry then finishes T1: {all}");
}

/// Before: "the value is out of its range", without the range, and nothing about a threshold
/// that must stay above (or below) its partner, or about the guards' rule a setting breaks.
#[test]
fn a_refused_write_says_the_range_and_the_threshold_rule() {
    let config = config_dir("range");
    let script = "set bowden 5\nset threshold_on.hub.filament 100\nset threshold_off.hub.filament 3000\n\
                  set park 1\nquit\n";
    let all = text(&run(&["console", "--sim"], script, &config));
    assert!(all.contains("5 is out of its range, 50 to 5000"), "{all}");
    assert!(
        all.contains(
            "rule 6 (park_clears_merge), the park distance must reach two revolutions past the merge"
        ),
        "{all}"
    );
    assert!(
        all.contains("\"on\" threshold must stay above its \"off\" one (threshold_off.hub.filament is 2400)"),
        "{all}"
    );
    assert!(
        all.contains("\"off\" threshold must stay below its \"on\" one (threshold_on.hub.filament is 2600)"),
        "{all}"
    );
}

/// Before: `unload` with nothing loaded said "unloaded: the filament is back at its park position".
#[test]
fn unload_with_nothing_loaded_says_so() {
    let config = config_dir("unload");
    let all = text(&run(
        &["console", "--sim"],
        "unload\nt 0\nunload\nquit\n",
        &config,
    ));
    assert!(
        all.contains("nothing was loaded: the unit had nothing to unload"),
        "{all}"
    );
    assert!(
        all.contains("unloaded: the filament is back at its park position"),
        "after t 0 the unload is real: {all}"
    );
}

/// Before: `button 9` was sent; the printer's screens have three buttons.
#[test]
fn only_the_printer_s_three_buttons_are_pressed() {
    let config = config_dir("button");
    let output = run(&["console", "--sim"], "button 9\nquit\n", &config);
    assert!(!output.status.success());
    assert!(
        text(&output).contains("button 9: the printer's buttons are 0 (right), 1 (middle"),
        "{}",
        text(&output)
    );
}

/// Before: Ctrl-C quit the console silently while the unit was mid-command. Now it says what the
/// unit goes on doing, and exits 130.
#[test]
fn ctrl_c_during_a_command_says_what_the_unit_goes_on_doing() {
    let config = config_dir("ctrl-c");
    let mut command = Command::new(env!("CARGO_BIN_EXE_mmu"));
    command
        .args(["console", "--sim", "--time-scale", "1"])
        .env("MMU_CONFIG_DIR", &config);
    // At 1 × real time the tool change takes 6 s: Ctrl-C comes in its middle.
    let run = interrupt_when_ready(command, Some("t 1\n"), "T1: ", None, 500);
    let all = format!("{}{}", run.stdout, run.stderr);
    assert_eq!(run.code, Some(130), "{all}");
    assert!(all.contains("stopped by Ctrl-C while the unit runs T1"), "{all}");
    assert!(all.contains("`status`"), "{all}");
}

/// Before: `--merge-mm 500` parked every slot 200 mm before the hub, behind its slot sensor, and
/// said every slot passed. Now a join behind the slot sensors is refused at once (exit 2), and
/// the park check says which slots it preloaded (none when none was parked).
#[test]
fn calibrate_refuses_a_join_behind_the_slot_sensors_and_says_what_it_checked() {
    let config = config_dir("merge");
    let output = run(&["calibrate", "--sim", "--merge-mm", "500"], "", &config);
    assert_eq!(output.status.code(), Some(2), "{}", text(&output));
    assert!(
        text(&output).contains("behind their slot sensors"),
        "{}",
        text(&output)
    );

    let output = run(&["calibrate", "--sim", "park", "--merge-mm", "8"], "", &config);
    assert!(output.status.success(), "{}", text(&output));
    assert!(
        text(&output).contains("no slot was parked, so none was checked"),
        "{}",
        text(&output)
    );
}

/// Before: `--slot 7` on a 3-slot unit failed with "no register register 0xbf".
#[test]
fn calibrate_names_a_slot_the_unit_lacks() {
    let config = config_dir("slot");
    let output = run(&["calibrate", "--sim", "bowden", "--slot", "7"], "", &config);
    assert_eq!(output.status.code(), Some(2), "{}", text(&output));
    let all = text(&output);
    assert!(all.contains("--slot 7: the unit has 3 slots (0-2)"), "{all}");
    assert!(!all.contains("register register"), "{all}");
}

/// The motor test: a good slot's motor turns both ways and its Hall sensor swings across both
/// thresholds; a dead motor is named, with what to check, and fails the run.
#[test]
fn the_motor_test_passes_a_good_motor_and_names_a_dead_one() {
    let config = config_dir("motor");
    let output = run(&["motor", "--sim", "1"], "", &config);
    let all = text(&output);
    assert!(output.status.success(), "{all}");
    assert!(all.contains("it swings across both"), "{all}");
    assert!(all.contains("motor test passed"), "{all}");
    let forward: i32 = all
        .split("forward ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|mm| mm.parse().ok())
        .expect("the forward distance is said");
    assert!(forward > 0, "{all}");

    let output = run(&["motor", "--sim", "--fault", "motor-dead:0", "0"], "", &config);
    let all = text(&output);
    assert_eq!(output.status.code(), Some(1), "{all}");
    assert!(all.contains("no motion was counted forward"), "{all}");
    assert!(all.contains("STALLED_PULLEY"), "{all}");
}

/// The motor test of a slot the unit lacks is a usage mistake; an empty slot is refused before
/// anything moves.
#[test]
fn the_motor_test_refuses_a_missing_or_empty_slot() {
    let config = config_dir("motor-empty");
    let output = run(&["motor", "--sim", "4"], "", &config);
    assert_eq!(output.status.code(), Some(2), "{}", text(&output));
    let output = run(&["console", "--sim"], "eject 0\nmotor 0\nquit\n", &config);
    let all = text(&output);
    assert!(all.contains("slot 0 has no filament at its sensor"), "{all}");
}

/// The slot map: material and colour noted on this PC, shown with where each filament is, and a
/// slot whose tip the unit does not know told apart from an empty one (the unit's register says 0
/// for both).
#[test]
fn the_slot_map_keeps_material_and_colour_and_tells_unknown_from_empty() {
    let config = config_dir("slots");
    let output = run(&["slots", "set", "1", "PETG", "red"], "", &config);
    assert!(output.status.success(), "{}", text(&output));
    assert!(config.join("slots.txt").exists());
    let all = text(&run(
        &["console", "--sim"],
        "eject 0\nload 2\nslots\nquit\n",
        &config,
    ));
    let line = |slot: &str| {
        all.lines()
            .find(|line| line.starts_with(&format!("slot {slot}: ")) && !line.contains("is "))
            .unwrap_or_else(|| panic!("no line for slot {slot}: {all}"))
            .to_string()
    };
    assert!(
        line("0").contains("empty: no filament at the slot sensor"),
        "{all}"
    );
    assert!(line("1").contains("PETG red"), "{all}");
    assert!(
        line("1").contains("unknown: filament at the slot sensor"),
        "{all}"
    );
    assert!(line("2").contains("parked before the hub"), "{all}");

    let output = run(&["slots", "clear", "1"], "", &config);
    assert!(output.status.success(), "{}", text(&output));
    let output = run(&["slots", "--sim"], "", &config);
    assert!(!text(&output).contains("PETG"), "{}", text(&output));
    let output = run(&["slots", "set", "9", "PLA", "blue"], "", &config);
    assert_eq!(output.status.code(), Some(2), "{}", text(&output));
}

/// Statistics: tool changes, errors and metres per slot since `stats reset`, and the time of
/// each tool change run at the bench.
#[test]
fn statistics_count_since_a_reset_and_time_each_tool_change() {
    let config = config_dir("stats");
    let script = "t 1\nt 2\nstats\nstats reset\nstats\nquit\n";
    let all = text(&run(&["console", "--sim"], script, &config));
    assert!(
        all.contains("tool change to slot 2: "),
        "each change is timed: {all}"
    );
    let first = all.find("mmu> stats\n").expect("stats ran");
    let after_reset = all.rfind("mmu> stats\n").expect("stats ran again");
    let before = &all[first..after_reset];
    assert!(
        before.contains("slot 1: 1 tool change(s), 0 error(s)"),
        "{before}"
    );
    assert!(
        before.contains("1 tool change(s) to it timed here: mean"),
        "{before}"
    );
    let after = &all[after_reset..];
    assert!(after.contains("slot 1: 0 tool change(s)"), "{after}");
    assert!(!after.contains("timed here"), "{after}");
}

/// `mmu sim --pty`, killed when dropped.
struct PtyUnit(Child, String);

impl Drop for PtyUnit {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn pty_unit() -> PtyUnit {
    pty_unit_with(&[])
}

/// `mmu sim --pty` with `extra` options.
fn pty_unit_with(extra: &[&str]) -> PtyUnit {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mmu"))
        .args(["sim", "--pty", "--quiet", "--time-scale", "10"])
        .args(extra)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("mmu sim runs");
    let mut path = String::new();
    BufReader::new(child.stdout.take().expect("piped"))
        .read_line(&mut path)
        .expect("mmu sim prints its terminal");
    thread::sleep(Duration::from_millis(200));
    PtyUnit(child, path.trim().to_string())
}

/// Before: on the bench `t 0` failed unless the person typed `fsensor on` at the right moment,
/// and nothing said so. Now the first tool change on a bench without a printer says how the
/// printer's sensor is played.
#[test]
fn a_tool_change_on_the_bench_says_how_to_play_the_printer_s_sensor() {
    let unit = pty_unit();
    let config = config_dir("bench-t");
    let output = run(&["console", "--port", &unit.1], "t 0\nabort\nquit\n", &config);
    let all = text(&output);
    assert!(all.contains("on the bench there is no printer"), "{all}");
    assert!(all.contains("`fsensor on`"), "{all}");
}

/// With a real unit the statistics outlive the session (kept on this PC); a damaged statistics
/// file does not keep the console from the unit.
#[test]
fn a_real_unit_s_statistics_outlive_the_session() {
    let config = config_dir("stats-kept");
    let events = config_dir("stats-events").with_extension("jsonl");
    let events_path = events.to_str().expect("UTF-8 path");
    let unit = pty_unit_with(&["--events", events_path]);
    let console = [
        "console",
        "--port",
        unit.1.as_str(),
        "--fsensor-events",
        events_path,
    ];
    let first = text(&run(&console, "t 1\nquit\n", &config));
    assert!(first.contains("tool change to slot 1: "), "{first}");
    let second = text(&run(&console, "stats\nquit\n", &config));
    assert!(second.contains("1 tool change(s) to it timed here"), "{second}");

    std::fs::write(config.join("stats.txt"), "this is not a statistics file\n").expect("written");
    let output = run(&console, "stats\nquit\n", &config);
    let third = text(&output);
    assert!(output.status.success(), "{third}");
    assert!(third.contains("the statistics start again"), "{third}");
    let _ = std::fs::remove_file(events);
}
