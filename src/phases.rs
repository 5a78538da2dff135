//! The phase catalogue: the bounded motions and checks that commands are made of.
//!
//! Each [`Phase`] is one motion of one slot motor towards a goal the sensors confirm (or a check
//! of the sensors), with the MMU3 progress code that best describes it and the [`Budget`] it may
//! not exceed. [`step`] decides each step whether the goal is reached, asks the slot's drive for
//! the motion otherwise, and says whether the phase goes on, is done or failed (and with which
//! error). Commands ([`crate::commands`]) arrange phases into plans; the runner
//! ([`crate::runner`]) steps them.

use mmu_hal_port::Direction;
use mmu_protocol::{ErrorCode, ProgressCode};

use crate::config::{Config, Contract};
use crate::drive::{Budget, Motion};
use crate::time::Instant;
use crate::unit::{Lane, SensorId, Unit};

/// How far a slot whose tip nobody knows is fed to find out whether the slot sensor sees it, mm
/// (the sensor sits just after the drive gear).
const SLOT_PROBE_MM: i32 = 10;
/// How long a check may wait for the sensors to settle after start, ms.
const SENSOR_SETTLE_MS: u64 = 1000;
/// How long the Bowden tube must read compressed before the push into the extruder stops, ms:
/// the tip has met something (the gears, turning or idle, or a jam), and the push must stop
/// while the printer's own push still runs (one noisy reading is not enough).
const MET_CONFIRM_MS: u64 = 10;
/// How long the Bowden tube must read taut, pulled from the extruder's side against the braked
/// slot motor, before the gears count as holding the tip, ms. A tube only ever goes taut
/// that way when something pulls the filament on: a jam cannot, a stopped tube cannot.
const GRIP_CONFIRM_MS: u64 = 100;
/// How far the push into the extruder may go past the extra load distance (register 0x0b: how
/// far past the printer's sensor its gears are and the tip is to go), mm, to meet the gears.
const NOZZLE_PUSH_MARGIN_MM: u16 = 10;
/// How long after the push began the printer's own push may still pull the filament on, beyond
/// its nominal duration (extra load + 2 mm at the slow speed), ms: the printer starts it when it
/// sees its sensor and `P1c` together, the unit when it hears both, within a few ms.
const PRINTER_PUSH_MARGIN_MS: u64 = 600;

/// How long an unload waits for the printer to release the filament (its sensor off), ms, before
/// it fails with `8004` having pulled nothing: MMU 3.0.4's limit (`unload_to_finda.cpp`, 4000 ms
/// from the command's acceptance).
const RELEASE_WAIT_MS: u64 = 4000;
/// How far an unload pulls at the slow speed (register 0x14) once the printer has released the
/// filament, mm, in 3.0.4 mode: MMU 3.0.4's `fsensorToNozzleAvoidGrindUnload`, which helps the
/// printer relieve the filament.
const RELEASE_SLOW_MM: u16 = 20;

/// How long a printer that accepted 3.0.3 or older retracts when it helps an unload, ms, from its
/// first `Q0` that saw `P3`: 20 mm at 20 mm/s (Buddy `mmu2_config.h`
/// `MMU2_RETRY_UNLOAD_TO_FINDA_LENGTH`, `_FEED_RATE`; `mmu2_mk4.cpp` `HelpUnloadToFinda`), and
/// half a second for its planner to start the move.
const PRINTER_HELP_MS: u64 = 1500;

/// How long the printer may stay silent before a phase that depends on it holds its motor, ms.
/// While a command runs, Prusa's printer sends `Q0` one heartbeat (1 s, `heartBeatPeriod` in
/// `protocol_logic.h`) after its last exchange, the register poll right after, and `f` as soon as
/// its sensor changes; so a line quiet for longer means a request or an answer was lost and the
/// printer waits out its 2 s link timeout before it handshakes again: its `f` cannot arrive and
/// its co-feed stops (printer-truth §8). 100 ms above the heartbeat for the exchange in flight
/// and the printer's loop; at `P1c`'s 20 mm/s the unit then pushes at most about 22 mm past the
/// printer's last word, inside what the printer's own co-feed and extra push take up before the
/// slot motor could count as stalled.
pub const PRINTER_SILENT_MS: u64 = 1100;

