//! `mmu console`: a person at a unit on the bench, or at the simulator, typing plain commands
//! (`t 1`, `read bowden`, `set bowden 410`, `retry`) instead of framed requests.
//!
//! The printer's protocol logic ([`mmu_sim::Printer`]: handshake, CRCs, `Q0` polling, `f`
//! reports, automatic Retry) does the talking over a [`BenchLink`]; this module turns commands
//! into requests and the answers into sentences, [`person`] asks the person where the unit needs
//! one, and [`calibrate`] measures the unit's distances and sensor levels. Commands come from a
//! terminal (history, tab completion) or a pipe (`printf 't 1\nquit\n' | mmu console --sim`);
//! a scripted session exits non-zero when one of its commands failed.

pub mod calibrate;
mod commands;
mod input;
mod link;
mod names;
mod person;
mod words;

use std::error::Error;
use std::path::PathBuf;

use mmu_protocol::{ButtonCode, ErrorCode, Family, ParamCode, Request, RequestCode, Response, ResultCode};
use mmu_sim::{Link, Outcome, Personality, Printer, PrinterOptions};

use crate::explain::{error_meaning, request_label, response_meaning};
use crate::printer_cli::console::{Console, state_text};
use crate::printer_cli::serial::{EventsTail, FsensorSource, SerialLink};
use crate::printer_cli::{SimTargetArgs, parse_version, sim_link};
use calibrate::{CalibrateOptions, Step};
use commands::{Command, HELP, parse};
use input::Input;
use link::{BenchLink, FsensorMode, Wire, sim_clear, sim_fault};
use person::{EjectDialog, Person};
use words::{done_text, fsensor_text, lane_text, unknown_register, value_note};

/// The unit a console or calibration talks to.
#[derive(Debug, clap::Args)]
pub struct TargetArgs {
    /// A real unit on this serial port, 115200 8N1: the USB-serial adapter wired to the unit's
    /// USART3 (PC10/PC11), e.g. /dev/ttyUSB0; or the path `mmu sim --pty` prints.
    #[arg(long, value_name = "DEV", conflicts_with = "sim")]
    pub port: Option<String>,
    /// The in-process simulator, in virtual time.
    #[arg(long)]
    pub sim: bool,
    /// The simulated unit (--sim only).
    #[command(flatten)]
    pub sim_options: SimTargetArgs,
    /// The printer's filament sensor follows the events file `mmu sim --events PATH` writes
    /// (--port only; else it reads 0 until `fsensor on`).
    #[arg(long, value_name = "PATH", requires = "port")]
    pub fsensor_events: Option<PathBuf>,
    /// The unit firmware version to expect; S0..S2 must answer it (3.0.2 for a unit set up for
    /// an MK3S).
    #[arg(long, value_name = "X.Y.Z", default_value = "3.0.4", value_parser = parse_version)]
    pub expect_version: (u8, u8, u8),
    /// Show every frame sent (`>`) and received (`<`).
    #[arg(short, long)]
    pub verbose: bool,
}

/// `mmu calibrate` options.
#[derive(Debug, clap::Args)]
pub struct CalibrateArgs {
    /// The unit.
    #[command(flatten)]
    pub target: TargetArgs,
    /// What to calibrate.
    #[arg(value_enum, default_value_t = Step::All)]
    pub step: Step,
    /// The slot whose filament measures the Bowden tube.
    #[arg(long, value_name = "K", default_value_t = 0)]
    pub slot: u8,
    /// The real distance from the hub sensor to each slot sensor, mm (95 on the reference unit).
    #[arg(long, value_name = "MM", default_value_t = calibrate::SLOT_TO_HUB_MM)]
    pub slot_to_hub_mm: f64,
    /// The longest feed while searching for the printer's filament sensor, mm.
    #[arg(long, value_name = "MM", default_value_t = calibrate::MAX_BOWDEN_MM)]
    pub max_bowden_mm: u16,
    /// The distance from the hub sensor back to where the slot paths join, mm: sets the park
    /// distance (that plus a margin).
    #[arg(long, value_name = "MM")]
    pub merge_mm: Option<u16>,
}

/// `mmu console` options.
#[derive(Debug, clap::Args)]
#[command(after_long_help = HELP)]
pub struct ConsoleArgs {
    /// The unit.
    #[command(flatten)]
    pub target: TargetArgs,
}

