//! The simulated unit on its wire: the unchanged unit logic stepped against the physical model,
//! with the printer's mechanics around it and the harness faults (UART, power) in between.
//!
//! A [`Sim`] takes the bytes a printer sends and returns the bytes the unit answers, one
//! millisecond of virtual time per [`Sim::step`]. The printer's *mechanics* (its extruder and
//! filament sensor) live here too, because no printer-side program can move them over the wire:
//! they react to the traffic the way the firmware of the printer played does (spec §5.7), by
//! watching the frames go by ([`crate::mechanics`], [`SimOptions::printer`]). The printer's
//! *protocol logic* (handshake, polling, retries) is the client's business; see
//! [`crate::printer`].

use mmu_firmware::profile::{MotionSensor, Profile, THESIS, TensionAt};
use mmu_firmware::runner::Status;
use mmu_firmware::{Config, Direction, Instant, MotorCommand};
use mmu_model::{Model, ModelConfig, Rng};
use mmu_protocol::RequestCode;

use crate::event::{Event, EventKind, FaultAction};
use crate::fault::{ScheduledFault, SimFault, SimFaultKind};
use crate::geometry::ExtruderGeometry;
use crate::logic::{StoreFlash, UnitLogic, new_logic};
use crate::mechanics::Mechanics;
pub use crate::mechanics::{
    COFEED_MM, LOAD_TO_NOZZLE_MM, LOAD_TO_NOZZLE_MM_S, PRINTER_UNLOAD_MM, PRINTER_UNLOAD_MM_S, UNLOAD_HELP_MM,
};
use crate::personality::Personality;

/// Slot motion is reported at most this often, ms.
const SLOT_REPORT_MS: u64 = 100;

/// A command's state as events and notes show it: `running FeedingToFinda`,
/// `error FINDA_DIDNT_SWITCH_ON` or `finished`.
pub fn status_text(status: Status) -> String {
    match status {
        Status::Running(progress) => format!("running {progress}"),
        Status::Failed(error) => format!("error {error}"),
        Status::Finished => String::from("finished"),
    }
}

/// What the simulator is made of.
#[derive(Debug, Clone)]
pub struct SimOptions {
    /// Slots, 1 to 5.
    pub slots: usize,
    /// Seed of every random draw (sensor noise, UART faults).
    pub seed: u64,
    /// The unit logic's configuration.
    pub unit: Config,
    /// Geometry and physics.
    pub model: ModelConfig,
    /// How fast the printer pulls filament while it prints after a tool change, mm/s (0: it does
    /// not print).
    pub print_mm_s: f32,
    /// How long the unit takes to boot after a reset or power-up, ms.
    pub boot_ms: u32,
    /// The printer whose mechanics (its extruder around a tool change) are played.
    pub printer: Personality,
    /// Where the printer's extruder gears sit against its filament sensor; `None`: the
    /// printer's own ([`Personality::extruder`]). Whatever [`SimOptions::model`] says, its gears
    /// are placed this way against its sensor.
    pub extruder: Option<ExtruderGeometry>,
    /// What senses each lane: the unit runs on this profile and the model's sensors read as it
    /// says ([`SimOptions::for_hardware`] also takes its default settings).
    pub hardware: &'static Profile,
}

impl SimOptions {
    /// The default options on the hardware `profile`: its default settings and, for the model,
    /// its sensors and its distance per turn of the sensed shaft.
    pub fn for_hardware(profile: &'static Profile) -> SimOptions {
        SimOptions::default().on_hardware(profile)
    }

    /// The extruder geometry played: [`SimOptions::extruder`], else the printer's own.
    pub fn extruder(&self) -> ExtruderGeometry {
        self.extruder.unwrap_or(self.printer.extruder())
    }

    /// These options on the hardware `profile`: the unit's settings keep theirs but those that
    /// depend on the hardware ([`Config::on_profile`]).
    pub fn on_hardware(self, profile: &'static Profile) -> SimOptions {
        SimOptions {
            unit: self.unit.clone().on_profile(profile),
            hardware: profile,
            ..self
        }
    }
}

/// `model` with the sensors of `profile`: what each lane's motion sensor reads, the lanes' own
/// tension sensors, and the turn of the sensed shaft where the profile has its own.
pub fn model_for(profile: &Profile, model: &ModelConfig) -> ModelConfig {
    let mm_per_rev = match profile.motion {
        MotionSensor::HallWave => model.mm_per_rev,
        _ => f32::from(profile.mm_per_rev_centi) / 100.0,
    };
    ModelConfig {
        motion_sensor: profile.motion,
        lane_tension: profile.tension == TensionAt::Lane,
        mm_per_rev,
        ..model.clone()
    }
}