/// One bounded step of a command. Its slot is a `u8` (a unit has at most [`crate::MAX_SLOTS`]):
/// a phase takes 4 bytes, and every plan, copied whole when a command starts, half the room.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Phase {
    /// `P5`: feed until the hub sensor sees the tip, at most `max_mm`.
    FeedToHub {
        /// The slot.
        slot: u8,
        /// Distance bound.
        max_mm: u16,
    },
    /// `P19`: pull back until the hub sensor clears, then the park distance.
    RetractToPark {
        /// The slot.
        slot: u8,
    },
    /// `P6`: fast feed through most of the Bowden tube; the printer's sensor must stay off.
    FeedThroughBowden {
        /// The slot.
        slot: u8,
    },
    /// `P1c`: slow feed until the printer's sensor triggers; the printer co-feeds.
    FeedToFsensor {
        /// The slot.
        slot: u8,
    },
    /// `P1c` after Retry of `8003`: the same slow feed from wherever the tip is past the hub
    /// sensor, at most the whole Bowden length plus the search distance (the tip may be anywhere
    /// in the tube: the user may have moved it, a slipping drive may have fed less than counted).
    SearchFsensor {
        /// The slot.
        slot: u8,
    },
    /// `P7`: push into the extruder's gears while the printer pushes with its own extruder, then
    /// hold and see the gears pull the filament on (the tube turns taut): only that shows the
    /// tip in the gears (a jam just before them stops it the same way).
    FeedToNozzle {
        /// The slot.
        slot: u8,
    },
    /// `P3`: pull back until the printer's sensor and then the hub sensor clear. With
    /// `await_release`, first wait, the motor free to turn, while the printer's gears may still
    /// grip the filament: until it reports its sensor off, or (3.0.3 and older) its help with
    /// its own extruder has had its time ([`still_gripped`]).
    UnloadToHub {
        /// The slot.
        slot: u8,
        /// Wait for the printer to release the filament before pulling.
        await_release: bool,
    },
    /// `P3`, for a slot only believed to hold the hub path (a stored lane): pull back at most the
    /// hub search distance, which leaves a parked filament in its drive gear whichever slot it
    /// is, until the hub sensor clears and proves the belief. Still seeing filament there is
    /// `8008`: someone has to look.
    ProveOwner {
        /// The slot.
        slot: u8,
    },
    /// `P19`, for a parked slot or one whose tip nobody knows (after `X42` or a wiped store),
    /// when another slot's feed stalls where the slot paths join: pull back the park distance
    /// (less if the slot sensor clears: the tip is at the drive gear), so a tip resting in the
    /// merge cannot block it.
    ClearMerge {
        /// The slot.
        slot: u8,
    },
    /// `P18`: pull back until the slot sensor clears.
    EjectFromSlot {
        /// The slot.
        slot: u8,
    },
    /// `P1a`: the sensors must be healthy and agree with the known lanes.
    CheckSensors,
    /// `E800c` until the user presses Continue.
    AwaitContinue,
}

impl Phase {
    /// The progress code the printer sees while this phase runs. Out of line: a dozen callers.
    #[inline(never)]
    pub const fn progress(self) -> ProgressCode {
        match self {
            Phase::FeedToHub { .. } => ProgressCode::FEEDING_TO_FINDA,
            Phase::RetractToPark { .. } | Phase::ClearMerge { .. } => ProgressCode::RETRACTING_FROM_FINDA,
            Phase::FeedThroughBowden { .. } => ProgressCode::FEEDING_TO_BONDTECH,
            Phase::FeedToFsensor { .. } | Phase::SearchFsensor { .. } => ProgressCode::FEEDING_TO_FSENSOR,
            Phase::FeedToNozzle { .. } => ProgressCode::FEEDING_TO_NOZZLE,
            Phase::UnloadToHub { .. } | Phase::ProveOwner { .. } => ProgressCode::UNLOADING_TO_FINDA,
            Phase::EjectFromSlot { .. } => ProgressCode::EJECTING_FILAMENT,
            Phase::CheckSensors => ProgressCode::HOMING,
            Phase::AwaitContinue => ProgressCode::ERR_WAITING_FOR_USER,
        }
    }

    /// The slot whose motor this phase drives.
    // Out of line: smaller in flash (measured with scripts/firmware-size.sh).
    #[inline(never)]
    pub const fn slot(self) -> Option<usize> {
        match self {
            Phase::FeedToHub { slot, .. }
            | Phase::RetractToPark { slot }
            | Phase::FeedThroughBowden { slot }
            | Phase::FeedToFsensor { slot }
            | Phase::SearchFsensor { slot }
            | Phase::FeedToNozzle { slot }
            | Phase::UnloadToHub { slot, .. }
            | Phase::ProveOwner { slot }
            | Phase::ClearMerge { slot }
            | Phase::EjectFromSlot { slot } => Some(slot as usize),
            Phase::CheckSensors | Phase::AwaitContinue => None,
        }
    }

    /// Where the slot's filament is once this phase is done.
    // Out of line: smaller in flash (measured with scripts/firmware-size.sh).
    #[inline(never)]
    const fn arrival(self) -> Option<Lane> {
        match self {
            Phase::FeedToHub { .. }
            | Phase::FeedThroughBowden { .. }
            | Phase::UnloadToHub { .. }
            | Phase::ProveOwner { .. } => Some(Lane::InHub),
            Phase::FeedToFsensor { .. } | Phase::SearchFsensor { .. } => Some(Lane::AtFsensor),
            Phase::FeedToNozzle { .. } => Some(Lane::Loaded),
            Phase::RetractToPark { .. } => Some(Lane::Parked),
            Phase::EjectFromSlot { .. } => Some(Lane::Empty),
            Phase::ClearMerge { .. } | Phase::CheckSensors | Phase::AwaitContinue => None,
        }
    }
}

/// How a motion phase moves: its direction, speed and how far it may go.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    direction: Direction,
    speed: u16,
    max_mm: u16,
    error: ErrorCode,
    /// Time on top of the nominal duration at `speed`: part of the way goes slower, ms.
    slower_ms: u32,
}

impl Bounds {
    /// The drive's budget: the distance, and twice the nominal duration plus slack.
    fn budget(&self, config: &Config) -> Budget {
        // At most 65 535 × 2000 + 65 535.
        let max_ms = u32::from(self.max_mm) * 2000 / u32::from(self.speed.max(1))
            + self.slower_ms
            + u32::from(config.phase_slack_ms);
        Budget {
            max_mm: self.max_mm,
            max_ms,
            max_still_ms: max_ms,
            error: self.error,
        }
    }
}

