//! MCU entry point of the reference board (NUCLEO-G071RB): the unit logic ([`mmu_firmware::App`])
//! stepped every millisecond, with the same code the host tests and the simulator step.
//!
//! One loop, [`run`]: once `main` has restored what the unit kept in flash ([`Persisted`]), every
//! millisecond of the board's uptime clock it scans all nine Hall sensors (about 210 µs),
//! drains the bytes the printer sent, debounces the button, steps the App, applies the motor
//! commands, queues the response bytes, drives the status LED, carries out resets, feeds the
//! watchdog when it stepped on time, and writes what changed to flash. A scan that never
//! completes stalls the loop, so the watchdog resets the MCU.
//!
//! No async executor: the firmware has one loop, and an Embassy executor with embassy-time (the
//! `Ticker`, the time driver on TIM15, its timer queue and wakers) took 1.9 KB more of the 32 KiB
//! flash than this loop paced by a hardware counter ([`board::wait_until`]), measured. The one
//! thing still `async`, a reset's steps ([`control::reset`], shared with the simulator), runs to
//! completion under `block_on`.
//!
//! The printer UART's receive path needs no task of its own: the USART interrupt moves every byte
//! into a 256-byte ring as it arrives, whatever the loop is doing, and each step takes at most
//! `control::MAX_RX_PER_STEP` bytes from it, more than arrive in a millisecond (the ring holds
//! 20 ms of continuous traffic beyond that). USART3 has no FIFO on this part: its receive register
//! and shift register hold two characters (174 µs), so bytes are lost only while the interrupt
//! cannot run that long: during a flash page erase (up to 40 ms, the CPU stalled on its flash
//! fetch; a double word's 85 µs fits), which the store does only after a step the printer was
//! quiet in. A request lost then goes unanswered: after 2 s the printer restarts the handshake
//! and counts one drop-out (ten in a row would show MMU_NOT_RESPONDING).
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
use embassy_futures::block_on;
use mmu_firmware::control::{self, ControlLoop, ResetBoard, Tick, TickSchedule};
use mmu_firmware::persist::{Boot, Keeper, Store};
use mmu_firmware::uart::LineErrors;
use mmu_firmware::{App, BoardAction, Config, Instant, drive};
use static_cell::StaticCell;

use board::SLOTS;

/// Period of the control step, µs.
const CONTROL_PERIOD_US: u64 = 1_000;
/// Most bytes handed to one step (`board::Control::receive` takes no more).
const RX_CHUNK: usize = control::MAX_RX_PER_STEP;
/// The longest a reset waits for the last response to leave the UART, µs.
const FLUSH_BEFORE_RESET_US: u64 = 20_000;

#[entry]
fn main() -> ! {
    // Before anything else: every bridge off, whatever state a reset left the pins in.
    board::emergency_stop();
    info!(
        "mmu-firmware {=str} starting, reset cause: {}",
        env!("CARGO_PKG_VERSION"),
        board::reset_cause()
    );

    let (control, sampler, flash) = board::init();
    let logic = new_logic();
    let persisted = Persisted::boot(logic.app_mut(), flash);
    run(control, sampler, persisted, logic)
}

/// The unit logic, in a static rather than in the loop's frame. Built out of line: `App::new`
/// builds it on the stack first (about 2.5 KiB), and this frame is gone before the loop runs,
/// whereas a temporary in [`run`] or `main` would stay under every later step (the worst-case
/// stack, `scripts/firmware-size.sh`).
#[inline(never)]
fn new_logic() -> &'static mut ControlLoop<SLOTS> {
    static LOGIC: StaticCell<ControlLoop<SLOTS>> = StaticCell::new();
    // `try_init` and defmt's `unwrap!` rather than `init`: its panic message would stay in flash.
    unwrap!(LOGIC.try_init(ControlLoop::new(
        App::new(Config::default()),
        millis(board::uptime_us()),
    )))
}

