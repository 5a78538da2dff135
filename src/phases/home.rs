//! Homing a lane at its presence sensor, on hardware without a hub sensor: the pull back until
//! the sensor's edge (where the tip is then known exactly) and the feed on to the park position
//! counted from there. Every park and every load of a lane whose tip the unit has not seen since
//! start goes through them ([`crate::commands::fit_to_profile`]), so the odometry's drift (a
//! drive gear slipping under load counts more than the filament moved) never outlives one unload.

use mmu_hal_port::Direction;
use mmu_protocol::{ErrorCode, ProgressCode};

use super::{Bounds, Decision, Goal, Milestone, MotionPhase, PhaseRun, Sight};
use crate::config::Config;
use crate::unit::Lane;

/// How close to the presence sensor the tip estimate may come at the full speed, mm: the rest
/// goes at the slow speed, so the edge stops the tip well before it leaves the drive gear.
const SLOW_NEAR_MM: i32 = 10;
/// How far a lane is fed with its presence sensor seeing nothing before it counts as empty, mm.
const EMPTY_AFTER_MM: i32 = 10;

/// `P19` ([`super::Phase::HomeLane`]): pull back until the presence sensor stops seeing the tip.
#[derive(Debug, Clone, Copy)]
pub(super) struct ToPresenceEdge;

impl MotionPhase for ToPresenceEdge {
    fn progress(self) -> ProgressCode {
        ProgressCode::RETRACTING_FROM_FINDA
    }

    /// From anywhere up to the merge and the hub search beyond it.
    fn bounds(self, config: &Config) -> Bounds {
        Bounds {
            slower_mm: SLOW_NEAR_MM as u16,
            ..Bounds::new(
                Direction::Reverse,
                config.load_speed,
                config.lane_to_hub_mm.saturating_add(config.hub_search_mm),
                ErrorCode::FINDA_DIDNT_SWITCH_OFF,
            )
        }
    }

    /// Reached at the edge, where the tip is behind the merge. No estimate stops the pull before
    /// the edge: a drive that slipped, or a filament whose tail was pulled back into its gear,
    /// leaves the count behind the filament; the phase's bound does.
    fn goal<const N: usize>(self, _run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        if !at.slot_sees {
            return Ok(Goal::Reached.learning(Milestone::MergeCleared));
        }
        let tip = at.unit.tip_centi(at.slot);
        Ok(match tip {
            Some(tip) if tip < SLOW_NEAR_MM * 100 => Goal::DriveAt(at.config.slow_speed),
            _ => Goal::Drive,
        }
        .into())
    }

    /// Its goal is the edge itself.
    fn past_slot_sensor(self) -> bool {
        true
    }
}

/// `P19` ([`super::Phase::FeedToPark`]): from behind the presence sensor, feed until the tip is
/// the park distance before the merge, counted from the sensor's edge.
#[derive(Debug, Clone, Copy)]
pub(super) struct FromEdgeToPark;

impl MotionPhase for FromEdgeToPark {
    fn progress(self) -> ProgressCode {
        ProgressCode::RETRACTING_FROM_FINDA
    }

    fn bounds(self, config: &Config) -> Bounds {
        Bounds::new(
            Direction::Forward,
            config.load_speed,
            config.lane_to_hub_mm,
            ErrorCode::FINDA_DIDNT_SWITCH_ON,
        )
    }

    /// Parked once the tip is the park distance before the merge. A lane whose sensor sees no
    /// tip come is empty: its filament left the drive gear (it ends there, the hub clear; a load
    /// that follows fails on the empty slot, `8001`). A sensor that sees filament whose tip is
    /// not known (its edge came while the motor was not driven) leaves nothing to count the park
    /// from: `8002`, whose Retry homes the lane again ([`crate::runner`]).
    fn goal<const N: usize>(self, _run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        let park_centi = (i32::from(at.config.lane_to_hub_mm) - i32::from(at.config.park_mm)) * 100;
        match (at.unit.tip_centi(at.slot), at.slot_sees) {
            (Some(tip), true) if tip >= park_centi => {
                Ok(Goal::Reached.learning(Milestone::Arrived(Lane::Parked)))
            }
            (None, true) => Err(ErrorCode::FINDA_DIDNT_SWITCH_OFF),
            (_, false) if at.toward_goal_mm >= EMPTY_AFTER_MM => {
                Ok(Goal::Reached.learning(Milestone::Arrived(Lane::Empty)))
            }
            _ => Ok(Goal::Drive.into()),
        }
    }
}