impl Default for SimOptions {
    fn default() -> Self {
        SimOptions {
            slots: 3,
            seed: 1,
            unit: Config::default(),
            model: ModelConfig::default(),
            print_mm_s: 1.0,
            boot_ms: 50,
            printer: Personality::default(),
            extruder: None,
            hardware: &THESIS,
        }
    }
}

/// Options the simulator cannot run with.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BadOptions(pub String);

impl std::fmt::Display for BadOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for BadOptions {}

/// A command the unit finished, as the simulator saw it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandRecord {
    /// The request.
    pub request: (RequestCode, u8),
    /// When the unit accepted it, ms of virtual time.
    pub started_ms: u64,
    /// When it finished, ms of virtual time.
    pub finished_ms: u64,
    /// Tip of the filament past the hub sensor when it started, mm (what an unload had to move).
    pub start_tip_mm: Option<f32>,
    /// Whether it stopped on an error on the way.
    pub had_error: bool,
}

/// A power cut in a phase of a command: `after_ms` after the unit first reports `progress`
/// while it runs a command with `code`, for `off_ms` ([`Sim::cut_power_during`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PhaseCut {
    /// The command's code (`T` for a tool change).
    pub code: RequestCode,
    /// The phase, by the progress code the unit reports in it.
    pub progress: mmu_protocol::ProgressCode,
    /// How long into the phase, ms.
    pub after_ms: u64,
    /// How long the unit stays unpowered, ms.
    pub off_ms: u32,
}

/// The simulated unit. See the [module documentation](self).
pub struct Sim {
    options: SimOptions,
    logic: Box<dyn UnitLogic>,
    model: Model,
    now_ms: u64,
    /// Virtual time of the unit's last boot: its clock starts at 0 there.
    boot_epoch_ms: u64,
    /// Unpowered or booting until then.
    off_until_ms: Option<u64>,
    rng: Rng,
    corrupt: f32,
    drop: f32,
    schedule: Vec<ScheduledFault>,
    printer: Mechanics,
    events: Vec<Event>,
    last_fsensor: u8,
    last_slot_report: Vec<(Option<f32>, u64)>,
    /// A power cut armed for the first step that writes the flash: its off time, and the bytes
    /// written before it was armed.
    cut_at_write: Option<(u32, u64)>,
    /// A power cut armed for a phase of a command ([`Sim::cut_power_during`]), and when the unit
    /// was first seen in it.
    cut_in_phase: Option<(PhaseCut, Option<u64>)>,
    /// Each slot's motor command as last reported.
    last_motors: Vec<MotorCommand>,
    last_command: ((RequestCode, u8), Status),
    running: Option<CommandRecord>,
    finished: Vec<CommandRecord>,
}

impl Sim {
    /// A unit just powered on, with every slot's filament parked and nothing loaded.
    pub fn new(options: SimOptions) -> Result<Sim, BadOptions> {
        let hardware = options.hardware;
        let logic = new_logic(
            options.slots,
            hardware,
            options.unit.clone(),
            StoreFlash::of_profile(hardware),
        )
        .ok_or_else(|| {
            BadOptions(format!(
                "the {} hardware has 1 to {} slots, not {}",
                hardware.name, hardware.max_slots, options.slots
            ))
        })?;
        Ok(Sim::with_unit(options, logic))
    }

    /// The unit `logic` (the host-built logic of [`Sim::new`], or a firmware image on an emulated
    /// chip: [`crate::firmware::FirmwareUnit`]) just powered on, with `options.slots` slots.
    pub fn with_unit(options: SimOptions, logic: Box<dyn UnitLogic>) -> Sim {
        let geometry = options
            .extruder()
            .apply(&model_for(options.hardware, &options.model));
        let model = Model::new(geometry, options.slots, options.seed);
        let printer = Mechanics::new(
            options.printer,
            f32::from(options.unit.extra_load_mm),
            f32::from(options.unit.slow_speed),
            options.print_mm_s,
        );
        let last_command = logic.command();
        Sim {
            rng: Rng::new(options.seed ^ 0x5541_5254), // "UART": independent of the model's noise
            last_slot_report: (0..options.slots).map(|slot| (model.tip_mm(slot), 0)).collect(),
            last_motors: vec![MotorCommand::Coast; options.slots],
            options,
            logic,
            model,
            now_ms: 0,
            boot_epoch_ms: 0,
            off_until_ms: None,
            corrupt: 0.0,
            drop: 0.0,
            schedule: Vec::new(),
            printer,
            events: Vec::new(),
            last_fsensor: 0,
            last_command,
            running: None,
            finished: Vec::new(),
            cut_at_write: None,
            cut_in_phase: None,
        }
    }

