//! The error screen a Prusa printer shows for each MMU error code, and what each of its buttons does.
//!
//! The unit must give every screen it causes a way out, and the two printer firmware families number
//! the same button differently on the wire: on FIL. ALREADY LOADED, `B0` means Unload to a Buddy
//! printer and Continue to an MK3S. This table is what the printers' sources say, so the unit's
//! error handling and its tests can be checked against it instead of against our own guesses.
//!
//! Sources (read, not copied; notes in the project's `printer-truth.md`):
//! - Buddy (MK4, MK3.5, MK3.9, Core One), Prusa-Firmware-Buddy 6.x:
//!   `src/mmu2/mmu2_error_converter.cpp` (`PrusaErrorCodeIndex`, `ButtonAvailable`),
//!   `lib/Prusa-Error-Codes/yaml/mmu-error-codes.yaml` with `generate_buddy_headers.py` (one action goes
//!   to the middle slot, two actions to slots 0 and 1), `lib/Marlin/.../MMU2/mmu2_mk4.cpp`
//!   (`CheckUserInput`), button labels from `src/common/client_response_texts.hpp`.
//! - MK3S, Prusa-Firmware 3.13/3.14: `Firmware/mmu2_error_converter.cpp` (`PrusaErrorCodeIndex`,
//!   `ButtonAvailable`), `Firmware/mmu2/errors_list.h` (`errorButtons`, `btnOperation` labels),
//!   `Firmware/mmu2.cpp` (`CheckUserInput`).
//!
//! A button reaches the unit (as `B<n>`) only when the error came from the unit; printer-side actions
//! (Reset MMU, Disable MMU, Stop print, Tune, Load, Eject) never do.

use crate::codes::{ButtonCode, ErrorCode};

/// The printer firmware family, which decides the screens' buttons and their `B<n>` numbers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Family {
    /// Prusa-Firmware-Buddy: MK4/MK4S, MK3.5/MK3.5S, MK3.9/MK3.9S, Core One.
    Buddy,
    /// Prusa-Firmware (8-bit): MK3S/MK3S+ (and MK2.5S).
    Mk3s,
}

impl Family {
    /// Both families.
    pub const ALL: [Family; 2] = [Family::Buddy, Family::Mk3s];
}

/// What pressing a button does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Action {
    /// Retry: the printer sends a button (`B1` on every Retry screen) and the unit retries.
    Retry,
    /// Continue (MK3S label "Done"): the printer sends a button, the unit goes on.
    Continue,
    /// Unload: the printer sends a button, the unit unloads.
    Unload,
    /// Printer side: power-cycles the unit (Buddy) or pulses its reset pin (MK3S, `X0` without the pin).
    ResetMmu,
    /// Printer side: stops talking to the unit and disables it in the printer's settings.
    DisableMmu,
    /// Printer side, meant to stop the print. Both firmwares' `CheckUserInput` leave it as a to-do:
    /// pressing it does nothing and sends nothing.
    StopPrint,
    /// Printer side (MK3S, CANNOT HOME screens): opens the stall-guard tuning menu.
    Tune,
    /// Printer side (MK3S M600 FILAMENT CHANGE screen): the printer then loads a slot itself.
    Load,
    /// Printer side (MK3S M600 FILAMENT CHANGE screen): the printer then sends `E<slot>` itself.
    Eject,
    /// Shown but dead: the firmware's `ButtonAvailable` has no case for this screen, so pressing it
    /// does nothing (MK3S UNKNOWN ERROR's ResetMMU).
    Inert,
}

impl Action {
    /// True for the actions a printer forwards to the unit as `B<n>` (for errors the unit raised).
    pub const fn reaches_unit(self) -> bool {
        matches!(self, Action::Retry | Action::Continue | Action::Unload)
    }
}

/// One button of an error screen.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Button {
    /// The label on the printer's screen.
    pub label: &'static str,
    /// What pressing it does.
    pub action: Action,
    /// The `B<n>` the printer sends to the unit, or `None` when the action stays on the printer
    /// (also for Continue on screens only the printer raises).
    pub sends: Option<ButtonCode>,
}

