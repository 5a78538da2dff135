//! The load from the hub into the printer: fast through the Bowden tube (`P6`), slowly to the
//! printer's sensor while the printer co-feeds (`P1c`, and its search after a Retry), and the
//! push into the extruder's gears with its proof that they hold the tip (`P7`). MMU 3.0.3 keeps
//! these in `feed_to_bondtech.cpp`.

use mmu_hal_port::Direction;
use mmu_protocol::{ErrorCode, ProgressCode};

use super::{Bounds, Decision, Goal, Milestone, MotionPhase, Outcome, PhaseRun, Sight, sensor_fault_error};
use crate::commands::load_to_nozzle::learned_bowden_mm;
use crate::config::Config;
use crate::feeder::distance_centi;
use crate::sensor::AnalogSensor;
use crate::time::Instant;
use crate::unit::{Lane, Unit};

/// How long the Bowden tube must read compressed before the push into the extruder stops, ms:
/// the tip has met something (the gears, turning or idle, or a jam), and the push must stop
/// while the printer's own push still runs (one noisy reading is not enough).
pub(super) const MET_CONFIRM_MS: u64 = 10;
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

/// A feed at `speed` for at most `max_mm`, failing with `error`.
const fn forward(speed: u16, max_mm: u16, error: ErrorCode) -> Bounds {
    Bounds::new(Direction::Forward, speed, max_mm, error)
}

/// A motor stopped on its way to the printer's sensor (`P6`, `P1c`) stopped because the
/// filament did not get there: a jam in the Bowden tube, or the tip pressed into the printer's
/// idle extruder because its sensor never triggered (or was never heard). That is FSENSOR DIDNT
/// TRIGG. (`8003`), whose screen sends the user to the tube and the printer's sensor; PULLEY
/// CANNOT MOVE (`8047`) would send them to the slot motor, which moved the filament all the way
/// from the hub. MMU 3.0.3 reports `8003` here too: it has no pulley stall detection and runs out
/// its planned distance (`feed_to_bondtech.cpp`).
fn short_of_fsensor(error: ErrorCode) -> Outcome {
    Outcome::Fail(match error {
        ErrorCode::STALLED_PULLEY => ErrorCode::FSENSOR_DIDNT_SWITCH_ON,
        error => error,
    })
}

/// `P6` ([`super::Phase::FeedThroughBowden`]): fast feed through most of the Bowden tube; the
/// printer's sensor must stay off.
#[derive(Debug, Clone, Copy)]
pub(super) struct ThroughBowden;

impl MotionPhase for ThroughBowden {
    fn progress(self) -> ProgressCode {
        ProgressCode::FEEDING_TO_BONDTECH
    }

    fn bounds(self, config: &Config) -> Bounds {
        forward(
            config.load_speed,
            config.bowden_mm.saturating_sub(config.bowden_slowdown_mm),
            ErrorCode::FSENSOR_DIDNT_SWITCH_ON,
        )
    }

    /// Ends at its distance, or where the tube reads compressed: the tip met a stop, the
    /// printer's idle gears where they come before its sensor (a jam stops the slow feed too).
    fn goal<const N: usize>(self, run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        let met = met_a_stop(run, at);
        if at.unit.fsensor_triggered() {
            Err(ErrorCode::FSENSOR_TOO_EARLY)
        } else if met {
            Ok(Goal::Reached.learning(Milestone::StopBeforeFsensor {
                from_hub_centi: run.goal_from_centi,
            }))
        } else if at.toward_goal_mm >= i32::from(at.bounds.max_mm) {
            Ok(Goal::Reached.into())
        } else {
            Ok(Goal::Drive.into())
        }
    }

    fn arrival(self) -> Option<Lane> {
        Some(Lane::InHub)
    }

    fn stopped<const N: usize>(self, error: ErrorCode, _unit: &Unit<N>, _slot: usize) -> Outcome {
        short_of_fsensor(error)
    }
}

/// The longest `P1c` holds a tip that met the printer's gears before its sensor, ms: Buddy 6.5.3's
/// 80 mm finishing retract at a quarter of its 20 mm/s, and a margin.
const GEARS_WAIT_MS: u64 = 20_000;

