//! The feed from a slot to the hub (`P5`), the clearance of the merge (`P19`) that a feed
//! stalled where the slot paths join calls for: the unit's own part of the path, before the
//! printer has any say (MMU 3.0.3's `feed_to_finda.cpp`); and the short push that proves a
//! stored belief while the printer's sensor reads filament (`P3`).

use mmu_hal_port::Direction;
use mmu_protocol::{ErrorCode, ProgressCode};

use super::load::{MET_CONFIRM_MS, compressed_for};
use super::{Bounds, Decision, Goal, Milestone, Outcome, PhaseRun, Sight, SlotSet};
use crate::config::{Config, Contract};
use crate::unit::{Lane, Unit};

/// How far a slot whose tip nobody knows is fed to find out whether the slot sensor sees it, mm
/// (the sensor sits just after the drive gear).
const SLOT_PROBE_MM: i32 = 10;
/// How far [`Feed::PushProof`] pushes, mm: less than a parked tip's distance to the merge (the
/// park position, 15 mm before the hub sensor, is 7 mm from the merge on the reference unit), so a
/// slot that does not hold the path stays in its own path; more than the printer's sensor's
/// distance to its gears (4 mm on an MK3S), so a tip resting between them meets the gears.
const PUSH_PROOF_MM: u16 = 5;
/// How long the push proof waits for the printer to report its sensor off first, ms: an unload's
/// wait (MMU 3.0.4 `unload_to_finda.cpp`, 4000 ms).
const PUSH_PROOF_WAIT_MS: u64 = 4000;

/// The feed phases.
#[derive(Debug, Clone, Copy)]
pub(super) enum Feed {
    /// [`super::Phase::FeedToHub`].
    ToHub { max_mm: u16 },
    /// [`super::Phase::ClearMerge`].
    ClearMerge,
    /// [`super::Phase::PushProof`].
    PushProof,
}

impl Feed {
    pub(super) const fn progress(self) -> ProgressCode {
        match self {
            Feed::ToHub { .. } => ProgressCode::FEEDING_TO_FINDA,
            Feed::ClearMerge => ProgressCode::RETRACTING_FROM_FINDA,
            Feed::PushProof => ProgressCode::UNLOADING_TO_FINDA,
        }
    }

    pub(super) fn bounds(self, config: &Config) -> Bounds {
        match self {
            Feed::ToHub { max_mm } => Bounds::new(
                Direction::Forward,
                config.load_speed,
                max_mm,
                ErrorCode::FINDA_DIDNT_SWITCH_ON,
            ),
            Feed::ClearMerge => Bounds::new(
                Direction::Reverse,
                config.load_speed,
                config.park_mm,
                ErrorCode::MOVE_PULLEY_FAILED,
            ),
            // Waits first: the bound counts only the push.
            Feed::PushProof => Bounds::new(
                Direction::Forward,
                config.slow_speed,
                PUSH_PROOF_MM,
                ErrorCode::FINDA_VS_EEPROM_DISREPANCY,
            ),
        }
    }

    /// The merge clearance pulls the tip out of the merge, back to its drive gear.
    pub(super) const fn past_slot_sensor(self) -> bool {
        matches!(self, Feed::ClearMerge)
    }

    pub(super) fn goal<const N: usize>(
        self,
        run: &mut PhaseRun,
        at: &Sight<'_, N>,
    ) -> Result<Decision, ErrorCode> {
        Ok(match self {
            Feed::PushProof => return push_proof(run, at),
            Feed::ToHub { .. } if at.hub => Goal::Reached.into(),
            Feed::ToHub { .. }
                if !at.slot_sees
                    && (at.unit.lane(at.slot) != Lane::Unknown || at.toward_goal_mm >= SLOT_PROBE_MM) =>
            {
                // An empty slot: nothing to feed (a tip of unknown position may rest between the
                // drive gear and the slot sensor: a short feed first shows it).
                return Err(ErrorCode::FINDA_DIDNT_SWITCH_ON);
            }
            Feed::ToHub { .. } if !at.slot_sees => Goal::Drive.into(),
            Feed::ToHub { .. } => Goal::Drive.learning(Milestone::LeavingPark),
            Feed::ClearMerge if !at.slot_sees || at.toward_goal_mm >= i32::from(at.config.park_mm) => {
                Goal::Reached.learning(Milestone::MergeCleared)
            }
            Feed::ClearMerge => Goal::Drive.into(),
        })
    }

    pub(super) const fn arrival(self) -> Option<Lane> {
        match self {
            Feed::ToHub { .. } => Some(Lane::InHub),
            Feed::ClearMerge | Feed::PushProof => None,
        }
    }

    /// A feed to the hub that stalls may have met another slot's tip where the slot paths join.
    pub(super) fn stopped<const N: usize>(self, error: ErrorCode, unit: &Unit<N>, slot: usize) -> Outcome {
        match (self, error) {
            // Blocked at once: not by the printer's gears, which compress the tube first.
            (Feed::PushProof, ErrorCode::STALLED_PULLEY) => {
                Outcome::Fail(ErrorCode::FINDA_VS_EEPROM_DISREPANCY)
            }
            (Feed::ToHub { .. }, ErrorCode::STALLED_PULLEY) => match merge_suspects(unit, slot) {
                0 => Outcome::Fail(ErrorCode::STALLED_PULLEY),
                suspects => Outcome::Blocked(suspects),
            },
            _ => Outcome::Fail(error),
        }
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

/// [`Feed::PushProof`]: nothing to do with the printer's sensor off (the pull back proves the
/// belief, [`super::Phase::ProveOwner`]). With it on, wait (the motor free) for the printer to
/// report it off: its retract before `U0` may be on the way. Still on, a printer that accepted
/// 3.0.3 or older (which pull at once) gets the push: the tube reading compressed proves that the
/// slot's filament runs to the printer's gears; pushed [`PUSH_PROOF_MM`] without that, `8008`. A
/// printer that accepted 3.0.4 gets `8008` at once: MMU 3.0.4 pulls nothing before the printer's
/// sensor is off, and the pull that would follow a proof is one.
fn push_proof<const N: usize>(run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
    if !at.unit.fsensor_triggered() || at.unit.proven_owner == Some(at.slot) {
        return Ok(Goal::Reached.into());
    }
    let waiting = run.mark_centi.is_none();
    if waiting && at.now.millis_since(run.started) < PUSH_PROOF_WAIT_MS {
        return Ok(Goal::Yield.into());
    }
    if at.config.version.contract() == Contract::AwaitRelease {
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
    let Some(tension) = at.unit.hub.tension.reading() else {
        return Err(ErrorCode::FINDA_VS_EEPROM_DISREPANCY);
    };
    if compressed_for(run, tension, at.now, at.config) >= MET_CONFIRM_MS {
        return Ok(Goal::Reached.learning(Milestone::OwnerInPath));
    }
    if at.toward_goal_mm >= i32::from(PUSH_PROOF_MM) {
        return Err(ErrorCode::FINDA_VS_EEPROM_DISREPANCY);
    }
    Ok(Goal::Drive.into())
}