/// An MMU error screen as one printer family shows it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Screen {
    /// The Prusa error number without the leading zero: 4101 is shown as `04101` (`prusa.io/04101`).
    pub id: u16,
    /// The screen's title.
    pub title: &'static str,
    /// The buttons, in the order the screen shows them.
    pub buttons: &'static [Button],
}

impl Screen {
    /// What a `B<n>` received from this family's printer means on this screen, if any button sends it.
    pub fn action_for(&self, sent: ButtonCode) -> Option<Action> {
        self.buttons
            .iter()
            .find(|button| button.sends == Some(sent))
            .map(|button| button.action)
    }
}

/// The screen `family`'s printer shows for `error`; `None` for RUNNING and OK, which show none.
///
/// Codes the printer does not know get UNKNOWN ERROR (04900), as on the printers.
pub fn screen(error: ErrorCode, family: Family) -> Option<&'static Screen> {
    if error.0 == ErrorCode::RUNNING.0 || error.0 == ErrorCode::OK.0 {
        return None;
    }
    let id = screen_id(error, family);
    let table = screens(family);
    table
        .iter()
        .find(|screen| screen.id == id)
        .or_else(|| table.iter().find(|s| s.id == UNKNOWN_ID))
}

/// Every screen a code can lead to on `family`'s printer (one entry per error number).
pub fn screens(family: Family) -> &'static [Screen] {
    match family {
        Family::Buddy => &BUDDY,
        Family::Mk3s => &MK3S,
    }
}

/// UNKNOWN ERROR, the screen for any code the printer cannot place.
const UNKNOWN_ID: u16 = 4900;

/// The error number `family`'s printer shows for `error` (their `PrusaErrorCodeIndex`): 4900 when it
/// has none. The families differ only for MCU_UNDERVOLTAGE_VCC (0x800d: MK3S 04306 MMU MCU ERROR,
/// Buddy UNKNOWN) and the MK3S's own FILAMENT_CHANGE (0x8029: 04508).
pub const fn screen_id(error: ErrorCode, family: Family) -> u16 {
    let mk3s = matches!(family, Family::Mk3s);
    match error.0 {
        0x8001 => 4101,
        0x8002 => 4102,
        0x8003 => 4103,
        0x8004 => 4104,
        0x8009 => 4106,
        0x800a => 4107,
        0x802a => 4108,
        0x800c => 4507,
        0x8047 | 0x804b => 4105,
        0x8087 => 4115,
        0x808b => 4116,
        0x8107 => 4125,
        0x810b => 4126,
        0x802e => 4401,
        0x802d => 4402,
        0x8005 => 4501,
        0x8006 => 4502,
        0x802b => 4503,
        0x802c => 4504,
        0x802f => 4505,
        0x8008 => 4506,
        0x800d if mk3s => 4306,
        0x8029 if mk3s => 4508,
        code => tmc_screen_id(code),
    }
}

/// Driver codes: the first axis bit (pulley, selector, idler) picks +0, +10 or +20, then the first
/// flag in the printers' order picks the screen; 4900 without an axis bit or a known flag.
const fn tmc_screen_id(code: u16) -> u16 {
    let axis_offset = if code & ErrorCode::TMC_PULLEY_BIT.0 != 0 {
        0
    } else if code & ErrorCode::TMC_SELECTOR_BIT.0 != 0 {
        10
    } else if code & ErrorCode::TMC_IDLER_BIT.0 != 0 {
        20
    } else {
        return UNKNOWN_ID;
    };
    let soldering = ErrorCode::MMU_SOLDERING_NEEDS_ATTENTION.0;
    let base = if code & soldering == soldering {
        4305
    } else if code & 0x0200 != 0 {
        4301
    } else if code & 0x0400 != 0 {
        4302
    } else if code & 0x0800 != 0 {
        4303
    } else if code & 0x1000 != 0 {
        4304
    } else if code & 0x2000 != 0 {
        4201
    } else if code & 0x4000 != 0 {
        4202
    } else {
        return UNKNOWN_ID;
    };
    base + axis_offset
}

