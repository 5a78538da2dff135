//! The tension follower: while a slot is loaded and printing, its motor helps the extruder pull
//! the filament off the spool, in proportion to how taut the Bowden tube reads.
//!
//! It is a supervised motion like any other ([`crate::drive`]): the stall rule applies, and a
//! motor that assists without turning for [`STILL_MS`] (a tangled spool or a jam the extruder
//! pulls against) is stopped. The follower then reports [`JAM_ERROR`] on the last command
//! (`T<n> E804b` to the printer's `Q0`): the printer shows PULLEY CANNOT MOVE, presses Retry
//! itself up to three times, then asks the user; Retry (`B1`) lets the follower try again
//! (`T<n> F0` once nothing is wrong). Nothing follows while the unit holds an error: no motor
//! moves then unless the user's Retry asks for it.

use mmu_protocol::ErrorCode;

use crate::config::Config;
use crate::drive::{Budget, Motion, follow_duty};
use crate::time::Instant;
use crate::unit::{Lane, Unit};

/// The longest the follower may assist without a motor revolution, ms. Within 5 s of a jam the
/// motor is stopped, whatever its duty.
pub const STILL_MS: u64 = 3000;

/// The error a jam or tangle while printing raises.
pub const JAM_ERROR: ErrorCode = ErrorCode::MOVE_PULLEY_FAILED;

/// The follower's budget: no distance or time limit while printing (a print consumes metres),
/// but the motor must keep turning.
const BUDGET: Budget = Budget {
    max_mm: u16::MAX,
    max_ms: u32::MAX,
    max_still_ms: STILL_MS as u32,
    error: JAM_ERROR,
};

/// Drive every loaded slot that no command drives (`driving`), as the tension says; every other
/// idle motor is released. `allowed` is false while the unit holds an error. Returns a slot whose
/// motor could not follow (it is stopped) and its error.
pub fn follow<const N: usize>(
    unit: &mut Unit<N>,
    driving: Option<usize>,
    allowed: bool,
    now: Instant,
    config: &Config,
) -> Option<(usize, ErrorCode)> {
    let tensions: [Option<u16>; N] = core::array::from_fn(|slot| unit.tension_reading(slot));
    let mut failed = None;
    // A slot restored as loaded is followed only once it is known to hold the path.
    let follows: [bool; N] =
        core::array::from_fn(|slot| unit.lanes.get(slot) == Some(&Lane::Loaded) && unit.owner_proven(slot));
    for (slot, (drive, feeder)) in unit.drives.iter_mut().zip(unit.feeders.iter()).enumerate() {
        if Some(slot) == driving {
            continue;
        }
        let tension = tensions.get(slot).copied().flatten();
        let assist = follow_duty(0, tension, config).permille() > 0;
        if !(allowed && follows.get(slot).copied().unwrap_or(false) && assist) {
            drive.release(now);
            continue;
        }
        if !drive.is_supervising() {
            drive.begin(BUDGET, feeder, now);
        }
        if let Err(error) = drive.run(Motion::Follow { speed: 0 }, feeder, tension, now, config) {
            failed = Some((slot, error));
        }
    }
    failed
}
