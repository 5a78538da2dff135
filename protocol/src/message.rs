//! Requests (printer to unit) and responses (unit to printer), and their byte-exact encoding.

use crate::codes::{ButtonCode, ErrorCode, ParamCode, ProgressCode, RequestCode, ResultCode};
use crate::crc::{request_crc, response_crc};
use crate::frame::Frame;

/// A request: `<code><value>*<crc>` or, for a write, `W<address> <value2>*<crc>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Request {
    /// What is asked.
    pub code: RequestCode,
    /// The argument: a slot, a register address, a button, a sensor state, ...
    pub value: u8,
    /// The value written by `W`; 0 for every other code.
    pub value2: u16,
}

impl Request {
    /// A request with one value (every code but `W`).
    pub const fn new(code: RequestCode, value: u8) -> Self {
        Request {
            code,
            value,
            value2: 0,
        }
    }

    /// A register write.
    pub const fn write(address: u8, value: u16) -> Self {
        Request {
            code: RequestCode::Write,
            value: address,
            value2: value,
        }
    }

    /// The CRC this request carries on the wire (`value2` counts only for `W`, the one code
    /// that prints it).
    pub fn crc(&self) -> u8 {
        let value2 = if self.code == RequestCode::Write {
            self.value2
        } else {
            0
        };
        request_crc(self.code.as_byte(), self.value, value2)
    }

    /// The frame exactly as the printer sends it.
    pub fn encode(&self) -> Frame {
        let mut frame = Frame::new();
        frame.push(self.code.as_byte());
        frame.push_hex(self.value.into());
        if self.code == RequestCode::Write {
            frame.push(b' ');
            frame.push_hex(self.value2);
        }
        frame.push_crc(self.crc());
        frame
    }
}

/// A response: `<code><value> <param>[<param_value>]*<crc>`.
///
/// The echoed code and value are the request answered, except for `Q0`, whose answer echoes the
/// current command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Response {
    /// The echoed request code.
    pub code: RequestCode,
    /// The echoed request value (the address for `W`; its written value is not echoed).
    pub value: u8,
    /// What the answer says.
    pub param: ParamCode,
    /// The parameter's value, when one is printed (`A` to a command prints none).
    pub param_value: Option<u16>,
}

impl Response {
    /// An answer with no printed value (`A` or `R` to a command or a write).
    pub const fn bare(code: RequestCode, value: u8, param: ParamCode) -> Self {
        Response {
            code,
            value,
            param,
            param_value: None,
        }
    }

    /// An answer with a printed value.
    pub const fn with_value(code: RequestCode, value: u8, param: ParamCode, param_value: u16) -> Self {
        Response {
            code,
            value,
            param,
            param_value: Some(param_value),
        }
    }

    /// `A` to `request`, with no value.
    pub const fn accepted(request: &Request) -> Self {
        Self::bare(request.code, request.value, ParamCode::Accepted)
    }

    /// `R` to `request`.
    pub const fn rejected(request: &Request) -> Self {
        Self::bare(request.code, request.value, ParamCode::Rejected)
    }

    /// `A<value>` to a read of any kind (`S`, `R`, `P`).
    pub const fn read(request: &Request, value: u16) -> Self {
        Self::with_value(request.code, request.value, ParamCode::Accepted, value)
    }

    /// `P<progress>` for the command `code value`.
    pub const fn progress(code: RequestCode, value: u8, progress: ProgressCode) -> Self {
        Self::with_value(code, value, ParamCode::Processing, progress.0 as u16)
    }

    /// `E<error>` for the command `code value`.
    pub const fn error(code: RequestCode, value: u8, error: ErrorCode) -> Self {
        Self::with_value(code, value, ParamCode::Error, error.0)
    }

    /// `F<result>` for the command `code value` (the result is always printed).
    pub const fn finished(code: RequestCode, value: u8, result: ResultCode) -> Self {
        Self::with_value(code, value, ParamCode::Finished, result.0)
    }

    /// `B<button>` for the command `code value`: a button pressed on the unit.
    pub const fn button(code: RequestCode, value: u8, button: ButtonCode) -> Self {
        Self::with_value(code, value, ParamCode::Button, button.0 as u16)
    }

    /// The CRC this response carries on the wire.
    pub fn crc(&self) -> u8 {
        response_crc(
            self.code.as_byte(),
            self.value,
            self.param.as_byte(),
            self.param_value.unwrap_or(0),
        )
    }

    /// The frame exactly as the unit sends it.
    pub fn encode(&self) -> Frame {
        let mut frame = Frame::new();
        frame.push(self.code.as_byte());
        frame.push_hex(self.value.into());
        frame.push(b' ');
        frame.push(self.param.as_byte());
        if let Some(value) = self.param_value {
            frame.push_hex(value);
        }
        frame.push_crc(self.crc());
        frame
    }
}
