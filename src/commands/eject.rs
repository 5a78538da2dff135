//! Eject (`E<n>`): slot *n*'s filament is pulled out past its slot sensor so the user can take
//! the spool away; the unit then waits for the user's Continue.
//!
//! `P3 P19` first when slot *n* is loaded, then `P18` reverse until the slot sensor clears, then
//! `E800c` (FILAMENT_EJECTED) until Continue (`B1`), then `F0`. Other slots stay as they are.

use mmu_protocol::{ButtonCode, ErrorCode};

use super::{Action, Plan, Recovery, extend, retry, unload_from_nozzle};
use crate::config::Config;
use crate::phases::Phase;
use crate::unit::Unit;

/// The plan for `E<slot>`, appended to `plan`.
pub fn plan<const N: usize>(slot: usize, unit: &Unit<N>, config: &Config, plan: &mut Plan) {
    if unit.active() == Some(slot) {
        extend(
            plan,
            &unload_from_nozzle::phases(slot, unload_from_nozzle::awaits_release(config)),
        );
    }
    extend(
        plan,
        &[Phase::EjectFromSlot { slot: slot as u8 }, Phase::AwaitContinue],
    );
}

/// What each error of the eject means and what the buttons do.
pub const RECOVERY: &[Recovery] = &[
    // `800c`: not an error but a question: the filament is out, take it away and press Continue.
    Recovery {
        error: ErrorCode::FILAMENT_EJECTED,
        button: ButtonCode::MIDDLE,
        action: Action::Continue,
    },
    // `804b` past the eject distance with the slot sensor still seeing filament.
    retry(ErrorCode::MOVE_PULLEY_FAILED),
];