    /// Virtual time, ms since start.
    pub fn now_ms(&self) -> u64 {
        self.now_ms
    }

    /// The options the simulator was built with.
    pub fn options(&self) -> &SimOptions {
        &self.options
    }

    /// The unit logic's configuration.
    pub fn unit_config(&self) -> &Config {
        self.logic.config()
    }

    /// The physical model (filament positions, the printer's sensor).
    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The physical model, to play the user (insert or pull out filament).
    pub fn model_mut(&mut self) -> &mut Model {
        &mut self.model
    }

    /// What a person does on the printer's UNLOAD MANUALLY screen (`8008`): pull every filament
    /// whose tip is past its park position (in the hub, the Bowden tube or the extruder) back to
    /// the park position. Returns how many were pulled back.
    pub fn unload_manually(&mut self) -> usize {
        let park = -f32::from(self.unit_config().park_mm);
        let past_park: Vec<usize> = (0..self.options.slots)
            .filter(|&slot| self.model.tip_mm(slot).is_some_and(|tip| tip > park))
            .collect();
        for &slot in &past_park {
            self.model.insert_filament(slot, park);
        }
        past_park.len()
    }

    /// The command the unit is carrying out and where it stands.
    pub fn unit_command(&self) -> ((RequestCode, u8), Status) {
        self.logic.command()
    }

    /// How much the unit's flash has been worn by its persisted state.
    pub fn flash_wear(&mut self) -> crate::flash::FlashWear {
        self.logic.flash_wear()
    }

    /// The unit's control loop hangs from now on, until its watchdog resets it
    /// ([`UnitLogic::hang`]).
    pub fn hang(&mut self) {
        if self.is_powered() {
            self.event(EventKind::Fault {
                action: FaultAction::Inject,
                fault: String::from("control loop hangs"),
            });
            self.logic.hang();
        }
    }

    /// Cut the power for `off_ms` at the end of the next step that writes to the unit's flash:
    /// in the middle of a save that takes more than one step.
    pub fn cut_power_at_next_flash_write(&mut self, off_ms: u32) {
        let written = self.logic.flash_wear().bytes_written;
        self.cut_at_write = Some((off_ms, written));
    }

    /// Cut the power as [`PhaseCut`] says: `after_ms` into the first time the unit reports
    /// `progress` while it runs a command with `code`.
    pub fn cut_power_during(&mut self, cut: PhaseCut) {
        self.cut_in_phase = Some((cut, None));
    }

    /// A power cut armed by [`Sim::cut_power_during`] has not happened yet.
    pub fn phase_cut_pending(&self) -> bool {
        self.cut_in_phase.is_some()
    }

    /// Why the unit can no longer be stepped (a firmware bench that stopped), if it cannot.
    pub fn unit_failure(&self) -> Option<String> {
        self.logic.failure()
    }

    /// The unit is powered and booted.
    pub fn is_powered(&self) -> bool {
        self.off_until_ms.is_none()
    }

    /// A button on the unit was pressed (ignored while it is off).
    pub fn press_button(&mut self, button: mmu_protocol::ButtonCode) {
        if self.is_powered() {
            self.logic.press_button(button);
        }
    }

    /// Inject `fault` now. False when the model refuses it (e.g. an unknown slot).
    pub fn inject(&mut self, fault: SimFault) -> bool {
        let ok = match fault {
            SimFault::Model(fault) => self.model.inject(fault),
            SimFault::UartCorrupt { probability } => {
                self.corrupt = probability.clamp(0.0, 1.0);
                true
            }
            SimFault::UartDrop { probability } => {
                self.drop = probability.clamp(0.0, 1.0);
                true
            }
            SimFault::PowerLoss { off_ms } => {
                self.power_off(off_ms);
                true
            }
        };
        if ok {
            self.event(EventKind::Fault {
                action: FaultAction::Inject,
                fault: fault.to_string(),
            });
        }
        ok
    }

