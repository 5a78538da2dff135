//! The control step: the body of every millisecond, written once and run by the firmware's
//! control task (src/tasks.rs) and by the simulator (sim/src/logic.rs) alike. Around it the board
//! only reads its peripherals, carries out what the step says, and resets through [`reset`],
//! which fixes the order a reset happens in.
//!
//! A step ([`ControlLoop::step`]):
//! - debounces the unit's button ([`Debounce`]) and presses it into the App;
//! - takes at most [`MAX_RX_PER_STEP`] bytes from the receive ring (the rest wait there for the
//!   next steps, so a burst of requests is spread over steps instead of stretching one), steps
//!   the [`App`] with them and the samples, and returns its answer to send now;
//! - feeds the watchdog only when it ran on time with fresh samples ([`feeds_watchdog`]): a
//!   stalled control loop or sampler resets the MCU, motors off;
//! - says whether a save piece runs after it ([`Deferral`]: not after a step busy with the printer
//!   or beginning a phase, unless several in a row were);
//! - counts statistics and reports them every [`STATS_PERIOD_MS`].

use mmu_hal_port::Samples;
use mmu_protocol::{ButtonCode, MAX_FRAME_LEN};

use crate::app::{App, BoardAction, Outputs, TX_CAPACITY};
use crate::time::{Instant, div_rem_u64};
use crate::uart::Received;

/// A step that starts later than this after its tick does not feed the watchdog, µs.
pub const ON_TIME_US: u64 = 2_000;
/// Samples older than this do not feed the watchdog (the sampler stalled), µs.
pub const MAX_SAMPLE_AGE_US: u64 = 5_000;
/// The button must read the same for this long to count, ms.
pub const DEBOUNCE_MS: u64 = 20;
/// Interval of the statistics report, ms.
pub const STATS_PERIOD_MS: u64 = 60_000;

/// The most received bytes one step decodes and answers. The printer link carries
/// [`LINE_BYTES_PER_S`] at most: a step that takes more than a millisecond's worth keeps up with
/// a printer that never pauses, and a burst that queued meanwhile (a late step, a save) is
/// answered over the next steps, a bounded amount of work in each. 12 bytes complete at most two
/// of the printer's requests (6 bytes and more: the end of one, then one whole), so a step
/// answers at most two.
pub const MAX_RX_PER_STEP: usize = 12;

/// Bytes the printer link carries per second at most: 115 200 Bd, 10 bits a byte.
pub const LINE_BYTES_PER_S: usize = 11_520;

/// [`LINE_BYTES_PER_S`] per millisecond, rounded up.
pub const LINE_BYTES_PER_MS: usize = LINE_BYTES_PER_S.div_ceil(1000);

/// The shortest frame the request decoder accepts: code, value, `*`, newline, when the empty CRC
/// field (0) matches (`Tab*\n`; a search of every shorter line finds none). Prusa's printer sends
/// 6 bytes and more (`Q0*ea\n`).
const MIN_REQUEST_LEN: usize = 5;

const _: () = {
    // The backlog of a printer that never pauses shrinks (by 0.48 bytes a step at least).
    assert!(MAX_RX_PER_STEP * 1000 > LINE_BYTES_PER_S);
    // Every request a step can complete (one finished by its first byte, then whole ones) has
    // room for its answer in the step's transmit buffer, so none is dropped for lack of room.
    assert!((1 + (MAX_RX_PER_STEP - 1) / MIN_REQUEST_LEN) * MAX_FRAME_LEN <= TX_CAPACITY);
};

/// When the control loop steps: every period on a fixed grid, the way Embassy's `Ticker` paces it
/// (a step that starts late is followed by the ones it delayed, at once), except after a flash
/// write or an overrun, whose missed ticks are dropped ([`TickSchedule::skip_missed`]).
#[derive(Debug, Clone, Copy)]
pub struct TickSchedule {
    next_us: u64,
    period_us: u16,
}

impl TickSchedule {
    /// The first step a period after `now_us`.
    pub const fn new(now_us: u64, period_us: u16) -> Self {
        TickSchedule {
            next_us: now_us + period_us as u64,
            period_us,
        }
    }

    /// When the next step is due, µs.
    pub const fn deadline_us(&self) -> u64 {
        self.next_us
    }