const fn sends(action: Action, label: &'static str, code: u8) -> Button {
    Button {
        label,
        action,
        sends: Some(ButtonCode(code)),
    }
}

const fn stays(action: Action, label: &'static str) -> Button {
    Button {
        label,
        action,
        sends: None,
    }
}

/// Buddy: the yaml's single action sits in the middle slot, so Retry and Continue send `B1`.
mod buddy {
    use super::{Action, Button, sends, stays};

    pub(super) const RETRY: &[Button] = &[sends(Action::Retry, "RETRY", 1)];
    pub(super) const CONTINUE: &[Button] = &[sends(Action::Continue, "CONTINUE", 1)];
    /// Only the printer raises LOAD TO EXTR. FAILED, and buttons reach the unit only for its own errors.
    pub(super) const CONTINUE_PRINTER: &[Button] = &[stays(Action::Continue, "CONTINUE")];
    /// Two actions: slot 0 sends `B0`, slot 1 sends `B1`.
    pub(super) const UNLOAD_CONTINUE: &[Button] = &[
        sends(Action::Unload, "UNLOAD", 0),
        sends(Action::Continue, "CONTINUE", 1),
    ];
    pub(super) const CONTINUE_RESET: &[Button] = &[
        sends(Action::Continue, "CONTINUE", 0),
        stays(Action::ResetMmu, "RESTART"),
    ];
    pub(super) const RESET: &[Button] = &[stays(Action::ResetMmu, "RESTART")];
    pub(super) const RESET_DISABLE: &[Button] = &[
        stays(Action::ResetMmu, "RESTART"),
        stays(Action::DisableMmu, "DISABLE MMU"),
    ];
    pub(super) const STOP_RESET: &[Button] = &[
        stays(Action::StopPrint, "STOP"),
        stays(Action::ResetMmu, "RESTART"),
    ];
}

/// MK3S: `ButtonAvailable` hard-codes each screen's numbers.
mod mk3s {
    use super::{Action, Button, sends, stays};

    pub(super) const RETRY: &[Button] = &[sends(Action::Retry, "Retry", 1)];
    pub(super) const RETRY_TUNE: &[Button] = &[sends(Action::Retry, "Retry", 1), stays(Action::Tune, "Tune")];
    pub(super) const DONE: &[Button] = &[sends(Action::Continue, "Done", 1)];
    /// Only the printer raises LOAD TO EXTR. FAILED, and buttons reach the unit only for its own errors.
    pub(super) const DONE_PRINTER: &[Button] = &[stays(Action::Continue, "Done")];
    /// Unload is `Buttons::Left` (2), Continue is `Buttons::Right` (0).
    pub(super) const UNLOAD_DONE: &[Button] = &[
        sends(Action::Unload, "Unload", 2),
        sends(Action::Continue, "Done", 0),
    ];
    /// The TMC warning's Continue is `Buttons::Left` (2).
    pub(super) const DONE_RESET: &[Button] = &[
        sends(Action::Continue, "Done", 2),
        stays(Action::ResetMmu, "ResetMMU"),
    ];
    pub(super) const RESET: &[Button] = &[stays(Action::ResetMmu, "ResetMMU")];
    pub(super) const RESET_DISABLE: &[Button] = &[
        stays(Action::ResetMmu, "ResetMMU"),
        stays(Action::DisableMmu, "Disable"),
    ];
    pub(super) const STOP_RESET: &[Button] = &[
        stays(Action::StopPrint, "Stop"),
        stays(Action::ResetMmu, "ResetMMU"),
    ];
    pub(super) const EJECT_LOAD: &[Button] = &[stays(Action::Eject, "Eject"), stays(Action::Load, "Load")];
    /// Shown, but `ButtonAvailable` has no case for UNKNOWN ERROR.
    pub(super) const RESET_INERT: &[Button] = &[stays(Action::Inert, "ResetMMU")];
}

