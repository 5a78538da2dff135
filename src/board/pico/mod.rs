//! The second board: a Raspberry Pi Pico (RP2040, Cortex-M0+ at 125 MHz, 3.3 V) driving two
//! TB6612FNG dual H-bridges on its PWM slices, nine analog Hall sensors through a 16:1 analog
//! multiplexer (CD74HC4067) on one ADC input, and the printer's MMU port on UART0, on embassy-rp's
//! drivers: the ADC, PWM, UART0 (sent by DMA; received by a DMA ring, `uart_ring`), the blocking
//! flash driver under the store (the last 16 sectors of the 2 MiB QSPI flash), the watchdog, and
//! embassy-time's driver on the TIMER.
//!
//! The `pin_map!` table below is the single source of truth for pins: the book's wiring table
//! mirrors it (`scripts/check-pinmap.sh`) and the emergency stop derives its pins from it.
//!
//! The sensor scan: the RP2040 has four ADC inputs, the unit nine sensors. The multiplexer's
//! four select lines pick one sensor at a time onto ADC0, in Gray-code order ([`MUX_CHANNEL`]:
//! one select line changes per step, so no intermediate channel is ever selected in passing), at
//! the start of each control tick, before the step. Per sensor: the select lines, then one
//! embassy-rp `Adc::read_many` of [`CONVERSIONS`] free-running conversions (2 µs each at 48 MHz)
//! that the ADC's FIFO hands to a DMA channel (DMA_CH3): the first [`SETTLE_CONVERSIONS`] are
//! discarded and are the settling time (the first kept one samples [`SETTLE_US`] after the
//! select lines changed, at the earliest), the last [`OVERSAMPLE`] are averaged. The CPU sleeps
//! during the conversions and is woken once per sensor by the DMA's completion interrupt, which
//! also stops the ADC ([`StopConversions`]). A conversion error anywhere in a sensor's free run
//! (the settling conversions included) fails the scan: `read_many` reports the ADC's sticky
//! error flag.
//!
//! Settling, reasoned (not measured on hardware): the CD74HC4067's on-resistance at 3.3 V is a
//! few hundred ohms and its common output about 50-90 pF, with a Hall sensor's output of a few
//! hundred ohms a time constant well under 0.1 µs; 12-bit settling needs about 9 of them, so
//! 10 µs leaves two orders of magnitude for cabling and the ADC's input.

mod uart_ring;

use core::ops::Range;

use embassy_rp::adc::{self, Adc};
use embassy_rp::flash::{Blocking, Flash};
use embassy_rp::gpio::{Input, Level, Output, Pull};
use embassy_rp::interrupt::typelevel::Handler;
use embassy_rp::peripherals::{self, FLASH, UART0};
use embassy_rp::pwm::{self, Pwm, PwmError, PwmOutput};
use embassy_rp::uart::{self, Uart, UartTx};
use embassy_rp::watchdog::Watchdog as RpWatchdog;
use embassy_rp::{Peri, bind_interrupts, dma, interrupt, pac};
use embassy_time::{Duration, Timer};
use embedded_hal::pwm::{ErrorType, SetDutyCycle};
use mmu_firmware::persist::SoftwareCrc;
use mmu_hal_port::tb6612::Tb6612;
use mmu_hal_port::{HubSamples, Samples, SensorScan, SlotSamples};

use super::Bridges;
pub use uart_ring::{PicoRing, RingRx};

