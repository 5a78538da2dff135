//! `mmu sim`: the simulated unit served to a real printer-side program, on stdin/stdout or a
//! pseudo-terminal.
//!
//! The simulator ([`Sim`]) runs in virtual time, one millisecond per step, and knows nothing of
//! clocks or file descriptors. This module paces it against the wall clock (`--time-scale`
//! virtual ms per wall ms) and connects it to a byte stream, so that a program that only knows
//! the wire protocol (`mmu printer`, a test, a printer's firmware behind a pty) talks to it as to
//! a unit on a UART. The protocol channel carries the unit's bytes exactly as on the wire and
//! nothing else; notes go to stderr.
//!
//! Unless `--quiet`, stderr tells a person watching what is served, in words: each request and
//! answer (`> T1  tool change slot 1`), frames the unit ignores and why (a bad CRC, an unknown
//! code), and the simulator's events (commands, the printer's filament sensor, faults, power).
//!
//! The printer's filament sensor is part of the simulation, but only the printer reports it
//! (`f`). The `--events` file makes it visible, for the printer-side program to follow: one JSON
//! line per event, e.g. `{"t_ms":1234,"kind":"fsensor","state":2}`, written at once.
//!
//! Shape: a reader thread turns the input (stdin, or the pty's master end) into chunks on a
//! channel; the main loop feeds each chunk to the step after its arrival, writes what the unit
//! answers at once, and waits for input or the next millisecond whenever it is not behind.

use std::collections::HashMap;
use std::error::Error;
use std::fs::File;
use std::io::{self, Read, Write};
use std::path::{Path, PathBuf};
use std::process::Stdio;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, TryRecvError};
use std::thread;
use std::time::{Duration, Instant};

use clap::{ArgGroup, Args};
use mmu_firmware::profile::{self, Profile};
use mmu_protocol::{
    DecodeError, Request, RequestCode, RequestDecoder, Response, ResponseDecoder, SILENCE_MS,
};
use mmu_sim::event::FaultAction;
use mmu_sim::firmware::{FirmwareUnit, default_fil_dir};
use mmu_sim::{Event, EventKind, ExtruderGeometry, FAULT_HELP, Personality, ScheduledFault, Sim, SimOptions};

use crate::explain::{request_meaning, response_meaning};
use crate::usage::usage;

/// After stdin ends, the simulator runs this long more, in virtual and in wall time, so that the
/// answer to the last request still goes out.
const EOF_GRACE: Duration = Duration::from_millis(100);
/// [`EOF_GRACE`] in virtual ms.
const EOF_GRACE_MS: u64 = EOF_GRACE.as_millis() as u64;
/// Longest wait for input while the simulator is not behind.
const IDLE_WAIT: Duration = Duration::from_millis(1);
/// Most steps between two looks at the input, so that a simulator that cannot keep up with the
/// time scale still hears the printer and answers promptly.
const MAX_STEPS_PER_BATCH: u64 = 100;
/// Falling this far behind the wall clock earns one warning.
const LAG_WARNING: Duration = Duration::from_secs(1);
/// An unfinished frame is shown up to this many bytes.
const MAX_SHOWN_LINE: usize = 40;
/// A poll answered as the time before, at most this long before, is a printer's routine poll.
const POLL_REPEAT_MS: u64 = 3000;
/// Bytes the reader thread takes from the input at once.
const READ_CHUNK: usize = 256;

