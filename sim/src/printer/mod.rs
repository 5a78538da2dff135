//! The printer's side of the protocol, as Prusa's firmware plays it (spec §5): the handshake with
//! its exact version check, `Q0` one heartbeat after the last activity, `f` reports the
//! moment the printer's filament sensor changes, the register poll, automatic Retry (`B1`) up to
//! three times per command, a link timeout followed by a new handshake, and the mmu2 layer's
//! "unload, then again" when the unit restarted under a command (BFW v6.5.3 `mmu2_mk4.cpp`
//! `ToolChangeCommonOnce`: `UnloadInner`, then `T` again; not after a premature finish, when the
//! printer had already returned from the tool change). The heartbeat, the timeout, the
//! version, the registers polled and the 6.5.3 "premature finish" of a tool change depend on the
//! printer played, its [`Personality`](crate::Personality).
//!
//! It talks through a [`Link`] (the in-process simulator, or a serial port in `mmu`), and a
//! person at the printer (an [`Operator`]) sees what happens and decides on errors.

use std::io;

use mmu_protocol::{
    ButtonCode, ErrorCode, ParamCode, ProgressCode, Request, RequestCode, Response, ResponseDecoder,
    ResultCode,
};

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

mod runout;
mod vocabulary;

pub use runout::{join_slot, runout_delay_ms};

pub use vocabulary::{
    Decision, Link, LinkFault, Operator, Outcome, PrinterError, PrinterEvent, PrinterOptions, has_retry,
};

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
    /// The slot the printer believes in its nozzle (a finished `T` or `L`; `U`, `E` clear it).
    tool: Option<u8>,
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
            tool: None,
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
                Some(outcome) => {
                    self.note_outcome(request, outcome);
                    return Ok(outcome);
                }
                None => {
                    if let Some(outcome) = self.unload_after_interrupt(op, request)? {
                        return Ok(outcome);
                    }
                }
            }
        }
        Err(PrinterError::Stuck(request))
    }

    /// After the unit restarted under `request`: for a tool change, the mmu2 layer's `U0` before
    /// the `T` goes out again (`UnloadInner`, BFW v6.5.3 `mmu2_mk4.cpp`); how it ended if not well.
    fn unload_after_interrupt(
        &mut self,
        op: &mut impl Operator<L>,
        request: Request,
    ) -> Result<Option<Outcome>, PrinterError> {
        if request.code != RequestCode::Tool {
            return Ok(None);
        }
        let unload = Request::new(RequestCode::Unload, 0);
        Ok(self
            .run(op, unload)?
            .filter(|outcome| *outcome != Outcome::Finished(ResultCode::OK)))
    }

    /// Print for `ms` (printer clock) after a tool change, polling the unit in idle scope. An
    /// error the unit reports meanwhile (a jam on the loaded slot) is taken up as the last
    /// command's and retried and shown as during a command, as Prusa's `IdleStep` does on an `E`
    /// answer (it switches to command scope). Returns how such an error ended, or `None` when the
    /// print went on without one.
    ///
    /// FINDA reading empty after an idle poll while a filament is believed loaded starts the
    /// printer's filament change ([`runout`]): with SpoolJoin the print goes on with the next
    /// slot; without it the print stops on the filament-change screen
    /// ([`Outcome::FilamentChange`]).
    pub fn print(&mut self, op: &mut impl Operator<L>, ms: u64) -> Result<Option<Outcome>, PrinterError> {
        self.print_for(op, ms, true)
    }

    /// [`Printer::print`], with the runout check on or off (off while an `M600` is queued).
    fn print_for(
        &mut self,
        op: &mut impl Operator<L>,
        ms: u64,
        runout_check: bool,
    ) -> Result<Option<Outcome>, PrinterError> {
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
            if runout_check && answer.param == ParamCode::Finished && self.runout_seen() {
                match self.filament_change(op)? {
                    None => {}
                    stopped => return Ok(stopped),
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
            None => match self.unload_after_interrupt(op, request)? {
                Some(outcome) => Ok(outcome),
                None => self.command(op, request),
            },
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
                if left_early {
                    // Buddy 6.5.3 returned from this tool change at its premature finish
                    // (`ToolChangeCommonOnce` leaves its loop once `manage_response` says
                    // `PrematureFinish`); the restart is seen later by `mmu_loop`'s `LogicStep`,
                    // which hands `Interrupted` on to nobody: no unload, no `T` again.
                    return Ok(Some(Outcome::Finished(ResultCode::OK)));
                }
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
            // Prusa's `SuppressShortDropOuts` starts a new count once it reported the screen
            // (`ResetCommunicationTimeoutAttempts`): a printer that connects again behind it
            // gets ten more tries.
            self.dropouts = 0;
            self.dropout_cause = None;
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