// Out of line: its table of bounds is one function rather than code inside the step.
#[inline(never)]
fn bounds(phase: Phase, config: &Config) -> Option<Bounds> {
    let forward = |speed, max_mm, error| {
        Some(Bounds {
            direction: Direction::Forward,
            speed,
            max_mm,
            error,
            slower_ms: 0,
        })
    };
    let reverse = |speed, max_mm, error| {
        Some(Bounds {
            direction: Direction::Reverse,
            speed,
            max_mm,
            error,
            slower_ms: 0,
        })
    };
    match phase {
        Phase::FeedToHub { max_mm, .. } => {
            forward(config.load_speed, max_mm, ErrorCode::FINDA_DIDNT_SWITCH_ON)
        }
        Phase::RetractToPark { .. } => reverse(
            config.load_speed,
            config.hub_search_mm.saturating_add(config.park_mm),
            ErrorCode::FINDA_DIDNT_SWITCH_OFF,
        ),
        Phase::FeedThroughBowden { .. } => forward(
            config.load_speed,
            config.bowden_mm.saturating_sub(config.bowden_slowdown_mm),
            ErrorCode::FSENSOR_DIDNT_SWITCH_ON,
        ),
        Phase::FeedToFsensor { .. } => forward(
            config.slow_speed,
            config.bowden_slowdown_mm.saturating_add(config.fsensor_search_mm),
            ErrorCode::FSENSOR_DIDNT_SWITCH_ON,
        ),
        Phase::SearchFsensor { .. } => forward(
            config.slow_speed,
            config.bowden_mm.saturating_add(config.fsensor_search_mm),
            ErrorCode::FSENSOR_DIDNT_SWITCH_ON,
        ),
        // Faster than the printer's push (its slow feed), so a tip its turning gears hold
        // compresses the tube at once and the push stops while they still pull.
        Phase::FeedToNozzle { .. } => forward(
            config.slow_speed.saturating_mul(2),
            config
                .extra_load_mm
                .saturating_mul(2)
                .saturating_add(NOZZLE_PUSH_MARGIN_MM),
            ErrorCode::MOVE_PULLEY_FAILED,
        ),
        Phase::UnloadToHub { .. } => reverse(
            config.unload_speed,
            config
                .bowden_mm
                .saturating_add(config.fsensor_search_mm)
                .saturating_add(config.hub_search_mm),
            ErrorCode::FINDA_DIDNT_SWITCH_OFF,
        )
        .map(|bounds| Bounds {
            // The slow start, twice its nominal duration as every bound.
            slower_ms: u32::from(RELEASE_SLOW_MM) * 2000 / u32::from(config.slow_speed.max(1)),
            ..bounds
        }),
        Phase::ClearMerge { .. } => reverse(config.load_speed, config.park_mm, ErrorCode::MOVE_PULLEY_FAILED),
        Phase::ProveOwner { .. } => reverse(
            config.load_speed,
            config.hub_search_mm,
            ErrorCode::FINDA_VS_EEPROM_DISREPANCY,
        ),
        Phase::EjectFromSlot { .. } => reverse(
            config.load_speed,
            config.eject_max_mm,
            ErrorCode::MOVE_PULLEY_FAILED,
        ),
        Phase::CheckSensors | Phase::AwaitContinue => None,
    }
}

/// The error a faulty sensor raises: the hub's sensors show INSPECT FINDA, a slot's sensors
/// show PULLEY CANNOT MOVE (the slot's drive needs a look).
// Out of line: smaller in flash (measured with scripts/firmware-size.sh).
#[inline(never)]
pub const fn sensor_fault_error(sensor: SensorId) -> ErrorCode {
    match sensor {
        SensorId::HubFilament | SensorId::HubTension | SensorId::HubCutter => ErrorCode::FINDA_FLICKERS,
        SensorId::SlotFilament(_) | SensorId::MotorHall(_) => ErrorCode::MOVE_PULLEY_FAILED,
    }
}

/// Bookkeeping of the running phase.
#[derive(Debug, Clone, Copy)]
pub struct PhaseRun {
    started: Instant,
    /// Odometry when the phase first started, kept across Retry: distance goals count from here.
    goal_from_centi: i32,
    /// Odometry at a milestone inside the phase (the hub cleared, the printer's sensor cleared).
    mark_centi: Option<i32>,
    /// Since when the Bowden tube reads compressed.
    compressed_since: Option<Instant>,
    /// Since when the Bowden tube reads taut.
    taut_since: Option<Instant>,
    /// The push into the extruder is over: the tip met something, or went its distance.
    pushed: bool,
    /// The budget of the motion in progress: when and where the drive's lease began, and what
    /// earlier leases of this attempt used (a hold ends a lease; the silence is not counted).
    lease: Lease,
    /// The motor is held while the printer is silent.
    held: bool,
    /// When the printer's `Q0` first saw this phase (it acts on the progress it sees).
    printer_saw: Option<Instant>,
    /// An attempt after a Retry: its distance goal counts from the first attempt.
    retried: bool,
}

/// What the leases of one phase attempt used of its budget.
#[derive(Debug, Clone, Copy)]
struct Lease {
    started: Instant,
    from_centi: i32,
    used_mm: u16,
    used_ms: u32,
}

impl Lease {
    fn new(now: Instant, odometry_centi: i32) -> Self {
        Lease {
            started: now,
            from_centi: odometry_centi,
            used_mm: 0,
            used_ms: 0,
        }
    }

