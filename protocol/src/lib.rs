//! The Prusa MMU2S/MMU3 serial protocol, as an unmodified Prusa printer speaks it.
//!
//! Both directions, `no_std`, no allocation:
//! - unit side: [`RequestDecoder`] (fed one byte at a time) and [`Response::encode`];
//! - printer side: [`Request::encode`] and [`ResponseDecoder`].
//!
//! Frames are byte-exact with Prusa's codec: lowercase hex without leading zeros, an unpadded
//! CRC-8 (polynomial 0x07) over the binary form ([`crc`]), one `\n` at the end. The decoders
//! accept everything Prusa's accepts (leading zeros, an empty value). A frame begins only at a line
//! boundary (after a newline, or after a silence the caller reports with `line_silent`), never at
//! a letter inside a broken line, so noise cannot forge a frame; blank lines and CRLF are skipped,
//! and stray bytes without a newline (such as the MK4's bootloader probe) cost nothing once the
//! line has been silent for [`SILENCE_MS`]. A rejected frame is reported as a [`DecodeError`],
//! never answered.
//!
//! The code tables ([`ErrorCode`], [`ProgressCode`], ...) keep unknown numeric values: a value
//! only this library does not know still round-trips.

#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]

pub mod codes;
pub mod crc;
mod decoder;
mod frame;
mod hex;
mod message;
pub mod screens;

pub use codes::{ButtonCode, ErrorCode, ParamCode, ProgressCode, RequestCode, ResultCode};
pub use decoder::{DecodeError, RequestDecoder, ResponseDecoder, SILENCE_MS};
pub use frame::{Frame, MAX_FRAME_LEN};
pub use message::{Request, Response};
pub use screens::{Action, Button, Family, Screen};
