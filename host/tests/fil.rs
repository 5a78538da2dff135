//! `mmu sim --firmware` and `mmu fil` from the outside: the image a user flashes, served on the
//! simulator's wire, answers the printer's first request; and the mistakes a user can make are
//! refused clearly.
//!
//! The served image needs the firmware images (`scripts/build-firmware.sh <board> dist`) and the
//! benches' emulators (`npm ci --prefix fil/pico`, `unicorn` for python3). Without them the test
//! says so and passes; CI sets `MMU_FIL_REQUIRED=1` once it has them, and then it must run.

use std::io::{Read, Write};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::Duration;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// Why `board`'s image cannot be served here, if it cannot.
fn missing(board: &str) -> Option<String> {
    let image = root().join(format!("dist/mmu-firmware-{board}.elf"));
    if !image.is_file() {
        return Some(format!("no {}", image.display()));
    }
    let emulator = match board {
        "pico" => root().join("fil/pico/node_modules/rp2040js").is_dir(),
        _ => Command::new("python3")
            .args(["-c", "import unicorn"])
            .status()
            .is_ok_and(|s| s.success()),
    };
    (!emulator).then(|| format!("the {board} bench's emulator is not installed"))
}

#[test]
fn each_image_served_by_mmu_sim_answers_the_printers_first_request() {
    let required = std::env::var_os("MMU_FIL_REQUIRED").is_some();
    for (board, shape) in [
        ("g071", &[][..]),
        ("pico", &[][..]),
        ("bmcu", &["--slots", "4", "--hardware", "bmcu-c"][..]),
    ] {
        if let Some(why) = missing(board) {
            assert!(!required, "MMU_FIL_REQUIRED is set but {why}");
            eprintln!("skipped {board}: {why}");
            continue;
        }
        let image = root().join(format!("dist/mmu-firmware-{board}.elf"));
        let log_path = std::env::temp_dir().join(format!("mmu-fil-test-{board}-{}.log", std::process::id()));
        let log = std::fs::File::create(&log_path).expect("a log file");
        let mut child = Command::new(env!("CARGO_BIN_EXE_mmu"))
            .args(["sim", "--stdio", "-q", "--board", board])
            .args(shape)
            .arg("--firmware")
            .arg(&image)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .expect("mmu runs");
        let mut stdin = child.stdin.take().expect("piped");
        let mut stdout = child.stdout.take().expect("piped");
        let (tx, rx) = mpsc::channel();
        thread::spawn(move || {
            let mut seen = Vec::new();
            let mut byte = [0u8; 1];
            while stdout.read(&mut byte).is_ok_and(|n| n == 1) {
                seen.push(byte[0]);
                if seen.ends_with(b"\n") && String::from_utf8_lossy(&seen).contains("S0 A") {
                    break;
                }
            }
            let _ = tx.send(seen);
        });
        // As a printer does: ask again every half second until the unit answers (one asked while
        // the image is still starting, before its UART listens, is not answered).
        let mut seen = Vec::new();
        for _ in 0..120 {
            stdin.write_all(b"S0*c6\n").expect("the request goes out");
            stdin.flush().expect("flushed");
            if let Ok(answer) = rx.recv_timeout(Duration::from_millis(500)) {
                seen = answer;
                break;
            }
        }
        drop(stdin);
        let status = child.wait().expect("mmu ends when stdin ends");
        let text = String::from_utf8_lossy(&seen);
        let log = std::fs::read_to_string(&log_path).unwrap_or_default();
        let _ = std::fs::remove_file(&log_path);
        assert!(
            text.contains("S0 A3*"),
            "{board}: the image answered {text:?}; its log:\n{log}"
        );
        assert!(status.success(), "{board}: {status}; its log:\n{log}");
    }
}

#[test]
fn a_missing_image_or_board_is_refused_clearly() {
    let run = |args: &[&str]| {
        let output = Command::new(env!("CARGO_BIN_EXE_mmu"))
            .args(args)
            .stdin(Stdio::null())
            .output()
            .expect("mmu runs");
        (
            output.status.code(),
            String::from_utf8_lossy(&output.stderr).into_owned(),
        )
    };
    let (code, stderr) = run(&["fil", "--board", "pico", "--image", "/no/such.elf"]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("no firmware image at /no/such.elf"), "{stderr}");
    let (code, stderr) = run(&["fil", "--board", "stm32f4"]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("g071, pico or bmcu"), "{stderr}");
    // A bench that cannot run fails its scenarios, with the bench's own words under them.
    let no_benches = std::env::temp_dir().join(format!("mmu-fil-no-benches-{}", std::process::id()));
    std::fs::create_dir_all(&no_benches).expect("a directory");
    let output = Command::new(env!("CARGO_BIN_EXE_mmu"))
        .args([
            "fil",
            "--board",
            "g071",
            "--only",
            "MK3S",
            "--image",
            "Cargo.toml",
            "--fil-dir",
        ])
        .arg(&no_benches)
        .arg("--log-dir")
        .arg(&no_benches)
        .output()
        .expect("mmu runs");
    let stdout = String::from_utf8_lossy(&output.stdout);
    assert_eq!(output.status.code(), Some(1), "{stdout}");
    assert!(stdout.contains("FAIL  g071: handshake, MK3S"), "{stdout}");
    assert!(
        stdout.contains("the g071 bench exited") && stdout.contains("bench.py"),
        "{stdout}"
    );
    assert!(
        stdout.contains("firmware-in-the-loop (g071): 0/1 scenarios passed"),
        "{stdout}"
    );
    let _ = std::fs::remove_dir_all(&no_benches);
    let (code, stderr) = run(&["sim", "--stdio", "--firmware", "x.elf"]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("--board"), "{stderr}");
}
