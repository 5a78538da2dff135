//! The person at the printer, as `mmu printer` and `mmu demo` play them.
//!
//! [`Console`] is the [`Operator`] of the printer's protocol logic: it shows every
//! [`PrinterEvent`] as a line a person reads (`T1: FeedingToFSensor`,
//! `T1: error FSENSOR_DIDNT_SWITCH_ON (printer screen 04103)`) or as one JSON object per line,
//! keeps a spinner on stderr while it works (only on a terminal, never with `--json`), and
//! answers the printer's dialogs as a command-line user would: Continue on the eject dialog
//! (after pulling the filament out, when the simulator lets it), give up on anything else.

use std::io::{IsTerminal, Write};
use std::time::Duration;

use indicatif::{ProgressBar, ProgressStyle};
use mmu_protocol::{ButtonCode, ErrorCode, ProgressCode, Request, RequestCode, ResultCode};
use mmu_sim::event::{EventKind, FaultAction};
use mmu_sim::{Decision, Link, Operator, PrinterEvent, SimLink};
use serde::Serialize;
use serde_json::Value;

use super::serial::NoAnswerHint;
use crate::explain::{error_meaning, request_label, request_meaning, response_label, response_meaning};

/// How often the eject dialog is answered for one command before the user gives up (the unit
/// should finish after the first Continue).
const MAX_DIALOG_PRESSES: u8 = 3;

/// A link the printer drives, and what the person at the printer can do to the unit behind it
/// besides pressing buttons.
pub trait Target: Link {
    /// The person pulls the ejected filament out of `slot`. False when that is up to a real
    /// person at a real unit.
    fn remove_filament(&mut self, slot: u8) -> bool;

    /// What happened inside the unit since the last call that a person would notice (a fault
    /// injected or cleared, a power loss): when (the printer's clock, ms) and what, one line each.
    fn notes(&mut self) -> Vec<(u64, String)>;

    /// What to check when the unit gave no answer yet: a serial port's words
    /// ([`super::serial::NoAnswerHint`]); `None` for the simulator.
    fn no_answer_hint(&self) -> Option<String> {
        None
    }
}

impl Target for SimLink {
    fn remove_filament(&mut self, slot: u8) -> bool {
        self.sim_mut().model_mut().remove_filament(usize::from(slot))
    }

    fn notes(&mut self) -> Vec<(u64, String)> {
        self.sim_mut()
            .take_events()
            .into_iter()
            .filter_map(|event| {
                let text = match event.what {
                    EventKind::Fault { action, fault } => match action {
                        FaultAction::Inject => format!("sim: fault {fault} injected"),
                        FaultAction::Clear => format!("sim: fault {fault} cleared"),
                    },
                    EventKind::Power { on: false } => "sim: the unit is off".to_string(),
                    EventKind::Power { on: true } => "sim: the unit boots".to_string(),
                    _ => return None,
                };
                Some((event.t_ms, text))
            })
            .collect()
    }
}

/// A command that finished, and how long it ran.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FinishedCommand {
    /// The command.
    pub request: Request,
    /// Its `F` result.
    pub result: ResultCode,
    /// From its first sending to its `F`, ms on the printer's clock (virtual with the simulator).
    pub duration_ms: u64,
}

/// The command in progress, as the person at the printer follows it.
#[derive(Debug, Clone, Copy)]
struct Running {
    request: Request,
    started_ms: u64,
    phase: Option<ProgressCode>,
}

