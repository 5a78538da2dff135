//! What the printer's protocol logic talks in: the wire it uses ([`Link`]), how it is set up
//! ([`PrinterOptions`]), what a person at it sees ([`PrinterEvent`]) and decides ([`Operator`],
//! [`Decision`]), and how commands and sessions end ([`Outcome`], [`PrinterError`]).

use std::io;

use mmu_protocol::{ButtonCode, ErrorCode, ProgressCode, Request, Response, ResultCode};

use crate::personality::Personality;

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
    /// later, 3.0.3 on Buddy 6.4 and MK3S 3.14.1, 3.0.2 on MK3S 3.13.3/3.14.0): by default the
    /// personality's, [`Personality::version`].
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
    /// SpoolJoin is on: a runout the unit reports (FINDA empty while printing) joins to the next
    /// slot (`M600 A` on Buddy, `M600 AUTO` on the MK3S) instead of stopping on the
    /// filament-change screen ([`crate::printer`]'s `runout` module).
    pub spool_join: bool,
    /// The slots SpoolJoin goes round: after slot `n` comes `(n + 1) % join_cycle`. The MK3S
    /// always counts 5 (`SpoolJoin::nextSlot`), whatever the unit has; a Buddy user joins the
    /// slots the unit has (the soak sets its slot count).
    pub join_cycle: u8,
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
            version: Personality::default().version(),
            extra_load_mm: 5,
            slow_feed_mm_s: 20,
            command_timeout_ms: 10 * 60 * 1000,
            read_only: false,
            spool_join: false,
            join_cycle: 5,
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
    /// FINDA (register 0x08) read empty while the printer printed with `slot` loaded
    /// (`MMU2::CheckFINDARunout`): it starts its filament change, joining to `join` if SpoolJoin
    /// is on.
    Runout {
        /// The slot the printer believes loaded.
        slot: u8,
        /// The slot SpoolJoin continues with, if it is on.
        join: Option<u8>,
    },
}

impl PrinterEvent {
    /// The traffic of every poll (a request, an answer, a heartbeat), as opposed to what a
    /// person at the printer would notice.
    pub fn is_routine(&self) -> bool {
        matches!(
            self,
            PrinterEvent::Sent(_) | PrinterEvent::Received(_) | PrinterEvent::Heartbeat(_)
        )
    }
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
    /// A print stopped on the filament-change screen after the unit reported a runout of this
    /// slot (`M600` without SpoolJoin): the old filament was unloaded; the user loads a new one.
    FilamentChange(u8),
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
