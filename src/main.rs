//! MCU entry point of the reference board (NUCLEO-G071RB): the unit logic ([`mmu_firmware::App`])
//! stepped every millisecond, with the same code the host tests and the simulator step.
//!
//! One task, `control_task`, on a thread-mode Embassy executor: at boot it restores what the unit
//! kept in flash ([`Persisted`]); then every millisecond (Ticker) it scans all nine Hall sensors
//! (DMA, about 210 µs with the CPU free), drains the bytes the printer sent, debounces the button,
//! steps the App, applies the motor commands, queues the response bytes, drives the status LED,
//! carries out resets, feeds the watchdog when it stepped on time, and writes what changed to
//! flash. (A separate sampler task publishing its scans cost 380 B of flash and 190 B of RAM
//! more; a scan that never completes now stalls the loop, so the watchdog resets the MCU.)
//!
//! The printer UART's receive path needs no task of its own: the USART interrupt moves every byte
//! into a 256-byte ring as it arrives, whatever the tasks are doing (a byte could only be lost if
//! interrupts stayed masked for a whole character time, 87 µs), and each step takes at most
//! `control::MAX_RX_PER_STEP` bytes from it, more than arrive in a millisecond (the ring holds
//! 20 ms of continuous traffic beyond that).
//!
//! Safety: [`board::emergency_stop`] runs first thing at boot, in the panic handler and in the
//! HardFault handler, and before every reset; the independent watchdog resets the MCU (bridges
//! off) when the control loop stops stepping on time. Only `board` touches Embassy HAL types.

#![no_std]
#![no_main]

mod board;

use core::panic::PanicInfo;
use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m_rt::{ExceptionFrame, entry, exception};
use defmt::{error, info, unwrap, warn};
use defmt_rtt as _;
use embassy_executor::Executor;
use embassy_time::{Duration, Instant as Clock, Ticker};
use mmu_firmware::control::{self, ControlLoop, ResetBoard, Tick};
use mmu_firmware::persist::{Boot, Keeper, Store};
use mmu_firmware::{App, BoardAction, Config, Instant, drive};
use static_cell::StaticCell;

use board::SLOTS;

/// Period of the control step.
const CONTROL_PERIOD: Duration = Duration::from_millis(1);
/// Most bytes handed to one step (`board::Control::receive` takes no more).
const RX_CHUNK: usize = control::MAX_RX_PER_STEP;
/// The longest a reset waits for the last response to leave the UART.
const FLUSH_BEFORE_RESET: Duration = Duration::from_millis(20);

#[entry]
fn main() -> ! {
    // Before anything else: every bridge off, whatever state a reset left the pins in.
    board::emergency_stop();
    info!(
        "mmu-firmware {} starting, reset cause: {}",
        env!("CARGO_PKG_VERSION"),
        board::reset_cause()
    );

    static EXECUTOR: StaticCell<Executor> = StaticCell::new();
    // `try_init` and defmt's `unwrap!` rather than `init`: its panic message would stay in flash.
    unwrap!(EXECUTOR.try_init(Executor::new())).run(|spawner| {
        let (control, sampler, flash) = board::init();
        let logic = new_logic();
        spawner.spawn(unwrap!(control_task(control, sampler, flash, logic)));
    })
}

/// The unit logic, in a static rather than in the control task's future. Built out of line:
/// `App::new` builds it on the stack first (about 2.5 KiB), and this frame is gone before the
/// tasks run, whereas a temporary in the task's `poll` or in `Executor::run` would stay under
/// every later step (the worst-case stack, `scripts/firmware-size.sh`).
#[inline(never)]
fn new_logic() -> &'static mut ControlLoop<SLOTS> {
    static LOGIC: StaticCell<ControlLoop<SLOTS>> = StaticCell::new();
    unwrap!(LOGIC.try_init(ControlLoop::new(
        App::new(Config::default()),
        millis(Clock::now()),
    )))
}

