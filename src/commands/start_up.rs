//! The start-up check: after every restart, before any command, the unit checks that its
//! sensors are healthy and that the stored lanes agree with the hub sensor. The printer sees it
//! as the command `X0`.
//!
//! `P1a`. Filament in the hub that no slot owns, or a slot recorded as loaded whose tip the hub
//! sensor does not see, is `8008` (UNLOAD MANUALLY) and no motor moves (a slot recorded between
//! its park position and the hub, a restart mid tool change, keeps the path); a sensor stuck
//! at a rail is `800a` (hub) or `804b` (slot).

use mmu_protocol::ErrorCode;

use super::{Plan, Recovery, extend, retry};
use crate::phases::Phase;

/// The plan of the check, appended to `plan`.
pub fn plan(plan: &mut Plan) {
    extend(plan, &[Phase::CheckSensors]);
}

/// Retry checks again, trusting what the sensors say now over the stored lanes.
pub const RECOVERY: &[Recovery] = &[
    retry(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
    retry(ErrorCode::FINDA_FLICKERS),
    retry(ErrorCode::MOVE_PULLEY_FAILED),
];