/// The board, as the boot log names it.
pub const NAME: &str = "Raspberry Pi Pico";
/// The thesis build's sensors: an analog Hall per motor, the hub's sensors.
pub const PROFILE: mmu_firmware::profile::Profile = mmu_firmware::profile::THESIS;
/// Filament slots on this board.
pub const SLOTS: usize = 3;
/// The Pico's QSPI flash: 2 MiB.
const FLASH_SIZE: usize = 2 * 1024 * 1024;
/// The persisted state's region, as offsets from the flash base (0x1000_0000): the last 16
/// sectors (4 KiB each), 0x1F_0000..0x20_0000. src/board/pico/memory.x ends FLASH before it.
pub const STORE_RANGE: Range<u32> = 0x1F_0000..0x20_0000;
/// The board has a button.
pub const HAS_BUTTON: bool = true;
/// Watchdog timeout. Longer than on the G071: a 4 KiB sector erase runs with interrupts off for
/// up to 400 ms (W25Q16JV), and nothing can feed the watchdog meanwhile.
pub const WATCHDOG_TIMEOUT: Duration = Duration::from_millis(600);
/// The printer line's rate, 8N1.
const BAUD: u32 = 115_200;
/// PWM: 125 MHz / (6249 + 1) = 20 kHz, above hearing, below the TB6612FNG's 100 kHz.
const PWM_TOP: u16 = 6_249;
/// One conversion of the free-running ADC, µs: 96 cycles of its 48 MHz clock (divider 0).
const CONVERSION_US: u32 = 2;
/// The ADC clock divider for back-to-back conversions (any value below 96 is the same).
const FREE_RUNNING: u16 = 0;
/// Conversions discarded per sensor while the multiplexer settles (see the module header).
const SETTLE_CONVERSIONS: usize = 5;
/// The multiplexer's settling time after its select lines change, µs: the discarded
/// conversions' time, at least the 10 µs the module header reasons.
const SETTLE_US: u32 = SETTLE_CONVERSIONS as u32 * CONVERSION_US;
const _: () = assert!(SETTLE_US >= 10);
/// Conversions averaged per sensor.
const OVERSAMPLE: usize = 4;
/// Conversions per sensor: one DMA transfer.
const CONVERSIONS: usize = SETTLE_CONVERSIONS + OVERSAMPLE;
/// Sensors: two per slot and three on the hub (as on the G071).
const ANALOG_INPUTS: usize = 2 * SLOTS + 3;
/// The first hub input.
const HUB_INPUTS: usize = 2 * SLOTS;
/// The multiplexer channel (C0..C15) wired to each sensor, in scan order: the Gray code of the
/// sensor's index, so consecutive sensors differ in one select line.
const MUX_CHANNEL: [u8; ANALOG_INPUTS] = {
    let mut channels = [0u8; ANALOG_INPUTS];
    let mut i = 0;
    while i < ANALOG_INPUTS {
        channels[i] = (i ^ (i >> 1)) as u8;
        i += 1;
    }
    channels
};

bind_interrupts!(struct Irqs {
    ADC_IRQ_FIFO => adc::InterruptHandler;
    UART0_IRQ => uart::InterruptHandler<UART0>;
    DMA_IRQ_0 => dma::InterruptHandler<peripherals::DMA_CH0>, dma::InterruptHandler<peripherals::DMA_CH1>,
        dma::InterruptHandler<peripherals::DMA_CH3>, StopConversions;
});

/// The sensor scan's DMA channel (`Parts::sensor_dma`), for [`StopConversions`].
const SENSOR_DMA: usize = 3;

/// Stops the ADC's free run when a sensor's transfer is done, in the DMA completion interrupt,
/// rather than when the woken task gets to `read_many`'s drop guard: the one place this board
/// writes the ADC outside embassy-rp's driver.
///
/// `read_many` stops the ADC only once its task is woken (it clears CS.START_MANY, then polls
/// CS.READY until the conversion under way ends, up to 2 µs); by then the ADC has started more
/// conversions nobody keeps, and the task polls for the one under way at every sensor. Cleared
/// here, START_MANY lets the conversion under way end and starts no other
/// while the task wakes, so the guard mostly finds READY set. The channel idle is the condition
/// (not its interrupt flag, which `dma::InterruptHandler` clears: the order of the handlers does
/// not matter): while a transfer runs it is busy, and `read_many` arms it before it sets
/// START_MANY; otherwise the ADC is stopped already, or running on after a transfer, or the
/// interrupt is another channel's. `read_many`'s guard clears START_MANY again (harmless) and
/// still waits for READY; its error check (CS.ERR_STICKY) and its drain of the FIFO at the next
/// sensor are unchanged.
struct StopConversions;

impl Handler<interrupt::typelevel::DMA_IRQ_0> for StopConversions {
    unsafe fn on_interrupt() {
        if !pac::DMA.ch(SENSOR_DMA).ctrl_trig().read().busy() {
            let mut stop = pac::adc::regs::Cs(0);
            stop.set_start_many(true);
            // SAFETY: CS's atomic bit-clear alias (RP2040 datasheet 2.1.2: the register's
            // address + 0x3000), the write `read_many`'s guard makes: it clears START_MANY only,
            // never the write-1-to-clear ERR_STICKY that a read-modify-write would.
            unsafe {
                pac::ADC
                    .cs()
                    .as_ptr()
                    .cast::<u8>()
                    .add(ATOMIC_CLEAR)
                    .cast::<pac::adc::regs::Cs>()
                    .write_volatile(stop)
            };
        }
    }
}

