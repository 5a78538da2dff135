//! Who drives each motor in a step. The running command's phase drives its slot; a loaded slot
//! follows the extruder through the tension sensor ([`follower`]) unless the unit holds an error
//! or that slot's spool end was reported; every other motor coasts. A slot that could not follow
//! stops the running command too, braked at once ([`Runner::interrupt`]): its failure is counted
//! on that slot, not on the command's, unless it is a spool end fastened to its core, which
//! FINDA then reports ([`SpoolEnd`]).

use mmu_hal_port::MotorCommand;

use crate::config::Config;
use crate::follower;
use crate::runner::{Runner, Status};
use crate::spool_end::SpoolEnd;
use crate::tally::Tally;
use crate::time::Instant;
use crate::unit::Unit;

/// The arbiter's state across steps: the loaded slot's spool-end watch.
#[derive(Debug, Clone, Copy, Default)]
pub struct MotorArbiter {
    spool_end: SpoolEnd,
}

impl MotorArbiter {
    /// Nothing watched.
    pub const NEW: MotorArbiter = MotorArbiter {
        spool_end: SpoolEnd::NEW,
    };

    /// The motors after the command `operation` stepped at `now`; `driving` is the slot it
    /// drives.
    pub fn drive<const N: usize>(
        &mut self,
        unit: &mut Unit<N>,
        operation: &mut Runner,
        tally: &mut Tally<N>,
        config: &Config,
        now: Instant,
        driving: Option<usize>,
    ) -> [MotorCommand; N] {
        let idle = matches!(operation.status(), Status::Finished);
        self.spool_end.watch(unit, idle, now);
        // A slot whose spool ended grips nothing: it is not followed.
        let allowed = !matches!(operation.status(), Status::Failed(_)) && self.spool_end.reported().is_none();
        if let Some((slot, error)) = follower::follow(unit, driving, allowed, now, config)
            && !self.spool_end.report_fastened(
                unit,
                slot,
                idle,
                config.spool_m.get(slot).copied().unwrap_or(0),
                tally.ledger.used_centi().get(slot).copied().unwrap_or(0),
            )
        {
            operation.interrupt(error, unit, now);
            tally.stalled(slot, error);
        }
        core::array::from_fn(|slot| {
            unit.drives
                .get(slot)
                .map_or(MotorCommand::Coast, |drive| drive.command())
        })
    }

    /// A command starts: a reported spool end has been handled (the printer's `U0`).
    pub fn command_started(&mut self) {
        self.spool_end.clear();
    }

    /// What FINDA reads: the hub sensor, or empty once a spool end is reported.
    pub fn finda<const N: usize>(&self, unit: &Unit<N>) -> bool {
        self.spool_end.finda(unit.hub_present(), unit.active().is_some())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive::Budget;
    use crate::unit::Lane;
    use mmu_hal_port::{Direction, Samples};
    use mmu_protocol::{ErrorCode, RequestCode};

    /// A unit whose slot 0 is loaded and proven to hold the path, its tension sensor pulled taut
    /// by the extruder for long enough to be believed.
    fn pulled_unit(config: &Config) -> Unit<3> {
        let mut unit = Unit::<3>::default();
        unit.set_lane(0, Lane::Loaded);
        unit.proven_owner = Some(0);
        let mut samples = Samples::<3>::uniform(2048);
        samples.hub.tension = config.tension_neutral + 4 * config.tension_deadband;
        for ms in 0..40 {
            unit.sense(&samples, Instant::from_millis(ms), config);
        }
        unit
    }

    fn finished() -> Runner {
        Runner::new((RequestCode::Reset, 0), &[])
    }

    /// The motors of a step at 40 ms of the pulled unit with slot 0's drive as `prepare` leaves
    /// it, `operation` running (or not); the tally after it.
    fn motors_of(
        operation: &mut Runner,
        prepare: impl FnOnce(&mut Unit<3>),
    ) -> ([MotorCommand; 3], Tally<3>) {
        let config = Config::default();
        let mut unit = pulled_unit(&config);
        prepare(&mut unit);
        let mut tally = Tally::new();
        let now = Instant::from_millis(40);
        let mut arbiter = MotorArbiter::NEW;
        let motors = arbiter.drive(&mut unit, operation, &mut tally, &config, now, None);
        (motors, tally)
    }

    #[test]
    fn a_loaded_slot_follows_the_extruder_and_every_other_motor_coasts() {
        let (motors, _) = motors_of(&mut finished(), |_| {});
        let forward = |motor| {
            matches!(
                motor,
                MotorCommand::Drive {
                    direction: Direction::Forward,
                    ..
                }
            )
        };
        assert!(forward(motors[0]), "{motors:?}");
        assert_eq!(&motors[1..], &[MotorCommand::Coast; 2]);
    }

    #[test]
    fn no_slot_follows_while_the_unit_holds_an_error() {
        let mut operation = Runner::failed((RequestCode::Tool, 1), ErrorCode::FSENSOR_DIDNT_SWITCH_ON);
        let (motors, tally) = motors_of(&mut operation, |_| {});
        assert!(motors.iter().all(|motor| !motor.is_driving()), "{motors:?}");
        assert_eq!(tally.counters.drive_errors, 0);
    }

    #[test]
    fn a_slot_that_cannot_follow_fails_the_command_and_counts_on_that_slot() {
        let mut operation = finished();
        // A budget already spent: the follower's drive gives up at once.
        let spent = Budget {
            max_mm: 0,
            max_ms: 0,
            max_still_ms: 0,
            error: ErrorCode::MOVE_PULLEY_FAILED,
        };
        let (motors, tally) = motors_of(&mut operation, |unit| {
            let feeder = unit.feeders[0];
            unit.drives[0].begin(spent, &feeder, Instant::ZERO);
        });
        assert!(!motors[0].is_driving(), "{motors:?}");
        assert!(matches!(operation.status(), Status::Failed(_)));
        assert_eq!(
            (tally.counters.drive_errors, tally.counters.failures),
            (1, [1, 0, 0])
        );
    }
}
