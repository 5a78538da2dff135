//! The thin hardware port of the MMU logic.
//!
//! The unit logic is stepped with sensor samples and answers with [`MotorCommand`]s; this crate
//! holds that shared vocabulary and the few traits a board implements to carry it out: a DC motor
//! channel, an analog input, a status LED and a button. Where `embedded-hal` 1.0 has a standard
//! trait, an adapter over it is provided (the TB6612FNG driver in [`tb6612`]), so a new board is
//! mostly wiring.

#![no_std]
#![warn(missing_docs)]

pub mod tb6612;

/// Largest raw analog sample: every board scales its ADC readings to 12 bits.
pub const ADC_MAX: u16 = 4095;

/// Counts of an angle sensor's turn (12 bits, AS5600).
pub const ANGLE_COUNTS: u16 = 4096;

/// Set in an angle sample the sensor could not measure (no magnet, a magnet too weak or too
/// strong, no answer on its bus).
pub const ANGLE_FAULT: u16 = 0x8000;

/// How a lane measures the filament's motion. Every source is read as a count of a sensed
/// shaft's turn, `counts_per_rev` counts to the turn; register 0x42 (`mm_per_rev_centi`) says
/// how far the filament moves per turn, so the odometry is `counts × mm_per_rev / counts_per_rev`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MotionSensor {
    /// An analog Hall sensor that sees one magnet on the motor shaft: a sine-like wave, one
    /// period per revolution, read on the ADC. It cannot tell the direction: a revolution counts
    /// the way the motor was last driven.
    HallWave,
    /// A two-channel Hall quadrature encoder on the motor: the board counts every edge of both
    /// channels, up and down, into a wrapping 16-bit count (the sample).
    Quadrature {
        /// Edges per turn of the output shaft (4 × pulses per channel × gear ratio).
        counts_per_rev: u16,
    },
    /// One channel of pulses (an encoder wired with one channel, a slotted disc): the board
    /// counts its edges up into a wrapping 16-bit count. It cannot tell the direction: the
    /// pulses count the way the motor was last driven, as a Hall wave's revolutions do.
    Pulses {
        /// Edges per turn of the output shaft.
        counts_per_rev: u16,
    },
    /// A magnetic angle sensor (AS5600) on the drive gear: the sample is its 12-bit angle, with
    /// [`ANGLE_FAULT`] set while the magnet is missing, too weak or too strong, or the sensor
    /// does not answer.
    Angle,
}

impl MotionSensor {
    /// Counts of one turn of the sensed shaft.
    pub const fn counts_per_rev(self) -> u16 {
        match self {
            MotionSensor::HallWave => 1,
            MotionSensor::Quadrature { counts_per_rev } | MotionSensor::Pulses { counts_per_rev } => {
                counts_per_rev
            }
            MotionSensor::Angle => ANGLE_COUNTS,
        }
    }
}

/// Which way a slot motor turns the filament.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Direction {
    /// Towards the hub and the printer.
    Forward,
    /// Back towards the spool.
    Reverse,
}

/// A PWM duty cycle in per mille (0 = off, 1000 = always on).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Duty(u16);

impl Duty {
    /// Full scale.
    pub const MAX: Duty = Duty(1000);
    /// Off.
    pub const ZERO: Duty = Duty(0);

    /// A duty cycle of `permille`, saturated at [`Duty::MAX`].
    pub const fn from_permille(permille: u16) -> Self {
        if permille > Self::MAX.0 {
            Self::MAX
        } else {
            Duty(permille)
        }
    }

    /// The duty cycle in per mille, `0..=1000`.
    pub const fn permille(self) -> u16 {
        self.0
    }
}

/// What one slot motor is told to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MotorCommand {
    /// Outputs open: the motor spins freely (the extruder may pull the filament through).
    #[default]
    Coast,
    /// Outputs shorted: the motor holds against being turned.
    Brake,
    /// Driven in `direction` at `duty`.
    Drive {
        /// Which way.
        direction: Direction,
        /// How hard.
        duty: Duty,
    },
}

impl MotorCommand {
    /// Drive forward (towards the printer) at `duty`.
    pub const fn forward(duty: Duty) -> Self {
        MotorCommand::Drive {
            direction: Direction::Forward,
            duty,
        }
    }

