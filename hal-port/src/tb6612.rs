//! TB6612FNG dual H-bridge driver over `embedded-hal` 1.0.
//!
//! Every filament slot is one DC motor on one half of a TB6612FNG. This module turns the logic's
//! [`MotorCommand`]s into that chip's pin levels, in one fixed order that never reverses a motor
//! at speed, so every board built on the chip shares a single, tested pin sequence.
//!
//! # Command to pins
//!
//! | Command               | IN1 | IN2 | PWM                | Bridge (datasheet)            |
//! |-----------------------|-----|-----|--------------------|-------------------------------|
//! | `Drive{Forward, d}`   | H   | L   | `d` of full scale  | CW, short brake in off phase  |
//! | `Drive{Reverse, d}`   | L   | H   | `d` of full scale  | CCW, short brake in off phase |
//! | `Brake`               | H   | H   | full scale         | short brake                   |
//! | `Coast`               | L   | L   | 0                  | stop, outputs high impedance  |
//!
//! The duty is scaled as [`SetDutyCycle::set_duty_cycle_fraction`]`(permille, 1000)` scales it
//! (`permille × max_duty_cycle() / 1000`, without its library division: see [`set_duty`]), so it is
//! truncated to the timer's resolution. A zero-duty drive therefore short-brakes (PWM low with
//! IN1 ≠ IN2). `Brake` sets the PWM to full scale although IN1 = IN2 = H already brakes whatever
//! the PWM level: the brake then holds on every row of the datasheet's truth table.
//!
//! # Transition order
//!
//! Every command that changes a channel writes the whole sequence, always in this order:
//!
//! 1. PWM duty 0 (the bridge short-brakes or coasts from here on, never drives),
//! 2. the IN pins that must be low, IN1 before IN2,
//! 3. the IN pins that must be high, IN1 before IN2,
//! 4. the new duty, only when it is not zero (it already is).
//!
//! So a direction change (H,L → L,H or back) passes through L,L (coast) at duty 0, and IN1 = IN2 = H
//! is only ever reached when `Brake` is commanded. A new non-zero duty in the direction the channel
//! already drives is written alone, so a speed controller's small corrections do not dip the
//! motor to zero. A command equal to the last one carried out on that channel writes nothing; after any error the channel's state counts as unknown and the
//! next command writes the whole sequence again.
//!
//! # Standby
//!
//! STBY low turns both outputs off. [`Tb6612`] raises STBY before carrying out a `Drive` or a
//! `Brake` (a `Coast` never touches it), and only [`Tb6612::standby`] (which the constructor
//! calls) lowers it: `Coast` on both channels leaves the chip awake with both outputs open.
//!
//! # Errors
//!
//! All PWM inputs of one driver share one error type and all its pins share another, which is
//! the case on every HAL (often [`core::convert::Infallible`]); [`Error`] tells which failed.

use core::convert::Infallible;

use embedded_hal::digital::OutputPin;
use embedded_hal::pwm::SetDutyCycle;

use crate::{Direction, Duty, MotorChannel, MotorCommand};

/// One of the two bridges of a TB6612FNG.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Channel {
    /// Bridge A: inputs PWMA, AIN1, AIN2; outputs AO1, AO2.
    A,
    /// Bridge B: inputs PWMB, BIN1, BIN2; outputs BO1, BO2.
    B,
}

/// A failed write to one of the chip's inputs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Error<PwmE, PinE> {
    /// Setting a PWM duty cycle failed.
    Pwm(PwmE),
    /// Setting an IN or STBY pin failed.
    Pin(PinE),
}

/// The pin levels that carry out one command.
struct Levels {
    in1_high: bool,
    in2_high: bool,
    duty: Duty,
}

impl Levels {
    const fn of(command: MotorCommand) -> Self {
        match command {
            MotorCommand::Coast => Levels {
                in1_high: false,
                in2_high: false,
                duty: Duty::ZERO,
            },
            MotorCommand::Brake => Levels {
                in1_high: true,
                in2_high: true,
                duty: Duty::MAX,
            },
            MotorCommand::Drive {
                direction: Direction::Forward,
                duty,
            } => Levels {
                in1_high: true,
                in2_high: false,
                duty,
            },
            MotorCommand::Drive {
                direction: Direction::Reverse,
                duty,
            } => Levels {
                in1_high: false,
                in2_high: true,
                duty,
            },
        }
    }
}