    /// Clear the fault of `kind`; false when none was active.
    pub fn clear(&mut self, kind: SimFaultKind) -> bool {
        let (cleared, name) = match kind {
            SimFaultKind::Model(kind) => {
                let name = self
                    .model
                    .active_faults()
                    .iter()
                    .find(|f| f.kind() == kind)
                    .map(|f| SimFault::Model(*f).to_string());
                (self.model.clear(kind), name)
            }
            SimFaultKind::UartCorrupt => (
                std::mem::take(&mut self.corrupt) > 0.0,
                Some("uart-corrupt".into()),
            ),
            SimFaultKind::UartDrop => (std::mem::take(&mut self.drop) > 0.0, Some("uart-drop".into())),
            SimFaultKind::PowerLoss => (false, None),
        };
        if let (true, Some(fault)) = (cleared, name) {
            self.event(EventKind::Fault {
                action: FaultAction::Clear,
                fault,
            });
        }
        cleared
    }

    /// The faults now active, in `--fault` syntax.
    pub fn active_faults(&self) -> Vec<SimFault> {
        let mut faults: Vec<SimFault> = self
            .model
            .active_faults()
            .iter()
            .map(|f| SimFault::Model(*f))
            .collect();
        if self.corrupt > 0.0 {
            faults.push(SimFault::UartCorrupt {
                probability: self.corrupt,
            });
        }
        if self.drop > 0.0 {
            faults.push(SimFault::UartDrop {
                probability: self.drop,
            });
        }
        faults
    }

    /// Inject `fault.fault` at `fault.at_ms` and clear it at `fault.until_ms`.
    pub fn schedule(&mut self, fault: ScheduledFault) {
        self.schedule.push(fault);
    }

    /// Events since the last call, oldest first.
    pub fn take_events(&mut self) -> Vec<Event> {
        std::mem::take(&mut self.events)
    }

    /// Commands the unit finished since the last call, oldest first.
    pub fn take_finished(&mut self) -> Vec<CommandRecord> {
        std::mem::take(&mut self.finished)
    }

    /// One millisecond of virtual time: the printer's bytes `rx` reach the unit, what the unit
    /// sends is appended to `tx`.
    pub fn step(&mut self, rx: &[u8], tx: &mut Vec<u8>) {
        self.run_schedule();
        let to_unit = self.pass_printer_bytes(rx);
        let mut from_unit = Vec::new();
        match self.off_until_ms {
            Some(until) => {
                self.model.step(1, &[]);
                if self.now_ms + 1 >= until {
                    self.boot();
                }
            }
            None => {
                let now = Instant::from_millis(self.now_ms - self.boot_epoch_ms);
                let action = self.logic.step(now, 1, &mut self.model, &to_unit, &mut from_unit);
                // The logic erased its store already for `X42`.
                if action.is_some() {
                    self.power_off(self.options.boot_ms);
                }
            }
        }
        self.uart_faults(&mut from_unit);
        let mut happened = Vec::new();
        self.printer
            .unit_bytes(&from_unit, &mut self.model, &mut happened);
        tx.extend_from_slice(&from_unit);
        self.printer.step(&mut self.model, &mut happened);
        for what in happened {
            self.event(what);
        }
        if let Some((off_ms, written)) = self.cut_at_write
            && self.is_powered()
            && self.logic.flash_wear().bytes_written > written
        {
            self.cut_at_write = None;
            self.inject(SimFault::PowerLoss { off_ms });
        }
        self.cut_in_phase_due();
        self.now_ms += 1;
        self.watch();
    }

    /// The power cut armed by [`Sim::cut_power_during`], when its time has come.
    fn cut_in_phase_due(&mut self) {
        let Some((cut, seen)) = self.cut_in_phase else {
            return;
        };
        let ((code, _), status) = self.logic.command();
        let seen = match seen {
            Some(seen) => seen,
            None if self.is_powered() && code == cut.code && status == Status::Running(cut.progress) => {
                self.cut_in_phase = Some((cut, Some(self.now_ms)));
                self.now_ms
            }
            None => return,
        };
        if self.now_ms >= seen + cut.after_ms {
            self.cut_in_phase = None;
            self.inject(SimFault::PowerLoss { off_ms: cut.off_ms });
        }
    }

    fn event(&mut self, what: EventKind) {
        self.events.push(Event {
            t_ms: self.now_ms,
            what,
        });
    }

    fn run_schedule(&mut self) {
        let now = self.now_ms;
        let due: Vec<ScheduledFault> = self
            .schedule
            .iter()
            .filter(|f| f.at_ms == now || f.until_ms == Some(now))
            .copied()
            .collect();
        for fault in due {
            if fault.at_ms == now {
                self.inject(fault.fault);
            } else {
                self.clear(fault.fault.kind());
            }
        }
        self.schedule
            .retain(|f| f.until_ms.map_or(f.at_ms > now, |until| until > now));
    }