/// `mmu sim` options.
#[derive(Debug, Args)]
#[command(group(ArgGroup::new("transport").required(true).args(["stdio", "pty"])))]
#[command(after_long_help = format!("Faults (--fault SPEC):\n{FAULT_HELP}"))]
pub struct SimArgs {
    /// Serve the protocol on stdin/stdout; stdout carries only the unit's bytes. Exits when stdin
    /// ends.
    #[arg(long)]
    pub stdio: bool,
    /// Create a pseudo-terminal, print its path on stdout and serve the protocol on it until
    /// killed.
    #[arg(long)]
    pub pty: bool,
    /// Write every simulator event (filament sensor, faults, power, commands, slot motion) to
    /// this file, one JSON line each, flushed at once.
    #[arg(long, value_name = "PATH")]
    pub events: Option<PathBuf>,
    /// Slots of the unit, 1 to 5.
    #[arg(long, value_name = "N", default_value_t = 3, value_parser = parse_slots)]
    pub slots: usize,
    /// Seed of every random draw (sensor noise, UART faults).
    #[arg(long, value_name = "S", default_value_t = 1)]
    pub seed: u64,
    /// What senses each lane: thesis (analog Hall per motor, hub sensors), n20-quadrature (N20
    /// encoder gear motors, hub sensors), bmcu-c (AS5600 on the drive gear, tension per lane,
    /// no hub sensor; 4 lanes).
    #[arg(long, value_name = "NAME", default_value = "thesis", value_parser = parse_hardware)]
    pub hardware: &'static Profile,
    /// Virtual ms per wall ms: 1 is real time, 10 runs ten times faster.
    #[arg(long, value_name = "K", default_value_t = 1.0, value_parser = parse_time_scale)]
    pub time_scale: f64,
    /// Inject a fault, e.g. `jam:1@2000-9000` (at 2 s of virtual time, cleared at 9 s); may be
    /// repeated. `mmu sim --help` lists the faults.
    #[arg(long = "fault", value_name = "SPEC", value_parser = parse_fault)]
    pub faults: Vec<ScheduledFault>,
    /// How fast the simulated printer pulls filament while it prints after a tool change, mm/s
    /// (0: it does not print).
    #[arg(
        long,
        value_name = "MM_S",
        default_value_t = SimOptions::default().print_mm_s,
        value_parser = parse_print_rate
    )]
    pub print_rate: f32,
    /// The printer whose extruder the simulator plays around a tool change: buddy-6.5 (Buddy
    /// 6.5.3 and later: T before its own 80 mm retract, co-feed from P1c, premature finish),
    /// buddy-6.4, mk3s (T once the filament is out of the gears).
    #[arg(long, value_name = "PRINTER", default_value = "buddy-6.4", value_parser = crate::printer_cli::parse_personality)]
    pub printer: Personality,
    /// Where the printer's extruder gears sit against its filament sensor: sensor-first (MK3S,
    /// MK3.5: the sensor 4 mm before the gears), gears-first (the Nextruder of the MK4, MK3.9
    /// and Core One: the gears 10 mm before the sensor), or the gears' distance past the sensor
    /// in mm (negative: gears first). Default: the --printer's (buddy-6.5 gears-first,
    /// buddy-6.4 and mk3s sensor-first).
    #[arg(long, value_name = "GEOMETRY", value_parser = parse_extruder)]
    pub extruder: Option<ExtruderGeometry>,
    /// Run this firmware image (ELF) on its board's emulated chip (the bench of `fil/`) instead
    /// of the host-built logic: the binary you are about to flash, on the same wire.
    #[arg(long, value_name = "ELF", requires = "board")]
    pub firmware: Option<PathBuf>,
    /// The board of --firmware: g071 (NUCLEO-G071RB), pico (Raspberry Pi Pico) or bmcu (the
    /// BMCU-C's CH32V203: with --slots 4 --hardware bmcu-c).
    #[arg(long, value_name = "BOARD", value_parser = crate::fil_cli::parse_board, requires = "firmware")]
    pub board: Option<mmu_sim::firmware::Board>,
    /// Print nothing on stderr but errors (no log of requests, answers and events).
    #[arg(long, short, conflicts_with = "verbose")]
    pub quiet: bool,
    /// Log every exchange, also the printer's polls (`Q0`, `R`) answered as the time before.
    #[arg(long, short)]
    pub verbose: bool,
}

