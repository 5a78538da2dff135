//! `mmu printer`: the printer's side of the MMU protocol, as Prusa's firmware plays it, against a
//! unit on a serial port (`--port`) or the in-process simulator (`--sim`).
//!
//! The protocol logic (handshake, `Q0` heartbeat, `f` reports, register poll, automatic Retry,
//! re-handshake after a link timeout) is [`mmu_sim::Printer`]. This module adds the printer's
//! menu actions on top of it ([`Session`]: status, tool change, preload, unload, eject, cut,
//! home, reset, register access, buttons), the bench actions ([`bench`]: stats, settings) and
//! soak runs ([`soak`]); [`console`] is the person at the printer (what is shown, how dialogs are
//! answered), [`serial`] the wire to a real unit, [`failure`] why an action failed.
//! `mmu demo` ([`crate::demo`]) plays a script on the same [`Session`].

mod bench;
pub mod console;
mod failure;
mod lanes;
pub mod serial;
mod soak;

use std::error::Error;
use std::path::PathBuf;

use clap::Subcommand;
use mmu_firmware::profile::Profile;
use mmu_firmware::registers::UNLOAD_STUCK;
use mmu_protocol::{ErrorCode, ParamCode, Request, RequestCode, Response};
use mmu_sim::{
    ExtruderGeometry, FAULT_HELP, Outcome, Personality, Printer, PrinterError, PrinterOptions,
    ScheduledFault, Sim, SimLink, SimOptions,
};
use serde_json::{Map, Value, json};

use crate::codec_cli::{parse_button, parse_u8, parse_u16};
use crate::explain::{
    error_meaning, parse_register, register_name, request_label, request_meaning, response_label,
    response_meaning, unload_stuck,
};
use crate::sim_cli::parse_slots;
use crate::usage::{Running, stop_on_ctrl_c, usage};
use console::{Console, JsonLine, Target, result_name, state_text};
pub use failure::Failure;
pub(crate) use failure::printer_failure;
use serial::{EventsTail, FsensorSource, SerialLink};
use soak::run_soak;
pub use soak::{SoakArgs, ctrl_c_flag};

/// Shown after `mmu printer --help`.
const AFTER_HELP: &str = "\
Numbers are decimal or 0x hex. Faults (--fault, simulator only):";

/// `mmu printer` options.
#[derive(Debug, clap::Args)]
#[command(after_long_help = format!("{AFTER_HELP}\n{FAULT_HELP}"))]
pub struct PrinterArgs {
    /// A real unit on this serial port (115200 8N1): a USB-serial adapter on USART1 (PB6/PB7; Pico: UART0, GP0/GP1), e.g.
    /// /dev/ttyUSB0 (not the NUCLEO's /dev/ttyACM0, the ST-LINK port).
    #[arg(long, value_name = "DEV", conflicts_with = "sim")]
    pub port: Option<String>,
    /// The in-process simulator, in virtual time (as fast as possible unless --time-scale).
    #[arg(long, global = true)]
    pub sim: bool,
    /// The simulated unit (--sim only).
    #[command(flatten)]
    pub sim_options: SimTargetArgs,
    /// Follow the printer's filament sensor in the events file that `mmu sim --events PATH`
    /// writes (--port only).
    #[arg(long, value_name = "PATH", requires = "port", conflicts_with = "fsensor")]
    pub fsensor_events: Option<PathBuf>,
    /// The printer's filament sensor, fixed (--port only): 0 no filament, 1 at the sensor,
    /// 2 in the nozzle. Default 0.
    #[arg(long, value_name = "STATE", requires = "port", value_parser = clap::value_parser!(u8).range(0..=3))]
    pub fsensor: Option<u8>,
    /// The unit firmware version the printer supports; S0..S2 must answer it exactly
    /// (Buddy 6.5.3 and later: 3.0.4; Buddy 6.4 and MK3S 3.14.1: 3.0.3; MK3S 3.13.3/3.14.0: 3.0.2).
    /// Default: the --printer's (3.0.3 without --printer).
    #[arg(long, value_name = "X.Y.Z", value_parser = parse_version)]
    pub expect_version: Option<(u8, u8, u8)>,
    /// The printer firmware played, in its protocol (version, Q0 period, answer timeout,
    /// registers polled, premature finish) and, with --sim, its extruder: buddy-6.5 (Buddy 6.5.3
    /// and later: 3.0.4, Q0 every 100 ms, 200 ms timeout, T before its own retract),
    /// buddy-6.4 (3.0.3, 1 s, 2 s, T after its retract), mk3s (3.0.2, 1 s, 2 s, no R22).
    /// Default: buddy-6.4.
    #[arg(long, value_name = "PRINTER", global = true, value_parser = parse_personality)]
    pub printer: Option<Personality>,
    /// SpoolJoin on: when the unit reports a runout while printing (FINDA empty), the printer
    /// joins to the next slot (`M600 A` / `M600 AUTO`) instead of stopping on its
    /// filament-change screen (`M600`).
    #[arg(long, global = true)]
    pub spool_join: bool,
    /// One JSON object per line per event, and a final `result` object.
    #[arg(long, global = true)]
    pub json: bool,
    /// Show every frame sent (`>`) and received (`<`).
    #[arg(short, long, global = true)]
    pub verbose: bool,
    /// What the printer does.
    #[command(subcommand)]
    pub action: Action,
}