    /// End the lease in progress at `now`, counting what it used.
    fn end(&mut self, now: Instant, odometry_centi: i32) {
        let mm = odometry_centi.abs_diff(self.from_centi) / 100;
        self.used_mm = self.used_mm.saturating_add(u16::try_from(mm).unwrap_or(u16::MAX));
        self.used_ms = self
            .used_ms
            .saturating_add(crate::drive::millis_u32(now.millis_since(self.started)));
    }

    /// Begin a new lease at `now`: what is left of `full`.
    fn resume(&mut self, full: Budget, now: Instant, odometry_centi: i32) -> Budget {
        self.started = now;
        self.from_centi = odometry_centi;
        let max_ms = full.max_ms.saturating_sub(self.used_ms);
        Budget {
            max_mm: full.max_mm.saturating_sub(self.used_mm),
            max_ms,
            max_still_ms: full.max_still_ms.min(max_ms),
            error: full.error,
        }
    }
}

impl PhaseRun {
    /// A phase attempt starting at `now`, its distance goal counting from `goal_from_centi`, with
    /// the filament at `odometry_centi`.
    // Out of line: two callers in the step (measured smaller).
    #[inline(never)]
    fn new(now: Instant, goal_from_centi: i32, odometry_centi: i32) -> Self {
        PhaseRun {
            started: now,
            goal_from_centi,
            mark_centi: None,
            compressed_since: None,
            taut_since: None,
            pushed: false,
            lease: Lease::new(now, odometry_centi),
            held: false,
            printer_saw: None,
            retried: false,
        }
    }

    /// Where the distance goal of this phase counts from (kept for the attempt after Retry).
    pub fn goal_from_centi(&self) -> i32 {
        self.goal_from_centi
    }

    /// How far the filament moved from the goal start to `odometry_centi`, forward positive
    /// (1/100 mm).
    pub fn fed_centi(&self, odometry_centi: i32) -> i32 {
        odometry_centi.saturating_sub(self.goal_from_centi)
    }
}

/// What phases of one command learn and pass on to the later ones.
#[derive(Debug, Clone, Copy, Default)]
pub struct Notes {
    /// Set by Retry: the user has looked, trust what the sensors say now over the known lanes.
    pub trust_sensors: bool,
    /// Odometry of a slot when the hub sensor last saw its tip leave, so parking that follows an
    /// unload measures from the hub and not from where the unload stopped.
    pub hub_cleared: Option<(usize, i32)>,
    /// The park position was measured from a point the hub sensor did not confirm.
    pub park_unsure: bool,
    /// What the unit knows of the link to the printer.
    pub printer: PrinterLink,
}

/// What the unit knows of the link to the printer, for the phases that depend on it.
#[derive(Debug, Clone, Copy, Default)]
pub struct PrinterLink {
    /// When a byte from the printer last arrived.
    pub heard: Instant,
    /// When the printer's `Q0` was last answered with the progress of a running phase.
    pub polled: Instant,
    /// False from a broken frame or the start of a handshake (`S0`) until the printer reports its
    /// sensor again (`f`) or polls (`Q0`): a frame was lost, and the printer's `f` with it, perhaps;
    /// it sends `f` again at the end of its handshake, before its next `Q0`
    /// (`protocol_logic.cpp` `StartSeqStep`, printer-truth §8).
    pub in_sync: bool,
}

impl PrinterLink {
    /// True when the printer may have a sensor change the unit has not heard: silent for longer
    /// than [`PRINTER_SILENT_MS`], or out of sync.
    pub fn in_doubt(&self, now: Instant) -> bool {
        !self.in_sync || now.millis_since(self.heard) > PRINTER_SILENT_MS
    }
}

/// What a phase did in one step.
pub enum Outcome {
    /// Still on its way.
    Continue,
    /// Done: the next phase may start in the same step.
    Done,
    /// Stopped on an error.
    Fail(ErrorCode),
    /// The feed stalled where the slot paths join and these other slots, whose tips nobody
    /// knows, may be what blocks it: clear them out of the merge, then feed again.
    Blocked(SlotSet),
}

/// A set of slots.
pub type SlotSet = u8;

/// Where a motion phase stands against its goal.
enum Goal {
    Reached,
    Drive,
    /// Drive at this speed instead of the phase's own.
    DriveAt(u16),
    /// Brake and wait (the lease ends: waiting counts against no bound).
    Hold,
    /// Let the motor turn freely and wait: something else moves the filament (the lease ends).
    Yield,
}

/// Advance `phase` by one step. `run` is its bookkeeping (`None` when it starts, or starts again
/// after Retry with its distance goal counting from `resume_goal_from`).
pub fn step<const N: usize>(
    phase: Phase,
    run: &mut Option<PhaseRun>,
    resume_goal_from: Option<i32>,
    notes: &mut Notes,
    unit: &mut Unit<N>,
    now: Instant,
    config: &Config,
) -> Outcome {
    match phase.slot() {
        Some(slot) => step_motion(phase, slot, run, resume_goal_from, notes, unit, now, config),
        None if phase == Phase::AwaitContinue => Outcome::Fail(ErrorCode::FILAMENT_EJECTED),
        None => check_sensors(run, notes, unit, now),
    }
}

