//! The control loop's policy: what the board's main loop decides around each step of the
//! [`App`], kept here so host tests run it. The board only reads its peripherals, calls
//! [`ControlLoop::step`] every millisecond, carries out what it says, and resets through
//! [`reset`], which fixes the order a reset happens in.
//!
//! - the unit's button is debounced ([`Debounce`]) and pressed into the App;
//! - the watchdog is fed only by a step that ran on time with fresh samples
//!   ([`feeds_watchdog`]): a stalled control loop or sampler resets the MCU, motors off;
//! - statistics are counted and reported every [`STATS_PERIOD_MS`];
//! - a step decodes and answers at most [`MAX_RX_PER_STEP`] received bytes; the rest wait in the
//!   UART's receive ring for the next steps ([`RxQueue`] is that rule for the host and the
//!   step-cost benchmark), so a burst of requests is spread over steps instead of stretching one.

use heapless::{Deque, Vec};
use mmu_hal_port::Samples;
use mmu_protocol::{ButtonCode, MAX_FRAME_LEN};

use crate::app::{App, BoardAction, Outputs, TX_CAPACITY};
use crate::time::Instant;

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

/// The receive ring a board needs so that no byte is lost while the control loop does not step
/// for `gap_ms` (a late step, the instructions of a save) with the printer sending without pause:
/// what arrives meanwhile plus what a step leaves waiting.
pub const fn rx_ring_needed(gap_ms: usize) -> usize {
    gap_ms * LINE_BYTES_PER_MS + MAX_RX_PER_STEP
}

/// The longest the control loop may go without a step and lose no received byte, ms: far beyond
/// a step late enough to miss the watchdog feed ([`ON_TIME_US`]) plus a save's instructions
/// (about 1.5 ms; during a flash stall the UART interrupt stalls too, and what the receiver's
/// own buffer cannot hold is lost whatever the ring).
pub const RX_GAP_MS: usize = 20;

/// The receive ring of the board's printer UART (`src/board.rs`), and of the [`RxQueue`] that
/// stands for it in the step-cost benchmark.
pub const RX_RING: usize = 256;

const _: () = assert!(RX_RING >= rx_ring_needed(RX_GAP_MS));

/// The longest a flash page erase stalls the NUCLEO-G071RB's CPU, ms (RM0444 / the STM32G071
/// datasheet: page erase 40 ms at most). The UART's DMA keeps receiving meanwhile.
pub const G071_ERASE_STALL_MS: usize = 40;
/// The printer UART's DMA receive ring on the NUCLEO-G071RB: what arrives during the longest
/// erase with the printer sending without pause, plus a step's worth (`crate::uart` tests it).
pub const G071_DMA_RING: usize = 512;
/// The longest a 4 KiB sector erase of the Pico's QSPI flash stalls its CPU, ms (W25Q16JV
/// datasheet, sector erase: 45 ms typical, 400 ms at most; embassy-rp's flash driver runs it
/// with interrupts off).
pub const PICO_ERASE_STALL_MS: usize = 400;
/// The printer UART's DMA receive ring on the Pico, as [`G071_DMA_RING`].
pub const PICO_DMA_RING: usize = 8192;

const _: () = assert!(G071_DMA_RING >= rx_ring_needed(G071_ERASE_STALL_MS));
const _: () = assert!(PICO_DMA_RING >= rx_ring_needed(PICO_ERASE_STALL_MS));

/// The bytes received from the printer that wait for the control loop, oldest first, with the
/// loop's rule: each step takes at most [`MAX_RX_PER_STEP`] of them. The board's UART driver
/// ([`crate::uart`]) does the same, and its tests check that it hands out what this does; this
/// one serves the host, the tests and the step-cost benchmark (`bench-mcu`), which must hand the
/// App exactly what the board would.
#[derive(Debug, Clone, Default)]
pub struct RxQueue<const CAPACITY: usize> {
    bytes: Deque<u8, CAPACITY>,
    lost: u32,
}

