//! End-to-end tests of the maker's bench tools: the read-only connection, `stats`, `settings
//! save|load`, `mmu sensors` (table, CSV, PNG plot) and the simulator's terminal log, run as a
//! user runs them: against `mmu sim --pty` (one unit that remembers between commands) or `--sim`.

use std::io::{BufRead, BufReader, Read, Write};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{self, Receiver};
use std::thread;
use std::time::{Duration, Instant};

use serde_json::Value;

mod common;

use common::{interrupt_when_ready, mmu, spawn_mmu, text};

/// Longest wait for the simulator to say something.
const WAIT: Duration = Duration::from_secs(20);
/// As a printer does, a client lets the unit boot before it talks: the unit takes a frame only
/// at the start of a quiet line (`mmu_protocol::SILENCE_MS`).
const BOOT: Duration = Duration::from_millis(200);

fn ok(args: &[&str]) -> String {
    let output = mmu(args);
    assert!(output.status.success(), "{args:?} failed:\n{}", text(&output));
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// A path in the test's temporary directory.
fn temp(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("bench-{}-{name}", std::process::id()))
}

/// `mmu sim --pty` running, killed when dropped; its stderr lines arrive on a channel.
struct PtySim {
    child: Child,
    path: String,
    events: PathBuf,
    stderr: Receiver<String>,
}

impl PtySim {
    fn spawn(name: &str, extra: &[&str]) -> PtySim {
        PtySim::spawn_at(name, "5", extra)
    }

    /// The simulator at `time_scale` × real time.
    fn spawn_at(name: &str, time_scale: &str, extra: &[&str]) -> PtySim {
        let events = temp(&format!("{name}-events.jsonl"));
        let mut child = Command::new(env!("CARGO_BIN_EXE_mmu"))
            .args(["sim", "--pty", "--time-scale", time_scale, "--events"])
            .arg(&events)
            .args(extra)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("the mmu binary runs");
        let mut stdout = BufReader::new(child.stdout.take().expect("stdout is piped"));
        let mut path = String::new();
        stdout
            .read_line(&mut path)
            .expect("mmu sim prints the pty's path");
        let (lines, stderr) = mpsc::channel();
        let pipe = child.stderr.take().expect("stderr is piped");
        thread::spawn(move || {
            for line in BufReader::new(pipe).lines() {
                let Ok(line) = line else { return };
                if lines.send(line).is_err() {
                    return;
                }
            }
        });
        PtySim {
            child,
            path: path.trim_end().to_string(),
            events,
            stderr,
        }
    }

    /// `mmu printer --port PTY args...` following the simulator's filament sensor, which must
    /// succeed; its stdout.
    fn printer(&self, args: &[&str]) -> String {
        let events = self.events.to_str().expect("UTF-8 path");
        let mut full = vec!["printer", "--port", &self.path, "--fsensor-events", events];
        full.extend_from_slice(args);
        ok(&full)
    }

    /// Wait until a stderr line contains `what`; every line seen so far.
    fn wait_for_log(&self, what: &str) -> Vec<String> {
        let deadline = Instant::now() + WAIT;
        let mut seen = Vec::new();
        while Instant::now() < deadline {
            if let Ok(line) = self.stderr.recv_timeout(Duration::from_millis(50)) {
                let found = line.contains(what);
                seen.push(line);
                if found {
                    return seen;
                }
            }
        }
        panic!(
            "the simulator never logged {what:?}; it logged:\n{}",
            seen.join("\n")
        );
    }
}

impl Drop for PtySim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_file(&self.events);
    }
}