/// The simulated unit of `--sim`.
#[derive(Debug, Clone, clap::Args)]
pub struct SimTargetArgs {
    /// Slots of the simulated unit, 1 to 5.
    #[arg(long, value_name = "N", default_value_t = 3, conflicts_with = "port", value_parser = parse_slots)]
    pub slots: usize,
    /// Seed of the simulator's random draws (and of `soak` unless it has its own).
    #[arg(long, value_name = "S", default_value_t = 1, conflicts_with = "port")]
    pub seed: u64,
    /// What senses each lane of the simulated unit: thesis, n20-quadrature, bmcu-c (see
    /// `mmu sim --help`).
    #[arg(long, value_name = "NAME", default_value = "thesis", conflicts_with = "port", value_parser = crate::sim_cli::parse_hardware)]
    pub hardware: &'static Profile,
    /// Where the simulated printer's extruder gears sit against its filament sensor:
    /// sensor-first, gears-first, or the gears' distance past the sensor in mm (see `mmu sim
    /// --help`). Default: the --printer's.
    #[arg(long, value_name = "GEOMETRY", conflicts_with = "port", value_parser = crate::sim_cli::parse_extruder)]
    pub extruder: Option<ExtruderGeometry>,
    /// Inject a fault, e.g. `jam:1` or `uart-drop:0.05@2000-9000` (repeatable; the list is
    /// at the end of --help).
    #[arg(long = "fault", value_name = "SPEC", conflicts_with = "port")]
    pub faults: Vec<ScheduledFault>,
    /// Pace the simulator at K × real time (default, or 0: as fast as possible).
    #[arg(long, value_name = "K", conflicts_with = "port", value_parser = parse_time_scale)]
    pub time_scale: Option<f64>,
}

/// What `mmu printer` does, as the printer's menus and G-codes would.
#[derive(Debug, Subcommand)]
pub enum Action {
    /// Connect; show the unit's version, its state (the first Q0 answer), the hub filament sensor and the polled
    /// registers.
    Status,
    /// Tool change `T<SLOT>`: the loaded slot comes out, SLOT goes to the nozzle.
    Tool {
        /// The slot (0 is the first).
        #[arg(value_parser = parse_u8)]
        slot: u8,
    },
    /// Preload `L<SLOT>`: feed the slot's filament to the hub sensor, then park it.
    Load {
        /// The slot.
        #[arg(value_parser = parse_u8)]
        slot: u8,
    },
    /// Unload `U0`: the loaded filament goes back to its park position.
    Unload,
    /// Eject: `U0` if the hub filament sensor (FINDA) sees filament, then `E<SLOT>`; the printer's FILAMENT_EJECTED dialog
    /// is answered with Continue (`B1`).
    Eject {
        /// The slot.
        #[arg(value_parser = parse_u8)]
        slot: u8,
    },
    /// Cut: `U0` if the hub filament sensor sees filament, then `K<SLOT>`.
    Cut {
        /// The slot.
        #[arg(value_parser = parse_u8)]
        slot: u8,
    },
    /// Home `H0`: the unit checks its sensors.
    Home,
    /// Reset `X0` (with --erase: `X2a`, erase the EEPROM too), connect again and show the first
    /// Q0 answer.
    Reset {
        /// Erase the unit's persisted data first (`M709 X42`).
        #[arg(long)]
        erase: bool,
    },
    /// Read register ADDRESS: `R<ADDRESS>`. Only reads.
    Read {
        /// The register: an address (0x08) or a name (bowden_mm, filtered.hub.filament).
        #[arg(value_parser = parse_register)]
        address: u8,
    },
    /// Write VALUE to register ADDRESS: `W<ADDRESS> <VALUE>`, and nothing else.
    Write {
        /// The register: an address (0x0b) or a name (extra_load_mm).
        #[arg(value_parser = parse_register)]
        address: u8,
        /// The value, 0..=65535.
        #[arg(value_parser = parse_u16)]
        value: u16,
    },
    /// Press a button: `B<N>` (0 Right, 1 Middle = Retry/Continue, 2 Left).
    Button {
        /// The button: 0, 1 or 2.
        #[arg(value_parser = parse_button)]
        button: u8,
    },
    /// Per-slot figures the unit keeps: tool changes, errors, metres fed, and where each slot's
    /// filament is. Only reads.
    Stats,
    /// The unit's settings (distances, speeds, sensor thresholds) to a file, or back from it.
    #[command(subcommand)]
    Settings(SettingsAction),
    /// Many tool changes on the simulator, with random faults if asked; prints the figures and
    /// exits non-zero when a change failed, got stuck or panicked. Ctrl-C stops it and prints the
    /// figures so far.
    Soak(SoakArgs),
}

