//! The person at the bench as the printer's protocol logic sees them: every event is shown (by the
//! printer tool's [`Console`]), and where the unit needs a person (take the ejected filament out,
//! fix the cause of an error and press Retry) the console says what to do and asks.

use mmu_protocol::screens::screen;
use mmu_protocol::{ButtonCode, ErrorCode, Family, Request, RequestCode};
use mmu_sim::{Decision, Link, Operator, PrinterEvent};

use crate::explain::{error_meaning, request_label};
use crate::printer_cli::console::{Console, Target};

use super::commands::{Command, parse};
use super::input::Input;
use super::link::BenchLink;

/// What to do at the eject dialog.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EjectDialog {
    /// The filament must come out (the simulated user pulls it; a real one is asked to).
    TakeOut,
    /// Calibration: the filament stays gripped behind the slot sensor; Continue at once.
    KeepIn,
}

/// The person at the bench. See the [module documentation](self).
pub struct Person {
    /// Shows the printer's events.
    pub display: Console,
    /// Where answers come from.
    pub input: Input,
    /// The eject dialog's answer.
    pub eject: EjectDialog,
    /// The person asked to end the session while the unit waited.
    pub quit: bool,
    /// The printer the unit is set up for, whose error screens the console offers.
    pub family: Family,
}

/// What a person can do about `error`, in words.
pub fn hint(error: ErrorCode) -> &'static str {
    match error {
        ErrorCode::FSENSOR_DIDNT_SWITCH_ON => {
            "the printer's filament sensor did not see the filament arrive: check the Bowden tube \
             and the sensor (on the bench: `fsensor on` once the tip is there)"
        }
        ErrorCode::FSENSOR_DIDNT_SWITCH_OFF => {
            "the printer's filament sensor still sees filament: free the extruder (on the bench: \
             `fsensor off`)"
        }
        ErrorCode::FSENSOR_TOO_EARLY => {
            "the printer's sensor saw filament before the Bowden length was fed: the Bowden \
             setting is too long (`calibrate bowden`) or a piece is left in the tube"
        }
        ErrorCode::FINDA_DIDNT_SWITCH_ON => {
            "the hub sensor did not see the filament: is there filament in the slot, does the \
             drive grip it, is the hub sensor's magnet in place?"
        }
        ErrorCode::FINDA_DIDNT_SWITCH_OFF => {
            "the hub sensor still sees filament after pulling back: a tip is stuck in the hub"
        }
        ErrorCode::STALLED_PULLEY | ErrorCode::MOVE_PULLEY_FAILED => {
            "the slot's motor did not turn or the filament did not move as far as expected: check \
             for a jam, the motor's wiring and its Hall sensor"
        }
        ErrorCode::FINDA_VS_EEPROM_DISREPANCY => {
            "the hub sensor disagrees with where the unit remembers the filament: look at the hub, \
             then Retry to trust the sensors"
        }
        ErrorCode::FINDA_FLICKERS => "a hub sensor reads nonsense: check its wiring (mmu sensors)",
        ErrorCode::FILAMENT_ALREADY_LOADED => "a filament is loaded: unload it first",
        ErrorCode::INVALID_TOOL => "the unit has no such slot",
        _ => "look at the unit, fix the cause, then Retry",
    }
}

impl Person {
    /// The person's next line after `prompt`, the spinner stopped so that it does not draw over
    /// the line being typed.
    pub fn line(&mut self, prompt: &str) -> Option<String> {
        self.display.close();
        self.input.line(prompt)
    }

    /// Show that the unit stopped on `error` under `request`, and what to do.
    pub fn explain(&self, t_ms: u64, request: &Request, error: ErrorCode) {
        let label = request_label(request);
        self.display
            .note(t_ms, &format!("{label} stopped: {}", error_meaning(error)));
        self.display.note(t_ms, &format!("what to do: {}", hint(error)));
    }

    /// The buttons of `error`'s printer screen that reach the unit: label and `B<n>`.
    fn buttons(&self, error: ErrorCode) -> Vec<(&'static str, ButtonCode)> {
        screen(error, self.family)
            .map(|screen| {
                screen
                    .buttons
                    .iter()
                    .filter_map(|button| button.sends.map(|code| (button.label, code)))
                    .collect()
            })
            .unwrap_or_default()
    }

