//! End-to-end tests of `mmu sim`: a printer-side program that knows only the protocol spec (it
//! frames requests and decodes answers with `mmu_protocol`, and follows the `--events` file to
//! report its filament sensor) drives the simulator over stdin/stdout and over a pseudo-terminal.
//!
//! The simulator runs at 20× real time, so one second of the printer's heartbeat is 50 ms of wall
//! time. Not faster: the printer's `f` reports travel in wall time, and on a loaded machine they
//! would reach the unit too late in virtual time (it allows about 0.4 s). Every wait has a
//! generous wall-clock bound and ends as soon as its condition holds.

use std::fs::File;
use std::io::{self, BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError};
use std::thread;
use std::time::{Duration, Instant};

use mmu_protocol::{
    ButtonCode, ErrorCode, ParamCode, Request, RequestCode, Response, ResponseDecoder, ResultCode,
};
use serde_json::Value;
use serialport::SerialPort;

mod common;

use common::spawn_mmu;

/// Virtual ms per wall ms.
const TIME_SCALE: u64 = 20;
/// The printer's `Q0` period, one virtual second, in wall time.
const HEARTBEAT: Duration = Duration::from_millis(1000 / TIME_SCALE);
/// Longest wait for one answer. The unit answers within a virtual millisecond; this is for a
/// loaded CI machine.
const ANSWER_TIMEOUT: Duration = Duration::from_secs(10);
/// Longest a command may run, wall time.
const COMMAND_TIMEOUT: Duration = Duration::from_secs(20);
/// Retry presses the printer makes by itself per command (`MAX_RETRIES`, spec §5.5).
const AUTO_RETRIES: u8 = 3;
/// How often the printer looks at its filament sensor while it waits.
const SENSOR_LOOK: Duration = Duration::from_millis(1);

/// A running `mmu sim`, killed when dropped (also when a test fails).
struct SimProcess {
    child: Child,
}

impl SimProcess {
    fn spawn(args: &[&str]) -> SimProcess {
        let args: Vec<&str> = ["sim"].into_iter().chain(args.iter().copied()).collect();
        SimProcess {
            child: spawn_mmu(&args),
        }
    }

    /// Wait for the process to exit on its own; its stderr.
    fn wait_for_exit(&mut self) -> (std::process::ExitStatus, String) {
        let deadline = Instant::now() + ANSWER_TIMEOUT;
        let status = loop {
            if let Some(status) = self.child.try_wait().expect("the child can be waited for") {
                break status;
            }
            assert!(Instant::now() < deadline, "mmu sim did not exit");
            thread::sleep(Duration::from_millis(5));
        };
        let mut stderr = String::new();
        if let Some(mut pipe) = self.child.stderr.take() {
            pipe.read_to_string(&mut stderr).expect("stderr is UTF-8");
        }
        (status, stderr)
    }
}

impl Drop for SimProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The simulator's `--events` file, read as it grows.
struct EventsFile {
    path: PathBuf,
    file: File,
    unfinished_line: String,
    events: Vec<Value>,
    /// The printer's filament sensor as the events tell it (0 before any change).
    fsensor: u8,
}

