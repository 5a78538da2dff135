//! The firmware: an Embassy application that runs the unit logic ([`mmu_firmware::App`], inside
//! [`ControlLoop`]) on a board, with the same code the host tests and the simulator step.
//!
//! One `main` for every board. The board is a module selected by feature (`src/board/g071/` for
//! the NUCLEO-G071RB, `src/board/pico/` for the Raspberry Pi Pico): it starts the clocks and the
//! HAL's drivers and hands over parts that implement the hal-port traits ([`SensorScan`],
//! [`Motors`], [`Watchdog`], embedded-io-async `Read`/`Write` for the printer link, a NOR flash for
//! the store). The tasks below are written against those traits only; each `#[task]` is a thin
//! non-generic wrapper (Embassy tasks cannot be generic) naming the board's types.
//!
//! Tasks, and what they say to each other (embassy-sync):
//! - `control`, every millisecond on an embassy-time [`Ticker`] (1 MHz ticks: the period is
//!   exact): scans the sensors (the wait bounded by [`SCAN_TIMEOUT`]), takes at most
//!   `control::MAX_RX_PER_STEP` bytes from [`RX_PIPE`], steps the [`ControlLoop`], applies the
//!   motor commands, queues the answer in [`TX_PIPE`], feeds the watchdog when the step was on
//!   time with fresh samples, and signals [`STEPPED`];
//! - `store`, woken by [`STEPPED`]: writes what changed to flash, one bounded piece after a
//!   step; and on [`RESET`] the whole save before a reset;
//! - `link_rx` / `link_tx`: the printer UART, received by DMA into a ring (no byte lost while a
//!   flash erase stalls the CPU), moved into [`RX_PIPE`]; [`TX_PIPE`] sent by DMA;
//! - `button`: the button's level, at each edge, in [`BUTTON`] (the control loop debounces);
//! - `status_led`: the LED, from [`LED`].
//!
//! Safety: the board's `emergency_stop` (every bridge off through raw register writes) runs
//! first at boot and in the HardFault handler, which then resets the MCU at once (it does not
//! wait for a watchdog that may not be running yet). A panic goes through panic-probe: it logs
//! the message over defmt and raises a HardFault (`udf`), so the same handler stops the motors
//! and resets (with a probe attached, probe-rs stops there and prints the backtrace instead). The
//! watchdog starts in `board::init`, right after the clocks; only the control task feeds it, and
//! the store's flash only within an allowance ([`WatchedFlash`]).

#![no_std]
#![no_main]

#[cfg(not(any(feature = "g071", feature = "pico")))]
compile_error!("choose a board: `cargo fw` (--features g071) or `cargo fw-pico` (--features pico)");
#[cfg(all(feature = "g071", feature = "pico"))]
compile_error!("the features g071 and pico are two boards: build one at a time");

mod board;

use core::cell::RefCell;

use defmt::{error, info, unwrap, warn};
use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_sync::signal::Signal;
use embassy_sync::watch::Watch;
use embassy_time::{Duration, Ticker, Timer, with_timeout};
use mmu_firmware::control::{self, ControlLoop, ResetBoard, Schedule, Tick};
use mmu_firmware::persist::{Boot, Keeper, Store};
use mmu_firmware::port::{CheckedCrc, SampleClock, WatchedFlash};
use mmu_firmware::uart::LineErrors;
use mmu_firmware::{App, BoardAction, Config, Instant, Samples, drive};
use mmu_hal_port::{Button, Motors, SensorScan, StatusLed, Watchdog};
use panic_probe as _;
use portable_atomic::{AtomicBool, AtomicU32, Ordering};
use static_cell::StaticCell;

use board::SLOTS;

