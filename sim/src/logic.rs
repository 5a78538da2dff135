//! The unit logic with its slot count chosen at run time.
//!
//! [`App`] takes its slot count as a const generic, as the firmware must; the simulator's
//! `--slots` is a run-time value. [`UnitLogic`] is the object-safe face of `App<N>` that
//! [`new_logic`] builds for any supported count.

use mmu_firmware::ops::Status;
use mmu_firmware::{App, BoardAction, Config, Instant, MAX_SLOTS, MotorCommand};
use mmu_model::Model;
use mmu_protocol::{ButtonCode, RequestCode};

/// One App of any slot count, stepped against the model.
pub trait UnitLogic: Send {
    /// One control step at `now`: sample `model`, step the App with `rx`, append what it sends to
    /// `tx`, and run the model for `dt_ms` with the App's motor commands. Returns the board action
    /// the App asked for, if any.
    fn step(
        &mut self,
        now: Instant,
        dt_ms: u32,
        model: &mut Model,
        rx: &[u8],
        tx: &mut Vec<u8>,
    ) -> Option<BoardAction>;

    /// The command the unit is carrying out (the one `Q0` echoes) and where it stands.
    fn command(&self) -> ((RequestCode, u8), Status);

    /// A physical button on the unit was pressed.
    fn press_button(&mut self, button: ButtonCode);

    /// The configuration the logic runs with.
    fn config(&self) -> &Config;
}

impl<const N: usize> UnitLogic for App<N> {
    fn step(
        &mut self,
        now: Instant,
        dt_ms: u32,
        model: &mut Model,
        rx: &[u8],
        tx: &mut Vec<u8>,
    ) -> Option<BoardAction> {
        let samples = model.samples::<N>();
        let out = App::step(self, now, &samples, rx);
        tx.extend_from_slice(&out.tx);
        let motors = if out.action.is_some() {
            [MotorCommand::Coast; N]
        } else {
            out.motors
        };
        model.step(dt_ms, &motors);
        out.action
    }

    fn command(&self) -> ((RequestCode, u8), Status) {
        let operation = self.operation();
        (operation.request, operation.status())
    }

    fn press_button(&mut self, button: ButtonCode) {
        App::press_button(self, button);
    }

    fn config(&self) -> &Config {
        App::config(self)
    }
}

/// A freshly booted unit logic with `slots` slots, or `None` when the count is not 1 to
/// [`MAX_SLOTS`].
pub fn new_logic(slots: usize, config: Config) -> Option<Box<dyn UnitLogic>> {
    const _: () = assert!(MAX_SLOTS == 5, "new_logic lists every slot count");
    Some(match slots {
        1 => Box::new(App::<1>::new(config)),
        2 => Box::new(App::<2>::new(config)),
        3 => Box::new(App::<3>::new(config)),
        4 => Box::new(App::<4>::new(config)),
        5 => Box::new(App::<5>::new(config)),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use mmu_model::ModelConfig;

    #[test]
    fn every_supported_slot_count_boots_and_no_other() {
        for slots in 1..=MAX_SLOTS {
            let mut logic = new_logic(slots, Config::default()).expect("supported count");
            let mut model = Model::new(ModelConfig::default(), slots, 1);
            let mut tx = Vec::new();
            for ms in 0..300 {
                logic.step(Instant::from_millis(ms), 1, &mut model, &[], &mut tx);
            }
            assert_eq!(logic.command(), ((RequestCode::Reset, 0), Status::Finished));
        }
        assert!(new_logic(0, Config::default()).is_none());
        assert!(new_logic(MAX_SLOTS + 1, Config::default()).is_none());
    }
}
