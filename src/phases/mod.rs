//! The phase catalogue: the bounded motions and checks that commands are made of.
//!
//! Each [`Phase`] is one motion of one slot motor towards a goal the sensors confirm (or a check
//! of the sensors), with the MMU3 progress code that best describes it and the [`Budget`] it may
//! not exceed. [`step`] decides each step whether the goal is reached, asks the slot's drive for
//! the motion otherwise, and says whether the phase goes on, is done or failed (and with which
//! error). Commands ([`crate::commands`]) arrange phases into plans; the runner
//! ([`crate::runner`]) steps them.
//!
//! Each motion phase is one type with one block, its goal, bounds, progress code, what it
//! learns and the error its stop means together ([`MotionPhase`]), as Prusa keeps a
//! sub-automaton a file; the types sit in their family's module: `feed.rs` (slot to hub),
//! `unload.rs` (back to the hub, the park position, out of the slot; `release.rs` tells them
//! when the printer has let go), `load.rs` (through the Bowden tube into the printer's extruder),
//! `home.rs` (a lane at its presence sensor), and the checks in `check.rs`. This module holds
//! what they share: the motion step (sensor faults, the guard at the slot sensor, hold and
//! yield, the drive), the one place a [`Phase`] meets its type (`motion!`), and the one place
//! where what a phase learned (a `Milestone`) is written into the unit.

mod check;
mod feed;
mod home;
mod load;
mod release;
mod run;
mod unload;

use mmu_hal_port::Direction;
use mmu_protocol::{ErrorCode, ProgressCode};

use crate::config::Config;
use crate::drive::{Budget, Motion};
use crate::feeder::distance_centi;
use crate::time::Instant;
use crate::unit::{Lane, SensorId, Unit};

pub use release::UnloadStuck;
pub use run::PhaseRun;

use check::Check;

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

/// The longest a phase may drive its motor without a revolution, ms (at the speeds where a
/// revolution takes less than a third of it; see [`Bounds::budget`]). A motor that turns shows a
/// revolution every `mm_per_rev_centi` (2 mm: 21 ms at the load speed, 100 ms at the slow one),
/// and starts from rest well within a second; one that shows none for 3 s is not turning. The
/// stall rule alone does not catch it when it is weak (a long `stall_timeout_ms`, up to 10 s; a
/// duty held below `stall_min_duty`), and a phase's time budget is up to about 42 s: a seized
/// motor whose Hall sensor is stuck between its thresholds (no edge, and no rail to report as a
/// fault) would be driven that long. The same as the tension follower's [`crate::follower::STILL_MS`].
pub const STILL_MS: u32 = 3000;

