//! The feed from a slot to the hub (`P5`), and the clearance of the merge (`P19`) that a feed
//! stalled where the slot paths join calls for: the unit's own part of the path, before the
//! printer has any say (MMU 3.0.3's `feed_to_finda.cpp`).

use mmu_hal_port::Direction;
use mmu_protocol::{ErrorCode, ProgressCode};

use super::{Bounds, Decision, Goal, Milestone, Outcome, PhaseRun, Sight, SlotSet};
use crate::config::Config;
use crate::unit::{Lane, Unit};

/// How far a slot whose tip nobody knows is fed to find out whether the slot sensor sees it, mm
/// (the sensor sits just after the drive gear).
const SLOT_PROBE_MM: i32 = 10;

/// The feed phases.
#[derive(Debug, Clone, Copy)]
pub(super) enum Feed {
    /// [`super::Phase::FeedToHub`].
    ToHub { max_mm: u16 },
    /// [`super::Phase::ClearMerge`].
    ClearMerge,
}

impl Feed {
    pub(super) const fn progress(self) -> ProgressCode {
        match self {
            Feed::ToHub { .. } => ProgressCode::FEEDING_TO_FINDA,
            Feed::ClearMerge => ProgressCode::RETRACTING_FROM_FINDA,
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
        }
    }

    /// The merge clearance pulls the tip out of the merge, back to its drive gear.
    pub(super) const fn past_slot_sensor(self) -> bool {
        matches!(self, Feed::ClearMerge)
    }

    pub(super) fn goal<const N: usize>(
        self,
        _run: &mut PhaseRun,
        at: &Sight<'_, N>,
    ) -> Result<Decision, ErrorCode> {
        Ok(match self {
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
            Feed::ClearMerge => None,
        }
    }

    /// A feed to the hub that stalls may have met another slot's tip where the slot paths join.
    pub(super) fn stopped<const N: usize>(self, error: ErrorCode, unit: &Unit<N>, slot: usize) -> Outcome {
        match (self, error) {
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
