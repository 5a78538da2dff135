//! Streaming decoders, fed one byte at a time with bounded memory.
//!
//! One state machine serves both directions; only the part after the echoed value differs
//! (`W`'s second value in a request, the parameter letter in a response).
//!
//! A frame may begin only at a line boundary, never inside a broken frame, so noise cannot turn
//! the tail of one frame into another:
//! - a byte that breaks a frame rejects the whole line, even a request letter (`W0 97E*d5`, one
//!   bit away from a write, is not `E0`). Prusa's decoder does the same (the MMU's
//!   `Protocol::DecodeRequest`, prusa3d/Prusa-Firmware-MMU `src/modules/protocol.cpp`);
//! - after a frame broken or cut short by a newline, nothing is accepted until the line falls
//!   silent: the bytes after that newline may be the same frame's tail (`W71 bee` + an inserted
//!   newline + `f*21` would be `f0`; `f` is both a hex digit and a request letter). The printer
//!   sends nothing after a frame the unit left unanswered until its 2 s timeout, so this costs nothing;
//! - lines that never began a frame (`ok`, `zzzz`), frames with a bad CRC, blank lines and CRLF
//!   end at their newline, and the next frame decodes at once;
//! - the caller reports a silence ([`RequestDecoder::line_silent`], after [`SILENCE_MS`] without a
//!   byte): it ends any broken line, with or without its newline, so stray bytes (such as the
//!   MK4's bootloader probe: `S` and `E` with no newline) do not cost the frame after them.

use core::fmt;

use crate::codes::{ParamCode, RequestCode};
use crate::crc::{request_crc, response_crc};
use crate::hex::digit_value;
use crate::message::{Request, Response};

/// Why a frame was rejected. It is for logs: a rejected frame is never answered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError<F> {
    /// The frame began with a byte that is no request code.
    UnknownCode(u8),
    /// A byte that cannot stand where it came (uppercase hex, a missing space, ...).
    UnexpectedByte(u8),
    /// The line ended before the `*<crc>` part.
    Incomplete,
    /// The line fell silent before the frame ended (reported by `line_silent`).
    Interrupted,
    /// A line that followed a broken frame with no silence between: it may be that frame's tail.
    AfterBrokenFrame,
    /// The frame is well formed but its CRC does not match; its fields are kept for logs.
    BadCrc {
        /// The frame as decoded.
        frame: F,
        /// The CRC computed over the decoded fields.
        computed: u8,
        /// The CRC the frame carried.
        received: u8,
    },
}

impl<F> fmt::Display for DecodeError<F> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DecodeError::UnknownCode(byte) => write!(f, "unknown code {:?}", char::from(*byte)),
            DecodeError::UnexpectedByte(byte) => write!(f, "unexpected byte {:?}", char::from(*byte)),
            DecodeError::Incomplete => f.write_str("line ended before the CRC"),
            DecodeError::Interrupted => f.write_str("the line fell silent before the frame ended"),
            DecodeError::AfterBrokenFrame => {
                f.write_str("a line right after a broken frame, before the line fell silent")
            }
            DecodeError::BadCrc {
                computed, received, ..
            } => {
                write!(
                    f,
                    "CRC mismatch: frame carries {received:x}, content gives {computed:x}"
                )
            }
        }
    }
}

