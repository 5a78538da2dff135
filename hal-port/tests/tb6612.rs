//! Exact pin and PWM sequences of the TB6612FNG driver.
//!
//! Each mock checks its own transactions; a shared journal, filled by thin wrappers around the
//! mocks, checks the order across all of them (PWM 0 before the IN pins, STBY first, ...).

use std::cell::RefCell;
use std::io::ErrorKind;
use std::rc::Rc;

use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
use embedded_hal::pwm::{ErrorType as PwmErrorType, SetDutyCycle};
use embedded_hal_mock::eh1::MockError;
use embedded_hal_mock::eh1::digital::{Mock as PinMock, State, Transaction as PinTransaction};
use embedded_hal_mock::eh1::pwm::{Mock as PwmMock, Transaction as PwmTransaction};
use mmu_hal_port::tb6612::{Channel, Error, Tb6612, Tb6612Channel};
use mmu_hal_port::{Duty, MotorChannel, MotorCommand};

/// `max_duty_cycle()` of every mocked PWM: 64 MHz / 20 kHz.
const MAX: u16 = 3200;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pin {
    A1,
    A2,
    B1,
    B2,
    Stby,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pwm {
    A,
    B,
}

/// One expected call on one input of the chip.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    Set(Pin, State),
    MaxDuty(Pwm),
    Duty(Pwm, u16),
}
use State::{High as H, Low as L};
use Step::{Duty as D, MaxDuty as M, Set as S};

type Journal = Rc<RefCell<Vec<Step>>>;

struct LoggedPin {
    id: Pin,
    mock: PinMock,
    journal: Journal,
}

impl PinErrorType for LoggedPin {
    type Error = MockError;
}

impl OutputPin for LoggedPin {
    fn set_low(&mut self) -> Result<(), MockError> {
        self.journal.borrow_mut().push(S(self.id, L));
        self.mock.set_low()
    }

    fn set_high(&mut self) -> Result<(), MockError> {
        self.journal.borrow_mut().push(S(self.id, H));
        self.mock.set_high()
    }
}

struct LoggedPwm {
    id: Pwm,
    mock: PwmMock,
    journal: Journal,
}

impl PwmErrorType for LoggedPwm {
    type Error = MockError;
}

impl SetDutyCycle for LoggedPwm {
    fn max_duty_cycle(&self) -> u16 {
        self.journal.borrow_mut().push(M(self.id));
        self.mock.max_duty_cycle()
    }

    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), MockError> {
        self.journal.borrow_mut().push(D(self.id, duty));
        self.mock.set_duty_cycle(duty)
    }
}

type Chip = Tb6612<LoggedPwm, LoggedPin, LoggedPin, LoggedPwm, LoggedPin, LoggedPin, LoggedPin>;

/// The chip's seven inputs, each a logged mock.
struct Parts {
    pwm_a: LoggedPwm,
    a1: LoggedPin,
    a2: LoggedPin,
    pwm_b: LoggedPwm,
    b1: LoggedPin,
    b2: LoggedPin,
    stby: LoggedPin,
}

impl Parts {
    fn chip(self) -> Result<Chip, Error<MockError, MockError>> {
        Tb6612::new(
            self.pwm_a, self.a1, self.a2, self.pwm_b, self.b1, self.b2, self.stby,
        )
    }
}

/// What the mocks expect, and clones of them to check at the end.
struct Rig {
    journal: Journal,
    expected: Vec<Step>,
    pins: Vec<PinMock>,
    pwms: Vec<PwmMock>,
}

fn io_error() -> MockError {
    MockError::Io(ErrorKind::Other)
}