/// `mmu printer settings save|load FILE`.
#[derive(Debug, Subcommand)]
pub enum SettingsAction {
    /// Read every writable setting and write them to FILE, one `ADDRESS VALUE  # name` line
    /// each. Only reads.
    Save {
        /// The file to write (replaced if it exists).
        file: PathBuf,
    },
    /// Write the settings of FILE (as `save` writes it; `#` starts a comment) to the unit,
    /// each one only where it differs.
    Load {
        /// The file to read.
        file: PathBuf,
    },
}

impl Action {
    /// The action's name, as on the command line.
    fn name(&self) -> &'static str {
        match self {
            Action::Status => "status",
            Action::Tool { .. } => "tool",
            Action::Load { .. } => "load",
            Action::Unload => "unload",
            Action::Eject { .. } => "eject",
            Action::Cut { .. } => "cut",
            Action::Home => "home",
            Action::Reset { .. } => "reset",
            Action::Read { .. } => "read",
            Action::Write { .. } => "write",
            Action::Button { .. } => "button",
            Action::Stats => "stats",
            Action::Settings(SettingsAction::Save { .. }) => "settings save",
            Action::Settings(SettingsAction::Load { .. }) => "settings load",
            Action::Soak(_) => "soak",
        }
    }

    /// A bench action: it talks to the unit without the printer's handshake writes (`W0b`,
    /// `W14`) and `f` reports, so that it changes nothing but what it is asked to.
    fn is_bench(&self) -> bool {
        matches!(
            self,
            Action::Status | Action::Read { .. } | Action::Write { .. } | Action::Stats | Action::Settings(_)
        )
    }
}

/// What a successful action found: the fields of the final JSON `result` object.
pub type Details = Map<String, Value>;

/// The printer on a link with the person at it: the printer's menu actions.
pub struct Session<L: Target> {
    printer: Printer<L>,
    console: Console,
    /// The unit version the printer supports, for the mismatch message.
    expected_version: (u8, u8, u8),
    /// The command the unit runs, for Ctrl-C to name.
    running: Running,
}

impl<L: Target> Session<L> {
    /// A printer set up with `options` on `link`, not yet connected.
    pub fn new(link: L, options: PrinterOptions, console: Console) -> Self {
        Session {
            printer: Printer::new(link, options),
            console,
            expected_version: options.version,
            running: Running::default(),
        }
    }

    /// The person at the printer.
    pub fn console(&self) -> &Console {
        &self.console
    }

    /// The link, to play the user on the simulator.
    pub fn link_mut(&mut self) -> &mut L {
        self.printer.link_mut()
    }

    /// The printer's clock, ms.
    pub fn now_ms(&self) -> u64 {
        self.printer.link().now_ms()
    }

    /// Handshake; returns the unit's state (the first `Q0` answer) and says so when the unit is
    /// not at rest.
    pub fn connect(&mut self) -> Result<Response, Failure> {
        let state = self
            .printer
            .connect(&mut self.console)
            .map_err(|error| self.failure(error))?;
        if state.param != ParamCode::Finished {
            let text = format!("the unit is not at rest: {}", state_text(&state));
            self.console.note(self.now_ms(), &text);
        }
        Ok(state)
    }

