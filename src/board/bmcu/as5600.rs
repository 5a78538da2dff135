//! The four lanes' AS5600 angle sensors, each on its own I2C bus (they all answer at 0x36), the
//! four buses clocked together by hand: one transaction reads every sensor. SCL PB15-PB12
//! (lanes 0-3) on one port, push-pull (the AS5600 never stretches the clock), so one register
//! write moves every clock; SDA PD0, PC15, PC14, PC13, open-drain, pulled up on the lane boards.
//! As the BMCU's own firmwares drive them (`many_soft_AS5600.cpp`), at 100 kHz, between their
//! 50 and 125 kHz.
//!
//! A transaction reads STATUS (0x0B), then RAW ANGLE (0x0C-0x0D), auto-incremented (AS5600
//! datasheet, I2C interface and register map). It is clocked a byte per control step (about
//! 0.1 ms of the step), so each lane's angle is new every [`PHASES`] steps; at the filament's
//! full speed that is well under the half turn the odometry can unwrap. A sensor that does not
//! acknowledge, or whose STATUS says no magnet (MD clear), reads [`ANGLE_FAULT`]; a magnet too
//! weak or too strong (ML, MH: the sensor's gain control at its end) still gives its angle, as
//! the BMCU's firmwares take it.
//!
//! The pins of PC13-PC15 move on early CH32V203 dies: WCH's GPIO driver
//! (`ch32v20x_gpio.c`, `GPIO_Init`) uses bits 0-2 of GPIOC for them when the flash controller's
//! word at 0x40022030 reads 0 in bits 27:24; so does [`AngleSensors::new`].

use ch32_metapac as pac;
use mmu_hal_port::ANGLE_FAULT;
use pac::gpio::vals::{Cnf, Mode};

use super::clock::systick_counts;
use super::{SLOTS, gpio_mode, time_driver};

/// The AS5600's fixed address, shifted for the R/W bit.
const ADDRESS: u8 = 0x36 << 1;
/// STATUS, then RAW ANGLE high and low.
const STATUS: u8 = 0x0B;
/// STATUS: magnet detected.
const MD: u8 = 1 << 5;
/// Half an SCL period at 100 kHz, in SysTick counts.
const HALF_PERIOD: u64 = systick_counts(5_000);
/// Steps a transaction takes: address, register, address again, three bytes.
pub const PHASES: u8 = 6;

/// The SCL pins of lanes 0-3, PB15-PB12, as a GPIOB bit mask.
const SCL_MASK: u32 = (1 << 15) | (1 << 14) | (1 << 13) | (1 << 12);

/// The four buses' lines, and the transaction under way.
pub struct AngleSensors {
    /// Lanes 1-3's SDA pins on GPIOC, as bit masks (lane 0's is PD0).
    sda_c: [u32; SLOTS - 1],
    /// The step of the transaction the next [`AngleSensors::advance`] clocks.
    phase: u8,
    acked: [bool; SLOTS],
    status: [u8; SLOTS],
    high: [u8; SLOTS],
    /// Each lane's last angle, or [`ANGLE_FAULT`] (until the first transaction ends).
    latest: [u16; SLOTS],
}

impl AngleSensors {
    /// Both lines of every bus high: SCL push-pull, SDA open-drain.
    pub fn new() -> Self {
        // SAFETY: a read of the flash controller's word WCH's GPIO driver reads for the same
        // purpose; it has no side effect.
        let die = unsafe { core::ptr::read_volatile(0x4002_2030 as *const u32) };
        let shift = if die & 0x0F00_0000 == 0 { 13 } else { 0 };
        let sda_c = [15 - shift, 14 - shift, 13 - shift];
        let buses = AngleSensors {
            sda_c: sda_c.map(|pin| 1 << pin),
            phase: 0,
            acked: [true; SLOTS],
            status: [0; SLOTS],
            high: [0; SLOTS],
            latest: [ANGLE_FAULT; SLOTS],
        };
        buses.release_scl();
        buses.write_sda(0xFF);
        // PB12-PB15: push-pull outputs at 10 MHz (each pin's 4-bit configuration 0b0001).
        pac::GPIOB
            .cfghr()
            .modify(|w| w.0 = (w.0 & 0x0000_FFFF) | 0x1111_0000);
        gpio_mode(
            pac::GPIOD,
            0,
            Mode::OUTPUT_10MHZ,
            Cnf::FLOATING_IN__OPEN_DRAIN_OUT,
        );
        for pin in sda_c {
            gpio_mode(
                pac::GPIOC,
                pin,
                Mode::OUTPUT_10MHZ,
                Cnf::FLOATING_IN__OPEN_DRAIN_OUT,
            );
        }
        buses
    }