/// One bridge of a TB6612FNG: its PWM input and its IN1/IN2 pins.
///
/// On its own it is a complete [`MotorChannel`] for a board that ties STBY high; [`Tb6612`] holds
/// two of them and the STBY pin.
#[derive(Debug)]
pub struct Tb6612Channel<P, I1, I2> {
    pwm: P,
    in1: I1,
    in2: I2,
    /// The command the pins are known to carry out; `None` before the first write and after an
    /// error.
    applied: Option<MotorCommand>,
}

impl<P, I1, I2, PwmE, PinE> Tb6612Channel<P, I1, I2>
where
    P: SetDutyCycle<Error = PwmE>,
    I1: OutputPin<Error = PinE>,
    I2: OutputPin<Error = PinE>,
{
    /// Takes the bridge's PWM input and IN1/IN2 pins and sets it coasting (duty 0, IN1 = IN2 = L).
    pub fn new(pwm: P, in1: I1, in2: I2) -> Result<Self, Error<PwmE, PinE>> {
        let mut channel = Self::unknown(pwm, in1, in2);
        channel.set(MotorCommand::Coast)?;
        Ok(channel)
    }

    /// Takes the pins without writing to them.
    const fn unknown(pwm: P, in1: I1, in2: I2) -> Self {
        Tb6612Channel {
            pwm,
            in1,
            in2,
            applied: None,
        }
    }

    /// Carries out `command` unless it is the one last carried out (see the module docs).
    fn set(&mut self, command: MotorCommand) -> Result<(), Error<PwmE, PinE>> {
        if self.applied == Some(command) {
            return Ok(());
        }
        if let (
            Some(MotorCommand::Drive {
                direction: was,
                duty: old,
            }),
            MotorCommand::Drive { direction, duty },
        ) = (self.applied, command)
            && was == direction
            && old != Duty::ZERO
            && duty != Duty::ZERO
        {
            // Same direction, still driving: only the duty changes, without a dip to zero.
            self.applied = None;
            set_duty(&mut self.pwm, duty).map_err(Error::Pwm)?;
            self.applied = Some(command);
            return Ok(());
        }
        self.applied = None;
        self.write(command)?;
        self.applied = Some(command);
        Ok(())
    }

    /// The pin sequence: duty 0, IN pins going low, IN pins going high, then the new duty.
    fn write(&mut self, command: MotorCommand) -> Result<(), Error<PwmE, PinE>> {
        let levels = Levels::of(command);
        self.pwm.set_duty_cycle_fully_off().map_err(Error::Pwm)?;
        if !levels.in1_high {
            self.in1.set_low().map_err(Error::Pin)?;
        }
        if !levels.in2_high {
            self.in2.set_low().map_err(Error::Pin)?;
        }
        if levels.in1_high {
            self.in1.set_high().map_err(Error::Pin)?;
        }
        if levels.in2_high {
            self.in2.set_high().map_err(Error::Pin)?;
        }
        if levels.duty != Duty::ZERO {
            set_duty(&mut self.pwm, levels.duty).map_err(Error::Pwm)?;
        }
        Ok(())
    }
}

impl<P, I1, I2, PwmE, PinE> MotorChannel for Tb6612Channel<P, I1, I2>
where
    P: SetDutyCycle<Error = PwmE>,
    I1: OutputPin<Error = PinE>,
    I2: OutputPin<Error = PinE>,
{
    type Error = Error<PwmE, PinE>;

    fn apply(&mut self, command: MotorCommand) -> Result<(), Self::Error> {
        self.set(command)
    }
}

/// One TB6612FNG: both bridges and the shared STBY pin.
#[derive(Debug)]
pub struct Tb6612<PA, A1, A2, PB, B1, B2, STBY> {
    a: Tb6612Channel<PA, A1, A2>,
    b: Tb6612Channel<PB, B1, B2>,
    stby: STBY,
}