/// Run `mmu sim`.
pub fn run(args: &SimArgs) -> Result<(), Box<dyn Error>> {
    for fault in &args.faults {
        fault
            .fault
            .check_slots(args.slots)
            .map_err(|error| usage(error.to_string()))?;
    }
    let options = SimOptions {
        slots: args.slots,
        seed: args.seed,
        print_mm_s: args.print_rate,
        printer: args.printer,
        extruder: args.extruder,
        ..SimOptions::for_hardware(args.hardware)
    };
    let mut sim = match (&args.firmware, args.board) {
        (Some(image), Some(board)) => {
            let unit = FirmwareUnit::start(
                board,
                image,
                &default_fil_dir(),
                options.unit.clone(),
                Stdio::inherit(),
            )?;
            if unit.slots() != args.slots {
                return Err(usage(format!(
                    "the image has {} slots, not {}: --slots {}",
                    unit.slots(),
                    args.slots,
                    unit.slots()
                )));
            }
            if unit.profile() != args.hardware {
                let built_for = unit.profile().name;
                return Err(usage(format!(
                    "the image is built for the {built_for} hardware, not {}: --hardware {built_for}",
                    args.hardware.name
                )));
            }
            Sim::with_unit(options, Box::new(unit))
        }
        _ => Sim::new(options)?,
    };
    for fault in &args.faults {
        sim.schedule(*fault);
    }
    let events = args.events.as_deref().map(create_events_file).transpose()?;
    let notes = Notes { quiet: args.quiet };
    notes.say(&start_line(args));
    let server = Server {
        sim,
        events,
        notes,
        wire: WireLog::new(args.verbose),
        time_scale: args.time_scale,
        lag_warned: false,
    };
    if args.stdio {
        let input = spawn_reader(Box::new(io::stdin()));
        server.serve(input, Box::new(io::stdout().lock()))
    } else {
        serve_pty(server)
    }
}

/// The simulator with its pacing and its side outputs.
struct Server {
    sim: Sim,
    events: Option<File>,
    notes: Notes,
    wire: WireLog,
    time_scale: f64,
    /// The lag warning was given.
    lag_warned: bool,
}

impl Server {
    /// Run until the input ends (plus a grace period), the output is closed, or an error.
    fn serve(
        mut self,
        input: Receiver<io::Result<Vec<u8>>>,
        mut output: Box<dyn Write>,
    ) -> Result<(), Box<dyn Error>> {
        let mut inbox = Inbox {
            chunks: Some(input),
            pending: Vec::new(),
        };
        let start = Instant::now();
        let mut input_ended: Option<(u64, Instant)> = None;
        loop {
            let now_ms = self.sim.now_ms();
            if input_ended
                .is_some_and(|(at_ms, at)| now_ms >= at_ms + EOF_GRACE_MS && at.elapsed() >= EOF_GRACE)
            {
                return Ok(());
            }
            let behind_ms = self.due_ms(start.elapsed()).saturating_sub(now_ms);
            if behind_ms == 0 {
                inbox.collect(IDLE_WAIT)?;
            } else {
                inbox.collect(Duration::ZERO)?;
                self.warn_if_lagging(behind_ms);
                let steps = behind_ms.min(MAX_STEPS_PER_BATCH);
                if !self.run_steps(steps, &mut inbox.pending, &mut output)? {
                    return Ok(());
                }
            }
            if input_ended.is_none() && inbox.chunks.is_none() {
                input_ended = Some((self.sim.now_ms(), Instant::now()));
            }
        }
    }

    /// Step the simulator `steps` times, `received` going in with the first step, then pass on
    /// what the unit sent and what happened. False when the printer side closed the output.
    fn run_steps(
        &mut self,
        steps: u64,
        received: &mut Vec<u8>,
        output: &mut dyn Write,
    ) -> Result<bool, Box<dyn Error>> {
        let mut sent = Vec::new();
        // The log of this batch, in the simulator's time order: what the printer sent, what the
        // unit answered (at the step it answered in), what happened.
        let mut log: Vec<(u64, String)> = Vec::new();
        let logging = !self.notes.quiet;
        if logging && !received.is_empty() {
            let at = self.sim.now_ms();
            log.extend(self.wire.printer_sent(at, received));
        }
        for _ in 0..steps {
            let before = sent.len();
            let heard = !received.is_empty();
            self.sim.step(received, &mut sent);
            received.clear();
            if logging {
                let at = self.sim.now_ms();
                if sent.len() > before {
                    log.extend(self.wire.unit_sent(at, sent.get(before..).unwrap_or(&[])));
                }
                if !heard {
                    log.extend(self.wire.printer_quiet(at));
                }
            }
        }
        let open = self.send(output, &sent)?;
        log.extend(self.record_events()?);
        log.sort_by_key(|(at, _)| *at);
        for (at, line) in log {
            self.notes.at(at, &line);
        }
        Ok(open)
    }