#[allow(clippy::too_many_arguments)]
fn step_motion<const N: usize>(
    phase: Phase,
    slot: usize,
    run: &mut Option<PhaseRun>,
    resume_goal_from: Option<i32>,
    notes: &mut Notes,
    unit: &mut Unit<N>,
    now: Instant,
    config: &Config,
) -> Outcome {
    let Some(bounds) = bounds(phase, config) else {
        return Outcome::Fail(ErrorCode::INTERNAL);
    };
    let (Some(feeder), Some(drive)) = (unit.feeders.get(slot), unit.drives.get_mut(slot)) else {
        return Outcome::Fail(ErrorCode::INVALID_TOOL);
    };
    let odometry = feeder.odometry_centi();
    let run = match run {
        Some(run) => run,
        None => {
            drive.begin(bounds.budget(config), feeder, now);
            let run = run.insert(PhaseRun::new(now, resume_goal_from.unwrap_or(odometry), odometry));
            run.retried = resume_goal_from.is_some();
            run
        }
    };
    let toward_goal_mm = match bounds.direction {
        Direction::Forward => (odometry - run.goal_from_centi) / 100,
        Direction::Reverse => (run.goal_from_centi - odometry) / 100,
    };
    if let Some(fault) = [
        SensorId::MotorHall(slot),
        SensorId::HubFilament,
        SensorId::SlotFilament(slot),
    ]
    .into_iter()
    .find(|&id| unit.sensor(id).is_some_and(|s| s.fault().is_some()))
    {
        return Outcome::Fail(sensor_fault_error(fault));
    }
    let Some(hub) = unit.hub_present() else {
        return Outcome::Continue;
    };
    let Some(slot_sees) = unit.feeders.get(slot).and_then(|f| f.filament.present()) else {
        return Outcome::Continue;
    };

    let goal = match phase {
        Phase::FeedToHub { .. } => {
            if hub {
                Goal::Reached
            } else if !slot_sees && (unit.lane(slot) != Lane::Unknown || toward_goal_mm >= SLOT_PROBE_MM) {
                // An empty slot: nothing to feed (a tip of unknown position may rest between the
                // drive gear and the slot sensor: a short feed first shows it).
                return Outcome::Fail(ErrorCode::FINDA_DIDNT_SWITCH_ON);
            } else if !slot_sees {
                Goal::Drive
            } else {
                // Known (and persisted) before the tip leaves the park position, so a restart
                // mid-way knows whose filament may be in the hub path.
                unit.set_lane(slot, Lane::InHub);
                unit.proven_owner = Some(slot);
                if let Some(clear) = unit.clear_of_merge.get_mut(slot) {
                    *clear = false;
                }
                Goal::Drive
            }
        }
        Phase::RetractToPark { .. } => match (hub, run.mark_centi.or(hub_mark(notes, slot))) {
            (true, _) => Goal::Drive,
            (false, None) => {
                // Where the hub cleared: the park distance counts from here, also after a Retry.
                // A retract that starts with the hub already clear (after a Retry) did not see
                // where: the tip ends somewhere behind its park position.
                run.mark_centi = Some(odometry);
                notes.hub_cleared = Some((slot, odometry));
                notes.park_unsure |= run.started == now;
                Goal::Drive
            }
            (false, Some(mark)) if (mark - odometry) / 100 >= i32::from(config.park_mm) => Goal::Reached,
            (false, Some(_)) => Goal::Drive,
        },
        Phase::FeedThroughBowden { .. } => {
            if unit.fsensor_triggered() {
                return Outcome::Fail(ErrorCode::FSENSOR_TOO_EARLY);
            }
            if toward_goal_mm >= i32::from(bounds.max_mm) {
                Goal::Reached
            } else {
                Goal::Drive
            }
        }
        Phase::FeedToFsensor { .. } | Phase::SearchFsensor { .. } => {
            if !unit.fsensor_triggered() {
                Goal::Drive
            } else if notes.printer.polled > run.started {
                Goal::Reached
            } else {
                // The printer pushes its extruder for the load only once it has seen `P1c` with
                // its sensor triggered (`OnMMUProgressMsgSame`, printer-truth §8): until its next
                // `Q0` has seen this phase, the tip waits at the sensor.
                Goal::Hold
            }
        }
        Phase::FeedToNozzle { .. } => match unit.hub.tension.reading() {
            Some(tension) => match push_into_gears(run, tension, toward_goal_mm, now, config) {
                Ok(goal) => goal,
                Err(error) => return Outcome::Fail(error),
            },
            // Nothing else shows the gears holding the tip: no load is reported done blind.
            None if unit.hub.tension.fault().is_some() => {
                return Outcome::Fail(sensor_fault_error(SensorId::HubTension));
            }
            None => Goal::Hold,
        },
        Phase::UnloadToHub { await_release, .. } => {
            let waiting = await_release && run.mark_centi.is_none();
            let gripped = match waiting && unit.fsensor_triggered() {
                true => still_gripped(run, notes, now, config),
                false => Ok(false),
            };
            if let Err(error) = gripped {
                return Outcome::Fail(error);
            }
            if gripped == Ok(true) {
                Goal::Yield
            } else {
                if waiting {
                    // Released: the pull starts here, and so does its check distance, unless an
                    // earlier attempt pulled already (a Retry does not start the count again: a
                    // stuck sensor must not let every Retry pull the check distance anew).
                    run.mark_centi = Some(odometry);
                    if !run.retried {
                        run.goal_from_centi = odometry;
                    }
                }
                match pull_out_of_printer(run, unit, hub, odometry, config) {
                    Ok(Goal::Reached) => {
                        notes.hub_cleared = Some((slot, odometry));
                        Goal::Reached
                    }
                    Ok(goal) => goal,
                    Err(error) => return Outcome::Fail(error),
                }
            }
        }
        Phase::ProveOwner { .. } => {
            if !hub && !unit.fsensor_triggered() {
                notes.hub_cleared = Some((slot, odometry));
                unit.proven_owner = Some(slot);
                Goal::Reached
            } else if unit.fsensor_triggered() || toward_goal_mm >= i32::from(bounds.max_mm) {
                // Filament in the printer, or pulled as far as is safe (Retry adds nothing).
                return Outcome::Fail(ErrorCode::FINDA_VS_EEPROM_DISREPANCY);
            } else {
                Goal::Drive
            }
        }
        Phase::ClearMerge { .. } => {
            if !slot_sees || toward_goal_mm >= i32::from(config.park_mm) {
                if let Some(clear) = unit.clear_of_merge.get_mut(slot) {
                    *clear = true;
                }
                Goal::Reached
            } else {
                Goal::Drive
            }
        }
        Phase::EjectFromSlot { .. } => {
            if slot_sees {
                Goal::Drive
            } else {
                Goal::Reached
            }
        }
        Phase::CheckSensors | Phase::AwaitContinue => Goal::Reached,
    };

    let tension = unit.hub.tension.reading();
    let (Some(feeder), Some(drive)) = (unit.feeders.get(slot), unit.drives.get_mut(slot)) else {
        return Outcome::Fail(ErrorCode::INTERNAL);
    };
    let motion = match goal {
        Goal::Reached => {
            drive.brake(now);
            let lane = match phase.arrival() {
                Some(Lane::Parked) if notes.park_unsure => Some(Lane::Unknown),
                lane => lane,
            };
            if let Some(lane) = lane {
                unit.set_lane(slot, lane);
            }
            return Outcome::Done;
        }
        // The slot sensor sits just after the drive gear: a tip pulled back past it is about to
        // leave the gear. Only an eject means to go there; any other pull back stops.
        Goal::Drive | Goal::DriveAt(_)
            if bounds.direction == Direction::Reverse
                && !slot_sees
                && !matches!(phase, Phase::EjectFromSlot { .. } | Phase::ClearMerge { .. }) =>
        {
            drive.brake(now);
            if let (Phase::RetractToPark { .. }, false) = (phase, hub) {
                // Behind its park position, at the gear: where exactly, nobody knows.
                unit.set_lane(slot, Lane::Unknown);
                return Outcome::Done;
            }
            // Still filament in the hub with this tip at its gear: the hub sensor is wrong, or
            // another filament is there. Not parked.
            return Outcome::Fail(bounds.error);
        }
        Goal::Drive if !(depends_on_printer(phase) && notes.printer.in_doubt(now)) => Motion::Run {
            direction: bounds.direction,
            speed: bounds.speed,
        },
        Goal::DriveAt(speed) => Motion::Run {
            direction: bounds.direction,
            speed,
        },
        Goal::Yield => return yield_motor(run, unit, slot, odometry, now),
        Goal::Drive | Goal::Hold => {
            // Hold: the phase waits, or the printer's `f` may be lost and its co-feed has
            // stopped. The lease ends, so the hold counts against no bound; what the phase used
            // so far stays counted.
            if !run.held {
                run.lease.end(now, odometry);
                run.held = true;
            }
            drive.brake(now);
            return Outcome::Continue;
        }
    };
    if run.held {
        run.held = false;
        drive.begin(
            run.lease.resume(bounds.budget(config), now, odometry),
            feeder,
            now,
        );
    }
    match drive.run(motion, feeder, tension, now, config) {
        Ok(()) => Outcome::Continue,
        Err(ErrorCode::STALLED_PULLEY) if matches!(phase, Phase::FeedToHub { .. }) => {
            match merge_suspects(unit, slot) {
                0 => Outcome::Fail(ErrorCode::STALLED_PULLEY),
                suspects => Outcome::Blocked(suspects),
            }
        }
        Err(error) => Outcome::Fail(first_cause(phase, error, unit.fsensor_triggered())),
    }
}