/// Before: every `--port` action replayed the printer's handshake writes, so a setting written
/// from the PC was overwritten by the next `read` (`write 0x0b 30`, then `read 0x0b` gave 5).
/// A unit keeps what the bench writes; `stats` counts its tool changes; settings go to a file
/// and come back from it.
#[test]
fn the_bench_reads_without_writing_counts_and_keeps_settings() {
    let sim = PtySim::spawn("bench", &["--quiet"]);
    sim.printer(&["write", "0x0b", "30"]);
    let out = sim.printer(&["read", "0x0b"]);
    assert!(
        out.contains("= 30"),
        "the read wrote the printer's 5 again:\n{out}"
    );

    sim.printer(&["tool", "1"]);
    let stats = sim.printer(&["stats"]);
    let slot1 = stats
        .lines()
        .find(|line| line.trim_start().starts_with("slot 1"))
        .unwrap_or_else(|| panic!("no slot 1 line:\n{stats}"));
    assert!(slot1.contains("1 tool change"), "{stats}");
    assert!(slot1.contains("loaded"), "{stats}");
    assert!(
        stats.lines().any(|l| l.trim_start().starts_with("slot 2")),
        "{stats}"
    );

    let file = temp("settings.txt");
    sim.printer(&["settings", "save", file.to_str().expect("UTF-8 path")]);
    let saved = std::fs::read_to_string(&file).expect("the settings file was written");
    assert!(saved.contains("0x22 360"), "{saved}");
    // `tool` is the printer's own session: its handshake wrote the printer's 5.
    assert!(saved.contains("0x0b 5 "), "{saved}");
    assert!(saved.contains("0x90 2600"), "the hub sensor's threshold: {saved}");
    std::fs::write(&file, saved.replace("0x22 360", "0x22 512")).expect("the file can be edited");
    let out = sim.printer(&["settings", "load", file.to_str().expect("UTF-8 path")]);
    assert!(out.contains("0x22"), "{out}");
    let out = sim.printer(&["read", "0x22"]);
    assert!(out.contains("= 512"), "{out}");
    let _ = std::fs::remove_file(file);

    // Register 0x52 is the first `S2` answer; a printer expecting another compatible revision
    // still connects, as it asks `S2` again (version negotiation).
    sim.printer(&["write", "0x52", "2"]);
    let out = sim.printer(&["status"]);
    assert!(out.contains("unit firmware: 3.0.3"), "{out}");
    let out = sim.printer(&["--expect-version", "3.0.2", "status"]);
    assert!(out.contains("unit firmware: 3.0.2"), "{out}");
    // Looking is not connecting: the bench never tells the unit which revision it accepted.
    let out = sim.printer(&["read", "0x52"]);
    assert!(out.contains("= 2"), "{out}");
}

/// Status, read, stats and sensors send no write and no `f`: only `S`, `Q`, `R`.
#[test]
fn bench_actions_only_read() {
    for action in [&["status"][..], &["read", "0x0b"], &["stats"]] {
        let mut args = vec!["printer", "--sim", "--json", "-v"];
        args.extend_from_slice(action);
        let out = ok(&args);
        for line in out.lines() {
            let object: Value = serde_json::from_str(line).expect("JSON lines");
            if object["event"] == "sent" {
                let frame = object["frame"].as_str().expect("a frame");
                assert!(
                    frame.starts_with(['S', 'Q', 'R']),
                    "{action:?} sent {frame}:\n{out}"
                );
            }
        }
    }
}

/// `--csv --seconds N` prints a header, then one row per sample with all nine sensors.
#[test]
fn sensors_stream_csv() {
    let out = ok(&["sensors", "--sim", "--csv", "--seconds", "1"]);
    let mut lines = out.lines();
    let header = lines.next().expect("a header");
    let columns: Vec<&str> = header.split(',').collect();
    assert_eq!(columns[0], "t_ms");
    for sensor in [
        "hub_filament",
        "hub_tension",
        "hub_cutter",
        "slot2_filament",
        "slot2_motion",
    ] {
        for field in ["raw", "filtered"] {
            let column = format!("{sensor}_{field}");
            assert!(columns.contains(&column.as_str()), "{column} missing: {header}");
        }
    }
    assert!(columns.contains(&"hub_filament_on"), "{header}");
    let rows: Vec<Vec<&str>> = lines.map(|line| line.split(',').collect()).collect();
    assert!(rows.len() >= 5, "a second holds several samples: {out}");
    for row in &rows {
        assert_eq!(row.len(), columns.len(), "{row:?}");
    }
    let last_t: u64 = rows.last().expect("rows")[0].parse().expect("t_ms is a number");
    assert!((900..=1500).contains(&last_t), "{last_t}");
    // The hub filament sensor reads well below its "on" threshold with nothing loaded.
    let at = |name: &str| columns.iter().position(|c| *c == name).expect("column");
    let filtered: u32 = rows[rows.len() - 1][at("hub_filament_filtered")]
        .parse()
        .expect("number");
    let on: u32 = rows[rows.len() - 1][at("hub_filament_on")]
        .parse()
        .expect("number");
    assert!(filtered < on, "{filtered} vs {on}");
}