/// The offset of a peripheral register's atomic bit-clear alias (RP2040 datasheet 2.1.2).
const ATOMIC_CLEAR: usize = 0x3000;

// ================================ PIN MAP (single source of truth) ================================
//
// TB6612 #1 drives slots 0 (bridge A) and 1 (bridge B), its PWM inputs on PWM slice 3 (A and B);
// TB6612 #2 drives slot 2 (bridge A, PWM slice 4 A; bridge B unused). "Pico pin" is the board's
// physical pin number. Logic levels: the RP2040 is a 3.3 V part and NO pin is 5 V tolerant: a
// 5 V printer port needs a level shifter on the unit's RX (GP1; the book's wiring page). The
// ADC input (GP26) takes at most 3.3 V: power the Hall sensors and the multiplexer from 3V3(OUT).
pin_map! {
    hal embassy_rp;
    stop u32 = gpio_mask;
    peripherals {
        adc: ADC, "The ADC: ADC0 (GP26) behind the multiplexer";
        printer_uart: UART0, "Printer MMU port, 115200 8N1";
        printer_tx_dma: DMA_CH0, "The printer UART's transmit DMA";
        printer_rx_dma: DMA_CH1, "embassy-rp's receive DMA channel (unused: uart_ring's is DMA_CH2)";
        printer_ring_dma: DMA_CH2, "The printer UART's receive ring";
        sensor_dma: DMA_CH3, "The sensor scan: ADC0's FIFO into RAM (Adc::read_many)";
        pwm_chip1: PWM_SLICE3, "Motor PWM of TB6612 #1, 20 kHz";
        pwm_chip2: PWM_SLICE4, "Motor PWM of TB6612 #2, 20 kHz";
        watchdog: WATCHDOG, "The watchdog, fed by the control task";
        flash: FLASH, "The QSPI flash: the persisted state in its last 16 sectors (STORE_RANGE)";
    }
    pins {
        // field         pin      function       Pico pin   wired to                                   safe
        printer_tx:      PIN_0,  "UART0 TX",    "pin 1",   "printer MMU port RX (3.3 V push-pull)",   -;
        printer_rx:      PIN_1,  "UART0 RX",    "pin 2",   "printer MMU port TX (via the level shifter)", -;
        mux_s0:          PIN_2,  "GPIO out",    "pin 4",   "CD74HC4067 S0",                           -;
        mux_s1:          PIN_3,  "GPIO out",    "pin 5",   "CD74HC4067 S1",                           -;
        mux_s2:          PIN_4,  "GPIO out",    "pin 6",   "CD74HC4067 S2",                           -;
        mux_s3:          PIN_5,  "GPIO out",    "pin 7",   "CD74HC4067 S3",                           -;
        slot0_pwm:       PIN_6,  "PWM3 A",      "pin 9",   "TB6612 #1 PWMA (10k pull-down to GND)",   off;
        slot1_pwm:       PIN_7,  "PWM3 B",      "pin 10",  "TB6612 #1 PWMB (10k pull-down to GND)",   off;
        slot2_pwm:       PIN_8,  "PWM4 A",      "pin 11",  "TB6612 #2 PWMA (10k pull-down to GND)",   off;
        slot0_in1:       PIN_9,  "GPIO out",    "pin 12",  "TB6612 #1 AIN1",                          off;
        slot0_in2:       PIN_10, "GPIO out",    "pin 14",  "TB6612 #1 AIN2",                          off;
        slot1_in1:       PIN_11, "GPIO out",    "pin 15",  "TB6612 #1 BIN1",                          off;
        slot1_in2:       PIN_12, "GPIO out",    "pin 16",  "TB6612 #1 BIN2",                          off;
        stby1:           PIN_13, "GPIO out",    "pin 17",  "TB6612 #1 STBY (10k pull-down to GND)",   stby;
        slot2_in1:       PIN_14, "GPIO out",    "pin 19",  "TB6612 #2 AIN1",                          off;
        slot2_in2:       PIN_15, "GPIO out",    "pin 20",  "TB6612 #2 AIN2",                          off;
        stby2:           PIN_16, "GPIO out",    "pin 21",  "TB6612 #2 STBY (10k pull-down to GND)",   stby;
        button:          PIN_17, "GPIO in",     "pin 22",  "push button to GND, active low: Middle",  -;
        status_led:      PIN_25, "GPIO out",    "on board", "the Pico's green LED",                   -;
        mux_sig:         PIN_26, "ADC0",        "pin 31",  "CD74HC4067 SIG (common)",                 -;
    }
}
// ==================================================================================================

