//! The control loop's policy: what the board's main loop decides around each step of the
//! [`App`], kept here so host tests run it. The board only reads its peripherals, calls
//! [`ControlLoop::step`] every millisecond, carries out what it says, and resets through
//! [`reset`], which fixes the order a reset happens in.
//!
//! - the unit's button is debounced ([`Debounce`]) and pressed into the App;
//! - the watchdog is fed only by a step that ran on time with fresh samples
//!   ([`feeds_watchdog`]): a stalled control loop or sampler resets the MCU, motors off;
//! - statistics are counted and reported every [`STATS_PERIOD_MS`].

use mmu_hal_port::Samples;
use mmu_protocol::ButtonCode;

use crate::app::{App, BoardAction, Outputs};
use crate::time::Instant;

/// A step that starts later than this after its tick does not feed the watchdog, µs.
pub const ON_TIME_US: u64 = 2_000;
/// Samples older than this do not feed the watchdog (the sampler stalled), µs.
pub const MAX_SAMPLE_AGE_US: u64 = 5_000;
/// The button must read the same for this long to count, ms.
pub const DEBOUNCE_MS: u64 = 20;
/// Interval of the statistics report, ms.
pub const STATS_PERIOD_MS: u64 = 60_000;

/// True when a step may feed the watchdog: it started at most [`ON_TIME_US`] late and its samples
/// are at most [`MAX_SAMPLE_AGE_US`] old.
pub const fn feeds_watchdog(lateness_us: u64, sample_age_us: u64) -> bool {
    lateness_us <= ON_TIME_US && sample_age_us <= MAX_SAMPLE_AGE_US
}

/// Turns the raw button level into one event per press.
#[derive(Debug, Clone, Copy)]
pub struct Debounce {
    /// The level last read and since when.
    raw: bool,
    since: Instant,
    /// The debounced level.
    stable: bool,
}

impl Debounce {
    /// A released button at `now`.
    pub const fn new(now: Instant) -> Self {
        Debounce {
            raw: false,
            since: now,
            stable: false,
        }
    }

    /// Feeds the current level; true once per press, when it has held for [`DEBOUNCE_MS`].
    pub fn pressed(&mut self, down: bool, now: Instant) -> bool {
        if down != self.raw {
            self.raw = down;
            self.since = now;
        }
        if self.raw != self.stable && now.millis_since(self.since) >= DEBOUNCE_MS {
            self.stable = self.raw;
            return self.stable;
        }
        false
    }
}

/// What the control loop counted over one [`STATS_PERIOD_MS`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Stats {
    /// When the period began.
    pub since: Instant,
    /// Steps run.
    pub steps: u32,
    /// Steps that started more than [`ON_TIME_US`] late.
    pub late: u32,
    /// The latest start, µs.
    pub max_lateness_us: u64,
    /// Steps with samples older than [`MAX_SAMPLE_AGE_US`].
    pub stale: u32,
    /// Steps that did not feed the watchdog.
    pub unfed: u32,
    /// Responses the board could not queue for sending.
    pub tx_dropped: u32,
    /// Flash writes (each stalled the CPU).
    pub saves: u32,
}

impl Stats {
    const fn new(since: Instant) -> Self {
        Stats {
            since,
            steps: 0,
            late: 0,
            max_lateness_us: 0,
            stale: 0,
            unfed: 0,
            tx_dropped: 0,
            saves: 0,
        }
    }

    /// True when the period saw anything worth a warning.
    pub const fn troubled(&self) -> bool {
        self.late + self.stale + self.tx_dropped > 0
    }
}

/// One tick of the board: the time, how late the tick came, and what the peripherals read.
pub struct Tick<'a, const N: usize> {
    /// Now.
    pub now: Instant,
    /// How late this step starts after its tick, µs.
    pub lateness_us: u64,
    /// How old the samples are, µs.
    pub sample_age_us: u64,
    /// The latest sensor scan.
    pub samples: &'a Samples<N>,
    /// The bytes the printer sent since the last step.
    pub rx: &'a [u8],
    /// The unit's button is held down.
    pub button_down: bool,
}

/// What the board must do after a step.
pub struct Step<const N: usize> {
    /// The App's outputs: motors, bytes to send, a reset.
    pub out: Outputs<N>,
    /// Feed the watchdog.
    pub feed_watchdog: bool,
    /// The button was pressed in this step.
    pub button_pressed: bool,
    /// A period's statistics, to log.
    pub report: Option<Stats>,
}

/// The App with the control loop's policy around it.
pub struct ControlLoop<const N: usize> {
    app: App<N>,
    button: Debounce,
    stats: Stats,
}

impl<const N: usize> ControlLoop<N> {
    /// The loop around `app`, starting at `now`.
    pub fn new(app: App<N>, now: Instant) -> Self {
        ControlLoop {
            app,
            button: Debounce::new(now),
            stats: Stats::new(now),
        }
    }

    /// The unit logic.
    pub fn app(&self) -> &App<N> {
        &self.app
    }

    /// The unit logic, to restore what the flash kept before the first step.
    pub fn app_mut(&mut self) -> &mut App<N> {
        &mut self.app
    }

    /// One control step.
    pub fn step(&mut self, tick: &Tick<N>) -> Step<N> {
        let button_pressed = self.button.pressed(tick.button_down, tick.now);
        if button_pressed {
            self.app.press_button(ButtonCode::MIDDLE);
        }
        let out = self.app.step(tick.now, tick.samples, tick.rx);
        let feed_watchdog = out.action.is_none() && feeds_watchdog(tick.lateness_us, tick.sample_age_us);

        let stats = &mut self.stats;
        stats.steps += 1;
        stats.late += u32::from(tick.lateness_us > ON_TIME_US);
        stats.stale += u32::from(tick.sample_age_us > MAX_SAMPLE_AGE_US);
        stats.unfed += u32::from(!feed_watchdog);
        stats.max_lateness_us = stats.max_lateness_us.max(tick.lateness_us);
        let report = (tick.now.millis_since(stats.since) >= STATS_PERIOD_MS)
            .then(|| core::mem::replace(stats, Stats::new(tick.now)));
        Step {
            out,
            feed_watchdog,
            button_pressed,
            report,
        }
    }

    /// The board could not queue a step's response bytes: logged, and counted in register 0x51.
    pub fn tx_dropped(&mut self) {
        self.stats.tx_dropped += 1;
        self.app.count_dropped_response();
    }

    /// The board wrote to flash after the step.
    pub fn saved(&mut self) {
        self.stats.saves += 1;
    }
}

/// What a reset needs from the board.
#[allow(async_fn_in_trait)] // implemented and awaited in one single-threaded executor
pub trait ResetBoard {
    /// Every motor off.
    fn stop_motors(&mut self);
    /// Wait until the last response has left the UART (bounded).
    async fn flush(&mut self);
    /// Save the state (`X0`) or forget it (`X42`).
    async fn persist(&mut self, action: BoardAction);
    /// Restart the MCU.
    fn restart(&mut self);
}

/// Carry out `action` in the one safe order: motors off first, then the answer flushed, then
/// the state saved or forgotten, then the restart.
pub async fn reset(board: &mut impl ResetBoard, action: BoardAction) {
    board.stop_motors();
    board.flush().await;
    board.persist(action).await;
    board.restart();
}
