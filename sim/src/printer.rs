//! The printer's side of the protocol, as Prusa's firmware plays it (spec §5): the handshake with
//! its exact version check, `Q0` one heartbeat after the last activity, `f` reports the
//! moment the printer's filament sensor changes, the register poll, automatic Retry (`B1`) up to
//! three times per command, a link timeout followed by a new handshake, and the mmu2 layer's
//! "unload, then again" when the unit restarted under a command. The heartbeat, the timeout, the
//! version, the registers polled and the 6.5.3 "premature finish" of a tool change depend on the
//! printer played, its [`Personality`].
//!
//! It talks through a [`Link`] (the in-process simulator, or a serial port in `mmu`), and a
//! person at the printer (an [`Operator`]) sees what happens and decides on errors.

use std::io;

use mmu_protocol::{
    ButtonCode, ErrorCode, ParamCode, ProgressCode, Request, RequestCode, Response, ResponseDecoder,
    ResultCode,
};

use crate::personality::Personality;
/// Consecutive link faults before the printer reports MMU_NOT_RESPONDING or PROTOCOL_ERROR,
/// whichever came first (`DropOutFilter`: one count for both, reset by every version answer
/// the printer accepts, `ProcessVersionResponse` calls `ResetCommunicationTimeoutAttempts`).
pub const MAX_DROPOUTS: u8 = 10;
/// How long after its start the printer first talks to the unit, ms.
const BOOT_WAIT_MS: u64 = 100;
/// Version answers that may be wrong during one handshake (`maxRetries`).
pub const VERSION_RETRIES: u8 = 6;
/// Automatic Retry presses per command (`MAX_RETRIES`).
pub const AUTO_RETRIES: u8 = 3;
/// How long the printer keeps sending a rejected command again (a unit still starting up rejects
/// commands for a moment) before this tool gives up, ms; the printer itself never gives up.
const REJECTS_FOR_MS: u64 = 2000;
/// Answers with the wrong code while a version is asked for, before the link counts as garbled.
const MAX_WRONG_ANSWERS: u8 = 10;
/// The link is looked at this often while waiting, ms.
const POLL_STEP_MS: u64 = 5;
/// A request whose answer is lost this many times, each time after a good handshake, ends the
/// session (the printer itself would retry for ever).
const MAX_REQUEST_ATTEMPTS: u8 = 5;
/// The mmu2 layer repeats a command interrupted by a unit restart this many times.
const MAX_INTERRUPTS: u8 = 3;

/// The wire to the unit, with the printer's clock and filament sensor.
pub trait Link {
    /// Send bytes to the unit.
    fn send(&mut self, bytes: &[u8]) -> io::Result<()>;
    /// Wait up to `max_ms` for bytes from the unit, append them to `into`, and return as soon as
    /// some arrived.
    fn receive(&mut self, max_ms: u64, into: &mut Vec<u8>) -> io::Result<()>;
    /// The printer's clock, ms (virtual for the simulator, wall time for a serial port).
    fn now_ms(&self) -> u64;
    /// The printer's filament sensor as `f` reports it: 0 none, 1 at the sensor, 2 in the nozzle.
    fn fsensor(&mut self) -> u8;
}

/// What the printer's firmware is set up with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PrinterOptions {
    /// The printer firmware played: its timing, its register poll, its tool change.
    pub personality: Personality,
    /// The unit version it supports: S0..S2 must answer exactly this (3.0.4 on Buddy 6.5.3 and
    /// later, 3.0.3 on Buddy 6.4 and MK3S 3.14.1, 3.0.2 on MK3S 3.13.3/3.14.0;
    /// [`Personality::version`] with [`PrinterOptions::of`]).
    pub version: (u8, u8, u8),
    /// Written to register 0x0b at every start (Buddy firmware writes 5).
    pub extra_load_mm: u16,
    /// Written to register 0x14 at every start.
    pub slow_feed_mm_s: u16,
    /// A command still running after this long counts as stuck, ms.
    pub command_timeout_ms: u64,
    /// Only look: the handshake writes no register (no `W0b`, no `W14`) and no `f` report ever
    /// goes out, so a bench tool reading a unit's settings or sensors changes nothing in it.
    pub read_only: bool,
}

impl PrinterOptions {
    /// The printer `personality` with the unit version it wants and Prusa's start-up writes.
    pub fn of(personality: Personality) -> Self {
        PrinterOptions {
            personality,
            version: personality.version(),
            ..PrinterOptions::default()
        }
    }
}