impl<const CAPACITY: usize> RxQueue<CAPACITY> {
    /// An empty queue.
    pub const fn new() -> Self {
        RxQueue {
            bytes: Deque::new(),
            lost: 0,
        }
    }

    /// Bytes that arrived from the line. Those that find the queue full are lost, as a UART
    /// overrun loses them, and counted.
    pub fn receive(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            if self.bytes.push_back(byte).is_err() {
                self.lost = self.lost.saturating_add(1);
            }
        }
    }

    /// The bytes for the next step: at most [`MAX_RX_PER_STEP`], oldest first.
    pub fn take_step(&mut self) -> Vec<u8, MAX_RX_PER_STEP> {
        let mut step = Vec::new();
        while !step.is_full() {
            match self.bytes.pop_front() {
                // Cannot fail: not full.
                Some(byte) => {
                    let _ = step.push(byte);
                }
                None => break,
            }
        }
        step
    }

    /// Bytes waiting.
    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    /// True when no byte waits.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// Bytes lost to a full queue since it was made.
    pub fn lost(&self) -> u32 {
        self.lost
    }
}

/// When the control loop steps: every period on a fixed grid, the way Embassy's `Ticker` paced it
/// (a step that starts late is followed by the ones it delayed, at once), except after a flash
/// write, whose missed ticks are dropped ([`TickSchedule::restart`]).
#[derive(Debug, Clone, Copy)]
pub struct TickSchedule {
    next_us: u64,
    period_us: u64,
}