/// A unit on the bench with the person at it. See the [module documentation](self).
pub struct Bench {
    printer: Printer<BenchLink>,
    person: Person,
    slots: u8,
    /// The printer's filament sensor follows a `mmu sim --events` file.
    fsensor_events: bool,
}

impl Bench {
    /// The unit of `target`, not yet connected; answers come from `input`.
    pub fn open(target: &TargetArgs, input: Input) -> Result<Bench, Box<dyn Error>> {
        let wire = match (&target.port, target.sim) {
            (Some(port), false) => {
                let fsensor = match &target.fsensor_events {
                    Some(path) => FsensorSource::Events(EventsTail::new(path.clone())),
                    None => FsensorSource::Fixed(0),
                };
                Wire::Serial(SerialLink::open(port, fsensor)?)
            }
            (None, true) => Wire::Sim(Box::new(sim_link(&target.sim_options, Personality::default())?)),
            _ => return Err(crate::usage::usage(crate::printer_cli::CHOOSE_THE_UNIT)),
        };
        let options = PrinterOptions {
            version: target.expect_version,
            ..PrinterOptions::default()
        };
        let mut bench = Bench::on_wire(wire, options, input, target.verbose);
        bench.fsensor_events = target.fsensor_events.is_some();
        Ok(bench)
    }

    /// The unit behind `wire`, not yet connected.
    fn on_wire(wire: Wire, options: PrinterOptions, input: Input, verbose: bool) -> Bench {
        Bench {
            printer: Printer::new(BenchLink::new(wire), options),
            person: Person {
                display: Console::new(false, verbose),
                input,
                eject: EjectDialog::TakeOut,
                quit: false,
                // MK3S firmware expects 3.0.2 (3.13.3, 3.14.0) or 3.0.3 (3.14.1); Buddy 3.0.3 or 3.0.4.
                family: if options.version.2 == 2 {
                    Family::Mk3s
                } else {
                    Family::Buddy
                },
            },
            slots: 0,
            fsensor_events: false,
        }
    }

    /// Handshake, learn the slot count, and say what state the unit is in.
    pub fn connect(&mut self) -> Result<(), String> {
        let state = self
            .printer
            .connect(&mut self.person)
            .map_err(|e| e.to_string())?;
        self.slots = self
            .read(0x40)
            .ok()
            .and_then(|n| u8::try_from(n).ok())
            .unwrap_or(0);
        self.describe_state(&state);
        Ok(())
    }

    /// A line for the person.
    pub fn say(&self, text: &str) {
        self.person.display.say(text);
    }

    /// The unit's slots.
    pub fn slots(&self) -> u8 {
        self.slots
    }

    /// The link, to play the user on the simulator.
    fn link(&mut self) -> &mut BenchLink {
        self.printer.link_mut()
    }

    /// Read register `address`.
    pub fn read(&mut self, address: u8) -> Result<u16, String> {
        let answer = self.request(Request::new(RequestCode::Read, address))?;
        match (answer.param, answer.param_value) {
            (ParamCode::Accepted, Some(value)) => Ok(value),
            _ => Err(format!(
                "the unit has no register {}",
                self.register_text(address)
            )),
        }
    }

    /// Write `value` to register `address` (the unit saves its settings at once).
    pub fn write(&mut self, address: u8, value: u16) -> Result<(), String> {
        let answer = self.request(Request::write(address, value))?;
        if answer.param == ParamCode::Accepted {
            Ok(())
        } else {
            Err(format!(
                "the unit refused {} = {value}: the value is out of its range",
                self.register_text(address)
            ))
        }
    }

    /// One request that is not a command, and its answer.
    fn request(&mut self, request: Request) -> Result<Response, String> {
        self.printer
            .request(&mut self.person, request)
            .map_err(|e| e.to_string())
    }

    /// Run a command to its end; an error the person gave up on is a failure (the unit waits).
    pub fn command(&mut self, request: Request) -> Result<(), String> {
        let outcome = self
            .printer
            .command(&mut self.person, request)
            .map_err(|e| e.to_string())?;
        self.outcome(request, outcome)
    }

    /// Say how a command ended.
    fn outcome(&mut self, request: Request, outcome: Outcome) -> Result<(), String> {
        let label = request_label(&request);
        match outcome {
            Outcome::Finished(ResultCode::OK) => {
                self.say(&done_text(&request));
                Ok(())
            }
            Outcome::Finished(result) => Err(format!("{label} ended with result {}", result.0)),
            Outcome::Rejected => Err(format!(
                "{label} refused: the unit is busy with another command or waits on an error (status says which)"
            )),
            Outcome::GaveUp(ErrorCode::INVALID_TOOL) => Err(format!(
                "{label} refused: the unit has no slot {} (it has {})",
                request.value, self.slots
            )),
            Outcome::GaveUp(error) => Err(format!(
                "{label} stopped on {}: the unit waits; fix it, then `retry`",
                error_meaning(error)
            )),
        }
    }

