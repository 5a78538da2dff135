//! The App: the whole unit as one stepped state machine.
//!
//! Each [`App::step`] takes the current time, a round of raw sensor samples and the bytes the
//! printer sent since the last step. It answers every complete request in the same step (queries
//! also while a command runs), advances the running command, and returns what the motors must do,
//! the bytes to send and any board action. Requests are handled as MMU 3.0.3 and 3.0.4 do
//! (`prusa-mmu-protocol.md` §3.3; `M` only for a printer that accepted 3.0.4): commands are
//! answered `A` or `R`, `Q0` reports the current command's progress, error or result, bad frames
//! and `F` get silence, `X` resets the board; `S0`..`S3` negotiate the revision (`Negotiation`).

use heapless::Vec;
use mmu_hal_port::{MotorCommand, Samples};
use mmu_protocol::{ButtonCode, ErrorCode, ParamCode, Request, RequestCode, Response, ResultCode};

use crate::arbiter::MotorArbiter;
use crate::config::{Config, Contract};
use crate::drive;
use crate::guards::{self, Rule};
use crate::persist::{IDENTITY_REGISTERS, MAX_SETTINGS, Snapshot};
use crate::profile::Profile;
use crate::registers;
use crate::runner::{Learned, Runner, Status};
use crate::session::Session;
use crate::tally::Tally;
use crate::time::Instant;
use crate::time::div_rem_u64;
use crate::unit::{Lane, Unit};

/// Room for the bytes one step may send: the answers to every request the at most
/// `control::MAX_RX_PER_STEP` bytes a step takes can complete (three, asserted in `control`).
/// Kept small: the outputs are copied out of every step.
pub const TX_CAPACITY: usize = 48;

/// `X` value that erases persisted data before the reset.
const ERASE_AND_RESET: u8 = 42;

/// Blink period of the status LED in an error state, ms.
const ERROR_BLINK_MS: u16 = 250;

/// Something only the board can do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BoardAction {
    /// Restart the MCU (`X0`).
    Reset,
    /// Erase persisted data, then restart (`X42`).
    EraseAndReset,
}

/// What one step asks of the board.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outputs<const N: usize> {
    /// Per slot motor command, to apply now.
    pub motors: [MotorCommand; N],
    /// Bytes to send to the printer, in order.
    pub tx: Vec<u8, TX_CAPACITY>,
    /// A reset or erase to carry out after sending `tx`.
    pub action: Option<BoardAction>,
    /// The status LED: lit while a command runs, blinking in an error state.
    pub status_led: bool,
    /// A phase of the running command began in this step (its motion's budget worked out, its
    /// motor started): one of the costliest steps, after which the board defers its save piece.
    pub phase_began: bool,
}

impl<const N: usize> Outputs<N> {
    /// Nothing to do: every motor stopped, nothing to send, no action, the LED off.
    pub fn none() -> Self {
        Outputs {
            motors: drive::stopped(),
            tx: Vec::new(),
            action: None,
            status_led: false,
            phase_began: false,
        }
    }
}

/// The unit logic for `N` slots (1 to 5): the printer's session, the unit and its running
/// command, the motor arbiter and the tally. `Clone` lets the power-cut study fork a unit's life.
#[derive(Clone)]
pub struct App<const N: usize> {
    pub(crate) config: Config,
    pub(crate) unit: Unit<N>,
    operation: Runner,
    /// The printer's side of the link ([`Session`]).
    session: Session,
    /// Who drives each motor ([`MotorArbiter`]).
    arbiter: MotorArbiter,
    /// What the unit counts ([`Tally`]).
    pub(crate) tally: Tally<N>,
    /// The time of the current step.
    pub(crate) now: Instant,
    /// The start-up check after power-up has ended (passed or failed). Until then the unit
    /// answers nothing, as MMU 3.0.3, which enables its receiver only after the check
    /// (`main.cpp` `setup2`; printer-truth §4): an `X0 P1a` opens Buddy's Homing dialog.
    started_up: bool,
    /// The Bowden length the last Retry of FSENSOR TOO EARLY learned since start, mm (0: none).
    bowden_learned_mm: u16,
    /// Moves (wrapping) whenever a setting may have changed: see [`App::settings_revision`].
    settings_revision: u32,
    /// The rule the last refusal broke: of a write (`None` when it broke none: an unknown or
    /// read-only register, a value out of range), or of the stored settings (register 0x8f).
    refused_rule: Option<Rule>,
}

