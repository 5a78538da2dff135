//! UnloadFromNozzle (`U0`, and the first half of a tool change): the slot that owns the hub path
//! comes back out of the printer and the hub and is parked.
//!
//! `P3` pull back until the printer's sensor (within register `0x0c` mm) and then the hub sensor
//! clear, `P19` on to the park position. Nothing loaded: done at once. While the printer's sensor
//! reads filament, `P3` first feels, pulling no harder than the extruder's grip always wins
//! against, until nothing holds the filament (`crate::phases::unload`); for a printer that
//! accepted MMU 3.0.4 the first 20 mm after that follow its gears as a feel too.

use mmu_protocol::ErrorCode;

use super::{Plan, Recovery, clear_hub, retry};
use crate::config::{Config, Contract};
use crate::phases::Phase;
use crate::unit::Unit;

/// Pull `slot`'s filament out of the printer and the hub, and park it; with `await_release`, only
/// once the printer has released it ([`Phase::UnloadToHub`]).
pub const fn phases(slot: usize, await_release: bool) -> [Phase; 2] {
    [
        Phase::UnloadToHub {
            slot: slot as u8,
            await_release,
        },
        Phase::RetractToPark { slot: slot as u8 },
    ]
}

/// Whether `U0`, `T<n>`, `E<n>` and `K<n>` wait for the printer to release the filament before
/// they pull in the strict mode (MMU 3.0.4's unload): for a printer that accepted MMU 3.0.4,
/// which sends `T` while its gears still grip it. A printer that accepted 3.0.3 or older pulls
/// its filament out of its gears before it sends them, and MMU 3.0.3 pulls at once
/// (`mmu-3.0.4.md`). Outside the strict mode every unload feels first.
pub fn awaits_release(config: &Config) -> bool {
    config.version.contract() == Contract::AwaitRelease
}

/// The plan for `U0`, appended to `plan`.
pub fn plan<const N: usize>(unit: &Unit<N>, config: &Config, plan: &mut Plan) -> Result<(), ErrorCode> {
    clear_hub(plan, unit, awaits_release(config))
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