/// One bounded step of a command. Its slot is a `u8` (a unit has at most [`crate::MAX_SLOTS`]):
/// a phase takes 4 bytes, and every plan, copied whole when a command starts, half the room.
/// Each motion variant's goal, bounds and errors are its type's, in the module named below.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Phase {
    /// `P5` (`feed.rs`): feed until the hub sensor sees the tip, at most `max_mm`.
    FeedToHub {
        /// The slot.
        slot: u8,
        /// Distance bound.
        max_mm: u16,
    },
    /// `P19` (`unload.rs`): pull back until the hub sensor clears, then the park distance.
    RetractToPark {
        /// The slot.
        slot: u8,
    },
    /// `P6` (`load.rs`): fast feed through most of the Bowden tube; the printer's sensor must
    /// stay off.
    FeedThroughBowden {
        /// The slot.
        slot: u8,
    },
    /// `P1c` (`load.rs`): slow feed until the printer's sensor triggers; the printer co-feeds.
    FeedToFsensor {
        /// The slot.
        slot: u8,
    },
    /// `P1c` after Retry of `8003` (`load.rs`): the same slow feed from wherever the tip is past
    /// the hub sensor, at most the whole Bowden length plus the search distance (the tip may be
    /// anywhere in the tube: the user may have moved it, a slipping drive may have fed less than
    /// counted).
    SearchFsensor {
        /// The slot.
        slot: u8,
    },
    /// `P7` (`load.rs`): push into the extruder's gears while the printer pushes with its own
    /// extruder, then hold and see the gears pull the filament on (the tube turns taut): only
    /// that shows the tip in the gears (a jam just before them stops it the same way).
    FeedToNozzle {
        /// The slot.
        slot: u8,
    },
    /// `P3` (`unload.rs`): pull back until the printer's sensor and then the hub sensor clear,
    /// feeling first while the printer's sensor reads filament. In the strict mode (MMU 3.0.4's
    /// unload, simulator only), with `await_release`, first wait, the motor free to turn: until
    /// the printer reports its sensor off, or (3.0.3 and older) its help has had its time.
    UnloadToHub {
        /// The slot.
        slot: u8,
        /// Wait for the printer to release the filament before pulling.
        await_release: bool,
    },
    /// `P3` (`unload.rs`), for a slot only believed to hold the hub path (a stored lane): pull
    /// back, stopped at the slot sensor (a filament that does not hold the path stays in its drive
    /// gear: `8008`, someone has to look), until the hub sensor clears or the slot sensor still
    /// sees filament after the longest slot path (either proves the belief); then on as an
    /// unload to the hub sensor.
    ProveOwner {
        /// The slot.
        slot: u8,
    },
    /// `P3` (`feed.rs`), before [`Phase::ProveOwner`], while the printer's sensor reads filament:
    /// first wait for the printer to report it off; still on, push the believed slot forward a
    /// few millimetres, which is safe whichever slot it is. Its filament meeting the printer's
    /// gears compresses the Bowden tube (the tension sensor) and proves the belief; a slot that
    /// does not hold the path moves freely, short of the merge: `8008`.
    PushProof {
        /// The slot.
        slot: u8,
    },
    /// `P19` (`feed.rs`), for a parked slot or one whose tip nobody knows (after `X42` or a wiped
    /// store), when another slot's feed stalls where the slot paths join: pull back the park
    /// distance (less if the slot sensor clears: the tip is at the drive gear), so a tip resting
    /// in the merge cannot block it.
    ClearMerge {
        /// The slot.
        slot: u8,
    },
    /// `P19` (`home.rs`), without a hub sensor: pull back until the slot's presence sensor
    /// clears, where its tip is known again.
    HomeLane {
        /// The slot.
        slot: u8,
    },
    /// `P19` (`home.rs`), after [`Phase::HomeLane`]: feed on to the park position.
    FeedToPark {
        /// The slot.
        slot: u8,
    },
    /// `P18` (`unload.rs`): pull back until the slot sensor clears.
    EjectFromSlot {
        /// The slot.
        slot: u8,
    },
    /// `P1a` (`check.rs`): the sensors must be healthy and agree with the known lanes.
    CheckSensors,
    /// `E800c` (`check.rs`) until the user presses Continue.
    AwaitContinue,
}

/// Runs `$body` with `$p` bound to the motion type of `$phase` (in its family's module), or
/// `$check` for a check: the one place a phase meets its type.
macro_rules! motion {
    ($phase:expr, $p:ident => $body:expr, check => $check:expr) => {
        match $phase {
            Phase::FeedToHub { max_mm, .. } => {
                let $p = feed::ToHub { max_mm };
                $body
            }
            Phase::ClearMerge { .. } => {
                let $p = feed::ClearMerge;
                $body
            }
            Phase::PushProof { .. } => {
                let $p = feed::PushProof;
                $body
            }
            Phase::UnloadToHub { await_release, .. } => {
                let $p = unload::ToHub { await_release };
                $body
            }
            Phase::ProveOwner { .. } => {
                let $p = unload::ProveOwner;
                $body
            }
            Phase::RetractToPark { .. } => {
                let $p = unload::ToPark;
                $body
            }
            Phase::EjectFromSlot { .. } => {
                let $p = unload::FromSlot;
                $body
            }
            Phase::HomeLane { .. } => {
                let $p = home::ToPresenceEdge;
                $body
            }
            Phase::FeedToPark { .. } => {
                let $p = home::FromEdgeToPark;
                $body
            }
            Phase::FeedThroughBowden { .. } => {
                let $p = load::ThroughBowden;
                $body
            }
            Phase::FeedToFsensor { .. } => {
                let $p = load::ToFsensor { search: false };
                $body
            }
            Phase::SearchFsensor { .. } => {
                let $p = load::ToFsensor { search: true };
                $body
            }
            Phase::FeedToNozzle { .. } => {
                let $p = load::ToNozzle;
                $body
            }
            Phase::CheckSensors | Phase::AwaitContinue => $check,
        }
    };
}

