//! The firmware: an Embassy application that runs the unit logic ([`mmu_firmware::App`], inside
//! [`ControlLoop`]) on a board, with the same code the host tests and the simulator step.
//!
//! One `main` for every board. The board is a module selected by feature (`src/board/g071/` for
//! the NUCLEO-G071RB, `src/board/pico/` for the Raspberry Pi Pico, `src/board/bmcu/` for the
//! BMCU-C's CH32V203), seen only through its
//! `board::Board` contract: it starts the clocks and the HAL's drivers and hands over parts that
//! implement the hal-port traits ([`SensorScan`],
//! [`Motors`], [`Watchdog`]), the printer link (a DMA receive ring and an embedded-io-async
//! `Write`) and a NOR flash for the store. The tasks below are written against those traits only; each `#[task]` is a thin
//! non-generic wrapper (Embassy tasks cannot be generic) naming the board's types.
//!
//! The tasks' bodies are `mmu_firmware::tasks` (control, store, link_tx, button, status_led, and
//! what they say to each other through embassy-sync), in the library, beside the control step
//! they run.
//!
//! Safety: the board's `emergency_stop` (every bridge off through raw register writes) runs
//! first at boot and in the fault handler, which then resets the MCU at once (it does not wait
//! for a watchdog that may not be running yet). On the Cortex-M boards a panic goes through
//! panic-probe: it logs the message over defmt and raises a HardFault (`udf`), so the same
//! handler stops the motors and resets (with a probe attached, probe-rs stops there and prints
//! the backtrace instead). On the BMCU-C (no defmt: it does not fit) the panic handler and
//! qingke-rt's exception handler stop the motors and reset. The watchdog starts in the board's
//! `init`, right after the clocks; only the control task feeds it, and the store's flash only
//! within an allowance (`mmu_firmware::port::WatchedFlash`).

#![no_std]
#![no_main]

#[cfg(not(any(feature = "g071", feature = "g071-n20", feature = "pico", feature = "bmcu")))]
compile_error!(
    "choose a board: `cargo fw` (--features g071), `cargo fw-n20` (--features g071-n20), `cargo fw-pico` (--features pico) or `cargo fw-bmcu` (--features bmcu)"
);
#[cfg(any(
    all(feature = "_stm32g071", feature = "pico"),
    all(feature = "_stm32g071", feature = "bmcu"),
    all(feature = "pico", feature = "bmcu")
))]
compile_error!("the features g071 (or g071-n20), pico and bmcu are three boards: build one at a time");
#[cfg(all(feature = "g071", feature = "g071-n20"))]
compile_error!("the features g071 and g071-n20 are two builds of one board: build one at a time");

mod board;

// Logs: defmt over RTT on the Cortex-M boards. The BMCU-C has none (defmt does not fit its flash,
// and its one free UART is the printer's): `info!` says nothing there, and a setup-time
// `unwrap!` that fails panics, which stops the motors and resets.
#[cfg(feature = "_cortex_m")]
use {
    defmt::{info, unwrap},
    defmt_rtt as _, panic_probe as _,
};

#[cfg(feature = "bmcu")]
macro_rules! info {
    ($format:literal, $($arg:expr),* $(,)?) => {{
        $( let _ = $arg; )*
    }};
}

#[cfg(feature = "bmcu")]
macro_rules! unwrap {
    ($e:expr) => {
        $e.unwrap()
    };
}

use core::cell::RefCell;

use embassy_executor::Spawner;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use mmu_firmware::control::ControlLoop;
use mmu_firmware::tasks::{self, Logic};
use mmu_firmware::{App, Config};
use mmu_hal_port::Watchdog as _;
use static_cell::StaticCell;

use board::{Board, SLOTS, ThisBoard};

/// The board's parts, by role.
type Sampler = <ThisBoard as Board>::Sampler;
type Motors = <ThisBoard as Board>::Motors;
type LinkRx = <ThisBoard as Board>::LinkRx;
type LinkTx = <ThisBoard as Board>::LinkTx;
type ButtonPin = <ThisBoard as Board>::ButtonPin;
type Led = <ThisBoard as Board>::Led;
type StoreFlash = <ThisBoard as Board>::StoreFlash;
type Crc = <ThisBoard as Board>::Crc;
type Watchdog = <ThisBoard as Board>::Watchdog;

/// The watchdog, once the board's `init` started it.
static WATCHDOG: Mutex<CriticalSectionRawMutex, RefCell<Option<Watchdog>>> = Mutex::new(RefCell::new(None));

#[cfg(feature = "_cortex_m")]
#[embassy_executor::main]
async fn main(spawner: Spawner) {
    start(spawner);
}

