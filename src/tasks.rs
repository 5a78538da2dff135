//! The firmware's tasks, written against the hal-port traits only, so that every board runs the
//! same ones (src/main.rs spawns them, each behind a thin non-generic `#[task]` wrapper that names
//! the board's types: Embassy tasks cannot be generic).
//!
//! - [`run_control`], every millisecond on an embassy-time [`Ticker`] (1 MHz ticks: the period is
//!   exact): scans the sensors (the wait bounded by the next tick), runs the control step
//!   ([`ControlLoop::step`], which takes the printer's bytes from the UART's DMA ring itself),
//!   applies the motor commands, queues the answer in [`TX_PIPE`], feeds the watchdog when the
//!   step says so, and signals [`STEPPED`] when a save piece runs after the step;
//! - [`run_store`]: restores what the flash holds (then [`BOOTED`]); woken by [`STEPPED`], writes
//!   what changed, one bounded piece after a step; on [`RESET`] the whole save before a reset;
//! - [`run_link_tx`]: sends what waits in [`TX_PIPE`] on the printer UART;
//! - [`run_button`]: the button's level, at each edge, in [`BUTTON`] (the control loop debounces);
//! - [`run_status_led`]: the LED, from [`LED`].
//!
//! Only the control task feeds the watchdog (through the board's `feed`), and the store's flash
//! only within an allowance ([`WatchedFlash`]).

use core::cell::RefCell;
use core::future::{Future, poll_fn};
use core::ops::Range;
use core::pin::{Pin, pin};
use core::task::Poll;

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_sync::signal::Signal;
use embassy_sync::watch::Watch;
use embassy_time::{Duration, Ticker, Timer, with_timeout};
use embedded_storage::nor_flash::NorFlash;
use mmu_hal_port::{Button, Motors, SensorScan, StatusLed};
use portable_atomic::{AtomicBool, AtomicU32, Ordering};

use crate::control::{self, ControlLoop, ResetBoard, Tick, TickSchedule};
use crate::persist::{Boot, EntryCrc, Keeper, Store};
use crate::port::{CheckedCrc, SampleClock, WatchedFlash};
use crate::time::div_rem_u64;
use crate::uart::{LineErrors, Received};
use crate::{App, BoardAction, Instant, Samples, drive};

/// defmt's logging macros when the crate logs (feature `defmt`), nothing otherwise (the tasks'
/// host test).
macro_rules! log {
    ($level:ident, $($arg:tt)*) => {{
        #[cfg(feature = "defmt")]
        ::defmt::$level!($($arg)*);
    }};
}

/// The control period, µs.
const PERIOD_US: u16 = 1_000;
/// The control period: 1 ms, exact at embassy-time's 1 MHz tick.
pub const PERIOD: Duration = Duration::from_micros(PERIOD_US as u64);
/// The scan's bound in a step that starts late (the scan is otherwise bounded by the next tick).
pub const LATE_SCAN: Duration = Duration::from_micros(600);
/// The longest a reset waits for the last response to leave the UART.
pub const FLUSH_BEFORE_RESET: Duration = Duration::from_millis(20);
/// Watchdog feeds the flash may give during a job that must run whole (the boot's repair, the
/// save before a reset): a save erases at most two pages, the one in progress finished first two
/// more; two spare. A loop in the save path runs out of them and the watchdog resets the MCU.
pub const WHOLE_JOB_FEEDS: u32 = 6;
/// Bytes of responses waiting for the UART: more than five steps' worth
/// (`crate::TX_CAPACITY` = 48).
pub const TX_QUEUE: usize = 256;