    /// Press Retry (B1) and follow the command the unit resumes.
    fn retry(&mut self, button: ButtonCode) -> Result<(), String> {
        let answer = self.request(Request::new(RequestCode::Button, button.0))?;
        if answer.param != ParamCode::Accepted {
            return Err(format!("the unit refused button {}", button.0));
        }
        let state = self.request(Request::new(RequestCode::Query, 0))?;
        let request = Request::new(state.code, state.value);
        match state.param {
            ParamCode::Processing | ParamCode::Error if state.code.is_command() => {
                let outcome = self
                    .printer
                    .follow(&mut self.person, request)
                    .map_err(|e| e.to_string())?;
                self.outcome(request, outcome)
            }
            _ => {
                self.say(&format!(
                    "button {} sent; the unit is at rest: {}",
                    button.0,
                    state_text(&state)
                ));
                Ok(())
            }
        }
    }

    /// `bowden_mm (0x22)`, or `register 0x99` for one the table does not know.
    fn register_text(&self, address: u8) -> String {
        match names::name(address, self.slots) {
            Some(name) => format!("{name} (0x{address:02x})"),
            None => format!("register 0x{address:02x}"),
        }
    }

    /// Say what the unit's `Q0` answer `state` means.
    fn describe_state(&self, state: &Response) {
        let words = match state.param {
            ParamCode::Finished => "at rest, ready for a command".to_string(),
            ParamCode::Processing => format!(
                "busy with {}",
                request_label(&Request::new(state.code, state.value))
            ),
            ParamCode::Error => format!(
                "waiting on an error under {}: {} (fix it, then `retry`)",
                request_label(&Request::new(state.code, state.value)),
                response_meaning(state)
            ),
            _ => response_meaning(state),
        };
        self.say(&format!("the unit is {words}  [{}]", state_text(state)));
    }

    /// `status`: the unit's state, its slots, the sensors and the settings calibration sets.
    fn status(&mut self) -> Result<(), String> {
        let state = self.request(Request::new(RequestCode::Query, 0))?;
        self.describe_state(&state);
        let hub = self.read(0x08)?;
        self.say(&format!(
            "hub sensor: {}",
            if hub != 0 {
                "filament present"
            } else {
                "no filament"
            }
        ));
        for slot in 0..self.slots {
            let lane = self.read(0xb8 + slot)?;
            self.say(&format!("slot {slot}: {}", lane_text(lane)));
        }
        let fsensor = self.link().fsensor();
        let is_sim = self.link().sim().is_some();
        let source = match self.link().fsensor {
            FsensorMode::Auto if is_sim => "the simulated printer's",
            FsensorMode::Auto => "from --fsensor-events, or 0",
            FsensorMode::Fixed(_) => "set by hand",
        };
        self.say(&format!(
            "printer's filament sensor: {} ({source})",
            fsensor_text(fsensor)
        ));
        for (address, what) in [
            (0x22, "Bowden length, mm"),
            (0x41, "park distance, mm"),
            (0x42, "mm per motor revolution × 100"),
        ] {
            let value = self.read(address)?;
            self.say(&format!("{what}: {value}"));
        }
        Ok(())
    }

    /// The printer's filament sensor from now on; the unit is told at once.
    fn set_fsensor(&mut self, mode: FsensorMode) -> Result<(), String> {
        self.link().fsensor = mode;
        let state = self.link().fsensor();
        self.request(Request::new(RequestCode::FilamentSensor, state))?;
        self.say(&format!(
            "printer's filament sensor: {} (f{state} sent)",
            fsensor_text(state)
        ));
        Ok(())
    }