    /// The due step starts at `now_us`: returns how late, µs, and schedules the next one a period
    /// after this one's deadline.
    pub fn start(&mut self, now_us: u64) -> u64 {
        let lateness = now_us.saturating_sub(self.next_us);
        self.next_us += u64::from(self.period_us);
        lateness
    }

    /// The loop stalled until `now_us` (a flash write, a late step): the ticks missed meanwhile
    /// are dropped, and the next step is the first tick of the grid after `now_us`, so the steps
    /// keep their place in the millisecond (the firmware's `Ticker` is reset to it).
    pub fn skip_missed(&mut self, now_us: u64) {
        if self.next_us <= now_us && self.period_us > 0 {
            let missed = div_rem_u64(now_us - self.next_us, self.period_us).0 + 1;
            self.next_us += missed * u64::from(self.period_us);
        }
    }
}

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
    /// A save piece runs after this step (the firmware's store task, the simulator's keeper).
    pub save_piece: bool,
}

/// Busy steps in a row after which a save piece runs anyway: a printer that never pauses delays
/// a save by at most this many steps, ms, per piece.
pub const MAX_DEFERRED_STEPS: u8 = 8;

/// Busy steps in a row without a save piece: whether a step's piece runs ([`MAX_DEFERRED_STEPS`]).
/// A step busy with the printer or beginning a phase is a step's busiest; the piece waits for a
/// quieter one, but a save must end.
#[derive(Debug, Default, Clone, Copy)]
pub struct Deferral {
    deferred: u8,
}

impl Deferral {
    /// After a step that was `busy` (with the printer, or beginning a phase: the costliest
    /// steps): true when a save piece runs after it (not busy, or [`MAX_DEFERRED_STEPS`] busy
    /// steps in a row went without one).
    pub fn piece_due(&mut self, busy: bool) -> bool {
        if busy && self.deferred < MAX_DEFERRED_STEPS {
            self.deferred += 1;
            return false;
        }
        self.deferred = 0;
        true
    }
}

/// The App with the control loop's policy around it.
pub struct ControlLoop<const N: usize> {
    app: App<N>,
    button: Debounce,
    stats: Stats,
    deferral: Deferral,
}

