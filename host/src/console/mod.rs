//! `mmu console`: a person at a unit on the bench, or at the simulator, typing plain commands
//! (`t 1`, `read bowden`, `set bowden 410`, `retry`) instead of framed requests.
//!
//! The printer's protocol logic ([`mmu_sim::Printer`]: handshake, CRCs, `Q0` polling, `f`
//! reports, automatic Retry) does the talking over a [`BenchLink`]; this module turns commands
//! into requests and the answers into sentences, [`person`] asks the person where the unit needs
//! one, and [`calibrate`] measures the unit's distances and sensor levels. Commands come from a
//! terminal (history, tab completion) or a pipe (`printf 't 1\nquit\n' | mmu console --sim`);
//! a scripted session exits non-zero when one of its commands failed.
//!
//! For the bench: [`motor`] tests a slot's motor and Hall sensor, [`pc_files`] keeps the slot map
//! (material, colour) and the statistics' starting point on this PC. A command is not sent while
//! the unit waits on an earlier command's error (it would fail with that error and be blamed for
//! it); Ctrl-C while the unit works says what it was doing and exits 130.

pub mod calibrate;
mod commands;
mod input;
mod link;
pub mod motor;
mod names;
pub mod pc_files;
mod person;
pub(crate) mod refused;
mod words;

use std::error::Error;
use std::path::PathBuf;

use mmu_protocol::{ButtonCode, ErrorCode, Family, ParamCode, Request, RequestCode, Response, ResultCode};
use mmu_sim::{Link, Outcome, Personality, Printer, PrinterOptions};

use crate::explain::{error_meaning, request_label, request_meaning, response_meaning};
use crate::printer_cli::console::{Console, state_text};
use crate::printer_cli::serial::{EventsTail, FsensorSource, SerialLink};
use crate::printer_cli::{SimTargetArgs, parse_version, sim_link};
use crate::usage::{Running, stop_on_ctrl_c};
use calibrate::{CalibrateOptions, Step};
use commands::{Command, HELP, parse};
use input::Input;
use link::{BenchLink, FsensorMode, Wire, sim_clear, sim_fault};
use pc_files::{SlotMap, SlotNote, Stats};
use person::{EjectDialog, Person};
use words::{done_text, fsensor_text, lane_text, unknown_register, value_note};