    /// Carry out one command.
    fn run(&mut self, command: Command) -> Result<(), String> {
        use RequestCode::{Cut, Eject, Home, Load, Tool, Unload};
        match command {
            Command::Tool(slot) => self.command(Request::new(Tool, slot)),
            Command::Load(slot) => self.command(Request::new(Load, slot)),
            Command::Unload => self.command(Request::new(Unload, 0)),
            Command::Eject(slot) => {
                self.unload_first()?;
                self.command(Request::new(Eject, slot))
            }
            Command::Cut(slot) => {
                self.unload_first()?;
                self.command(Request::new(Cut, slot))
            }
            Command::Home => self.command(Request::new(Home, 0)),
            Command::Read(name) => {
                let addresses = names::resolve_all(&name, self.slots);
                if addresses.is_empty() {
                    return Err(unknown_register(&name));
                }
                for address in addresses {
                    let value = self.read(address)?;
                    let text = format!(
                        "{} = {value}{}",
                        self.register_text(address),
                        value_note(address, value)
                    );
                    self.say(&text);
                }
                Ok(())
            }
            Command::Write(name, value) => {
                let address = names::resolve(&name, self.slots).ok_or_else(|| unknown_register(&name))?;
                if names::writable(address, self.slots) == Some(false) {
                    return Err(format!("{} is read only", self.register_text(address)));
                }
                self.write(address, value)?;
                let text = format!(
                    "{} = {value}: accepted, the unit saves it",
                    self.register_text(address)
                );
                self.say(&text);
                Ok(())
            }
            Command::Retry => self.retry(ButtonCode::MIDDLE),
            Command::Button(button) => self.retry(ButtonCode(button)),
            Command::Status => self.status(),
            Command::Fsensor(mode) => self.set_fsensor(mode),
            Command::Calibrate(step, slot) => {
                let options = CalibrateOptions {
                    slot: slot.unwrap_or(0),
                    ..CalibrateOptions::default()
                };
                calibrate::run(self, step, &options).map(|_| ())
            }
            Command::SimFault(spec) => {
                let text = sim_fault(self.link(), &spec);
                self.say(&text);
                Ok(())
            }
            Command::SimClear => {
                let text = sim_clear(self.link());
                self.say(&text);
                Ok(())
            }
            Command::Wait(seconds) => {
                self.link()
                    .pause(u64::from(seconds) * 1000)
                    .map_err(|e| e.to_string())?;
                let state = self.request(Request::new(RequestCode::Query, 0))?;
                self.describe_state(&state);
                Ok(())
            }
            Command::Help => {
                self.say(HELP);
                Ok(())
            }
            Command::Quit => Ok(()),
        }
    }

    /// As the printer does before `E`/`K`: unload when the hub sensor sees filament.
    fn unload_first(&mut self) -> Result<(), String> {
        if self.read(0x08)? != 0 {
            self.say("the hub sensor sees filament: unloading first");
            self.command(Request::new(RequestCode::Unload, 0))?;
        }
        Ok(())
    }
}

/// Run `mmu calibrate`: connect, calibrate, print what was saved.
pub fn run_calibrate(args: &CalibrateArgs) -> Result<(), Box<dyn Error>> {
    if !(1.0..=1000.0).contains(&args.slot_to_hub_mm) {
        return Err("--slot-to-hub-mm must be between 1 and 1000".into());
    }
    let input = Input::from_stdin(args.target.sim_options.slots.try_into().unwrap_or(5));
    let mut bench = Bench::open(&args.target, input)?;
    bench.connect()?;
    let options = CalibrateOptions {
        slot: args.slot,
        slot_to_hub_mm: args.slot_to_hub_mm,
        max_bowden_mm: args.max_bowden_mm,
        merge_mm: args.merge_mm,
    };
    let result = calibrate::run(&mut bench, args.step, &options);
    bench.person.display.close();
    result.map(|_| ()).map_err(Into::into)
}

/// Run `mmu console`.
pub fn run(args: &ConsoleArgs) -> Result<(), Box<dyn Error>> {
    let input = Input::from_stdin(args.target.sim_options.slots.try_into().unwrap_or(5));
    let scripted = input.is_script();
    let mut bench = Bench::open(&args.target, input)?;
    bench.connect()?;
    if !scripted {
        bench.say("type help for the commands, quit to leave");
    }
    let mut failed = 0u32;
    while !bench.person.quit {
        let Some(line) = bench.person.line("mmu> ") else {
            break;
        };
        let result = match parse(&line) {
            Ok(None) => continue,
            Ok(Some(Command::Quit)) => break,
            Ok(Some(command)) => bench.run(command),
            Err(error) => Err(error),
        };
        if let Err(error) = result {
            bench.person.display.close();
            bench.say(&format!("failed: {error}"));
            failed += 1;
        }
    }
    bench.person.display.close();
    if scripted && failed > 0 {
        return Err(format!("{failed} command(s) of the script failed").into());
    }
    Ok(())
}