impl TickSchedule {
    /// The first step a period after `now_us`.
    pub const fn new(now_us: u64, period_us: u64) -> Self {
        TickSchedule {
            next_us: now_us + period_us,
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
        self.next_us += self.period_us;
        lateness
    }

    /// The loop stalled until `now_us` (a flash write): the next step a period from now, the
    /// ticks missed meanwhile dropped.
    pub fn restart(&mut self, now_us: u64) {
        self.next_us = now_us + self.period_us;
    }

    /// The loop stalled until `now_us` (a flash write, a late step): the ticks missed meanwhile
    /// are dropped, and the next step is the first tick of the grid after `now_us`, so the steps
    /// keep their place in the millisecond (the firmware's `Ticker` is reset to it).
    pub fn skip_missed(&mut self, now_us: u64) {
        if self.next_us <= now_us && self.period_us > 0 {
            let missed = (now_us - self.next_us) / self.period_us + 1;
            self.next_us += missed * self.period_us;
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
    /// The bytes received from the printer for this step: at most [`MAX_RX_PER_STEP`], the
    /// oldest waiting (the rest wait for the next steps).
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

impl<const N: usize> Step<N> {
    /// Nothing to do ([`Outputs::none`]), no feed, no press, no report.
    pub fn none() -> Self {
        Step {
            out: Outputs::none(),
            feed_watchdog: false,
            button_pressed: false,
            report: None,
        }
    }
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
        let mut step = Step::none();
        self.step_into(tick, &mut step);
        step
    }

    /// [`ControlLoop::step`] written into `step` (whatever it held is replaced): the control
    /// task keeps one, rather than having every step's (120 bytes with three slots) copied out.
    pub fn step_into(&mut self, tick: &Tick<N>, step: &mut Step<N>) {
        let button_pressed = self.button.pressed(tick.button_down, tick.now);
        if button_pressed {
            self.app.press_button(ButtonCode::MIDDLE);
        }
        step.button_pressed = button_pressed;
        self.app.step_into(tick.now, tick.samples, tick.rx, &mut step.out);
        let feed_watchdog = step.out.action.is_none() && feeds_watchdog(tick.lateness_us, tick.sample_age_us);
        step.feed_watchdog = feed_watchdog;

        let stats = &mut self.stats;
        stats.steps += 1;
        stats.late += u32::from(tick.lateness_us > ON_TIME_US);
        stats.stale += u32::from(tick.sample_age_us > MAX_SAMPLE_AGE_US);
        stats.unfed += u32::from(!feed_watchdog);
        stats.max_lateness_us = stats.max_lateness_us.max(tick.lateness_us);
        step.report = (tick.now.millis_since(stats.since) >= STATS_PERIOD_MS)
            .then(|| core::mem::replace(stats, Stats::new(tick.now)));
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
    use mmu_protocol::{Request, RequestCode, RequestDecoder};

    extern crate std;
    use std::string::String;
    use std::vec::Vec as StdVec;

    /// Mid-scale readings: every sensor healthy, no filament anywhere.
    const SAMPLES: Samples<3> = Samples::uniform(2048);

    /// A unit past its start-up check, at `ms`.
    fn listening() -> (ControlLoop<3>, u64) {
        let mut control = ControlLoop::new(App::<3>::default(), Instant::ZERO);
        let mut ms = 0;
        while !control.app().is_listening() || ms < 1500 {
            ms += 1;
            control.step(&tick(ms, &[]));
        }
        (control, ms)
    }

    fn tick(ms: u64, rx: &[u8]) -> Tick<'_, 3> {
        Tick {
            now: Instant::from_millis(ms),
            lateness_us: 0,
            sample_age_us: 0,
            samples: &SAMPLES,
            rx,
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
        let mut queue = RxQueue::<256>::new();
        // A printer catching up after a stall: the whole burst waits at once.
        queue.receive(&burst);
        let mut sent = StdVec::new();
        let mut steps = 0;
        while !queue.is_empty() {
            let rx = queue.take_step();
            assert!(rx.len() <= MAX_RX_PER_STEP);
            ms += 1;
            steps += 1;
            sent.extend_from_slice(&control.step(&tick(ms, &rx)).out.tx);
        }
        assert_eq!(steps, burst.len().div_ceil(MAX_RX_PER_STEP));
        let expected: StdVec<String> = requests.iter().map(echo).collect();
        assert!(echoes(&sent) == expected, "answered {:?}", echoes(&sent));
        assert_eq!(control.app().read_register(0x51), Some(0), "no answer dropped");
        assert_eq!(queue.lost(), 0);
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
        let mut queue = RxQueue::<{ rx_ring_needed(1) }>::new();
        let mut at = 0;
        let mut answered = 0;
        let mut most_waiting = 0;
        let mut sent = StdVec::new();
        for step in 0..5000u64 {
            // Bytes that arrived by the end of this millisecond.
            let due = usize::try_from(step + 1).unwrap_or(usize::MAX) * LINE_BYTES_PER_S / 1000;
            while at < due.min(line.len()) {
                queue.receive(&[line[at].1]);
                at += 1;
            }
            most_waiting = most_waiting.max(queue.len());
            let rx = queue.take_step();
            ms += 1;
            let out = control.step(&tick(ms, &rx)).out;
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
        assert_eq!(queue.lost(), 0);
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
        // A flash write stalled the CPU until 50 000: no burst of late steps after it.
        schedule.restart(50_000);
        assert_eq!(schedule.deadline_us(), 51_000);
        assert_eq!(schedule.start(51_000), 0);
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

    #[test]
    fn the_queue_hands_out_at_most_a_step_s_bytes_in_order_and_counts_what_overflows() {
        let mut queue = RxQueue::<{ MAX_RX_PER_STEP + 4 }>::new();
        let bytes: StdVec<u8> = (0..MAX_RX_PER_STEP as u8 + 9).collect();
        queue.receive(&bytes);
        assert_eq!(queue.lost(), 5);
        assert_eq!(queue.take_step().as_slice(), &bytes[..MAX_RX_PER_STEP]);
        assert_eq!(
            queue.take_step().as_slice(),
            &bytes[MAX_RX_PER_STEP..MAX_RX_PER_STEP + 4]
        );
        assert!(queue.take_step().is_empty());
    }
}