/// Mocks expecting exactly `expected`, in that order; the step at index `fail` returns an error.
fn rig_failing(expected: &[Step], fail: Option<usize>) -> (Parts, Rig) {
    let journal = Journal::default();
    let failing = |index: usize| fail == Some(index);
    let pin = |id: Pin| {
        let transactions: Vec<PinTransaction> = expected
            .iter()
            .enumerate()
            .filter_map(|(index, step)| match *step {
                S(pin, state) if pin == id => {
                    let transaction = PinTransaction::set(state);
                    Some(if failing(index) {
                        transaction.with_error(io_error())
                    } else {
                        transaction
                    })
                }
                _ => None,
            })
            .collect();
        LoggedPin {
            id,
            mock: PinMock::new(&transactions),
            journal: journal.clone(),
        }
    };
    let pwm = |id: Pwm| {
        let transactions: Vec<PwmTransaction> = expected
            .iter()
            .enumerate()
            .filter_map(|(index, step)| match *step {
                M(pwm) if pwm == id => Some(PwmTransaction::max_duty_cycle(MAX)),
                D(pwm, duty) if pwm == id => {
                    let transaction = PwmTransaction::set_duty_cycle(duty);
                    Some(if failing(index) {
                        transaction.with_error(io_error())
                    } else {
                        transaction
                    })
                }
                _ => None,
            })
            .collect();
        LoggedPwm {
            id,
            mock: PwmMock::new(&transactions),
            journal: journal.clone(),
        }
    };
    let parts = Parts {
        pwm_a: pwm(Pwm::A),
        a1: pin(Pin::A1),
        a2: pin(Pin::A2),
        pwm_b: pwm(Pwm::B),
        b1: pin(Pin::B1),
        b2: pin(Pin::B2),
        stby: pin(Pin::Stby),
    };
    let rig = Rig {
        journal: journal.clone(),
        expected: expected.to_vec(),
        pins: [&parts.a1, &parts.a2, &parts.b1, &parts.b2, &parts.stby]
            .map(|pin| pin.mock.clone())
            .to_vec(),
        pwms: vec![parts.pwm_a.mock.clone(), parts.pwm_b.mock.clone()],
    };
    (parts, rig)
}

fn rig(expected: &[Step]) -> (Parts, Rig) {
    rig_failing(expected, None)
}

impl Rig {
    /// The calls made were exactly the expected ones, in the expected order.
    fn done(mut self) {
        assert_eq!(*self.journal.borrow(), self.expected);
        self.pins.iter_mut().for_each(PinMock::done);
        self.pwms.iter_mut().for_each(PwmMock::done);
    }
}

/// Construction: STBY low, then both bridges coasting.
const INIT: [Step; 7] = [
    S(Pin::Stby, L),
    D(Pwm::A, 0),
    S(Pin::A1, L),
    S(Pin::A2, L),
    D(Pwm::B, 0),
    S(Pin::B1, L),
    S(Pin::B2, L),
];

/// From anything to forward at 50 % on bridge A (STBY not included).
const A_FORWARD_HALF: [Step; 5] = [
    D(Pwm::A, 0),
    S(Pin::A2, L),
    S(Pin::A1, H),
    M(Pwm::A),
    D(Pwm::A, MAX / 2),
];

fn steps(parts: &[&[Step]]) -> Vec<Step> {
    parts.concat()
}

fn half() -> MotorCommand {
    MotorCommand::forward(Duty::from_permille(500))
}

#[test]
fn construction_leaves_the_chip_in_standby_with_both_bridges_coasting() {
    let (parts, rig) = rig(&INIT);
    parts.chip().unwrap();
    rig.done();
}

#[test]
fn forward_at_half_raises_stby_then_zeroes_the_duty_before_the_in_pins() {
    let (parts, rig) = rig(&steps(&[&INIT, &[S(Pin::Stby, H)], &A_FORWARD_HALF]));
    let mut chip = parts.chip().unwrap();
    chip.apply(Channel::A, half()).unwrap();
    rig.done();
}

#[test]
fn reverse_lowers_in1_and_raises_in2_and_truncates_the_scaled_duty() {
    let (parts, rig) = rig(&steps(&[
        &INIT,
        &[
            S(Pin::Stby, H),
            D(Pwm::B, 0),
            S(Pin::B1, L),
            S(Pin::B2, H),
            M(Pwm::B),
            // 333 * 3200 / 1000 = 1065.6
            D(Pwm::B, 1065),
        ],
    ]));
    let mut chip = parts.chip().unwrap();
    chip.apply(Channel::B, MotorCommand::reverse(Duty::from_permille(333)))
        .unwrap();
    rig.done();
}