/// The control period: 1 ms, exact at embassy-time's 1 MHz tick.
const PERIOD: Duration = Duration::from_micros(1_000);
/// The longest the control task waits for a sensor scan (the G071's DMA scan takes about 210 µs,
/// the Pico's multiplexed one about 170 µs); past it the step runs on the previous samples,
/// whose age then grows until `control::MAX_SAMPLE_AGE_US` stops the watchdog feed.
const SCAN_TIMEOUT: Duration = Duration::from_micros(600);
/// The longest a reset waits for the last response to leave the UART.
const FLUSH_BEFORE_RESET: Duration = Duration::from_millis(20);
/// Watchdog feeds the flash may give during a job that must run whole (the boot's repair, the
/// save before a reset): a save erases at most two pages, the one in progress finished first two
/// more; two spare. A loop in the save path runs out of them and the watchdog resets the MCU.
const WHOLE_JOB_FEEDS: u32 = 6;
/// Bytes of responses waiting for the UART: more than five steps' worth
/// (`mmu_firmware::TX_CAPACITY` = 48).
const TX_QUEUE: usize = 256;

/// Bytes from the printer waiting for the control task (it takes at most
/// `control::MAX_RX_PER_STEP` a step); the UART's DMA ring holds what does not fit yet.
static RX_PIPE: Pipe<CriticalSectionRawMutex, { control::RX_RING }> = Pipe::new();
/// Responses waiting for the UART.
static TX_PIPE: Pipe<CriticalSectionRawMutex, TX_QUEUE> = Pipe::new();
/// True while `link_tx` has bytes in flight.
static TX_BUSY: AtomicBool = AtomicBool::new(false);
/// The button's level (true: held down).
static BUTTON: Watch<CriticalSectionRawMutex, bool, 1> = Watch::new();
/// The status LED's state, sent when it changes.
static LED: Signal<CriticalSectionRawMutex, bool> = Signal::new();
/// A control step is done; true if it was busy with the printer (took bytes or answered).
static STEPPED: Signal<CriticalSectionRawMutex, bool> = Signal::new();
/// The store has restored the logic's state: the control task may step.
static BOOTED: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// A reset is due: save (or forget) whole, then say so on [`RESET_SAVED`].
static RESET: Signal<CriticalSectionRawMutex, BoardAction> = Signal::new();
/// The save before a reset is done.
static RESET_SAVED: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// The store wrote to flash after the last step (the CPU stalled): the control task drops the
/// ticks it missed instead of catching up in a burst.
static STORE_WROTE: AtomicBool = AtomicBool::new(false);
/// The watchdog, once `board::init` started it.
static WATCHDOG: Mutex<CriticalSectionRawMutex, RefCell<Option<board::Watchdog>>> =
    Mutex::new(RefCell::new(None));
/// Receive errors the link reported: overruns and garbled frames.
static OVERRUNS: AtomicU32 = AtomicU32::new(0);
static GARBLED: AtomicU32 = AtomicU32::new(0);

/// The unit logic, shared by the control task (which steps it) and the store task (which saves
/// what it holds). Both run on the one thread executor and never hold it across an `.await`.
type Logic = RefCell<ControlLoop<SLOTS>>;
/// The store as the board keeps it.
type BoardKeeper = Keeper<WatchedFlash<board::StoreFlash>, SLOTS, CheckedCrc<board::Crc>>;

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // Before anything else: every bridge off, whatever state a reset left the pins in.
    board::emergency_stop();
    info!(
        "mmu-firmware {=str} on {=str} starting, reset cause: {}",
        env!("CARGO_PKG_VERSION"),
        board::NAME,
        board::reset_cause()
    );
    let parts = board::init();
    WATCHDOG.lock(|watchdog| watchdog.replace(Some(parts.watchdog)));

    let logic: &'static Logic = new_logic();

    // The store task restores the logic's state first; the control task waits for it.
    spawner.spawn(unwrap!(store(parts.flash, parts.crc, logic)));
    spawner.spawn(unwrap!(control(parts.sampler, parts.motors, logic)));
    spawner.spawn(unwrap!(link_rx(parts.link_rx)));
    spawner.spawn(unwrap!(link_tx(parts.link_tx)));
    spawner.spawn(unwrap!(button(parts.button)));
    spawner.spawn(unwrap!(status_led(parts.led)));
}