/// qingke-rt's entry: the spinning executor (see Cargo.toml), in a static.
#[cfg(feature = "bmcu")]
#[qingke_rt::entry]
fn main() -> ! {
    static EXECUTOR: StaticCell<embassy_executor::Executor> = StaticCell::new();
    EXECUTOR.init(embassy_executor::Executor::new()).run(start)
}

/// Stops the motors, starts the board and spawns the tasks.
fn start(spawner: Spawner) {
    // Before anything else: every bridge off, whatever state a reset left the pins in.
    ThisBoard::emergency_stop();
    info!(
        "mmu-firmware {=str} on {=str} ({=str} lanes) starting, reset cause: {}",
        env!("CARGO_PKG_VERSION"),
        ThisBoard::NAME,
        ThisBoard::PROFILE.name,
        ThisBoard::reset_cause()
    );
    let parts = ThisBoard::init();
    WATCHDOG.lock(|watchdog| watchdog.replace(Some(parts.watchdog)));

    let logic: &'static Logic<SLOTS> = new_logic();

    // The store task restores the logic's state first; the control task waits for it.
    spawner.spawn(unwrap!(store(parts.flash, parts.crc, logic)));
    spawner.spawn(unwrap!(control(
        parts.sampler,
        parts.motors,
        parts.link_rx,
        logic
    )));
    spawner.spawn(unwrap!(link_tx(parts.link_tx)));
    if ThisBoard::HAS_BUTTON {
        spawner.spawn(unwrap!(button(parts.button)));
    }
    spawner.spawn(unwrap!(status_led(parts.led)));
}

/// The board's hardware profile, fixed at build time for the logic (feature `fixed-profile`,
/// `mmu_firmware::unit::Unit::profile`): the compiler drops every other profile's code.
#[unsafe(export_name = "mmu_fixed_profile")]
static FIXED_PROFILE: mmu_firmware::profile::Profile = *ThisBoard::PROFILE;

/// The unit logic, in a static. Out of line: `App::new` builds it on the stack first, and this
/// frame is gone before the tasks run, whereas in `main`'s task it would stay in the frame the
/// executor polls.
#[inline(never)]
fn new_logic() -> &'static mut Logic<SLOTS> {
    static LOGIC: StaticCell<Logic<SLOTS>> = StaticCell::new();
    let profile = ThisBoard::PROFILE;
    // The board's default settings, worked out at build time: copied from flash whole rather
    // than built field by field.
    const CONFIG: Config = Config::for_profile(ThisBoard::PROFILE);
    LOGIC.init_with(|| {
        let app = unwrap!(App::with_profile(profile, CONFIG));
        RefCell::new(ControlLoop::new(app, tasks::now()))
    })
}

/// Reloads the watchdog (once the board's `init` has started it).
fn feed_watchdog() {
    WATCHDOG.lock(|watchdog| {
        if let Ok(mut watchdog) = watchdog.try_borrow_mut()
            && let Some(watchdog) = watchdog.as_mut()
        {
            watchdog.feed();
        }
    });
}

#[embassy_executor::task]
async fn control(sampler: Sampler, motors: Motors, received: LinkRx, logic: &'static Logic<SLOTS>) {
    tasks::run_control(sampler, motors, received, logic, feed_watchdog, ThisBoard::reset).await
}

#[embassy_executor::task]
async fn store(flash: StoreFlash, crc: Crc, logic: &'static Logic<SLOTS>) {
    tasks::run_store(flash, crc, ThisBoard::STORE_RANGE, logic, feed_watchdog).await
}

#[embassy_executor::task]
async fn link_tx(tx: LinkTx) {
    tasks::run_link_tx(tx).await
}

#[embassy_executor::task]
async fn button(button: ButtonPin) {
    tasks::run_button(button).await
}

#[embassy_executor::task]
async fn status_led(led: Led) {
    tasks::run_status_led(led).await
}

/// A fault, or a panic (panic-probe ends in `udf`): every motor off, then a reset at once, so a
/// fault before the watchdog runs does not leave the unit silent until a power cycle.
#[cfg(feature = "_cortex_m")]
#[cortex_m_rt::exception]
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    ThisBoard::emergency_stop();
    cortex_m::peripheral::SCB::sys_reset()
}

/// A panic on the BMCU-C: every motor off, then a reset at once (no defmt to say why: the reset
/// cause after it reads as a software reset).
#[cfg(feature = "bmcu")]
#[panic_handler]
fn panic(_info: &core::panic::PanicInfo) -> ! {
    ThisBoard::reset()
}

/// A fault on the BMCU-C (an illegal instruction, a bad load or store): as a panic. qingke-rt's
/// trap entry calls it for every exception.
#[cfg(feature = "bmcu")]
#[unsafe(export_name = "ExceptionHandler")]
extern "C" fn exception_handler() -> ! {
    ThisBoard::reset()
}