/// `P1c` ([`super::Phase::FeedToFsensor`]): slow feed until the printer's sensor triggers; the
/// printer co-feeds. As a `search` after Retry of `8003` ([`super::Phase::SearchFsensor`]), the
/// same feed from wherever the tip is past the hub sensor, at most the whole Bowden length plus
/// the search distance (the tip may be anywhere in the tube).
#[derive(Debug, Clone, Copy)]
pub(super) struct ToFsensor {
    pub(super) search: bool,
}

impl MotionPhase for ToFsensor {
    fn progress(self) -> ProgressCode {
        ProgressCode::FEEDING_TO_FSENSOR
    }

    fn bounds(self, config: &Config) -> Bounds {
        let before_search = if self.search {
            config.bowden_mm
        } else {
            config.bowden_slowdown_mm
        };
        forward(
            config.slow_speed,
            before_search.saturating_add(config.fsensor_search_mm),
            ErrorCode::FSENSOR_DIDNT_SWITCH_ON,
        )
    }

    /// It ends on the printer's `f1` while the printer co-feeds.
    fn paced_by_printer(self) -> bool {
        true
    }

    /// The slow feed ends at the printer's sensor, once the printer's `Q0` has seen this phase.
    fn goal<const N: usize>(self, run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        let met = met_a_stop(run, at);
        Ok(if !at.unit.fsensor_triggered() {
            // Met a stop before the sensor: the printer's gears, turning back while its retract
            // lasts, take the tip once its co-feed turns them forward. Pushing on would stall.
            if met && at.now.millis_since(run.started) < GEARS_WAIT_MS {
                Goal::Hold.into()
            } else {
                Goal::Drive.into()
            }
        } else if at.notes.printer.polled > run.started {
            // After a stop before the sensor, where it triggered is the Bowden length.
            let measured = at
                .notes
                .stop_before_fsensor
                .and_then(|from| learned_bowden_mm(distance_centi(from, at.odometry) / 100, at.config));
            match measured {
                Some(mm) => Goal::Reached.learning(Milestone::BowdenMeasured(mm)),
                None => Goal::Reached.into(),
            }
        } else {
            // The printer pushes its extruder for the load only once it has seen `P1c` with its
            // sensor triggered (`OnMMUProgressMsgSame`, printer-truth §8): until its next `Q0`
            // has seen this phase, the tip waits at the sensor.
            Goal::Hold.into()
        })
    }

    fn arrival(self) -> Option<Lane> {
        Some(Lane::AtFsensor)
    }

    fn stopped<const N: usize>(self, error: ErrorCode, _unit: &Unit<N>, _slot: usize) -> Outcome {
        short_of_fsensor(error)
    }
}

/// `P7` ([`super::Phase::FeedToNozzle`]): push into the extruder's gears while the printer
/// pushes with its own extruder, then hold and see the gears pull the filament on.
#[derive(Debug, Clone, Copy)]
pub(super) struct ToNozzle;

impl MotionPhase for ToNozzle {
    fn progress(self) -> ProgressCode {
        ProgressCode::FEEDING_TO_NOZZLE
    }

    /// Faster than the printer's push (its slow feed), so a tip its turning gears hold
    /// compresses the tube at once and the push stops while they still pull.
    fn bounds(self, config: &Config) -> Bounds {
        forward(
            config.slow_speed.saturating_mul(2),
            config
                .extra_load_mm
                .saturating_mul(2)
                .saturating_add(NOZZLE_PUSH_MARGIN_MM),
            ErrorCode::MOVE_PULLEY_FAILED,
        )
    }

    /// It pushes into the printer's extruder as the printer takes the filament.
    fn paced_by_printer(self) -> bool {
        true
    }

    fn goal<const N: usize>(self, run: &mut PhaseRun, at: &Sight<'_, N>) -> Result<Decision, ErrorCode> {
        let sensor = at.unit.tension(at.slot);
        let goal = match sensor.and_then(AnalogSensor::reading) {
            Some(tension) => push_into_gears(run, tension, at.toward_goal_mm, at.now, at.config)?,
            // Nothing else shows the gears holding the tip: no load is reported done blind.
            None if sensor.is_some_and(|sensor| sensor.fault().is_some()) => {
                return Err(sensor_fault_error(at.unit.tension_id(at.slot)));
            }
            None => Goal::Hold,
        };
        Ok(goal.into())
    }

