//! Whether the printer has let go of the filament an unload is to pull. This unit feels
//! ([`feel_for_release`]): it pulls too weakly to move a filament the extruder's gears grip and
//! watches the lane's motion and the tube's tension, so it waits as long as the printer moves the
//! filament and pulls as soon as nothing holds it, whatever the printer's sensor says; it tells
//! why it gives up ([`UnloadStuck`]). The strict mode, a simulator-only comparison, waits blind
//! as MMU 3.0.4 does ([`still_gripped`]).

use mmu_protocol::ErrorCode;

use super::load::{compressed_for, taut_for};
use super::{Goal, Notes, PhaseRun, Sight};
use crate::config::{Config, Contract};
use crate::feeder::distance_centi;
use crate::time::Instant;

/// How long an unload waits for the printer to release the filament (its sensor off), ms, before
/// it fails with `8004` having pulled nothing: MMU 3.0.4's limit (`unload_to_finda.cpp`, 4000 ms
/// from the command's acceptance).
pub(super) const RELEASE_WAIT_MS: u64 = 4000;
/// How far a feel must bring the filament back with the tube at rest before nothing holds it,
/// mm: two revolutions of a Hall lane, counted in whole ones.
const FREE_MM: i32 = 4;
/// The longest a feel waits while the filament keeps moving (the printer retracting slowly), ms.
const FEEL_MAX_MS: u64 = 30_000;
/// How long a filament that came back freely must keep the tube at rest with the motor braked,
/// ms: a printer retracting it at 20 mm/s compresses the tube past the deadband within 20 ms.
const FREE_PROBE_MS: u64 = 150;
/// How long a printer that accepted 3.0.3 or older retracts when it helps an unload, ms, from its
/// first `Q0` that saw `P3`: 20 mm at 20 mm/s (Buddy `mmu2_config.h`
/// `MMU2_RETRY_UNLOAD_TO_FINDA_LENGTH`, `_FEED_RATE`; `mmu2_mk4.cpp` `HelpUnloadToFinda`), and
/// half a second for its planner to start the move.
const PRINTER_HELP_MS: u64 = 1500;

/// Why an unload stopped on FSENSOR DIDNT CLEAR (`8004`): the printer shows one screen for what
/// the unit tells apart (register 0xfc, [`crate::registers::UNLOAD_STUCK`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnloadStuck {
    /// Felt held and still: the filament is stuck in the extruder (a blob on its tip, a cold
    /// nozzle, gears that still grip it).
    InExtruder = 1,
    /// Pulled back freely its check distance, the printer's sensor still reading filament: the
    /// sensor sticks, a string of the tip is left at it, or the lane's drive slips (its motion
    /// sensor counts the motor, not the filament).
    SensorStillOn = 2,
}

/// `8004`, with why noted for the register.
pub(super) fn stuck_because(run: &mut PhaseRun, why: UnloadStuck) -> ErrorCode {
    run.stuck = Some(why);
    ErrorCode::FSENSOR_DIDNT_SWITCH_OFF
}

/// The strict mode: the unload as MMU 3.0.4 does it (a simulator-only comparison).
pub(super) fn strict(config: &Config) -> bool {
    #[cfg(feature = "strict-unload")]
    return config.strict_unload;
    #[cfg(not(feature = "strict-unload"))]
    {
        let _ = config;
        false
    }
}