    /// Why the printer could not go on, in plain words.
    fn failure(&self, error: PrinterError) -> Failure {
        printer_failure(error, self.expected_version)
    }

    /// Run a command (`T L U E K H`) to its end.
    pub fn command(&mut self, request: Request) -> Result<Details, Failure> {
        let label = request_label(&request);
        self.running.set(Some(label.clone()));
        let outcome = self.printer.command(&mut self.console, request);
        self.running.set(None);
        let outcome = outcome.map_err(|error| self.failure(error))?;
        match outcome {
            Outcome::Finished(result) => {
                let mut details = Details::new();
                details.insert("request".into(), label.into());
                details.insert("result".into(), result_name(result).into());
                Ok(details)
            }
            Outcome::Rejected => Err(Failure::new(format!(
                "{label} rejected: the unit answered R every time"
            ))),
            Outcome::FilamentChange(slot) => Err(Failure::new(format!(
                "{label}: the print stopped on the filament-change screen after slot {slot} ran out"
            ))),
            Outcome::GaveUp(error @ ErrorCode::INVALID_TOOL) => Err(Failure::unit(
                format!(
                    "{label} rejected by the unit: it has no slot {}: {}",
                    request.value,
                    error_meaning(error)
                ),
                error,
            )),
            Outcome::GaveUp(error) => {
                let mut message = format!(
                    "{label} ({}) stopped on error {}",
                    request_meaning(&request),
                    error_meaning(error)
                );
                if error == ErrorCode::FSENSOR_DIDNT_SWITCH_OFF
                    // Best effort: a read lost on the link leaves the error as it is.
                    && let Ok(Some(why)) = self.read_quietly(UNLOAD_STUCK)
                    && why != 0
                {
                    message = format!("{message}\n  which (register 0xfc): {}", unload_stuck(why));
                }
                Err(Failure::unit(message, error))
            }
        }
    }

    /// Eject as the printer does: `U0` first if FINDA sees filament, then `E<slot>`; the
    /// console answers the FILAMENT_EJECTED dialog.
    pub fn eject(&mut self, slot: u8) -> Result<Details, Failure> {
        self.unload_if_finda()?;
        self.command(Request::new(RequestCode::Eject, slot))
    }

    /// Cut as the printer does: `U0` first if FINDA sees filament, then `K<slot>`.
    pub fn cut(&mut self, slot: u8) -> Result<Details, Failure> {
        self.unload_if_finda()?;
        self.command(Request::new(RequestCode::Cut, slot))
    }

    fn unload_if_finda(&mut self) -> Result<(), Failure> {
        if self.printer.finda() {
            self.console.note(
                self.now_ms(),
                "the hub filament sensor (the printer's FINDA) sees filament: the printer unloads first",
            );
            self.command(Request::new(RequestCode::Unload, 0))?;
        }
        Ok(())
    }

    /// Show the unit's version, `state`, FINDA and the polled registers.
    pub fn status(&mut self, state: &Response) -> Details {
        let mut details = Details::new();
        if let Some(((major, minor, revision), build)) = self.console.version() {
            let version = format!("{major}.{minor}.{revision}");
            self.console
                .say(&format!("unit firmware: {version}, build {build}"));
            details.insert("version".into(), version.into());
            details.insert("build".into(), build.into());
        }
        self.console.say(&format!("state (Q0): {}", state_text(state)));
        details.extend(state_details(state));
        let finda = self.printer.finda();
        let seen = if finda { "filament present" } else { "no filament" };
        self.console.say(&format!("hub filament sensor (FINDA): {seen}"));
        details.insert("finda".into(), finda.into());
        self.console.say("polled registers:");
        let mut registers = Vec::new();
        for &address in self.printer.polled_registers() {
            let Some(value) = self.printer.polled(address) else {
                self.console.say(&format!("  register 0x{address:02x}: not read"));
                continue;
            };
            let answer = Response::read(&Request::new(RequestCode::Read, address), value);
            self.console.say(&format!("  {}", response_meaning(&answer)));
            registers.push(json!({
                "address": address,
                "name": register_name(address),
                "value": value,
            }));
        }
        details.insert("registers".into(), registers.into());
        details.extend(self.lanes_status());
        details
    }

