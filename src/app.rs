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
use mmu_protocol::{
    ButtonCode, ErrorCode, MAX_FRAME_LEN, ParamCode, Request, RequestCode, RequestDecoder, Response,
    ResultCode,
};

use crate::config::{Config, Contract, offered_revision};
use crate::drive;
use crate::feeder::distance_centi;
use crate::follower;
use crate::lanes::Ledger;
use crate::persist::{Counters, MAX_SETTINGS, Snapshot};
use crate::phases::PrinterLink;
use crate::registers;
use crate::runner::{Learned, Runner, Status};
use crate::spool_end::SpoolEnd;
use crate::time::Instant;
use crate::unit::{Lane, Unit};

/// Room for the bytes one step may send: the answers to every request the at most
/// `control::MAX_RX_PER_STEP` bytes a step takes can complete (three, asserted in `control`).
/// Kept small: the outputs are copied out of every step.
pub const TX_CAPACITY: usize = 48;

/// `X` value that erases persisted data before the reset.
const ERASE_AND_RESET: u8 = 42;

/// Blink period of the status LED in an error state, ms.
const ERROR_BLINK_MS: u64 = 250;

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

/// The unit logic for `N` slots (1 to 5). `Clone` lets the power-cut study fork a unit's life.
#[derive(Clone)]
pub struct App<const N: usize> {
    pub(crate) config: Config,
    pub(crate) unit: Unit<N>,
    operation: Runner,
    pub(crate) counters: Counters<N>,
    /// Responses that did not fit a step's transmit buffer (not persisted).
    pub(crate) dropped_responses: u16,
    /// Odometry of each slot at the last step, 1/100 mm.
    odometry_seen: [i32; N],
    /// The hundredths of a millimetre each slot drove beyond its whole millimetres in
    /// `counters.fed_mm` (below 100).
    fed_centi_beyond_mm: [u8; N],
    decoder: RequestDecoder,
    /// The time of the current step.
    pub(crate) now: Instant,
    /// A physical button press waiting for the printer to collect it with `Q0` (during `T`, the
    /// printer is in charge of buttons and sends them back).
    pending_button: Option<ButtonCode>,
    /// The start-up check after power-up has ended (passed or failed). Until then the unit
    /// answers nothing, as MMU 3.0.3, which enables its receiver only after the check
    /// (`main.cpp` `setup2`; printer-truth §4): an `X0 P1a` opens Buddy's Homing dialog.
    started_up: bool,
    /// The version negotiation ([`Negotiation`]).
    negotiation: Negotiation,
    /// The Bowden length the last Retry of FSENSOR TOO EARLY learned since start, mm (0: none).
    bowden_learned_mm: u16,
    /// The link to the printer as the phases that depend on it see it (`P1c`, `P7` hold their
    /// motor while it is in doubt).
    printer: PrinterLink,
    /// Moves (wrapping) whenever a setting may have changed: see [`App::settings_revision`].
    settings_revision: u32,
    /// Filament left and lane health, as they are counted ([`crate::lanes`]).
    ledger: Ledger<N>,
    /// The loaded slot's spool end while printing, as FINDA reports it ([`SpoolEnd`]).
    spool_end: SpoolEnd,
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
            counters: Counters::default(),
            dropped_responses: 0,
            odometry_seen: [0; N],
            fed_centi_beyond_mm: [0; N],
            // The printer may be mid-frame when the unit starts: only a newline or a silence
            // starts the first frame.
            decoder: RequestDecoder::new_mid_line(),
            now: Instant::ZERO,
            pending_button: None,
            started_up: false,
            negotiation: Negotiation::default(),
            bowden_learned_mm: 0,
            printer: PrinterLink {
                heard: Instant::ZERO,
                polled: Instant::ZERO,
                in_sync: true,
            },
            settings_revision: 0,
            ledger: Ledger::default(),
            spool_end: SpoolEnd::NEW,
        }
    }

    /// The settings in force.
    pub fn config(&self) -> &Config {
        &self.config
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
        if let (Some(feeder), Some(seen)) =
            (self.unit.feeders.get_mut(slot), self.odometry_seen.get_mut(slot))
        {
            feeder.set_odometry_centi(centi);
            *seen = centi;
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
        // The answers of the last step have gone out: an `S2` from now on follows them.
        self.negotiation.answered_this_step = None;
        self.unit.sense(samples, now, &self.config);
        self.ledger.observe(
            &self.unit,
            self.operation.driving_slot(),
            matches!(self.operation.status(), Status::Running(_)),
            &mut self.counters.lanes,
            &self.config,
            now,
        );
        if !rx.is_empty() {
            self.printer.heard = now;
        } else if now.millis_since(self.printer.heard) >= u64::from(mmu_protocol::SILENCE_MS) {
            // A silence on the line ends any frame: what was dropped is not a request.
            if self.decoder.line_silent().is_some() {
                self.printer.in_sync = false;
            }
        }
        for &byte in rx {
            let request = match self.decoder.feed(byte) {
                Some(Ok(request)) => request,
                Some(Err(_)) => {
                    // A lost frame: perhaps the printer's `f`.
                    self.printer.in_sync = false;
                    continue;
                }
                None => continue,
            };
            if !self.started_up {
                // Not heard: the printer re-sends after its 2 s link timeout.
                continue;
            }
            match (request.code, request.value) {
                (RequestCode::Version, 0) => self.printer.in_sync = false,
                (RequestCode::FilamentSensor | RequestCode::Query, _) => self.printer.in_sync = true,
                _ => {}
            }
            self.handle(&request, &mut out);
            if out.action.is_some() {
                // The board resets: motors stay off and nothing after `X` is answered.
                return out;
            }
        }
        let before = self.operation.status();
        self.operation
            .step(&mut self.unit, now, &self.config, self.printer);
        self.count_transition(before);
        out.phase_began = self.operation.phase_began_at(now);
        self.started_up |= !matches!(self.operation.status(), Status::Running(_));
        // Once: `Runner::driving_slot` looks the phase up in the plan.
        let driving = self.operation.driving_slot();
        self.count_fed(driving);
        let idle = matches!(self.operation.status(), Status::Finished);
        self.spool_end.watch(&self.unit, idle, now);
        self.drive_motors(now, driving, &mut out);
        out.status_led = match self.operation.status() {
            Status::Running(_) => true,
            Status::Failed(_) => (now.as_millis() / ERROR_BLINK_MS).is_multiple_of(2),
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
            self.pending_button = Some(button);
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
        if let Some(Learned::BowdenMm(mm)) = self.operation.press(button, &self.unit, &mut self.config) {
            self.bowden_learned_mm = mm;
        }
    }

    /// Act on `request` and queue its answer. A request whose answer would not fit this step's
    /// transmit buffer is not acted on at all (and counted in register 0x51): the printer, left
    /// without an answer, sends it again, and nothing happens that it was never told about.
    fn handle(&mut self, request: &Request, out: &mut Outputs<N>) {
        let answered = !matches!(request.code, RequestCode::Reset | RequestCode::FilamentType)
            && (request.code != RequestCode::Mode
                || self.config.version.contract() == Contract::AwaitRelease);
        if answered && out.tx.capacity() - out.tx.len() < MAX_FRAME_LEN {
            self.dropped_responses = self.dropped_responses.saturating_add(1);
            return;
        }
        let asks_revision = request.code == RequestCode::Version && request.value == 2;
        if request.code == RequestCode::Version
            && request.value == 3
            && let Some(accepted) = self.negotiation.offered
            && accepted != self.config.version.revision
        {
            // The printer asks for the build only once the revision matched: keep it.
            self.config.version.revision = accepted;
            self.settings_revision = self.settings_revision.wrapping_add(1);
        }
        let response = match request.code {
            RequestCode::Version if asks_revision => Some(Response::read(
                request,
                self.negotiation.offer(self.config.version.revision).into(),
            )),
            RequestCode::Query => Some(self.query_answer()),
            code if code.is_command() => Some(self.start_command(request)),
            RequestCode::Reset => {
                out.action = Some(if request.value == ERASE_AND_RESET {
                    BoardAction::EraseAndReset
                } else {
                    BoardAction::Reset
                });
                None
            }
            RequestCode::Finda => Some(Response::read(
                request,
                self.spool_end
                    .finda(self.unit.hub_present(), self.unit.active().is_some())
                    .into(),
            )),
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
        };
        if !asks_revision {
            self.negotiation.other_request(request);
        }
        if let Some(response) = response {
            let frame = response.encode();
            if out.tx.extend_from_slice(frame.as_bytes()).is_err() {
                self.dropped_responses = self.dropped_responses.saturating_add(1);
            }
        }
    }

    fn query_answer(&mut self) -> Response {
        let (code, value) = self.operation.request;
        if let Some(button) = self.pending_button.take() {
            return Response::button(code, value, button);
        }
        match self.operation.status() {
            Status::Running(progress) => {
                // The printer acts on the progress it sees (its co-feed on `P1c`).
                self.printer.polled = self.now;
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
        self.pending_button = None;
        self.spool_end.clear();
        let names_a_slot = matches!(
            request.code,
            RequestCode::Tool | RequestCode::Load | RequestCode::Eject | RequestCode::Cut
        );
        if names_a_slot && usize::from(request.value) < N {
            self.unit.selected = Some(request.value.into());
        }
        self.ledger.command_started(
            request.code,
            request.value,
            superseded,
            &mut self.counters.lanes,
            self.now,
        );
        if superseded {
            self.operation = Runner::supersede(&self.operation, key);
        } else {
            self.operation = Runner::start(key, &self.unit, &self.config);
        }
        Response::bare(request.code, request.value, ParamCode::Accepted)
    }

    /// Add the motion of the slot the running command drives to its fed distance (the extruder
    /// pulling a loaded slot while printing does not count), and every slot's motion to what
    /// left its spool ([`Ledger::moved`]). `driving`: the slot the running command drives.
    fn count_fed(&mut self, driving: Option<usize>) {
        for (slot, feeder) in self.unit.feeders.iter().enumerate() {
            let odometry = feeder.odometry_centi();
            let seen = core::mem::replace(&mut self.odometry_seen[slot], odometry);
            if odometry != seen {
                // Every motion counts off the spool, the printer's pull too.
                self.ledger
                    .moved(slot, distance_centi(seen, odometry), &mut self.counters.lanes);
            }
            if driving == Some(slot) && odometry != seen {
                (self.counters.fed_mm[slot], self.fed_centi_beyond_mm[slot]) = add_centi(
                    self.counters.fed_mm[slot],
                    self.fed_centi_beyond_mm[slot],
                    distance_centi(seen, odometry).unsigned_abs(),
                );
            }
        }
    }

    /// The board could not send a step's response bytes (its transmit ring was full): counted with
    /// the responses the step itself dropped, in register 0x51.
    pub fn count_dropped_response(&mut self) {
        self.dropped_responses = self.dropped_responses.saturating_add(1);
    }

    /// The value of register `address`, or `None` when the unit has no such register.
    pub fn read_register(&self, address: u8) -> Option<u16> {
        let view = registers::View {
            config: &self.config,
            hub: &self.unit.hub,
            finda: self
                .spool_end
                .finda(self.unit.hub_present(), self.unit.active().is_some()),
            feeders: &self.unit.feeders,
            lanes: &self.unit.lanes,
            fsensor: self.unit.fsensor,
            path_slot: self.unit.active().or(self.unit.selected),
            driving_slot: self.operation.driving_slot(),
            status: self.operation.status(),
            drive_errors: self.counters.drive_errors,
            tool_changes: &self.counters.tool_changes,
            failures: &self.counters.failures,
            fed_mm: &self.counters.fed_mm,
            dropped_responses: self.dropped_responses,
            bowden_learned_mm: self.bowden_learned_mm,
            lane_figures: &self.counters.lanes,
            used_centi: self.ledger.used_centi(),
            lanes_drifted: self.ledger.drifted(),
            // Right after an `S2`, the build of the revision it offered: what `S3` would report.
            build: crate::config::build_of(self.negotiation.offered.unwrap_or(self.config.version.revision)),
            now: self.now,
        };
        registers::read(&view, address)
    }

    /// Write `value` to register `address`; false (answered `R`) when the register is unknown or
    /// read-only or the value is out of range.
    pub fn write_register(&mut self, address: u8, value: u16) -> bool {
        let filament_readings = self.filament_readings();
        let mut target = registers::Target {
            config: &mut self.config,
            fsensor: &mut self.unit.fsensor,
            filament_readings,
            used_centi: self.ledger.used_centi_mut(),
        };
        let accepted = registers::write(&mut target, N, address, value);
        if accepted && registers::LEFT <= address && address < registers::LEFT + N as u8 {
            self.ledger.sync_used(&mut self.counters.lanes);
        }
        if accepted && address != registers::FSENSOR {
            self.settings_revision = self.settings_revision.wrapping_add(1);
        }
        accepted
    }

    /// The reading of each presence sensor that sees filament where the lanes say filament is
    /// (the hub's while a slot owns the hub path, a slot's while its tip is at least parked),
    /// for the threshold guard ([`registers::FilamentReadings`]). A reading counts only at or
    /// above the "on" threshold in force: a sensor stuck "present" below it (an "off" threshold
    /// no reading goes under) holds no write back.
    fn filament_readings(&self) -> registers::FilamentReadings {
        let mut readings = registers::NO_FILAMENT_READINGS;
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
        registers::changed_settings(&self.config, &Config::DEFAULT, &self.unit.hub, N, &mut settings);
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
            counters: self.counters,
            settings: self.settings(),
        }
    }

    /// Take back what a previous run kept, before the first step. Settings go through the
    /// register checks (a value out of range is dropped; the reciprocals of those the steps divide
    /// by are built as they come, not in the first move); the start-up check then compares the
    /// lanes with what the sensors show.
    pub fn restore(&mut self, snapshot: &Snapshot<N>) {
        for (slot, &lane) in snapshot.lanes.iter().enumerate() {
            self.unit.set_lane(slot, lane);
        }
        self.counters = snapshot.counters;
        self.ledger.restore(&snapshot.counters.lanes, &snapshot.lanes);
        self.fed_centi_beyond_mm = [0; N];
        // Twice: a pair of thresholds may only be valid once both are in.
        for _ in 0..2 {
            for &(address, value) in &snapshot.settings {
                self.write_register(address, value);
            }
        }
    }

    fn count_transition(&mut self, before: Status) {
        let after = self.operation.status();
        if after == before {
            return;
        }
        let slot = self.operation.phase().and_then(crate::phases::Phase::slot);
        self.ledger.lanes_seen(&self.unit.lanes, &mut self.counters.lanes);
        self.ledger.command_changed(
            self.operation.request.0,
            after,
            slot,
            &mut self.counters.lanes,
            self.now,
        );
        if after == Status::Finished {
            // What the printer's extruder moves from now on is evidence for the next command.
            self.unit.moved_by_printer = [0; N];
        }
        match after {
            Status::Failed(error) if error != ErrorCode::FILAMENT_EJECTED => {
                self.counters.drive_errors = self.counters.drive_errors.saturating_add(1);
                if let Some(count) = self
                    .operation
                    .phase()
                    .and_then(crate::phases::Phase::slot)
                    .and_then(|s| self.counters.failures.get_mut(s))
                {
                    *count = count.saturating_add(1);
                }
            }
            Status::Finished if self.operation.request.0 == RequestCode::Tool => {
                if let Some(count) = self
                    .counters
                    .tool_changes
                    .get_mut(usize::from(self.operation.request.1))
                {
                    *count = count.saturating_add(1);
                }
            }
            _ => {}
        }
    }

    /// The running phase drives its slot; a loaded slot follows the extruder through the tension
    /// sensor ([`follower`]); every other motor coasts. A slot that could not follow stops the
    /// running command too, braked at once ([`Runner::interrupt`]), and its failure is counted
    /// on that slot, not on the command's. `driving`: the slot the running command drives.
    fn drive_motors(&mut self, now: Instant, driving: Option<usize>, out: &mut Outputs<N>) {
        // A slot whose spool ended grips nothing: it is not followed.
        let allowed =
            !matches!(self.operation.status(), Status::Failed(_)) && self.spool_end.reported().is_none();
        let idle = matches!(self.operation.status(), Status::Finished);
        if let Some((slot, error)) = follower::follow(&mut self.unit, driving, allowed, now, &self.config)
            // A spool end fastened to the core, told from a tangle by the filament left: FINDA
            // reads empty instead of the jam error.
            && !self.spool_end.report_fastened(
                &self.unit,
                slot,
                idle,
                self.config.spool_m.get(slot).copied().unwrap_or(0),
                self.ledger.used_centi().get(slot).copied().unwrap_or(0),
            )
        {
            self.operation.interrupt(error, &mut self.unit, now);
            self.ledger.stalled(slot, error, &mut self.counters.lanes);
            self.counters.drive_errors = self.counters.drive_errors.saturating_add(1);
            if let Some(count) = self.counters.failures.get_mut(slot) {
                *count = count.saturating_add(1);
            }
        }
        for (motor, drive) in out.motors.iter_mut().zip(self.unit.drives.iter()) {
            *motor = drive.command();
        }
    }
}

/// `mm` whole millimetres and `centi` hundredths (below 100) after `more` hundredths more, the
/// millimetres saturating at `u32::MAX`.
fn add_centi(mm: u32, centi: u8, more: u32) -> (u32, u8) {
    let more_mm = more / 100;
    let centi = more - more_mm * 100 + u32::from(centi);
    let carry = u32::from(centi >= 100);
    // Below 100 after the carry; `more_mm + carry` is below 2³².
    (mm.saturating_add(more_mm + carry), (centi - carry * 100) as u8)
}

/// The version handshake as the unit sees it. Prusa's printer sends the same `S2` again after a
/// wrong answer, and `S3` only once `S2` matched (`protocol_logic.cpp` `ProcessVersionResponse`):
/// each repeated `S2` gets the next revision of the cycle ([`offered_revision`]), and the one
/// answered last before `S3` is the one the printer accepted.
#[derive(Debug, Clone, Copy, Default)]
struct Negotiation {
    /// `S2` requests answered in a row (in different steps), none other between.
    repeats: u8,
    /// The revision the last `S2` was answered with, while nothing but `S2` and `S3` followed:
    /// an `S3` now means the printer accepted it.
    offered: Option<u8>,
    /// The revision an `S2` of this step was answered with: that answer has not gone out yet, so
    /// an `S2` in the same step was queued before the printer heard it, and gets the same answer
    /// (a burst answered 4, 3, 2, 1, 0 could cost a printer its budget).
    answered_this_step: Option<u8>,
}

impl Negotiation {
    /// The answer to an `S2`, the cycle starting from `accepted`.
    fn offer(&mut self, accepted: u8) -> u8 {
        let revision = match self.answered_this_step {
            Some(revision) => revision,
            None => {
                let revision = offered_revision(accepted, self.repeats);
                self.repeats = self.repeats.wrapping_add(1);
                revision
            }
        };
        self.offered = Some(revision);
        self.answered_this_step = Some(revision);
        revision
    }

    /// Any request but `S2` ends a run of them; any but `S3` forgets the last offer.
    fn other_request(&mut self, request: &Request) {
        self.repeats = 0;
        self.answered_this_step = None;
        if !(request.code == RequestCode::Version && request.value == 3) {
            self.offered = None;
        }
    }
}

impl<const N: usize> Default for App<N> {
    fn default() -> Self {
        Self::new(Config::default())
    }
}

#[cfg(test)]
mod tests {
    use super::add_centi;

    /// The fed distance as a 64-bit sum of hundredths, divided for the register.
    fn dividing_add(total_centi: u64, more: u32) -> (u64, u32) {
        let total = total_centi + u64::from(more);
        (total, u32::try_from(total / 100).unwrap_or(u32::MAX))
    }

    #[test]
    fn the_fed_millimetres_carry_their_hundredths_as_a_64_bit_sum() {
        let steps = [0, 1, 99, 100, 101, 199, 200, 201, 65_535, 4_294_967_199, u32::MAX];
        let starts = [
            0u64,
            1,
            99,
            12_345,
            429_496_729_500,
            429_496_729_599,
            u64::from(u32::MAX) * 100 + 99,
        ];
        for start in starts {
            for more in steps {
                for again in steps {
                    let (mut total, mut mm, mut centi) = (
                        start,
                        u32::try_from(start / 100).unwrap_or(u32::MAX),
                        (start % 100) as u8,
                    );
                    for step in [more, again] {
                        let expected;
                        (total, expected) = dividing_add(total, step);
                        (mm, centi) = add_centi(mm, centi, step);
                        assert_eq!(mm, expected, "{start} + {more} + {again}");
                        assert!(centi < 100);
                    }
                }
            }
        }
    }
}
