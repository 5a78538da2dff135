//! `tasks::bounded`, the control task's bound on the sensor scan, on the stack the firmware runs:
//! embassy-executor 0.10's raw executor and embassy-time-queue-utils 0.3's timer queue, behind a
//! time driver on a virtual clock that counts the registrations the queue takes as a change (on
//! the boards, each one a walk of the queue and the alarm set again). The scan stands in as a
//! future woken from outside, as the Pico's DMA interrupt wakes its nine transfers.
//!
//! Needs the `tasks` feature: `cargo test -p mmu-firmware --features tasks --test bounded`.
#![cfg(feature = "tasks")]

use core::future::{Future, poll_fn};
use core::pin::{Pin, pin};
use core::task::{Poll, Waker};
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};

use embassy_executor::raw::Executor;
use embassy_time::{Instant, Timer, with_deadline};
use embassy_time_queue_utils::Queue;
use mmu_firmware::tasks::bounded;

/// The virtual clock, µs (embassy-time ticks at 1 MHz).
static NOW: AtomicU64 = AtomicU64::new(0);
/// The timer queue, as the boards' time drivers keep it.
static QUEUE: Mutex<Queue> = Mutex::new(Queue::new());
/// Registrations the queue took as a change (`schedule_wake` returned true).
static CHANGES: AtomicU32 = AtomicU32::new(0);
/// The executor asked to be polled.
static PENDED: AtomicBool = AtomicBool::new(false);
/// The scan's waker, as the DMA channel keeps it; and how its bound ended.
static SCAN: Mutex<Option<Waker>> = Mutex::new(None);
static OUTCOME: Mutex<Option<Outcome>> = Mutex::new(None);
/// One scenario at a time: the executor's task, the clock and the queue are shared.
static SERIAL: Mutex<()> = Mutex::new(());

#[derive(Debug, PartialEq)]
enum Outcome {
    /// The scan ended first.
    Scanned,
    /// The bound passed first, at this instant.
    TimedOut(u64),
}

struct Driver;

impl embassy_time_driver::Driver for Driver {
    fn now(&self) -> u64 {
        NOW.load(Ordering::SeqCst)
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        if QUEUE.lock().unwrap().schedule_wake(at, waker) {
            CHANGES.fetch_add(1, Ordering::SeqCst);
        }
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: Driver = Driver);

#[unsafe(export_name = "__pender")]
fn pender(_context: *mut ()) {
    PENDED.store(true, Ordering::SeqCst);
}

/// One thread at a time (SERIAL): nothing to mask.
struct NoInterrupts;
critical_section::set_impl!(NoInterrupts);
// SAFETY: the scenarios run one at a time on one thread.
unsafe impl critical_section::Impl for NoInterrupts {
    unsafe fn acquire() -> critical_section::RawRestoreState {}

    unsafe fn release(_restore: critical_section::RawRestoreState) {}
}

/// The scan: pending until `wake_scan` and `finish`, or forever.
fn scan(finish: &'static AtomicBool) -> impl Future<Output = ()> {
    poll_fn(move |cx| {
        if finish.load(Ordering::SeqCst) {
            return Poll::Ready(());
        }
        *SCAN.lock().unwrap() = Some(cx.waker().clone());
        Poll::Pending
    })
}

static FINISH: AtomicBool = AtomicBool::new(false);
/// Registered before the scan: a stale registration of the task at this instant (0: none).
static STALE_US: AtomicU64 = AtomicU64::new(0);
/// The bound, µs.
const DEADLINE_US: u64 = 500;

// A task per scenario: a task's timer registration lives in its own storage, which the
// queue of the next scenario must not find still set.
#[embassy_executor::task]
async fn bounded_timeout_task() {
    run_bounded().await
}

#[embassy_executor::task]
async fn bounded_scanned_task() {
    run_bounded().await
}

#[embassy_executor::task]
async fn bounded_stale_task() {
    run_bounded().await
}

/// A step's scan under `bounded`, after the stale registration a late step can leave.
async fn run_bounded() {
    register_stale().await;
    let scanned = pin!(scan(&FINISH));
    let outcome = match bounded(Instant::from_micros(DEADLINE_US), scanned).await {
        Some(()) => Outcome::Scanned,
        None => Outcome::TimedOut(NOW.load(Ordering::SeqCst)),
    };
    *OUTCOME.lock().unwrap() = Some(outcome);
}

/// The same under embassy-time's `with_deadline`.
#[embassy_executor::task]
async fn with_deadline_task() {
    register_stale().await;
    let outcome = match with_deadline(Instant::from_micros(DEADLINE_US), scan(&FINISH)).await {
        Ok(()) => Outcome::Scanned,
        Err(_) => Outcome::TimedOut(NOW.load(Ordering::SeqCst)),
    };
    *OUTCOME.lock().unwrap() = Some(outcome);
}

/// Registers a wake-up at [`STALE_US`] for this task and moves on without waiting for it.
async fn register_stale() {
    let at = STALE_US.load(Ordering::SeqCst);
    if at == 0 {
        return;
    }
    let mut timer = Timer::at(Instant::from_micros(at));
    poll_fn(|cx| {
        let _ = Pin::new(&mut timer).poll(cx);
        Poll::Ready(())
    })
    .await;
}

/// The scenario's world: a fresh queue and clock, the task spawned and polled at 0.
struct World {
    executor: &'static Executor,
}

impl World {
    fn start(stale_us: u64, spawn: fn(&embassy_executor::Spawner)) -> Self {
        *QUEUE.lock().unwrap() = Queue::new();
        NOW.store(0, Ordering::SeqCst);
        CHANGES.store(0, Ordering::SeqCst);
        FINISH.store(false, Ordering::SeqCst);
        STALE_US.store(stale_us, Ordering::SeqCst);
        *SCAN.lock().unwrap() = None;
        *OUTCOME.lock().unwrap() = None;
        let executor: &'static Executor = Box::leak(Box::new(Executor::new(core::ptr::null_mut())));
        spawn(&executor.spawner());
        let world = World { executor };
        world.run();
        world
    }

