//! The four lanes' AS5600 angle sensors, each on its own I2C bus (they all answer at 0x36), the
//! four buses clocked together by hand: one transaction reads every sensor. SCL PB15-PB12
//! (lanes 0-3) on one port, so one register write moves every clock; SDA PD0, PC15, PC14, PC13.
//! Both lines open-drain; the sensor boards pull them up.
//!
//! One read per control step: STATUS (0x0B), then RAW ANGLE (0x0C-0x0D), auto-incremented
//! (AS5600 datasheet, I2C interface and register map). A sensor that does not acknowledge, or
//! whose STATUS says no magnet (MD clear) or a magnet too weak (ML) or too strong (MH), reads
//! [`ANGLE_FAULT`]. At 400 kHz (fast mode) the transaction takes about 150 µs of the step.

use ch32_metapac as pac;
use mmu_hal_port::ANGLE_FAULT;
use pac::gpio::vals::{Cnf, Mode};

use super::clock::systick_counts;
use super::{SLOTS, gpio_mode, time_driver};

/// The AS5600's fixed address, shifted for the R/W bit.
const ADDRESS: u8 = 0x36 << 1;
/// STATUS, then RAW ANGLE high and low.
const STATUS: u8 = 0x0B;
/// STATUS: magnet detected, too weak, too strong.
const MD: u8 = 1 << 5;
const ML: u8 = 1 << 4;
const MH: u8 = 1 << 3;
/// Half an SCL period at 400 kHz (fast mode), in SysTick counts.
const HALF_PERIOD: u64 = systick_counts(1_250);

/// Each lane's SCL pin on GPIOB.
const SCL: [usize; SLOTS] = [15, 14, 13, 12];
/// Each lane's SDA: its port and pin.
const SDA: [(pac::gpio::Gpio, usize); SLOTS] = [
    (pac::GPIOD, 0),
    (pac::GPIOC, 15),
    (pac::GPIOC, 14),
    (pac::GPIOC, 13),
];

/// The four buses' lines.
pub struct AngleSensors;

impl AngleSensors {
    /// Both lines of every bus released (high) as open-drain outputs.
    pub fn new() -> Self {
        let buses = AngleSensors;
        buses.release_scl();
        buses.write_sda(0xFF);
        for pin in SCL {
            gpio_mode(
                pac::GPIOB,
                pin,
                Mode::OUTPUT_10MHZ,
                Cnf::FLOATING_IN__OPEN_DRAIN_OUT,
            );
        }
        for (port, pin) in SDA {
            gpio_mode(port, pin, Mode::OUTPUT_10MHZ, Cnf::FLOATING_IN__OPEN_DRAIN_OUT);
        }
        buses
    }

    /// Every lane's raw angle (0-4095), or [`ANGLE_FAULT`].
    pub fn read(&mut self) -> [u16; SLOTS] {
        let mut acked = [true; SLOTS];
        self.start();
        self.write_byte(ADDRESS, &mut acked);
        self.write_byte(STATUS, &mut acked);
        self.start();
        self.write_byte(ADDRESS | 1, &mut acked);
        let status = self.read_byte(true);
        let high = self.read_byte(true);
        let low = self.read_byte(false);
        self.stop();
        core::array::from_fn(|lane| {
            let healthy = status[lane] & (MD | ML | MH) == MD;
            if acked[lane] && healthy {
                (u16::from(high[lane] & 0x0F) << 8) | u16::from(low[lane])
            } else {
                ANGLE_FAULT
            }
        })
    }

    /// A start (or repeated start): SDA falls while SCL is high.
    fn start(&self) {
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
        let sda = read_sda();
        self.pull_scl();
        sda
    }

    fn release_scl(&self) {
        pac::GPIOB
            .bshr()
            .write(|w| SCL.iter().for_each(|&pin| w.set_bs(pin, true)));
    }

    fn pull_scl(&self) {
        pac::GPIOB
            .bcr()
            .write(|w| SCL.iter().for_each(|&pin| w.set_br(pin, true)));
    }

    /// Every bus's SDA: lane `n` released (high) where bit `n` of `levels` is set, else pulled
    /// low.
    fn write_sda(&self, levels: u8) {
        for (lane, (port, pin)) in SDA.iter().enumerate() {
            if levels & (1 << lane) != 0 {
                port.bshr().write(|w| w.set_bs(*pin, true));
            } else {
                port.bcr().write(|w| w.set_br(*pin, true));
            }
        }
    }
}

/// Every bus's SDA level.
fn read_sda() -> [bool; SLOTS] {
    let c = pac::GPIOC.indr().read();
    let d = pac::GPIOD.indr().read();
    SDA.map(|(port, pin)| {
        if port == pac::GPIOD {
            d.idr(pin)
        } else {
            c.idr(pin)
        }
    })
}

/// Half an SCL period.
fn wait() {
    let until = time_driver::counts() + HALF_PERIOD;
    while time_driver::counts() < until {}
}