/// While an unload waits for the printer to release the filament and its sensor still reads it:
/// whether its gears may still grip it (keep waiting), or `8004`.
///
/// A printer that accepted 3.0.4 reports its sensor off once it has released the filament: after
/// [`RELEASE_WAIT_MS`] without that, `8004`, nothing pulled (MMU 3.0.4). A printer that accepted
/// 3.0.3 or older helps an unload it did not send as `U0`/`T` when its `Q0` sees `P3`, and after
/// the Retry of `8004`: once its help has had its time ([`PRINTER_HELP_MS`] from that `Q0`), or
/// at the latest after [`RELEASE_WAIT_MS`], the unit pulls, as MMU 3.0.3 does.
fn still_gripped(
    run: &mut PhaseRun,
    notes: &Notes,
    now: Instant,
    config: &Config,
) -> Result<bool, ErrorCode> {
    if notes.printer.polled > run.started && run.printer_saw.is_none() {
        run.printer_saw = Some(notes.printer.polled);
    }
    let waited_out = now.millis_since(run.started) >= RELEASE_WAIT_MS;
    match config.version.contract() {
        Contract::AwaitRelease if waited_out => Err(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF),
        Contract::AwaitRelease => Ok(true),
        Contract::PullAtOnce => {
            let helped = run
                .printer_saw
                .is_some_and(|saw| now.millis_since(saw) >= PRINTER_HELP_MS);
            Ok(!(helped || waited_out))
        }
    }
}

