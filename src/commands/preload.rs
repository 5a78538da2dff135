//! Preload (`L<n>`): slot *n* is fed until the hub sensor sees its tip, then parked, so the next
//! tool change starts close to the hub.
//!
//! `P5` then `P19`. `8005` while a slot is loaded: Continue leaves it so, Unload unloads and
//! parks it first, then preloads.

use mmu_protocol::{ButtonCode, ErrorCode};

use super::{Action, Plan, Recovery, clear_hub, extend, retry};
use crate::config::Config;
use crate::phases::Phase;
use crate::unit::Unit;

/// The plan for `L<slot>`, appended to `plan`.
pub fn plan<const N: usize>(
    slot: usize,
    unit: &Unit<N>,
    config: &Config,
    plan: &mut Plan,
) -> Result<(), ErrorCode> {
    if unit.active().is_some() {
        return Err(ErrorCode::FILAMENT_ALREADY_LOADED);
    }
    clear_hub(plan, unit, true)?;
    extend(plan, &phases(slot, config.preload_max_mm));
    Ok(())
}

/// Feed `slot` until the hub sensor sees its tip (at most `max_mm`), then park it.
pub const fn phases(slot: usize, max_mm: u16) -> [Phase; 2] {
    [
        Phase::FeedToHub {
            slot: slot as u8,
            max_mm,
        },
        Phase::RetractToPark { slot: slot as u8 },
    ]
}

/// What each error of the preload means and what Retry does.
pub const RECOVERY: &[Recovery] = &[
    // `8001`: the hub sensor did not see the tip within the preload distance (or the slot is empty).
    retry(ErrorCode::FINDA_DIDNT_SWITCH_ON),
    // `8002`: the hub sensor still sees filament after parking.
    retry(ErrorCode::FINDA_DIDNT_SWITCH_OFF),
    // `8005`: a slot is loaded. Continue (Buddy `B1`) leaves it so and finishes; Unload (Buddy
    // `B0`, MK3S `B2`) unloads and parks it, then preloads as asked. Buddy numbers the yaml's
    // actions (`mmu2_error_converter.cpp` `ButtonAvailable`: the button's index), the MK3S has its
    // own switch (`Firmware/mmu2_error_converter.cpp`: Unload is Left, Done is Right = `B0`): this
    // unit cannot tell the families apart, so an MK3S's Done (`B0`) unloads too.
    Recovery {
        error: ErrorCode::FILAMENT_ALREADY_LOADED,
        button: ButtonCode::MIDDLE,
        action: Action::Continue,
    },
    Recovery {
        error: ErrorCode::FILAMENT_ALREADY_LOADED,
        button: ButtonCode::RIGHT,
        action: Action::UnloadFirst,
    },
    Recovery {
        error: ErrorCode::FILAMENT_ALREADY_LOADED,
        button: ButtonCode::LEFT,
        action: Action::UnloadFirst,
    },
    // `8008`: filament in the hub that no slot is known to own.
    retry(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
];
