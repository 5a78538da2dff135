//! Commands as small state machines.
//!
//! Every printer command becomes an [`Operation`]: a short plan of [`Phase`]s, each one bounded
//! motion of one slot motor (or a check) with the MMU3 progress code that best describes it.
//! Composite commands are built from the same phases: a tool change is "unload the loaded slot"
//! followed by "load the new one". A phase that runs past its distance or time bound, stalls its
//! motor or loses a sensor stops every motor of the operation and fails with the error the printer
//! expects; Retry (`B1`) runs the failed phase again from wherever the sensors say the filament is.

use heapless::Vec;
use mmu_hal_port::{Direction, Duty};
use mmu_protocol::{ErrorCode, ProgressCode, RequestCode};

use crate::config::Config;
use crate::time::Instant;
use crate::unit::{Lane, SensorId, Unit};

/// The longest plan: unload (2 phases) + load to nozzle (4) + eject (2) fits with room.
const MAX_PHASES: usize = 8;

/// The phases of one command, in order.
pub type Plan = Vec<Phase, MAX_PHASES>;

/// How long a check may wait for the sensors to settle after start, ms.
const SENSOR_SETTLE_MS: u64 = 1000;
/// How long the Bowden tube must stay compressed before the extruder's gears count as holding
/// the tip, ms (one noisy reading is not enough).
const HELD_CONFIRM_MS: u64 = 100;
/// Extra travel allowed to the push into the extruder beyond twice its nominal distance, mm: the
/// printer pushes its own extra load + 2 mm, and the tube takes up some before it holds.
const NOZZLE_PUSH_MARGIN_MM: u16 = 10;

/// One bounded step of a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Phase {
    /// `P5`: feed until the hub sensor sees the tip, at most `max_mm`.
    FeedToHub {
        /// The slot.
        slot: usize,
        /// Distance bound.
        max_mm: u16,
    },
    /// `P19`: pull back until the hub sensor clears, then the park distance.
    RetractToPark {
        /// The slot.
        slot: usize,
    },
    /// `P6`: fast feed through most of the Bowden tube; the printer's sensor must stay off.
    FeedThroughBowden {
        /// The slot.
        slot: usize,
    },
    /// `P1c`: slow feed until the printer's sensor triggers; the printer co-feeds.
    FeedToFsensor {
        /// The slot.
        slot: usize,
    },
    /// `P7`: push the extra load distance at the slow speed, following the extruder's tension.
    FeedToNozzle {
        /// The slot.
        slot: usize,
    },
    /// `P3`: pull back until the printer's sensor and then the hub sensor clear.
    UnloadToHub {
        /// The slot.
        slot: usize,
    },
    /// `P18`: pull back until the slot sensor clears.
    EjectFromSlot {
        /// The slot.
        slot: usize,
    },
    /// `P1a`: the sensors must be healthy and agree with the known lanes.
    CheckSensors,
    /// `E800c` until the user presses Continue.
    AwaitContinue,
}

impl Phase {
    /// The progress code the printer sees while this phase runs.
    pub const fn progress(self) -> ProgressCode {
        match self {
            Phase::FeedToHub { .. } => ProgressCode::FEEDING_TO_FINDA,
            Phase::RetractToPark { .. } => ProgressCode::RETRACTING_FROM_FINDA,
            Phase::FeedThroughBowden { .. } => ProgressCode::FEEDING_TO_BONDTECH,
            Phase::FeedToFsensor { .. } => ProgressCode::FEEDING_TO_FSENSOR,
            Phase::FeedToNozzle { .. } => ProgressCode::FEEDING_TO_NOZZLE,
            Phase::UnloadToHub { .. } => ProgressCode::UNLOADING_TO_FINDA,
            Phase::EjectFromSlot { .. } => ProgressCode::EJECTING_FILAMENT,
            Phase::CheckSensors => ProgressCode::HOMING,
            Phase::AwaitContinue => ProgressCode::ERR_WAITING_FOR_USER,
        }
    }

    /// The slot whose motor this phase drives.
    pub const fn slot(self) -> Option<usize> {
        match self {
            Phase::FeedToHub { slot, .. }
            | Phase::RetractToPark { slot }
            | Phase::FeedThroughBowden { slot }
            | Phase::FeedToFsensor { slot }
            | Phase::FeedToNozzle { slot }
            | Phase::UnloadToHub { slot }
            | Phase::EjectFromSlot { slot } => Some(slot),
            Phase::CheckSensors | Phase::AwaitContinue => None,
        }
    }
}

