//! How a failure ends the process: the same kind of mistake gets the same exit status in every
//! subcommand. A usage mistake found after clap's parsing (options that do not fit together, a
//! fault naming a slot the unit lacks) exits 2 as clap's own do; Ctrl-C exits 130 after the tool
//! printed what it had.

use std::error::Error;
use std::fmt;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

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

/// The command the unit runs for the tool (`T1`), for Ctrl-C to name; shared with the handler's
/// thread.
#[derive(Debug, Clone, Default)]
pub struct Running(Arc<Mutex<Option<String>>>);

impl Running {
    /// The unit runs `what` from now on (`None`: nothing).
    pub fn set(&self, what: Option<String>) {
        if let Ok(mut running) = self.0.lock() {
            *running = what;
        }
    }

    fn get(&self) -> Option<String> {
        self.0.lock().ok().and_then(|running| running.clone())
    }
}

/// On Ctrl-C, say what the unit was left doing (`running`) and how to see where it ends (`look`,
/// then `extra` if any), and end with status 130: the tool cannot stop a command the unit runs
/// (the printer protocol has no abort), and must not leave the person believing it did.
pub fn stop_on_ctrl_c(running: &Running, look: String, extra: Option<&'static str>) {
    let running = running.clone();
    let result = ctrlc::set_handler(move || {
        let mut text = match running.get() {
            Some(command) => format!(
                "\nmmu: stopped by Ctrl-C while the unit runs {command}: the command keeps running on the unit, \
                 which finishes or fails it by itself (the printer protocol has no abort; every motion is \
                 bounded); {look}"
            ),
            None => "\nmmu: stopped by Ctrl-C".to_string(),
        };
        if let Some(extra) = extra {
            text.push_str("; ");
            text.push_str(extra);
        }
        eprintln!("{text}");
        std::process::exit(130);
    });
    // Without a handler Ctrl-C still ends the process, only without the words.
    let _ = result;
}