/// One line of `--json` output. Every line has `event`; most have `t_ms`, the printer's clock.
#[derive(Debug, Serialize)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum JsonLine {
    /// A request went out (`-v` only).
    Sent {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The frame without its newline.
        frame: String,
        /// What it asks for.
        meaning: String,
    },
    /// An answer came in (`-v` only).
    Received {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The frame without its newline.
        frame: String,
        /// What it says.
        meaning: String,
    },
    /// The handshake passed.
    Connected {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The unit's version, `3.0.3`.
        version: String,
        /// Its build number.
        build: u16,
    },
    /// A command reached a new phase.
    Progress {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The command, e.g. `T1`.
        request: String,
        /// The progress code.
        code: u8,
        /// Its name, e.g. `FeedingToFSensor`.
        name: String,
    },
    /// A command stopped on an error.
    Error {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The command.
        request: String,
        /// The error code in hex, as on the wire.
        code: String,
        /// Its name, e.g. `FSENSOR_DIDNT_SWITCH_ON`.
        name: String,
        /// The printer's error screen, e.g. `04103`.
        screen: String,
    },
    /// The printer pressed Retry by itself.
    Retry {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The command.
        request: String,
        /// The error retried.
        error: String,
        /// Automatic presses left.
        left: u8,
    },
    /// A button went to the unit.
    Button {
        /// The printer's clock, ms.
        t_ms: u64,
        /// Its number.
        button: u8,
        /// `Right`, `Middle` or `Left`.
        name: &'static str,
    },
    /// The printer shows a dialog and the user answers it.
    Dialog {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The command.
        request: String,
        /// The dialog's code name.
        error: String,
        /// The printer's screen.
        screen: String,
        /// What the user presses.
        button: &'static str,
    },
    /// The (simulated) user did something to the unit.
    User {
        /// The printer's clock, ms.
        t_ms: u64,
        /// What, e.g. `remove_filament`.
        action: &'static str,
        /// The slot.
        slot: u8,
    },
    /// A command finished.
    Finished {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The command.
        request: String,
        /// `OK` or `Cancelled`.
        result: String,
        /// How long it ran, ms.
        duration_ms: u64,
    },
    /// No valid answer: the printer connects again.
    LinkLost {
        /// The printer's clock, ms.
        t_ms: u64,
        /// `timeout` or `garbled`.
        why: &'static str,
    },
    /// The unit restarted under a command; the printer repeats it.
    Interrupted {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The command.
        request: String,
    },
    /// The printer left a tool change before the unit finished it (Buddy 6.5.3) and loads on to
    /// the nozzle while it keeps polling.
    PrematureFinish {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The command.
        request: String,
    },
    /// FINDA read empty while printing: the printer starts its filament change (`M600`), or
    /// joins to the next slot with SpoolJoin on.
    Runout {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The slot that ran out.
        slot: u8,
        /// The slot SpoolJoin continues with, if on.
        join: Option<u8>,
    },
    /// Something happened inside the simulator (a fault, a power loss).
    Sim {
        /// The printer's clock, ms.
        t_ms: u64,
        /// What.
        what: String,
    },
    /// A remark of the tool (e.g. why it unloads first).
    Note {
        /// The printer's clock, ms.
        t_ms: u64,
        /// The remark.
        text: String,
    },
    /// A step of `mmu demo` begins.
    Step {
        /// What the step shows.
        text: String,
    },
    /// The last line: how the action ended.
    Result {
        /// The action, e.g. `tool`.
        action: &'static str,
        /// It succeeded.
        ok: bool,
        /// What it found (an object; absent when empty).
        #[serde(flatten)]
        details: serde_json::Map<String, Value>,
    },
}

/// The person at the printer: shows what happens and answers the dialogs. See the
/// [module documentation](self).
pub struct Console {
    json: bool,
    verbose: bool,
    /// Show a spinner on stderr (a terminal, and not `--json`).
    live: bool,
    spinner: Option<ProgressBar>,
    running: Option<Running>,
    version: Option<((u8, u8, u8), u16)>,
    finished: Vec<FinishedCommand>,
    dialogs: u8,
    /// What to check when a port gives no answer, said once.
    no_answer: NoAnswerHint,
}

impl Console {
    /// A console printing JSON lines (`json`) or text, with every frame when `verbose`.
    pub fn new(json: bool, verbose: bool) -> Self {
        Console {
            json,
            verbose,
            live: !json && std::io::stderr().is_terminal(),
            spinner: None,
            running: None,
            version: None,
            finished: Vec::new(),
            dialogs: 0,
            no_answer: NoAnswerHint::default(),
        }
    }