/// Responses waiting for the UART: the control task writes a whole answer or none, the transmit
/// task sends what waits.
pub static TX_PIPE: Pipe<CriticalSectionRawMutex, TX_QUEUE> = Pipe::new();
/// True while the link's transmit task has bytes in flight.
pub static TX_BUSY: AtomicBool = AtomicBool::new(false);
/// The button's level (true: held down).
pub static BUTTON: Watch<CriticalSectionRawMutex, bool, 1> = Watch::new();
/// The status LED's state, sent when it changes.
pub static LED: Signal<CriticalSectionRawMutex, bool> = Signal::new();
/// A control step is done and a save piece runs after it ([`control::Deferral`]).
pub static STEPPED: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// The store has restored the logic's state: the control task may step.
pub static BOOTED: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// A reset is due: save (or forget) whole, then say so on [`RESET_SAVED`].
pub static RESET: Signal<CriticalSectionRawMutex, BoardAction> = Signal::new();
/// The save before a reset is done.
pub static RESET_SAVED: Signal<CriticalSectionRawMutex, ()> = Signal::new();
/// The store wrote to flash after the last step (the CPU stalled): the control task drops the
/// ticks it missed instead of catching up in a burst.
pub static STORE_WROTE: AtomicBool = AtomicBool::new(false);
/// Control steps taken since boot, wrapping; written by the control task alone. A debugger
/// reads it by name to see the loop run, and the emulated-chip benches (fil/) measure the load of
/// the milliseconds in which it moved: the control task's, not the boot's (the store's restore,
/// its repair after a power cut).
#[unsafe(no_mangle)]
pub static MMU_CONTROL_STEPS: AtomicU32 = AtomicU32::new(0);
/// The unit logic, shared by the control task (which steps it) and the store task (which saves
/// what it holds). Both run on the one thread executor and never hold it across an `.await`.
pub type Logic<const N: usize> = RefCell<ControlLoop<N>>;

/// The uptime, µs.
pub fn now_us() -> u64 {
    embassy_time::Instant::now().as_micros()
}

/// The logic's clock: the uptime in ms.
pub fn now() -> Instant {
    Instant::from_micros(now_us())
}

/// The control task: a step every [`PERIOD`] (see the module header), once the store has
/// restored the logic's state. `received` is the printer UART's DMA ring; `feed` reloads the
/// board's watchdog; `restart` stops the motors and restarts the MCU.
pub async fn run_control<const N: usize, S, M, R>(
    mut sampler: S,
    mut motors: M,
    mut received: R,
    logic: &Logic<N>,
    feed: fn(),
    restart: fn() -> !,
) -> !
where
    S: SensorScan<N>,
    M: Motors<N>,
    R: Received,
{
    BOOTED.wait().await;
    let mut ticker = Ticker::every(PERIOD);
    // The first tick on the grid of whole periods: a period before it, the schedule starts.
    let mut schedule = TickSchedule::new(next_tick_us(now_us()) - u64::from(PERIOD_US), PERIOD_US);
    // The Ticker on the schedule's grid to the microsecond: the scan's bound below is the next
    // tick, the same instant, so the time driver has one alarm a period.
    align(&mut ticker, &schedule);
    let mut samples = Samples::<N>::uniform(mmu_hal_port::ADC_MAX / 2);
    let mut sample_clock = SampleClock::new(now_us());
    let mut button = BUTTON.receiver();
    let mut outlets = Outlets {
        led: None,
        line_errors: LineErrors::default(),
        feed,
    };
    loop {
        ticker.next().await;
        let started_us = now_us();
        let lateness_us = schedule.start(started_us);
        // The scan is waited for until the next tick at most, or [`LATE_SCAN`] in a step that
        // starts so late (after a flash write) that the next tick is near or past; past it the
        // step runs on the previous samples, which then grow old and stop the watchdog's feed.
        let bound_us = schedule.deadline_us().max(started_us + LATE_SCAN.as_micros());
        if let Some(scan) = scan_until(&mut sampler, bound_us).await {
            samples = scan;
            sample_clock.fresh(now_us());
        }
        let at_us = now_us();
        let button_down = button.as_mut().and_then(|b| b.try_get()).unwrap_or(false);
        // The step, in a block of its own: the logic is never borrowed across an `.await`.
        let action = {
            let Ok(mut control) = logic.try_borrow_mut() else {
                continue;
            };
            let tick = Tick {
                now: Instant::from_micros(at_us),
                lateness_us,
                sample_age_us: sample_clock.age_us(at_us),
                samples: &samples,
                button_down,
            };
            let step = control.step(&tick, &mut received);
            motors.apply(&step.out.motors);
            outlets.carry_out(&step, &mut control, &received);
            step.out.action
        };
        if let Some(action) = action {
            let mut resetting = Resetting::<M, N> {
                motors: &mut motors,
                restart,
            };
            control::reset(&mut resetting, action).await;
        }
        let steps = MMU_CONTROL_STEPS.load(Ordering::Relaxed);
        MMU_CONTROL_STEPS.store(steps.wrapping_add(1), Ordering::Relaxed);
        // A flash write stalled the CPU (or the step overran): the ticks missed are dropped
        // rather than caught up in a burst of late, unfed steps; the next is the grid's next
        // tick, so the scan and the step keep their place in the millisecond.
        if STORE_WROTE.swap(false, Ordering::Relaxed) || lateness_us > control::ON_TIME_US {
            schedule.skip_missed(now_us());
            align(&mut ticker, &schedule);
        }
    }
}

