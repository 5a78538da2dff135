//! The pulls back: the unload from the printer to the hub (`P3`) with its wait for the printer to
//! release the filament, the proof of a stored owner (`P3`), the retract to the park position
//! (`P19`) and the eject out of the slot (`P18`). MMU 3.0.4 keeps the unload's contract with the
//! printer in `unload_to_finda.cpp`: it waits blind for the printer's sensor. This unit feels
//! instead ([`feel_for_release`], in `release.rs`).

use mmu_hal_port::Direction;
use mmu_protocol::{ErrorCode, ProgressCode};

use super::load::taut_for;
use super::release::{
    RELEASE_WAIT_MS, UnloadStuck, feel_for_release, go_on_feeling, still_gripped, strict, stuck_because,
    taut_or_unread,
};
use super::{Bounds, Decision, Goal, Milestone, MotionPhase, Notes, Outcome, PhaseRun, Sight};
use crate::config::{Config, Contract};
use crate::feeder::distance_centi;
use crate::unit::{Lane, Unit};

/// How far an unload pulls at the slow speed (register 0x14) once the printer has released the
/// filament, mm, in 3.0.4 mode: MMU 3.0.4's `fsensorToNozzleAvoidGrindUnload`, which helps the
/// printer relieve the filament.
const RELEASE_SLOW_MM: u16 = 20;

/// How long a pull that went its check distance freely waits for the printer's sensor to report
/// off, ms: a sensor that users see clear up to 8 s late.
const LATE_SENSOR_MS: u64 = 10_000;

/// A pull back at `speed` for at most `max_mm`, failing with `error`.
const fn reverse(speed: u16, max_mm: u16, error: ErrorCode) -> Bounds {
    Bounds::new(Direction::Reverse, speed, max_mm, error)
}

/// The longest way from the printer's sensor back to the hub sensor, mm; without a hub sensor,
/// back to the lane's presence sensor, which a tip not seen since start must reach to clear the
/// hub ([`crate::unit::Unit::hub_present`]).
const fn printer_to_hub_mm(config: &Config) -> u16 {
    config
        .bowden_mm
        .saturating_add(config.fsensor_search_mm)
        .saturating_add(config.hub_search_mm)
        .saturating_add(config.lane_to_hub_mm)
}

/// `P3` ([`super::Phase::UnloadToHub`]): pull back until the printer's sensor and then the hub
/// sensor clear; first feel while the printer's sensor reads filament ([`feel_for_release`]).
/// `await_release` matters only in the strict mode: first wait, the motor free to turn, while
/// the printer's gears may still grip the filament.
#[derive(Debug, Clone, Copy)]
pub(super) struct ToHub {
    pub(super) await_release: bool,
}

impl MotionPhase for ToHub {
    fn progress(self) -> ProgressCode {
        ProgressCode::UNLOADING_TO_FINDA
    }

    fn bounds(self, config: &Config) -> Bounds {
        Bounds {
            // The slow start, twice its nominal duration as every bound.
            slower_mm: RELEASE_SLOW_MM,
            ..reverse(
                config.unload_speed,
                printer_to_hub_mm(config),
                ErrorCode::FINDA_DIDNT_SWITCH_OFF,
            )
        }
    }

    fn goal<const N: usize>(self, run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        unload_to_hub(self.await_release, run, at)
    }

    fn arrival(self) -> Option<Lane> {
        Some(Lane::InHub)
    }

    /// An unload stopped while the printer's sensor still reads filament stopped against the
    /// printer's gears: FSENSOR DIDNT CLEAR (`8004`), as MMU 3.0.3 reports it after the check
    /// distance, and whose Retry makes the printer help with its own extruder (Buddy
    /// `mmu2_mk4.cpp` `CheckUserInput`: `HelpUnloadToFinda` on `FSENSOR_DIDNT_SWITCH_OFF`).
    fn stopped<const N: usize>(self, error: ErrorCode, unit: &Unit<N>, _slot: usize) -> Outcome {
        Outcome::Fail(match error {
            ErrorCode::STALLED_PULLEY if unit.fsensor_triggered() => ErrorCode::FSENSOR_DIDNT_SWITCH_OFF,
            error => error,
        })
    }
}

/// `P3` ([`super::Phase::ProveOwner`]), for a slot only believed to hold the hub path: see
/// [`prove_owner`].
#[derive(Debug, Clone, Copy)]
pub(super) struct ProveOwner;

impl MotionPhase for ProveOwner {
    fn progress(self) -> ProgressCode {
        ProgressCode::UNLOADING_TO_FINDA
    }

    /// Past the proof, an unload: as far as one from the printer's sensor.
    fn bounds(self, config: &Config) -> Bounds {
        reverse(
            config.load_speed,
            printer_to_hub_mm(config),
            ErrorCode::FINDA_DIDNT_SWITCH_OFF,
        )
    }

