//! Every screen, every button, both printer families (issue 12): for every error code the unit
//! can raise, the screen Prusa's printer shows for it (`mmu_protocol::screens`, from the printers'
//! sources), each of its buttons, and what the unit does with the `B<n>` the button sends
//! ([`Command::on_button`], the commands' recovery tables). A button either leads out of the error
//! as its label promises, or stays on the printer (Reset MMU, Stop print, Disable MMU) and never
//! reaches the unit.

use mmu_firmware::commands::{Action, Command};
use mmu_protocol::screens::{self, Family};
use mmu_protocol::{ButtonCode, ErrorCode};

/// What each command (and the start-up check) can raise, from the code: the plan's own errors,
/// those of every phase in its plans, and the follower's jam while printing (raised on the last
/// command, a tool change). A command sent over a waiting error takes that error over with the
/// buttons of the command that raised it (`Runner::supersede`), so its rows are that command's.
const RAISES: &[(Command, &[ErrorCode])] = &[
    (Command::StartUp, SENSOR_CHECK),
    (Command::Home, SENSOR_CHECK),
    (
        Command::ToolChange,
        &[
            ErrorCode::INVALID_TOOL,
            ErrorCode::FINDA_VS_EEPROM_DISREPANCY,
            ErrorCode::FINDA_FLICKERS,
            // Unload: P3 P19.
            ErrorCode::FSENSOR_DIDNT_SWITCH_OFF,
            ErrorCode::FINDA_DIDNT_SWITCH_OFF,
            // Load: P5 P6 P1c P7.
            ErrorCode::FINDA_DIDNT_SWITCH_ON,
            ErrorCode::FSENSOR_TOO_EARLY,
            ErrorCode::FSENSOR_DIDNT_SWITCH_ON,
            // Any motion: a stall, a slot sensor at a rail, a bound; the follower's jam.
            ErrorCode::STALLED_PULLEY,
            ErrorCode::MOVE_PULLEY_FAILED,
            ErrorCode::INTERNAL,
        ],
    ),
    (
        Command::Preload,
        &[
            ErrorCode::INVALID_TOOL,
            ErrorCode::FILAMENT_ALREADY_LOADED,
            ErrorCode::FINDA_VS_EEPROM_DISREPANCY,
            ErrorCode::FINDA_FLICKERS,
            ErrorCode::FINDA_DIDNT_SWITCH_ON,
            ErrorCode::FINDA_DIDNT_SWITCH_OFF,
            ErrorCode::STALLED_PULLEY,
            ErrorCode::MOVE_PULLEY_FAILED,
            ErrorCode::INTERNAL,
        ],
    ),
    (Command::UnloadFromNozzle, UNLOAD),
    (
        Command::Eject,
        &[
            ErrorCode::INVALID_TOOL,
            ErrorCode::FILAMENT_EJECTED,
            ErrorCode::FINDA_FLICKERS,
            ErrorCode::FSENSOR_DIDNT_SWITCH_OFF,
            ErrorCode::FINDA_DIDNT_SWITCH_OFF,
            ErrorCode::STALLED_PULLEY,
            ErrorCode::MOVE_PULLEY_FAILED,
            ErrorCode::INTERNAL,
        ],
    ),
    (
        Command::Cut,
        &[
            ErrorCode::INVALID_TOOL,
            ErrorCode::FINDA_VS_EEPROM_DISREPANCY,
            ErrorCode::FINDA_FLICKERS,
            ErrorCode::FSENSOR_DIDNT_SWITCH_OFF,
            ErrorCode::FINDA_DIDNT_SWITCH_OFF,
            ErrorCode::FINDA_DIDNT_SWITCH_ON,
            ErrorCode::STALLED_PULLEY,
            ErrorCode::MOVE_PULLEY_FAILED,
            ErrorCode::INTERNAL,
        ],
    ),
];

/// The sensor check (start-up, `H0`): hub sensor at a rail, slot sensor at a rail, lanes that
/// disagree with the hub sensor.
const SENSOR_CHECK: &[ErrorCode] = &[
    ErrorCode::FINDA_FLICKERS,
    ErrorCode::MOVE_PULLEY_FAILED,
    ErrorCode::FINDA_VS_EEPROM_DISREPANCY,
];

/// `U0`: P3 P19, and the plan's own errors.
const UNLOAD: &[ErrorCode] = &[
    ErrorCode::FINDA_VS_EEPROM_DISREPANCY,
    ErrorCode::FINDA_FLICKERS,
    ErrorCode::FSENSOR_DIDNT_SWITCH_OFF,
    ErrorCode::FINDA_DIDNT_SWITCH_OFF,
    ErrorCode::STALLED_PULLEY,
    ErrorCode::MOVE_PULLEY_FAILED,
    ErrorCode::INTERNAL,
];

/// The rows where the two families send the same `B<n>` for different labels, so the unit cannot
/// keep both promises, and what it does (README, "Errors and recovery"): FIL. ALREADY LOADED's
/// `B0` is Unload on a Buddy printer and Done on an MK3S; the unit unloads (Buddy's label; an
/// MK3S's Done then unloads the loaded slot before the preload, which still leads out).
const AMBIGUOUS: &[(ErrorCode, Family, ButtonCode)] = &[(
    ErrorCode::FILAMENT_ALREADY_LOADED,
    Family::Mk3s,
    ButtonCode::RIGHT,
)];