impl Phase {
    /// The progress code the printer sees while this phase runs.
    pub fn progress(self) -> ProgressCode {
        motion!(self, phase => phase.progress(), check => self.check().map_or(ProgressCode::HOMING, Check::progress))
    }

    /// The slot whose motor this phase drives.
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
            | Phase::PushProof { slot }
            | Phase::HomeLane { slot }
            | Phase::FeedToPark { slot }
            | Phase::EjectFromSlot { slot } => Some(slot as usize),
            Phase::CheckSensors | Phase::AwaitContinue => None,
        }
    }

    /// The check this phase is, if it moves nothing.
    const fn check(self) -> Option<Check> {
        match self {
            Phase::CheckSensors => Some(Check::Sensors),
            Phase::AwaitContinue => Some(Check::AwaitContinue),
            _ => None,
        }
    }
}

/// A motion phase: its progress code, how it moves, where it stands against its goal, and what
/// its end means. Each is a type in its family's module, one block a phase: a new phase is that
/// block, a variant of [`Phase`] and its line in `motion!`.
trait MotionPhase: Copy {
    /// The progress code the printer sees while the phase runs.
    fn progress(self) -> ProgressCode;

    /// How the phase moves.
    fn bounds(self, config: &Config) -> Bounds;

    /// Where the phase stands against its goal, and what it learned on the way.
    fn goal<const N: usize>(self, run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode>;

    /// Where the slot's filament is once the phase is done.
    fn arrival(self) -> Option<Lane> {
        None
    }

    /// May pull the tip back past the slot sensor, out of the drive gear's reach (an eject, a
    /// merge clearance); any other pull back stops there.
    fn past_slot_sensor(self) -> bool {
        false
    }

    /// Progress rests on the printer: the motor holds while the link to it is in doubt
    /// ([`PrinterLink::in_doubt`]).
    fn paced_by_printer(self) -> bool {
        false
    }

    /// The phase pulled its tip back to the slot sensor, which sits just after the drive gear:
    /// where that still counts as done, the lane it leaves.
    fn stopped_at_gear(self, _hub: bool) -> Option<Lane> {
        None
    }

    /// The error of a pull back stopped at the slot sensor with the hub still seeing filament.
    fn at_gear_error(self, error: ErrorCode) -> ErrorCode {
        error
    }

    /// What the drive stopping on `error` means for the phase: the error that names what the
    /// user must look at.
    fn stopped<const N: usize>(self, error: ErrorCode, _unit: &Unit<N>, _slot: usize) -> Outcome {
        Outcome::Fail(error)
    }
}

/// How a motion phase moves: its direction, speed and how far it may go.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    direction: Direction,
    speed: u16,
    max_mm: u16,
    error: ErrorCode,
    /// Part of the way goes at the slow speed instead: its nominal duration, twice as every
    /// bound, comes on top of the nominal duration at `speed` (see [`Bounds::budget`]), mm.
    slower_mm: u16,
}

impl Bounds {
    /// A motion `direction` at `speed` mm/s for at most `max_mm`, failing with `error`.
    const fn new(direction: Direction, speed: u16, max_mm: u16, error: ErrorCode) -> Self {
        Bounds {
            direction,
            speed,
            max_mm,
            error,
            slower_mm: 0,
        }
    }