/// The unit logic, in a static. Out of line: `App::new` builds it on the stack first (about
/// 2.5 KiB), and this frame is gone before the tasks run, whereas in `main`'s task it would stay
/// in the frame the executor polls (the worst-case stack, `scripts/firmware-size.sh`).
#[inline(never)]
fn new_logic() -> &'static mut Logic {
    static LOGIC: StaticCell<Logic> = StaticCell::new();
    LOGIC.init_with(|| RefCell::new(ControlLoop::new(App::new(Config::default()), now())))
}

/// The uptime, µs.
fn now_us() -> u64 {
    embassy_time::Instant::now().as_micros()
}

/// The logic's clock: the uptime in ms.
fn now() -> Instant {
    Instant::from_millis(now_us() / 1000)
}

/// Reloads the watchdog (once `board::init` has started it).
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
async fn control(sampler: board::Sampler, motors: board::Motors, logic: &'static Logic) {
    run_control(sampler, motors, logic).await
}

/// The control task: a step every [`PERIOD`] (see the module header).
async fn run_control<S: SensorScan<SLOTS>, M: Motors<SLOTS>>(
    mut sampler: S,
    mut motors: M,
    logic: &Logic,
) -> ! {
    BOOTED.wait().await;
    let mut ticker = Ticker::every(PERIOD);
    let mut schedule = Schedule::new(now_us(), PERIOD.as_micros());
    let mut samples = Samples::<SLOTS>::uniform(mmu_hal_port::ADC_MAX / 2);
    let mut sample_clock = SampleClock::new(now_us());
    let mut button = BUTTON.receiver();
    let mut rx = [0u8; control::MAX_RX_PER_STEP];
    let mut led = None;
    let mut line_errors = LineErrors::default();
    loop {
        ticker.next().await;
        let lateness_us = schedule.start(now_us());
        if let Ok(Ok(scan)) = with_timeout(SCAN_TIMEOUT, sampler.scan()).await {
            samples = scan;
            sample_clock.fresh(now_us());
        }
        let at_us = now_us();
        let received = RX_PIPE.try_read(&mut rx).unwrap_or(0);
        let button_down = button.as_mut().and_then(|b| b.try_get()).unwrap_or(false);
        // The step, in a block of its own: the logic is never borrowed across an `.await`.
        let (action, busy) = {
            let Ok(mut control) = logic.try_borrow_mut() else {
                continue;
            };
            let step = control.step(&Tick {
                now: Instant::from_millis(at_us / 1000),
                lateness_us,
                sample_age_us: sample_clock.age_us(at_us),
                samples: &samples,
                rx: rx.get(..received).unwrap_or_default(),
                button_down,
            });
            motors.apply(&step.out.motors);
            if led != Some(step.out.status_led) {
                led = Some(step.out.status_led);
                LED.signal(step.out.status_led);
            }
            if !step.out.tx.is_empty() && !send(&step.out.tx) {
                control.tx_dropped();
            }
            if step.button_pressed {
                info!("button: Middle");
            }
            if step.feed_watchdog {
                feed_watchdog();
            }
            if let Some(stats) = step.report {
                let now_errors = line_errors_now();
                log_stats(&stats, &now_errors.since(&line_errors));
                line_errors = now_errors;
            }
            (step.out.action, received > 0 || !step.out.tx.is_empty())
        };
        if let Some(action) = action {
            control::reset(&mut Resetting { motors: &mut motors }, action).await;
        }
        STEPPED.signal(busy);
        // A flash write stalled the CPU (or the step overran): the ticks missed are dropped
        // rather than caught up in a burst of late, unfed steps.
        if STORE_WROTE.swap(false, Ordering::Relaxed) || lateness_us > control::ON_TIME_US {
            ticker.reset();
            schedule.restart(now_us());
        }
    }
}

/// Queues a whole response for the printer, or nothing when it does not fit.
fn send(bytes: &[u8]) -> bool {
    TX_PIPE.free_capacity() >= bytes.len() && TX_PIPE.try_write(bytes) == Ok(bytes.len())
}