/// Whether the unit's `action` does what a button labelled `label` promises.
fn keeps_promise(label: screens::Action, action: Action) -> bool {
    match label {
        screens::Action::Retry => matches!(action, Action::RetryPhase | Action::Replan(_)),
        screens::Action::Continue => matches!(action, Action::Continue),
        screens::Action::Unload => matches!(action, Action::UnloadFirst),
        _ => false,
    }
}

#[test]
fn every_button_of_every_screen_leads_out_or_stays_on_the_printer() {
    let mut rows = 0;
    let mut broken = Vec::new();
    for family in Family::ALL {
        for &(command, errors) in RAISES {
            for &error in errors {
                let screen = screens::screen(error, family).expect("every error has a screen");
                assert_ne!(
                    screen.id, 4900,
                    "{error} shows UNKNOWN ERROR on {family:?}: the user learns nothing"
                );
                assert!(!screen.buttons.is_empty(), "{error} on {family:?}: no button");
                for button in screen.buttons {
                    rows += 1;
                    let Some(sent) = button.sends else {
                        assert!(
                            !button.action.reaches_unit(),
                            "{family:?} {error} {}: sends nothing yet reaches the unit",
                            button.label
                        );
                        continue;
                    };
                    let unit_does = command.on_button(error, sent);
                    let kept = unit_does.is_some_and(|action| keeps_promise(button.action, action));
                    let documented = AMBIGUOUS.contains(&(error, family, sent));
                    if kept == documented {
                        broken.push(format!(
                            "{family:?} {command:?} {error} {} (B{}): unit does {unit_does:?}{}",
                            button.label,
                            sent.0,
                            if documented {
                                ", yet listed as ambiguous"
                            } else {
                                ""
                            }
                        ));
                    }
                }
            }
        }
    }
    assert!(rows > 100, "{rows} rows walked");
    assert!(
        broken.is_empty(),
        "buttons that break their promise:\n{}",
        broken.join("\n")
    );
}

/// An error screen with no button that reaches the unit must be one the unit leaves by itself:
/// INVALID TOOL (Stop print / Reset MMU) is accepted over by the next command, and FW RUNTIME
/// ERROR (Reset MMU) restarts it. Anything else needs a Retry or Continue to be shown.
#[test]
fn only_invalid_tool_and_internal_errors_leave_the_user_printer_side_buttons_only() {
    for family in Family::ALL {
        for &(_, errors) in RAISES {
            for &error in errors {
                let screen = screens::screen(error, family).expect("a screen");
                let reaches = screen.buttons.iter().any(|b| b.action.reaches_unit());
                assert!(
                    reaches || error == ErrorCode::INVALID_TOOL || error == ErrorCode::INTERNAL,
                    "{family:?} {error}: only printer-side buttons"
                );
            }
        }
    }
}

mod common;

use common::Rig;
use mmu_protocol::{ParamCode, Request, RequestCode};

/// PULLEY CANNOT MOVE after a jam while printing is reported on whatever command came last; its
/// Retry must lead out of it (the follower goes on), not into another screen. After `L1` over a
/// loaded slot 0 (FIL. ALREADY LOADED, Continue) a Retry that planned the preload again showed
/// FIL. ALREADY LOADED; after `E2` it ejected again and asked FILAMENT EJECTED.
#[test]
fn retry_of_a_jam_while_printing_leads_out_whatever_the_last_command() {
    for last in [
        Request::new(RequestCode::Load, 1),
        Request::new(RequestCode::Eject, 2),
    ] {
        let mut rig = Rig::<3>::new();
        rig.boot();
        rig.command(Request::new(RequestCode::Tool, 0));
        rig.send(last);
        rig.idle(20_000);
        // The question the command asks (FIL. ALREADY LOADED, FILAMENT EJECTED): Continue.
        assert_eq!(rig.query().param, ParamCode::Error, "{last:?}");
        rig.send(Request::new(RequestCode::Button, 1));
        rig.idle(100);
        assert_eq!(rig.query().param, ParamCode::Finished, "{last:?}");
        rig.model.set_printing(Some(4.0));
        rig.idle(5_000);
        rig.inject(mmu_model::Fault::Jam { slot: 0 });
        rig.idle(30_000);
        let jammed = rig.query();
        assert!(
            [ErrorCode::STALLED_PULLEY, ErrorCode::MOVE_PULLEY_FAILED]
                .map(|e| Some(e.0))
                .contains(&jammed.param_value),
            "{last:?}: {jammed:?}"
        );
        assert!(rig.model.clear(mmu_model::FaultKind::Jam(0)));
        rig.send(Request::new(RequestCode::Button, 1));
        rig.idle(10_000);
        let answer = rig.query();
        assert_eq!(
            (answer.code, answer.value, answer.param),
            (last.code, last.value, ParamCode::Finished),
            "{last:?}: Retry led to {answer:?}"
        );
        assert_eq!(rig.model.loaded_slot(), Some(0), "{last:?}");
    }
}
