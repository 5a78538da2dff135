//! The NUCLEO-G071RB's parts for N20 encoder gear motors (feature `g071-n20`, profile
//! `n20-quadrature`): each lane's quadrature encoder counted by a timer in encoder mode, and the
//! motor PWM on the three one-channel timers.
//!
//! Only TIM1, TIM2 and TIM3 have the encoder interface on the STM32G071 (RM0444: the slave mode
//! controller's encoder modes are in the advanced-control and general-purpose timers TIM1 to TIM3,
//! not in TIM14 to TIM17), one lane each; embassy-time then runs on TIM15 (its two channels are
//! what the time driver needs) and the motor PWM on TIM14, TIM16 and TIM17, one channel each.
//! embassy-stm32 0.6.0 has no PWM driver for a one-channel timer (`SimplePwm` takes a
//! four-channel one, and its `TimerPin` trait covers four-channel timers only), so
//! [`SingleChannelPwm`] sets the channel up on the HAL's low-level `Timer`, in this one place.

use core::convert::Infallible;

use embassy_stm32::Peri;
use embassy_stm32::gpio::{AfType, Flex, OutputType, Pin, Pull, Speed};
use embassy_stm32::peripherals::{TIM1, TIM2, TIM3};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::{RoundTo, Timer};
use embassy_stm32::timer::qei::{Config as QeiConfig, Qei, QeiMode};
use embassy_stm32::timer::{AdvancedInstance1Channel, Ch1, Ch2, GeneralInstance1Channel, TimerPin};
use embedded_hal::pwm::{ErrorType, SetDutyCycle};

/// The lanes' encoder counters: slot 0 on TIM2, slot 1 on TIM3, slot 2 on TIM1.
pub struct LaneEncoders {
    /// Slot 0's encoder.
    slot0: Qei<'static, TIM2>,
    /// Slot 1's encoder.
    slot1: Qei<'static, TIM3>,
    /// Slot 2's encoder.
    slot2: Qei<'static, TIM1>,
}

/// A timer counting every edge of both encoder channels (encoder mode 3: TI1 and TI2, x4), up
/// when channel A leads, over the whole 16 bits (auto-reload 0xFFFF). The inputs are pulled up:
/// an open-drain encoder output needs it, a push-pull one does not mind.
fn encoder<T: embassy_stm32::timer::GeneralInstance4Channel>(
    timer: Peri<'static, T>,
    channel_a: Peri<'static, impl TimerPin<T, Ch1>>,
    channel_b: Peri<'static, impl TimerPin<T, Ch2>>,
) -> Qei<'static, T> {
    let config = QeiConfig {
        mode: QeiMode::Mode3,
        auto_reload: u16::MAX,
        ch1_pull: Pull::Up,
        ch2_pull: Pull::Up,
    };
    Qei::new(timer, channel_a, channel_b, config)
}

/// One lane's encoder: its timer and the pins of channels A and B.
type EncoderParts<T, A, B> = (Peri<'static, T>, Peri<'static, A>, Peri<'static, B>);

impl LaneEncoders {
    /// The three counters, started at 0.
    pub fn new(
        slot0: EncoderParts<TIM2, impl TimerPin<TIM2, Ch1>, impl TimerPin<TIM2, Ch2>>,
        slot1: EncoderParts<TIM3, impl TimerPin<TIM3, Ch1>, impl TimerPin<TIM3, Ch2>>,
        slot2: EncoderParts<TIM1, impl TimerPin<TIM1, Ch1>, impl TimerPin<TIM1, Ch2>>,
    ) -> Self {
        LaneEncoders {
            slot0: encoder(slot0.0, slot0.1, slot0.2),
            slot1: encoder(slot1.0, slot1.1, slot1.2),
            slot2: encoder(slot2.0, slot2.1, slot2.2),
        }
    }

    /// Each lane's count (the timer's CNT, 16 bits, wrapping), in slot order. TIM2's counter is
    /// 32 bits wide, but its auto-reload of 0xFFFF wraps it at 16 bits like the others.
    pub fn counts(&self) -> [u16; 3] {
        [self.slot0.count(), self.slot1.count(), self.slot2.count()]
    }
}

/// A PWM output on channel 1 of a one-channel timer (TIM14, TIM16, TIM17): PWM mode 1, edge
/// aligned, the compare value preloaded (a new duty starts with the next period), duty 0 from
/// the start.
pub struct SingleChannelPwm<T: GeneralInstance1Channel> {
    /// The timer, enabled for as long as this lives.
    timer: Timer<'static, T>,
    /// The output pin, in its alternate function.
    _pin: Flex<'static>,
}

impl<T: GeneralInstance1Channel> SingleChannelPwm<T> {
    /// The timer at `frequency` with duty 0, then the pin switched to the channel's alternate
    /// function `alternate_function` (the datasheet's AF number: embassy-stm32 has no typed pin
    /// for these timers).
    fn start(
        timer: Peri<'static, T>,
        pin: Peri<'static, impl Pin>,
        alternate_function: u8,
        frequency: Hertz,
    ) -> Self {
        let timer = Timer::new(timer);
        timer.set_frequency(frequency, RoundTo::Slower);
        let regs = timer.regs_1ch();
        regs.ccr(0).write(|w| w.set_ccr(0));
        regs.ccmr_output(0).modify(|w| {
            w.set_ocm(0, embassy_stm32::pac::timer::vals::OcmLimited::PWM_MODE1);
            w.set_ocpe(0, true);
        });
        regs.cr1().modify(|w| w.set_arpe(true));
        timer.generate_update_event();
        regs.ccer().modify(|w| w.set_cce(0, true));
        timer.start();
        let mut output = Flex::new(pin);
        output.set_as_af_unchecked(
            alternate_function,
            AfType::output(OutputType::PushPull, Speed::VeryHigh),
        );
        SingleChannelPwm { timer, _pin: output }
    }

    /// TIM14's channel 1 (no break unit).
    pub fn new(
        timer: Peri<'static, T>,
        pin: Peri<'static, impl Pin>,
        alternate_function: u8,
        frequency: Hertz,
    ) -> Self {
        Self::start(timer, pin, alternate_function, frequency)
    }
}

impl<T: AdvancedInstance1Channel> SingleChannelPwm<T> {
    /// TIM16's or TIM17's channel 1: these have a break unit, whose main output enable (MOE)
    /// must be set for the channel to drive its pin.
    pub fn with_break_unit(
        timer: Peri<'static, T>,
        pin: Peri<'static, impl Pin>,
        alternate_function: u8,
        frequency: Hertz,
    ) -> Self {
        let pwm = Self::start(timer, pin, alternate_function, frequency);
        pwm.timer.set_moe(true);
        pwm
    }
}

impl<T: GeneralInstance1Channel> ErrorType for SingleChannelPwm<T> {
    type Error = Infallible;
}

impl<T: GeneralInstance1Channel> SetDutyCycle for SingleChannelPwm<T> {
    /// A period's timer ticks (ARR + 1): 3200 at 20 kHz from 64 MHz.
    fn max_duty_cycle(&self) -> u16 {
        let auto_reload = self.timer.regs_1ch().arr().read().arr();
        auto_reload.saturating_add(1)
    }

    /// Ticks high per period, `duty` above [`Self::max_duty_cycle`] kept high throughout.
    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Infallible> {
        self.timer.regs_1ch().ccr(0).write(|w| w.set_ccr(duty));
        Ok(())
    }
}
