//! The feed from a slot to the hub (`P5`), the clearance of the merge (`P19`) that a feed
//! stalled where the slot paths join calls for: the unit's own part of the path, before the
//! printer has any say (MMU 3.0.3's `feed_to_finda.cpp`); and the short push that proves a
//! stored belief while the printer's sensor reads filament (`P3`).

use mmu_hal_port::Direction;
use mmu_protocol::{ErrorCode, ProgressCode};

use super::load::{MET_CONFIRM_MS, compressed_for};
use super::release::strict;
use super::{Bounds, Decision, Goal, Milestone, MotionPhase, Outcome, PhaseRun, Sight, SlotSet};
use crate::config::{Config, Contract};
use crate::unit::{Lane, Unit};

/// How far a slot whose tip nobody knows is fed to find out whether the slot sensor sees it, mm
/// (the sensor sits just after the drive gear).
const SLOT_PROBE_MM: i32 = 10;
/// How far [`PushProof`] pushes, mm: less than a parked tip's distance to the merge (the
/// park position, 15 mm before the hub sensor, is 7 mm from the merge on the reference unit), so a
/// slot that does not hold the path stays in its own path; more than the printer's sensor's
/// distance to its gears (4 mm on an MK3S), so a tip resting between them meets the gears.
const PUSH_PROOF_MM: u16 = 5;
/// How long the push proof waits for the printer to report its sensor off first, ms: an unload's
/// wait (MMU 3.0.4 `unload_to_finda.cpp`, 4000 ms).
const PUSH_PROOF_WAIT_MS: u64 = 4000;
/// How long the push proof holds the tube braked after its distance for a compression to show,
/// ms: a few times [`MET_CONFIRM_MS`].
const PUSH_PROOF_SETTLE_MS: u64 = 5 * MET_CONFIRM_MS;

/// `P5` ([`super::Phase::FeedToHub`]): feed until the hub sensor sees the tip, at most `max_mm`.
#[derive(Debug, Clone, Copy)]
pub(super) struct ToHub {
    pub(super) max_mm: u16,
}

impl MotionPhase for ToHub {
    fn progress(self) -> ProgressCode {
        ProgressCode::FEEDING_TO_FINDA
    }

    fn bounds(self, config: &Config) -> Bounds {
        Bounds::new(
            Direction::Forward,
            config.load_speed,
            self.max_mm,
            ErrorCode::FINDA_DIDNT_SWITCH_ON,
        )
    }

    fn goal<const N: usize>(self, _run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        let known_or_probed = at.unit.lane(at.slot) != Lane::Unknown || at.toward_goal_mm >= SLOT_PROBE_MM;
        if at.hub {
            Ok(Goal::Reached.into())
        } else if !at.slot_sees && known_or_probed {
            // An empty slot: nothing to feed (a tip of unknown position may rest between the
            // drive gear and the slot sensor: a short feed first shows it).
            Err(ErrorCode::FINDA_DIDNT_SWITCH_ON)
        } else if !at.slot_sees {
            Ok(Goal::Drive.into())
        } else {
            Ok(Goal::Drive.learning(Milestone::LeavingPark))
        }
    }

    fn arrival(self) -> Option<Lane> {
        Some(Lane::InHub)
    }

    /// A feed to the hub that stalls may have met another slot's tip where the slot paths join.
    fn stopped<const N: usize>(self, error: ErrorCode, unit: &Unit<N>, slot: usize) -> Outcome {
        if error != ErrorCode::STALLED_PULLEY {
            return Outcome::Fail(error);
        }
        match merge_suspects(unit, slot) {
            0 => Outcome::Fail(error),
            suspects => Outcome::Blocked(suspects),
        }
    }
}

/// `P19` ([`super::Phase::ClearMerge`]), for a parked slot or one whose tip nobody knows, when
/// another slot's feed stalls where the slot paths join: pull back the park distance (less if
/// the slot sensor clears: the tip is at the drive gear), so a tip resting in the merge cannot
/// block it.
#[derive(Debug, Clone, Copy)]
pub(super) struct ClearMerge;

impl MotionPhase for ClearMerge {
    fn progress(self) -> ProgressCode {
        ProgressCode::RETRACTING_FROM_FINDA
    }