/// How far a phase may run and what running past that means.
#[derive(Debug, Clone, Copy)]
struct Bounds {
    direction: Direction,
    speed: u16,
    max_mm: u16,
    error: ErrorCode,
}

impl Bounds {
    /// Twice the nominal duration plus slack.
    fn max_ms(&self, config: &Config) -> u64 {
        u64::from(self.max_mm) * 2000 / u64::from(self.speed.max(1)) + u64::from(config.phase_slack_ms)
    }
}

fn bounds(phase: Phase, config: &Config) -> Option<Bounds> {
    let forward = |speed, max_mm, error| {
        Some(Bounds {
            direction: Direction::Forward,
            speed,
            max_mm,
            error,
        })
    };
    let reverse = |speed, max_mm, error| {
        Some(Bounds {
            direction: Direction::Reverse,
            speed,
            max_mm,
            error,
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
        Phase::FeedToNozzle { .. } => forward(
            config.slow_speed,
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
pub const fn sensor_fault_error(sensor: SensorId) -> ErrorCode {
    match sensor {
        SensorId::HubFilament | SensorId::HubTension | SensorId::HubCutter => ErrorCode::FINDA_FLICKERS,
        SensorId::SlotFilament(_) | SensorId::MotorHall(_) => ErrorCode::MOVE_PULLEY_FAILED,
    }
}

/// Where an operation stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Status {
    /// A phase is running.
    Running(ProgressCode),
    /// Stopped on an error, waiting for the user (or the printer's automatic Retry).
    Failed(ErrorCode),
    /// Done.
    Finished,
}

/// Bookkeeping of the running phase.
#[derive(Debug, Clone, Copy)]
struct PhaseRun {
    started: Instant,
    /// Odometry when this attempt started: the bounds count from here.
    from_centi: i32,
    /// Odometry when the phase first started, kept across Retry: distance goals count from here.
    goal_from_centi: i32,
    /// Odometry at a milestone inside the phase (the hub cleared, the printer's sensor cleared).
    mark_centi: Option<i32>,
    /// Since when the Bowden tube reads compressed.
    compressed_since: Option<Instant>,
}

/// One command being carried out.
#[derive(Debug, Clone)]
pub struct Operation {
    /// The request this operation answers for (echoed by `Q0`).
    pub request: (RequestCode, u8),
    plan: Vec<Phase, MAX_PHASES>,
    index: usize,
    run: Option<PhaseRun>,
    status: Status,
    /// Set by Retry: the user has looked, trust what the sensors say now over the known lanes.
    trust_sensors: bool,
    /// Odometry of a slot when the hub sensor last saw its tip leave, so parking that follows an
    /// unload measures from the hub and not from where the unload stopped.
    hub_cleared: Option<(usize, i32)>,
    /// The failed phase's [`PhaseRun::goal_from_centi`], for the attempt after Retry.
    resume_goal_from: Option<i32>,
}

impl Operation {
    /// An operation that runs `plan` for `request`.
    pub fn new(request: (RequestCode, u8), plan: &[Phase]) -> Self {
        let mut phases = Plan::new();
        extend(&mut phases, plan);
        let status = match phases.first() {
            Some(phase) => Status::Running(phase.progress()),
            None => Status::Finished,
        };
        Operation {
            request,
            plan: phases,
            index: 0,
            run: None,
            status,
            trust_sensors: false,
            hub_cleared: None,
            resume_goal_from: None,
        }
    }

    /// An operation that failed before it moved anything.
    pub fn failed(request: (RequestCode, u8), error: ErrorCode) -> Self {
        let mut operation = Self::new(request, &[]);
        operation.status = Status::Failed(error);
        operation
    }

    /// Where the operation stands.
    pub fn status(&self) -> Status {
        self.status
    }

    /// True while the operation runs or waits in an error: new commands are refused.
    pub fn is_busy(&self) -> bool {
        match self.status {
            Status::Running(_) => true,
            // An invalid tool needs no recovery: the printer stops the print or resets the unit.
            Status::Failed(error) => error != ErrorCode::INVALID_TOOL,
            Status::Finished => false,
        }
    }

    /// The phase running (or failed), if any.
    pub fn phase(&self) -> Option<Phase> {
        self.plan.get(self.index).copied()
    }

    /// The slot motor this operation drives now.
    pub fn driving_slot(&self) -> Option<usize> {
        match self.status {
            Status::Running(_) => self.phase().and_then(Phase::slot),
            _ => None,
        }
    }

    /// The Middle button (Retry / Continue).
    pub fn retry(&mut self, config: &Config) {
        let Status::Failed(error) = self.status else {
            return;
        };
        if error == ErrorCode::INVALID_TOOL {
            return;
        }
        if self.phase() == Some(Phase::AwaitContinue) {
            self.advance();
            return;
        }
        self.trust_sensors = true;
        if error == ErrorCode::FSENSOR_TOO_EARLY
            && let Some(slot) = self.phase().and_then(Phase::slot)
        {
            // The Bowden tube is shorter than configured or holds a leftover: pull back to the park
            // position and load again.
            let mut plan = Plan::new();
            extend(&mut plan, &unload(slot));
            extend(&mut plan, &load_to_nozzle(slot, config.hub_search_mm));
            *self = Operation {
                trust_sensors: true,
                ..Operation::new(self.request, &plan)
            };
            return;
        }
        self.run = None;
        self.status = self
            .phase()
            .map_or(Status::Finished, |phase| Status::Running(phase.progress()));
    }

    fn advance(&mut self) {
        self.index += 1;
        self.run = None;
        self.resume_goal_from = None;
        self.status = match self.phase() {
            Some(phase) => Status::Running(phase.progress()),
            None => Status::Finished,
        };
    }

    fn fail<const N: usize>(&mut self, error: ErrorCode, unit: &mut Unit<N>, now: Instant, config: &Config) {
        if let Some(slot) = self.phase().and_then(Phase::slot)
            && let Some(feeder) = unit.feeders.get_mut(slot)
        {
            feeder.brake(now, config);
        }
        self.resume_goal_from = self.run.take().map(|run| run.goal_from_centi);
        self.status = Status::Failed(error);
    }

    /// Advance the operation to `now`: drive the motor of the running phase and move on, finish
    /// or fail as the sensors say.
    pub fn step<const N: usize>(&mut self, unit: &mut Unit<N>, now: Instant, config: &Config) {
        // Phases that finish at once (a check, a move already at its goal) hand over in the same step.
        for _ in 0..MAX_PHASES {
            let Status::Running(_) = self.status else { return };
            let Some(phase) = self.phase() else {
                self.status = Status::Finished;
                return;
            };
            match self.step_phase(phase, unit, now, config) {
                Outcome::Continue => return,
                Outcome::Done => {
                    record_arrival(phase, unit);
                    self.advance();
                }
                Outcome::Fail(error) => {
                    self.fail(error, unit, now, config);
                    return;
                }
            }
        }
    }

    fn step_phase<const N: usize>(
        &mut self,
        phase: Phase,
        unit: &mut Unit<N>,
        now: Instant,
        config: &Config,
    ) -> Outcome {
        let Some(slot) = phase.slot() else {
            return match phase {
                Phase::AwaitContinue => Outcome::Fail(ErrorCode::FILAMENT_EJECTED),
                _ => self.check_sensors(unit, now),
            };
        };
        let Some(bounds) = bounds(phase, config) else {
            return Outcome::Fail(ErrorCode::INTERNAL);
        };
        let Some(feeder) = unit.feeders.get(slot) else {
            return Outcome::Fail(ErrorCode::INVALID_TOOL);
        };
        let odometry = feeder.odometry_centi();
        let resume = self.resume_goal_from.take();
        let run = *self.run.get_or_insert(PhaseRun {
            started: now,
            from_centi: odometry,
            goal_from_centi: resume.unwrap_or(odometry),
            mark_centi: None,
            compressed_since: None,
        });
        let travel = |from: i32| match bounds.direction {
            Direction::Forward => (odometry - from) / 100,
            Direction::Reverse => (from - odometry) / 100,
        };
        let (moved_mm, toward_goal_mm) = (travel(run.from_centi), travel(run.goal_from_centi));

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
                } else if !slot_sees {
                    // An empty slot: nothing to feed.
                    return Outcome::Fail(ErrorCode::FINDA_DIDNT_SWITCH_ON);
                } else {
                    // Known (and persisted) before the tip leaves the park position, so a restart
                    // mid-way knows whose filament may be in the hub path.
                    unit.set_lane(slot, Lane::InHub);
                    Goal::Drive
                }
            }
            Phase::RetractToPark { .. } => match (hub, run.mark_centi.or(self.hub_mark(slot))) {
                (true, _) => Goal::Drive,
                (false, None) => {
                    self.mark(odometry);
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
            Phase::FeedToFsensor { .. } => {
                if unit.fsensor_triggered() {
                    Goal::Reached
                } else {
                    Goal::Drive
                }
            }
            Phase::FeedToNozzle { .. } => {
                // The extruder has the filament when its gears hold the tip and the tube fills up
                // behind it: after the printer's own push, or at once if that push came first.
                // Odometry alone would be fooled by a slipping drive; it decides only without a
                // tension reading.
                let held = match unit.hub.tension.reading() {
                    Some(tension) => self.compressed_for(tension, now, config) >= HELD_CONFIRM_MS,
                    None => toward_goal_mm >= i32::from(config.extra_load_mm),
                };
                if held { Goal::Reached } else { Goal::Follow }
            }
            Phase::UnloadToHub { .. } => {
                if unit.fsensor_triggered() && moved_mm >= i32::from(config.unload_check_mm) {
                    return Outcome::Fail(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF);
                }
                if !hub && !unit.fsensor_triggered() {
                    self.hub_cleared = Some((slot, odometry));
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
        let Some(feeder) = unit.feeders.get_mut(slot) else {
            return Outcome::Fail(ErrorCode::INTERNAL);
        };
        match goal {
            Goal::Reached => {
                feeder.brake(now, config);
                return Outcome::Done;
            }
            Goal::Drive => feeder.drive(bounds.direction, bounds.speed, now, config),
            Goal::Follow => feeder.push(follow_duty(config.slow_speed, tension, config), now, config),
        }
        if feeder.stalled(now, config) {
            return Outcome::Fail(ErrorCode::STALLED_PULLEY);
        }
        if moved_mm > i32::from(bounds.max_mm) || now.millis_since(run.started) > bounds.max_ms(config) {
            return Outcome::Fail(bounds.error);
        }
        Outcome::Continue
    }

    /// How long the Bowden tube has read compressed past the follower's deadband (where
    /// [`follow_duty`] backs off, so the tube settles there when the tip is held), ms.
    fn compressed_for(&mut self, tension: u16, now: Instant, config: &Config) -> u64 {
        let compressed =
            u32::from(tension) + u32::from(config.tension_deadband) < u32::from(config.tension_neutral);
        let Some(run) = self.run.as_mut() else { return 0 };
        run.compressed_since = if compressed {
            run.compressed_since.or(Some(now))
        } else {
            None
        };
        run.compressed_since.map_or(0, |since| now.millis_since(since))
    }

    fn hub_mark(&self, slot: usize) -> Option<i32> {
        self.hub_cleared
            .filter(|&(cleared, _)| cleared == slot)
            .map(|(_, odometry)| odometry)
    }

    fn mark(&mut self, odometry: i32) {
        if let Some(run) = self.run.as_mut() {
            run.mark_centi = Some(odometry);
        }
    }

    fn check_sensors<const N: usize>(&mut self, unit: &mut Unit<N>, now: Instant) -> Outcome {
        if let Some(fault) = unit.first_fault() {
            return Outcome::Fail(sensor_fault_error(fault));
        }
        let Some(hub) = unit.hub_present() else {
            let started = self
                .run
                .get_or_insert(PhaseRun {
                    started: now,
                    from_centi: 0,
                    goal_from_centi: 0,
                    mark_centi: None,
                    compressed_since: None,
                })
                .started;
            if now.millis_since(started) > SENSOR_SETTLE_MS {
                return Outcome::Fail(ErrorCode::FINDA_FLICKERS);
            }
            return Outcome::Continue;
        };
        // At most one slot can be past its park position: stored lanes that say otherwise are
        // not to be believed. After Retry they are forgotten and the hub sensor decides.
        if (0..N).filter(|&slot| unit.lane(slot).owns_hub()).count() > 1 {
            if !self.trust_sensors {
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
            (false, Some(slot)) if self.trust_sensors => unit.set_lane(slot, Lane::InHub),
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
}

enum Outcome {
    Continue,
    Done,
    Fail(ErrorCode),
}

enum Goal {
    Reached,
    Drive,
    /// Drive at the slow speed, corrected by the Bowden tension.
    Follow,
}

/// Duty that moves the filament at `speed` while keeping the Bowden tube at rest: more when the
/// extruder pulls it taut, less when it is compressed. Without a healthy tension sensor it is the
/// open-loop duty for `speed`.
pub fn follow_duty(speed: u16, tension: Option<u16>, config: &Config) -> Duty {
    let open_loop = i32::from(speed) * 1000 / i32::from(config.full_duty_speed.max(1));
    let correction = tension.map_or(0, |value| {
        let deviation = i32::from(value) - i32::from(config.tension_neutral);
        let deadband = i32::from(config.tension_deadband);
        let beyond = if deviation > deadband {
            deviation - deadband
        } else if deviation < -deadband {
            deviation + deadband
        } else {
            0
        };
        beyond * i32::from(config.tension_gain)
    });
    let limit = i32::from(config.tension_max_duty.min(config.max_duty));
    Duty::from_permille((open_loop + correction).clamp(0, limit) as u16)
}

/// What a finished phase says about where the slot's filament is now.
fn record_arrival<const N: usize>(phase: Phase, unit: &mut Unit<N>) {
    let Some(slot) = phase.slot() else { return };
    let lane = match phase {
        Phase::FeedToHub { .. } | Phase::FeedThroughBowden { .. } | Phase::UnloadToHub { .. } => Lane::InHub,
        Phase::FeedToFsensor { .. } => Lane::AtFsensor,
        Phase::FeedToNozzle { .. } => Lane::Loaded,
        Phase::RetractToPark { .. } => Lane::Parked,
        Phase::EjectFromSlot { .. } => Lane::Empty,
        Phase::CheckSensors | Phase::AwaitContinue => return,
    };
    unit.set_lane(slot, lane);
}

/// Append as much of `phases` as fits (every plan built here fits).
fn extend(plan: &mut Plan, phases: &[Phase]) {
    for &phase in phases {
        if plan.push(phase).is_err() {
            return;
        }
    }
}

/// Pull a slot's filament out of the printer and the hub, and park it.
pub const fn unload(slot: usize) -> [Phase; 2] {
    [Phase::UnloadToHub { slot }, Phase::RetractToPark { slot }]
}

/// Feed a slot's filament from before the hub into the printer's extruder.
pub const fn load_to_nozzle(slot: usize, hub_search_mm: u16) -> [Phase; 4] {
    [
        Phase::FeedToHub {
            slot,
            max_mm: hub_search_mm,
        },
        Phase::FeedThroughBowden { slot },
        Phase::FeedToFsensor { slot },
        Phase::FeedToNozzle { slot },
    ]
}

/// The plan for a printer command with argument `value` (a slot for `T L E K`), or the error it
/// fails with before anything moves. An empty plan finishes at once.
pub fn plan<const N: usize>(
    code: RequestCode,
    value: u8,
    unit: &Unit<N>,
    config: &Config,
) -> Result<Plan, ErrorCode> {
    let slot = usize::from(value);
    let needs_slot = matches!(
        code,
        RequestCode::Tool | RequestCode::Load | RequestCode::Eject | RequestCode::Cut
    );
    if needs_slot && slot >= N {
        return Err(ErrorCode::INVALID_TOOL);
    }
    let mut plan = Plan::new();
    // From the park position the hub is close; from an unknown position it may be a slot away.
    let hub_search = |slot| match unit.lane(slot) {
        Lane::Parked => config.hub_search_mm,
        _ => config.preload_max_mm,
    };
    // Whatever occupies the hub path comes out first. With filament in the hub but no slot known
    // to own it, no motor moves on a guess.
    let clear_hub = |plan: &mut Plan| match (unit.active(), unit.hub_present()) {
        (Some(active), _) => {
            extend(plan, &unload(active));
            Ok(())
        }
        (None, Some(false)) => Ok(()),
        (None, Some(true)) => Err(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
        (None, None) => Err(sensor_fault_error(SensorId::HubFilament)),
    };
    match code {
        RequestCode::Tool => {
            if unit.lane(slot) == Lane::Loaded {
                return Ok(plan);
            }
            clear_hub(&mut plan)?;
            extend(&mut plan, &load_to_nozzle(slot, hub_search(slot)));
        }
        RequestCode::Load => {
            if unit.active().is_some() {
                return Err(ErrorCode::FILAMENT_ALREADY_LOADED);
            }
            clear_hub(&mut plan)?;
            extend(
                &mut plan,
                &[
                    Phase::FeedToHub {
                        slot,
                        max_mm: config.preload_max_mm,
                    },
                    Phase::RetractToPark { slot },
                ],
            );
        }
        RequestCode::Unload => clear_hub(&mut plan)?,
        RequestCode::Eject => {
            if unit.active() == Some(slot) {
                extend(&mut plan, &unload(slot));
            }
            extend(&mut plan, &[Phase::EjectFromSlot { slot }, Phase::AwaitContinue]);
        }
        RequestCode::Cut => {
            clear_hub(&mut plan)?;
            extend(
                &mut plan,
                &[
                    Phase::FeedToHub {
                        slot,
                        max_mm: hub_search(slot),
                    },
                    Phase::RetractToPark { slot },
                ],
            );
        }
        RequestCode::Home => extend(&mut plan, &[Phase::CheckSensors]),
        _ => return Err(ErrorCode::INTERNAL),
    }
    Ok(plan)
}