impl EventsFile {
    /// An empty file at a path unique to `test`, for `mmu sim` to write.
    fn create(test: &str) -> EventsFile {
        let path = Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("sim-events-{test}-{}.jsonl", std::process::id()));
        File::create(&path).expect("the events file can be created");
        let file = File::open(&path).expect("the events file can be read");
        EventsFile {
            path,
            file,
            unfinished_line: String::new(),
            events: Vec::new(),
            fsensor: 0,
        }
    }

    fn path(&self) -> &str {
        self.path.to_str().expect("the temporary path is UTF-8")
    }

    /// Read the events written since the last call.
    fn update(&mut self) {
        self.file
            .read_to_string(&mut self.unfinished_line)
            .expect("the events file is UTF-8");
        while let Some(end) = self.unfinished_line.find('\n') {
            let line: String = self.unfinished_line.drain(..=end).collect();
            let event: Value = serde_json::from_str(&line).unwrap_or_else(|e| panic!("event {line:?}: {e}"));
            if event["kind"] == "fsensor" {
                let state = event["state"].as_u64().expect("an fsensor event has a state");
                self.fsensor = u8::try_from(state).expect("the state is 0, 1 or 2");
            }
            self.events.push(event);
        }
    }

    /// How many events were written so far.
    fn count(&mut self) -> usize {
        self.update();
        self.events.len()
    }

    /// Wait until an event after the first `after` ones satisfies `matches`.
    fn wait_for(&mut self, after: usize, what: &str, matches: impl Fn(&Value) -> bool) {
        let deadline = Instant::now() + ANSWER_TIMEOUT;
        loop {
            self.update();
            if self.events.iter().skip(after).any(&matches) {
                return;
            }
            assert!(Instant::now() < deadline, "no {what} event in {:?}", self.events);
            thread::sleep(SENSOR_LOOK);
        }
    }
}

impl Drop for EventsFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Where the unit's bytes come from.
enum FromUnit {
    /// A pipe, read by a thread of its own.
    Pipe(Receiver<Vec<u8>>),
    /// A serial port, read here: when the printer is dropped, nothing is left reading it.
    Port(Box<dyn SerialPort>),
}

impl FromUnit {
    /// What arrived within `wait`.
    fn read(&mut self, wait: Duration) -> Vec<u8> {
        match self {
            FromUnit::Pipe(chunks) => match chunks.recv_timeout(wait) {
                Ok(bytes) => bytes,
                Err(RecvTimeoutError::Timeout) => Vec::new(),
                Err(RecvTimeoutError::Disconnected) => panic!("the unit's output closed"),
            },
            FromUnit::Port(port) => {
                port.set_timeout(wait).expect("the port takes a timeout");
                let mut buffer = [0; 256];
                match port.read(&mut buffer) {
                    Ok(n) => buffer[..n].to_vec(),
                    Err(err) if err.kind() == io::ErrorKind::TimedOut => Vec::new(),
                    Err(err) => panic!("cannot read the port: {err}"),
                }
            }
        }
    }
}

/// The printer: requests out, answers in, and (given the events file) its filament sensor.
struct Printer {
    to_unit: Box<dyn Write + Send>,
    from_unit: FromUnit,
    decoder: ResponseDecoder,
    answers: Vec<Response>,
    events: Option<EventsFile>,
    reported_fsensor: u8,
}

impl Printer {
    fn new(to_unit: Box<dyn Write + Send>, from_unit: FromUnit, events: Option<EventsFile>) -> Self {
        Printer {
            to_unit,
            from_unit,
            decoder: ResponseDecoder::new(),
            answers: Vec::new(),
            events,
            reported_fsensor: 0,
        }
    }

    fn events(&mut self) -> &mut EventsFile {
        self.events.as_mut().expect("the printer follows the events file")
    }

    fn send_bytes(&mut self, bytes: &[u8]) {
        self.to_unit.write_all(bytes).expect("the unit takes the bytes");
        self.to_unit.flush().expect("the bytes go out");
    }

    fn send(&mut self, request: Request) {
        self.send_bytes(request.encode().as_bytes());
    }

    /// Decode what the unit sent within `wait`.
    fn receive(&mut self, wait: Duration) {
        for byte in self.from_unit.read(wait) {
            match self.decoder.feed(byte) {
                Some(Ok(response)) => self.answers.push(response),
                Some(Err(err)) => panic!("the unit sent a bad frame: {err:?}"),
                None => {}
            }
        }
    }

    /// The next answer.
    fn answer(&mut self) -> Response {
        let deadline = Instant::now() + ANSWER_TIMEOUT;
        while self.answers.is_empty() {
            assert!(Instant::now() < deadline, "no answer from the unit");
            self.receive(Duration::from_millis(50));
        }
        self.answers.remove(0)
    }

    fn ask(&mut self, request: Request) -> Response {
        self.send(request);
        self.answer()
    }

