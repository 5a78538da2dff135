//! Rows pinned against the printers' sources, and a walk over both tables.

use super::*;

fn buttons(code: u16, family: Family) -> &'static [Button] {
    match screen(ErrorCode(code), family) {
        Some(screen) => screen.buttons,
        None => panic!("no screen for {code:#x} on {family:?}"),
    }
}

fn sent(code: u16, family: Family, action: Action) -> Option<u8> {
    buttons(code, family)
        .iter()
        .find(|b| b.action == action)
        .and_then(|b| b.sends)
        .map(|c| c.0)
}

/// BFW `ButtonAvailable` returns the slot index; the yaml lists `[Unload, Continue]`.
#[test]
fn already_loaded_on_buddy_unload_sends_b0_and_continue_sends_b1() {
    let screen = screen(ErrorCode::FILAMENT_ALREADY_LOADED, Family::Buddy).unwrap();
    assert_eq!((screen.id, screen.title), (4501, "FIL. ALREADY LOADED"));
    assert_eq!(sent(0x8005, Family::Buddy, Action::Unload), Some(0));
    assert_eq!(sent(0x8005, Family::Buddy, Action::Continue), Some(1));
    assert_eq!(screen.action_for(ButtonCode(0)), Some(Action::Unload));
}

/// PFW `ButtonAvailable`: Unload → `Buttons::Left` (2), Continue → `Buttons::Right` (0).
#[test]
fn already_loaded_on_mk3s_unload_sends_b2_and_continue_sends_b0() {
    assert_eq!(sent(0x8005, Family::Mk3s, Action::Unload), Some(2));
    assert_eq!(sent(0x8005, Family::Mk3s, Action::Continue), Some(0));
    let screen = screen(ErrorCode::FILAMENT_ALREADY_LOADED, Family::Mk3s).unwrap();
    assert_eq!(screen.action_for(ButtonCode(0)), Some(Action::Continue));
    assert_eq!(screen.action_for(ButtonCode(1)), None);
}

#[test]
fn every_retry_screen_sends_b1_on_both_families() {
    let retry_codes = [
        0x8001, 0x8002, 0x8003, 0x8004, 0x8047, 0x804b, 0x8087, 0x808b, 0x8107, 0x810b, 0x8008, 0x8009,
        0x800a,
    ];
    for family in Family::ALL {
        for code in retry_codes {
            assert_eq!(
                sent(code, family, Action::Retry),
                Some(1),
                "{code:#x} on {family:?}"
            );
        }
    }
    assert_eq!(
        screen(ErrorCode::STALLED_PULLEY, Family::Mk3s).unwrap().title,
        "PULLEY CANNOT MOVE"
    );
    assert_eq!(
        screen(ErrorCode::FINDA_VS_EEPROM_DISREPANCY, Family::Buddy)
            .unwrap()
            .id,
        4506
    );
}

#[test]
fn filament_ejected_continue_sends_b1_on_both_families() {
    for family in Family::ALL {
        assert_eq!(sent(0x800c, family, Action::Continue), Some(1));
    }
}

/// Both buttons of INVALID TOOL (Stop print, Reset MMU) stay on the printer.
#[test]
fn invalid_tool_offers_nothing_the_unit_receives() {
    for family in Family::ALL {
        let screen = screen(ErrorCode::INVALID_TOOL, family).unwrap();
        assert_eq!(screen.id, 4502);
        let actions: Vec<Action> = screen.buttons.iter().map(|b| b.action).collect();
        assert_eq!(actions, [Action::StopPrint, Action::ResetMmu]);
        assert!(screen.buttons.iter().all(|b| b.sends.is_none()));
    }
}

/// BFW's `PrusaErrorCodeIndex` has no case for 0x800d; PFW's does (MMU MCU ERROR).
#[test]
fn mcu_undervoltage_is_unknown_on_buddy_and_mcu_error_on_mk3s() {
    assert_eq!(
        screen(ErrorCode::MCU_UNDERVOLTAGE_VCC, Family::Buddy)
            .unwrap()
            .title,
        "UNKNOWN ERROR"
    );
    assert_eq!(
        screen(ErrorCode::MCU_UNDERVOLTAGE_VCC, Family::Mk3s).unwrap().id,
        4306
    );
}

/// The TMC warning's Continue: slot 0 on Buddy, `Buttons::Left` on the MK3S.
#[test]
fn tmc_warning_continue_is_b0_on_buddy_and_b2_on_mk3s() {
    let pulley_too_hot = 0xa040;
    assert_eq!(screen(ErrorCode(pulley_too_hot), Family::Buddy).unwrap().id, 4201);
    assert_eq!(sent(pulley_too_hot, Family::Buddy, Action::Continue), Some(0));
    assert_eq!(sent(pulley_too_hot, Family::Mk3s, Action::Continue), Some(2));
}

#[test]
fn mk3s_unknown_error_reset_button_is_dead() {
    assert_eq!(
        buttons(0x1234, Family::Mk3s),
        &[Button {
            label: "ResetMMU",
            action: Action::Inert,
            sends: None
        }]
    );
    assert_eq!(buttons(0x1234, Family::Buddy)[0].action, Action::ResetMmu);
}

#[test]
fn running_and_ok_show_no_screen() {
    for family in Family::ALL {
        assert_eq!(screen(ErrorCode::RUNNING, family), None);
        assert_eq!(screen(ErrorCode::OK, family), None);
    }
}

/// Every button either reaches the unit with a number 0..=2 or is a printer-side action; no screen
/// uses one number twice; every row is reachable from some code; ids are unique.
#[test]
fn both_tables_are_consistent_and_every_row_is_reachable() {
    for family in Family::ALL {
        let table = screens(family);
        for (index, screen) in table.iter().enumerate() {
            assert!(
                table[..index].iter().all(|other| other.id != screen.id),
                "{} twice",
                screen.id
            );
            assert!(!screen.buttons.is_empty() && !screen.title.is_empty());
            for (i, button) in screen.buttons.iter().enumerate() {
                assert!(!button.label.is_empty());
                if let Some(code) = button.sends {
                    assert!(
                        code.0 <= 2 && button.action.reaches_unit(),
                        "{} {}",
                        screen.id,
                        button.label
                    );
                    assert!(screen.buttons[..i].iter().all(|b| b.sends != Some(code)));
                } else if button.action.reaches_unit() {
                    assert_eq!(
                        screen.id, 4108,
                        "only the printer's own LOAD TO EXTR. FAILED keeps Continue"
                    );
                }
            }
        }
        let mut reached = vec![false; table.len()];
        for code in 0..=u16::MAX {
            if let Some(shown) = screen(ErrorCode(code), family) {
                assert_eq!(shown.id, screen_id(ErrorCode(code), family));
                let index = table.iter().position(|row| row.id == shown.id).unwrap();
                reached[index] = true;
            }
        }
        assert!(reached.iter().all(|&hit| hit), "unreachable rows on {family:?}");
    }
}