    /// Say once that the machine is too slow for the time scale.
    fn warn_if_lagging(&mut self, behind_ms: u64) {
        let behind_wall_ms = behind_ms as f64 / self.time_scale;
        if !self.lag_warned && behind_wall_ms > LAG_WARNING.as_millis() as f64 {
            self.lag_warned = true;
            self.notes.say(&format!(
                "the simulator cannot keep up with --time-scale {}: virtual time lags behind",
                self.time_scale
            ));
        }
    }

    /// Virtual time due after `elapsed` of wall time, ms.
    fn due_ms(&self, elapsed: Duration) -> u64 {
        // Saturating conversion: a float too large for u64 gives u64::MAX.
        (elapsed.as_secs_f64() * 1000.0 * self.time_scale) as u64
    }

    /// Write the unit's bytes and flush. False when the printer side closed the output.
    fn send(&self, output: &mut dyn Write, bytes: &[u8]) -> Result<bool, Box<dyn Error>> {
        if bytes.is_empty() {
            return Ok(true);
        }
        match output.write_all(bytes).and_then(|()| output.flush()) {
            Ok(()) => Ok(true),
            Err(err) if err.kind() == io::ErrorKind::BrokenPipe => {
                self.notes.say("the printer side closed the output; stopping");
                Ok(false)
            }
            Err(err) if err.kind() == io::ErrorKind::TimedOut => {
                // A pty nobody reads: the unit's UART would drop the bytes too.
                self.notes
                    .say(&format!("nobody reads the output: {} bytes dropped", bytes.len()));
                Ok(true)
            }
            Err(err) => Err(format!("cannot write the unit's bytes: {err}").into()),
        }
    }

    /// Write the simulator's new events to the events file; returns the notes on the notable
    /// ones for stderr. The lines go out in one write, so that a reader following the file never
    /// sees half a line.
    fn record_events(&mut self) -> Result<Vec<(u64, String)>, Box<dyn Error>> {
        let events = self.sim.take_events();
        if events
            .iter()
            .any(|event| matches!(event.what, EventKind::Power { on: true }))
        {
            self.wire.unit_booted();
        }
        let notes = events
            .iter()
            .filter_map(|event| event_note(event).map(|note| (event.t_ms, note)))
            .collect();
        if let Some(file) = &mut self.events {
            let lines: String = events.iter().map(|event| event.to_json() + "\n").collect();
            file.write_all(lines.as_bytes())
                .map_err(|err| format!("cannot write the events file: {err}"))?;
        }
        Ok(notes)
    }
}

/// Serve on a new pseudo-terminal until killed.
#[cfg(unix)]
fn serve_pty(server: Server) -> Result<(), Box<dyn Error>> {
    use serialport::{SerialPort, TTYPort};

    let (master, slave) = TTYPort::pair().map_err(|err| format!("cannot create a pseudo-terminal: {err}"))?;
    let path = slave.name().ok_or("the pseudo-terminal has no path")?;
    let reader = master
        .try_clone_native()
        .map_err(|err| format!("cannot share the pseudo-terminal: {err}"))?;
    let mut stdout = io::stdout();
    writeln!(stdout, "{path}")
        .and_then(|()| stdout.flush())
        .map_err(|err| format!("cannot print the pseudo-terminal's path: {err}"))?;
    server.notes.say(&format!("serving on {path}"));
    // Our own open slave end: without it the master end hangs up (reads and writes fail)
    // whenever no client has the path open, e.g. before the first client or between two.
    let _keep_open = slave;
    server.serve(spawn_reader(Box::new(reader)), Box::new(master))
}

/// Pseudo-terminals are a Unix thing.
#[cfg(not(unix))]
fn serve_pty(_server: Server) -> Result<(), Box<dyn Error>> {
    Err("--pty needs a Unix system; use --stdio".into())
}

/// The printer's bytes, as the reader thread hands them over.
struct Inbox {
    /// `None` once the input ended.
    chunks: Option<Receiver<io::Result<Vec<u8>>>>,
    /// Received, not yet given to the simulator.
    pending: Vec<u8>,
}