/// The SIO bit of `PIN_n`; a name that is not a pin fails the build.
const fn gpio_bit(name: &str) -> u32 {
    let name = name.as_bytes();
    assert!(name.len() > 4 && name[0] == b'P' && name[3] == b'_');
    let mut pin = 0u32;
    let mut digit = 4;
    while digit < name.len() {
        assert!(name[digit].is_ascii_digit());
        pin = pin * 10 + (name[digit] - b'0') as u32;
        digit += 1;
    }
    assert!(pin < 30);
    1 << pin
}

/// The mask of the pins named (`"PIN_6"`), for [`pin_map!`].
const fn gpio_mask(names: &[Option<&str>]) -> u32 {
    let mut mask = 0;
    let mut i = 0;
    while i < names.len() {
        if let Some(name) = names[i] {
            mask |= gpio_bit(name);
        }
        i += 1;
    }
    mask
}

/// Drives the pins of `mask` low as SIO outputs through raw register writes: IO_BANK0 and
/// PADS_BANK0 out of reset (they may still be held there at boot), the output latches low
/// (SIO GPIO_OUT_CLR), output enabled (GPIO_OE_SET), then each pin's function SIO (IO_BANK0
/// GPIOn_CTRL.FUNCSEL = 5), which takes it from its PWM or GPIO driver; the pads' reset value
/// already allows output (RP2040 datasheet, 2.19 GPIO and 2.14 Subsystem resets).
fn force_low(mask: u32) {
    pac::RESETS.reset().modify(|w| {
        w.set_io_bank0(false);
        w.set_pads_bank0(false);
    });
    while !(pac::RESETS.reset_done().read().io_bank0() && pac::RESETS.reset_done().read().pads_bank0()) {}
    pac::SIO.gpio_out(0).value_clr().write_value(mask);
    pac::SIO.gpio_oe(0).value_set().write_value(mask);
    for pin in 0..30 {
        if mask & (1 << pin) != 0 {
            pac::IO_BANK0
                .gpio(pin)
                .ctrl()
                .write(|w| w.set_funcsel(pac::io::vals::Gpio0ctrlFuncsel::SIO_0 as u8));
        }
    }
}

/// Turns every motor bridge off at once, without the HAL: both TB6612 STBY pins low (outputs
/// high impedance), then every PWM and IN pin low (duty 0, coast). Called first thing at boot
/// and from the HardFault handler (panics end there). The pins float while the RP2040 is held in
/// reset (with the pads' default pull-downs once it runs), so STBY and PWM need external
/// pull-downs to keep the bridges off then.
pub fn emergency_stop() {
    force_low(STOP_STBY);
    force_low(STOP_OFF);
}

/// Why the RP2040 last started, as its watchdog tells (WATCHDOG_REASON).
#[derive(Debug, Clone, Copy, PartialEq, Eq, defmt::Format)]
pub enum ResetCause {
    /// The watchdog expired: the control task stalled.
    Watchdog,
    /// A forced reset through the watchdog.
    Forced,
    /// Power-on, the RUN pin, or a software reset (`SCB::sys_reset`: `X0`/`X42`, a fault).
    Other,
}

/// Why the RP2040 last started.
pub fn reset_cause() -> ResetCause {
    let reason = pac::WATCHDOG.reason().read();
    if reason.timer() {
        ResetCause::Watchdog
    } else if reason.force() {
        ResetCause::Forced
    } else {
        ResetCause::Other
    }
}

/// Stops every motor and restarts the MCU.
pub fn reset() -> ! {
    emergency_stop();
    cortex_m::peripheral::SCB::sys_reset()
}

/// The board's flash for the store: 4 KiB sectors, byte writes (the driver pads to 256-byte
/// pages). A write or erase runs from RAM with interrupts off; the UART's DMA ring keeps
/// receiving meanwhile.
pub type StoreFlash = Flash<'static, FLASH, Blocking, FLASH_SIZE>;
/// The RP2040 has no CRC unit the store could use: the software CRC.
pub type Crc = SoftwareCrc;
/// TB6612 #2's bridge B has no PWM pin.
pub struct UnusedPwm;

impl ErrorType for UnusedPwm {
    type Error = PwmError;
}

impl SetDutyCycle for UnusedPwm {
    fn max_duty_cycle(&self) -> u16 {
        1
    }