    /// The printer's start-up (spec §5.2), up to the unit's start-up check having finished.
    fn handshake(&mut self) {
        // As a printer does, let the unit boot first: it takes a frame only at the start of a
        // quiet line (mmu_protocol::SILENCE_MS).
        std::thread::sleep(Duration::from_millis(200));
        for (register, version) in [(0, 3), (1, 0)] {
            let request = Request::new(RequestCode::Version, register);
            assert_eq!(self.ask(request), Response::read(&request, version));
        }
        // A printer that wants 3.0.3 (Buddy 6.4) asks `S2` again on another revision (the unit
        // offers the one accepted last first, 3.0.4 on a fresh unit).
        let s2 = Request::new(RequestCode::Version, 2);
        let answers: Vec<_> = (0..5)
            .map_while(|_| {
                let answer = self.ask(s2);
                (answer != Response::read(&s2, 3)).then_some(answer)
            })
            .collect();
        assert!(answers.len() < 5, "3.0.3 never offered: {answers:?}");
        let build = self.ask(Request::new(RequestCode::Version, 3));
        assert_eq!(
            (build.code, build.value, build.param),
            (RequestCode::Version, 3, ParamCode::Accepted)
        );
        assert!(
            build.param_value.is_some(),
            "S3 carries the build number: {build:?}"
        );
        for write in [Request::write(0x0b, 5), Request::write(0x14, 0x14)] {
            assert_eq!(self.ask(write), Response::accepted(&write));
        }
        self.report_fsensor(0);
        let idle = Response::finished(RequestCode::Reset, 0, ResultCode::OK);
        let deadline = Instant::now() + COMMAND_TIMEOUT;
        loop {
            let answer = self.ask(Request::new(RequestCode::Query, 0));
            if answer == idle {
                return;
            }
            assert_eq!(
                (answer.code, answer.param),
                (RequestCode::Reset, ParamCode::Processing),
                "start-up check"
            );
            assert!(Instant::now() < deadline, "the start-up check does not finish");
            self.idle(HEARTBEAT);
        }
    }

    fn report_fsensor(&mut self, state: u8) {
        let request = Request::new(RequestCode::FilamentSensor, state);
        assert_eq!(self.ask(request), Response::accepted(&request));
        self.reported_fsensor = state;
    }

    /// Wait `period`, telling the unit at once when the filament sensor changes (spec §5.3).
    fn idle(&mut self, period: Duration) {
        let deadline = Instant::now() + period;
        while Instant::now() < deadline {
            if let Some(events) = &mut self.events {
                events.update();
                let state = events.fsensor;
                if state != self.reported_fsensor {
                    self.report_fsensor(state);
                }
            }
            self.receive(SENSOR_LOOK);
            assert!(self.answers.is_empty(), "unsolicited answer {:?}", self.answers);
        }
    }

    /// Send a command, expect `A`, then [`poll`](Self::poll) until `stop` holds.
    fn command(&mut self, request: Request, stop: impl Fn(&Response) -> bool) -> Response {
        assert_eq!(self.ask(request), Response::accepted(&request));
        self.poll(request, stop)
    }

    /// Poll `Q0` every heartbeat until `stop` holds for the answer about `request`. On any other
    /// error the printer presses Retry itself, up to three times per command (spec §5.5): on a
    /// loaded machine an `f` report can reach the unit late in virtual time.
    fn poll(&mut self, request: Request, stop: impl Fn(&Response) -> bool) -> Response {
        let deadline = Instant::now() + COMMAND_TIMEOUT;
        let mut retries_left = AUTO_RETRIES;
        loop {
            self.idle(HEARTBEAT);
            let answer = self.ask(Request::new(RequestCode::Query, 0));
            assert_eq!(
                (answer.code, answer.value),
                (request.code, request.value),
                "Q0 echoes the command"
            );
            if stop(&answer) {
                return answer;
            }
            match answer.param {
                ParamCode::Processing => {}
                ParamCode::Error if retries_left > 0 => {
                    retries_left -= 1;
                    eprintln!("{request:?} stopped on {answer:?}: the printer presses Retry");
                    let retry = Request::new(RequestCode::Button, ButtonCode::MIDDLE.0);
                    assert_eq!(self.ask(retry), Response::accepted(&retry));
                }
                _ => panic!("{request:?} ended otherwise: {answer:?}"),
            }
            assert!(Instant::now() < deadline, "{request:?} does not end: {answer:?}");
        }
    }
}