impl Default for PrinterOptions {
    fn default() -> Self {
        PrinterOptions {
            personality: Personality::default(),
            // What today's Buddy printers want; the timing and tool change stay Buddy 6.4's
            // until the unit plays the 3.0.4 contract.
            version: (3, 0, 4),
            extra_load_mm: 5,
            slow_feed_mm_s: 20,
            command_timeout_ms: 10 * 60 * 1000,
            read_only: false,
        }
    }
}

/// Something the person at the printer could see.
#[derive(Debug, Clone, PartialEq)]
pub enum PrinterEvent {
    /// A request went out.
    Sent(Request),
    /// An answer came in.
    Received(Response),
    /// The handshake passed.
    Connected {
        /// S0..S2.
        version: (u8, u8, u8),
        /// S3.
        build: u16,
    },
    /// The command in progress reached a new phase.
    Progress(Request, ProgressCode),
    /// The command stopped on an error.
    Error(Request, ErrorCode),
    /// The printer pressed Retry itself; `left` automatic presses remain.
    AutoRetry(ErrorCode, u8),
    /// A button went to the unit.
    Button(ButtonCode),
    /// The command finished.
    Finished(Request, ResultCode),
    /// No valid answer; the printer re-handshakes.
    LinkLost(LinkFault),
    /// The unit restarted under the command; the printer repeats it.
    Interrupted(Request),
    /// One `Q0` cycle of a command passed.
    Heartbeat(Request),
    /// The printer left the tool change before the unit finished it (Buddy 6.5.3: its own
    /// sensor saw the filament during `P1c`, or the unit went on to `P2`); it loads on to the
    /// nozzle and keeps polling until the unit's `F`.
    PrematureFinish(Request),
}

/// Why the printer lost the link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkFault {
    /// No complete answer within the link timeout (the printer's `CommunicationTimeout`).
    Timeout,
    /// An answer that does not decode or does not fit (`ProtocolError`).
    Garbled,
}

impl LinkFault {
    /// `timeout` or `garbled`.
    pub fn as_str(self) -> &'static str {
        match self {
            LinkFault::Timeout => "timeout",
            LinkFault::Garbled => "garbled",
        }
    }
}

/// What the person at the printer does about an error the printer did not retry away.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decision {
    /// Press this button on the error screen.
    Press(ButtonCode),
    /// Look again at the next heartbeat.
    Wait,
    /// Stop: the command ends unrecovered.
    GiveUp,
}

/// The person at the printer. The link is passed in so that a simulated person can act on the
/// simulated unit (pull out filament, clear a fault).
pub trait Operator<L> {
    /// Something happened.
    fn event(&mut self, link: &mut L, event: &PrinterEvent);
    /// The unit is stopped on `error` for `request` and the printer will not retry by itself.
    fn decide(&mut self, link: &mut L, request: Request, error: ErrorCode) -> Decision;
}

/// How a command ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// `F` with this result.
    Finished(ResultCode),
    /// The unit answered `R` every time.
    Rejected,
    /// The operator gave up on this error.
    GaveUp(ErrorCode),
}

/// Why the printer could not go on.
#[derive(Debug)]
pub enum PrinterError {
    /// The link itself failed (a serial port error).
    Io(io::Error),
    /// The unit's version is not the one the printer supports (screen 04504).
    VersionMismatch {
        /// The version request that failed, 0..=2.
        part: u8,
        /// What the unit answered.
        got: Option<u16>,
    },
    /// Ten timeouts in a row (screen 04401).
    NotResponding,
    /// Ten garbled answers in a row (screen 04402).
    ProtocolError,
    /// A command did not end in time.
    Stuck(Request),
}

impl std::fmt::Display for PrinterError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PrinterError::Io(error) => write!(f, "link error: {error}"),
            PrinterError::VersionMismatch { part, got } => write!(
                f,
                "MMU FW UPDATE NEEDED (printer screen 04504): S{part} answered {got:?}"
            ),
            PrinterError::NotResponding => {
                f.write_str("MMU_NOT_RESPONDING (printer screen 04401): no answer 10 times in a row")
            }
            PrinterError::ProtocolError => {
                f.write_str("PROTOCOL_ERROR (printer screen 04402): a garbled answer 10 times in a row")
            }
            PrinterError::Stuck(request) => write!(
                f,
                "{}{:x} did not finish in time: the unit is stuck",
                request.code.as_char(),
                request.value
            ),
        }
    }
}