    /// The drive's budget: the distance, twice the nominal duration plus slack, and the still
    /// limit: [`STILL_MS`], or three marks ([`crate::odometer`], `mark_centi` apart) at the slower
    /// of `speed` and the slow speed when they take longer (slow speeds or a long
    /// `mm_per_rev_centi` set by the user), never more than the time bound.
    ///
    /// Computed where a phase's motion begins or resumes only: [`Bounds`] itself holds no time.
    fn budget(&self, config: &Config, mark_centi: u16) -> Budget {
        let twice_the_time_ms = |mm: u16, speed: u16| u32::from(mm) * 2000 / u32::from(speed.max(1));
        // At most 65 535 × 2000 + 65 535 × 2000 + 65 535.
        let max_ms = twice_the_time_ms(self.max_mm, self.speed)
            + twice_the_time_ms(self.slower_mm, config.slow_speed)
            + u32::from(config.phase_slack_ms);
        // Part of a phase may go at the slow speed (`Goal::DriveAt`).
        let slowest = u32::from(self.speed.min(config.slow_speed).max(1));
        let three_marks_ms = 3 * u32::from(mark_centi) * 10 / slowest;
        Budget {
            max_mm: self.max_mm,
            max_ms,
            max_still_ms: STILL_MS.max(three_marks_ms).min(max_ms),
            error: self.error,
        }
    }
}

/// What a motion phase sees this step, for its goal.
struct Sight<'a, const N: usize> {
    slot: usize,
    /// The hub sensor sees filament.
    hub: bool,
    /// The slot sensor sees filament.
    slot_sees: bool,
    odometry: i32,
    /// Whole millimetres moved towards the goal from where it counts.
    toward_goal_mm: i32,
    bounds: Bounds,
    unit: &'a Unit<N>,
    notes: &'a Notes,
    now: Instant,
    config: &'a Config,
}

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
    /// Pull back too weakly to move a gripped filament and wait (the lease ends):
    /// [`crate::drive::SlotDrive::feel`].
    Feel,
}

/// A phase's goal decision: where it stands, and what it learned that the unit must know.
struct Decision {
    goal: Goal,
    learned: Option<Milestone>,
}

impl From<Goal> for Decision {
    fn from(goal: Goal) -> Self {
        Decision { goal, learned: None }
    }
}

impl Goal {
    /// This goal, having learned `milestone`.
    fn learning(self, milestone: Milestone) -> Decision {
        Decision {
            goal: self,
            learned: Some(milestone),
        }
    }
}

/// What a phase learned about its slot's filament, for [`learn`] to write down.
#[derive(Debug, Clone, Copy)]
enum Milestone {
    /// The slot sensor sees the tip on its way to the hub: the slot holds the hub path, this
    /// unit fed it there, and it is back in the merge. Known (and persisted) before the tip
    /// leaves the park position, so a restart mid-way knows whose filament may be in the path.
    LeavingPark,
    /// The hub sensor saw the tip leave at this odometry; parking that follows measures from
    /// here. `unsure`: the hub was already clear when the phase started, so where it cleared
    /// nobody saw.
    HubCleared { at_centi: i32, unsure: bool },
    /// The hub cleared at this odometry pulling this slot: its claim on the hub path is proven.
    OwnerProven { at_centi: i32 },
    /// Pulled back further than a tip before the hub can be from its slot sensor, which still
    /// sees filament: this slot's filament runs through the hub, its claim on the path is proven.
    OwnerInPath,
    /// Pulled back out of the merge.
    MergeCleared,
    /// The slot's filament is now here.
    Arrived(Lane),
    /// The fast feed met a stop short of its distance with the printer's sensor off (the gears
    /// before the sensor, a Bowden length set too long); it began at the hub sensor here.
    StopBeforeFsensor { from_hub_centi: i32 },
    /// The printer's sensor triggered this far from the hub sensor, mm: a Bowden length to keep.
    BowdenMeasured(u16),
}