    /// Drive in reverse (towards the spool) at `duty`.
    pub const fn reverse(duty: Duty) -> Self {
        MotorCommand::Drive {
            direction: Direction::Reverse,
            duty,
        }
    }

    /// True when the motor is powered to turn (a non-zero drive duty).
    pub const fn is_driving(self) -> bool {
        matches!(self, MotorCommand::Drive { duty, .. } if duty.0 > 0)
    }
}

/// One DC motor channel.
pub trait MotorChannel {
    /// The driver's error (a pin or PWM error).
    type Error;

    /// Carry out `command`.
    fn apply(&mut self, command: MotorCommand) -> Result<(), Self::Error>;
}

/// The unit's status LED.
pub trait StatusLed {
    /// The pin's error.
    type Error;

    /// Turn the LED on or off.
    fn set_lit(&mut self, lit: bool) -> Result<(), Self::Error>;
}

impl<P: embedded_hal::digital::OutputPin> StatusLed for P {
    type Error = P::Error;

    fn set_lit(&mut self, lit: bool) -> Result<(), Self::Error> {
        self.set_state(lit.into())
    }
}

/// A push button on the unit, active low (pressed pulls the pin to ground).
pub trait Button {
    /// The pin's error.
    type Error;

    /// True while the button is held down.
    fn is_pressed(&mut self) -> Result<bool, Self::Error>;
}

impl<P: embedded_hal::digital::InputPin> Button for P {
    type Error = P::Error;

    fn is_pressed(&mut self) -> Result<bool, Self::Error> {
        self.is_low()
    }
}

/// Every sensor of a unit with `N` slots, scanned together: the board's ADC (by DMA on the
/// NUCLEO-G071RB, through an analog multiplexer on the Pico). The firmware's control task bounds
/// the wait with a timeout, so an implementation may simply wait for its converter.
#[allow(async_fn_in_trait)] // called from one executor thread; no `Send` bound is wanted
pub trait SensorScan<const N: usize> {
    /// The converter's error.
    type Error;

    /// One scan of every sensor, raw 12-bit values (`0..=ADC_MAX`).
    async fn scan(&mut self) -> Result<Samples<N>, Self::Error>;
}

/// Every slot motor of a unit with `N` slots, driven as one.
pub trait Motors<const N: usize> {
    /// Carries out one step's commands, slot by slot.
    fn apply(&mut self, commands: &[MotorCommand; N]);
}

/// A hardware watchdog that resets the MCU unless fed in time.
pub trait Watchdog {
    /// Restarts the watchdog's countdown.
    fn feed(&mut self);
}

/// Raw samples of one slot's sensors. What `motion` means is the lane's [`MotionSensor`]'s: an
/// analog Hall level, a wrapping count, or an angle sensor's 12-bit angle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SlotSamples {
    /// The lane's motion sensor.
    pub motion: u16,
    /// The slot filament sensor at the slot entry: higher with filament present.
    pub filament: u16,
    /// The lane's own tension sensor, where the profile has one (0 where it has none).
    pub tension: u16,
}

/// Raw samples of the Filament Hub's three analog Hall sensors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HubSamples {
    /// Filament present in the hub (the unit's FINDA): higher with filament present.
    pub filament: u16,
    /// Bowden tube buffer: mid-scale at rest, higher when the filament is pulled taut, lower
    /// when it is pushed into compression.
    pub tension: u16,
    /// Reserved for a future blade: read and reported only.
    pub cutter: u16,
}

/// One sampling round of every analog sensor of a unit with `N` slots.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Samples<const N: usize> {
    /// Per slot, in slot order.
    pub slots: [SlotSamples; N],
    /// The hub.
    pub hub: HubSamples,
}

impl<const N: usize> Samples<N> {
    /// Every sensor reading `value` (mid-scale: every sensor healthy, no filament anywhere).
    pub const fn uniform(value: u16) -> Self {
        Samples {
            slots: [SlotSamples {
                motion: value,
                filament: value,
                tension: value,
            }; N],
            hub: HubSamples {
                filament: value,
                tension: value,
                cutter: value,
            },
        }
    }
}

impl<const N: usize> Default for Samples<N> {
    fn default() -> Self {
        Samples {
            slots: [SlotSamples::default(); N],
            hub: HubSamples::default(),
        }
    }
}