impl std::error::Error for PrinterError {}

impl From<io::Error> for PrinterError {
    fn from(error: io::Error) -> Self {
        PrinterError::Io(error)
    }
}

/// Why one step of the dialogue failed.
#[derive(Debug)]
enum Fault {
    /// The link is lost: re-handshake.
    Link(LinkFault),
    /// Nothing to recover.
    Fatal(PrinterError),
}

impl From<io::Error> for Fault {
    fn from(error: io::Error) -> Self {
        Fault::Fatal(PrinterError::Io(error))
    }
}

/// Whether the error screen of `error` has a Retry button (the printer presses it by itself).
pub fn has_retry(error: ErrorCode) -> bool {
    matches!(
        error,
        ErrorCode::FINDA_DIDNT_SWITCH_ON
            | ErrorCode::FINDA_DIDNT_SWITCH_OFF
            | ErrorCode::FSENSOR_DIDNT_SWITCH_ON
            | ErrorCode::FSENSOR_DIDNT_SWITCH_OFF
            | ErrorCode::FINDA_VS_EEPROM_DISREPANCY
            | ErrorCode::FSENSOR_TOO_EARLY
            | ErrorCode::FINDA_FLICKERS
            | ErrorCode::STALLED_PULLEY
            | ErrorCode::MOVE_PULLEY_FAILED
            | ErrorCode::HOMING_SELECTOR_FAILED
            | ErrorCode::HOMING_IDLER_FAILED
            | ErrorCode::MOVE_SELECTOR_FAILED
            | ErrorCode::MOVE_IDLER_FAILED
    )
}

/// The printer's protocol logic over `L`.
pub struct Printer<L> {
    link: L,
    options: PrinterOptions,
    decoder: ResponseDecoder,
    inbox: Vec<u8>,
    last_activity_ms: u64,
    reported_fsensor: Option<u8>,
    /// Consecutive link faults since the last accepted version answer, and the first of them
    /// (the printer's `DropOutFilter` and its initial cause).
    dropouts: u8,
    dropout_cause: Option<LinkFault>,
    /// The last values of the polled registers ([`Personality::polled_registers`]).
    registers: Vec<Option<u16>>,
}

impl<L: Link> Printer<L> {
    /// A printer on `link`, not yet connected.
    pub fn new(link: L, options: PrinterOptions) -> Self {
        let now = link.now_ms();
        Printer {
            link,
            options,
            decoder: ResponseDecoder::new(),
            inbox: Vec::new(),
            last_activity_ms: now,
            reported_fsensor: None,
            dropouts: 0,
            dropout_cause: None,
            registers: vec![None; options.personality.polled_registers().len()],
        }
    }

    /// The link.
    pub fn link(&self) -> &L {
        &self.link
    }

    /// The link, mutably.
    pub fn link_mut(&mut self) -> &mut L {
        &mut self.link
    }