    /// A slot proven before the pull began (by the push, [`super::Phase::PushProof`], or by an
    /// attempt before a Retry) is unloaded as any other: felt first while the printer's sensor
    /// reads its filament, never pulled against gripping gears.
    fn goal<const N: usize>(self, run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        if *run
            .proven_at_start
            .get_or_insert(at.unit.proven_owner == Some(at.slot))
        {
            unload_to_hub(false, run, at)
        } else {
            prove_owner(run, at)
        }
    }

    fn arrival(self) -> Option<Lane> {
        Some(Lane::InHub)
    }

    /// Stopped at the slot sensor with the hub still seeing filament: another slot holds the
    /// path (`8008`).
    fn at_gear_error(self, _error: ErrorCode) -> ErrorCode {
        ErrorCode::FINDA_VS_EEPROM_DISREPANCY
    }
}

/// `P19` ([`super::Phase::RetractToPark`]): pull back until the hub sensor clears, then the park
/// distance.
#[derive(Debug, Clone, Copy)]
pub(super) struct ToPark;

impl MotionPhase for ToPark {
    fn progress(self) -> ProgressCode {
        ProgressCode::RETRACTING_FROM_FINDA
    }

    fn bounds(self, config: &Config) -> Bounds {
        reverse(
            config.load_speed,
            config.hub_search_mm.saturating_add(config.park_mm),
            ErrorCode::FINDA_DIDNT_SWITCH_OFF,
        )
    }

    fn goal<const N: usize>(self, run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        Ok(match (at.hub, run.mark_centi.or(hub_mark(at.notes, at.slot))) {
            (true, _) => Goal::Drive.into(),
            (false, None) => {
                // Where the hub cleared: the park distance counts from here, also after a
                // Retry. A retract that starts with the hub already clear (after a Retry) did
                // not see where: the tip ends somewhere behind its park position.
                run.mark_centi = Some(at.odometry);
                Goal::Drive.learning(Milestone::HubCleared {
                    at_centi: at.odometry,
                    unsure: run.started == at.now,
                })
            }
            (false, Some(mark))
                if distance_centi(at.odometry, mark) / 100 >= i32::from(at.config.park_mm) =>
            {
                Goal::Reached.into()
            }
            (false, Some(_)) => Goal::Drive.into(),
        })
    }

    fn arrival(self) -> Option<Lane> {
        Some(Lane::Parked)
    }

    /// A retract that reaches the drive gear with the hub clear is done, behind its park
    /// position: where exactly, nobody knows.
    fn stopped_at_gear(self, hub: bool) -> Option<Lane> {
        (!hub).then_some(Lane::Unknown)
    }
}

/// `P18` ([`super::Phase::EjectFromSlot`]): pull back until the slot sensor clears.
#[derive(Debug, Clone, Copy)]
pub(super) struct FromSlot;

impl MotionPhase for FromSlot {
    fn progress(self) -> ProgressCode {
        ProgressCode::EJECTING_FILAMENT
    }

    fn bounds(self, config: &Config) -> Bounds {
        reverse(
            config.load_speed,
            config.eject_max_mm,
            ErrorCode::MOVE_PULLEY_FAILED,
        )
    }

    /// The eject means to pull the tip out of its drive gear.
    fn past_slot_sensor(self) -> bool {
        true
    }

    fn goal<const N: usize>(self, _run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        Ok(if at.slot_sees { Goal::Drive } else { Goal::Reached }.into())
    }

    fn arrival(self) -> Option<Lane> {
        Some(Lane::Empty)
    }
}

/// `P3`: wait for the printer to release the filament, then pull it out of the printer back to
/// the hub. The wait feels ([`feel_for_release`]); in the strict mode it is MMU 3.0.4's (with
/// `await_release`, [`still_gripped`]).
fn unload_to_hub<const N: usize>(
    await_release: bool,
    run: &mut PhaseRun,
    at: &Sight<'_, N>,
) -> Result<Decision, ErrorCode> {
    let strict = strict(at.config);
    if run.mark_centi.is_none() && at.unit.fsensor_triggered() {
        if strict {
            if await_release && still_gripped(run, at.notes, at.now, at.config)? {
                return Ok(Goal::Yield.into());
            }
        } else if at.hub {
            // With the tip out of the hub already, nothing is felt or pulled (see
            // `pull_out_of_printer`).
            if let Some(goal) = feel_for_release(run, at)? {
                return Ok(goal.into());
            }
        }
    }
    if run.mark_centi.is_none() && (await_release || !strict) {
        // Released: the pull starts here, and so does its check distance. In the strict mode a
        // Retry does not start the count again, so a stuck sensor cannot let every Retry pull
        // the check distance anew; a feel proved the filament free, and it is pulled anew.
        run.mark_centi = Some(at.odometry);
        if !run.retried || !strict {
            run.goal_from_centi = at.odometry;
        }
    }
    Ok(match pull_out_of_printer(run, at)? {
        Goal::Reached => Goal::Reached.learning(Milestone::HubCleared {
            at_centi: at.odometry,
            unsure: false,
        }),
        // On its way back, no longer loaded: recorded (and persisted) while the tip is still far
        // past the hub, so a restart that finds the hub clear knows the slot was between the hub
        // and its park position (the start-up check), not loaded with its tip unseen.
        goal if at.unit.lane(at.slot) == Lane::Loaded => goal.learning(Milestone::Arrived(Lane::InHub)),
        goal => goal.into(),
    })
}

