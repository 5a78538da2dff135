//! `mmu sensors` as a maker at the bench meets it: Ctrl-C ends a live view with status 130 (as
//! every `mmu` subcommand), `--seconds` is the unit's time however slow the link, a plot that
//! cannot be written is refused before anything is recorded, and one sensor alone is sampled
//! fast enough to follow a motor Hall sensor.

use std::process::Command;
use std::time::{Duration, Instant};

mod common;

use common::{interrupt_when_ready, mmu, text};

/// Before: Ctrl-C ended the table with status 0, though the book (and every other subcommand)
/// says 130.
#[test]
fn ctrl_c_ends_the_live_view_with_status_130_after_showing_it() {
    let mut command = Command::new(env!("CARGO_BIN_EXE_mmu"));
    command.args(["sensors", "--sim"]);
    let run = interrupt_when_ready(command, None, "until Ctrl-C", None, 500);
    let all = format!("{}{}", run.stdout, run.stderr);
    assert_eq!(run.code, Some(130), "{all}");
    assert!(run.stdout.contains("hub filament"), "the table is shown: {all}");
    assert!(run.stderr.contains("stopped by Ctrl-C"), "{all}");
}

/// Before: `--every 10` sampled every 19 ms without a word, and `--seconds 1` ran for a hundred
/// rows (1.9 s of the unit's clock). Now the samples stop at the unit's second, and the slower
/// pace is said once.
#[test]
fn seconds_are_the_unit_s_time_and_a_slower_pace_is_said() {
    let output = mmu(&["sensors", "--sim", "--csv", "--seconds", "1", "--every", "10"]);
    assert!(output.status.success(), "{}", text(&output));
    let stdout = String::from_utf8_lossy(&output.stdout);
    let last: u64 = stdout
        .lines()
        .last()
        .and_then(|row| row.split(',').next())
        .and_then(|t| t.parse().ok())
        .expect("rows start with t_ms");
    assert!(last <= 1000, "the last sample is within the second: t_ms {last}");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("longer than --every 10") && stderr.contains("--sensor NAME"),
        "{stderr}"
    );
}

/// One motor Hall sensor alone: a sample every few milliseconds instead of every 19.
#[test]
fn one_sensor_alone_is_sampled_several_times_faster() {
    let output = mmu(&[
        "sensors",
        "--sim",
        "--csv",
        "--seconds",
        "1",
        "--every",
        "1",
        "--sensor",
        "slot0.motion",
    ]);
    assert!(output.status.success(), "{}", text(&output));
    let stdout = String::from_utf8_lossy(&output.stdout);
    let mut lines = stdout.lines();
    assert_eq!(
        lines.next(),
        Some(
            "t_ms,slot0_motion_raw,slot0_motion_filtered,slot0_motion_on,slot0_motion_off,slot0_motion_stuck"
        )
    );
    let rows = lines.count();
    assert!(rows >= 200, "at least 200 samples in a second: {rows}");
}

/// Before: a bad `--plot` path failed after the whole recording with a raw Rust error, and the
/// samples were lost. Now it is refused at once, in words, as a usage mistake.
#[test]
fn a_plot_that_cannot_be_written_is_refused_before_recording() {
    let started = Instant::now();
    let output = mmu(&[
        "sensors",
        "--sim",
        "--plot",
        "/no/such/folder/s.png",
        "--seconds",
        "60",
        "--time-scale",
        "1",
    ]);
    assert_eq!(output.status.code(), Some(2), "{}", text(&output));
    assert!(
        started.elapsed() < Duration::from_secs(20),
        "refused before recording"
    );
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(
        stderr.contains("/no/such/folder/s.png") && stderr.contains("nothing was recorded"),
        "{stderr}"
    );
    let output = mmu(&["sensors", "--sim", "--plot", "trace.txt", "--seconds", "1"]);
    assert_eq!(output.status.code(), Some(2), "{}", text(&output));
    assert!(text(&output).contains(".png"), "{}", text(&output));
}

/// A sensor the unit does not have is named with the ones it has.
#[test]
fn an_unknown_sensor_lists_the_unit_s_sensors() {
    let output = mmu(&["sensors", "--sim", "--sensor", "slot7.motion", "--seconds", "1"]);
    assert_eq!(output.status.code(), Some(2), "{}", text(&output));
    assert!(text(&output).contains("slot2.motion"), "{}", text(&output));
}