impl<PA, A1, A2, PB, B1, B2, STBY, PwmE, PinE> Tb6612<PA, A1, A2, PB, B1, B2, STBY>
where
    PA: SetDutyCycle<Error = PwmE>,
    A1: OutputPin<Error = PinE>,
    A2: OutputPin<Error = PinE>,
    PB: SetDutyCycle<Error = PwmE>,
    B1: OutputPin<Error = PinE>,
    B2: OutputPin<Error = PinE>,
    STBY: OutputPin<Error = PinE>,
{
    /// Takes the chip's pins and puts it in standby with both bridges coasting, as
    /// [`Tb6612::standby`] does: STBY low, then duty 0, IN1 low, IN2 low on A, then on B.
    pub fn new(
        pwm_a: PA,
        a_in1: A1,
        a_in2: A2,
        pwm_b: PB,
        b_in1: B1,
        b_in2: B2,
        stby: STBY,
    ) -> Result<Self, Error<PwmE, PinE>> {
        let mut chip = Tb6612 {
            a: Tb6612Channel::unknown(pwm_a, a_in1, a_in2),
            b: Tb6612Channel::unknown(pwm_b, b_in1, b_in2),
            stby,
        };
        chip.standby()?;
        Ok(chip)
    }

    /// Carries out `command` on bridge `channel`, raising STBY first for a `Drive` or a `Brake`.
    ///
    /// A command equal to the last one carried out on that bridge writes nothing.
    pub fn apply(&mut self, channel: Channel, command: MotorCommand) -> Result<(), Error<PwmE, PinE>> {
        match channel {
            Channel::A => Self::apply_on(&mut self.a, &mut self.stby, command),
            Channel::B => Self::apply_on(&mut self.b, &mut self.stby, command),
        }
    }

    /// Bridge `channel` as a [`MotorChannel`], borrowing the chip.
    pub fn channel(&mut self, channel: Channel) -> impl MotorChannel<Error = Error<PwmE, PinE>> + '_ {
        ChannelOf { chip: self, channel }
    }

    /// Lowers STBY (both outputs off at once), then sets both bridges coasting (duty 0,
    /// IN1 = IN2 = L) so that raising STBY again cannot resume an old command.
    ///
    /// Every write is attempted even after one fails; the first error is returned.
    pub fn standby(&mut self) -> Result<(), Error<PwmE, PinE>> {
        // Forget the bridges' state first: if anything below fails, the next command rewrites all.
        self.a.applied = None;
        self.b.applied = None;
        let stby = self.stby.set_low().map_err(Error::Pin);
        let a = self.a.set(MotorCommand::Coast);
        let b = self.b.set(MotorCommand::Coast);
        stby.and(a).and(b)
    }

    fn apply_on<P, I1, I2>(
        bridge: &mut Tb6612Channel<P, I1, I2>,
        stby: &mut STBY,
        command: MotorCommand,
    ) -> Result<(), Error<PwmE, PinE>>
    where
        P: SetDutyCycle<Error = PwmE>,
        I1: OutputPin<Error = PinE>,
        I2: OutputPin<Error = PinE>,
    {
        // An unchanged drive or brake is skipped whole: STBY went high before it was carried out
        // and `standby` forgets every bridge's state, so STBY is still high.
        if bridge.applied == Some(command) {
            return Ok(());
        }
        if command != MotorCommand::Coast {
            stby.set_high().map_err(Error::Pin)?;
        }
        bridge.set(command)
    }
}

/// One bridge of a borrowed [`Tb6612`], returned by [`Tb6612::channel`].
struct ChannelOf<'a, T> {
    chip: &'a mut T,
    channel: Channel,
}

impl<PA, A1, A2, PB, B1, B2, STBY, PwmE, PinE> MotorChannel
    for ChannelOf<'_, Tb6612<PA, A1, A2, PB, B1, B2, STBY>>
where
    PA: SetDutyCycle<Error = PwmE>,
    A1: OutputPin<Error = PinE>,
    A2: OutputPin<Error = PinE>,
    PB: SetDutyCycle<Error = PwmE>,
    B1: OutputPin<Error = PinE>,
    B2: OutputPin<Error = PinE>,
    STBY: OutputPin<Error = PinE>,
{
    type Error = Error<PwmE, PinE>;

    fn apply(&mut self, command: MotorCommand) -> Result<(), Self::Error> {
        self.chip.apply(self.channel, command)
    }
}