impl<const N: usize> ControlLoop<N> {
    /// The loop around `app`, starting at `now`.
    pub fn new(app: App<N>, now: Instant) -> Self {
        ControlLoop {
            app,
            button: Debounce::new(now),
            stats: Stats::new(now),
            deferral: Deferral::default(),
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

    /// One control step at `tick`, with the oldest bytes waiting in `received` (see the module
    /// header).
    pub fn step(&mut self, tick: &Tick<N>, received: &mut impl Received) -> Step<N> {
        let button_pressed = self.button.pressed(tick.button_down, tick.now);
        if button_pressed {
            self.app.press_button(ButtonCode::MIDDLE);
        }
        let mut rx = [0u8; MAX_RX_PER_STEP];
        let taken = received.take(&mut rx);
        let out = self
            .app
            .step(tick.now, tick.samples, rx.get(..taken).unwrap_or_default());
        let feed_watchdog = out.action.is_none() && feeds_watchdog(tick.lateness_us, tick.sample_age_us);
        let busy = taken > 0 || !out.tx.is_empty() || out.phase_began;
        let save_piece = out.action.is_none() && self.deferral.piece_due(busy);

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
            save_piece,
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
#[allow(async_fn_in_trait)] // awaited under `block_on`, on one thread (the board, the tests)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::uart::{MemoryRing, ReceiveRing};
    use mmu_protocol::{Request, RequestCode, RequestDecoder};

    extern crate std;
    use std::string::String;
    use std::vec::Vec as StdVec;

    /// Mid-scale readings: every sensor healthy, no filament anywhere.
    const SAMPLES: Samples<3> = Samples::uniform(2048);

    /// The printer's bytes as a board receives them, in a ring of `R` bytes.
    type Ring<const R: usize> = ReceiveRing<MemoryRing<R>, R>;

    /// A unit past its start-up check, at `ms`.
    fn listening() -> (ControlLoop<3>, u64) {
        let mut control = ControlLoop::new(App::<3>::default(), Instant::ZERO);
        let mut ring = Ring::<64>::new(MemoryRing::new());
        let mut ms = 0;
        while !control.app().is_listening() || ms < 1500 {
            ms += 1;
            control.step(&tick(ms), &mut ring);
        }
        (control, ms)
    }

    fn tick(ms: u64) -> Tick<'static, 3> {
        Tick {
            now: Instant::from_millis(ms),
            lateness_us: 0,
            sample_age_us: 0,
            samples: &SAMPLES,
            button_down: false,
        }
    }

    /// Requests a printer polls with, in turn: each answer echoes its code and value (a `Q0`
    /// answer echoes the command, `X0` here).
    fn polls(count: usize) -> StdVec<Request> {
        let cycle = [
            Request::new(RequestCode::Read, 0x08),
            Request::new(RequestCode::Finda, 0),
            Request::new(RequestCode::Read, 0x1b),
            Request::new(RequestCode::Version, 1),
        ];
        cycle.iter().copied().cycle().take(count).collect()
    }

    /// The code and value each answer line starts with (`Q0`, `R8`, ...).
    fn echoes(tx: &[u8]) -> StdVec<String> {
        String::from_utf8_lossy(tx)
            .lines()
            .map(|line| line.split([' ', '*']).next().unwrap_or("").into())
            .collect()
    }

    fn echo(request: &Request) -> String {
        let frame = request.encode();
        let line = String::from_utf8_lossy(frame.as_bytes()).into_owned();
        line.split('*').next().unwrap_or("").into()
    }

    #[test]
    fn a_long_burst_is_answered_completely_and_in_order_over_several_steps() {
        let (mut control, mut ms) = listening();
        let requests = polls(40);
        let burst: StdVec<u8> = requests
            .iter()
            .flat_map(|r| r.encode().as_bytes().to_vec())
            .collect();
        assert!(burst.len() > 200, "{} bytes", burst.len());
        let mut ring = Ring::<256>::new(MemoryRing::new());
        // A printer catching up after a stall: the whole burst waits at once.
        ring.source_mut().receive(&burst);
        let mut sent = StdVec::new();
        let mut steps = 0;
        while sent.iter().filter(|&&b| b == b'\n').count() < requests.len() && steps < 1000 {
            ms += 1;
            steps += 1;
            sent.extend_from_slice(&control.step(&tick(ms), &mut ring).out.tx);
        }
        // A step's bytes at most each step: the last request completes in the last step.
        assert_eq!(steps, burst.len().div_ceil(MAX_RX_PER_STEP));
        let expected: StdVec<String> = requests.iter().map(echo).collect();
        assert!(echoes(&sent) == expected, "answered {:?}", echoes(&sent));
        assert_eq!(control.app().read_register(0x51), Some(0), "no answer dropped");
        assert_eq!(ring.errors().total(), 0);
    }

    #[test]
    fn a_printer_that_never_pauses_is_answered_within_two_steps_and_never_overruns() {
        // The line full for 5 s: a request starts the moment the last one ends, the bytes
        // arriving at 115 200 Bd (11.52 a ms). The unit answers each request within 2 ms of its
        // last byte, whatever waits behind it, and the backlog stays bounded.
        let (mut control, mut ms) = listening();
        let requests = polls(10_000);
        let line: StdVec<(usize, u8)> = requests
            .iter()
            .enumerate()
            .flat_map(|(i, r)| {
                r.encode()
                    .as_bytes()
                    .iter()
                    .map(move |&b| (i, b))
                    .collect::<StdVec<_>>()
            })
            .collect();
        let mut ring = Ring::<{ crate::uart::rx_ring_needed(1).next_power_of_two() }>::new(MemoryRing::new());
        let mut at = 0;
        let mut answered = 0;
        let mut most_waiting = 0;
        let mut sent = StdVec::new();
        for step in 0..5000u64 {
            // Bytes that arrived by the end of this millisecond.
            let due = usize::try_from(step + 1).unwrap_or(usize::MAX) * LINE_BYTES_PER_S / 1000;
            while at < due.min(line.len()) {
                ring.source_mut().receive(&[line[at].1]);
                at += 1;
            }
            most_waiting = most_waiting.max(ring.waiting());
            ms += 1;
            let out = control.step(&tick(ms), &mut ring).out;
            sent.extend_from_slice(&out.tx);
            let now_answered = answered + out.tx.iter().filter(|&&b| b == b'\n').count();
            // Every request whose last byte arrived before the previous step is answered.
            let complete_before = line[..at.saturating_sub(LINE_BYTES_PER_MS + 1)]
                .last()
                .map_or(0, |&(i, _)| i);
            assert!(
                now_answered >= complete_before,
                "step {step}: {now_answered} < {complete_before}"
            );
            answered = now_answered;
        }
        assert!(answered > 5000 * 11 / 7, "{answered} requests answered");
        let expected: StdVec<String> = requests[..answered].iter().map(echo).collect();
        assert!(echoes(&sent) == expected, "answers out of order");
        assert!(
            most_waiting <= LINE_BYTES_PER_MS + MAX_RX_PER_STEP,
            "{most_waiting} bytes waited"
        );
        assert_eq!(ring.errors().total(), 0, "never lapped");
        assert_eq!(control.app().read_register(0x51), Some(0));
    }

    #[test]
    fn no_line_shorter_than_the_shortest_request_decodes() {
        // Every line of fewer than MIN_REQUEST_LEN bytes over the bytes a request is made of.
        let alphabet = b"TLUEKHXQSRWBFfPM0123456789abcdef* \n";
        let decodes = |line: &[u8]| {
            let mut decoder = RequestDecoder::new();
            line.iter().any(|&b| matches!(decoder.feed(b), Some(Ok(_))))
        };
        for len in 1..MIN_REQUEST_LEN {
            let mut line = [0u8; MIN_REQUEST_LEN];
            for mut n in 0..alphabet.len().pow(len as u32) {
                for byte in line.iter_mut().take(len) {
                    *byte = alphabet[n % alphabet.len()];
                    n /= alphabet.len();
                }
                assert!(!decodes(&line[..len]), "{:?}", &line[..len]);
            }
        }
        assert!(decodes(b"Tab*\n"));
    }

    #[test]
    fn the_schedule_reports_lateness_keeps_its_grid_and_drops_what_a_flash_write_stalled() {
        let mut schedule = TickSchedule::new(500, 1_000);
        assert_eq!(schedule.deadline_us(), 1_500);
        assert_eq!(schedule.start(1_500), 0);
        assert_eq!(schedule.start(2_530), 30, "a step 30 us late");
        assert_eq!(schedule.deadline_us(), 3_500, "the grid is kept");
        // A step overran to 6 200: the steps it delayed follow at once, each knowing how late.
        let late: StdVec<u64> = (0..3).map(|_| schedule.start(6_200)).collect();
        assert_eq!(late, [2_700, 1_700, 700]);
        assert_eq!(schedule.deadline_us(), 6_500);
        // A flash write stalled the CPU until 50 200: no burst of late steps after it.
        schedule.skip_missed(50_200);
        assert_eq!(schedule.deadline_us(), 50_500);
        assert_eq!(schedule.start(50_500), 0);
    }

    #[test]
    fn skipping_missed_ticks_keeps_the_grid() {
        let mut schedule = TickSchedule::new(0, 1_000);
        assert_eq!(schedule.start(1_000), 0);
        // A save stalled the CPU until 41 090: the ticks up to 41 000 are dropped, the next is
        // 42 000, still on the grid.
        schedule.skip_missed(41_090);
        assert_eq!(schedule.deadline_us(), 42_000);
        assert_eq!(schedule.start(42_000), 0);
        // On time: nothing to skip.
        schedule.skip_missed(42_300);
        assert_eq!(schedule.deadline_us(), 43_000);
    }

    /// The deferral: after busy steps, a piece every `MAX_DEFERRED_STEPS + 1`th;
    /// a quiet step runs one and starts the count over.
    #[test]
    fn a_deferral_runs_a_piece_after_max_deferred_busy_steps() {
        let mut deferral = Deferral::default();
        for _ in 0..3 {
            for _ in 0..MAX_DEFERRED_STEPS {
                assert!(!deferral.piece_due(true));
            }
            assert!(deferral.piece_due(true));
        }
        assert!(!deferral.piece_due(true));
        assert!(deferral.piece_due(false));
        assert!(deferral.piece_due(false));
        for _ in 0..MAX_DEFERRED_STEPS {
            assert!(!deferral.piece_due(true));
        }
    }
}