    /// The unit's version and build, once connected.
    pub fn version(&self) -> Option<((u8, u8, u8), u16)> {
        self.version
    }

    /// The commands that finished so far, oldest first.
    pub fn finished(&self) -> &[FinishedCommand] {
        &self.finished
    }

    /// A progress bar of `len` steps on stderr, when a person watches a terminal.
    pub fn progress_bar(&self, len: u64, what: &str) -> Option<ProgressBar> {
        if !self.live {
            return None;
        }
        let template = format!("{{bar:40}} {{pos}}/{{len}} {what}  {{elapsed}} (eta {{eta}})");
        let bar = ProgressBar::new(len);
        if let Ok(style) = ProgressStyle::with_template(&template) {
            bar.set_style(style);
        }
        Some(bar)
    }

    /// A line of text for a person (nothing with `--json`).
    pub fn say(&self, text: &str) {
        if !self.json {
            self.print(text);
        }
    }

    /// One JSON line (nothing without `--json`).
    pub fn emit(&self, line: &JsonLine) {
        if self.json {
            match serde_json::to_string(line) {
                Ok(text) => self.print(&text),
                Err(error) => self.print(&format!(r#"{{"event":"bug","error":"{error}"}}"#)),
            }
        }
    }

    /// A remark at printer time `t_ms`, as text or as a `note` line.
    pub fn note(&self, t_ms: u64, text: &str) {
        self.show(t_ms, text, || JsonLine::Note {
            t_ms,
            text: text.to_string(),
        });
    }

    /// The heading of a step of a scripted session.
    pub fn heading(&self, text: &str) {
        self.say("");
        self.say(&format!("== {text}"));
        self.emit(&JsonLine::Step {
            text: text.to_string(),
        });
    }

    /// Stop the spinner.
    pub fn close(&mut self) {
        if let Some(spinner) = self.spinner.take() {
            spinner.finish_and_clear();
        }
    }

    /// Print a whole line on stdout, clearing the spinner around it. Output errors (a closed
    /// pipe) are ignored: the unit must still be driven to the end of its command.
    fn print(&self, line: &str) {
        let write = || {
            let _ = writeln!(std::io::stdout().lock(), "{line}");
        };
        match &self.spinner {
            Some(spinner) => spinner.suspend(write),
            None => write(),
        }
    }

    /// Show an event: a timestamped text line, or its JSON line.
    fn show(&self, t_ms: u64, text: &str, json: impl FnOnce() -> JsonLine) {
        if self.json {
            self.emit(&json());
        } else {
            self.line(t_ms, text);
        }
    }

    /// A text line stamped with the printer's clock (nothing with `--json`).
    fn line(&self, t_ms: u64, text: &str) {
        if !self.json {
            self.print(&format!("{:>9.3} s  {text}", t_ms as f64 / 1000.0));
        }
    }

    /// The spinner's line: what runs, in which phase, at what time.
    fn update_spinner(&mut self, t_ms: u64) {
        if !self.live {
            return;
        }
        let spinner = self.spinner.get_or_insert_with(|| {
            let spinner = ProgressBar::new_spinner();
            if let Ok(style) = ProgressStyle::with_template("{spinner} {msg}") {
                spinner.set_style(style);
            }
            spinner.enable_steady_tick(Duration::from_millis(100));
            spinner
        });
        let doing = match &self.running {
            Some(running) => {
                let phase = running.phase.map_or("accepted".to_string(), |p| p.to_string());
                format!("{} {phase}", request_label(&running.request))
            }
            None => "talking to the unit".to_string(),
        };
        spinner.set_message(format!("{doing}  (printer clock {:.1} s)", t_ms as f64 / 1000.0));
    }

    fn sent(&mut self, t_ms: u64, request: &Request) {
        let is_new = self.running.is_none_or(|r| r.request != *request);
        if request.code.is_command() && is_new {
            self.running = Some(Running {
                request: *request,
                started_ms: t_ms,
                phase: None,
            });
            self.dialogs = 0;
        }
        if self.verbose {
            let frame = request.encode().as_str().to_string();
            let meaning = request_meaning(request);
            self.show(t_ms, &format!("> {frame}  {meaning}"), || JsonLine::Sent {
                t_ms,
                frame,
                meaning,
            });
        }
    }

    fn received(&self, t_ms: u64, response: &mmu_protocol::Response) {
        if self.verbose {
            let frame = response.encode().as_str().to_string();
            let meaning = response_meaning(response);
            self.show(t_ms, &format!("< {frame}  {meaning}"), || JsonLine::Received {
                t_ms,
                frame,
                meaning,
            });
        }
    }

    fn progress(&mut self, t_ms: u64, request: &Request, code: ProgressCode) {
        if let Some(running) = &mut self.running {
            running.phase = Some(code);
        }
        let label = request_label(request);
        self.show(t_ms, &format!("{label}: {code}"), || JsonLine::Progress {
            t_ms,
            request: label.clone(),
            code: code.0,
            name: code.to_string(),
        });
    }

    fn error(&self, t_ms: u64, request: &Request, error: ErrorCode) {
        let label = request_label(request);
        let text = match error {
            ErrorCode::INVALID_TOOL => format!(
                "{label}: rejected by the unit: it has no slot {}: {}",
                request.value,
                error_meaning(error)
            ),
            ErrorCode::FILAMENT_EJECTED => format!("{label}: {}", error_meaning(error)),
            _ => format!("{label}: error {}", error_meaning(error)),
        };
        self.show(t_ms, &text, || JsonLine::Error {
            t_ms,
            request: label.clone(),
            code: format!("{:x}", error.0),
            name: error.to_string(),
            screen: format!("{:05}", error.printer_screen()),
        });
    }

    fn auto_retry(&self, t_ms: u64, error: ErrorCode, left: u8) {
        let label = self.running_label();
        self.show(t_ms, &format!("{label}: auto Retry ({left} left)"), || {
            JsonLine::Retry {
                t_ms,
                request: label.clone(),
                error: error.to_string(),
                left,
            }
        });
    }

    fn button(&self, t_ms: u64, button: ButtonCode) {
        let name = button.name().unwrap_or("unknown");
        let line = JsonLine::Button {
            t_ms,
            button: button.0,
            name,
        };
        if self.json {
            self.emit(&line);
        } else if self.verbose {
            self.show(t_ms, &format!("button {} {name} sent", button.0), || line);
        }
    }

    fn finished_command(&mut self, t_ms: u64, request: &Request, result: ResultCode) {
        let started = self
            .running
            .filter(|r| r.request == *request)
            .map_or(t_ms, |r| r.started_ms);
        let duration_ms = t_ms.saturating_sub(started);
        self.finished.push(FinishedCommand {
            request: *request,
            result,
            duration_ms,
        });
        self.running = None;
        let label = request_label(request);
        let result = result_name(result);
        let text = format!(
            "{label}: finished {result} in {:.1} s",
            duration_ms as f64 / 1000.0
        );
        self.show(t_ms, &text, || JsonLine::Finished {
            t_ms,
            request: label.clone(),
            result: result.clone(),
            duration_ms,
        });
    }

    fn running_label(&self) -> String {
        self.running
            .map_or_else(|| "unit".to_string(), |r| request_label(&r.request))
    }

    /// The eject dialog: the filament must come out of the slot, then Continue.
    fn eject_dialog<L: Target>(&mut self, link: &mut L, request: Request, error: ErrorCode) -> Decision {
        let t_ms = link.now_ms();
        let label = request_label(&request);
        let slot = request.value;
        let screen = format!("{:05}", error.printer_screen());
        let text = format!(
            "{label}: printer dialog {error} (screen {screen}): remove the filament from slot {slot}, then [Continue]"
        );
        self.show(t_ms, &text, || JsonLine::Dialog {
            t_ms,
            request: label.clone(),
            error: error.to_string(),
            screen: screen.clone(),
            button: "Continue",
        });
        if link.remove_filament(slot) {
            let text = format!("{label}: the simulated user pulls the filament out of slot {slot}");
            self.show(t_ms, &text, || JsonLine::User {
                t_ms,
                action: "remove_filament",
                slot,
            });
        }
        // In JSON the `button` line that follows says it.
        self.line(t_ms, &format!("{label}: Continue pressed (B1)"));
        Decision::Press(ButtonCode::MIDDLE)
    }
}

impl Drop for Console {
    fn drop(&mut self) {
        self.close();
    }
}

impl<L: Target> Operator<L> for Console {
    fn event(&mut self, link: &mut L, event: &PrinterEvent) {
        for (t_ms, note) in link.notes() {
            self.show(t_ms, &note, || JsonLine::Sim {
                t_ms,
                what: note.clone(),
            });
        }
        let t_ms = link.now_ms();
        match event {
            PrinterEvent::Sent(request) => self.sent(t_ms, request),
            PrinterEvent::Received(response) => {
                self.no_answer.on_event(link, event);
                self.received(t_ms, response);
            }
            PrinterEvent::Connected { version, build } => {
                self.version = Some((*version, *build));
                let (major, minor, revision) = *version;
                let version = format!("{major}.{minor}.{revision}");
                let text = format!("connected: unit firmware {version}, build {build}");
                self.show(t_ms, &text, || JsonLine::Connected {
                    t_ms,
                    version: version.clone(),
                    build: *build,
                });
            }
            PrinterEvent::Progress(request, code) => self.progress(t_ms, request, *code),
            PrinterEvent::Error(request, error) => self.error(t_ms, request, *error),
            PrinterEvent::AutoRetry(error, left) => self.auto_retry(t_ms, *error, *left),
            PrinterEvent::Button(button) => self.button(t_ms, *button),
            PrinterEvent::Finished(request, result) => self.finished_command(t_ms, request, *result),
            PrinterEvent::LinkLost(fault) => {
                let why = fault.as_str();
                let text = format!("link lost ({why}): the printer connects again");
                self.show(t_ms, &text, || JsonLine::LinkLost { t_ms, why });
                if let Some(hint) = self.no_answer.on_event(link, event) {
                    self.note(t_ms, &hint);
                }
            }
            PrinterEvent::Interrupted(request) => {
                let label = request_label(request);
                let text = format!("{label}: the unit restarted under it; the printer repeats it");
                self.show(t_ms, &text, || JsonLine::Interrupted {
                    t_ms,
                    request: label.clone(),
                });
            }
            PrinterEvent::PrematureFinish(request) => {
                let label = request_label(request);
                let text = format!(
                    "{label}: the printer leaves the tool change early (premature finish) and loads on to the nozzle while the unit finishes"
                );
                self.show(t_ms, &text, || JsonLine::PrematureFinish {
                    t_ms,
                    request: label.clone(),
                });
            }
            PrinterEvent::Runout { slot, join } => {
                let text = match join {
                    Some(next) => format!("FINDA runout of slot {slot}: M600 A, SpoolJoin to slot {next}"),
                    None => format!("FINDA runout of slot {slot}: M600, filament change"),
                };
                self.show(t_ms, &text, || JsonLine::Runout {
                    t_ms,
                    slot: *slot,
                    join: *join,
                });
            }
            PrinterEvent::Heartbeat(_) => {}
        }
        self.update_spinner(t_ms);
    }

    fn decide(&mut self, link: &mut L, request: Request, error: ErrorCode) -> Decision {
        let dialog = error == ErrorCode::FILAMENT_EJECTED && request.code == RequestCode::Eject;
        if !dialog || self.dialogs >= MAX_DIALOG_PRESSES {
            return Decision::GiveUp;
        }
        self.dialogs += 1;
        self.eject_dialog(link, request, error)
    }
}

/// `OK`, `Cancelled`, or the number.
pub fn result_name(result: ResultCode) -> String {
    result
        .name()
        .map_or_else(|| format!("result {}", result.0), str::to_string)
}

/// The state the unit reported (a `Q0` answer) as a person reads it: `X0 F0 (finished OK)`.
pub fn state_text(state: &mmu_protocol::Response) -> String {
    format!("{} ({})", response_label(state), response_meaning(state))
}