    fn bounds(self, config: &Config) -> Bounds {
        Bounds::new(
            Direction::Reverse,
            config.load_speed,
            config.park_mm,
            ErrorCode::MOVE_PULLEY_FAILED,
        )
    }

    /// It pulls the tip out of the merge, back to its drive gear.
    fn past_slot_sensor(self) -> bool {
        true
    }

    fn goal<const N: usize>(self, _run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        Ok(
            if !at.slot_sees || at.toward_goal_mm >= i32::from(at.config.park_mm) {
                Goal::Reached.learning(Milestone::MergeCleared)
            } else {
                Goal::Drive.into()
            },
        )
    }
}

/// `P3` ([`super::Phase::PushProof`]), before the proof of a stored owner while the printer's
/// sensor reads filament: see [`push_proof`].
#[derive(Debug, Clone, Copy)]
pub(super) struct PushProof;

impl MotionPhase for PushProof {
    fn progress(self) -> ProgressCode {
        ProgressCode::UNLOADING_TO_FINDA
    }

    /// It waits first: the bound counts only the push.
    fn bounds(self, config: &Config) -> Bounds {
        Bounds::new(
            Direction::Forward,
            config.slow_speed,
            PUSH_PROOF_MM,
            ErrorCode::FINDA_VS_EEPROM_DISREPANCY,
        )
    }

    fn goal<const N: usize>(self, run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        push_proof(run, at)
    }

    /// Blocked at once: not by the printer's gears, which compress the tube first.
    fn stopped<const N: usize>(self, error: ErrorCode, _unit: &Unit<N>, _slot: usize) -> Outcome {
        Outcome::Fail(match error {
            ErrorCode::STALLED_PULLEY => ErrorCode::FINDA_VS_EEPROM_DISREPANCY,
            error => error,
        })
    }
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

/// [`PushProof`]: nothing to do with the printer's sensor off (the pull back proves the
/// belief, [`super::Phase::ProveOwner`]). With it on, wait (the motor free) for the printer to
/// report it off: its retract before `U0` may be on the way. Still on, it pushes: the tube
/// reading compressed proves that the slot's filament runs to the printer's gears; pushed
/// [`PUSH_PROOF_MM`] without that, `8008`. The unload that follows a proof feels first, on
/// either contract. In the strict mode (MMU 3.0.4, which pulls nothing before the printer's
/// sensor is off) a printer that accepted 3.0.4 gets `8008` at once.
fn push_proof<const N: usize>(run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
    if !at.unit.fsensor_triggered() || at.unit.proven_owner == Some(at.slot) {
        return Ok(Goal::Reached.into());
    }
    let waiting = run.mark_centi.is_none();
    if waiting && at.now.millis_since(run.started) < PUSH_PROOF_WAIT_MS {
        return Ok(Goal::Yield.into());
    }
    if strict(at.config) && at.config.version.contract() == Contract::AwaitRelease {
        return Err(ErrorCode::FINDA_VS_EEPROM_DISREPANCY);
    }
    if waiting {
        // The push counts from here, not from where the printer's retract left the odometry; a
        // Retry does not start it again (each would push a slot that does not hold the path
        // further, into the merge).
        run.mark_centi = Some(at.odometry);
        if !run.retried {
            run.goal_from_centi = at.odometry;
            return Ok(Goal::Drive.into());
        }
    }
    let Some(tension) = at.unit.tension_reading(at.slot) else {
        return Err(ErrorCode::FINDA_VS_EEPROM_DISREPANCY);
    };
    if compressed_for(run, tension, at.now, at.config) >= MET_CONFIRM_MS {
        return Ok(Goal::Reached.learning(Milestone::OwnerInPath));
    }
    if run.distance_done_at.is_none() && at.toward_goal_mm >= i32::from(PUSH_PROOF_MM) {
        run.distance_done_at = Some(at.now);
    }
    match run.distance_done_at {
        None => Ok(Goal::Drive.into()),
        // The odometry counts whole marks (a revolution of a Hall lane, 2 mm), so the push may
        // have gone a mark less than counted and only just met the gears: braked, a tube they
        // compressed stays so.
        Some(pushed) if at.now.millis_since(pushed) < PUSH_PROOF_SETTLE_MS => Ok(Goal::Hold.into()),
        Some(_) => Err(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
    }
}