/// `--plot FILE.png --seconds N` writes a PNG of the trace.
#[test]
fn sensors_plot_a_png() {
    let file = temp("sensors.png");
    let _ = std::fs::remove_file(&file);
    let out = ok(&[
        "sensors",
        "--sim",
        "--plot",
        file.to_str().expect("UTF-8"),
        "--seconds",
        "2",
    ]);
    assert!(out.contains("sensors.png"), "{out}");
    let bytes = std::fs::read(&file).expect("the PNG was written");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "not a PNG");
    // IHDR: width and height, big-endian, at bytes 16..24.
    let width = u32::from_be_bytes(bytes[16..20].try_into().expect("4 bytes"));
    let height = u32::from_be_bytes(bytes[20..24].try_into().expect("4 bytes"));
    assert!(width >= 800 && height >= 600, "{width}x{height}");
    assert!(
        bytes.len() > 20_000,
        "a plot with text and traces: {} bytes",
        bytes.len()
    );
    let _ = std::fs::remove_file(file);
}

/// The table: one row per sensor with its readings, thresholds and state.
#[test]
fn sensors_table_names_every_sensor() {
    let out = ok(&["sensors", "--sim", "--seconds", "1"]);
    for name in [
        "hub filament",
        "hub tension",
        "hub cutter",
        "slot 0 filament",
        "slot 0 motion sensor",
        "slot 2 motion sensor",
    ] {
        assert!(out.contains(name), "{name} missing:\n{out}");
    }
    assert!(out.contains("no filament"), "{out}");
}

/// On hardware without hub sensors and with a tension sensor per lane, the table shows the
/// sensors the unit has: no hub row, a tension row per lane.
#[test]
fn sensors_table_follows_the_hardware() {
    let out = ok(&[
        "sensors",
        "--sim",
        "--hardware",
        "bmcu-c",
        "--slots",
        "4",
        "--seconds",
        "1",
    ]);
    assert!(!out.contains("hub"), "{out}");
    for name in [
        "slot 0 filament",
        "slot 3 motion sensor",
        "slot 0 tension",
        "slot 3 tension",
    ] {
        assert!(out.contains(name), "{name} missing:\n{out}");
    }
}

/// Before: `mmu sim --pty` showed nothing while serving, even for an invalid request.
#[test]
fn the_simulator_logs_what_it_serves() {
    let sim = PtySim::spawn("log", &[]);
    let mut port = serialport::new(&sim.path, 115_200)
        .timeout(WAIT)
        .open()
        .expect("the pty opens");
    thread::sleep(BOOT);
    port.write_all(b"S0*c6\n").expect("write");
    let seen = sim.wait_for_log("version major = 3");
    assert!(
        seen.iter().any(|l| l.contains("< S0") || l.contains("S0 A3")),
        "{seen:?}"
    );
    port.write_all(b"T1*00\n").expect("write");
    let seen = sim.wait_for_log("ignored");
    let last = seen.last().expect("a line");
    assert!(last.contains("CRC"), "{last}");
    let mut buffer = [0u8; 64];
    let _ = port.read(&mut buffer);
}

/// `-q` silences the log.
#[test]
fn the_simulator_log_is_silenced_by_q() {
    let mut child = spawn_mmu(&["sim", "--stdio", "-q"]);
    thread::sleep(BOOT);
    child
        .stdin
        .take()
        .expect("piped")
        .write_all(b"S0*c6\nT1*00\n")
        .expect("write");
    let output = child.wait_with_output().expect("mmu sim ends");
    assert!(output.status.success());
    assert!(
        output.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&output.stderr)
    );
    assert!(String::from_utf8_lossy(&output.stdout).contains("S0 A3"));
}

/// `mmu sensors` on a serial port: the simulator behind a pty, as a real unit behind an adapter.
#[test]
fn sensors_over_a_serial_port() {
    let sim = PtySim::spawn("sensors", &["--quiet"]);
    let out = ok(&[
        "sensors",
        "--port",
        &sim.path,
        "--csv",
        "--seconds",
        "1",
        "--every",
        "200",
    ]);
    let lines: Vec<&str> = out.lines().collect();
    assert!(
        lines
            .first()
            .is_some_and(|h| h.starts_with("t_ms,hub_filament_raw")),
        "{out}"
    );
    assert!(lines.len() >= 3, "a header and samples: {out}");
    let file = temp("port.png");
    let out = ok(&[
        "sensors",
        "--port",
        &sim.path,
        "--plot",
        file.to_str().expect("UTF-8"),
        "--seconds",
        "1",
    ]);
    assert!(out.contains("drawn to"), "{out}");
    assert_eq!(
        &std::fs::read(&file).expect("the PNG was written")[..4],
        b"\x89PNG"
    );
    let _ = std::fs::remove_file(file);
}