/// How long the line must stay silent, in ms, before the caller reports it with
/// [`RequestDecoder::line_silent`] (or [`ResponseDecoder::line_silent`]).
///
/// A printer never pauses inside a frame: Buddy writes each frame with one `uart->write`
/// (`ProtocolLogic::SendMsg` in prusa3d/Prusa-Firmware-Buddy
/// `lib/Marlin/Marlin/src/feature/prusa/MMU2/protocol_logic.cpp`), the MK3S byte after byte
/// with only interrupt handlers between them (`MMU2Serial::write`, prusa3d/Prusa-Firmware
/// `Firmware/mmu2_serial.cpp`); a whole 13-byte frame takes 1.1 ms at 115200 Bd. The MK4's
/// bootloader probe sends its `S` and `E` bytes 500 ms apart and waits 1 s before the first
/// `S0` (prusa3d/Prusa-Firmware-Buddy `src/mmu2/mmu2_bootloader.cpp`), and the printer re-sends
/// a request only after 2 s without an answer (`linkLayerTimeout`). 10 ms is well clear of both.
pub const SILENCE_MS: u32 = 10;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Direction {
    Request,
    Response,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// At a line boundary: newlines are skipped, a code letter starts a frame.
    Idle,
    Value,
    /// `W`'s written value, after the space.
    WriteValue,
    /// A response's parameter letter, after the space.
    Param,
    ParamValue,
    Crc,
    /// A rejected line: everything up to the newline is dropped, then this reason is reported.
    Discard(Rejection),
    /// After a broken frame: everything is dropped until the line falls silent; `dropped` says
    /// whether the current line held anything (it is reported at its newline).
    AwaitSilence {
        dropped: bool,
    },
}

/// A rejection before any field is complete, so it carries no frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Rejection {
    UnknownCode(u8),
    UnexpectedByte(u8),
    Incomplete,
    Interrupted,
    AfterBrokenFrame,
}

impl Rejection {
    const fn into_error<F>(self) -> DecodeError<F> {
        match self {
            Rejection::UnknownCode(byte) => DecodeError::UnknownCode(byte),
            Rejection::UnexpectedByte(byte) => DecodeError::UnexpectedByte(byte),
            Rejection::Incomplete => DecodeError::Incomplete,
            Rejection::Interrupted => DecodeError::Interrupted,
            Rejection::AfterBrokenFrame => DecodeError::AfterBrokenFrame,
        }
    }

    /// Where the line goes after this rejection's newline. A line that began as a frame and broke
    /// may continue after a newline that noise put there, so it waits for a silence; a line that
    /// never began a frame cannot.
    const fn next_state(self) -> State {
        match self {
            Rejection::UnknownCode(_) => State::Idle,
            _ => State::AwaitSilence { dropped: false },
        }
    }
}

/// The fields of the frame being decoded. Hex fields shift digits in without a length limit and
/// keep the low bits, exactly as Prusa's decoder does (`L00` is `L0`).
#[derive(Debug, Clone, Copy, Default)]
struct Fields {
    code: u8,
    value: u8,
    value2: u16,
    param: u8,
    param_value: Option<u16>,
    crc: u8,
}

enum Step {
    Pending,
    Complete(Fields),
    Rejected(Rejection),
}

/// The state machine of one direction: `RESPONSE` false decodes requests, true responses. A
/// constant, not a field: the firmware's request decoder then has no code for a response's
/// parameter.
#[derive(Debug, Clone)]
struct FrameDecoder<const RESPONSE: bool> {
    state: State,
    fields: Fields,
}

const fn is_newline(byte: u8) -> bool {
    byte == b'\n' || byte == b'\r'
}

impl<const RESPONSE: bool> FrameDecoder<RESPONSE> {
    const DIRECTION: Direction = if RESPONSE {
        Direction::Response
    } else {
        Direction::Request
    };

    const fn new(state: State) -> Self {
        let fields = Fields {
            code: 0,
            value: 0,
            value2: 0,
            param: 0,
            param_value: None,
            crc: 0,
        };
        FrameDecoder { state, fields }
    }