/// The receive errors so far.
fn line_errors_now() -> LineErrors {
    LineErrors {
        overruns: OVERRUNS.load(Ordering::Relaxed),
        garbled: GARBLED.load(Ordering::Relaxed),
        dropped: 0,
    }
}

/// The board's side of a reset ([`control::reset`] fixes the order): motors off, the answer
/// flushed, the state saved by the store task, then the restart.
struct Resetting<'a, M> {
    motors: &'a mut M,
}

impl<M: Motors<SLOTS>> ResetBoard for Resetting<'_, M> {
    fn stop_motors(&mut self) {
        self.motors.apply(&drive::stopped());
    }

    async fn flush(&mut self) {
        let sent = async {
            while !TX_PIPE.is_empty() || TX_BUSY.load(Ordering::Relaxed) {
                Timer::after_micros(200).await;
            }
        };
        let _ = with_timeout(FLUSH_BEFORE_RESET, sent).await;
    }

    async fn persist(&mut self, action: BoardAction) {
        RESET.signal(action);
        RESET_SAVED.wait().await;
    }

    fn restart(&mut self) {
        board::reset()
    }
}

#[embassy_executor::task]
async fn store(flash: board::StoreFlash, crc: board::Crc, logic: &'static Logic) {
    run_store(flash, crc, logic).await
}

/// The store task: restores what the flash holds into the logic (then [`BOOTED`]), and then a
/// bounded piece of a save after each step, or the whole save before a reset.
async fn run_store(flash: board::StoreFlash, crc: board::Crc, logic: &Logic) -> ! {
    let mut keeper = match logic.try_borrow_mut() {
        Ok(mut control) => boot_store(control.app_mut(), flash, crc),
        Err(_) => defmt::panic!("the logic is borrowed at boot"),
    };
    BOOTED.signal(());
    loop {
        match select(STEPPED.wait(), RESET.wait()).await {
            Either::First(busy) => {
                let Ok(control) = logic.try_borrow() else {
                    continue;
                };
                let wrote = keeper.update_after(control.app(), now(), busy);
                if let Some(health) = keeper.take_news() {
                    warn!("store: {}", health);
                }
                drop(control);
                // A failed write stalled the CPU too.
                if wrote.unwrap_or(true) {
                    STORE_WROTE.store(true, Ordering::Relaxed);
                    if let Ok(mut control) = logic.try_borrow_mut() {
                        control.saved();
                    }
                }
            }
            Either::Second(action) => {
                if let Ok(control) = logic.try_borrow() {
                    keeper.store().flash().allow_feeds(WHOLE_JOB_FEEDS);
                    match keeper.before(action, control.app()) {
                        Ok(()) => info!("store: {} done", action),
                        Err(e) => error!("store: {} failed: {}", action, e),
                    }
                }
                RESET_SAVED.signal(());
            }
        }
    }
}

/// Checks the CRC unit, then restores into `app` what the flash holds, before its first step.
/// Out of line, for the same reason as [`new_logic`].
#[inline(never)]
fn boot_store(app: &mut App<SLOTS>, flash: board::StoreFlash, crc: board::Crc) -> BoardKeeper {
    let (crc, check) = CheckedCrc::check(crc);
    if !crc.is_unit() {
        error!(
            "CRC unit: {=u32:#x} for the check value, not {=u32:#x}: the store uses the software CRC",
            check,
            mmu_firmware::persist::iso_hdlc::CHECK
        );
    }
    let mut flash = WatchedFlash::new(flash, feed_watchdog);
    // The boot may repair the store (erase a damaged page): a job that runs whole.
    flash.allow_feeds(WHOLE_JOB_FEEDS);
    let store = unwrap!(Store::with_crc(flash, crc, board::STORE_RANGE));
    let (mut keeper, boot) = Keeper::boot(store, app);
    keeper.store().flash().allow_feeds(0);
    match boot {
        Boot::Restored => {
            let snapshot = keeper.snapshot(app);
            let c = &snapshot.counters;
            info!(
                "restored: lanes {=[?]}, {=usize} settings, errors {=u16}, tool changes {=[?]}, failures {=[?]}, fed {=[?]} mm",
                &snapshot.lanes[..],
                snapshot.settings.len(),
                c.drive_errors,
                &c.tool_changes[..],
                &c.failures[..],
                &c.fed_mm[..]
            );
        }
        Boot::Damaged(damage) => warn!(
            "store: {=u16} unreadable double words, {=u16} torn entries (a power cut): the newest complete records are restored",
            damage.unreadable, damage.torn
        ),
    }
    keeper
}