#[test]
fn direction_change_stops_the_pwm_and_passes_through_coast() {
    let (parts, rig) = rig(&steps(&[
        &INIT,
        &[S(Pin::Stby, H)],
        &A_FORWARD_HALF,
        &[
            S(Pin::Stby, H),
            D(Pwm::A, 0),
            S(Pin::A1, L),
            S(Pin::A2, H),
            M(Pwm::A),
            D(Pwm::A, MAX / 4),
        ],
        // And back.
        &[S(Pin::Stby, H)],
        &A_FORWARD_HALF,
    ]));
    let mut chip = parts.chip().unwrap();
    chip.apply(Channel::A, half()).unwrap();
    chip.apply(Channel::A, MotorCommand::reverse(Duty::from_permille(250)))
        .unwrap();
    chip.apply(Channel::A, half()).unwrap();
    rig.done();
}

#[test]
fn brake_sets_both_in_pins_high_and_the_pwm_full() {
    let (parts, rig) = rig(&steps(&[
        &INIT,
        &[S(Pin::Stby, H)],
        &A_FORWARD_HALF,
        &[
            S(Pin::Stby, H),
            D(Pwm::A, 0),
            S(Pin::A1, H),
            S(Pin::A2, H),
            M(Pwm::A),
            D(Pwm::A, MAX),
        ],
        // From brake to reverse: IN1 goes low before anything goes high.
        &[
            S(Pin::Stby, H),
            D(Pwm::A, 0),
            S(Pin::A1, L),
            S(Pin::A2, H),
            M(Pwm::A),
            D(Pwm::A, MAX / 2),
        ],
    ]));
    let mut chip = parts.chip().unwrap();
    chip.apply(Channel::A, half()).unwrap();
    chip.apply(Channel::A, MotorCommand::Brake).unwrap();
    chip.apply(Channel::A, MotorCommand::reverse(Duty::from_permille(500)))
        .unwrap();
    rig.done();
}

#[test]
fn coast_zeroes_the_duty_lowers_both_in_pins_and_leaves_stby_high() {
    let (parts, rig) = rig(&steps(&[
        &INIT,
        &[S(Pin::Stby, H)],
        &A_FORWARD_HALF,
        &[D(Pwm::A, 0), S(Pin::A1, L), S(Pin::A2, L)],
    ]));
    let mut chip = parts.chip().unwrap();
    chip.apply(Channel::A, half()).unwrap();
    chip.apply(Channel::A, MotorCommand::Coast).unwrap();
    rig.done();
}

#[test]
fn standby_lowers_stby_first_then_coasts_both_bridges_and_a_drive_wakes_the_chip() {
    let (parts, rig) = rig(&steps(&[
        &INIT,
        &[S(Pin::Stby, H)],
        &A_FORWARD_HALF,
        &[
            S(Pin::Stby, H),
            D(Pwm::B, 0),
            S(Pin::B2, L),
            S(Pin::B1, H),
            M(Pwm::B),
            D(Pwm::B, MAX),
        ],
        &INIT,
        &[S(Pin::Stby, H)],
        &A_FORWARD_HALF,
    ]));
    let mut chip = parts.chip().unwrap();
    chip.apply(Channel::A, half()).unwrap();
    chip.apply(Channel::B, MotorCommand::forward(Duty::MAX)).unwrap();
    chip.standby().unwrap();
    // The same command as before standby is carried out again, STBY included.
    chip.apply(Channel::A, half()).unwrap();
    rig.done();
}

#[test]
fn duty_saturates_at_full_scale() {
    let full = [
        D(Pwm::A, 0),
        S(Pin::A2, L),
        S(Pin::A1, H),
        M(Pwm::A),
        D(Pwm::A, MAX),
    ];
    let (parts, rig) = rig(&steps(&[&INIT, &[S(Pin::Stby, H)], &full]));
    let mut chip = parts.chip().unwrap();
    chip.apply(Channel::A, MotorCommand::forward(Duty::from_permille(1500)))
        .unwrap();
    // Saturated to the same command: nothing more is written.
    chip.apply(Channel::A, MotorCommand::forward(Duty::from_permille(u16::MAX)))
        .unwrap();
    rig.done();
}