    /// `X<value>`, then connect again; show the first `Q0` answer.
    pub fn reset(&mut self, value: u8) -> Result<Details, Failure> {
        let state = self
            .printer
            .reset(&mut self.console, value)
            .map_err(|error| self.failure(error))?;
        self.console
            .say(&format!("after the reset, Q0: {}", state_text(&state)));
        Ok(state_details(&state))
    }

    /// A request that is not a command (`R`, `W`, `B`): its answer, or a failure when the unit
    /// refuses it.
    pub fn ask(&mut self, request: Request) -> Result<Details, Failure> {
        let answer = self
            .printer
            .request(&mut self.console, request)
            .map_err(|error| self.failure(error))?;
        let label = request_label(&request);
        let what = request_meaning(&request);
        if (answer.code, answer.value) != (request.code, request.value) {
            let got = response_label(&answer);
            return Err(Failure::new(format!("{label} ({what}): unexpected answer {got}")));
        }
        if answer.param != ParamCode::Accepted {
            let said = response_meaning(&answer);
            let mut message = format!("{label} ({what}): {said} by the unit");
            if request.code == RequestCode::Write {
                let why = self.why_refused(request.value, request.value2)?;
                message.push_str(&format!(": {why}"));
            }
            return Err(Failure::new(message));
        }
        let meaning = match answer.param_value {
            Some(_) => response_meaning(&answer),
            None => format!("{what}: accepted"),
        };
        self.console.say(&meaning);
        let mut details = Details::new();
        details.insert("request".into(), label.into());
        details.insert("meaning".into(), meaning.into());
        if let Some(value) = answer.param_value {
            details.insert("value".into(), value.into());
        }
        Ok(details)
    }

    /// Print the final JSON `result` line for `action` and stop the spinner.
    pub fn finish(&mut self, action: &'static str, result: &Result<Details, Failure>) {
        let (ok, details) = match result {
            Ok(details) => (true, details.clone()),
            Err(failure) => (false, failure.details()),
        };
        self.console.close();
        self.console.emit(&JsonLine::Result { action, ok, details });
    }
}

/// The unit's state (a `Q0` answer) as JSON fields.
fn state_details(state: &Response) -> Details {
    let mut details = Details::new();
    details.insert("state".into(), response_label(state).into());
    details.insert("state_meaning".into(), response_meaning(state).into());
    details
}

/// Run `mmu printer`.
pub fn run(args: &PrinterArgs) -> Result<(), Box<dyn Error>> {
    let console = Console::new(args.json, args.verbose);
    if let Action::Soak(soak) = &args.action {
        return run_soak(args, soak, console);
    }
    let options = PrinterOptions {
        read_only: args.action.is_bench(),
        ..printer_options(args)
    };
    match (&args.port, args.sim) {
        (Some(port), false) => {
            let link = SerialLink::open(port, fsensor_source(args))?;
            let session = Session::new(link, options, console);
            // A real unit goes on without the tool; the simulator ends with it.
            let look = format!("`mmu printer --port {port} status` shows its state");
            stop_on_ctrl_c(&session.running, look, None);
            run_session(session, &args.action)
        }
        (None, true) => {
            let link = sim_link(&args.sim_options, personality(args))?;
            run_session(Session::new(link, options, console), &args.action)
        }
        _ => Err(usage(CHOOSE_THE_UNIT)),
    }
}

/// The usage mistake of naming no unit.
pub const CHOOSE_THE_UNIT: &str = "choose the unit: --port DEV (a real one) or --sim (the simulator)";

/// Connect, perform `action`, print the result line.
fn run_session<L: Target>(mut session: Session<L>, action: &Action) -> Result<(), Box<dyn Error>> {
    let result = perform(&mut session, action);
    session.finish(action.name(), &result);
    result.map(|_| ()).map_err(Into::into)
}