/// `P3` once the pull has begun: on until the printer's sensor and then the hub sensor clear. The
/// printer's sensor must clear within the check distance of where the pull began (Retry does not
/// start the count again unless it waited for the printer), and never after the tip has left
/// the hub: pulling on would drag the filament out of its drive gear (MMU 3.0.3 checks too). A
/// printer that accepted 3.0.4 gets the first [`RELEASE_SLOW_MM`] at the slow speed.
fn pull_out_of_printer<const N: usize>(
    run: &PhaseRun,
    unit: &Unit<N>,
    hub: bool,
    odometry: i32,
    config: &Config,
) -> Result<Goal, ErrorCode> {
    let pulled_mm = (run.goal_from_centi - odometry) / 100;
    let stuck = pulled_mm >= i32::from(config.unload_check_mm) || !hub;
    Ok(match (unit.fsensor_triggered(), hub) {
        (true, _) if stuck => return Err(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF),
        (false, false) => Goal::Reached,
        _ if config.version.contract() == Contract::AwaitRelease
            && pulled_mm < i32::from(RELEASE_SLOW_MM) =>
        {
            Goal::DriveAt(config.slow_speed)
        }
        _ => Goal::Drive,
    })
}

/// Let `slot`'s motor turn freely while the phase waits: the lease ends, so the wait counts
/// against no bound (what the phase used so far stays counted).
fn yield_motor<const N: usize>(
    run: &mut PhaseRun,
    unit: &mut Unit<N>,
    slot: usize,
    odometry: i32,
    now: Instant,
) -> Outcome {
    if !run.held {
        run.lease.end(now, odometry);
        run.held = true;
    }
    if let Some(drive) = unit.drives.get_mut(slot) {
        drive.release(now);
    }
    Outcome::Continue
}

/// The other slots with filament that rest before the hub (parked, or nobody knows where: lanes
/// wiped) and were not pulled out of the merge since they were last fed: one of them may rest
/// where the slot paths join and block `slot`'s feed (a park counted by a slipping drive falls
/// short, an unknown tip may be anywhere).
fn merge_suspects<const N: usize>(unit: &Unit<N>, slot: usize) -> SlotSet {
    (0..N)
        .filter(|&other| other != slot && matches!(unit.lane(other), Lane::Unknown | Lane::Parked))
        .filter(|&other| !unit.clear_of_merge.get(other).copied().unwrap_or(true))
        .filter(|&other| unit.feeders.get(other).and_then(|f| f.filament.present()) != Some(false))
        .fold(0, |set, other| set | (1 << other))
}

/// The error that names what the user must look at. A motor stopped on its way to the printer's
/// sensor (`P6`, `P1c`) stopped because the filament did not get there: a jam in the Bowden
/// tube, or the tip pressed into the printer's idle extruder because its sensor never triggered
/// (or was never heard). That is FSENSOR DIDNT TRIGG. (`8003`), whose screen sends the user to the
/// tube and the printer's sensor; PULLEY CANNOT MOVE (`8047`) would send them to the slot motor,
/// which moved the filament all the way from the hub. MMU 3.0.3 reports `8003` here too: it has
/// no pulley stall detection and runs out its planned distance (`feed_to_bondtech.cpp`).
///
/// Likewise an unload stopped while the printer's sensor still reads filament stopped against
/// the printer's gears: FSENSOR DIDNT CLEAR (`8004`), as MMU 3.0.3 reports it after the check
/// distance, and whose Retry makes the printer help with its own extruder (Buddy `mmu2_mk4.cpp`
/// `CheckUserInput`: `HelpUnloadToFinda` on `FSENSOR_DIDNT_SWITCH_OFF`).
fn first_cause(phase: Phase, error: ErrorCode, fsensor: bool) -> ErrorCode {
    let towards_fsensor = matches!(
        phase,
        Phase::FeedThroughBowden { .. } | Phase::FeedToFsensor { .. } | Phase::SearchFsensor { .. }
    );
    match (phase, error) {
        (_, ErrorCode::STALLED_PULLEY) if towards_fsensor => ErrorCode::FSENSOR_DIDNT_SWITCH_ON,
        (Phase::UnloadToHub { .. }, ErrorCode::STALLED_PULLEY) if fsensor => {
            ErrorCode::FSENSOR_DIDNT_SWITCH_OFF
        }
        _ => error,
    }
}

/// The phases whose progress rests on the printer: `P1c` ends on its `f1` while it co-feeds,
/// `P7` pushes into its extruder as it takes the filament.
const fn depends_on_printer(phase: Phase) -> bool {
    matches!(
        phase,
        Phase::FeedToFsensor { .. } | Phase::SearchFsensor { .. } | Phase::FeedToNozzle { .. }
    )
}