    fn set_duty_cycle(&mut self, _duty: u16) -> Result<(), PwmError> {
        Ok(())
    }
}

/// The slot motors.
pub type Motors = Bridges<
    Tb6612<
        PwmOutput<'static>,
        Output<'static>,
        Output<'static>,
        PwmOutput<'static>,
        Output<'static>,
        Output<'static>,
        Output<'static>,
    >,
    Tb6612<
        PwmOutput<'static>,
        Output<'static>,
        Output<'static>,
        UnusedPwm,
        super::NotConnected,
        super::NotConnected,
        Output<'static>,
    >,
>;
/// The printer UART's receive side.
pub type LinkRx = RingRx;
/// The on-board LED.
pub type Led = Output<'static>;
/// The unit's button.
pub type ButtonPin = Input<'static>;

/// The printer UART's transmit side: embassy-rp's DMA transmit, as embedded-io-async.
pub struct LinkTx(UartTx<'static, uart::Async>);

impl embedded_io_async::ErrorType for LinkTx {
    type Error = uart::Error;
}

impl embedded_io_async::Write for LinkTx {
    async fn write(&mut self, bytes: &[u8]) -> Result<usize, uart::Error> {
        self.0.write(bytes).await?;
        Ok(bytes.len())
    }

    /// Until the last byte has left the shift register.
    async fn flush(&mut self) -> Result<(), uart::Error> {
        while self.0.busy() {
            Timer::after_micros(100).await;
        }
        Ok(())
    }
}

/// The watchdog, as the hal-port trait.
pub struct Watchdog(RpWatchdog);

impl mmu_hal_port::Watchdog for Watchdog {
    fn feed(&mut self) {
        self.0.feed(WATCHDOG_TIMEOUT);
    }
}

/// The sensors through the multiplexer on ADC0.
pub struct Sampler {
    adc: Adc<'static, adc::Async>,
    input: adc::Channel<'static>,
    /// Moves the ADC's FIFO into a sensor's conversions.
    dma: dma::Channel<'static>,
    select: [Output<'static>; 4],
    /// The channel the select lines pick now (all low at start: C0).
    selected: u8,
    /// A sensor's conversions, as the DMA writes them (every one, at each read): kept here
    /// rather than zeroed on the stack at every sensor.
    conversions: [u16; CONVERSIONS],
}

impl Sampler {
    /// Selects multiplexer channel `channel` (S0 = bit 0 .. S3 = bit 3), writing only the lines
    /// that change: one a sensor in the Gray-code scan order, two from the last sensor to the
    /// first.
    fn select(&mut self, channel: u8) {
        let changed = self.selected ^ channel;
        for (bit, line) in self.select.iter_mut().enumerate() {
            if changed & (1 << bit) != 0 {
                line.set_level(Level::from(channel & (1 << bit) != 0));
            }
        }
        self.selected = channel;
    }

    /// One sensor: select, then [`CONVERSIONS`] free-running conversions by DMA, the first
    /// [`SETTLE_CONVERSIONS`] discarded (the multiplexer settling), the last [`OVERSAMPLE`]
    /// averaged.
    ///
    /// What embassy-rp 0.10's `read_many` does around the transfer, relied on here: it stops
    /// the ADC only once woken after the DMA's last transfer (clears START_MANY, then busy-waits
    /// for the conversion under way, at most 2 µs), which [`StopConversions`] does sooner, in
    /// the DMA's completion interrupt, so that the wait finds the ADC stopped; the conversion
    /// that ends after the DMA's last transfer (the one under way when START_MANY is cleared;
    /// without the interrupt's stop, every one that ended until the wake-up: the FIFO keeps four
    /// and sets FCS.OVER, which nothing reads or clears) stays in the FIFO; its next call drains
    /// it (it waits for READY and reads the FIFO until empty) before it arms the DMA, so it never
    /// reaches a kept conversion (the last sensor's waits in the FIFO for the next scan). Its
    /// error check reads CS.ERR_STICKY, cleared at its start: a failed conversion anywhere in the
    /// free run, the discarded ones and the one after the DMA's last transfer included, fails
    /// the sensor.
    async fn read(&mut self, channel: u8) -> Result<u16, adc::Error> {
        self.select(channel);
        self.adc
            .read_many(
                &mut self.input,
                &mut self.conversions,
                FREE_RUNNING,
                &mut self.dma,
            )
            .await?;
        let sum: u32 = self
            .conversions
            .iter()
            .skip(SETTLE_CONVERSIONS)
            .map(|&conversion| u32::from(conversion))
            .sum();
        Ok((sum / OVERSAMPLE as u32) as u16)
    }
}

impl SensorScan<SLOTS> for Sampler {
    type Error = adc::Error;

    /// Every sensor in scan order (see the module header); a failed conversion fails the scan
    /// (the control task then keeps the previous samples).
    async fn scan(&mut self) -> Result<Samples<SLOTS>, adc::Error> {
        let mut raw = [0u16; ANALOG_INPUTS];
        for (value, &channel) in raw.iter_mut().zip(&MUX_CHANNEL) {
            *value = self.read(channel).await?;
        }
        Ok(Samples {
            slots: core::array::from_fn(|slot| SlotSamples {
                motion: raw.get(2 * slot).copied().unwrap_or_default(),
                filament: raw.get(2 * slot + 1).copied().unwrap_or_default(),
                tension: 0,
            }),
            hub: HubSamples {
                filament: raw[HUB_INPUTS],
                tension: raw[HUB_INPUTS + 1],
                cutter: raw[HUB_INPUTS + 2],
            },
        })
    }
}

/// A GPIO output, low from the start.
fn low(pin: Peri<'static, impl embassy_rp::gpio::Pin>) -> Output<'static> {
    Output::new(pin, Level::Low)
}

board_contract!(Pico);

/// Starts the clocks (125 MHz) and every peripheral of the board. The watchdog first; the
/// bridges come up in standby with both inputs low and duty 0.
fn init() -> super::Parts<Pico> {
    let parts = Parts::take(embassy_rp::init(Default::default()));

    let mut watchdog = RpWatchdog::new(parts.watchdog);
    watchdog.start(WATCHDOG_TIMEOUT);

    let mut pwm_config = pwm::Config::default();
    pwm_config.top = PWM_TOP;
    pwm_config.compare_a = 0;
    pwm_config.compare_b = 0;
    let (pwm_a, pwm_b) = Pwm::new_output_ab(
        parts.pwm_chip1,
        parts.slot0_pwm,
        parts.slot1_pwm,
        pwm_config.clone(),
    )
    .split();
    let (pwm_c, _) = Pwm::new_output_a(parts.pwm_chip2, parts.slot2_pwm, pwm_config).split();
    let (Some(pwm_a), Some(pwm_b), Some(pwm_c)) = (pwm_a, pwm_b, pwm_c) else {
        defmt::panic!("PWM outputs");
    };
    let chip1 = Tb6612::new(
        pwm_a,
        low(parts.slot0_in1),
        low(parts.slot0_in2),
        pwm_b,
        low(parts.slot1_in1),
        low(parts.slot1_in2),
        low(parts.stby1),
    );
    let chip2 = Tb6612::new(
        pwm_c,
        low(parts.slot2_in1),
        low(parts.slot2_in2),
        UnusedPwm,
        super::NotConnected,
        super::NotConnected,
        low(parts.stby2),
    );
    let (Ok(chip1), Ok(chip2)) = (chip1, chip2) else {
        defmt::panic!("TB6612 set-up");
    };

    let mut uart_config = uart::Config::default();
    uart_config.baudrate = BAUD;
    let uart = Uart::new(
        parts.printer_uart,
        parts.printer_tx,
        parts.printer_rx,
        Irqs,
        parts.printer_tx_dma,
        parts.printer_rx_dma,
        uart_config,
    );
    let (link_tx, rx) = uart.split();
    let link_rx = PicoRing::start(rx, parts.printer_ring_dma);

    let sampler = Sampler {
        adc: Adc::new(parts.adc, Irqs, adc::Config::default()),
        input: adc::Channel::new_pin(parts.mux_sig, Pull::None),
        dma: dma::Channel::new(parts.sensor_dma, Irqs),
        select: [
            low(parts.mux_s0),
            low(parts.mux_s1),
            low(parts.mux_s2),
            low(parts.mux_s3),
        ],
        selected: 0,
        conversions: [0; CONVERSIONS],
    };

    super::Parts {
        sampler,
        motors: Bridges::new(chip1, chip2),
        link_rx,
        link_tx: LinkTx(link_tx),
        led: low(parts.status_led),
        button: Input::new(parts.button, Pull::Up),
        watchdog: Watchdog(watchdog),
        flash: Flash::new_blocking(parts.flash),
        crc: SoftwareCrc::default(),
    }
}