/// A printer polls every second: polls answered as the time before are left out of the log
/// (and counted) unless `-v`; what changes stands out.
#[test]
fn the_simulator_log_leaves_out_unchanged_polls_unless_verbose() {
    let run = |verbose: bool| {
        let mut args = vec!["sim", "--stdio", "--time-scale", "5"];
        if verbose {
            args.push("-v");
        }
        let mut child = spawn_mmu(&args);
        let mut stdin = child.stdin.take().expect("piped");
        thread::sleep(BOOT);
        for _ in 0..3 {
            stdin.write_all(b"R1b*9e\n").expect("write");
            thread::sleep(Duration::from_millis(30));
        }
        stdin.write_all(b"S0*c6\n").expect("write");
        drop(stdin);
        let output = child.wait_with_output().expect("mmu sim ends");
        String::from_utf8_lossy(&output.stderr).into_owned()
    };
    let log = run(false);
    assert_eq!(log.matches("< R1b A5").count(), 1, "{log}");
    assert!(log.contains("(2 polls answered as before not shown"), "{log}");
    assert!(log.contains("< S0 A3"), "{log}");
    let log = run(true);
    assert_eq!(log.matches("< R1b A5").count(), 3, "{log}");
}

/// A sensor stuck at a rail is flagged in the CSV and in the table, with what to check.
#[test]
fn sensors_flag_a_stuck_sensor() {
    let fault = ["--fault", "disconnect:slot-filament-1:high@500"];
    let mut args = vec!["sensors", "--sim", "--csv", "--seconds", "2"];
    args.extend_from_slice(&fault);
    let out = ok(&args);
    let mut lines = out.lines();
    let header: Vec<&str> = lines.next().expect("a header").split(',').collect();
    let stuck = header
        .iter()
        .position(|c| *c == "slot1_filament_stuck")
        .expect("a stuck column");
    let last: Vec<&str> = lines.last().expect("rows").split(',').collect();
    assert_eq!(last[stuck], "1", "{out}");
    let mut args = vec!["sensors", "--sim", "--seconds", "2"];
    args.extend_from_slice(&fault);
    let out = ok(&args);
    let row = out
        .lines()
        .find(|l| l.contains("slot 1 filament"))
        .expect("a row");
    assert!(row.contains("STUCK AT A RAIL: check its wiring"), "{out}");
}

/// A frame left unfinished (a person stopped typing) is reported once the line falls silent,
/// as the unit's decoder sees it (spec: a printer never pauses inside a frame), and the next
/// request is logged.
#[test]
fn the_simulator_log_reports_an_unfinished_frame_after_a_silence() {
    let mut child = spawn_mmu(&["sim", "--stdio"]);
    let mut stdin = child.stdin.take().expect("piped");
    thread::sleep(BOOT);
    stdin.write_all(b"T1").expect("write");
    stdin.flush().expect("flush");
    thread::sleep(Duration::from_millis(200));
    stdin.write_all(b"S0*c6\n").expect("write");
    drop(stdin);
    let output = child.wait_with_output().expect("mmu sim ends");
    let log = String::from_utf8_lossy(&output.stderr);
    assert!(log.contains("> frame ignored: T1 unfinished"), "{log}");
    assert!(log.contains("> S0*c6  version major"), "{log}");
}

/// A serial port with nothing behind it that speaks the protocol: a pseudo-terminal whose other
/// end the test holds, silent, or sending `noise` again and again (a device at another baud rate,
/// a line picking up interference) until dropped.
struct FakePort {
    path: String,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    writer: Option<thread::JoinHandle<()>>,
    _ends: (serialport::TTYPort, serialport::TTYPort),
}

