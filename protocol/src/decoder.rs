//! Streaming decoders, fed one byte at a time with bounded memory.
//!
//! One state machine serves both directions; only the part after the echoed value differs
//! (`W`'s second value in a request, the parameter letter in a response). Compared with Prusa's
//! decoder it accepts the same frames but recovers sooner: any error ends at the next newline, a
//! bare CR or LF between frames is ignored, and a request letter arriving where it cannot belong
//! starts a new frame.

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
    /// A new frame began before this one ended.
    Interrupted,
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
            DecodeError::Interrupted => f.write_str("a new frame began before this one ended"),
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

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Direction {
    Request,
    Response,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum State {
    /// Between frames: newlines are skipped, a code letter starts a frame.
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
}

/// A rejection before any field is complete, so it carries no frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Rejection {
    UnknownCode(u8),
    UnexpectedByte(u8),
    Incomplete,
    Interrupted,
}

impl Rejection {
    const fn into_error<F>(self) -> DecodeError<F> {
        match self {
            Rejection::UnknownCode(byte) => DecodeError::UnknownCode(byte),
            Rejection::UnexpectedByte(byte) => DecodeError::UnexpectedByte(byte),
            Rejection::Incomplete => DecodeError::Incomplete,
            Rejection::Interrupted => DecodeError::Interrupted,
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

#[derive(Debug, Clone)]
struct FrameDecoder {
    direction: Direction,
    state: State,
    fields: Fields,
}

const fn is_newline(byte: u8) -> bool {
    byte == b'\n' || byte == b'\r'
}

impl FrameDecoder {
    const fn new(direction: Direction) -> Self {
        let fields = Fields {
            code: 0,
            value: 0,
            value2: 0,
            param: 0,
            param_value: None,
            crc: 0,
        };
        FrameDecoder {
            direction,
            state: State::Idle,
            fields,
        }
    }

    fn feed(&mut self, byte: u8) -> Step {
        let digit = digit_value(byte);
        match (self.state, digit) {
            (State::Idle, _) if is_newline(byte) => Step::Pending,
            (State::Idle, _) => self.start(byte),
            (State::Discard(rejection), _) => {
                if is_newline(byte) {
                    self.state = State::Idle;
                    Step::Rejected(rejection)
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
            (State::ParamValue, Some(d)) => {
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
                self.state = match self.direction {
                    Direction::Request => State::WriteValue,
                    Direction::Response => State::Param,
                };
                Step::Pending
            }
            (State::Param, _) if ParamCode::from_byte(byte).is_some() => {
                self.fields.param = byte;
                self.state = State::ParamValue;
                Step::Pending
            }
            (_, _) if is_newline(byte) => {
                self.state = State::Idle;
                Step::Rejected(Rejection::Incomplete)
            }
            (_, _) if RequestCode::from_byte(byte).is_some() => {
                // A frame letter where none belongs: the sender gave up on the last frame (or it was
                // noise, such as the MK4's bootloader probe); the new frame is not lost with it.
                self.start(byte);
                Step::Rejected(Rejection::Interrupted)
            }
            (_, _) => {
                self.state = State::Discard(Rejection::UnexpectedByte(byte));
                Step::Pending
            }
        }
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
        match (self.direction, self.state) {
            (Direction::Request, State::Value) => self.fields.code != RequestCode::Write.as_byte(),
            (Direction::Request, State::WriteValue) => true,
            (Direction::Response, State::ParamValue) => true,
            _ => false,
        }
    }

    /// A space follows the value in every response, and in a request only for `W`.
    fn space_allowed(&self) -> bool {
        match self.direction {
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
pub struct RequestDecoder(FrameDecoder);

impl Default for RequestDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl RequestDecoder {
    /// A decoder waiting for the first frame.
    pub const fn new() -> Self {
        RequestDecoder(FrameDecoder::new(Direction::Request))
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

    /// Forget any partial frame.
    pub fn reset(&mut self) {
        self.0.state = State::Idle;
    }
}

/// The printer's decoder of the unit's responses.
#[derive(Debug, Clone)]
pub struct ResponseDecoder(FrameDecoder);

impl Default for ResponseDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl ResponseDecoder {
    /// A decoder waiting for the first frame.
    pub const fn new() -> Self {
        ResponseDecoder(FrameDecoder::new(Direction::Response))
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

    /// Forget any partial frame.
    pub fn reset(&mut self) {
        self.0.state = State::Idle;
    }
}