/// Read a pipe on a thread of its own; chunks arrive on the channel until the pipe ends.
fn spawn_reader(mut pipe: impl Read + Send + 'static) -> Receiver<Vec<u8>> {
    let (chunks, received) = mpsc::channel();
    thread::spawn(move || {
        let mut buffer = [0; 256];
        while let Ok(n @ 1..) = pipe.read(&mut buffer) {
            if chunks.send(buffer[..n].to_vec()).is_err() {
                return;
            }
        }
    });
    received
}

fn finished(code: RequestCode, value: u8) -> impl Fn(&Response) -> bool {
    move |answer| *answer == Response::finished(code, value, ResultCode::OK)
}

/// A whole session over stdin/stdout, as the printer's firmware would run it.
#[test]
fn stdio_serves_a_printer_session() {
    let events = EventsFile::create("stdio-session");
    let scale = TIME_SCALE.to_string();
    let mut sim = SimProcess::spawn(&["--stdio", "--time-scale", &scale, "--events", events.path()]);
    let stdin = sim.child.stdin.take().expect("stdin is piped");
    let stdout = sim.child.stdout.take().expect("stdout is piped");
    let mut printer = Printer::new(
        Box::new(stdin),
        FromUnit::Pipe(spawn_reader(stdout)),
        Some(events),
    );

    printer.handshake();

    // A tool change: the unit loads slot 1 into the printer's extruder, told of the sensor by `f`.
    let tool = Request::new(RequestCode::Tool, 1);
    printer.command(tool, finished(RequestCode::Tool, 1));
    assert_ne!(
        printer.reported_fsensor, 0,
        "the filament reached the printer's sensor"
    );

    let unload = Request::new(RequestCode::Unload, 0);
    printer.command(unload, finished(RequestCode::Unload, 0));
    assert_eq!(printer.reported_fsensor, 0, "the filament left the printer");

    let preload = Request::new(RequestCode::Load, 2);
    printer.command(preload, finished(RequestCode::Load, 2));

    // Eject stops on FILAMENT_EJECTED until the user presses Continue.
    let eject = Request::new(RequestCode::Eject, 2);
    let ejected = Response::error(RequestCode::Eject, 2, ErrorCode::FILAMENT_EJECTED);
    printer.command(eject, |answer| *answer == ejected);
    let button = Request::new(RequestCode::Button, ButtonCode::MIDDLE.0);
    assert_eq!(printer.ask(button), Response::accepted(&button));
    printer.poll(eject, finished(RequestCode::Eject, 2));

    // A frame with a bad CRC and garbage get no answer; the next good request is answered.
    printer.send_bytes(b"T1*00\n");
    printer.send_bytes(b"#\x01garbage\xff~~\n");
    let version = Request::new(RequestCode::Version, 0);
    assert_eq!(printer.ask(version), Response::read(&version, 3));

    // A slot the unit does not have: refused at once (Prusa's `R`), or accepted and then reported
    // INVALID_TOOL (what this firmware does, see tests/tool_change.rs).
    let no_such_slot = Request::new(RequestCode::Tool, 7);
    let answer = printer.ask(no_such_slot);
    if answer != Response::rejected(&no_such_slot) {
        assert_eq!(answer, Response::accepted(&no_such_slot));
        let invalid = Response::error(RequestCode::Tool, 7, ErrorCode::INVALID_TOOL);
        assert_eq!(printer.ask(Request::new(RequestCode::Query, 0)), invalid);
    }

    // A reset: no answer, the unit reboots, and a new handshake finds it idle.
    let events_before = printer.events().count();
    printer.send(Request::new(RequestCode::Reset, 0));
    printer.events().wait_for(events_before, "boot", |event| {
        event["kind"] == "power" && event["on"] == true
    });
    printer.handshake();

    // At the end of stdin the simulator finishes and exits cleanly.
    drop(printer);
    let (status, stderr) = sim.wait_for_exit();
    assert!(status.success(), "exit {status}: {stderr}");
    assert!(stderr.contains("3 slots, seed 1"), "start line: {stderr}");
}

