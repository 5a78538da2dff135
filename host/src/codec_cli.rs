//! `mmu encode` and `mmu decode`: build frames exactly as on the wire ([here](self)), and explain
//! frames or printer log lines ([`decode`]); the number and letter parsers the other subcommands
//! share.

mod decode;
mod log_line;

pub use decode::{DecodeArgs, decode};

use std::error::Error;

use clap::Subcommand;
use mmu_protocol::{ParamCode, Request, RequestCode, Response};

use crate::usage::UsageError;

/// `mmu encode <request|response> ...`.
#[derive(Debug, Subcommand)]
pub enum EncodeCommand {
    /// A request (printer → unit), e.g. `mmu encode request T 1` → `T1*cf`,
    /// `mmu encode request W 0xb 5` → `Wb 5*33`.
    Request {
        /// The request letter: Q T L M U X P S B E W K F f H R (case-sensitive).
        #[arg(value_name = "CODE", value_parser = parse_request_code)]
        code: RequestCode,
        /// The value (slot, register address, ...): 0-255, decimal or 0x hex.
        #[arg(value_name = "VALUE", value_parser = parse_u8)]
        value: u8,
        /// The written value, for `W` only: 0-65535, decimal or 0x hex.
        #[arg(value_name = "VALUE2", value_parser = parse_u16)]
        value2: Option<u16>,
    },
    /// A response (unit → printer), e.g. `mmu encode response T 0 E 0x8003` → `T0 E8003*13`.
    Response {
        /// The echoed request letter: Q T L M U X P S B E W K F f H R.
        #[arg(value_name = "REQ_CODE", value_parser = parse_request_code)]
        code: RequestCode,
        /// The echoed request value: 0-255, decimal or 0x hex.
        #[arg(value_name = "REQ_VALUE", value_parser = parse_u8)]
        value: u8,
        /// The parameter letter: A (accepted), R (rejected), P (progress), E (error),
        /// F (finished), B (button).
        #[arg(value_name = "PARAM", value_parser = parse_param_code)]
        param: ParamCode,
        /// The parameter value, if the frame prints one: 0-65535, decimal or 0x hex.
        #[arg(value_name = "PARAM_VALUE", value_parser = parse_u16)]
        param_value: Option<u16>,
    },
}

/// The message built by `mmu encode`, or a usage error (`VALUE2` given to, or missing from, `W`).
pub fn build_frame(command: &EncodeCommand) -> Result<String, UsageError> {
    match *command {
        EncodeCommand::Request { code, value, value2 } => {
            let request = match (code, value2) {
                (RequestCode::Write, Some(value2)) => Request::write(value, value2),
                (RequestCode::Write, None) => {
                    return Err(UsageError(
                        "a write request needs VALUE2, the value to write (e.g. `mmu encode request W 0xb 5`)"
                            .to_string(),
                    ));
                }
                (_, None) => Request::new(code, value),
                (_, Some(_)) => {
                    return Err(UsageError(format!(
                        "only a write request (W) takes VALUE2, not {code}"
                    )));
                }
            };
            Ok(request.encode().as_str().to_string())
        }
        EncodeCommand::Response {
            code,
            value,
            param,
            param_value,
        } => {
            let response = Response {
                code,
                value,
                param,
                param_value,
            };
            Ok(response.encode().as_str().to_string())
        }
    }
}

/// Runs `mmu encode`: prints the frame without its newline.
pub fn encode(command: &EncodeCommand) -> Result<(), Box<dyn Error>> {
    let frame = build_frame(command)?;
    println!("{frame}");
    Ok(())
}

// --- argument parsers -----------------------------------------------------------------------

const REQUEST_LETTERS: &str = "Q T L M U X P S B E W K F f H R";
const PARAM_LETTERS: &str = "A R P E F B";

/// One letter, as a `u8`.
fn single_letter(text: &str) -> Option<u8> {
    match text.as_bytes() {
        [byte] => Some(*byte),
        _ => None,
    }
}