/// `P3` once the pull has begun: on until the printer's sensor and then the hub sensor clear. A
/// tube that reads taut on the way is felt, not pulled ([`go_on_feeling`]). The
/// printer's sensor must clear within the check distance of where the pull began (Retry does not
/// start the count again unless it waited for the printer), and never after the tip has left
/// the hub: pulling on would drag the filament out of its drive gear (MMU 3.0.3 checks too). A
/// printer that accepted 3.0.4 gets the first [`RELEASE_SLOW_MM`] at the slow speed.
fn pull_out_of_printer<const N: usize>(run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Goal, ErrorCode> {
    let config = at.config;
    let pulled_mm = distance_centi(at.odometry, run.goal_from_centi) / 100;
    let stuck = pulled_mm >= i32::from(config.unload_check_mm) || !at.hub;
    Ok(match (at.unit.fsensor_triggered(), at.hub) {
        // Pulled freely its check distance: the sensor may clear late. Held there, no further.
        (true, _) if stuck && !strict(config) => {
            let since = *run.distance_done_at.get_or_insert(at.now);
            if at.now.millis_since(since) >= LATE_SENSOR_MS {
                return Err(stuck_because(run, UnloadStuck::SensorStillOn));
            }
            Goal::Hold
        }
        (true, _) if stuck => return Err(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF),
        (false, false) => Goal::Reached,
        _ if config.version.contract() == Contract::AwaitRelease
            && pulled_mm < i32::from(RELEASE_SLOW_MM) =>
        {
            // With the gears still gripping, as the printer's retract goes on: a feel follows
            // them with no more force than it has.
            if strict(config) {
                Goal::DriveAt(config.slow_speed)
            } else {
                let taut = taut_or_unread(run, at);
                go_on_feeling(run, at, taut)?
            }
        }
        // Held again on the way (a stringy tip the gears still grip): only felt, until let go.
        _ if !strict(config)
            && at
                .unit
                .tension_reading(at.slot)
                .is_some_and(|t| taut_for(run, t, at.now, config) > 0) =>
        {
            go_on_feeling(run, at, true)?
        }
        _ => Goal::Drive,
    })
}

/// `P3` for a slot only believed to hold the hub path (a stored lane, after a restart): pull it
/// back, which is safe whichever slot really holds the path. A slot that does not hold it has its
/// tip before the merge, at most [`Config::preload_max_mm`] (the longest feed from the slot
/// sensor to the hub) ahead of its slot sensor: pulling it back clears its slot sensor within that
/// distance, and the guard at the slot sensor stops it there, its filament still in the drive
/// gear (`8008`: the stored belief was wrong, someone has to look). The slot that holds the path
/// shows it: the hub sensor clears (its tip was short of the printer), or its slot sensor still
/// sees filament after that distance (its tip was past the hub: a filament that long in front of
/// the slot sensor runs through the hub). Proven, it is unloaded on to the hub sensor, as far as
/// an unload from the printer's sensor; the printer's sensor, off when the proof began, must not
/// stay on for more than register `0x0c` mm (`8004`, whose Retry makes the printer help).
fn prove_owner<const N: usize>(run: &PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
    let past_proof_mm = at.toward_goal_mm - i32::from(at.config.preload_max_mm);
    Ok(match (at.hub, at.unit.fsensor_triggered()) {
        (false, false) => Goal::Reached.learning(Milestone::OwnerProven {
            at_centi: at.odometry,
        }),
        // Filament at the printer's sensor before the proof (the push proof waited for it to go
        // off): the unit's sensors read the same whichever slot's it is, and the printer may
        // still hold it. Prusa's recovery retracts it before its `U0`, and its report may come
        // just after the `U0`: wait for it, the motor free, as an unload waits
        // ([`RELEASE_WAIT_MS`]). Still on then: `8008`, nothing pulled.
        (_, true) if past_proof_mm <= 0 && at.now.millis_since(run.started) < RELEASE_WAIT_MS => {
            Goal::Yield.into()
        }
        (_, true) if past_proof_mm <= 0 => return Err(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
        (_, true) if past_proof_mm > i32::from(at.config.unload_check_mm) => {
            return Err(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF);
        }
        _ if past_proof_mm > 0 && at.unit.proven_owner != Some(at.slot) => {
            Goal::Drive.learning(Milestone::OwnerInPath)
        }
        _ => Goal::Drive.into(),
    })
}

/// Where `slot`'s tip left the hub, when an earlier phase of the command saw it.
fn hub_mark(notes: &Notes, slot: usize) -> Option<i32> {
    notes
        .hub_cleared
        .filter(|&(cleared, _)| cleared == slot)
        .map(|(_, odometry)| odometry)
}