impl FakePort {
    fn new(noise: Option<&'static [u8]>) -> FakePort {
        use serialport::SerialPort;
        use std::sync::atomic::{AtomicBool, Ordering};

        let (master, slave) = serialport::TTYPort::pair().expect("a pseudo-terminal");
        let path = slave.name().expect("the pseudo-terminal has a path");
        let stop = std::sync::Arc::new(AtomicBool::new(false));
        let writer = noise.map(|noise| {
            let mut master = master.try_clone_native().expect("a second handle");
            let stop = std::sync::Arc::clone(&stop);
            thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    let _ = master.write_all(noise);
                    thread::sleep(Duration::from_millis(20));
                }
            })
        });
        FakePort {
            path,
            stop,
            writer,
            _ends: (master, slave),
        }
    }
}

impl FakePort {
    /// `mmu printer --port PORT status`, which must fail (exit 1); all it printed. On buddy-6.5,
    /// whose link timeout is 200 ms, the ten attempts take about 2 s.
    fn status_fails(&self) -> String {
        let output = mmu(&[
            "printer",
            "--printer",
            "buddy-6.5",
            "--port",
            &self.path,
            "status",
        ]);
        let all = text(&output);
        assert_eq!(output.status.code(), Some(1), "{all}");
        all
    }
}

impl Drop for FakePort {
    fn drop(&mut self) {
        self.stop.store(true, std::sync::atomic::Ordering::Relaxed);
        if let Some(writer) = self.writer.take() {
            let _ = writer.join();
        }
    }
}

/// Before: a port with nothing behind it gave ten "link lost" lines (20 s on the default
/// printer) and MMU_NOT_RESPONDING, with no word of what to check. Now the first failed handshake
/// says it once: the port, TX and RX crossed, GND, 115200, a powered and flashed unit.
#[test]
fn a_silent_port_says_once_what_to_check() {
    let port = FakePort::new(None);
    let all = port.status_fails();
    assert_eq!(
        all.matches("not one byte came back").count(),
        1,
        "said once:\n{all}"
    );
    for what in [
        port.path.as_str(),
        "TX",
        "RX",
        "GND",
        "115200",
        "powered",
        "flashed",
    ] {
        assert!(all.contains(what), "{what} missing:\n{all}");
    }
    assert!(!all.contains("baud rate"), "{all}");

    // The other tools that open a port say it too (on the default printer, after its first 2 s
    // attempt): the console, and `mmu sensors`, which shows no link events at all.
    for tool in ["console", "sensors"] {
        let mut command = Command::new(env!("CARGO_BIN_EXE_mmu"));
        command.args([tool, "--port", &port.path]);
        let run = interrupt_when_ready(command, None, "not one byte came back", None, 0);
        let all = format!("{}{}", run.stdout, run.stderr);
        assert!(all.contains("not one byte came back"), "{tool}:\n{all}");
    }
}

/// Before: bytes that never make a frame (a wrong baud rate, noise) looked the same as silence.
/// Now the first failed handshake says bytes came but none decoded, and what that means.
#[test]
fn a_port_with_noise_says_what_bytes_without_frames_mean() {
    let port = FakePort::new(Some(b"\x00\xfe\x80~x\xf0\r\n"));
    let all = port.status_fails();
    assert_eq!(all.matches("none decoded").count(), 1, "said once:\n{all}");
    assert!(all.contains("baud rate") && all.contains("115200"), "{all}");
    assert!(all.contains("noise"), "{all}");
    assert!(!all.contains("not one byte"), "{all}");
}

/// Before: Ctrl-C during `mmu printer ... tool N` ended the tool silently, the unit mid-change.
/// Now it says the command keeps running on the unit (the protocol has no abort) and how to see
/// its state, and exits 130.
#[test]
fn ctrl_c_during_a_printer_command_says_the_unit_goes_on() {
    // At real time the tool change takes seconds: Ctrl-C comes in its middle.
    let sim = PtySim::spawn_at("ctrl-c", "1", &["--quiet"]);
    let mut printer = Command::new(env!("CARGO_BIN_EXE_mmu"));
    printer.args(["printer", "--port", &sim.path, "tool", "1"]);
    let run = interrupt_when_ready(printer, None, "T1: ", None, 500);
    let all = format!("{}{}", run.stdout, run.stderr);
    assert_eq!(run.code, Some(130), "{all}");
    assert!(all.contains("while the unit runs T1"), "{all}");
    assert!(all.contains("keeps running on the unit"), "{all}");
    assert!(all.contains("no abort"), "{all}");
    let status = format!("mmu printer --port {} status", sim.path);
    assert!(all.contains(&status), "{all}");
}