const fn row(id: u16, title: &'static str, buttons: &'static [Button]) -> Screen {
    Screen { id, title, buttons }
}

/// Buddy's reachable screens: `mmu-error-codes.yaml` minus 04306/04307, which its
/// `PrusaErrorCodeIndex` never selects.
static BUDDY: [Screen; 43] = [
    row(4101, "FINDA DIDNT TRIGGER", buddy::RETRY),
    row(4102, "FINDA FILAM. STUCK", buddy::RETRY),
    row(4103, "FSENSOR DIDNT TRIGG.", buddy::RETRY),
    row(4104, "FSENSOR FIL. STUCK", buddy::RETRY),
    row(4105, "PULLEY CANNOT MOVE", buddy::RETRY),
    row(4106, "FSENSOR TOO EARLY", buddy::RETRY),
    row(4107, "INSPECT FINDA", buddy::RETRY),
    row(4108, "LOAD TO EXTR. FAILED", buddy::CONTINUE_PRINTER),
    row(4115, "SELECTOR CANNOT HOME", buddy::RETRY),
    row(4116, "SELECTOR CANNOT MOVE", buddy::RETRY),
    row(4125, "IDLER CANNOT HOME", buddy::RETRY),
    row(4126, "IDLER CANNOT MOVE", buddy::RETRY),
    row(4201, "WARNING TMC TOO HOT", buddy::CONTINUE_RESET),
    row(4211, "WARNING TMC TOO HOT", buddy::CONTINUE_RESET),
    row(4221, "WARNING TMC TOO HOT", buddy::CONTINUE_RESET),
    row(4202, "TMC OVERHEAT ERROR", buddy::RESET),
    row(4212, "TMC OVERHEAT ERROR", buddy::RESET),
    row(4222, "TMC OVERHEAT ERROR", buddy::RESET),
    row(4301, "TMC DRIVER ERROR", buddy::RESET),
    row(4311, "TMC DRIVER ERROR", buddy::RESET),
    row(4321, "TMC DRIVER ERROR", buddy::RESET),
    row(4302, "TMC DRIVER RESET", buddy::RESET),
    row(4312, "TMC DRIVER RESET", buddy::RESET),
    row(4322, "TMC DRIVER RESET", buddy::RESET),
    row(4303, "TMC UNDERVOLTAGE ERR", buddy::RESET),
    row(4313, "TMC UNDERVOLTAGE ERR", buddy::RESET),
    row(4323, "TMC UNDERVOLTAGE ERR", buddy::RESET),
    row(4304, "TMC DRIVER SHORTED", buddy::RESET),
    row(4314, "TMC DRIVER SHORTED", buddy::RESET),
    row(4324, "TMC DRIVER SHORTED", buddy::RESET),
    row(4305, "MMU SELFTEST FAILED", buddy::RESET),
    row(4315, "MMU SELFTEST FAILED", buddy::RESET),
    row(4325, "MMU SELFTEST FAILED", buddy::RESET),
    row(4401, "MMU NOT RESPONDING", buddy::RESET_DISABLE),
    row(4402, "COMMUNICATION ERROR", buddy::RESET_DISABLE),
    row(4501, "FIL. ALREADY LOADED", buddy::UNLOAD_CONTINUE),
    row(4502, "INVALID TOOL", buddy::STOP_RESET),
    row(4503, "QUEUE FULL", buddy::RESET),
    row(4504, "MMU FW UPDATE NEEDED", buddy::RESET_DISABLE),
    row(4505, "FW RUNTIME ERROR", buddy::RESET),
    row(4506, "UNLOAD MANUALLY", buddy::RETRY),
    row(4507, "FILAMENT EJECTED", buddy::CONTINUE),
    row(UNKNOWN_ID, "UNKNOWN ERROR", buddy::RESET),
];