/// The unit a console or calibration talks to.
#[derive(Debug, clap::Args)]
pub struct TargetArgs {
    /// A real unit on this serial port, 115200 8N1: the USB-serial adapter wired to the unit's
    /// USART1 (PB6/PB7; Pico: UART0, GP0/GP1), e.g. /dev/ttyUSB0; or the path `mmu sim --pty` prints.
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
    #[arg(long, value_name = "X.Y.Z", default_value = "3.0.3", value_parser = parse_version)]
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

/// `mmu motor` options.
#[derive(Debug, clap::Args)]
pub struct MotorArgs {
    /// The unit.
    #[command(flatten)]
    pub target: TargetArgs,
    /// The slot whose motor to test (0 is the first); it must hold filament.
    #[arg(value_parser = crate::codec_cli::parse_u8)]
    pub slot: u8,
}

/// `mmu slots` options.
#[derive(Debug, clap::Args)]
pub struct SlotsArgs {
    /// The unit, to show where each slot's filament is (not needed to note or forget a slot).
    #[command(flatten)]
    pub target: TargetArgs,
    /// Note or forget a slot's material and colour (without: show the map).
    #[command(subcommand)]
    pub change: Option<SlotChange>,
}

/// A change to the slot map.
#[derive(Debug, clap::Subcommand)]
pub enum SlotChange {
    /// Note what slot SLOT holds, e.g. `set 1 PETG red`.
    Set {
        /// The slot (0 is the first).
        #[arg(value_parser = crate::codec_cli::parse_u8)]
        slot: u8,
        /// PLA, PETG, ... (one word).
        material: String,
        /// red, #ff0000, ... (one word).
        colour: String,
    },
    /// Forget what slot SLOT holds.
    Clear {
        /// The slot.
        #[arg(value_parser = crate::codec_cli::parse_u8)]
        slot: u8,
    },
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
    /// The command the unit runs for the console, for Ctrl-C to name.
    running: Running,
    /// The statistics: kept in their file for a real unit, for the session with the simulator.
    stats: Stats,
    /// The person was told how the printer's sensor works on the bench.
    told_about_the_bench: bool,
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
        if bench.is_real_unit() {
            // A damaged statistics file must not keep the console from the unit.
            bench.stats = Stats::load().unwrap_or_else(|error| {
                eprintln!("mmu: the statistics start again: {error}");
                Stats::default()
            });
        }
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
            running: Running::default(),
            stats: Stats::default(),
            told_about_the_bench: false,
        }
    }

    /// A unit on a serial port (or `mmu sim --pty` behind one), not the in-process simulator.
    fn is_real_unit(&self) -> bool {
        self.printer.link().sim().is_none()
    }

    /// The printer's clock, ms.
    fn now_ms(&self) -> u64 {
        self.printer.link().now_ms()
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
            _ => Err(match names::name(address, self.slots) {
                Some(name) => format!("the unit refused to read {name} (0x{address:02x})"),
                None => format!("the unit has no register 0x{address:02x}"),
            }),
        }
    }

    /// Write `value` to register `address` (the unit saves its settings at once).
    pub fn write(&mut self, address: u8, value: u16) -> Result<(), String> {
        let answer = self.request(Request::write(address, value))?;
        if answer.param == ParamCode::Accepted {
            return Ok(());
        }
        let register = self.register_text(address);
        let why = refused::why_refused(address, value, self.slots, &mut |address| self.read(address).ok());
        Err(format!("the unit refused {register} = {value}: {why}"))
    }

    /// Refuse to send `request` while the unit waits on an error: it would accept the command
    /// and fail at once with that error, and the console would blame the new command for it.
    fn refuse_if_waiting(&mut self, request: &Request) -> Result<(), String> {
        let state = self.request(Request::new(RequestCode::Query, 0))?;
        // INVALID_TOOL holds nothing: the unit takes the next command as usual (the printer's
        // Stop print sends nothing to it).
        let invalid_tool = state.param_value == Some(ErrorCode::INVALID_TOOL.0);
        if state.param != ParamCode::Error || invalid_tool {
            return Ok(());
        }
        let holder = Request::new(state.code, state.value);
        Err(format!(
            "not sent: the unit still waits on {} from {} ({}); answer that first (`retry`, which is \
             also Continue; `button N`), then {}",
            response_meaning(&state),
            request_label(&holder),
            request_meaning(&holder),
            request_label(request)
        ))
    }

    /// One request that is not a command, and its answer.
    fn request(&mut self, request: Request) -> Result<Response, String> {
        self.printer
            .request(&mut self.person, request)
            .map_err(|e| e.to_string())
    }

    /// Run a command to its end; an error the person gave up on is a failure (the unit waits).
    pub fn command(&mut self, request: Request) -> Result<(), String> {
        self.command_saying(request, None)
    }

    /// Run a command to its end and say `done` (else what the command does) when it finished.
    fn command_saying(&mut self, request: Request, done: Option<String>) -> Result<(), String> {
        self.refuse_if_waiting(&request)?;
        let started = self.now_ms();
        self.set_running(Some(request_label(&request)));
        let outcome = self.printer.command(&mut self.person, request);
        self.set_running(None);
        let outcome = outcome.map_err(|e| e.to_string())?;
        if request.code == RequestCode::Tool && outcome == Outcome::Finished(ResultCode::OK) {
            self.timed_change(request.value, self.now_ms() - started);
        }
        self.outcome(request, outcome, done)
    }

    /// What Ctrl-C names as running.
    fn set_running(&self, what: Option<String>) {
        self.running.set(what);
    }

    /// Count a tool change to `slot` that took `ms` (kept in the statistics' file for a real unit).
    fn timed_change(&mut self, slot: u8, ms: u64) {
        self.stats.changes.push((slot, ms));
        self.say(&format!(
            "tool change to slot {slot}: {:.1} s",
            ms as f64 / 1000.0
        ));
        if self.is_real_unit()
            && let Err(error) = self.stats.save()
        {
            self.say(&format!("(the time is not kept: {error})"));
        }
    }

    /// Say how a command ended.
    fn outcome(&mut self, request: Request, outcome: Outcome, done: Option<String>) -> Result<(), String> {
        let label = request_label(&request);
        match outcome {
            Outcome::Finished(ResultCode::OK) => {
                self.say(&done.unwrap_or_else(|| done_text(&request)));
                Ok(())
            }
            Outcome::Finished(result) => Err(format!("{label} ended with result {}", result.0)),
            Outcome::FilamentChange(slot) => Err(format!(
                "{label}: the print stopped on the filament-change screen after slot {slot} ran out"
            )),
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
                self.set_running(Some(request_label(&request)));
                let outcome = self.printer.follow(&mut self.person, request);
                self.set_running(None);
                let outcome = outcome.map_err(|e| e.to_string())?;
                self.outcome(request, outcome, None)
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
            let text = self.slot_text(slot)?;
            self.say(&format!("slot {slot}: {text}"));
        }
        self.lanes_status();
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

    /// Each slot's filament left (with its uncertainty) and health, and the warnings.
    fn lanes_status(&mut self) {
        let slots = self.slots;
        match crate::lanes_text::read_lanes(slots, |address| self.read(address)) {
            Ok((lanes, warnings)) => {
                for lane in &lanes {
                    self.say(&lane.left_text());
                }
                for lane in &lanes {
                    self.say(&lane.health_text());
                }
                for line in crate::lanes_text::warning_lines(warnings, slots) {
                    self.say(&line);
                }
            }
            Err(_) => {
                self.say("filament left and lane health: not reported by this unit (an earlier firmware)")
            }
        }
    }

    /// Where slot `slot`'s filament is, in words. The unit's lane register says 0 both for an
    /// empty slot and for one whose tip it does not know (after `X42`, or a filament pushed in by
    /// hand): its slot sensor tells them apart.
    fn slot_text(&mut self, slot: u8) -> Result<String, String> {
        let lane = self.read(0xb8 + slot)?;
        if lane != 0 {
            return Ok(lane_text(lane).to_string());
        }
        let sensor = 3 + 2 * slot;
        if self.read(0x50)? & (1 << sensor) != 0 {
            return Ok("unknown: its slot sensor is stuck at a rail (check its wiring: mmu sensors)".into());
        }
        let (filtered, on, off) = (
            self.read(0x70 + sensor)?,
            self.read(0x90 + sensor)?,
            self.read(0xa0 + sensor)?,
        );
        Ok(if filtered >= on {
            format!("unknown: filament at the slot sensor, its tip not yet found (`load {slot}` preloads it)")
        } else if filtered <= off {
            "empty: no filament at the slot sensor".to_string()
        } else {
            format!("unknown: the slot sensor reads {filtered}, between its thresholds ({off} off, {on} on)")
        })
    }

    /// `slots`: each slot's material and colour (this PC's slot map) and where its filament is.
    fn slots_table(&mut self) -> Result<(), String> {
        let map = SlotMap::load()?;
        for slot in 0..self.slots {
            let note = map.get(slot).map_or("(not noted)".to_string(), |n| {
                format!("{} {}", n.material, n.colour)
            });
            let text = self.slot_text(slot)?;
            self.say(&format!("slot {slot}: {note:<16} {text}"));
        }
        Ok(())
    }

    /// `slot SLOT MATERIAL COLOUR` / `slot SLOT clear`.
    fn note_slot(&mut self, slot: u8, note: Option<(String, String)>) -> Result<(), String> {
        if slot >= self.slots {
            return Err(format!("the unit has no slot {slot}: it has {}", self.slots));
        }
        let mut map = SlotMap::load()?;
        let words = match &note {
            Some((material, colour)) => format!("slot {slot}: {material} {colour}"),
            None => format!("slot {slot}: forgotten"),
        };
        map.set(slot, note.map(|(material, colour)| SlotNote { material, colour }));
        let path = map.save()?;
        self.say(&format!("{words} (kept in {})", path.display()));
        Ok(())
    }

    /// `stats` / `stats reset`.
    fn statistics(&mut self, reset: bool) -> Result<(), String> {
        let mut now = std::collections::BTreeMap::new();
        for slot in 0..self.slots {
            now.insert(
                slot,
                [
                    self.read(0xc0 + slot)?,
                    self.read(0xc8 + slot)?,
                    self.read(0xe0 + slot)?,
                ],
            );
        }
        if reset {
            self.stats = Stats {
                baseline: now,
                changes: Vec::new(),
            };
            self.say("statistics: counting from now");
        } else {
            for (slot, counters) in now {
                let line = self.stats.slot_line(slot, counters);
                self.say(&line);
            }
        }
        if self.is_real_unit() {
            let path = self.stats.save()?;
            if reset {
                self.say(&format!("(kept in {})", path.display()));
            }
        }
        Ok(())
    }

    /// Before a tool change on the bench: how the printer's filament sensor works there.
    fn tell_about_the_bench(&mut self) {
        let on_the_bench = self.is_real_unit() && !self.fsensor_events;
        if !on_the_bench || self.told_about_the_bench {
            return;
        }
        self.told_about_the_bench = true;
        self.say(
            "on the bench there is no printer: its filament sensor is yours (`fsensor`). The tool change stops \
             at FeedingToFSensor on FSENSOR_DIDNT_SWITCH_ON unless the sensor reads filament: when the tip \
             comes out of the Bowden tube, answer the error prompt with `fsensor on`, then `retry`. The last \
             push needs an extruder to pull the filament in: without one it ends on that error again.",
        );
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
            Command::Tool(slot) => {
                self.tell_about_the_bench();
                self.command(Request::new(Tool, slot))
            }
            Command::Load(slot) => self.command(Request::new(Load, slot)),
            Command::Unload => {
                let done = if self.anything_loaded()? {
                    None
                } else {
                    Some(
                        "nothing was loaded: the unit had nothing to unload, every slot is as it was"
                            .to_string(),
                    )
                };
                self.command_saying(Request::new(Unload, 0), done)
            }
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
            Command::Motor(slot) => {
                let report = motor::run(self, slot)?;
                for line in report.lines() {
                    self.say(&line);
                }
                if report.passed() {
                    Ok(())
                } else {
                    Err(format!("slot {slot}'s motor test did not pass"))
                }
            }
            Command::Slots => self.slots_table(),
            Command::SlotNote(slot, note) => self.note_slot(slot, note),
            Command::Stats(reset) => self.statistics(reset),
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

    /// Whether a filament is past its park position: a slot's lane says so, or the hub sensor
    /// sees one.
    fn anything_loaded(&mut self) -> Result<bool, String> {
        for slot in 0..self.slots {
            if matches!(self.read(0xb8 + slot)?, 2 | 4 | 8) {
                return Ok(true);
            }
        }
        Ok(self.read(0x08)? != 0)
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

/// How to see where a command stopped by Ctrl-C ends, for [`stop_on_ctrl_c`].
const LOOK_AGAIN: &str = "`mmu console` again and `status` tell where it ended";

/// What a Bowden measurement stopped by Ctrl-C leaves behind.
const CALIBRATION_LEFT: &str = "a Bowden measurement stopped half-way leaves bowden_mm (0x22), the printer-sensor \
     search (0x48) and the slow-down distance (0x4a) at its own values: set them back (`set`) or calibrate again";

/// `--merge-mm`: the park distance it makes (the join plus a margin) must be a distance the unit
/// takes (register 0x41) and leave the parked tip in front of the slot sensor, or the slot would
/// read empty.
fn check_merge(merge_mm: u16, slot_to_hub_mm: f64) -> Result<(), String> {
    let park = u32::from(merge_mm) + u32::from(calibrate::PARK_MARGIN_MM);
    let furthest = slot_to_hub_mm - f64::from(calibrate::PARK_MARGIN_MM);
    if park > 200 || f64::from(park) >= furthest {
        return Err(format!(
            "--merge-mm {merge_mm}: the slots would park {park} mm before the hub sensor, behind their slot \
             sensors ({slot_to_hub_mm} mm before it, --slot-to-hub-mm): measure from the hub sensor back to \
             where the slot paths join (a few mm to a few tens of mm)"
        ));
    }
    Ok(())
}

/// Run `mmu calibrate`: connect, calibrate, print what was saved.
pub fn run_calibrate(args: &CalibrateArgs) -> Result<(), Box<dyn Error>> {
    if !(1.0..=1000.0).contains(&args.slot_to_hub_mm) {
        return Err(crate::usage::usage("--slot-to-hub-mm must be between 1 and 1000"));
    }
    if let Some(merge_mm) = args.merge_mm {
        check_merge(merge_mm, args.slot_to_hub_mm).map_err(crate::usage::usage)?;
    }
    let input = Input::from_stdin(args.target.sim_options.slots.try_into().unwrap_or(5));
    let mut bench = Bench::open(&args.target, input)?;
    bench.connect()?;
    if args.slot >= bench.slots() {
        return Err(crate::usage::usage(format!(
            "--slot {}: the unit has {} slots (0-{})",
            args.slot,
            bench.slots(),
            bench.slots().saturating_sub(1)
        )));
    }
    stop_on_ctrl_c(&bench.running, LOOK_AGAIN.into(), Some(CALIBRATION_LEFT));
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

/// The most slots a unit can have (the simulator's limit; the protocol's slot numbers go to 4).
const MAX_SLOTS: u8 = 5;

/// Run `mmu motor`: connect, test the slot's motor, say what was seen. Fails (exit 1) when the
/// test does not pass.
pub fn run_motor(args: &MotorArgs) -> Result<(), Box<dyn Error>> {
    let input = Input::from_stdin(args.target.sim_options.slots.try_into().unwrap_or(MAX_SLOTS));
    let mut bench = Bench::open(&args.target, input)?;
    bench.connect()?;
    if args.slot >= bench.slots() {
        return Err(crate::usage::usage(format!(
            "slot {}: the unit has {} slots (0-{})",
            args.slot,
            bench.slots(),
            bench.slots().saturating_sub(1)
        )));
    }
    stop_on_ctrl_c(&bench.running, LOOK_AGAIN.into(), None);
    bench.set_running(Some(format!("the motor test of slot {} (a preload)", args.slot)));
    let result = bench.run(Command::Motor(args.slot));
    bench.person.display.close();
    result.map_err(Into::into)
}

/// Run `mmu slots`: show the map with the unit's lanes, or note or forget a slot (no unit needed).
pub fn run_slots(args: &SlotsArgs) -> Result<(), Box<dyn Error>> {
    match &args.change {
        Some(change) => {
            let (slot, note) = match change {
                SlotChange::Set {
                    slot,
                    material,
                    colour,
                } => (
                    *slot,
                    Some(SlotNote {
                        material: material.clone(),
                        colour: colour.clone(),
                    }),
                ),
                SlotChange::Clear { slot } => (*slot, None),
            };
            if slot >= MAX_SLOTS {
                return Err(crate::usage::usage(format!(
                    "slot {slot}: a unit has at most {MAX_SLOTS} slots (0-{})",
                    MAX_SLOTS - 1
                )));
            }
            let mut map = SlotMap::load()?;
            let words = match &note {
                Some(note) => format!("slot {slot}: {} {}", note.material, note.colour),
                None => format!("slot {slot}: forgotten"),
            };
            map.set(slot, note);
            let path = map.save()?;
            println!("{words} (kept in {})", path.display());
            Ok(())
        }
        None => {
            let input = Input::from_stdin(args.target.sim_options.slots.try_into().unwrap_or(MAX_SLOTS));
            let mut bench = Bench::open(&args.target, input)?;
            bench.connect()?;
            let result = bench.slots_table();
            bench.person.display.close();
            result.map_err(Into::into)
        }
    }
}

/// Run `mmu console`.
pub fn run(args: &ConsoleArgs) -> Result<(), Box<dyn Error>> {
    let input = Input::from_stdin(args.target.sim_options.slots.try_into().unwrap_or(5));
    let scripted = input.is_script();
    let mut bench = Bench::open(&args.target, input)?;
    bench.connect()?;
    stop_on_ctrl_c(&bench.running, LOOK_AGAIN.into(), None);
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