/// A request letter (case-sensitive: `f` is the filament sensor, `F` the filament type).
fn parse_request_code(text: &str) -> Result<RequestCode, String> {
    single_letter(text)
        .and_then(RequestCode::from_byte)
        .ok_or_else(|| format!("unknown request code {text:?}; expected one of: {REQUEST_LETTERS}"))
}

/// A response parameter letter.
fn parse_param_code(text: &str) -> Result<ParamCode, String> {
    single_letter(text)
        .and_then(ParamCode::from_byte)
        .ok_or_else(|| format!("unknown parameter code {text:?}; expected one of: {PARAM_LETTERS}"))
}

/// A number, decimal or `0x` hex, up to `max`.
fn parse_number(text: &str, max: u16) -> Result<u16, String> {
    let (digits, radix) = match text.strip_prefix("0x").or_else(|| text.strip_prefix("0X")) {
        Some(hex) => (hex, 16),
        None => (text, 10),
    };
    let not_a_number = || format!("{text:?} is not a number (decimal, or hex with 0x)");
    if digits.is_empty() || !digits.chars().all(|c| c.is_digit(radix)) {
        return Err(not_a_number());
    }
    // Only digits are left, so the one failure is an overflow.
    let value = u32::from_str_radix(digits, radix).unwrap_or(u32::MAX);
    u16::try_from(value)
        .ok()
        .filter(|&v| v <= max)
        .ok_or_else(|| format!("{text} is too large (at most {max})"))
}

/// A `u8`, decimal or `0x` hex (also for `mmu printer`).
pub(crate) fn parse_u8(text: &str) -> Result<u8, String> {
    parse_number(text, u8::MAX.into()).and_then(|v| u8::try_from(v).map_err(|e| e.to_string()))
}

/// A `u16`, decimal or `0x` hex (also for `mmu printer`).
pub(crate) fn parse_u16(text: &str) -> Result<u16, String> {
    parse_number(text, u16::MAX)
}

/// A button of the printer's screens, `0`, `1` or `2` (the protocol's `B0` to `B2`, Prusa's
/// `ButtonCode`): `mmu printer button N` and the console's `button N`.
pub(crate) fn parse_button(text: &str) -> Result<u8, String> {
    let button = parse_u8(text).map_err(|error| format!("button {text}: {error}"))?;
    if mmu_protocol::ButtonCode(button).name().is_none() {
        return Err(format!(
            "button {button}: the printer's buttons are 0 (right), 1 (middle: Retry, Continue) and 2 (left)"
        ));
    }
    Ok(button)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers() {
        assert_eq!(parse_u8("0"), Ok(0));
        assert_eq!(parse_u8("255"), Ok(255));
        assert_eq!(parse_u8("0x1b"), Ok(0x1b));
        assert_eq!(parse_u8("0XFF"), Ok(0xff));
        assert!(parse_u8("256").is_err());
        assert!(parse_u8("0x100").is_err());
        assert!(parse_u8("-1").is_err());
        assert!(parse_u8("").is_err());
        assert!(parse_u8("0x").is_err());
        assert!(parse_u8("+1").is_err());
        assert!(parse_u8("0x+1").is_err());
        assert_eq!(parse_u16("0x8003"), Ok(0x8003));
        assert_eq!(parse_u16("65535"), Ok(65535));
        assert!(parse_u16("65536").is_err());
        assert!(parse_u16("99999999999").is_err());
    }

    #[test]
    fn letters() {
        assert_eq!(parse_request_code("f"), Ok(RequestCode::FilamentSensor));
        assert_eq!(parse_request_code("F"), Ok(RequestCode::FilamentType));
        assert!(parse_request_code("Z").is_err());
        assert!(parse_request_code("TT").is_err());
        assert!(parse_request_code("").is_err());
        assert_eq!(parse_param_code("E"), Ok(ParamCode::Error));
        assert!(parse_param_code("e").is_err());
    }
}