/// `--pty` prints a path that a serial-port client opens, closes and opens again.
#[test]
fn pty_serves_a_serial_port_client() {
    let scale = TIME_SCALE.to_string();
    let mut sim = SimProcess::spawn(&["--pty", "--time-scale", &scale, "--quiet"]);
    let path = pty_path(&mut sim);
    assert!(path.starts_with('/'), "not a path: {path:?}");

    for session in 0..2 {
        let port = open_port(&path, session);
        let writer = port.try_clone().expect("the port can be cloned");
        let mut printer = Printer::new(Box::new(writer), FromUnit::Port(port), None);
        printer.handshake();
    }
}

/// The pty's path, as `mmu sim --pty` prints it.
fn pty_path(sim: &mut SimProcess) -> String {
    let stdout = sim.child.stdout.take().expect("stdout is piped");
    let (path_sender, path_receiver) = mpsc::channel();
    thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(stdout).read_line(&mut line);
        let _ = path_sender.send(line);
    });
    let path = path_receiver
        .recv_timeout(ANSWER_TIMEOUT)
        .expect("mmu sim prints the pty's path");
    path.trim_end().to_string()
}

/// The two halves of the product together, as a user runs them: `mmu printer --port` plays the
/// printer against `mmu sim --pty`, following the simulator's events for its filament sensor.
/// Slower than the simulator alone: the printer keeps its own clock in wall time.
#[test]
fn the_printer_tool_drives_the_simulator_over_a_pty() {
    let events = EventsFile::create("printer-over-pty");
    let mut sim = SimProcess::spawn(&["--pty", "--time-scale", "5", "--quiet", "--events", events.path()]);
    let path = pty_path(&mut sim);
    for action in [&["tool", "1"][..], &["eject", "2"][..]] {
        let output = Command::new(env!("CARGO_BIN_EXE_mmu"))
            .args(["printer", "--port", &path, "--fsensor-events", events.path()])
            .args(action)
            .output()
            .expect("the mmu binary runs");
        let out = String::from_utf8_lossy(&output.stdout);
        assert!(
            output.status.success(),
            "{action:?}: {out}{}",
            String::from_utf8_lossy(&output.stderr)
        );
        assert!(out.contains("connected: unit firmware 3.0.3"), "{out}");
        assert!(!out.contains("link lost"), "{out}");
    }
}

/// Open the pty exclusively, as serial-port clients do by default. The previous session's lock
/// can outlive it by a moment: a child another test forks at that time holds a copy of the
/// descriptor until it executes `mmu`.
fn open_port(path: &str, session: usize) -> Box<dyn SerialPort> {
    let deadline = Instant::now() + ANSWER_TIMEOUT;
    loop {
        match serialport::new(path, 115_200).timeout(ANSWER_TIMEOUT).open() {
            Ok(port) => return port,
            Err(err) if Instant::now() > deadline => panic!("session {session}: cannot open {path}: {err}"),
            Err(_) => thread::sleep(Duration::from_millis(10)),
        }
    }
}

