//! The four lanes' AT8236 H-bridges: each has two inputs and no standby pin, both on timer PWM
//! (TIM4 CH3/CH4 lane 0, TIM4 CH1/CH2 lane 1, TIM3 CH1/CH2 lane 2, TIM2 CH1/CH2 lane 3; the
//! BMCU's `Motion_control.cpp` `MC_PWM_init` and `Motion_control_set_PWM`), at 20 kHz.
//!
//! The AT8236's inputs (its datasheet's truth table, as the DRV8871's): IN1 high and IN2 low
//! drive one way, the reverse the other; both high brake (both low-side switches on, the motor
//! shorted); both low coast (outputs open). Driving at a duty PWMs one input with the other low,
//! so the off-time coasts (fast decay). Which way the BMCU's wiring turns the filament for IN1
//! is not published: IN1 is taken as forward, towards the printer (the book says to check it).

use ch32_metapac as pac;
use mmu_hal_port::{Direction, MotorCommand};
use pac::gpio::vals::{Cnf, Mode};
use pac::timer::vals::Ocm;

use super::clock::TIMER_HZ;
use super::{SLOTS, gpio_mode};

/// PWM: 120 MHz / 6000 = 20 kHz, above hearing.
const PERIOD: u16 = 6_000;
const _: () = assert!(TIMER_HZ / PERIOD as u32 == 20_000);

/// A bridge input: its timer and channel (0-3), its port and pin.
struct Input {
    timer: pac::timer::Gptm,
    channel: usize,
    port: pac::gpio::Gpio,
    pin: usize,
}

/// Each lane's IN1 and IN2, in lane order (the pin map's rows).
const INPUTS: [[Input; 2]; SLOTS] = [
    [
        input(pac::TIM4, 2, pac::GPIOB, 8),
        input(pac::TIM4, 3, pac::GPIOB, 9),
    ],
    [
        input(pac::TIM4, 0, pac::GPIOB, 6),
        input(pac::TIM4, 1, pac::GPIOB, 7),
    ],
    [
        input(pac::TIM3, 0, pac::GPIOB, 4),
        input(pac::TIM3, 1, pac::GPIOB, 5),
    ],
    [
        input(pac::TIM2, 0, pac::GPIOA, 15),
        input(pac::TIM2, 1, pac::GPIOB, 3),
    ],
];

const fn input(timer: pac::timer::Gptm, channel: usize, port: pac::gpio::Gpio, pin: usize) -> Input {
    Input {
        timer,
        channel,
        port,
        pin,
    }
}

/// Every bridge input low as a plain GPIO output, by raw register writes (no timer needed):
/// every motor coasts. The inputs are PB3-PB9 and PA15 ([`INPUTS`]): their output latches
/// cleared, then each pin's 4-bit configuration set to 0b0010 (a push-pull output, 2 MHz)
/// in one write a register, whatever the timers were doing with them.
pub fn stop_all() {
    // The ports' clocks first: at boot they are off, and a write to an unclocked port is lost.
    pac::RCC.apb2pcenr().modify(|w| {
        w.set_iopaen(true);
        w.set_iopben(true);
    });
    pac::GPIOB.bshr().write_value(pac::gpio::regs::Bshr(0x3F8 << 16));
    pac::GPIOA
        .bshr()
        .write_value(pac::gpio::regs::Bshr(1 << (15 + 16)));
    pac::GPIOB
        .cfglr()
        .modify(|w| w.0 = (w.0 & 0x0000_0FFF) | 0x2222_2000);
    pac::GPIOB.cfghr().modify(|w| w.0 = (w.0 & !0xFF) | 0x22);
    pac::GPIOA
        .cfghr()
        .modify(|w| w.0 = (w.0 & 0x0FFF_FFFF) | 0x2000_0000);
}

const _: () = {
    // [`stop_all`]'s masks cover exactly the pins of [`INPUTS`].
    let mut b = 0u32;
    let mut a = 0u32;
    let mut lane = 0;
    while lane < SLOTS {
        let mut i = 0;
        while i < 2 {
            let pin = INPUTS[lane][i].pin;
            if pin == 15 {
                a |= 1 << pin;
            } else {
                b |= 1 << pin;
            }
            i += 1;
        }
        lane += 1;
    }
    assert!(b == 0x3F8 && a == 1 << 15);
};

/// The four bridges on their timers.
pub struct Motors;

impl Motors {
    /// Starts TIM2-4 at 20 kHz with every compare at 0 (coast), then hands the pins to them.
    pub fn new() -> Self {
        pac::RCC.apb1pcenr().modify(|w| {
            w.set_tim2en(true);
            w.set_tim3en(true);
            w.set_tim4en(true);
        });
        for timer in [pac::TIM2, pac::TIM3, pac::TIM4] {
            timer.psc().write_value(0);
            timer.atrlr().write_value(PERIOD - 1);
            timer.ctlr1().modify(|w| w.set_arpe(true));
        }
        for input in INPUTS.iter().flatten() {
            input.timer.chcvr(input.channel).write_value(0);
            input.timer.chctlr_output(input.channel / 2).modify(|w| {
                w.set_ocm(input.channel % 2, Ocm::PWMMODE1);
                w.set_ocpe(input.channel % 2, true);
            });
            input.timer.ccer().modify(|w| w.set_cce(input.channel, true));
        }
        for timer in [pac::TIM2, pac::TIM3, pac::TIM4] {
            timer.swevgr().write(|w| w.set_ug(true));
            timer.ctlr1().modify(|w| w.set_cen(true));
        }
        for input in INPUTS.iter().flatten() {
            gpio_mode(
                input.port,
                input.pin,
                Mode::OUTPUT_50MHZ,
                Cnf::PULL_IN__AF_PUSH_PULL_OUT,
            );
        }
        Motors
    }
}

/// IN1's and IN2's compares for `command`: a duty's share of [`PERIOD`] on the driving input;
/// a compare of `PERIOD` holds an input high (brake).
fn compares(command: MotorCommand) -> [u16; 2] {
    match command {
        MotorCommand::Coast => [0, 0],
        MotorCommand::Brake => [PERIOD, PERIOD],
        MotorCommand::Drive { direction, duty } => {
            let on = (u32::from(duty.permille()) * u32::from(PERIOD) / 1000) as u16;
            match direction {
                Direction::Forward => [on, 0],
                Direction::Reverse => [0, on],
            }
        }
    }
}

impl mmu_hal_port::Motors<SLOTS> for Motors {
    fn apply(&mut self, commands: &[MotorCommand; SLOTS]) {
        for (inputs, &command) in INPUTS.iter().zip(commands) {
            for (input, compare) in inputs.iter().zip(compares(command)) {
                input.timer.chcvr(input.channel).write_value(compare);
            }
        }
    }
}