impl Inbox {
    /// Take whatever arrived, waiting up to `wait` for the first chunk (just waiting, once the
    /// input ended).
    fn collect(&mut self, wait: Duration) -> Result<(), Box<dyn Error>> {
        let Some(chunks) = &self.chunks else {
            thread::sleep(wait);
            return Ok(());
        };
        let mut next = chunks.recv_timeout(wait);
        loop {
            match next {
                Ok(chunk) => {
                    let chunk = chunk.map_err(|err| format!("cannot read the printer's bytes: {err}"))?;
                    self.pending.extend_from_slice(&chunk);
                }
                Err(RecvTimeoutError::Timeout) => return Ok(()),
                Err(RecvTimeoutError::Disconnected) => break,
            }
            next = chunks.try_recv().map_err(|err| match err {
                TryRecvError::Empty => RecvTimeoutError::Timeout,
                TryRecvError::Disconnected => RecvTimeoutError::Disconnected,
            });
        }
        self.chunks = None;
        Ok(())
    }
}

/// Read `input` on a thread of its own until it ends; the chunks arrive on the returned channel,
/// which disconnects at the end of the input (after an error, if one ended it).
fn spawn_reader(mut input: Box<dyn Read + Send>) -> Receiver<io::Result<Vec<u8>>> {
    let (chunks, received) = mpsc::channel();
    thread::spawn(move || {
        let mut buffer = [0; READ_CHUNK];
        loop {
            let chunk = match input.read(&mut buffer) {
                Ok(0) => return,
                Ok(n) => Ok(buffer[..n].to_vec()),
                // A serial port's read times out when nothing comes: keep waiting.
                Err(err)
                    if matches!(
                        err.kind(),
                        io::ErrorKind::Interrupted | io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock
                    ) =>
                {
                    continue;
                }
                Err(err) => Err(err),
            };
            let failed = chunk.is_err();
            if chunks.send(chunk).is_err() || failed {
                return;
            }
        }
    });
    received
}

/// Human-readable lines on stderr, unless `--quiet`.
#[derive(Debug, Clone, Copy)]
struct Notes {
    quiet: bool,
}

impl Notes {
    fn say(&self, line: &str) {
        if !self.quiet {
            eprintln!("mmu sim: {line}");
        }
    }

    /// A line stamped with the simulator's clock.
    fn at(&self, t_ms: u64, line: &str) {
        self.say(&format!("{:>9.3} s  {line}", t_ms as f64 / 1000.0));
    }
}

/// Decodes both directions of the wire for the log: what the printer asked, what the unit
/// answered, and the frames the unit ignores with the reason. A printer polls `Q0` and five
/// registers every second; unless `every`, a poll answered as the last time, less than
/// [`POLL_REPEAT_MS`] before, is left out (and counted), so that what changes stands out, while a
/// person typing a read sees every answer.
struct WireLog {
    requests: RequestDecoder,
    responses: ResponseDecoder,
    every: bool,
    /// A poll request waiting for its answer, with its time and line.
    pending: Option<(u64, Request, String)>,
    /// The last answer to each poll request, and when.
    last: HashMap<(RequestCode, u8), (Response, u64)>,
    /// Polls left out since the last line shown.
    hidden: u32,
    /// The printer's bytes since its last newline, to show an unfinished frame.
    line: Vec<u8>,
    /// Milliseconds since the printer's last byte.
    quiet_ms: u32,
}

/// A log line and the simulator's time it belongs to.
type LogLine = (u64, String);

impl WireLog {
    fn new(every: bool) -> Self {
        WireLog {
            // As the unit's: it starts mid-line, taking a frame only after a silence.
            requests: RequestDecoder::new_mid_line(),
            responses: ResponseDecoder::new(),
            every,
            pending: None,
            last: HashMap::new(),
            hidden: 0,
            line: Vec::new(),
            quiet_ms: 0,
        }
    }

    /// The unit booted: its decoder starts mid-line again.
    fn unit_booted(&mut self) {
        self.requests = RequestDecoder::new_mid_line();
        self.line.clear();
    }

    /// A millisecond without a byte from the printer: once the line has been silent for
    /// [`SILENCE_MS`] the decoder is told, as the unit's is, and a frame left unfinished (a
    /// person who stopped typing) is reported.
    fn printer_quiet(&mut self, at: u64) -> Vec<LogLine> {
        let mut lines = Vec::new();
        self.quiet_ms = self.quiet_ms.saturating_add(1);
        if self.quiet_ms >= SILENCE_MS && self.requests.line_silent().is_some() {
            self.flush_pending(&mut lines);
            let text = String::from_utf8_lossy(&self.line).into_owned();
            self.show(
                &mut lines,
                at,
                format!(
                    "> frame ignored: {text} unfinished: the line fell silent before its *CRC and newline"
                ),
            );
            self.line.clear();
        }
        lines
    }