#[embassy_executor::task]
async fn control_task(
    mut board: board::Control,
    mut sampler: board::Sampler,
    flash: board::StoreFlash,
    control: &'static mut ControlLoop<SLOTS>,
) {
    let mut persisted = Persisted::boot(control.app_mut(), flash);
    let mut ticker = Ticker::every(CONTROL_PERIOD);
    let mut deadline = Clock::now() + CONTROL_PERIOD;
    let mut rx = [0u8; RX_CHUNK];
    loop {
        ticker.next().await;
        let lateness = Clock::now().saturating_duration_since(deadline);
        deadline += CONTROL_PERIOD;

        // This tick's scan, then the step: the App steps on readings taken just before it.
        let samples = sampler.sample().await;
        let now = Clock::now();
        let received = board.receive(&mut rx);
        let button_down = board.button_down();
        let step = control_step(
            control,
            &Tick {
                now: millis(now),
                lateness_us: lateness.as_micros(),
                sample_age_us: 0,
                samples: &samples,
                rx: &rx[..received],
                button_down,
            },
        );
        if step.button_pressed {
            info!("button: Middle");
        }
        board.apply(&step.out.motors);
        board.set_status_led(step.out.status_led);
        if !step.out.tx.is_empty() && !board.send(&step.out.tx) {
            control.tx_dropped();
        }
        if let Some(action) = step.out.action {
            info!("board action: {}", action);
            let mut resetting = Resetting {
                board: &mut board,
                persisted: &mut persisted,
                app: control.app(),
            };
            control::reset(&mut resetting, action).await;
        }
        if step.feed_watchdog {
            board.feed_watchdog();
        }
        if let Some(stats) = step.report {
            log_stats(&stats);
        }

        // Last, just after the feed: a write stalls the CPU (see `board::WatchedFlash`; a page
        // erase up to 40 ms), the motors keeping this step's commands meanwhile. The ticks it
        // missed are dropped rather than caught up in a burst of late, unfed steps.
        let busy = received > 0 || !step.out.tx.is_empty();
        if persisted.update(control.app(), now, busy) {
            control.saved();
            ticker.reset();
            deadline = Clock::now() + CONTROL_PERIOD;
        }
    }
}

fn millis(at: Clock) -> Instant {
    Instant::from_millis(at.as_millis())
}

/// One step of the unit logic and its loop policy. Kept out of line so that its size shows as
/// `mmu_firmware::control_step` in `scripts/firmware-size.sh` rather than inside the task's future.
#[inline(never)]
fn control_step(control: &mut ControlLoop<SLOTS>, tick: &Tick<SLOTS>) -> control::Step<SLOTS> {
    control.step(tick)
}

/// The board's side of a reset ([`control::reset`] fixes the order).
struct Resetting<'a> {
    board: &'a mut board::Control,
    persisted: &'a mut Persisted,
    app: &'a App<SLOTS>,
}

impl ResetBoard for Resetting<'_> {
    fn stop_motors(&mut self) {
        self.board.apply(&drive::stopped());
    }

    async fn flush(&mut self) {
        self.board.flush(FLUSH_BEFORE_RESET).await;
    }

    async fn persist(&mut self, action: BoardAction) {
        self.persisted.before(action, self.app);
    }

    fn restart(&mut self) {
        board::reset()
    }
}

fn log_stats(stats: &control::Stats) {
    if stats.troubled() {
        warn!(
            "control: {} steps, {} late (max {} us), {} with stale samples, {} watchdog feeds skipped, {} responses dropped, {} flash writes",
            stats.steps,
            stats.late,
            stats.max_lateness_us,
            stats.stale,
            stats.unfed,
            stats.tx_dropped,
            stats.saves
        );
    } else {
        info!(
            "control: {} steps on time, max lateness {} us, {} flash writes",
            stats.steps, stats.max_lateness_us, stats.saves
        );
    }
}

/// The App's state in flash, kept by the policy the simulator runs too ([`Keeper`]).
///
/// The store is synchronous: every flash operation of [`board::WatchedFlash`] blocks (the CPU
/// stalls anyway while the G0's flash programs or erases). Its calls are plain out-of-line
/// functions, whose frames stay out of the control task's future.
struct Persisted(Keeper<board::WatchedFlash, SLOTS, board::HardwareCrc>);

impl Persisted {
    /// Restores into `app` what the flash holds, before its first step: each record's newest
    /// complete copy (a double word with an ECC error costs only its entry).
    #[inline(never)]
    fn boot(app: &mut App<SLOTS>, flash: board::StoreFlash) -> Self {
        let store = unwrap!(Store::with_crc(flash.flash, flash.crc, board::STORE_RANGE));
        let (keeper, boot) = Keeper::boot(store, app);
        let persisted = Persisted(keeper);
        persisted.log_boot(app, boot);
        persisted
    }