/// The MK3S's screens: `errors_list.h` `errorCodes` with their `ButtonAvailable` numbers.
static MK3S: [Screen; 45] = [
    row(4101, "FINDA DIDNT TRIGGER", mk3s::RETRY),
    row(4102, "FINDA FILAM. STUCK", mk3s::RETRY),
    row(4103, "FSENSOR DIDNT TRIGG.", mk3s::RETRY),
    row(4104, "FSENSOR FIL. STUCK", mk3s::RETRY),
    row(4105, "PULLEY CANNOT MOVE", mk3s::RETRY),
    row(4106, "FSENSOR TOO EARLY", mk3s::RETRY),
    row(4107, "INSPECT FINDA", mk3s::RETRY),
    row(4108, "LOAD TO EXTR. FAILED", mk3s::DONE_PRINTER),
    row(4115, "SELECTOR CANNOT HOME", mk3s::RETRY_TUNE),
    row(4116, "SELECTOR CANNOT MOVE", mk3s::RETRY),
    row(4125, "IDLER CANNOT HOME", mk3s::RETRY_TUNE),
    row(4126, "IDLER CANNOT MOVE", mk3s::RETRY),
    row(4201, "WARNING TMC TOO HOT", mk3s::DONE_RESET),
    row(4211, "WARNING TMC TOO HOT", mk3s::DONE_RESET),
    row(4221, "WARNING TMC TOO HOT", mk3s::DONE_RESET),
    row(4202, "TMC OVERHEAT ERROR", mk3s::RESET),
    row(4212, "TMC OVERHEAT ERROR", mk3s::RESET),
    row(4222, "TMC OVERHEAT ERROR", mk3s::RESET),
    row(4301, "TMC DRIVER ERROR", mk3s::RESET),
    row(4311, "TMC DRIVER ERROR", mk3s::RESET),
    row(4321, "TMC DRIVER ERROR", mk3s::RESET),
    row(4302, "TMC DRIVER RESET", mk3s::RESET),
    row(4312, "TMC DRIVER RESET", mk3s::RESET),
    row(4322, "TMC DRIVER RESET", mk3s::RESET),
    row(4303, "TMC UNDERVOLTAGE ERR", mk3s::RESET),
    row(4313, "TMC UNDERVOLTAGE ERR", mk3s::RESET),
    row(4323, "TMC UNDERVOLTAGE ERR", mk3s::RESET),
    row(4304, "TMC DRIVER SHORTED", mk3s::RESET),
    row(4314, "TMC DRIVER SHORTED", mk3s::RESET),
    row(4324, "TMC DRIVER SHORTED", mk3s::RESET),
    row(4305, "MMU SELFTEST FAILED", mk3s::RESET),
    row(4315, "MMU SELFTEST FAILED", mk3s::RESET),
    row(4325, "MMU SELFTEST FAILED", mk3s::RESET),
    row(4306, "MMU MCU ERROR", mk3s::RESET),
    row(4401, "MMU NOT RESPONDING", mk3s::RESET_DISABLE),
    row(4402, "COMMUNICATION ERROR", mk3s::RESET_DISABLE),
    row(4501, "FIL. ALREADY LOADED", mk3s::UNLOAD_DONE),
    row(4502, "INVALID TOOL", mk3s::STOP_RESET),
    row(4503, "QUEUE FULL", mk3s::RESET),
    row(4504, "MMU FW UPDATE NEEDED", mk3s::RESET_DISABLE),
    row(4505, "FW RUNTIME ERROR", mk3s::RESET),
    row(4506, "UNLOAD MANUALLY", mk3s::RETRY),
    row(4507, "FILAMENT EJECTED", mk3s::DONE),
    row(4508, "FILAMENT CHANGE", mk3s::EJECT_LOAD),
    row(UNKNOWN_ID, "UNKNOWN ERROR", mk3s::RESET_INERT),
];

#[cfg(test)]
mod tests;
