//! Why a `mmu printer` action failed, in words a person acts on: the unit's error with what it
//! means on this hardware and what to check, or the printer's own trouble (a version mismatch
//! with how to go on).

use std::error::Error;
use std::fmt;

use mmu_protocol::ErrorCode;
use mmu_sim::PrinterError;
use serde_json::{Map, Value};

use crate::explain::error_help;

/// Why an action failed, with the unit's error when it stopped on one.
#[derive(Debug)]
pub struct Failure {
    message: String,
    error: Option<ErrorCode>,
}

impl Failure {
    /// A failure with no unit error behind it.
    pub fn new(message: impl Into<String>) -> Self {
        Failure {
            message: message.into(),
            error: None,
        }
    }

    /// A command stopped on the unit's `error`.
    pub(super) fn unit(message: String, error: ErrorCode) -> Self {
        Failure {
            message,
            error: Some(error),
        }
    }

    /// The failure as the fields of a final JSON `result` object.
    pub(super) fn details(&self) -> Map<String, Value> {
        let mut details = Map::new();
        details.insert("message".into(), self.message.clone().into());
        if let Some(error) = self.error {
            let help = error_help(error);
            details.insert("error".into(), error.to_string().into());
            details.insert("screen".into(), format!("{:05}", error.printer_screen()).into());
            details.insert("meaning".into(), help.meaning.into());
            details.insert("check".into(), help.check.into());
        }
        details
    }
}

impl fmt::Display for Failure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)?;
        if let Some(error) = self.error {
            let help = error_help(error);
            write!(f, "\n  what it means: {}\n  check: {}", help.meaning, help.check)?;
        }
        Ok(())
    }
}

impl Error for Failure {}

impl From<PrinterError> for Failure {
    fn from(error: PrinterError) -> Self {
        Failure::new(error.to_string())
    }
}

/// The printer stopped on `error`, in plain words; a version mismatch says what the unit
/// reports and how to talk to it anyway (`expected`: the version the printer supports).
pub(crate) fn printer_failure(error: PrinterError, expected: (u8, u8, u8)) -> Failure {
    let PrinterError::VersionMismatch { part, got } = error else {
        return Failure::new(error.to_string());
    };
    let (major, minor, revision) = expected;
    let want = format!("{major}.{minor}.{revision}");
    let screen = "MMU FW UPDATE NEEDED, printer screen 04504";
    let Some(got) = got else {
        return Failure::new(format!(
            "the unit answered the version request S{part} without a number; the printer expects {want} ({screen})"
        ));
    };
    let mut parts = [major.to_string(), minor.to_string(), revision.to_string()];
    if let Some(slot) = parts.get_mut(usize::from(part)) {
        *slot = got.to_string();
    }
    for later in parts.iter_mut().skip(usize::from(part) + 1) {
        *later = "?".to_string();
    }
    let reported = parts.join(".");
    let mut message = format!("the unit reports version {reported}, the printer expects {want} ({screen})");
    if part == 2 && mmu_firmware::config::REVISIONS.contains(&revision) {
        message.push_str(&format!(
            ".\n  To talk to this unit as it is, add --expect-version {reported}.\n  To make it offer {want} first (register 0x52; it offers 3.0.4 to 3.0.0 by itself): \
             mmu printer --port DEV --expect-version {reported} write 0x52 {revision}"
        ));
    } else if part == 2 {
        message.push_str(&format!(
            ".\n  This unit speaks MMU 3.0.0 to 3.0.4; to talk to it anyway, add --expect-version {reported}"
        ));
    } else {
        message.push_str(&format!(
            ".\n  Check that the unit runs this firmware; to talk to it anyway, add --expect-version {reported}"
        ));
    }
    Failure::new(message)
}