/// The sensors' scan, waited for until `bound_us` at most.
async fn scan_until<const N: usize>(sampler: &mut impl SensorScan<N>, bound_us: u64) -> Option<Samples<N>> {
    let scan = pin!(sampler.scan());
    match bounded(embassy_time::Instant::from_micros(bound_us), scan).await {
        Some(Ok(samples)) => Some(samples),
        _ => None,
    }
}

/// Where a step's outputs go besides the motors and a reset: the LED, the answer, the log, the
/// watchdog and the store task.
struct Outlets {
    /// The LED as last signalled.
    led: Option<bool>,
    /// The line's errors as of the last statistics report.
    line_errors: LineErrors,
    /// Reloads the board's watchdog.
    feed: fn(),
}

impl Outlets {
    /// Carry out what `step` of `control` says, `received` the step's receive side.
    fn carry_out<const N: usize>(
        &mut self,
        step: &control::Step<N>,
        control: &mut ControlLoop<N>,
        received: &impl Received,
    ) {
        if self.led != Some(step.out.status_led) {
            self.led = Some(step.out.status_led);
            LED.signal(step.out.status_led);
        }
        if !step.out.tx.is_empty() && !queue_answer(&step.out.tx) {
            control.tx_dropped();
        }
        if step.button_pressed {
            log!(info, "button: Middle");
        }
        if step.feed_watchdog {
            (self.feed)();
        }
        if let Some(stats) = step.report {
            let now_errors = received.errors();
            log_stats(&stats, &now_errors.since(&self.line_errors));
            self.line_errors = now_errors;
        }
        if step.save_piece {
            STEPPED.signal(());
        }
    }
}

/// `fut`'s output, or `None` once `deadline` has passed first: embassy-time's `with_deadline`,
/// minus its cost at every wake-up of `fut` (the Pico's scan wakes nine times a step).
///
/// `with_deadline` polls its `Timer` after every pending poll of `fut`, and each poll registers
/// the deadline again (`schedule_wake`); the timer queue of embassy-time-queue-utils 0.3 (both
/// boards' time drivers use it) takes a deadline at or before the
/// task's registered one as a change, so the driver walks the queue and sets its alarm again,
/// the same alarm, every time. Here the first pending poll registers `deadline`, the later ones
/// `deadline` + 1 tick: a registration still standing at or before it makes that a no-op in the
/// queue (no walk, no alarm), and one that is gone is made again. It can be gone: embassy-executor
/// 0.10 keeps a task's registration across polls (only its expiry removes it, waking the task),
/// but the task's one registration takes the earliest of the instants asked for, so a stale
/// earlier one (the previous step's bound, after a late step) expires during the scan and takes
/// this one with it. So the wake-up comes at `deadline`, or a tick (1 µs) after it in that case.
pub fn bounded<F: Future>(
    deadline: embassy_time::Instant,
    mut fut: Pin<&mut F>,
) -> impl Future<Output = Option<F::Output>> {
    let mut registered = false;
    poll_fn(move |cx| {
        if let Poll::Ready(output) = fut.as_mut().poll(cx) {
            return Poll::Ready(Some(output));
        }
        // The first pending poll registers without reading the clock (a deadline already past
        // wakes the task at once), as a `Timer` does.
        let at = if registered {
            if embassy_time::Instant::now() >= deadline {
                return Poll::Ready(None);
            }
            deadline + Duration::from_ticks(1)
        } else {
            registered = true;
            deadline
        };
        // A new Timer's first poll registers `at` for this task and is pending.
        let _ = Pin::new(&mut Timer::at(at)).poll(cx);
        Poll::Pending
    })
}

