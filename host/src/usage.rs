//! How a failure ends the process: the same kind of mistake gets the same exit status in every
//! subcommand. A usage mistake found after clap's parsing (options that do not fit together, a
//! fault naming a slot the unit lacks) exits 2 as clap's own do; Ctrl-C exits 130 after the tool
//! printed what it had.

use std::error::Error;
use std::fmt;
use std::process::ExitCode;

/// A usage mistake found after clap's parsing: exits 2.
#[derive(Debug)]
pub struct UsageError(pub String);

impl fmt::Display for UsageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl Error for UsageError {}

/// A usage mistake, boxed as the subcommands return it.
pub fn usage(message: impl Into<String>) -> Box<dyn Error> {
    Box::new(UsageError(message.into()))
}

/// The run was stopped by Ctrl-C (after printing what it had): exits 130, as a shell reports a
/// process ended by SIGINT.
#[derive(Debug)]
pub struct Interrupted(pub String);

impl fmt::Display for Interrupted {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl Error for Interrupted {}

/// The exit status for `error`: 2 for a usage mistake, 130 for Ctrl-C, 1 otherwise.
pub fn exit_code(error: &(dyn Error + 'static)) -> ExitCode {
    if error.is::<UsageError>() {
        ExitCode::from(2)
    } else if error.is::<Interrupted>() {
        ExitCode::from(130)
    } else {
        ExitCode::FAILURE
    }
}