    /// Every lane's latest raw angle (0-4095), or [`ANGLE_FAULT`].
    pub fn latest(&self) -> [u16; SLOTS] {
        self.latest
    }

    /// Clocks the next byte of the transaction; the last one ends it and updates
    /// [`AngleSensors::latest`].
    pub fn advance(&mut self) {
        let mut acked = self.acked;
        match self.phase {
            0 => {
                acked = [true; SLOTS];
                self.start();
                self.write_byte(ADDRESS, &mut acked);
            }
            1 => self.write_byte(STATUS, &mut acked),
            2 => {
                self.start();
                self.write_byte(ADDRESS | 1, &mut acked);
            }
            3 => self.status = self.read_byte(true),
            4 => self.high = self.read_byte(true),
            _ => {
                let low = self.read_byte(false);
                self.stop();
                self.latest = core::array::from_fn(|lane| {
                    if acked[lane] && self.status[lane] & MD != 0 {
                        (u16::from(self.high[lane] & 0x0F) << 8) | u16::from(low[lane])
                    } else {
                        ANGLE_FAULT
                    }
                });
            }
        }
        self.acked = acked;
        self.phase = (self.phase + 1) % PHASES;
    }

    /// A start (or repeated start): SDA falls while SCL is high.
    fn start(&self) {
        wait();
        self.write_sda(0xFF);
        self.release_scl();
        wait();
        self.write_sda(0);
        wait();
        self.pull_scl();
    }

    /// A stop: SDA rises while SCL is high.
    fn stop(&self) {
        self.write_sda(0);
        wait();
        self.release_scl();
        wait();
        self.write_sda(0xFF);
        wait();
    }

    /// `byte` to every bus, most significant bit first; a bus that does not acknowledge clears
    /// its `acked`.
    fn write_byte(&self, byte: u8, acked: &mut [bool; SLOTS]) {
        for bit in (0..8).rev() {
            self.write_sda(if byte & (1 << bit) != 0 { 0xFF } else { 0 });
            self.clock_pulse();
        }
        self.write_sda(0xFF);
        let ack = self.clock_pulse();
        for (lane, acked) in acked.iter_mut().enumerate() {
            *acked &= !ack[lane];
        }
    }

    /// A byte from every bus; `ack` acknowledges it (more to come), else not (the last).
    fn read_byte(&self, ack: bool) -> [u8; SLOTS] {
        let mut bytes = [0u8; SLOTS];
        self.write_sda(0xFF);
        for _ in 0..8 {
            let bits = self.clock_pulse();
            for (byte, bit) in bytes.iter_mut().zip(bits) {
                *byte = (*byte << 1) | u8::from(bit);
            }
        }
        self.write_sda(if ack { 0 } else { 0xFF });
        self.clock_pulse();
        bytes
    }

    /// One SCL pulse; every bus's SDA as sampled while SCL is high.
    fn clock_pulse(&self) -> [bool; SLOTS] {
        wait();
        self.release_scl();
        wait();
        let sda = self.read_sda();
        self.pull_scl();
        sda
    }

    fn release_scl(&self) {
        pac::GPIOB.bshr().write_value(pac::gpio::regs::Bshr(SCL_MASK));
    }

    fn pull_scl(&self) {
        pac::GPIOB
            .bshr()
            .write_value(pac::gpio::regs::Bshr(SCL_MASK << 16));
    }

    /// Every bus's SDA: lane `n` released (high) where bit `n` of `levels` is set, else pulled
    /// low. One BSHR write a port: its low half sets pins, its high half resets them.
    fn write_sda(&self, levels: u8) {
        let set_or_reset = |high: bool, mask: u32| if high { mask } else { mask << 16 };
        let d = set_or_reset(levels & 1 != 0, 1);
        let c = (1..SLOTS).fold(0, |c, lane| {
            c | set_or_reset(levels & (1 << lane) != 0, self.sda_c[lane - 1])
        });
        pac::GPIOD.bshr().write_value(pac::gpio::regs::Bshr(d));
        pac::GPIOC.bshr().write_value(pac::gpio::regs::Bshr(c));
    }

    /// Every bus's SDA level.
    fn read_sda(&self) -> [bool; SLOTS] {
        let c = pac::GPIOC.indr().read().0;
        let d = pac::GPIOD.indr().read().0;
        [
            d & 1 != 0,
            c & self.sda_c[0] != 0,
            c & self.sda_c[1] != 0,
            c & self.sda_c[2] != 0,
        ]
    }
}

/// Half an SCL period.
fn wait() {
    time_driver::spin_until(time_driver::counts() + HALF_PERIOD);
}