/// Write what the phase on `slot` learned into the unit and the command's notes: the one place
/// where phases change what the unit knows (besides the sensor check's lanes).
fn learn<const N: usize>(milestone: Milestone, slot: usize, notes: &mut Notes, unit: &mut Unit<N>) {
    match milestone {
        Milestone::LeavingPark => {
            unit.set_lane(slot, Lane::InHub);
            unit.proven_owner = Some(slot);
            if let Some(clear) = unit.clear_of_merge.get_mut(slot) {
                *clear = false;
            }
        }
        Milestone::HubCleared { at_centi, unsure } => {
            notes.hub_cleared = Some((slot, at_centi));
            notes.park_unsure |= unsure;
        }
        Milestone::OwnerProven { at_centi } => {
            notes.hub_cleared = Some((slot, at_centi));
            unit.proven_owner = Some(slot);
        }
        Milestone::OwnerInPath => unit.proven_owner = Some(slot),
        Milestone::MergeCleared => {
            if let Some(clear) = unit.clear_of_merge.get_mut(slot) {
                *clear = true;
            }
        }
        // Parked from where the hub cleared unseen: behind the park position, nobody knows where.
        Milestone::Arrived(Lane::Parked) if notes.park_unsure => unit.set_lane(slot, Lane::Unknown),
        Milestone::Arrived(lane) => unit.set_lane(slot, lane),
        Milestone::StopBeforeFsensor { from_hub_centi } => notes.stop_before_fsensor = Some(from_hub_centi),
        Milestone::BowdenMeasured(mm) => notes.bowden_measured_mm = Some(mm),
    }
}

/// The error a faulty sensor raises: the hub's sensors show INSPECT FINDA, a slot's sensors
/// show PULLEY CANNOT MOVE (the slot's drive needs a look).
pub const fn sensor_fault_error(sensor: SensorId) -> ErrorCode {
    match sensor {
        SensorId::HubFilament | SensorId::HubTension | SensorId::HubCutter => ErrorCode::FINDA_FLICKERS,
        SensorId::SlotFilament(_) | SensorId::Motion(_) | SensorId::LaneTension(_) => {
            ErrorCode::MOVE_PULLEY_FAILED
        }
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
    /// The fast feed met a stop before the printer's sensor: the odometry where it left the hub.
    pub stop_before_fsensor: Option<i32>,
    /// A Bowden length measured on the way, mm, for the configuration to take.
    pub bowden_measured_mm: Option<u16>,
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
    let Some(slot) = phase.slot() else {
        let Some(check) = phase.check() else {
            return Outcome::Fail(ErrorCode::INTERNAL);
        };
        let (outcome, lanes) = check.step(run, notes, unit, now);
        // The check's verdict on the lanes holds whatever its outcome.
        unit.lanes = lanes;
        return outcome;
    };
    motion!(phase, motion => {
        let mut step = MotionStep {
            motion,
            slot,
            bounds: motion.bounds(config),
            notes,
            unit,
            now,
            config,
        };
        step.run(run, resume_goal_from)
    }, check => Outcome::Fail(ErrorCode::INTERNAL))
}

/// A motion phase's step: the phase, its slot, and what it works on.
struct MotionStep<'a, P, const N: usize> {
    motion: P,
    slot: usize,
    bounds: Bounds,
    notes: &'a mut Notes,
    unit: &'a mut Unit<N>,
    now: Instant,
    config: &'a Config,
}

/// What the sensors showed a motion step, read once for its goal, its motion and its drive.
#[derive(Debug, Clone, Copy)]
struct Seen {
    /// The hub sensor sees filament.
    hub: bool,
    /// The slot sensor sees filament.
    slot_sees: bool,
    /// The slot's odometry, 1/100 mm.
    odometry: i32,
}