impl<const N: usize> App<N> {
    const SLOTS_OK: () = assert!(N >= 1 && N <= crate::MAX_SLOTS, "a unit has 1 to 5 slots");

    /// A freshly started unit: it checks its sensors (`X0` is the current command), answering
    /// nothing, before it reports `X0 F0` (or the error it found).
    pub fn new(config: Config) -> Self {
        let () = Self::SLOTS_OK;
        App {
            config,
            unit: Unit::default(),
            operation: Runner::new((RequestCode::Reset, 0), &{
                let mut plan = crate::commands::Plan::new();
                crate::commands::start_up::plan(&mut plan);
                plan
            }),
            session: Session::new(),
            arbiter: MotorArbiter::NEW,
            tally: Tally::new(),
            now: Instant::ZERO,
            started_up: false,
            bowden_learned_mm: 0,
            settings_revision: 0,
            refused_rule: None,
        }
    }

    /// A freshly started unit on the hardware `profile` with `config` (its defaults:
    /// [`Config::for_profile`]); `None` when the profile has fewer than `N` lanes.
    pub fn with_profile(profile: &'static Profile, config: Config) -> Option<Self> {
        if N > profile.max_slots {
            return None;
        }
        let mut app = Self::new(config);
        app.unit.profile = profile;
        Some(app)
    }