    fn arrival(self) -> Option<Lane> {
        Some(Lane::Loaded)
    }
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
    if run.distance_done_at.is_none() {
        let met = compressed_for(run, tension, now, config) >= MET_CONFIRM_MS;
        let push_mm = config.extra_load_mm.saturating_add(NOZZLE_PUSH_MARGIN_MM);
        if !met && pushed_mm < i32::from(push_mm) {
            return Ok(Goal::Drive);
        }
        run.distance_done_at = Some(now);
    }
    // Past the printer's push: `extra_load_mm + 2` mm at the slow speed, plus the margin.
    let push_ms =
        u32::from(config.extra_load_mm.saturating_add(2)) * 1000 / u32::from(config.slow_speed.max(1));
    if now.millis_since(run.started) > u64::from(push_ms) + PRINTER_PUSH_MARGIN_MS {
        Err(ErrorCode::FSENSOR_DIDNT_SWITCH_ON)
    } else {
        Ok(Goal::Hold)
    }
}

/// The Bowden tube has read compressed for [`MET_CONFIRM_MS`]: the tip met something. Inlined:
/// at opt-level "z" a call from each generic phase takes more flash than the body.
#[inline(always)]
fn met_a_stop<const N: usize>(run: &mut PhaseRun, at: &Sight<'_, N>) -> bool {
    at.unit
        .tension_reading(at.slot)
        .is_some_and(|tension| compressed_for(run, tension, at.now, at.config) >= MET_CONFIRM_MS)
}

/// How long the Bowden tube has read taut past the follower's deadband (pulled from the
/// extruder's side), ms. A reading at the supply rail is a loose wire, not a pull.
pub(super) fn taut_for(run: &mut PhaseRun, tension: u16, now: Instant, config: &Config) -> u64 {
    let taut = u32::from(tension) > u32::from(config.tension_neutral) + u32::from(config.tension_deadband)
        && tension < crate::sensor::RAIL_HIGH;
    run.taut_since = if taut { run.taut_since.or(Some(now)) } else { None };
    run.taut_since.map_or(0, |since| now.millis_since(since))
}

/// How long the Bowden tube has read compressed by more than half the follower's deadband, ms:
/// the push stops as soon as the tip meets something, so the printer's push has the most left to
/// pull (stopping early is the safe side: the tip may fall short, then no grip shows and Retry
/// pushes again).
pub(super) fn compressed_for(run: &mut PhaseRun, tension: u16, now: Instant, config: &Config) -> u64 {
    let compressed =
        u32::from(tension) + u32::from(config.tension_deadband / 2) < u32::from(config.tension_neutral);
    run.compressed_since = if compressed {
        run.compressed_since.or(Some(now))
    } else {
        None
    };
    run.compressed_since.map_or(0, |since| now.millis_since(since))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The push went its distance with the tube at rest: from here on only the printer's push
    /// can show a grip, and it lasts `extra_load_mm + 2` mm at the slow speed plus the margin.
    #[test]
    fn the_unit_holds_until_the_printers_push_is_over_and_then_reports_8003() {
        for (extra_load_mm, slow_speed) in [(30, 20), (0, 1), (7, 3), (65_535, 65_535), (100, 0)] {
            let config = Config {
                extra_load_mm,
                slow_speed,
                ..Config::default()
            };
            let started = Instant::from_millis(5_000);
            let mut slot = None;
            let run = PhaseRun::start(&mut slot, started, 0, 0);
            run.distance_done_at = Some(started);
            let neutral = config.tension_neutral;
            let push_ms = (u64::from(extra_load_mm) + 2) * 1000 / u64::from(slow_speed.max(1)) + 600;
            let at = |ms: u64| Instant::from_millis(5_000 + ms);
            for ms in [0, push_ms - 1, push_ms] {
                assert!(
                    matches!(push_into_gears(run, neutral, 0, at(ms), &config), Ok(Goal::Hold)),
                    "{extra_load_mm} mm at {slow_speed} mm/s: held at {ms} of {push_ms} ms"
                );
            }
            for ms in [push_ms + 1, push_ms + 10_000, u64::from(u32::MAX) + push_ms] {
                assert_eq!(
                    push_into_gears(run, neutral, 0, at(ms), &config).err(),
                    Some(ErrorCode::FSENSOR_DIDNT_SWITCH_ON),
                    "{extra_load_mm} mm at {slow_speed} mm/s: {ms} of {push_ms} ms"
                );
            }
        }
    }
}