#[test]
fn a_repeated_command_writes_nothing_and_a_new_duty_in_the_same_direction_writes_only_the_duty() {
    let (parts, rig) = rig(&steps(&[
        &INIT,
        &[S(Pin::Stby, H)],
        &A_FORWARD_HALF,
        &[S(Pin::Stby, H), M(Pwm::A), D(Pwm::A, 320)],
    ]));
    let mut chip = parts.chip().unwrap();
    chip.apply(Channel::A, half()).unwrap();
    chip.apply(Channel::A, half()).unwrap();
    chip.apply(Channel::A, MotorCommand::forward(Duty::from_permille(100)))
        .unwrap();
    chip.apply(Channel::A, MotorCommand::forward(Duty::from_permille(100)))
        .unwrap();
    rig.done();
}

#[test]
fn a_zero_duty_drive_sets_the_direction_and_leaves_the_pwm_at_zero() {
    let (parts, rig) = rig(&steps(&[
        &INIT,
        &[S(Pin::Stby, H), D(Pwm::A, 0), S(Pin::A2, L), S(Pin::A1, H)],
    ]));
    let mut chip = parts.chip().unwrap();
    chip.apply(Channel::A, MotorCommand::forward(Duty::ZERO)).unwrap();
    rig.done();
}

#[test]
fn channel_handle_drives_its_own_bridge() {
    fn drive(motor: &mut impl MotorChannel<Error = Error<MockError, MockError>>) {
        motor
            .apply(MotorCommand::reverse(Duty::from_permille(500)))
            .unwrap();
    }
    let (parts, rig) = rig(&steps(&[
        &INIT,
        &[
            S(Pin::Stby, H),
            D(Pwm::B, 0),
            S(Pin::B1, L),
            S(Pin::B2, H),
            M(Pwm::B),
            D(Pwm::B, MAX / 2),
        ],
    ]));
    let mut chip = parts.chip().unwrap();
    drive(&mut chip.channel(Channel::B));
    rig.done();
}

#[test]
fn single_channel_coasts_on_construction_and_never_touches_stby() {
    let (parts, rig) = rig(&[
        D(Pwm::A, 0),
        S(Pin::A1, L),
        S(Pin::A2, L),
        D(Pwm::A, 0),
        S(Pin::A2, L),
        S(Pin::A1, H),
        M(Pwm::A),
        D(Pwm::A, MAX / 2),
        D(Pwm::A, 0),
        S(Pin::A1, L),
        S(Pin::A2, H),
        M(Pwm::A),
        D(Pwm::A, MAX / 2),
    ]);
    let mut motor = Tb6612Channel::new(parts.pwm_a, parts.a1, parts.a2).unwrap();
    motor.apply(half()).unwrap();
    motor
        .apply(MotorCommand::reverse(Duty::from_permille(500)))
        .unwrap();
    rig.done();
}

#[test]
fn a_failed_write_stops_the_sequence_and_the_retry_rewrites_everything() {
    let expected = steps(&[
        &INIT,
        // IN1 fails to go high: the duty is not set.
        &[S(Pin::Stby, H), D(Pwm::A, 0), S(Pin::A2, L), S(Pin::A1, H)],
        // The same command again is carried out in full.
        &[S(Pin::Stby, H)],
        &A_FORWARD_HALF,
    ]);
    let (parts, rig) = rig_failing(&expected, Some(INIT.len() + 3));
    let mut chip = parts.chip().unwrap();
    assert_eq!(chip.apply(Channel::A, half()), Err(Error::Pin(io_error())));
    chip.apply(Channel::A, half()).unwrap();
    rig.done();
}

#[test]
fn standby_still_coasts_both_bridges_when_stby_fails() {
    let expected = steps(&[&INIT, &[S(Pin::Stby, H)], &A_FORWARD_HALF, &INIT]);
    let stby_low = INIT.len() + 1 + A_FORWARD_HALF.len();
    let (parts, rig) = rig_failing(&expected, Some(stby_low));
    let mut chip = parts.chip().unwrap();
    chip.apply(Channel::A, half()).unwrap();
    assert_eq!(chip.standby(), Err(Error::Pin(io_error())));
    rig.done();
}