impl<P: MotionPhase, const N: usize> MotionStep<'_, P, N> {
    /// One step of the phase attempt `run` (see [`step`]).
    fn run(&mut self, run: &mut Option<PhaseRun>, resume_goal_from: Option<i32>) -> Outcome {
        let Some(run) = self.attempt(run, resume_goal_from) else {
            return Outcome::Fail(ErrorCode::INVALID_TOOL);
        };
        let (goal, seen) = match self.decide(run) {
            Ok(decided) => decided,
            Err(outcome) => return outcome,
        };
        match self.motion(goal, seen, run) {
            Ok(motion) => self.drive(motion, seen, run),
            Err(outcome) => outcome,
        }
    }

    /// The phase attempt under way, or a new one (its drive's budget begun) whose distance goal
    /// counts from `resume_goal_from` or from here; `None` for a slot the unit lacks.
    fn attempt<'r>(
        &mut self,
        run: &'r mut Option<PhaseRun>,
        resume_goal_from: Option<i32>,
    ) -> Option<&'r mut PhaseRun> {
        let mark_centi = self.unit.mark_centi(self.config);
        let (feeder, drive) = (
            self.unit.feeders.get(self.slot)?,
            self.unit.drives.get_mut(self.slot)?,
        );
        let odometry = feeder.odometry_centi();
        Some(match run {
            Some(run) => run,
            None => {
                drive.begin(self.bounds.budget(self.config, mark_centi), feeder, self.now);
                let run = PhaseRun::start(run, self.now, resume_goal_from.unwrap_or(odometry), odometry);
                run.retried = resume_goal_from.is_some();
                run
            }
        })
    }

    /// Where the phase stands against its goal, what it learned written down, and what the
    /// sensors showed; `Err` when the step ends here (a faulty sensor fails it; a sensor warming
    /// up waits).
    fn decide(&mut self, run: &mut PhaseRun) -> Result<(Goal, Seen), Outcome> {
        let slot = self.slot;
        let sensors = [
            SensorId::Motion(slot),
            SensorId::HubFilament,
            SensorId::SlotFilament(slot),
        ];
        if let Some(fault) = sensors
            .into_iter()
            .find(|&id| self.unit.sensor(id).is_some_and(|s| s.fault().is_some()))
        {
            return Err(Outcome::Fail(sensor_fault_error(fault)));
        }
        let hub = self.unit.hub_present().ok_or(Outcome::Continue)?;
        let feeder = self
            .unit
            .feeders
            .get(slot)
            .ok_or(Outcome::Fail(ErrorCode::INTERNAL))?;
        let slot_sees = feeder.filament.present().ok_or(Outcome::Continue)?;
        let odometry = feeder.odometry_centi();
        let toward_goal_mm = match self.bounds.direction {
            Direction::Forward => distance_centi(run.goal_from_centi, odometry) / 100,
            Direction::Reverse => distance_centi(odometry, run.goal_from_centi) / 100,
        };
        let sight = Sight {
            slot,
            hub,
            slot_sees,
            odometry,
            toward_goal_mm,
            bounds: self.bounds,
            unit: self.unit,
            notes: self.notes,
            now: self.now,
            config: self.config,
        };
        let Decision { goal, learned } = self.motion.goal(run, &sight).map_err(Outcome::Fail)?;
        if let Some(milestone) = learned {
            learn(milestone, slot, self.notes, self.unit);
        }
        let seen = Seen {
            hub,
            slot_sees,
            odometry,
        };
        Ok((goal, seen))
    }

    /// How the motor moves toward `goal`; `Err` when the phase ends or waits this step (the
    /// motor braked or freed).
    fn motion(&mut self, goal: Goal, seen: Seen, run: &mut PhaseRun) -> Result<Motion, Outcome> {
        let (phase, slot, now, direction) = (self.motion, self.slot, self.now, self.bounds.direction);
        let Some(drive) = self.unit.drives.get_mut(slot) else {
            return Err(Outcome::Fail(ErrorCode::INTERNAL));
        };
        match goal {
            Goal::Reached => {
                drive.brake(now);
                if let Some(lane) = phase.arrival() {
                    learn(Milestone::Arrived(lane), slot, self.notes, self.unit);
                }
                Err(Outcome::Done)
            }
            Goal::Drive | Goal::DriveAt(_)
                if direction == Direction::Reverse && !seen.slot_sees && !phase.past_slot_sensor() =>
            {
                drive.brake(now);
                match phase.stopped_at_gear(seen.hub) {
                    Some(lane) => {
                        learn(Milestone::Arrived(lane), slot, self.notes, self.unit);
                        Err(Outcome::Done)
                    }
                    // Still filament in the hub with this tip at its gear: the hub sensor is
                    // wrong, or another filament is there. Not parked.
                    None => Err(Outcome::Fail(phase.at_gear_error(self.bounds.error))),
                }
            }
            Goal::Drive if !(phase.paced_by_printer() && self.notes.printer.in_doubt(now)) => {
                Ok(Motion::Run {
                    direction,
                    speed: self.bounds.speed,
                })
            }
            Goal::DriveAt(speed) => Ok(Motion::Run { direction, speed }),
            Goal::Yield => {
                // Let the motor turn freely while the phase waits.
                run.pause(now, seen.odometry);
                drive.release(now);
                Err(Outcome::Continue)
            }
            Goal::Feel => {
                run.pause(now, seen.odometry);
                drive.feel();
                Err(Outcome::Continue)
            }
            Goal::Drive | Goal::Hold => {
                // Hold: the phase waits, or the printer's `f` may be lost and its co-feed has
                // stopped.
                run.pause(now, seen.odometry);
                drive.brake(now);
                Err(Outcome::Continue)
            }
        }
    }

    /// Drive `motion` under the drive's budget, begun again after a hold.
    fn drive(&mut self, motion: Motion, seen: Seen, run: &mut PhaseRun) -> Outcome {
        let (slot, now, config) = (self.slot, self.now, self.config);
        let tension = self.unit.tension_reading(slot);
        let mark_centi = self.unit.mark_centi(config);
        let (Some(feeder), Some(drive)) = (self.unit.feeders.get(slot), self.unit.drives.get_mut(slot))
        else {
            return Outcome::Fail(ErrorCode::INTERNAL);
        };
        if run.held {
            run.held = false;
            drive.begin(
                run.budget_use
                    .resume(self.bounds.budget(config, mark_centi), now, seen.odometry),
                feeder,
                now,
            );
        }
        match drive.run(motion, feeder, tension, now, config) {
            Ok(()) => Outcome::Continue,
            Err(error) => self.motion.stopped(error, self.unit, slot),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A phase may take twice its nominal time plus the slack, its slow part at the slow speed,
    /// and stand still for [`STILL_MS`] or three revolutions at its slowest speed, whichever is
    /// longer, never longer than it may take. A speed of 0 counts as 1 mm/s.
    #[test]
    fn a_budget_is_twice_the_nominal_time_and_three_revolutions_still() {
        let config = Config {
            slow_speed: 20,
            mm_per_rev_centi: 1000,
            phase_slack_ms: 500,
            ..Config::default()
        };
        let bounds = |speed, max_mm, slower_mm| Bounds {
            slower_mm,
            ..Bounds::new(Direction::Forward, speed, max_mm, ErrorCode::MOVE_PULLEY_FAILED)
        };
        // 100 mm at 50 mm/s, 20 of them at 20 mm/s: 4000 + 2000 + 500 ms.
        let budget = bounds(50, 100, 20).budget(&config, 1000);
        assert_eq!((budget.max_mm, budget.max_ms), (100, 6500));
        // Three 10 mm marks at 20 mm/s take 1500 ms.
        assert_eq!(budget.max_still_ms, STILL_MS.max(1500));
        let budget = bounds(0, 1, 0).budget(&config, 1000);
        assert_eq!((budget.max_ms, budget.max_still_ms), (2500, 2500));
        let slowest = bounds(u16::MAX, u16::MAX, u16::MAX).budget(
            &Config {
                slow_speed: 0,
                ..config
            },
            u16::MAX,
        );
        assert_eq!(slowest.max_still_ms, 3 * 65_535 * 10);
        assert_eq!(slowest.error, ErrorCode::MOVE_PULLEY_FAILED);
    }
}