    fn power_off(&mut self, off_ms: u32) {
        if self.off_until_ms.is_none() {
            self.logic.power_off();
            self.event(EventKind::Power { on: false });
        }
        self.off_until_ms = Some(self.now_ms + u64::from(off_ms.max(1)));
    }

    fn boot(&mut self) {
        self.off_until_ms = None;
        self.boot_epoch_ms = self.now_ms + 1;
        self.logic.power_on(&self.options.unit);
        self.running = None;
        self.event(EventKind::Power { on: true });
    }

    /// The printer's bytes, as the printer's mechanics let them through
    /// ([`Mechanics::pass_printer_bytes`]); then the UART faults strike.
    fn pass_printer_bytes(&mut self, rx: &[u8]) -> Vec<u8> {
        let mut happened = Vec::new();
        let mut out = self
            .printer
            .pass_printer_bytes(self.now_ms, rx, &mut self.model, &mut happened);
        for what in happened {
            self.event(what);
        }
        self.uart_faults(&mut out);
        if self.off_until_ms.is_some() {
            out.clear();
        }
        out
    }

    fn uart_faults(&mut self, bytes: &mut Vec<u8>) {
        if self.corrupt == 0.0 && self.drop == 0.0 {
            return;
        }
        let (corrupt, drop) = (f64::from(self.corrupt), f64::from(self.drop));
        let rng = &mut self.rng;
        bytes.retain_mut(|byte| {
            if rng.uniform() < corrupt {
                *byte ^= 1 << (rng.next_u64() % 8);
            }
            rng.uniform() >= drop
        });
    }

    /// Report what changed: the printer's sensor, slot motion, the unit's command.
    fn watch(&mut self) {
        let state = self.model.fsensor_state();
        if state != self.last_fsensor {
            self.last_fsensor = state;
            self.event(EventKind::Fsensor { state });
        }
        for slot in 0..self.last_slot_report.len() {
            let tip = self.model.tip_mm(slot);
            let (last_tip, last_ms) = self.last_slot_report[slot];
            let moved = match (tip, last_tip) {
                (Some(a), Some(b)) => (a - b).abs() >= 0.1,
                (a, b) => a.is_some() != b.is_some(),
            };
            if moved && self.now_ms >= last_ms + SLOT_REPORT_MS {
                self.last_slot_report[slot] = (tip, self.now_ms);
                self.event(EventKind::Slot {
                    slot,
                    tip_mm: tip.map(|t| (t * 10.0).round() / 10.0),
                });
            }
        }
        let motors = if self.is_powered() {
            self.logic.motors()
        } else {
            vec![MotorCommand::Coast; self.last_motors.len()]
        };
        for (slot, &motor) in motors.iter().enumerate() {
            if self.last_motors.get(slot).is_some_and(|&last| last != motor) {
                self.last_motors[slot] = motor;
                let (state, duty) = match motor {
                    MotorCommand::Drive { direction, duty } => (
                        match direction {
                            Direction::Forward => "forward",
                            Direction::Reverse => "reverse",
                        },
                        duty.permille(),
                    ),
                    MotorCommand::Brake => ("brake", 0),
                    MotorCommand::Coast => ("coast", 0),
                };
                self.event(EventKind::Motor { slot, state, duty });
            }
        }
        if self.is_powered() {
            self.watch_command();
        }
    }

    fn watch_command(&mut self) {
        let current = self.logic.command();
        if current == self.last_command {
            return;
        }
        let ((code, value), status) = current;
        let new_request = current.0 != self.last_command.0;
        self.last_command = current;
        let request = format!("{}{value:x}", code.as_char());
        let text = status_text(status);
        self.event(EventKind::Command {
            request,
            status: text,
        });
        if new_request && code.is_command() {
            let start_tip_mm = self.model.loaded_slot().and_then(|slot| self.model.tip_mm(slot));
            self.running = Some(CommandRecord {
                request: (code, value),
                started_ms: self.now_ms,
                finished_ms: self.now_ms,
                start_tip_mm,
                had_error: false,
            });
        }
        if let Some(record) = &mut self.running {
            match status {
                Status::Failed(_) => record.had_error = true,
                Status::Finished => {
                    record.finished_ms = self.now_ms;
                    self.finished.push(*record);
                    self.running = None;
                }
                Status::Running(_) => {}
            }
        }
    }
}