/// `P7`, with a tension reading. Push until the tube reads compressed (the tip met the gears,
/// turning or idle, or a jam) or the push distance is gone, then hold: the printer pushes the
/// extra load distance + 2 mm after its sensor triggers (less on the MK3.5, whose sensor reports
/// late), longer than the unit pushes, so gears that hold the tip pull the tube taut against the
/// braked motor. Taut for [`GRIP_CONFIRM_MS`] is the only proof. None by the end of the
/// printer's push is `8003`: the filament did not get into the extruder (a jam just before the
/// gears, idle gears, a printer that never pushed), and Retry runs `P1c` again, whose `Q0`
/// makes the printer push again.
fn push_into_gears(
    run: &mut PhaseRun,
    tension: u16,
    pushed_mm: i32,
    now: Instant,
    config: &Config,
) -> Result<Goal, ErrorCode> {
    if taut_for(run, tension, now, config) >= GRIP_CONFIRM_MS {
        return Ok(Goal::Reached);
    }
    if !run.pushed {
        let met = compressed_for(run, tension, now, config) >= MET_CONFIRM_MS;
        let push_mm = config.extra_load_mm.saturating_add(NOZZLE_PUSH_MARGIN_MM);
        run.pushed = met || pushed_mm >= i32::from(push_mm);
    }
    if !run.pushed {
        return Ok(Goal::Drive);
    }
    let printer_push_ms = u64::from(config.extra_load_mm.saturating_add(2)) * 1000
        / u64::from(config.slow_speed.max(1))
        + PRINTER_PUSH_MARGIN_MS;
    if now.millis_since(run.started) > printer_push_ms {
        Err(ErrorCode::FSENSOR_DIDNT_SWITCH_ON)
    } else {
        Ok(Goal::Hold)
    }
}

/// How long the Bowden tube has read taut past the follower's deadband (pulled from the
/// extruder's side), ms. A reading at the supply rail is a loose wire, not a pull.
// Out of line: smaller in flash (measured with scripts/firmware-size.sh).
#[inline(never)]
fn taut_for(run: &mut PhaseRun, tension: u16, now: Instant, config: &Config) -> u64 {
    let taut = u32::from(tension) > u32::from(config.tension_neutral) + u32::from(config.tension_deadband)
        && tension < crate::sensor::RAIL_HIGH;
    run.taut_since = if taut { run.taut_since.or(Some(now)) } else { None };
    run.taut_since.map_or(0, |since| now.millis_since(since))
}

/// How long the Bowden tube has read compressed by more than half the follower's deadband, ms:
/// the push stops as soon as the tip meets something, so the printer's push has the most left to
/// pull (stopping early is the safe side: the tip may fall short, then no grip shows and Retry
/// pushes again).
fn compressed_for(run: &mut PhaseRun, tension: u16, now: Instant, config: &Config) -> u64 {
    let compressed =
        u32::from(tension) + u32::from(config.tension_deadband / 2) < u32::from(config.tension_neutral);
    run.compressed_since = if compressed {
        run.compressed_since.or(Some(now))
    } else {
        None
    };
    run.compressed_since.map_or(0, |since| now.millis_since(since))
}

fn hub_mark(notes: &Notes, slot: usize) -> Option<i32> {
    notes
        .hub_cleared
        .filter(|&(cleared, _)| cleared == slot)
        .map(|(_, odometry)| odometry)
}

/// `P1a`: every sensor healthy, and the hub sensor agrees with the known lanes.
fn check_sensors<const N: usize>(
    run: &mut Option<PhaseRun>,
    notes: &Notes,
    unit: &mut Unit<N>,
    now: Instant,
) -> Outcome {
    if let Some(fault) = unit.first_fault() {
        return Outcome::Fail(sensor_fault_error(fault));
    }
    // Every sensor must have settled: a reading, or a fault (a sensor stuck at a rail is called
    // faulty only after the rail timeout, so an early check would miss it).
    let unsettled = (0..Unit::<N>::SENSOR_COUNT)
        .map(SensorId::from_index)
        .find(|&id| unit.sensor(id).is_some_and(|s| s.reading().is_none()));
    let hub = unit.hub_present();
    if let (Some(_), _) | (None, None) = (unsettled, hub) {
        let started = run.get_or_insert(PhaseRun::new(now, 0, 0)).started;
        if now.millis_since(started) > SENSOR_SETTLE_MS {
            return Outcome::Fail(unsettled.map_or(ErrorCode::FINDA_FLICKERS, sensor_fault_error));
        }
        return Outcome::Continue;
    }
    let Some(hub) = hub else {
        return Outcome::Continue;
    };
    // At most one slot can be past its park position: stored lanes that say otherwise are
    // not to be believed. After Retry they are forgotten and the hub sensor decides.
    if (0..N).filter(|&slot| unit.lane(slot).owns_hub()).count() > 1 {
        if !notes.trust_sensors {
            return Outcome::Fail(ErrorCode::FINDA_VS_EEPROM_DISREPANCY);
        }
        for slot in 0..N {
            if unit.lane(slot).owns_hub() {
                unit.set_lane(slot, Lane::Unknown);
            }
        }
    }
    match (hub, unit.active()) {
        (true, None) => return Outcome::Fail(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
        // The user has looked: the slot's tip is somewhere before the hub sensor. It keeps the
        // path until the next command parks it from there.
        (false, Some(slot)) if notes.trust_sensors => unit.set_lane(slot, Lane::InHub),
        (false, Some(_)) => return Outcome::Fail(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
        _ => {}
    }
    for slot in 0..N {
        let sees = unit.feeders.get(slot).and_then(|f| f.filament.present());
        match (unit.lane(slot), sees) {
            (Lane::Unknown | Lane::Parked, Some(false)) => unit.set_lane(slot, Lane::Empty),
            (Lane::Empty, Some(true)) => unit.set_lane(slot, Lane::Unknown),
            _ => {}
        }
    }
    Outcome::Done
}