/// The control task's first tick after `now_us`: the ticks fall on whole periods of the uptime.
pub fn next_tick_us(now_us: u64) -> u64 {
    let (ticks, _) = div_rem_u64(now_us, PERIOD_US);
    (ticks + 1) * u64::from(PERIOD_US)
}

/// Makes `ticker` tick next at `schedule`'s deadline. `Ticker::reset_at(d)` ticks a period
/// after `d` (as if it had just ticked at `d`): given the deadline itself, the Ticker ran a period
/// behind the schedule after every flash write, each later step counted a period late (and the
/// scan, bounded by the schedule's next tick, was given none).
fn align(ticker: &mut Ticker, schedule: &TickSchedule) {
    let deadline = embassy_time::Instant::from_micros(schedule.deadline_us());
    ticker.reset_at(deadline.checked_sub(PERIOD).unwrap_or(deadline));
}

/// Queues a whole response for the printer, or nothing when it does not fit; true if queued.
pub fn queue_answer(bytes: &[u8]) -> bool {
    TX_PIPE.free_capacity() >= bytes.len() && TX_PIPE.try_write(bytes) == Ok(bytes.len())
}

/// The board's side of a reset ([`control::reset`] fixes the order): motors off, the answer
/// flushed, the state saved by the store task, then the restart.
struct Resetting<'a, M, const N: usize> {
    motors: &'a mut M,
    restart: fn() -> !,
}

impl<M: Motors<N>, const N: usize> ResetBoard for Resetting<'_, M, N> {
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
        (self.restart)()
    }
}

/// The store task: restores what the flash holds into the logic (then [`BOOTED`]), and then a
/// bounded piece of a save after each step, or the whole save before a reset. `range` is the
/// store's region of `flash`; `feed` reloads the board's watchdog.
pub async fn run_store<const N: usize, F: NorFlash, C: EntryCrc>(
    flash: F,
    crc: C,
    range: Range<u32>,
    logic: &Logic<N>,
    feed: fn(),
) -> ! {
    let mut keeper = {
        // The control task waits for BOOTED: nothing else borrows the logic yet.
        let Ok(mut control) = logic.try_borrow_mut() else {
            panic!("the logic is borrowed at boot")
        };
        boot_store(control.app_mut(), flash, crc, range, feed)
    };
    BOOTED.signal(());
    loop {
        match select(STEPPED.wait(), RESET.wait()).await {
            Either::First(()) => {
                let Ok(control) = logic.try_borrow() else {
                    continue;
                };
                // The control task deferred the piece after busy steps already.
                let wrote = keeper.update(control.app(), now());
                if let Some(_health) = keeper.take_news() {
                    log!(warn, "store: {}", _health);
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
                        Ok(()) => log!(info, "store: {} done", action),
                        Err(_e) => log!(error, "store: {} failed: {}", action, _e),
                    }
                }
                RESET_SAVED.signal(());
            }
        }
    }
}

