//! Cut (`K<n>`). This hardware has no blade: `K` re-parks slot *n* instead. Whatever is loaded is
//! unloaded, slot *n* is fed to the hub and parked again, so the printer's cut flow (`U0`, then
//! `K<n>`) leaves a verified, parked filament. Never refused.
//!
//! `P3 P19` when a slot is loaded, then `P5 P19`.

use mmu_protocol::ErrorCode;

use super::{Plan, Recovery, clear_hub, extend, hub_search, preload, retry, unload_from_nozzle};
use crate::config::Config;
use crate::unit::Unit;

/// The plan for `K<slot>`, appended to `plan`.
pub fn plan<const N: usize>(
    slot: usize,
    unit: &Unit<N>,
    config: &Config,
    plan: &mut Plan,
) -> Result<(), ErrorCode> {
    clear_hub(plan, unit, unload_from_nozzle::awaits_release(config))?;
    extend(plan, &preload::phases(slot, hub_search(slot, unit, config)));
    Ok(())
}

/// After the errors raised before anything moved (the motions' are the preload's and unload's).
pub const RECOVERY: &[Recovery] = &[retry(ErrorCode::FINDA_VS_EEPROM_DISREPANCY)];