    /// Show `line`, after saying how many unchanged polls were left out before it.
    fn show(&mut self, into: &mut Vec<LogLine>, at: u64, line: String) {
        if self.hidden > 0 {
            let polls = self.hidden;
            self.hidden = 0;
            into.push((
                at,
                format!("({polls} polls answered as before not shown; -v shows them)"),
            ));
        }
        into.push((at, line));
    }

    fn flush_pending(&mut self, into: &mut Vec<LogLine>) {
        if let Some((at, _, line)) = self.pending.take() {
            self.show(into, at, line);
        }
    }

    /// The log lines for bytes the printer sent at `at`.
    fn printer_sent(&mut self, at: u64, bytes: &[u8]) -> Vec<LogLine> {
        let mut lines = Vec::new();
        self.quiet_ms = 0;
        for &byte in bytes {
            if byte == b'\n' {
                self.line.clear();
            } else if self.line.len() < MAX_SHOWN_LINE {
                self.line.push(byte);
            }
        }
        let decoded: Vec<_> = bytes
            .iter()
            .filter_map(|&byte| self.requests.feed(byte))
            .collect();
        for frame in decoded {
            self.flush_pending(&mut lines);
            match frame {
                Ok(request)
                    if !self.every && matches!(request.code, RequestCode::Query | RequestCode::Read) =>
                {
                    self.pending = Some((at, request, request_line(&request)));
                }
                Ok(request) => self.show(&mut lines, at, request_line(&request)),
                Err(error) => self.show(
                    &mut lines,
                    at,
                    format!("> frame ignored: {}", ignored_reason(&error)),
                ),
            }
        }
        lines
    }

    /// The log lines for bytes the unit sent at `at`.
    fn unit_sent(&mut self, at: u64, bytes: &[u8]) -> Vec<LogLine> {
        let mut lines = Vec::new();
        let decoded: Vec<_> = bytes
            .iter()
            .filter_map(|&byte| self.responses.feed(byte))
            .collect();
        for frame in decoded {
            let response = match frame {
                Ok(response) => response,
                Err(error) => {
                    self.flush_pending(&mut lines);
                    self.show(&mut lines, at, format!("< unreadable answer: {error}"));
                    continue;
                }
            };
            let key = (response.code, response.value);
            let answers_pending = self
                .pending
                .as_ref()
                .is_some_and(|(_, request, _)| (request.code, request.value) == key);
            let repeated = self.last.get(&key).is_some_and(|&(last, last_at)| {
                last == response && at.saturating_sub(last_at) < POLL_REPEAT_MS
            });
            if answers_pending {
                self.last.insert(key, (response, at));
            }
            if answers_pending && repeated {
                self.pending = None;
                self.hidden += 1;
                continue;
            }
            self.flush_pending(&mut lines);
            self.show(&mut lines, at, response_line(&response));
        }
        lines
    }
}

/// `> T1*cf  tool change slot 1`.
fn request_line(request: &Request) -> String {
    format!("> {}  {}", request.encode().as_str(), request_meaning(request))
}

/// `< T1 A*27  accepted`.
fn response_line(response: &Response) -> String {
    format!("< {}  {}", response.encode().as_str(), response_meaning(response))
}

/// Why the unit ignores a frame, in words; a bad CRC names the one it should carry.
fn ignored_reason(error: &DecodeError<Request>) -> String {
    match error {
        DecodeError::BadCrc {
            frame,
            computed,
            received,
        } => {
            let body = frame.encode();
            let body = body.as_str().split('*').next().unwrap_or("");
            format!(
                "{body} ({}) has a bad CRC: it carries {received:02x}, the unit expects {computed:02x} ({body}*{computed:02x})",
                request_meaning(frame)
            )
        }
        DecodeError::AfterBrokenFrame => format!(
            "the line was not quiet for {SILENCE_MS} ms before it (the unit was starting, or a broken frame came just before): \
             the unit takes a frame only at the start of a quiet line"
        ),
        other => other.to_string(),
    }
}