    /// The registers the printer reads after every `Q0`, in order.
    pub fn polled_registers(&self) -> &'static [u8] {
        self.options.personality.polled_registers()
    }

    /// The last polled value of register `address`, if it is one of the polled registers.
    pub fn polled(&self, address: u8) -> Option<u16> {
        self.polled_registers()
            .iter()
            .position(|&a| a == address)
            .and_then(|i| self.registers[i])
    }

    /// Handshake until the unit answers as the printer expects, and let a unit that is still
    /// starting up finish; returns the `Q0` answer (`X0 F0` for a unit at rest, an error it
    /// stopped on, or the command it is still running).
    pub fn connect(&mut self, op: &mut impl Operator<L>) -> Result<Response, PrinterError> {
        // The printer lets a unit boot before it talks (a Buddy printer sends its bootloader probe
        // and waits 1 s): a unit takes a frame only at the start of a quiet line.
        let quiet_until = BOOT_WAIT_MS;
        while self.link.now_ms() < quiet_until {
            let wait = quiet_until - self.link.now_ms();
            self.link
                .receive(wait, &mut Vec::new())
                .map_err(PrinterError::Io)?;
        }
        let deadline = self.link.now_ms() + self.options.command_timeout_ms;
        loop {
            let mut answer = match self.handshake(op) {
                Ok(answer) => answer,
                Err(Fault::Link(why)) => {
                    self.link_lost(op, why)?;
                    continue;
                }
                Err(Fault::Fatal(error)) => return Err(error),
            };
            let booting = |a: &Response| a.code == RequestCode::Reset && a.param == ParamCode::Processing;
            while booting(&answer) && self.link.now_ms() < deadline {
                match self.poll(op, false) {
                    Ok(next) => answer = next,
                    Err(Fault::Link(why)) => {
                        self.link_lost(op, why)?;
                        break;
                    }
                    Err(Fault::Fatal(error)) => return Err(error),
                }
            }
            if !booting(&answer) || self.link.now_ms() >= deadline {
                return Ok(answer);
            }
        }
    }

    /// Send a request that is not a command (`R`, `W`, `B`, `f`, `S`) and return its answer,
    /// re-handshaking if the link fails on the way.
    pub fn request(&mut self, op: &mut impl Operator<L>, request: Request) -> Result<Response, PrinterError> {
        let mut lost = LinkFault::Timeout;
        for _ in 0..MAX_REQUEST_ATTEMPTS {
            match self.exchange(op, request) {
                Ok(answer) => return Ok(answer),
                Err(Fault::Link(why)) => {
                    lost = why;
                    self.link_lost(op, why)?;
                    self.connect(op)?;
                }
                Err(Fault::Fatal(error)) => return Err(error),
            }
        }
        Err(match lost {
            LinkFault::Timeout => PrinterError::NotResponding,
            LinkFault::Garbled => PrinterError::ProtocolError,
        })
    }

    /// `X<value>`: the unit restarts without an answer; wait out the link timeout and connect
    /// again, as the printer does. Returns the first `Q0` answer after the restart.
    pub fn reset(&mut self, op: &mut impl Operator<L>, value: u8) -> Result<Response, PrinterError> {
        self.send(op, Request::new(RequestCode::Reset, value))?;
        self.wait_silence(self.options.personality.link_timeout_ms())?;
        op.event(&mut self.link, &PrinterEvent::LinkLost(LinkFault::Timeout));
        self.flush();
        self.connect(op)
    }

    /// Run a printer command (`T L U E K H`) to its end, playing the printer throughout; a
    /// command the unit restarted under is repeated (for `T`, after an unload), as Prusa's mmu2
    /// layer does.
    pub fn command(&mut self, op: &mut impl Operator<L>, request: Request) -> Result<Outcome, PrinterError> {
        for _ in 0..MAX_INTERRUPTS {
            match self.run(op, request)? {
                Some(outcome) => return Ok(outcome),
                None if request.code == RequestCode::Tool => {
                    let unload = Request::new(RequestCode::Unload, 0);
                    if let Some(outcome) = self.run(op, unload)?
                        && outcome != Outcome::Finished(ResultCode::OK)
                    {
                        return Ok(outcome);
                    }
                }
                None => {}
            }
        }
        Err(PrinterError::Stuck(request))
    }

    /// Print for `ms` (printer clock) after a tool change, polling the unit in idle scope. An
    /// error the unit reports meanwhile (a jam on the loaded slot) is taken up as the last
    /// command's and retried and shown as during a command, as Prusa's `IdleStep` does on an `E`
    /// answer (it switches to command scope). Returns how such an error ended, or `None` when the
    /// print went on without one.
    pub fn print(&mut self, op: &mut impl Operator<L>, ms: u64) -> Result<Option<Outcome>, PrinterError> {
        let until = self.link.now_ms() + ms;
        let mut ended = None;
        while self.link.now_ms() < until {
            let answer = match self.poll(op, false) {
                Ok(answer) => answer,
                Err(Fault::Link(why)) => {
                    self.link_lost(op, why)?;
                    self.connect(op)?
                }
                Err(Fault::Fatal(error)) => return Err(error),
            };
            if answer.param == ParamCode::Error {
                let request = Request::new(answer.code, answer.value);
                match self.follow_run(op, request, self.link.now_ms())? {
                    Some(Outcome::GaveUp(error)) => return Ok(Some(Outcome::GaveUp(error))),
                    outcome => ended = outcome.or(ended),
                }
            }
        }
        Ok(ended)
    }

    /// Whether the unit's hub sensor (its FINDA, register 0x08) saw filament at the last poll.
    pub fn finda(&self) -> bool {
        self.polled(0x08).is_some_and(|v| v != 0)
    }

    /// One run of `request`; `None` when the unit restarted under it.
    fn run(&mut self, op: &mut impl Operator<L>, request: Request) -> Result<Option<Outcome>, PrinterError> {
        let started = self.link.now_ms();
        let mut first_reject = None;
        loop {
            if self.link.now_ms().saturating_sub(started) > self.options.command_timeout_ms {
                return Err(PrinterError::Stuck(request));
            }
            match self.exchange(op, request) {
                Ok(answer) if answer.param == ParamCode::Accepted => break,
                Ok(answer)
                    if answer.param == ParamCode::Rejected
                        && self.link.now_ms() - *first_reject.get_or_insert(self.link.now_ms())
                            < REJECTS_FOR_MS =>
                {
                    // Again at once, as the printer does (one poll step apart here).
                    self.link.receive(POLL_STEP_MS, &mut Vec::new())?;
                }
                Ok(_) => return Ok(Some(Outcome::Rejected)),
                Err(Fault::Link(why)) => {
                    self.link_lost(op, why)?;
                    // The answer may be what got lost: a unit running the command says so (an `F`
                    // with the same echo may be an earlier command's).
                    let state = self.connect(op)?;
                    let running = matches!(state.param, ParamCode::Processing | ParamCode::Error);
                    if running && (state.code, state.value) == (request.code, request.value) {
                        break;
                    }
                }
                Err(Fault::Fatal(error)) => return Err(error),
            }
        }
        self.follow_run(op, request, started)
    }

    /// Follow a command the unit already runs (the person pressed Retry on its error by hand, or
    /// it was found running at connect) to its end, as [`Printer::command`] does once the unit
    /// accepted it; a command the unit restarted under is sent again.
    pub fn follow(&mut self, op: &mut impl Operator<L>, request: Request) -> Result<Outcome, PrinterError> {
        let started = self.link.now_ms();
        match self.follow_run(op, request, started)? {
            Some(outcome) => Ok(outcome),
            None => self.command(op, request),
        }
    }

    /// Poll an accepted command (started at `started`, printer clock) to its end; `None` when
    /// the unit restarted under it.
    fn follow_run(
        &mut self,
        op: &mut impl Operator<L>,
        request: Request,
        started: u64,
    ) -> Result<Option<Outcome>, PrinterError> {
        let mut retries_left = AUTO_RETRIES;
        let mut shown: Option<Response> = None;
        // Buddy 6.5.3's premature finish of a tool change (`MMU2::OnMMUProgressMsgChanged` and
        // `OnMMUProgressMsgSame` in `mmu2_mk4.cpp`): armed on the change to `P1c`
        // (`loadFilamentStarted`), taken once.
        let may_finish_early =
            request.code == RequestCode::Tool && self.options.personality.premature_finish();
        let mut load_started = false;
        let mut left_early = false;
        loop {
            if self.link.now_ms().saturating_sub(started) > self.options.command_timeout_ms {
                return Err(PrinterError::Stuck(request));
            }
            let answer = match self.poll(op, true) {
                Ok(answer) => answer,
                Err(Fault::Link(why)) => {
                    self.link_lost(op, why)?;
                    self.connect(op)?
                }
                Err(Fault::Fatal(error)) => return Err(error),
            };
            // Only `F` must echo the command: a unit that restarted reports `X0 F0` (or its start-up
            // error, which is handled as this command's, as the printer does).
            let echoes = (answer.code, answer.value) == (request.code, request.value);
            if answer.param == ParamCode::Finished && !echoes {
                op.event(&mut self.link, &PrinterEvent::Interrupted(request));
                return Ok(None);
            }
            let new = shown != Some(answer);
            shown = Some(answer);
            let value = answer.param_value.unwrap_or(0);
            match answer.param {
                ParamCode::Processing => {
                    let progress = ProgressCode(value as u8);
                    if new {
                        op.event(&mut self.link, &PrinterEvent::Progress(request, progress));
                    }
                    if may_finish_early && !left_early {
                        if progress == ProgressCode::FEEDING_TO_FSENSOR && new {
                            load_started = true;
                        }
                        // Prusa's layer looks at its sensor between polls too, so the unit may
                        // have moved on from `P1c` by the answer that shows it here.
                        let sensor = load_started && self.link.fsensor() != 0;
                        let disengaging = load_started && progress == ProgressCode::DISENGAGING_IDLER;
                        if sensor || disengaging {
                            left_early = true;
                            op.event(&mut self.link, &PrinterEvent::PrematureFinish(request));
                        }
                    }
                }
                ParamCode::Error => {
                    let error = ErrorCode(value);
                    if new {
                        op.event(&mut self.link, &PrinterEvent::Error(request, error));
                    }
                    if retries_left > 0 && has_retry(error) {
                        if self.press(op, ButtonCode::MIDDLE)? {
                            retries_left -= 1;
                            op.event(&mut self.link, &PrinterEvent::AutoRetry(error, retries_left));
                            shown = None;
                        }
                    } else {
                        match op.decide(&mut self.link, request, error) {
                            Decision::Press(button) => {
                                self.press(op, button)?;
                                shown = None;
                            }
                            Decision::Wait => {}
                            Decision::GiveUp => return Ok(Some(Outcome::GaveUp(error))),
                        }
                    }
                }
                ParamCode::Button => {
                    // The unit's own button while the printer is in charge: send it back.
                    self.press(op, ButtonCode(value as u8))?;
                }
                ParamCode::Finished => {
                    let result = ResultCode(value);
                    op.event(&mut self.link, &PrinterEvent::Finished(request, result));
                    return Ok(Some(Outcome::Finished(result)));
                }
                ParamCode::Accepted | ParamCode::Rejected => {
                    self.link_lost(op, LinkFault::Garbled)?;
                    self.connect(op)?;
                    continue;
                }
            }
            op.event(&mut self.link, &PrinterEvent::Heartbeat(request));
        }
    }

    /// Send button `button`; true when the unit accepted it.
    fn press(&mut self, op: &mut impl Operator<L>, button: ButtonCode) -> Result<bool, PrinterError> {
        op.event(&mut self.link, &PrinterEvent::Button(button));
        let answer = self.request(op, Request::new(RequestCode::Button, button.0))?;
        Ok(answer.param == ParamCode::Accepted)
    }

    /// Wait for the heartbeat (reporting a change of the filament sensor at once), then `Q0`,
    /// `f` (after every `P`/`E` answer while a command runs, else on a change) and the register
    /// poll.
    fn poll(&mut self, op: &mut impl Operator<L>, in_command: bool) -> Result<Response, Fault> {
        let heartbeat_ms = self.options.personality.heartbeat_ms();
        while self.link.now_ms() < self.last_activity_ms + heartbeat_ms {
            self.report_fsensor(op)?;
            // Nothing is expected between exchanges; the printer drops it.
            self.link.receive(POLL_STEP_MS, &mut Vec::new())?;
        }
        let answer = self.exchange(op, Request::new(RequestCode::Query, 0))?;
        if in_command && matches!(answer.param, ParamCode::Processing | ParamCode::Error) {
            self.reported_fsensor = None;
        }
        self.report_fsensor(op)?;
        self.poll_registers(op)?;
        Ok(answer)
    }

    fn report_fsensor(&mut self, op: &mut impl Operator<L>) -> Result<(), Fault> {
        if self.options.read_only {
            return Ok(());
        }
        let state = self.link.fsensor();
        if self.reported_fsensor != Some(state) {
            self.exchange(op, Request::new(RequestCode::FilamentSensor, state))?;
            self.reported_fsensor = Some(state);
        }
        Ok(())
    }

    fn poll_registers(&mut self, op: &mut impl Operator<L>) -> Result<(), Fault> {
        for (i, &address) in self.polled_registers().iter().enumerate() {
            let answer = self.exchange(op, Request::new(RequestCode::Read, address))?;
            self.registers[i] = (answer.param == ParamCode::Accepted)
                .then_some(answer.param_value)
                .flatten();
        }
        Ok(())
    }

    fn handshake(&mut self, op: &mut impl Operator<L>) -> Result<Response, Fault> {
        let (major, minor, revision) = self.options.version;
        let expected = [major, minor, revision];
        let mut version = [0u16; 4];
        let mut retries = VERSION_RETRIES;
        let mut wrong = 0;
        let mut part = 0u8;
        while part < 4 {
            // A bench that only looks reads the build (register 3) instead of asking `S3`: `S3`
            // right after a matching `S2` tells the unit which revision a printer accepted, and
            // the unit keeps it.
            let request = if part == 3 && self.options.read_only {
                Request::new(RequestCode::Read, 3)
            } else {
                Request::new(RequestCode::Version, part)
            };
            let answer = self.exchange(op, request)?;
            if (answer.code, answer.value, answer.param) != (request.code, request.value, ParamCode::Accepted)
            {
                wrong += 1;
                if wrong >= MAX_WRONG_ANSWERS {
                    return Err(Fault::Link(LinkFault::Garbled));
                }
                continue;
            }
            let got = answer.param_value;
            if let Some(&want) = expected.get(usize::from(part))
                && got != Some(u16::from(want))
            {
                retries -= 1;
                if retries == 0 {
                    return Err(Fault::Fatal(PrinterError::VersionMismatch { part, got }));
                }
                continue;
            }
            if part < 3 {
                // A meaningful answer from the unit: the drop-out count starts again.
                self.dropouts = 0;
                self.dropout_cause = None;
            }
            version[usize::from(part)] = got.unwrap_or(0);
            part += 1;
        }
        if !self.options.read_only {
            // `A` or `R`: the printer does not check.
            self.exchange(op, Request::write(0x0b, self.options.extra_load_mm))?;
            self.exchange(op, Request::write(0x14, self.options.slow_feed_mm_s))?;
        }
        self.reported_fsensor = None;
        self.report_fsensor(op)?;
        op.event(
            &mut self.link,
            &PrinterEvent::Connected {
                version: (major, minor, revision),
                build: version[3],
            },
        );
        let answer = self.exchange(op, Request::new(RequestCode::Query, 0))?;
        self.poll_registers(op)?;
        Ok(answer)
    }

    /// Count a link fault; the tenth in a row without an accepted version answer between ends the
    /// session with the first one's cause. Then the printer drops what is in flight (after a
    /// garbled answer it first waits out a heartbeat period).
    fn link_lost(&mut self, op: &mut impl Operator<L>, why: LinkFault) -> Result<(), PrinterError> {
        op.event(&mut self.link, &PrinterEvent::LinkLost(why));
        self.dropouts += 1;
        let cause = *self.dropout_cause.get_or_insert(why);
        if self.dropouts >= MAX_DROPOUTS {
            return Err(match cause {
                LinkFault::Timeout => PrinterError::NotResponding,
                LinkFault::Garbled => PrinterError::ProtocolError,
            });
        }
        if why == LinkFault::Garbled {
            self.wait_silence(self.options.personality.heartbeat_ms())?;
        }
        self.flush();
        Ok(())
    }

    /// Let `ms` pass since the last activity, dropping whatever arrives.
    fn wait_silence(&mut self, ms: u64) -> Result<(), PrinterError> {
        let end = self.last_activity_ms + ms;
        while self.link.now_ms() < end {
            let mut dropped = Vec::new();
            self.link.receive(POLL_STEP_MS, &mut dropped)?;
        }
        Ok(())
    }

    fn flush(&mut self) {
        self.inbox.clear();
        self.decoder.reset();
    }

    fn send(&mut self, op: &mut impl Operator<L>, request: Request) -> io::Result<()> {
        op.event(&mut self.link, &PrinterEvent::Sent(request));
        self.link.send(request.encode().as_bytes())?;
        self.last_activity_ms = self.link.now_ms();
        Ok(())
    }

    /// Send `request` and wait for one complete answer within the link timeout.
    fn exchange(&mut self, op: &mut impl Operator<L>, request: Request) -> Result<Response, Fault> {
        self.flush();
        self.send(op, request)?;
        // Bytes keep the link alive, but a stream that never makes a frame is garbage.
        let timeout_ms = self.options.personality.link_timeout_ms();
        let give_up = self.last_activity_ms + 2 * timeout_ms;
        loop {
            for byte in std::mem::take(&mut self.inbox).into_iter() {
                match self.decoder.feed(byte) {
                    Some(Ok(answer)) => {
                        op.event(&mut self.link, &PrinterEvent::Received(answer));
                        return Ok(answer);
                    }
                    Some(Err(_)) => return Err(Fault::Link(LinkFault::Garbled)),
                    None => {}
                }
            }
            let now = self.link.now_ms();
            if now >= self.last_activity_ms + timeout_ms {
                return Err(Fault::Link(LinkFault::Timeout));
            }
            if now >= give_up {
                return Err(Fault::Link(LinkFault::Garbled));
            }
            let wait = (self.last_activity_ms + timeout_ms - now).min(POLL_STEP_MS);
            let before = self.inbox.len();
            self.link.receive(wait, &mut self.inbox)?;
            if self.inbox.len() > before {
                self.last_activity_ms = self.link.now_ms();
            }
        }
    }
}