/// Checks the CRC unit, then restores into `app` what the flash holds, before its first step.
/// Out of line: its frame (the keeper is built there) is gone before the store task loops.
#[inline(never)]
fn boot_store<const N: usize, F: NorFlash, C: EntryCrc>(
    app: &mut App<N>,
    flash: F,
    crc: C,
    range: Range<u32>,
    feed: fn(),
) -> Keeper<WatchedFlash<F>, N, CheckedCrc<C>> {
    let (crc, _check) = CheckedCrc::check(crc);
    if !crc.is_unit() {
        log!(
            error,
            "CRC unit: {=u32:#x} for the check value, not {=u32:#x}: the store uses the software CRC",
            _check,
            crate::persist::iso_hdlc::CHECK
        );
    }
    let mut flash = WatchedFlash::new(flash, feed);
    // The boot may repair the store (erase a damaged page): a job that runs whole.
    flash.allow_feeds(WHOLE_JOB_FEEDS);
    let Ok(store) = Store::with_crc(flash, crc, range) else {
        panic!("the store's region does not fit the flash")
    };
    let (mut keeper, boot) = Keeper::boot(store, app);
    keeper.store().flash().allow_feeds(0);
    match boot {
        Boot::Restored => log_restored(&keeper, app),
        Boot::Damaged(_damage) => log!(
            warn,
            "store: {=u16} unreadable double words, {=u16} torn entries (a power cut): the newest complete records are restored",
            _damage.unreadable,
            _damage.torn
        ),
    }
    keeper
}

/// What the boot restored.
fn log_restored<const N: usize, F: NorFlash, C: EntryCrc>(_keeper: &Keeper<F, N, C>, _app: &App<N>) {
    #[cfg(feature = "defmt")]
    {
        let snapshot = _keeper.snapshot(_app);
        let c = &snapshot.counters;
        defmt::info!(
            "restored: lanes {=[?]}, {=usize} settings, errors {=u16}, tool changes {=[?]}, failures {=[?]}, fed {=[?]} mm",
            &snapshot.lanes[..],
            snapshot.settings.len(),
            c.drive_errors,
            &c.tool_changes[..],
            &c.failures[..],
            &c.fed_mm[..]
        );
        if let Some(rule) = _app.refused_rule() {
            defmt::warn!(
                "restored settings refused (rule {=u8}, {}): running on the defaults",
                rule.code(),
                rule
            );
        }
    }
}

/// The link's transmit task: sends what the control task queued in [`TX_PIPE`].
pub async fn run_link_tx<W: embedded_io_async::Write>(mut tx: W) -> ! {
    let mut buf = [0u8; 64];
    loop {
        let count = TX_PIPE.read(&mut buf).await;
        TX_BUSY.store(true, Ordering::Relaxed);
        // A write error leaves nothing to retry: the printer asks again.
        let _ = tx.write_all(buf.get(..count).unwrap_or_default()).await;
        let _ = tx.flush().await;
        TX_BUSY.store(false, Ordering::Relaxed);
    }
}

/// The button task: publishes the button's level at every edge (the control loop debounces it).
pub async fn run_button<B: Button + embedded_hal_async::digital::Wait>(mut button: B) -> ! {
    let sender = BUTTON.sender();
    loop {
        sender.send(button.is_pressed().unwrap_or(false));
        let _ = button.wait_for_any_edge().await;
    }
}

/// The status LED task: lights the LED as the control task says.
pub async fn run_status_led<L: StatusLed>(mut led: L) -> ! {
    loop {
        let lit = LED.wait().await;
        let _ = led.set_lit(lit);
    }
}

/// The period's statistics, with what went wrong on the printer's receive line meanwhile.
fn log_stats(_stats: &control::Stats, _line: &LineErrors) {
    #[cfg(feature = "defmt")]
    if _stats.troubled() || _line.total() > 0 {
        defmt::warn!(
            "control: {=u32} steps, {=u32} late (max {=u64} us), {=u32} with stale samples, {=u32} watchdog feeds skipped, {=u32} responses dropped, {=u32} flash writes; received: {=u32} overruns, {=u32} garbled",
            _stats.steps,
            _stats.late,
            _stats.max_lateness_us,
            _stats.stale,
            _stats.unfed,
            _stats.tx_dropped,
            _stats.saves,
            _line.overruns,
            _line.garbled
        );
    } else {
        defmt::info!(
            "control: {=u32} steps on time, max lateness {=u64} us, {=u32} flash writes",
            _stats.steps,
            _stats.max_lateness_us,
            _stats.saves
        );
    }
}