/// The control loop: a step every [`CONTROL_PERIOD_US`] of the uptime clock ([`TickSchedule`]). A
/// step that starts late (the previous one overran) runs at once and reports its lateness, which
/// decides the watchdog feed ([`control::feeds_watchdog`]); the ticks a flash write stalled are
/// dropped rather than caught up in a burst of late, unfed steps.
fn run(
    mut board: board::Control,
    mut sampler: board::Sampler,
    mut persisted: Persisted,
    control: &'static mut ControlLoop<SLOTS>,
) -> ! {
    let mut schedule = TickSchedule::new(board::uptime_us(), CONTROL_PERIOD_US);
    let mut rx = [0u8; RX_CHUNK];
    let mut line_errors = LineErrors::default();
    loop {
        let lateness_us = schedule.start(board::wait_until(schedule.deadline_us()));

        // This tick's scan, then the step: the App steps on readings taken just before it.
        let samples = sampler.sample();
        let now = millis(board::uptime_us());
        let received = board.receive(&mut rx);
        let button_down = board.button_down();
        let step = control_step(
            control,
            &Tick {
                now,
                lateness_us,
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
            // Logged by `Persisted::before`, which every reset runs ("store: Reset done").
            let mut resetting = Resetting {
                board: &mut board,
                persisted: &mut persisted,
                app: control.app(),
            };
            block_on(control::reset(&mut resetting, action));
        }
        if step.feed_watchdog {
            board.feed_watchdog();
        }
        if let Some(stats) = step.report {
            let now_errors = board.line_errors();
            log_stats(&stats, &now_errors.since(&line_errors));
            line_errors = now_errors;
        }

        // Last, just after the feed: a write stalls the CPU (see `board::WatchedFlash`; a page
        // erase up to 40 ms), the motors keeping this step's commands meanwhile. The ticks it
        // missed are dropped rather than caught up in a burst of late, unfed steps.
        let busy = received > 0 || !step.out.tx.is_empty();
        if persisted.update(control.app(), now, busy) {
            control.saved();
            schedule.restart(board::uptime_us());
        }
    }
}

fn millis(at_us: u64) -> Instant {
    Instant::from_millis(at_us / 1000)
}

/// One step of the unit logic and its loop policy. Kept out of line so that its size shows as
/// `mmu_firmware::control_step` in `scripts/firmware-size.sh` rather than inside [`run`].
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
        self.board.flush(FLUSH_BEFORE_RESET_US);
    }

    async fn persist(&mut self, action: BoardAction) {
        self.persisted.before(action, self.app);
    }

    fn restart(&mut self) {
        board::reset()
    }
}

/// The period's statistics, with what went wrong on the printer's receive line meanwhile.
fn log_stats(stats: &control::Stats, line: &LineErrors) {
    if stats.troubled() || line.total() > 0 {
        warn!(
            "control: {=u32} steps, {=u32} late (max {=u64} us), {=u32} with stale samples, {=u32} watchdog feeds skipped, {=u32} responses dropped, {=u32} flash writes; received: {=u32} overruns, {=u32} garbled, {=u32} dropped",
            stats.steps,
            stats.late,
            stats.max_lateness_us,
            stats.stale,
            stats.unfed,
            stats.tx_dropped,
            stats.saves,
            line.overruns,
            line.garbled,
            line.dropped
        );
    } else {
        info!(
            "control: {=u32} steps on time, max lateness {=u64} us, {=u32} flash writes",
            stats.steps, stats.max_lateness_us, stats.saves
        );
    }
}

/// The App's state in flash, kept by the policy the simulator runs too ([`Keeper`]).
///
/// The store is synchronous: every flash operation of [`board::WatchedFlash`] blocks (the CPU
/// stalls anyway while the G0's flash programs or erases). Its calls are plain out-of-line
/// functions, whose frames stay off the loop's.
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
    /// together with the keeper's boot frame.
    #[inline(never)]
    fn log_boot(&self, app: &App<SLOTS>, boot: Boot) {
        match boot {
            Boot::Restored => {
                let snapshot = self.0.snapshot(app);
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
    }

    /// Writes what changed (see [`Keeper::update_after`]): nothing after a step `busy` with the
    /// printer (it took bytes or answered), unless several in a row were. Returns whether it
    /// wrote, i.e. stalled the CPU. A failed write leaves the previous record in flash; the
    /// keeper tries again after a pause, and its health is logged once per change.
    #[inline(never)]
    fn update(&mut self, app: &App<SLOTS>, now: Instant, busy: bool) -> bool {
        let wrote = self.0.update_after(app, now, busy);
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