#[embassy_executor::task]
async fn link_rx(rx: board::LinkRx) {
    run_link_rx(rx).await
}

/// Moves what the UART's DMA ring received into [`RX_PIPE`], waiting for room when the control
/// task is behind (the ring holds the rest), and counts the receive errors.
async fn run_link_rx<R: embedded_io_async::Read<Error = board::LinkRxError>>(mut rx: R) -> ! {
    let mut buf = [0u8; 32];
    loop {
        match rx.read(&mut buf).await {
            Ok(count) => RX_PIPE.write_all(buf.get(..count).unwrap_or_default()).await,
            Err(e) => {
                let counter = match board::line_error(&e) {
                    board::LineError::Overrun => &OVERRUNS,
                    board::LineError::Garbled => &GARBLED,
                };
                counter.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

#[embassy_executor::task]
async fn link_tx(tx: board::LinkTx) {
    run_link_tx(tx).await
}

/// Sends what the control task queued in [`TX_PIPE`].
async fn run_link_tx<W: embedded_io_async::Write>(mut tx: W) -> ! {
    let mut buf = [0u8; 64];
    loop {
        let count = TX_PIPE.read(&mut buf).await;
        TX_BUSY.store(true, Ordering::Relaxed);
        // A write error leaves nothing to retry: the printer asks again.
        let _ = tx.write_all(buf.get(..count).unwrap_or_default()).await;
        let _ = tx.flush().await;
        TX_BUSY.store(!TX_PIPE.is_empty(), Ordering::Relaxed);
    }
}

#[embassy_executor::task]
async fn button(button: board::ButtonPin) {
    run_button(button).await
}

/// Publishes the button's level at every edge (the control loop debounces it).
async fn run_button<B: Button + embedded_hal_async::digital::Wait>(mut button: B) -> ! {
    let sender = BUTTON.sender();
    loop {
        sender.send(button.is_pressed().unwrap_or(false));
        let _ = button.wait_for_any_edge().await;
    }
}

#[embassy_executor::task]
async fn status_led(led: board::Led) {
    run_status_led(led).await
}

/// Lights the LED as the control task says.
async fn run_status_led<L: StatusLed>(mut led: L) -> ! {
    loop {
        let lit = LED.wait().await;
        let _ = led.set_lit(lit);
    }
}

/// The period's statistics, with what went wrong on the printer's receive line meanwhile.
fn log_stats(stats: &control::Stats, line: &LineErrors) {
    if stats.troubled() || line.total() > 0 {
        warn!(
            "control: {=u32} steps, {=u32} late (max {=u64} us), {=u32} with stale samples, {=u32} watchdog feeds skipped, {=u32} responses dropped, {=u32} flash writes; received: {=u32} overruns, {=u32} garbled",
            stats.steps,
            stats.late,
            stats.max_lateness_us,
            stats.stale,
            stats.unfed,
            stats.tx_dropped,
            stats.saves,
            line.overruns,
            line.garbled
        );
    } else {
        info!(
            "control: {=u32} steps on time, max lateness {=u64} us, {=u32} flash writes",
            stats.steps, stats.max_lateness_us, stats.saves
        );
    }
}

/// A fault, or a panic (panic-probe ends in `udf`): every motor off, then a reset at once, so a
/// fault before the watchdog runs does not leave the unit silent until a power cycle.
#[cortex_m_rt::exception]
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    board::emergency_stop();
    cortex_m::peripheral::SCB::sys_reset()
}