/// Connect, then do what `action` asks.
fn perform<L: Target>(session: &mut Session<L>, action: &Action) -> Result<Details, Failure> {
    let state = session.connect()?;
    use RequestCode::{Button, Home, Load, Read, Tool, Unload};
    match *action {
        Action::Status => Ok(session.status(&state)),
        Action::Tool { slot } => session.command(Request::new(Tool, slot)),
        Action::Load { slot } => session.command(Request::new(Load, slot)),
        Action::Unload => session.command(Request::new(Unload, 0)),
        Action::Eject { slot } => session.eject(slot),
        Action::Cut { slot } => session.cut(slot),
        Action::Home => session.command(Request::new(Home, 0)),
        Action::Reset { erase } => session.reset(if erase { 42 } else { 0 }),
        Action::Read { address } => session.ask(Request::new(Read, address)),
        Action::Write { address, value } => session.ask(Request::write(address, value)),
        Action::Button { button } => session.ask(Request::new(Button, button)),
        Action::Stats => session.stats(),
        Action::Settings(SettingsAction::Save { ref file }) => session.save_settings(file),
        Action::Settings(SettingsAction::Load { ref file }) => session.load_settings(file),
        Action::Soak(_) => Err(Failure::new("soak runs on its own simulator")),
    }
}

/// The printer's set-up: its personality and supported unit version, the rest as Prusa's
/// firmware has it.
fn printer_options(args: &PrinterArgs) -> PrinterOptions {
    let defaults = PrinterOptions::of(personality(args));
    PrinterOptions {
        version: args.expect_version.unwrap_or(defaults.version),
        spool_join: args.spool_join,
        ..defaults
    }
}

/// The printer played (`--printer`, else the default).
fn personality(args: &PrinterArgs) -> Personality {
    args.printer.unwrap_or_default()
}

/// `buddy-6.5`, `buddy-6.4` or `mk3s` (also for `mmu sim --printer`).
pub(crate) fn parse_personality(text: &str) -> Result<Personality, String> {
    text.parse::<Personality>().map_err(|error| error.to_string())
}

/// The simulator of `--sim`, with its faults scheduled and its pace set. A fault naming a slot
/// the unit lacks is a usage mistake.
pub fn sim_link(args: &SimTargetArgs, printer: Personality) -> Result<SimLink, Box<dyn Error>> {
    for fault in &args.faults {
        fault
            .fault
            .check_slots(args.slots)
            .map_err(|error| usage(error.to_string()))?;
    }
    let mut sim = Sim::new(SimOptions {
        slots: args.slots,
        seed: args.seed,
        printer,
        extruder: args.extruder,
        ..SimOptions::for_hardware(args.hardware)
    })?;
    for fault in &args.faults {
        sim.schedule(*fault);
    }
    let mut link = SimLink::new(sim);
    link.set_time_scale(args.time_scale);
    Ok(link)
}

/// The printer's filament sensor for `--port`.
fn fsensor_source(args: &PrinterArgs) -> FsensorSource {
    match &args.fsensor_events {
        Some(path) => {
            if !path.exists() && !args.json {
                eprintln!(
                    "mmu: {} does not exist yet; the filament sensor reads 0 until it does",
                    path.display()
                );
            }
            FsensorSource::Events(EventsTail::new(path.clone()))
        }
        None => FsensorSource::Fixed(args.fsensor.unwrap_or(0)),
    }
}

/// `3.0.3` → (3, 0, 3).
pub(crate) fn parse_version(text: &str) -> Result<(u8, u8, u8), String> {
    let parts: Vec<Option<u8>> = text.split('.').map(|part| part.parse().ok()).collect();
    match parts.as_slice() {
        [Some(major), Some(minor), Some(revision)] => Ok((*major, *minor, *revision)),
        _ => Err(format!("{text:?} is not a version such as 3.0.3")),
    }
}

/// A pace: a finite number ≥ 0 (0: as fast as possible).
pub fn parse_time_scale(text: &str) -> Result<f64, String> {
    text.parse::<f64>()
        .ok()
        .filter(|k| k.is_finite() && *k >= 0.0)
        .ok_or_else(|| format!("{text:?} is not a time scale (a number ≥ 0; 0: as fast as possible)"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_and_versions() {
        assert_eq!(parse_u8("0x0b"), Ok(11));
        assert_eq!(parse_u8("30"), Ok(30));
        assert!(parse_u8("256").is_err());
        assert!(parse_u8("0x").is_err());
        assert!(parse_u8("-1").is_err());
        assert_eq!(parse_u16("0xffff"), Ok(65535));
        assert_eq!(parse_version("3.0.2"), Ok((3, 0, 2)));
        assert!(parse_version("3.0").is_err());
        assert!(parse_version("3.0.x").is_err());
        assert_eq!(parse_time_scale("0"), Ok(0.0));
        assert!(parse_time_scale("-1").is_err());
        assert!(parse_time_scale("inf").is_err());
    }
}