/// What the simulator is set up with, as one line (the printer played only when it is not the
/// default).
fn start_line(args: &SimArgs) -> String {
    let printer = if args.printer == Personality::default() {
        String::new()
    } else {
        format!(", printer {}", args.printer)
    };
    let extruder = match args.extruder {
        Some(geometry) if geometry != args.printer.extruder() => format!(", extruder {geometry}"),
        _ => String::new(),
    };
    let faults = if args.faults.is_empty() {
        String::from("none")
    } else {
        args.faults.iter().map(fault_spec).collect::<Vec<_>>().join(", ")
    };
    let unit = match (&args.firmware, args.board) {
        (Some(image), Some(board)) => {
            format!(", firmware {} on an emulated {}", image.display(), board.name())
        }
        _ => String::new(),
    };
    format!(
        "{} slots, seed {}, time scale {}x, print rate {} mm/s, faults: {faults}{printer}{extruder}{unit}",
        args.slots, args.seed, args.time_scale, args.print_rate
    )
}

/// A scheduled fault in `--fault` syntax.
fn fault_spec(fault: &ScheduledFault) -> String {
    match fault.until_ms {
        Some(until_ms) => format!("{}@{}-{until_ms}", fault.fault, fault.at_ms),
        None => format!("{}@{}", fault.fault, fault.at_ms),
    }
}

/// The stderr note for an event worth telling a person about (not the slots' motion).
fn event_note(event: &Event) -> Option<String> {
    let what = match &event.what {
        EventKind::Fault {
            action: FaultAction::Inject,
            fault,
        } => format!("fault injected: {fault}"),
        EventKind::Fault {
            action: FaultAction::Clear,
            fault,
        } => format!("fault cleared: {fault}"),
        EventKind::Power { on: false } => String::from("the unit lost power"),
        EventKind::Power { on: true } => String::from("the unit booted"),
        EventKind::Command { request, status } => format!("command {request}: {status}"),
        EventKind::Fsensor { state } => format!(
            "the printer's filament sensor: {}",
            match state {
                0 => "no filament",
                1 => "filament at the sensor",
                2 => "filament in the nozzle",
                _ => "unknown",
            }
        ),
        EventKind::Extruder { action, mm } => format!("the printer's extruder: {action} {mm:.1} mm"),
        // Motion: many per second; the events file has them.
        EventKind::Slot { .. } | EventKind::Motor { .. } => return None,
    };
    Some(what)
}

/// Create (or truncate) the events file.
fn create_events_file(path: &Path) -> Result<File, Box<dyn Error>> {
    File::create(path)
        .map_err(|err| format!("cannot create the events file {}: {err}", path.display()).into())
}

/// A slot count, 1 to the firmware's most (also for `mmu printer --slots`).
pub(crate) fn parse_slots(text: &str) -> Result<usize, String> {
    let max = mmu_firmware::MAX_SLOTS;
    match text.parse::<usize>() {
        Ok(slots) if (1..=max).contains(&slots) => Ok(slots),
        _ => Err(format!("a unit has 1 to {max} slots")),
    }
}

/// A hardware profile by name (also for `mmu printer --sim --hardware`).
pub(crate) fn parse_hardware(text: &str) -> Result<&'static Profile, String> {
    profile::by_name(text).ok_or_else(|| {
        let names: Vec<&str> = profile::ALL.iter().map(|p| p.name).collect();
        format!("the hardware is one of {}", names.join(", "))
    })
}

/// `sensor-first`, `gears-first` or the gears' distance past the sensor in mm (also for
/// `mmu printer --sim --extruder`).
pub(crate) fn parse_extruder(text: &str) -> Result<ExtruderGeometry, String> {
    text.parse::<ExtruderGeometry>()
        .map_err(|error| error.to_string())
}

fn parse_time_scale(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(scale) if scale.is_finite() && scale > 0.0 => Ok(scale),
        _ => Err(String::from("the time scale is a number above 0 (1: real time)")),
    }
}

fn parse_print_rate(text: &str) -> Result<f32, String> {
    match text.parse::<f32>() {
        Ok(rate) if rate.is_finite() && rate >= 0.0 => Ok(rate),
        _ => Err(String::from("the print rate is a number of mm/s, 0 or more")),
    }
}

fn parse_fault(text: &str) -> Result<ScheduledFault, String> {
    text.parse::<ScheduledFault>().map_err(|err| err.to_string())
}
