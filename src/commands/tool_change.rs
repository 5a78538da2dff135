//! ToolChange (`T<n>`): the loaded slot comes out ([`super::unload_from_nozzle`]), slot *n* goes
//! in to the nozzle ([`super::load_to_nozzle`]). Slot *n* already loaded (and known to be, not
//! only stored): done at once.
//!
//! Progress: `P3 P19` (unload, when another slot is loaded), then `P5 P6 P1c P7`. Errors and
//! recovery: those of its two parts; filament in the hub that no slot owns is `8008` before
//! anything moves.

use mmu_protocol::ErrorCode;

use super::{Plan, Recovery, clear_hub, extend, hub_search, load_to_nozzle, retry, unload_from_nozzle};
use crate::config::Config;
use crate::unit::{Lane, Unit};

/// The plan for `T<slot>`, appended to `plan`.
pub fn plan<const N: usize>(
    slot: usize,
    unit: &Unit<N>,
    config: &Config,
    plan: &mut Plan,
) -> Result<(), ErrorCode> {
    // Already loaded, and known to be (a stored lane alone could report the wrong filament as
    // loaded: then it is unloaded, proving or refusing the belief, and loaded again).
    if unit.lane(slot) == Lane::Loaded && unit.owner_proven(slot) {
        return Ok(());
    }
    clear_hub(plan, unit, unload_from_nozzle::awaits_release(config))?;
    extend(
        plan,
        &load_to_nozzle::phases(slot, hub_search(slot, unit, config)),
    );
    Ok(())
}

/// After the errors raised before anything moved.
pub const RECOVERY: &[Recovery] = &[
    // Filament in the hub that no slot is known to own: the user takes it out, then Retry.
    retry(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
];