    fn feed(&mut self, byte: u8) -> Step {
        let digit = digit_value(byte);
        match (self.state, digit) {
            (State::Idle, _) if is_newline(byte) => Step::Pending,
            (State::Idle, _) => self.start(byte),
            (State::Discard(rejection), _) => {
                if is_newline(byte) {
                    self.state = rejection.next_state();
                    Step::Rejected(rejection)
                } else {
                    Step::Pending
                }
            }
            (State::AwaitSilence { dropped }, _) => {
                let newline = is_newline(byte);
                self.state = State::AwaitSilence { dropped: !newline };
                if newline && dropped {
                    Step::Rejected(Rejection::AfterBrokenFrame)
                } else {
                    Step::Pending
                }
            }
            (State::Value, Some(d)) => {
                self.fields.value = (self.fields.value << 4) | d;
                Step::Pending
            }
            (State::WriteValue, Some(d)) => {
                self.fields.value2 = (self.fields.value2 << 4) | u16::from(d);
                Step::Pending
            }
            (State::ParamValue, Some(d)) if RESPONSE => {
                let previous = self.fields.param_value.unwrap_or(0);
                self.fields.param_value = Some((previous << 4) | u16::from(d));
                Step::Pending
            }
            (State::Crc, Some(d)) => {
                self.fields.crc = (self.fields.crc << 4) | d;
                Step::Pending
            }
            (State::Crc, None) if is_newline(byte) => {
                self.state = State::Idle;
                Step::Complete(self.fields)
            }
            (State::Value | State::WriteValue | State::ParamValue, None)
                if byte == b'*' && self.star_allowed() =>
            {
                self.state = State::Crc;
                Step::Pending
            }
            (State::Value, None) if byte == b' ' && self.space_allowed() => {
                self.state = match Self::DIRECTION {
                    Direction::Request => State::WriteValue,
                    Direction::Response => State::Param,
                };
                Step::Pending
            }
            (State::Param, _) if RESPONSE && ParamCode::from_byte(byte).is_some() => {
                self.fields.param = byte;
                self.state = State::ParamValue;
                Step::Pending
            }
            (_, _) if is_newline(byte) => {
                self.state = Rejection::Incomplete.next_state();
                Step::Rejected(Rejection::Incomplete)
            }
            (_, _) => {
                // Even a request letter: a frame never begins inside a broken line.
                self.state = State::Discard(Rejection::UnexpectedByte(byte));
                Step::Pending
            }
        }
    }

    /// The line fell silent: whatever was not finished is rejected, and the next byte may begin
    /// a frame.
    fn line_silent(&mut self) -> Option<Rejection> {
        let rejection = match self.state {
            State::Idle | State::AwaitSilence { dropped: false } => None,
            State::AwaitSilence { dropped: true } => Some(Rejection::AfterBrokenFrame),
            State::Discard(rejection) => Some(rejection),
            _ => Some(Rejection::Interrupted),
        };
        self.state = State::Idle;
        rejection
    }

    fn start(&mut self, byte: u8) -> Step {
        self.fields = Fields {
            code: byte,
            ..Fields::default()
        };
        self.state = if RequestCode::from_byte(byte).is_some() {
            State::Value
        } else {
            State::Discard(Rejection::UnknownCode(byte))
        };
        Step::Pending
    }

    /// `*` may follow a request's value (a write's second value) or a response's parameter.
    fn star_allowed(&self) -> bool {
        match (Self::DIRECTION, self.state) {
            (Direction::Request, State::Value) => self.fields.code != RequestCode::Write.as_byte(),
            (Direction::Request, State::WriteValue) => true,
            (Direction::Response, State::ParamValue) => true,
            _ => false,
        }
    }

    /// A space follows the value in every response, and in a request only for `W`.
    fn space_allowed(&self) -> bool {
        match Self::DIRECTION {
            Direction::Request => self.fields.code == RequestCode::Write.as_byte(),
            Direction::Response => true,
        }
    }
}

fn map_step<F>(
    step: Step,
    build: impl FnOnce(&Fields) -> Option<(F, u8)>,
) -> Option<Result<F, DecodeError<F>>> {
    match step {
        Step::Pending => None,
        Step::Complete(fields) => {
            let (frame, computed) = build(&fields)?;
            if computed == fields.crc {
                Some(Ok(frame))
            } else {
                Some(Err(DecodeError::BadCrc {
                    frame,
                    computed,
                    received: fields.crc,
                }))
            }
        }
        Step::Rejected(rejection) => Some(Err(rejection.into_error())),
    }
}