    /// What the boot found. Out of line: the snapshot it logs from is then not on the stack
    /// together with the store's boot future.
    #[inline(never)]
    fn log_boot(&self, app: &App<SLOTS>, boot: Boot) {
        match boot {
            Boot::Restored => {
                let snapshot = self.0.snapshot(app);
                let c = &snapshot.counters;
                info!(
                    "restored: lanes {}, {} settings, errors {}, tool changes {}, failures {}, fed {} mm",
                    snapshot.lanes,
                    snapshot.settings.len(),
                    c.drive_errors,
                    c.tool_changes,
                    c.failures,
                    c.fed_mm
                );
            }
            Boot::Damaged(damage) => warn!(
                "store: {} unreadable double words, {} torn entries (a power cut): the newest complete records are restored",
                damage.unreadable, damage.torn
            ),
        }
    }

    /// Writes what changed (see [`Keeper::update_after`]): nothing after a step `busy` with the
    /// printer (it took bytes or answered), unless several in a row were. Returns whether it
    /// wrote, i.e. stalled the CPU. A failed write leaves the previous record in flash; the
    /// keeper tries again after a pause, and its health is logged once per change.
    #[inline(never)]
    fn update(&mut self, app: &App<SLOTS>, now: Clock, busy: bool) -> bool {
        let wrote = self
            .0
            .update_after(app, Instant::from_millis(now.as_millis()), busy);
        if let Some(health) = self.0.take_news() {
            warn!("store: {}", health);
        }
        wrote.unwrap_or(true)
    }

    /// Saves everything before a reset, or forgets it for `X42`.
    #[inline(never)]
    fn before(&mut self, action: BoardAction, app: &App<SLOTS>) {
        match self.0.before(action, app) {
            Ok(()) => info!("store: {} done", action),
            Err(e) => error!("store: {} failed: {}", action, e),
        }
    }
}

/// Stops every motor, reports the panic over RTT once, then faults: with a probe attached,
/// `probe-rs run` prints a backtrace and exits; without one, the HardFault handler waits for the
/// watchdog to reset the MCU.
///
/// Inlined into `core::panicking::panic_fmt` (under fat LTO), which then visibly never reads the
/// message: the `fmt::Arguments` that the core panics (bounds checks, `unwrap`, in Embassy too)
/// build become dead and `core::fmt` (`Formatter::pad`, integer `Display`) is not linked, 1.7 KiB
/// of flash. Reading `info.message()` here, or dropping the `inline`, brings it back
/// (`scripts/firmware-size.sh` fails on any `core::fmt` symbol).
#[panic_handler]
// rustc calls the hint unused on an exported function, but LLVM applies it under LTO.
#[allow(unused_attributes)]
#[inline(always)]
fn panic(info: &PanicInfo) -> ! {
    if stop_on_first_panic() {
        // The location only (see above).
        match info.location() {
            Some(at) => error!("panic at {=str}:{=u32}", at.file(), at.line()),
            None => error!("panic"),
        }
    }
    cortex_m::asm::udf()
}

/// A panic raised through defmt (`unwrap!`, `panic!`, `assert!`), which has logged its message:
/// the same stop as [`panic`]. (defmt's default handler calls `core::panic!()`, whose location is
/// always defmt's own `lib.rs`, logged as a second, useless line, and whose message and path took
/// flash.)
#[defmt::panic_handler]
fn defmt_panic() -> ! {
    stop_on_first_panic();
    cortex_m::asm::udf()
}

/// Masks interrupts and stops every motor; returns true on the first panic only, so that a panic
/// while reporting one is not reported again.
fn stop_on_first_panic() -> bool {
    static PANICKED: AtomicBool = AtomicBool::new(false);
    cortex_m::interrupt::disable();
    board::emergency_stop();
    // thumbv6m has no atomic swap; interrupts are off, so load + store cannot be torn apart.
    let first = !PANICKED.load(Ordering::Relaxed);
    PANICKED.store(true, Ordering::Relaxed);
    first
}

/// The NMI: on this part a double ECC error reading the flash (see
/// `board::on_flash_double_ecc_error`: in the store it fails the read, elsewhere it resets).
#[exception]
unsafe fn NonMaskableInt() {
    board::on_flash_double_ecc_error()
}

/// A fault (or a panic's `udf`): every motor off, then wait for the watchdog reset.
#[exception]
unsafe fn HardFault(_frame: &ExceptionFrame) -> ! {
    board::emergency_stop();
    loop {
        cortex_m::asm::nop();
    }
}
