//! Homing a lane at its presence sensor, on hardware without a hub sensor: the pull back until
//! the sensor's edge (where the tip is then known exactly) and the feed on to the park position
//! counted from there. Every park and every load of a lane whose tip the unit has not seen since
//! start goes through them ([`crate::commands::fit_to_profile`]), so the odometry's drift (a
//! drive gear slipping under load counts more than the filament moved) never outlives one unload.

use mmu_hal_port::Direction;
use mmu_protocol::{ErrorCode, ProgressCode};

use super::{Bounds, Decision, Goal, MotionPhase, PhaseRun, Sight};
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

    fn goal<const N: usize>(self, _run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        let near = at
            .unit
            .tip_centi(at.slot)
            .is_some_and(|tip| tip < SLOW_NEAR_MM * 100);
        Ok(match (at.slot_sees, near) {
            (false, _) => Goal::Reached,
            (true, true) => Goal::DriveAt(at.config.slow_speed),
            (true, false) => Goal::Drive,
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

    fn goal<const N: usize>(self, _run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        let park_centi = (i32::from(at.config.lane_to_hub_mm) - i32::from(at.config.park_mm)) * 100;
        match at.unit.tip_centi(at.slot) {
            Some(tip) if at.slot_sees && tip >= park_centi => Ok(Goal::Reached.into()),
            // The sensor never saw a tip come: an empty lane.
            _ if !at.slot_sees && at.toward_goal_mm >= EMPTY_AFTER_MM => {
                Err(ErrorCode::FINDA_DIDNT_SWITCH_ON)
            }
            _ => Ok(Goal::Drive.into()),
        }
    }

    fn arrival(self) -> Option<Lane> {
        Some(Lane::Parked)
    }
}