/// The unit's decoder of the printer's requests.
#[derive(Debug, Clone)]
pub struct RequestDecoder(FrameDecoder<false>);

impl Default for RequestDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl RequestDecoder {
    /// A decoder at a line boundary, waiting for the first frame.
    pub const fn new() -> Self {
        RequestDecoder(FrameDecoder::new(State::Idle))
    }

    /// A decoder joining a line that may be in the middle of a frame (the unit just booted while
    /// the printer may be sending): it accepts nothing until the line falls silent, so the tail
    /// of a frame is never taken for a frame.
    pub const fn new_mid_line() -> Self {
        RequestDecoder(FrameDecoder::new(State::AwaitSilence { dropped: false }))
    }

    /// Feed one byte. Returns a request when a frame completes, an error when a frame is rejected,
    /// and `None` otherwise.
    pub fn feed(&mut self, byte: u8) -> Option<Result<Request, DecodeError<Request>>> {
        let step = self.0.feed(byte);
        map_step(step, |f| {
            let code = RequestCode::from_byte(f.code)?;
            let request = Request {
                code,
                value: f.value,
                value2: f.value2,
            };
            Some((request, request_crc(f.code, f.value, f.value2)))
        })
    }

    /// Tell the decoder that no byte arrived for [`SILENCE_MS`] (or longer): a frame the printer
    /// sends never pauses that long, so a frame left unfinished is rejected (returned, for logs)
    /// and the next byte may begin a new one. Calling it again while the line stays silent does
    /// nothing.
    pub fn line_silent(&mut self) -> Option<DecodeError<Request>> {
        self.0.line_silent().map(Rejection::into_error)
    }

    /// Forget any partial frame: the next byte may begin a new one. For a caller that knows a
    /// frame boundary by other means (a link just opened); noise is handled by [`Self::feed`]
    /// and [`Self::line_silent`].
    pub fn reset(&mut self) {
        self.0.state = State::Idle;
    }
}

/// The printer's decoder of the unit's responses.
#[derive(Debug, Clone)]
pub struct ResponseDecoder(FrameDecoder<true>);

impl Default for ResponseDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl ResponseDecoder {
    /// A decoder at a line boundary, waiting for the first frame.
    pub const fn new() -> Self {
        ResponseDecoder(FrameDecoder::new(State::Idle))
    }

    /// A decoder joining a line that may be in the middle of a frame (see
    /// [`RequestDecoder::new_mid_line`]).
    pub const fn new_mid_line() -> Self {
        ResponseDecoder(FrameDecoder::new(State::AwaitSilence { dropped: false }))
    }

    /// Feed one byte. Returns a response when a frame completes, an error when a frame is
    /// rejected, and `None` otherwise.
    pub fn feed(&mut self, byte: u8) -> Option<Result<Response, DecodeError<Response>>> {
        let step = self.0.feed(byte);
        map_step(step, |f| {
            let response = Response {
                code: RequestCode::from_byte(f.code)?,
                value: f.value,
                param: ParamCode::from_byte(f.param)?,
                param_value: f.param_value,
            };
            let crc = response_crc(f.code, f.value, f.param, f.param_value.unwrap_or(0));
            Some((response, crc))
        })
    }

    /// Tell the decoder that no byte arrived for [`SILENCE_MS`] (or longer); see
    /// [`RequestDecoder::line_silent`].
    pub fn line_silent(&mut self) -> Option<DecodeError<Response>> {
        self.0.line_silent().map(Rejection::into_error)
    }

    /// Forget any partial frame: the next byte may begin a new one (see
    /// [`RequestDecoder::reset`]).
    pub fn reset(&mut self) {
        self.0.state = State::Idle;
    }
}