/// Bad options fail before anything runs, with a message that says why.
#[test]
fn bad_options_are_refused_clearly() {
    for (args, message) in [
        (&["--stdio", "--fault", "jam"][..], "missing slot"),
        (&["--stdio", "--fault", "typo:1"], "faults are:"),
        (&["--stdio", "--slots", "9"], "1 to 5 slots"),
        (&["--stdio", "--slots", "0"], "1 to 5 slots"),
        (&["--stdio", "--time-scale", "0"], "time scale"),
        (&["--stdio", "--time-scale", "inf"], "time scale"),
        (&[], "--stdio|--pty"),
        (&["--stdio", "--pty"], "cannot be used with"),
    ] {
        let output = Command::new(env!("CARGO_BIN_EXE_mmu"))
            .arg("sim")
            .args(args)
            .stdin(Stdio::null())
            .output()
            .expect("the mmu binary runs");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert!(!output.status.success(), "{args:?} should fail");
        assert!(output.stdout.is_empty(), "{args:?} printed on stdout");
        assert!(stderr.contains(message), "{args:?}: {stderr:?} lacks {message:?}");
    }
}

/// Scheduled faults come and go in the events file and in the notes on stderr.
#[test]
fn scheduled_faults_are_reported() {
    let mut events = EventsFile::create("faults");
    let scale = TIME_SCALE.to_string();
    let mut sim = SimProcess::spawn(&[
        "--stdio",
        "--time-scale",
        &scale,
        "--events",
        events.path(),
        "--fault",
        "jam:1@10-50",
    ]);
    drop(sim.child.stdin.take());
    let (status, stderr) = sim.wait_for_exit();
    assert!(status.success(), "exit {status}: {stderr}");
    events.update();
    let faults: Vec<(&str, &str)> = events
        .events
        .iter()
        .filter(|event| event["kind"] == "fault")
        .map(|event| {
            (
                event["action"].as_str().unwrap_or(""),
                event["fault"].as_str().unwrap_or(""),
            )
        })
        .collect();
    assert_eq!(faults, [("inject", "jam:1"), ("clear", "jam:1")]);
    assert!(stderr.contains("faults: jam:1@10-50"), "{stderr}");
    assert!(stderr.contains("fault injected: jam:1"), "{stderr}");
    assert!(stderr.contains("fault cleared: jam:1"), "{stderr}");
}

/// The MK4's bootloader probe (`S`, then no answer for 500 ms, BFW `src/mmu2/mmu2_bootloader.cpp`)
/// reaches the unit as it is sent, pauses and all, so the first `S0` after it is answered: the
/// simulator passes the printer's bytes as they arrive instead of gathering them to a newline.
#[test]
fn the_bootloader_probe_costs_the_printer_no_s0() {
    let scale = TIME_SCALE.to_string();
    let mut sim = SimProcess::spawn(&[
        "--stdio",
        "--time-scale",
        &scale,
        "--quiet",
        "--printer",
        "buddy-6.5",
    ]);
    let stdin = sim.child.stdin.take().expect("stdin is piped");
    let stdout = sim.child.stdout.take().expect("stdout is piped");
    let mut printer = Printer::new(Box::new(stdin), FromUnit::Pipe(spawn_reader(stdout)), None);
    thread::sleep(Duration::from_millis(200));
    for _ in 0..2 {
        printer.send_bytes(b"S");
        // 500 virtual ms without an answer.
        thread::sleep(Duration::from_millis(500 / TIME_SCALE));
    }
    let version = Request::new(RequestCode::Version, 0);
    assert_eq!(printer.ask(version), Response::read(&version, 3));
    drop(printer);
    let (status, stderr) = sim.wait_for_exit();
    assert!(status.success(), "exit {status}: {stderr}");
}

/// `--printer` names the printer whose extruder is played; the start line says which.
#[test]
fn the_printer_played_is_chosen_and_named() {
    let output = Command::new(env!("CARGO_BIN_EXE_mmu"))
        .args(["sim", "--stdio", "--printer", "buddy-6.5"])
        .stdin(Stdio::null())
        .output()
        .expect("the mmu binary runs");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(stderr.contains("printer buddy-6.5"), "{stderr}");
    let output = Command::new(env!("CARGO_BIN_EXE_mmu"))
        .args(["sim", "--stdio", "--printer", "mk4"])
        .stdin(Stdio::null())
        .output()
        .expect("the mmu binary runs");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("buddy-6.5, buddy-6.4, mk3s"), "{stderr}");
}
