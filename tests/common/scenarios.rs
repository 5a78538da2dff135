//! The printer's and the user's recurring moves in the command tests, as methods of the rig:
//! register writes, Retry, a command that stops on an error and what Retry then does, so each
//! test reads as its scenario.

use super::{
    HUB_OFF_REGISTER, OFF_THRESHOLD_DEFAULT, OFF_THRESHOLD_NEVER, PARK_MM, Rig, Run, error, finished, press,
    t,
};
use mmu_model::{Fault, Rail, SensorId};
use mmu_protocol::{ButtonCode, ErrorCode, ParamCode, ProgressCode, Request, RequestCode, Response};

impl<const N: usize> Rig<N> {
    /// Write a register; the unit accepts it.
    pub fn write(&mut self, address: u8, value: u16) {
        let answer = self.send(Request::write(address, value));
        assert_eq!(
            answer.map(|a| a.param),
            Some(ParamCode::Accepted),
            "write {address:#04x} = {value}"
        );
    }

    /// The value of register `address`.
    pub fn read(&mut self, address: u8) -> Option<u16> {
        self.send(Request::new(RequestCode::Read, address))
            .and_then(|a| a.param_value)
    }

    /// Retry (the Middle button) after the printer has reported its sensor as it is now.
    pub fn retry(&mut self) {
        self.printer_step(None);
        press(self, ButtonCode::MIDDLE);
    }

    /// Retry (the Middle button, as the only thing sent), then the `Q0` answer 50 ms later.
    pub fn press_retry_then_query(&mut self) -> Response {
        press(self, ButtonCode::MIDDLE);
        self.idle(50);
        self.query()
    }

    /// `request` waits on `code`: Retry with the cause still there gives the same error; the
    /// cause is removed (`fix`) and Retry checks again: `request` finishes.
    pub fn retry_fails_until_fixed(
        &mut self,
        request: Request,
        code: ErrorCode,
        fix: impl FnOnce(&mut Self),
    ) {
        assert_eq!(
            self.press_retry_then_query(),
            error(request, code),
            "the cause is still there"
        );
        fix(self);
        self.idle(1000);
        assert_eq!(self.press_retry_then_query(), finished(request));
    }

    /// `T<slot>` runs to the end: it finishes with slot `slot` loaded.
    pub fn tool_change_loads(&mut self, slot: u8) -> Run {
        let run = self.command(t(slot));
        assert_eq!(run.last, finished(t(slot)), "progress {:?}", run.progress);
        assert_eq!(self.model.loaded_slot(), Some(slot.into()));
        run
    }

    /// The `T<slot>` in progress goes on to the end: it finishes with slot `slot` loaded.
    pub fn tool_change_goes_on_and_loads(&mut self, slot: u8) -> Run {
        let run = self.follow(t(slot), 120_000);
        assert_eq!(run.last, finished(t(slot)), "progress {:?}", run.progress);
        assert_eq!(self.model.loaded_slot(), Some(slot.into()));
        run
    }

    /// Issue `request` and play it until `Q0` reports `progress`.
    pub fn command_until(&mut self, request: Request, progress: ProgressCode) -> Run {
        self.issue(request);
        let run = self.follow_until(request, Some(progress), 120_000);
        assert_eq!(run.progress.last(), Some(&progress), "{:?}", run.last);
        run
    }

    /// Issue `request`: it stops on `code` and every motor stops.
    pub fn command_fails_with(&mut self, request: Request, code: ErrorCode) -> Run {
        let run = self.command(request);
        self.stopped_on(request, code, run)
    }

    /// The command in progress stops on `code` and every motor stops.
    pub fn fails_with(&mut self, request: Request, code: ErrorCode) -> Run {
        let run = self.follow(request, 120_000);
        self.stopped_on(request, code, run)
    }

    fn stopped_on(&mut self, request: Request, code: ErrorCode, run: Run) -> Run {
        assert_eq!(run.last, error(request, code), "progress {:?}", run.progress);
        self.idle(10);
        assert!(self.motors_stopped(), "every motor stops on {code}");
        run
    }

    /// Retry, then play the command until it ends: it finishes.
    pub fn retry_finishes(&mut self, request: Request) -> Run {
        self.retry();
        let run = self.follow(request, 120_000);
        assert_eq!(run.last, finished(request), "progress {:?}", run.progress);
        run
    }

    /// The command in progress stops on `code` with every motor stopped; the fault is cleared
    /// and Retry pressed: it goes on from the failed phase (`progress`) and finishes.
    pub fn fails_then_retry_finishes(
        &mut self,
        request: Request,
        code: ErrorCode,
        progress: &[ProgressCode],
    ) {
        self.fails_with(request, code);
        self.model.clear_all();
        self.idle(1000);
        assert_eq!(self.retry_finishes(request).progress, progress);
    }

    /// The hub sensor never reads "off": the next command that pulls a tip out of the hub
    /// stops on `FINDA_DIDNT_SWITCH_OFF`.
    pub fn hub_never_clears(&mut self) {
        self.write(HUB_OFF_REGISTER, OFF_THRESHOLD_NEVER);
    }

    /// The hub sensor's "off" threshold is right again, and the rig has seen it.
    pub fn hub_clears_again(&mut self) {
        self.write(HUB_OFF_REGISTER, OFF_THRESHOLD_DEFAULT);
        self.idle(100);
    }

    /// The hub sensor never reads "off": `request` stops on `FINDA_DIDNT_SWITCH_OFF` with every
    /// motor stopped; the threshold is fixed and Retry finishes it. The failed run and the
    /// retried one.
    pub fn hub_never_clears_then_retry(&mut self, request: Request) -> (Run, Run) {
        self.hub_never_clears();
        let failed = self.command_fails_with(request, ErrorCode::FINDA_DIDNT_SWITCH_OFF);
        self.hub_clears_again();
        (failed, self.retry_finishes(request))
    }

    /// `sensor`'s wire comes loose and rests at `rail`.
    pub fn disconnect(&mut self, sensor: SensorId, rail: Rail) {
        self.inject(Fault::SensorDisconnected { sensor, rail });
    }

    /// Filament pushed into the hub by hand (slot 1's, 5 mm past the sensor): `request` stops on
    /// `FINDA_VS_EEPROM_DISREPANCY`; Retry with it still there gives the same error and moves
    /// no motor. The user pulls it back to the park position and presses Retry: the run that
    /// follows.
    pub fn filament_in_the_hub_no_slot_owns_then_pulled_back(&mut self, request: Request) -> Run {
        self.model.insert_filament(1, 5.0);
        self.idle(100);
        let before = self.motor_log.len();
        let run = self.command(request);
        let unowned = error(request, ErrorCode::FINDA_VS_EEPROM_DISREPANCY);
        assert_eq!(run.last, unowned);
        self.retry();
        self.idle(50);
        assert_eq!(self.query(), unowned, "the cause is still there");
        assert!(self.nothing_moved_since(before), "no motor moves on a guess");
        self.model.insert_filament(1, PARK_MM);
        self.idle(100);
        self.retry();
        self.follow(request, 120_000)
    }

    /// No motor was driven since the motor log had `since` entries.
    pub fn nothing_moved_since(&self, since: usize) -> bool {
        self.motor_log[since..]
            .iter()
            .all(|motors| motors.iter().all(|m| !m.is_driving()))
    }

    /// Slot `slot`'s motor was never driven.
    pub fn slot_never_ran(&self, slot: usize) -> bool {
        self.motor_log.iter().all(|motors| !motors[slot].is_driving())
    }
}