    /// What senses each lane.
    pub fn profile(&self) -> &'static Profile {
        self.unit.profile()
    }

    /// The settings in force.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The rule of the guards ([`crate::guards`]) the last refusal broke: of a register write
    /// (`None` when it broke none: an unknown or read-only register, a value out of range), or of
    /// the stored settings at start (register 0x8f).
    pub fn refused_rule(&self) -> Option<Rule> {
        self.refused_rule
    }

    /// A number that changes whenever a setting may have changed (an accepted setting write, a
    /// restore, any button acted on in an error: a Retry may learn the Bowden length), so that
    /// the persistence keeper compares it instead of every setting.
    pub fn settings_revision(&self) -> u32 {
        self.settings_revision
    }

    /// What the unit knows about its hardware.
    pub fn unit(&self) -> &Unit<N> {
        &self.unit
    }

    /// Start slot `slot`'s odometry from `centi` ([`crate::feeder::Feeder::set_odometry_centi`]): for tests (a
    /// slot that has fed kilometres) and a restart that keeps it. Counted as no motion.
    pub fn set_odometry_centi(&mut self, slot: usize, centi: i32) {
        if let Some(feeder) = self.unit.feeders.get_mut(slot) {
            feeder.set_odometry_centi(centi);
            self.tally.odometry_set(slot, centi);
        }
    }

    /// False until the start-up check after power-up has ended: until then the unit hears and
    /// answers nothing.
    pub fn is_listening(&self) -> bool {
        self.started_up
    }

    /// Whether the last step drove any motor (the flash must not stall the CPU under it).
    pub fn motors_driven(&self) -> bool {
        self.unit.drives.iter().any(|drive| drive.command().is_driving())
    }

    /// The command being carried out (or the last one).
    pub fn operation(&self) -> &Runner {
        &self.operation
    }

    /// Advance the unit to `now` with the latest sensor samples and the bytes received since the
    /// last step.
    pub fn step(&mut self, now: Instant, samples: &Samples<N>, rx: &[u8]) -> Outputs<N> {
        let mut out = Outputs::none();
        self.now = now;
        self.session.begin_step(now, rx);
        self.unit.sense(samples, now, &self.config);
        let running = matches!(self.operation.status(), Status::Running(_));
        self.tally.observe(
            &self.unit,
            self.operation.driving_slot(),
            running,
            &self.config,
            now,
        );
        for &byte in rx {
            let Some(request) = self.session.decode(byte) else {
                continue;
            };
            if !self.started_up {
                // Not heard: the printer re-sends after its 2 s link timeout.
                continue;
            }
            self.session.listen(&request);
            self.handle(&request, &mut out);
            if out.action.is_some() {
                // The board resets: motors stay off and nothing after `X` is answered.
                return out;
            }
        }
        let before = self.operation.status();
        self.operation
            .step(&mut self.unit, now, &self.config, self.session.printer);
        if let Some(learned) = self.operation.take_learned() {
            // Measured by the load itself: a setting changed.
            self.settings_revision = self.settings_revision.wrapping_add(1);
            self.keep(learned);
        }
        self.command_changed(before);
        out.phase_began = self.operation.phase_began_at(now);
        self.started_up |= !matches!(self.operation.status(), Status::Running(_));
        // Once: `Runner::driving_slot` looks the phase up in the plan.
        let driving = self.operation.driving_slot();
        self.tally.count_fed(&self.unit, driving);
        out.motors = self.arbiter.drive(
            &mut self.unit,
            &mut self.operation,
            &mut self.tally,
            &self.config,
            now,
            driving,
        );
        out.status_led = match self.operation.status() {
            Status::Running(_) => true,
            Status::Failed(_) => div_rem_u64(now.as_millis(), ERROR_BLINK_MS).0.is_multiple_of(2),
            Status::Finished => false,
        };
        out
    }

    /// A physical button on the unit was pressed. In an error state it is Retry / Continue; during
    /// a tool change the printer is in charge, so the press is reported to it instead (`B1` in
    /// the next `Q0` answer) and acted on when the printer sends it back.
    pub fn press_button(&mut self, button: ButtonCode) {
        if !matches!(self.operation.status(), Status::Failed(_)) {
            return;
        }
        if self.operation.request.0 == RequestCode::Tool {
            self.session.pending_button = Some(button);
        } else {
            self.act_on_button(button);
        }
    }

    /// Hand `button` to the command in its error. Its recovery may change a setting (a Bowden
    /// length learned by a Retry), so every press that lends it the configuration moves the
    /// settings revision (the keeper then compares the settings); what it learned is also kept
    /// where register 0x53 shows it.
    fn act_on_button(&mut self, button: ButtonCode) {
        self.settings_revision = self.settings_revision.wrapping_add(1);
        if let Some(learned) = self.operation.press(button, &self.unit, &mut self.config) {
            self.keep(learned);
        }
    }

    /// Keep a setting a command learned: in the configuration, and where register 0x53 shows it.
    fn keep(&mut self, learned: Learned) {
        let Learned::BowdenMm(mm) = learned;
        self.config.bowden_mm = mm;
        self.bowden_learned_mm = mm;
    }

    /// Act on `request` and queue its answer. A request whose answer would not fit this step's
    /// transmit buffer is not acted on at all (and counted in register 0x51): the printer, left
    /// without an answer, sends it again, and nothing happens that it was never told about.
    fn handle(&mut self, request: &Request, out: &mut Outputs<N>) {
        let answered = !matches!(request.code, RequestCode::Reset | RequestCode::FilamentType)
            && (request.code != RequestCode::Mode
                || self.config.version.contract() == Contract::AwaitRelease);
        if answered && !self.session.room_for_answer(&out.tx) {
            return;
        }
        let asks_revision = request.code == RequestCode::Version && request.value == 2;
        if request.code == RequestCode::Version
            && request.value == 3
            && let Some(accepted) = self.session.offered_revision()
            && accepted != self.config.version.revision
        {
            // The printer asks for the build only once the revision matched: keep it.
            self.config.version.revision = accepted;
            self.settings_revision = self.settings_revision.wrapping_add(1);
        }
        let response = self.respond(request, asks_revision, &mut out.action);
        if !asks_revision {
            self.session.other_request(request);
        }
        if let Some(response) = response {
            self.session.send(response, &mut out.tx);
        }
    }

    /// What `request` does and its answer, if it has one; a reset sets `action`.
    fn respond(
        &mut self,
        request: &Request,
        asks_revision: bool,
        action: &mut Option<BoardAction>,
    ) -> Option<Response> {
        match request.code {
            RequestCode::Version if asks_revision => Some(Response::read(
                request,
                self.session.offer_revision(self.config.version.revision).into(),
            )),
            RequestCode::Query => Some(self.query_answer()),
            code if code.is_command() => Some(self.start_command(request)),
            RequestCode::Reset => {
                *action = Some(if request.value == ERASE_AND_RESET {
                    BoardAction::EraseAndReset
                } else {
                    BoardAction::Reset
                });
                None
            }
            RequestCode::Finda => Some(Response::read(request, self.arbiter.finda(&self.unit).into())),
            RequestCode::Version | RequestCode::Read => Some(match self.read_register(request.value) {
                Some(value) => Response::read(request, value),
                None => Response::rejected(request),
            }),
            RequestCode::Write => Some(if self.write_register(request.value, request.value2) {
                Response::accepted(request)
            } else {
                Response::rejected(request)
            }),
            RequestCode::Button => {
                self.act_on_button(ButtonCode(request.value));
                Some(Response::accepted(request))
            }
            RequestCode::FilamentSensor => {
                self.unit.fsensor = request.value;
                Some(Response::accepted(request))
            }
            // MMU 3.0.4 plans the motor mode as a command that finishes at once (`M<n> A`, then
            // `F0`: Prusa-Firmware-MMU `application.cpp`, `39b24f8`); this unit's DC motors have
            // no stealth mode to switch.
            RequestCode::Mode if self.config.version.contract() == Contract::AwaitRelease => {
                Some(self.start_command(request))
            }
            // MMU 3.0.3 answers neither the filament type nor the motor mode.
            _ => None,
        }
    }

    fn query_answer(&mut self) -> Response {
        let (code, value) = self.operation.request;
        if let Some(button) = self.session.pending_button.take() {
            return Response::button(code, value, button);
        }
        match self.operation.status() {
            Status::Running(progress) => {
                // The printer acts on the progress it sees (its co-feed on `P1c`).
                self.session.printer.polled = self.now;
                Response::progress(code, value, progress)
            }
            Status::Failed(error) => Response::error(code, value, error),
            Status::Finished => {
                if code == RequestCode::Home {
                    // The printer's idle check knows no `H` echo and re-handshakes on one, forever
                    // (`protocol_logic.cpp` `IdleStep`; printer-truth §3): `H0 F0` ends the
                    // printer's `H0` once, then the unit reports itself idle as `X0 F0`.
                    self.operation.request = (RequestCode::Reset, 0);
                }
                Response::finished(code, value, ResultCode::OK)
            }
        }
    }

    /// A command is refused only while another one runs. Over an error that waits for the user
    /// it is accepted and takes the error over ([`Runner::supersede`]): Prusa's printer re-sends
    /// a refused command at once, forever, and could never send the screen's Retry
    /// (printer-truth §2.3, §7).
    fn start_command(&mut self, request: &Request) -> Response {
        let key = (request.code, request.value);
        let superseded = match self.operation.status() {
            Status::Running(_) => return Response::rejected(request),
            Status::Failed(error) if error != ErrorCode::INVALID_TOOL => true,
            _ => false,
        };
        self.session.pending_button = None;
        self.arbiter.command_started();
        let names_a_slot = matches!(
            request.code,
            RequestCode::Tool | RequestCode::Load | RequestCode::Eject | RequestCode::Cut
        );
        if names_a_slot && usize::from(request.value) < N {
            self.unit.selected = Some(request.value.into());
        }
        self.tally
            .command_started(request.code, request.value, superseded, self.now);
        if superseded {
            self.operation = Runner::supersede(&self.operation, key);
        } else {
            self.operation = Runner::start(key, &self.unit, &self.config);
        }
        Response::bare(request.code, request.value, ParamCode::Accepted)
    }

    /// The board could not send a step's response bytes (its transmit ring was full): counted with
    /// the responses the step itself dropped, in register 0x51.
    pub fn count_dropped_response(&mut self) {
        self.session.count_dropped();
    }

    /// The value of register `address`, or `None` when the unit has no such register.
    pub fn read_register(&self, address: u8) -> Option<u16> {
        let view = registers::View {
            profile: self.unit.profile(),
            config: &self.config,
            hub: &self.unit.hub,
            finda: self.arbiter.finda(&self.unit),
            feeders: &self.unit.feeders,
            slots: N,
            lanes: &self.unit.lanes,
            fsensor: self.unit.fsensor,
            path_slot: self.unit.active().or(self.unit.selected),
            driving_slot: self.operation.driving_slot(),
            status: self.operation.status(),
            drive_errors: self.tally.counters.drive_errors,
            tool_changes: &self.tally.counters.tool_changes,
            failures: &self.tally.counters.failures,
            fed_mm: &self.tally.counters.fed_mm,
            dropped_responses: self.session.dropped_responses,
            bowden_learned_mm: self.bowden_learned_mm,
            lane_figures: &self.tally.counters.lanes,
            used_centi: self.tally.ledger.used_centi(),
            lanes_drifted: self.tally.ledger.drifted(),
            refused_rule: self.refused_rule,
            unload_stuck: self.operation.unload_stuck(),
            // Right after an `S2`, the build of the revision it offered: what `S3` would report.
            build: crate::config::build_of(
                self.session
                    .offered_revision()
                    .unwrap_or(self.config.version.revision),
            ),
            now: self.now,
        };
        registers::read(&view, address)
    }

    /// Write `value` to register `address`; false (answered `R`, nothing changed) when the register
    /// is unknown or read-only, the value out of range, or the settings with it would break a
    /// rule of the guards ([`crate::guards`]; register 0x8f then names the rule).
    pub fn write_register(&mut self, address: u8, value: u16) -> bool {
        let filament_readings = self.filament_readings();
        let mut target = registers::Target {
            profile: self.unit.profile(),
            slots: N,
            config: &mut self.config,
            fsensor: &mut self.unit.fsensor,
            filament_readings,
            used_centi: self.tally.ledger.used_centi_mut(),
        };
        let written = registers::write(&mut target, N, address, value);
        if let Err(refused) = written {
            self.refused_rule = match refused {
                registers::Refused::Broke(rule) => Some(rule),
                _ => None,
            };
        }
        let accepted = written.is_ok();
        if accepted && registers::LEFT <= address && address < registers::LEFT + N as u8 {
            self.tally.left_written();
        }
        if accepted && address != registers::FSENSOR {
            self.settings_revision = self.settings_revision.wrapping_add(1);
        }
        accepted
    }

    /// The reading of each presence sensor that sees filament where the lanes say filament is
    /// (the hub's while a slot owns the hub path, a slot's while its tip is at least parked),
    /// for the guards ([`guards::FilamentReadings`]). A reading counts only at or
    /// above the "on" threshold in force: a sensor stuck "present" below it (an "off" threshold
    /// no reading goes under) holds no write back.
    fn filament_readings(&self) -> guards::FilamentReadings {
        let mut readings = guards::NO_FILAMENT_READINGS;
        let filament = |reading: Option<u16>, on: u16| reading.filter(|&value| value >= on);
        if let Some(hub) = readings.first_mut()
            && self.unit.active().is_some()
        {
            *hub = filament(
                self.unit.hub.filament.analog.reading(),
                self.config.hub_thresholds.on,
            );
        }
        for (slot, feeder) in self.unit.feeders.iter().enumerate() {
            let parked_or_further = !matches!(self.unit.lane(slot), Lane::Unknown | Lane::Empty);
            if let (true, Some(seen), Some(thresholds)) = (
                parked_or_further,
                readings.get_mut(1 + slot),
                self.config.slot_thresholds.get(slot),
            ) {
                *seen = filament(feeder.filament.analog.reading(), thresholds.on);
            }
        }
        readings
    }

    /// Every writable setting that differs from its default, and its value (only what differs:
    /// a later firmware's defaults then apply to the others).
    fn settings(&self) -> Vec<(u8, u16), MAX_SETTINGS> {
        let mut settings = Vec::new();
        // MAX_SETTINGS holds every setting of a 5-slot unit.
        registers::changed_settings(
            self.unit.profile(),
            &self.config,
            &Config::for_profile(self.unit.profile()),
            &self.unit.hub,
            N,
            &mut settings,
        );
        settings
    }

    /// Where each slot's filament is.
    pub fn lanes(&self) -> [Lane; N] {
        core::array::from_fn(|slot| self.unit.lane(slot))
    }

    /// What the unit keeps across a restart: lanes, counters, settings.
    pub fn snapshot(&self) -> Snapshot<N> {
        Snapshot {
            lanes: self.lanes(),
            counters: self.tally.counters,
            settings: self.settings(),
        }
    }

    /// Take back what a previous run kept, before the first step; the start-up check then
    /// compares the lanes with what the sensors show.
    ///
    /// The stored settings are outside input. Each goes in with its register's own checks (a
    /// value out of range is dropped), all together onto the build's settings, and the guards
    /// then judge the whole ([`guards::check`]). A stored configuration that breaks a rule is
    /// dropped whole: the unit runs on the build's settings (the defaults), keeping only the
    /// identity registers ([`IDENTITY_REGISTERS`]: no rule concerns them, and a printer needs
    /// them to talk to the unit), and register 0x8f names the rule. The store keeps only the
    /// newest settings, so there is no older good one to go back to; the next save writes the
    /// settings in force over the refused ones.
    pub fn restore(&mut self, snapshot: &Snapshot<N>) {
        for (slot, &lane) in snapshot.lanes.iter().enumerate() {
            self.unit.set_lane(slot, lane);
        }
        self.tally.restore(snapshot);
        let mut stored = self.config.clone();
        for &(address, value) in &snapshot.settings {
            registers::apply_setting(self.unit.profile(), &mut stored, N, address, value);
        }
        match guards::check(&stored, &guards::NO_FILAMENT_READINGS) {
            Ok(()) => self.config = stored,
            Err(rule) => {
                self.refused_rule = Some(rule);
                let identity = snapshot
                    .settings
                    .iter()
                    .filter(|(address, _)| IDENTITY_REGISTERS.contains(address));
                for &(address, value) in identity {
                    registers::apply_setting(self.unit.profile(), &mut self.config, N, address, value);
                }
            }
        }
        self.settings_revision = self.settings_revision.wrapping_add(1);
    }

    /// The running command's status changed from `before`, or not: counted, and what the
    /// printer's extruder moves from a finished command on is evidence for the next one.
    fn command_changed(&mut self, before: Status) {
        self.tally
            .command_changed(&self.operation, before, &self.unit.lanes, self.now);
        if self.operation.status() != before && self.operation.status() == Status::Finished {
            self.unit.moved_by_printer = [0; N];
        }
    }
}

impl<const N: usize> Default for App<N> {
    fn default() -> Self {
        Self::new(Config::default())
    }
}