/// The three slot motors on two TB6612FNG: chip 1 drives slots 0 (bridge A) and 1 (bridge B),
/// chip 2 slot 2 (bridge A; bridge B unused). A chip whose motors all coast is put in standby
/// (STBY low), so a bridge is only powered while the logic drives or brakes it.
pub struct Bridges<C1, C2> {
    chip1: C1,
    chip2: C2,
    /// Whether each chip is in standby.
    standby: [bool; 2],
}

impl<PA, A1, A2, PB, B1, B2, S1, QA, C1, C2, QB, D1, D2, S2, E>
    Bridges<Tb6612<PA, A1, A2, PB, B1, B2, S1>, Tb6612<QA, C1, C2, QB, D1, D2, S2>>
where
    PA: SetDutyCycle<Error = E>,
    PB: SetDutyCycle<Error = E>,
    QA: SetDutyCycle<Error = E>,
    QB: SetDutyCycle<Error = E>,
    A1: OutputPin<Error = Infallible>,
    A2: OutputPin<Error = Infallible>,
    B1: OutputPin<Error = Infallible>,
    B2: OutputPin<Error = Infallible>,
    S1: OutputPin<Error = Infallible>,
    C1: OutputPin<Error = Infallible>,
    C2: OutputPin<Error = Infallible>,
    D1: OutputPin<Error = Infallible>,
    D2: OutputPin<Error = Infallible>,
    S2: OutputPin<Error = Infallible>,
{
    /// Both chips, in standby (as `Tb6612::new` leaves them).
    pub fn new(chip1: Tb6612<PA, A1, A2, PB, B1, B2, S1>, chip2: Tb6612<QA, C1, C2, QB, D1, D2, S2>) -> Self {
        Bridges {
            chip1,
            chip2,
            standby: [true; 2],
        }
    }
}

impl<PA, A1, A2, PB, B1, B2, S1, QA, C1, C2, QB, D1, D2, S2, E> crate::Motors<3>
    for Bridges<Tb6612<PA, A1, A2, PB, B1, B2, S1>, Tb6612<QA, C1, C2, QB, D1, D2, S2>>
where
    PA: SetDutyCycle<Error = E>,
    PB: SetDutyCycle<Error = E>,
    QA: SetDutyCycle<Error = E>,
    QB: SetDutyCycle<Error = E>,
    A1: OutputPin<Error = Infallible>,
    A2: OutputPin<Error = Infallible>,
    B1: OutputPin<Error = Infallible>,
    B2: OutputPin<Error = Infallible>,
    S1: OutputPin<Error = Infallible>,
    C1: OutputPin<Error = Infallible>,
    C2: OutputPin<Error = Infallible>,
    D1: OutputPin<Error = Infallible>,
    D2: OutputPin<Error = Infallible>,
    S2: OutputPin<Error = Infallible>,
{
    /// A PWM or pin error (none on either HAL: their errors are `Infallible`) leaves that
    /// bridge's state unknown to its driver, which rewrites it at the next command.
    fn apply(&mut self, motors: &[MotorCommand; 3]) {
        let coast = MotorCommand::Coast;
        if motors[0] == coast && motors[1] == coast {
            if !self.standby[0] {
                ignore(self.chip1.standby());
                self.standby[0] = true;
            }
        } else {
            ignore(self.chip1.apply(Channel::A, motors[0]));
            ignore(self.chip1.apply(Channel::B, motors[1]));
            self.standby[0] = false;
        }
        if motors[2] == coast {
            if !self.standby[1] {
                ignore(self.chip2.standby());
                self.standby[1] = true;
            }
        } else {
            ignore(self.chip2.apply(Channel::A, motors[2]));
            self.standby[1] = false;
        }
    }
}

/// A driver error: nothing to do about it here (see [`Bridges`]'s `apply`).
fn ignore<E>(_: Result<(), Error<E, Infallible>>) {}

/// Sets `pwm` to `duty` of its full scale.
fn set_duty<P: SetDutyCycle>(pwm: &mut P, duty: Duty) -> Result<(), P::Error> {
    pwm.set_duty_cycle_fraction(duty.permille(), 1000)
}
