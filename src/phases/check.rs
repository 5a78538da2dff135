//! The phases that move nothing: the sensor check (`P1a`) that starts the unit and homes it, and
//! the wait for the user after an eject (`E800c`).

use mmu_protocol::{ErrorCode, ProgressCode};

use super::{Notes, Outcome, PhaseRun, sensor_fault_error};
use crate::time::Instant;
use crate::unit::{Lane, Unit};

/// How long a check may wait for the sensors to settle after start, ms.
const SENSOR_SETTLE_MS: u64 = 1000;

/// The phases that move nothing.
#[derive(Debug, Clone, Copy)]
pub(super) enum Check {
    /// [`super::Phase::CheckSensors`].
    Sensors,
    /// [`super::Phase::AwaitContinue`].
    AwaitContinue,
}

impl Check {
    pub(super) const fn progress(self) -> ProgressCode {
        match self {
            Check::Sensors => ProgressCode::HOMING,
            Check::AwaitContinue => ProgressCode::ERR_WAITING_FOR_USER,
        }
    }

    /// One step of the check, and the lanes as it finds them (the unit's own, when it has not
    /// come to them).
    pub(super) fn step<const N: usize>(
        self,
        run: &mut Option<PhaseRun>,
        notes: &Notes,
        unit: &Unit<N>,
        now: Instant,
    ) -> (Outcome, [Lane; N]) {
        let mut lanes = unit.lanes;
        let outcome = match self {
            Check::Sensors => check_sensors(run, notes, unit, &mut lanes, now),
            Check::AwaitContinue => Outcome::Fail(ErrorCode::FILAMENT_EJECTED),
        };
        (outcome, lanes)
    }
}

/// `P1a`: every sensor healthy, and the hub sensor agrees with the known `lanes` (corrected as
/// the sensors and a Retry allow).
fn check_sensors<const N: usize>(
    run: &mut Option<PhaseRun>,
    notes: &Notes,
    unit: &Unit<N>,
    lanes: &mut [Lane; N],
    now: Instant,
) -> Outcome {
    if let Some(fault) = unit.first_fault() {
        return Outcome::Fail(sensor_fault_error(fault));
    }
    // Every sensor must have settled: a reading, or a fault (a sensor stuck at a rail is called
    // faulty only after the rail timeout, so an early check would miss it).
    let unsettled =
        Unit::<N>::sensor_ids().find(|&id| unit.sensor(id).is_some_and(|s| s.reading().is_none()));
    let hub = unit.hub_present();
    if let (Some(_), _) | (None, None) = (unsettled, hub) {
        let started = match run {
            Some(run) => run.started,
            None => PhaseRun::start(run, now, 0, 0).started,
        };
        if now.millis_since(started) > SENSOR_SETTLE_MS {
            return Outcome::Fail(unsettled.map_or(ErrorCode::FINDA_FLICKERS, sensor_fault_error));
        }
        return Outcome::Continue;
    }
    let Some(hub) = hub else {
        return Outcome::Continue;
    };
    // At most one slot can be past its park position: stored lanes that say otherwise are
    // not to be believed. After Retry they are forgotten and the hub sensor decides.
    if lanes.iter().filter(|lane| lane.owns_hub()).count() > 1 {
        if !notes.trust_sensors {
            return Outcome::Fail(ErrorCode::FINDA_VS_EEPROM_DISREPANCY);
        }
        for lane in lanes.iter_mut().filter(|lane| lane.owns_hub()) {
            *lane = Lane::Unknown;
        }
    }
    let active = lanes.iter().position(|lane| lane.owns_hub());
    match (hub, active.and_then(|slot| lanes.get_mut(slot))) {
        (true, None) => return Outcome::Fail(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
        // The user has looked, or the slot was on its way between its park position and the hub
        // (a restart while it was fed or retracted): its tip is somewhere before the hub sensor.
        // It keeps the path until the next command parks it from there. (MMU 3.0.4's start-up
        // drops a record FINDA does not confirm: `start_up.cpp` `CheckFINDAvsEEPROM`.) A slot
        // recorded as loaded that the hub sensor does not see is `8008`: someone has to look.
        (false, Some(lane)) if notes.trust_sensors || *lane == Lane::InHub => *lane = Lane::InHub,
        (false, Some(_)) => return Outcome::Fail(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
        _ => {}
    }
    for (lane, feeder) in lanes.iter_mut().zip(unit.feeders.iter()) {
        match (*lane, feeder.filament.present()) {
            (Lane::Unknown | Lane::Parked, Some(false)) => *lane = Lane::Empty,
            (Lane::Empty, Some(true)) => *lane = Lane::Unknown,
            _ => {}
        }
    }
    Outcome::Done
}