    /// The executor until no task is ready.
    fn run(&self) {
        while PENDED.swap(false, Ordering::SeqCst) {
            // SAFETY: one thread, not from the pender.
            unsafe { self.executor.poll() };
        }
    }

    /// The clock at `us`, the alarm's expired registrations woken, the executor run.
    fn at(&self, us: u64) {
        NOW.store(us, Ordering::SeqCst);
        let _ = QUEUE.lock().unwrap().next_expiration(us);
        self.run();
    }

    /// The scan's interrupt at `us`: its waker woken (the DMA's completion), the executor run.
    fn wake_scan(&self, us: u64) {
        NOW.store(us, Ordering::SeqCst);
        let _ = QUEUE.lock().unwrap().next_expiration(us);
        if let Some(waker) = SCAN.lock().unwrap().take() {
            waker.wake();
        }
        self.run();
    }

    /// The first alarm after now: when the queue would wake a task next.
    fn next_alarm(&self) -> u64 {
        QUEUE.lock().unwrap().next_expiration(NOW.load(Ordering::SeqCst))
    }
}

/// The nine wake-ups of the Pico's scan, 30 µs apart, before the bound.
const WAKE_UPS: [u64; 8] = [30, 60, 90, 120, 150, 180, 210, 240];

#[test]
fn with_deadline_registers_the_bound_as_a_change_at_every_wake_up() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let world = World::start(0, |s| s.spawn(with_deadline_task().unwrap()));
    assert_eq!(CHANGES.load(Ordering::SeqCst), 1);
    for us in WAKE_UPS {
        world.wake_scan(us);
    }
    // Each wake-up's poll registered the same instant again, and the queue took it as a change.
    assert_eq!(CHANGES.load(Ordering::SeqCst), 1 + WAKE_UPS.len() as u32);
}

#[test]
fn bounded_registers_the_bound_once_across_the_wake_ups_and_ends_the_scan_at_it() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let world = World::start(0, |s| s.spawn(bounded_timeout_task().unwrap()));
    assert_eq!(CHANGES.load(Ordering::SeqCst), 1);
    assert_eq!(world.next_alarm(), DEADLINE_US);
    for us in WAKE_UPS {
        world.wake_scan(us);
    }
    assert_eq!(CHANGES.load(Ordering::SeqCst), 1, "a wake-up changed the queue");
    assert_eq!(*OUTCOME.lock().unwrap(), None);
    world.at(DEADLINE_US - 1);
    assert_eq!(*OUTCOME.lock().unwrap(), None);
    world.at(DEADLINE_US);
    assert_eq!(*OUTCOME.lock().unwrap(), Some(Outcome::TimedOut(DEADLINE_US)));
}

#[test]
fn bounded_returns_the_scan_when_it_ends_first() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let world = World::start(0, |s| s.spawn(bounded_scanned_task().unwrap()));
    world.wake_scan(30);
    FINISH.store(true, Ordering::SeqCst);
    world.wake_scan(60);
    assert_eq!(*OUTCOME.lock().unwrap(), Some(Outcome::Scanned));
}

#[test]
fn a_stale_earlier_registration_that_expires_during_the_scan_does_not_take_the_bound_with_it() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    // The task's one registration holds the earliest instant asked for: 100 µs, not the bound.
    let world = World::start(100, |s| s.spawn(bounded_stale_task().unwrap()));
    assert_eq!(world.next_alarm(), 100);
    world.wake_scan(30);
    world.wake_scan(60);
    // The stale one expires and wakes the task: the bound is registered again (1 µs later).
    world.at(100);
    assert_eq!(world.next_alarm(), DEADLINE_US + 1);
    world.wake_scan(130);
    // No wake-up from the scan after that (a stuck conversion): the bound still ends it.
    world.at(DEADLINE_US);
    assert_eq!(*OUTCOME.lock().unwrap(), None);
    world.at(DEADLINE_US + 1);
    assert_eq!(*OUTCOME.lock().unwrap(), Some(Outcome::TimedOut(DEADLINE_US + 1)));
}
