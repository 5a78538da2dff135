//! UnloadFromNozzle (`U0`, and the first half of a tool change): the slot that owns the hub path
//! comes back out of the printer and the hub and is parked.
//!
//! `P3` pull back until the printer's sensor (within register `0x0c` mm) and then the hub sensor
//! clear, `P19` on to the park position. Nothing loaded: done at once.

use mmu_protocol::ErrorCode;

use super::{Plan, Recovery, clear_hub, retry};
use crate::phases::Phase;
use crate::unit::Unit;

/// Pull `slot`'s filament out of the printer and the hub, and park it.
pub const fn phases(slot: usize) -> [Phase; 2] {
    [
        Phase::UnloadToHub { slot: slot as u8 },
        Phase::RetractToPark { slot: slot as u8 },
    ]
}

/// The plan for `U0`, appended to `plan`.
pub fn plan<const N: usize>(unit: &Unit<N>, plan: &mut Plan) -> Result<(), ErrorCode> {
    clear_hub(plan, unit)
}

/// What each error of the unload means and what Retry does.
pub const RECOVERY: &[Recovery] = &[
    // `8004`: the printer's sensor still sees filament after the unload check distance.
    retry(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF),
    // `8002`: the hub sensor still sees filament after the unload or park distance.
    retry(ErrorCode::FINDA_DIDNT_SWITCH_OFF),
    // `8008`: filament in the hub that no slot is known to own.
    retry(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
];