    /// Ask until the person answers what to do about the unit waiting on `error`: a button of its
    /// screen by its label, or a console command that helps.
    fn ask(&mut self, link: &mut BenchLink, prompt: &str, error: ErrorCode) -> Decision {
        let buttons = self.buttons(error);
        loop {
            let Some(line) = self.line(prompt) else {
                self.quit = true;
                return Decision::GiveUp;
            };
            let word = line.trim().to_ascii_lowercase();
            if let Some(&(_, code)) = buttons
                .iter()
                .find(|(label, _)| !word.is_empty() && label.to_ascii_lowercase() == word)
            {
                return Decision::Press(code);
            }
            match parse(&line) {
                Ok(None) if self.input.is_script() => continue,
                Ok(None) | Ok(Some(Command::Retry)) => return Decision::Press(ButtonCode::MIDDLE),
                Ok(Some(Command::Button(button))) => return Decision::Press(ButtonCode(button)),
                Ok(Some(Command::Wait(_))) => return Decision::Wait,
                Ok(Some(Command::Quit)) => {
                    self.quit = true;
                    return Decision::GiveUp;
                }
                Ok(Some(Command::Fsensor(mode))) => {
                    link.fsensor = mode;
                    self.display.say("the printer's filament sensor is set");
                }
                Ok(Some(Command::SimFault(spec))) => self.display.say(&super::link::sim_fault(link, &spec)),
                Ok(Some(Command::SimClear)) => self.display.say(&super::link::sim_clear(link)),
                _ if line.trim() == "abort" => return Decision::GiveUp,
                _ => {
                    self.display.say(
                        "the unit waits: answer retry (or Enter), abort, wait, fsensor on|off|auto, sim fault|clear, quit",
                    );
                    if self.input.is_script() {
                        return Decision::GiveUp;
                    }
                }
            }
        }
    }

    fn eject_dialog(&mut self, link: &mut BenchLink, request: Request) -> Decision {
        let slot = request.value;
        let t_ms = link.now_ms();
        match self.eject {
            EjectDialog::KeepIn => {
                self.display.note(
                    t_ms,
                    &format!("slot {slot}'s filament stays behind its sensor: Continue (B1)"),
                );
                Decision::Press(ButtonCode::MIDDLE)
            }
            EjectDialog::TakeOut if link.remove_filament(slot) => {
                self.display.note(
                    t_ms,
                    &format!("the simulated user pulls the filament out of slot {slot}: Continue (B1)"),
                );
                Decision::Press(ButtonCode::MIDDLE)
            }
            EjectDialog::TakeOut => {
                self.display.say(&format!(
                    "Pull the filament out of slot {slot}, then press Enter (Continue)."
                ));
                self.ask(link, "eject> ", ErrorCode::FILAMENT_EJECTED)
            }
        }
    }
}

impl Operator<BenchLink> for Person {
    fn event(&mut self, link: &mut BenchLink, event: &PrinterEvent) {
        Operator::<BenchLink>::event(&mut self.display, link, event);
    }

    fn decide(&mut self, link: &mut BenchLink, request: Request, error: ErrorCode) -> Decision {
        if error == ErrorCode::FILAMENT_EJECTED && request.code == RequestCode::Eject {
            return self.eject_dialog(link, request);
        }
        if error == ErrorCode::INVALID_TOOL {
            return Decision::GiveUp;
        }
        self.explain(link.now_ms(), &request, error);
        let offered: Vec<String> = self
            .buttons(error)
            .iter()
            .map(|(label, code)| format!("{} (B{})", label.to_ascii_lowercase(), code.0))
            .collect();
        if let Some(screen) = screen(error, self.family) {
            self.display.say(&format!(
                "the printer shows {} (prusa.io/{:05}) with {}",
                screen.title,
                screen.id,
                if offered.is_empty() {
                    "no button for the unit".to_string()
                } else {
                    offered.join(", ")
                }
            ));
        }
        self.display.say(
            "Fix it, then type retry (or press Enter) or another button; abort leaves the unit waiting on the error.",
        );
        self.ask(link, "error> ", error)
    }
}