/// Before the pull, while the printer's sensor reads the filament: feel ([`Goal::Feel`]) until it
/// is free (`None`). Free means the feel brought it back [`FREE_MM`] with the tube at rest all
/// the way, and it stays at rest with the motor braked for [`FREE_PROBE_MS`] (a printer that
/// retracts it as fast as the feel would compress the tube then): nothing holds it, whatever the
/// sensor says (the tip between the sensor and the gears, a sensor that clears late). A tube
/// that reads taut (the gears grip what the feel pulls) or compressed (the printer retracts
/// faster than the feel) starts the count again. See [`go_on_feeling`] for how long.
pub(super) fn feel_for_release<const N: usize>(
    run: &mut PhaseRun,
    at: &Sight<'_, N>,
) -> Result<Option<Goal>, ErrorCode> {
    let taut = taut_or_unread(run, at);
    let held = taut
        || at
            .unit
            .tension_reading(at.slot)
            .is_some_and(|tension| compressed_for(run, tension, at.now, at.config) > 0);
    if held {
        run.felt_from_centi = Some(at.odometry);
        run.distance_done_at = None;
    }
    let felt_from = *run.felt_from_centi.get_or_insert(at.odometry);
    if distance_centi(at.odometry, felt_from) < FREE_MM * 100 {
        return go_on_feeling(run, at, taut).map(Some);
    }
    let stopped = *run.distance_done_at.get_or_insert(at.now);
    if at.now.millis_since(stopped) < FREE_PROBE_MS {
        return Ok(Some(Goal::Hold));
    }
    run.distance_done_at = None;
    Ok(None)
}

/// Whether the tube reads taut; a tension sensor that cannot be read counts as taut, since it
/// shows nothing free.
pub(super) fn taut_or_unread<const N: usize>(run: &mut PhaseRun, at: &Sight<'_, N>) -> bool {
    at.unit
        .tension_reading(at.slot)
        .is_none_or(|tension| taut_for(run, tension, at.now, at.config) > 0)
}

/// Feel on while the filament moves (the printer retracting it), at most [`FEEL_MAX_MS`]; still
/// for [`RELEASE_WAIT_MS`] with the tube taut: `8004`, the filament stuck in the extruder, and
/// nothing pulled harder than a feel. Still for the stall timeout with the tube not taut, the
/// feel did not even take up the tube's give: the motor is stalled.
pub(super) fn go_on_feeling<const N: usize>(
    run: &mut PhaseRun,
    at: &Sight<'_, N>,
    taut: bool,
) -> Result<Goal, ErrorCode> {
    if taut {
        run.last_taut = Some(at.now);
    }
    let last_mark = at
        .unit
        .feeders
        .get(at.slot)
        .map_or(run.started, |f| f.motion.last_mark());
    let still_ms = at.now.millis_since(last_mark.max(run.started));
    let moved_or_taut = run.last_taut.map_or(last_mark, |taut| taut.max(last_mark));
    let stalled =
        at.now.millis_since(moved_or_taut.max(run.started)) >= u64::from(at.config.stall_timeout_ms);
    if !taut && stalled {
        Err(ErrorCode::STALLED_PULLEY)
    } else if still_ms >= RELEASE_WAIT_MS {
        Err(stuck_because(run, UnloadStuck::InExtruder))
    } else if at.now.millis_since(run.started) >= FEEL_MAX_MS {
        Err(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF)
    } else {
        Ok(Goal::Feel)
    }
}

/// While an unload waits for the printer to release the filament and its sensor still reads it:
/// whether its gears may still grip it (keep waiting), or `8004`.
///
/// A printer that accepted 3.0.4 reports its sensor off once it has released the filament: after
/// [`RELEASE_WAIT_MS`] without that, `8004`, nothing pulled (MMU 3.0.4). A printer that accepted
/// 3.0.3 or older helps an unload it did not send as `U0`/`T` when its `Q0` sees `P3`, and after
/// the Retry of `8004`: once its help has had its time ([`PRINTER_HELP_MS`] from that `Q0`), or
/// at the latest after [`RELEASE_WAIT_MS`], the unit pulls, as MMU 3.0.3 does.
pub(super) fn still_gripped(
    run: &mut PhaseRun,
    notes: &Notes,
    now: Instant,
    config: &Config,
) -> Result<bool, ErrorCode> {
    if notes.printer.polled > run.started && run.printer_saw.is_none() {
        run.printer_saw = Some(notes.printer.polled);
    }
    let waited_out = now.millis_since(run.started) >= RELEASE_WAIT_MS;
    match config.version.contract() {
        Contract::AwaitRelease if waited_out => Err(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF),
        Contract::AwaitRelease => Ok(true),
        Contract::PullAtOnce => {
            let helped = run
                .printer_saw
                .is_some_and(|saw| now.millis_since(saw) >= PRINTER_HELP_MS);
            Ok(!(helped || waited_out))
        }
    }
}
