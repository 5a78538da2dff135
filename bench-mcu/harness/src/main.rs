//! The step-cost harness: the firmware's tasks (`mmu_firmware::tasks`: control, store, the
//! printer link, button, LED) on Embassy's executor and embassy-time, built for thumbv6m-none-eabi
//! with the firmware's profile, replaying a recorded session in an emulator (`bench-mcu/run.py`).
//!
//! Every millisecond of the session is what the firmware's CPU does in it: the bytes that arrived
//! on the line are handed to the link's receive task half a millisecond before the tick (as the
//! UART's DMA ring would, the task woken as by its interrupt), then the tick: the time driver's
//! alarm (embassy's timer queue, as the driver's interrupt runs it) and the executor polled until
//! no task is ready (the thread executor's loop without its WFE): the control task (Ticker, sensor
//! scan with its timeout, `ControlLoop::step` with at most `control::MAX_RX_PER_STEP` bytes, the
//! motors through the TB6612 driver, the answer queued, the watchdog fed), the store task's save
//! piece and the link's transmit task. The emulator counts the instructions between the calls to
//! [`bench_mark`] around each millisecond.
//!
//! Stand-ins for the HAL drivers, which the emulator does not model: the sensor scan returns the
//! session's samples (the G071's DMA scan sleeps meanwhile), pins and PWM compare registers are
//! volatile stores to RAM, the UART's receive ring is a buffer the harness fills and its transmit
//! side digests what it is given (the DMA sends it), the flash is RAM with NOR semantics, the
//! watchdog a volatile store. No runtime, no interrupts: the emulator sets the stack pointer and
//! starts at [`bench_main`].

#![no_std]
#![no_main]

use core::cell::{Cell, RefCell, UnsafeCell};
use core::convert::Infallible;
use core::panic::PanicInfo;
use core::task::Waker;

use embassy_executor::raw::Executor;
use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashErrorKind, ReadNorFlash};
use mmu_firmware::control::ControlLoop;
use mmu_firmware::persist::SoftwareCrc;
use mmu_firmware::runner::Status;
use mmu_firmware::tasks::{self, LineError, Logic};
use mmu_firmware::{App, Config, HubSamples, Samples, SlotSamples};
use mmu_hal_port::SensorScan;
use mmu_hal_port::tb6612::{Bridges, Tb6612};

const SLOTS: usize = 3;
/// Where the emulator maps the session file's length (u32), followed by the file (read-only).
const SESSION: usize = 0x6000_0000;
/// The persisted state's region of the internal flash, as offsets from its base (board g071).
const STORE_RANGE: core::ops::Range<u32> = 0x1_8000..0x2_0000;
const FLASH_BASE: usize = 0x0800_0000;
const PAGE: usize = 2048;

/// What a [`bench_mark`] call says.
#[repr(u32)]
#[derive(Clone, Copy)]
enum Mark {
    /// Two marks with nothing between: the cost of the marks themselves.
    CalibrateBegin = 1,
    CalibrateEnd = 2,
    BootBegin = 3,
    BootEnd = 4,
    StepBegin = 5,
    /// a: step, b: request code | value << 8 | status << 16 | rx length << 24, c: progress or
    /// error code | bytes waiting before the step took its share << 16.
    StepEnd = 6,
    SaveBegin = 7,
    /// a: step, b: 1 when the flash was written.
    SaveEnd = 8,
    /// a: steps, b: digest of every byte the App sent.
    Done = 9,
    /// a: line.
    Panic = 10,
    /// The session file is not what the harness expects.
    BadSession = 11,
    /// a: the step's info, b: its code (see StepEnd), after the step's millisecond.
    StepContext = 12,
}

/// The emulator hooks this function's address; the registers carry the mark's words.
#[unsafe(no_mangle)]
#[inline(never)]
pub extern "C" fn bench_mark(kind: u32, a: u32, b: u32, c: u32) {
    // SAFETY: an empty instruction sequence; it only keeps the arguments in their registers.
    unsafe {
        core::arch::asm!("", in("r0") kind, in("r1") a, in("r2") b, in("r3") c, options(nomem, nostack, preserves_flags));
    }
}

fn mark(kind: Mark, a: u32, b: u32, c: u32) {
    bench_mark(kind as u32, a, b, c);
}

/// The persisted state's flash region as plain memory the emulator maps at its MCU address:
/// NOR semantics (erase to 0xff, writes of 8 bytes that only clear bits) like the STM32G0's.
struct EmulatedFlash;

#[derive(Debug)]
struct FlashError(NorFlashErrorKind);

impl embedded_storage::nor_flash::NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        self.0
    }
}

impl ErrorType for EmulatedFlash {
    type Error = FlashError;
}

fn region(offset: u32, len: usize) -> Result<*mut u8, FlashError> {
    let end = (offset as usize).checked_add(len);
    if (offset as usize) < STORE_RANGE.start as usize || end.is_none_or(|end| end > STORE_RANGE.end as usize)
    {
        return Err(FlashError(NorFlashErrorKind::OutOfBounds));
    }
    Ok((FLASH_BASE + offset as usize) as *mut u8)
}

impl ReadNorFlash for EmulatedFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        let from = region(offset, bytes.len())?;
        // SAFETY: inside the mapped store region (checked above), not aliased by Rust objects.
        unsafe { core::ptr::copy_nonoverlapping(from, bytes.as_mut_ptr(), bytes.len()) };
        Ok(())
    }

    fn capacity(&self) -> usize {
        STORE_RANGE.end as usize
    }
}

impl NorFlash for EmulatedFlash {
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        if from % PAGE as u32 != 0 || to % PAGE as u32 != 0 || to < from {
            return Err(FlashError(NorFlashErrorKind::NotAligned));
        }
        let start = region(from, (to - from) as usize)?;
        // SAFETY: inside the mapped store region (checked above).
        unsafe { core::ptr::write_bytes(start, 0xff, (to - from) as usize) };
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        if offset % 8 != 0 || bytes.len() % 8 != 0 {
            return Err(FlashError(NorFlashErrorKind::NotAligned));
        }
        let start = region(offset, bytes.len())?;
        for (i, &byte) in bytes.iter().enumerate() {
            // SAFETY: inside the mapped store region (checked above).
            unsafe {
                let at = start.add(i);
                at.write_volatile(at.read_volatile() & byte);
            }
        }
        Ok(())
    }
}

/// The recorded session (see `bench-mcu/session`): steps of samples and the bytes that arrived
/// on the line.
struct Session {
    bytes: &'static [u8],
    at: usize,
}

impl Session {
    fn u8(&mut self) -> Option<u8> {
        let byte = *self.bytes.get(self.at)?;
        self.at += 1;
        Some(byte)
    }

    fn u16(&mut self) -> Option<u16> {
        Some(u16::from_le_bytes([self.u8()?, self.u8()?]))
    }

    fn u32(&mut self) -> Option<u32> {
        Some(u32::from(self.u16()?) | (u32::from(self.u16()?) << 16))
    }

    fn slice(&mut self, len: usize) -> Option<&'static [u8]> {
        let bytes = self.bytes.get(self.at..self.at + len)?;
        self.at += len;
        Some(bytes)
    }

    fn step(&mut self) -> Option<(Samples<SLOTS>, &'static [u8])> {
        let mut samples = Samples::<SLOTS>::default();
        for slot in &mut samples.slots {
            *slot = SlotSamples {
                motor_hall: self.u16()?,
                filament: self.u16()?,
            };
        }
        samples.hub = HubSamples {
            filament: self.u16()?,
            tension: self.u16()?,
            cutter: self.u16()?,
        };
        let len = usize::from(self.u8()?);
        Some((samples, self.slice(len)?))
    }
}

/// The harness's state, shared with the stand-ins: single-threaded, no interrupts.
struct Shared<T>(T);
// SAFETY: the harness runs on one core without interrupts.
unsafe impl<T> Sync for Shared<T> {}

/// The virtual clock, µs.
static NOW_US: Shared<Cell<u64>> = Shared(Cell::new(0));
/// Embassy's timer queue, as the time driver keeps it.
static QUEUE: Shared<RefCell<embassy_time_queue_utils::Queue>> =
    Shared(RefCell::new(embassy_time_queue_utils::Queue::new()));
/// The executor asked to be polled again (its pender ran).
static PENDED: Shared<Cell<bool>> = Shared(Cell::new(false));
/// The samples of the current millisecond.
static SAMPLES: Shared<Cell<Option<Samples<SLOTS>>>> = Shared(Cell::new(None));
/// The bytes the session's printer has sent and the line has not carried yet: 115 200 Bd carries
/// at most `control::LINE_BYTES_PER_MS` (12) a millisecond, so a burst in the session reaches
/// the UART over several milliseconds (the App gets the same bytes in the same steps: it takes
/// at most 12 a step either way).
static BACKLOG: Shared<RefCell<Backlog>> = Shared(RefCell::new(Backlog {
    bytes: [0; BACKLOG_BYTES],
    head: 0,
    len: 0,
}));
const BACKLOG_BYTES: usize = 4096;

struct Backlog {
    bytes: [u8; BACKLOG_BYTES],
    head: usize,
    len: usize,
}

/// The bytes the UART received this millisecond (in its DMA ring), and the waker of the link's
/// receive task.
static LINE: Shared<RefCell<Line>> = Shared(RefCell::new(Line {
    bytes: [0; LINE_BYTES_PER_MS],
    start: 0,
    end: 0,
    waker: None,
}));
const LINE_BYTES_PER_MS: usize = mmu_firmware::control::LINE_BYTES_PER_MS;

struct Line {
    bytes: [u8; LINE_BYTES_PER_MS],
    start: usize,
    end: usize,
    waker: Option<Waker>,
}
/// The FNV-1a digest of every byte the link's transmit task was given.
static DIGEST: Shared<Cell<u32>> = Shared(Cell::new(0x811c_9dc5));
/// Where the stand-ins' pins, compare registers and the watchdog's key register are written.
static REGISTERS: Shared<UnsafeCell<[u32; 8]>> = Shared(UnsafeCell::new([0; 8]));

/// A volatile store to a stand-in register, as a driver's register write.
fn write_register(index: usize, value: u32) {
    // SAFETY: inside the array; single-threaded.
    unsafe {
        (REGISTERS.0.get().cast::<u32>())
            .add(index % 8)
            .write_volatile(value)
    };
}

/// The time driver on the virtual clock.
struct Driver;

impl embassy_time_driver::Driver for Driver {
    fn now(&self) -> u64 {
        NOW_US.0.get()
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        // The real driver would set its alarm when the queue says so; the harness looks at the
        // queue every millisecond.
        let _ = QUEUE.0.borrow_mut().schedule_wake(at, waker);
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: Driver = Driver);

/// The executor's pender: the thread executor's SEV.
#[unsafe(export_name = "__pender")]
fn pender(_context: *mut ()) {
    PENDED.0.set(true);
}

/// No interrupts: a critical section has nothing to mask.
struct SingleCore;
critical_section::set_impl!(SingleCore);
// SAFETY: one core, no interrupts.
unsafe impl critical_section::Impl for SingleCore {
    unsafe fn acquire() -> critical_section::RawRestoreState {
        true
    }

    unsafe fn release(_restore: critical_section::RawRestoreState) {}
}

/// The sensor scan: the session's samples of this millisecond.
struct Sampler;

/// The NUCLEO-G071RB's scan: one DMA transfer the CPU does not attend.
#[cfg(not(feature = "pico"))]
impl SensorScan<SLOTS> for Sampler {
    type Error = Infallible;

    async fn scan(&mut self) -> Result<Samples<SLOTS>, Infallible> {
        Ok(SAMPLES.0.get().unwrap_or_default())
    }
}

/// The Pico's scan (feature `pico`), as src/board/pico does it on the CPU: per sensor, the
/// multiplexer's select lines that change (one in the Gray-code order, two from the last sensor to
/// the first), then embassy-rp 0.10's `Adc::read_many` of nine free-running conversions into
/// DMA_CH3 (`read_many_inner` and `dma::Channel::read`), register access for register access: CS
/// set up (read, write), READY read, the FIFO drained of the previous sensor's [`FIFO_LEFTOVERS`]
/// (a FCS read before each FIFO read, one after), FCS written, the channel's READ_ADDR, WRITE_ADDR,
/// TRANS_COUNT and CTRL_TRIG written, DIV (read, write), START_MANY set, the transfer polled
/// (CTRL_TRIG read); then one `Timer::after_micros(18)` await for the nine conversions, standing
/// for the DMA completion interrupt's wake-up (the same executor path: the task woken, polled
/// again), and the register accesses of the interrupt's handlers (embassy-rp runs the handler of
/// each channel bound to DMA_IRQ_0, and the board's StopConversions stops the ADC); the transfer
/// polled again (CTRL_TRIG), dropped (CHAN_ABORT read, written; CTRL_TRIG read), the drop guard
/// (START_MANY cleared, READY read once: the ADC stopped while the task woke; before
/// StopConversions, up to 2 µs busy for it, counted as 28 loads), FCS cleared, CS read for the
/// sticky error. The four kept conversions summed. The stand-in's timer is the control task's one
/// timer registration, as the scan's bound is (`tasks::bounded`): its expiry takes the bound with
/// it, so here the bound is registered again at every wake-up, where the board's DMA wake-up leaves
/// it standing; and this time driver neither walks its queue nor sets an alarm when a registration
/// changes, which is what `bounded` saves on the board (measured on the emulated Pico, not here).
/// Checked against the real code on the emulated Pico (fil/pico, rp2040js: the image's instructions
/// a millisecond, idle): the scan's change saves 1 764 there, and this stand-in's change saves less
/// than that here.
#[cfg(feature = "pico")]
impl SensorScan<SLOTS> for Sampler {
    type Error = Infallible;

    async fn scan(&mut self) -> Result<Samples<SLOTS>, Infallible> {
        let mut sum = 0u32;
        // The multiplexer's channels in the Gray-code scan order; the last sensor's selected.
        let gray = |sensor: u32| sensor ^ (sensor >> 1);
        let mut selected = gray(2 * SLOTS as u32 + 2);
        for channel in 0..(2 * SLOTS as u32 + 3) {
            // The select lines that change: one, two from the last sensor to the first.
            let changed = selected ^ gray(channel);
            for bit in 0..4 {
                if changed & (1 << bit) != 0 {
                    write_register(6, gray(channel) & (1 << bit));
                }
            }
            selected = gray(channel);
            // read_many_inner: CS modify, READY, the FIFO drained, FCS.
            write_register(4, read_register(4) | 1);
            let _ = read_register(4);
            for _ in 0..FIFO_LEFTOVERS {
                let _ = read_register(5);
                let _ = read_register(6);
            }
            let _ = read_register(5);
            write_register(5, 0x0100_0009);
            // dma::Channel::read (configure): four channel registers.
            for register in 0..4 {
                write_register(7, register);
            }
            // DIV modify, START_MANY set, the transfer's first poll.
            write_register(5, read_register(5) & !0xffff);
            write_register(4, 1 << 3);
            let _ = read_register(7);
            embassy_time::Timer::after_micros(18).await;
            // DMA_IRQ_0's handlers (DMA_CH0, DMA_CH1, DMA_CH3 bound): each reads its channel's
            // CTRL_TRIG and INTS0; DMA_CH3's clears its INTS0 bit and wakes the task. Then the
            // board's StopConversions: DMA_CH3's CTRL_TRIG read, START_MANY cleared.
            for _ in 0..3 {
                let _ = read_register(7);
                let _ = read_register(6);
            }
            write_register(6, 1 << 3);
            let _ = read_register(7);
            write_register(4, 1 << 3);
            // The transfer's second poll and its drop (CHAN_ABORT modify, CTRL_TRIG read).
            let _ = read_register(7);
            write_register(7, read_register(7) | 1 << 3);
            let _ = read_register(7);
            // The drop guard: START_MANY cleared, READY read (the ADC stopped meanwhile), FCS
            // cleared; the sticky error.
            write_register(4, 1 << 3);
            sum += read_register(4).wrapping_add(2048);
            write_register(5, 0b1011);
            let _ = read_register(4);
            for _ in 0..4 {
                sum += read_register(3);
            }
        }
        write_register(5, sum);
        Ok(SAMPLES.0.get().unwrap_or_default())
    }
}

/// The conversions a Pico sensor's `read_many` leaves in the ADC's FIFO for the next one to
/// drain: the one under way at the DMA's last transfer, which the board's interrupt lets end
/// when it stops the ADC (StopConversions; before it, those that ended until the drop guard's
/// stop: the wake-up takes longer than three conversions, and rp2040js showed the FIFO full, 4).
#[cfg(feature = "pico")]
const FIFO_LEFTOVERS: usize = 1;

/// A volatile load from a stand-in register, as a driver's register read.
#[cfg(feature = "pico")]
fn read_register(index: usize) -> u32 {
    // SAFETY: inside the array; single-threaded.
    unsafe { (REGISTERS.0.get().cast::<u32>()).add(index % 8).read_volatile() }
}

/// A GPIO output: a store to its port's set/reset register.
struct Pin(usize);

impl embedded_hal::digital::ErrorType for Pin {
    type Error = Infallible;
}

impl embedded_hal::digital::OutputPin for Pin {
    fn set_low(&mut self) -> Result<(), Infallible> {
        write_register(0, 1 << (16 + self.0));
        Ok(())
    }

    fn set_high(&mut self) -> Result<(), Infallible> {
        write_register(0, 1 << self.0);
        Ok(())
    }
}

/// A PWM channel: a store to its compare register.
struct Pwm(usize);

impl embedded_hal::pwm::ErrorType for Pwm {
    type Error = Infallible;
}

impl embedded_hal::pwm::SetDutyCycle for Pwm {
    fn max_duty_cycle(&self) -> u16 {
        3199
    }

    fn set_duty_cycle(&mut self, duty: u16) -> Result<(), Infallible> {
        write_register(1 + self.0, u32::from(duty));
        Ok(())
    }
}

type Motors = Bridges<Tb6612<Pwm, Pin, Pin, Pwm, Pin, Pin, Pin>, Tb6612<Pwm, Pin, Pin, Pwm, Pin, Pin, Pin>>;

/// The link's receive side: what the harness put on the line.
struct LinkRx;

impl embedded_io_async::ErrorType for LinkRx {
    type Error = Infallible;
}

impl embedded_io_async::Read for LinkRx {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        core::future::poll_fn(|cx| {
            let mut line = LINE.0.borrow_mut();
            if line.start == line.end {
                line.waker = Some(cx.waker().clone());
                return core::task::Poll::Pending;
            }
            let count = (line.end - line.start).min(buf.len());
            let start = line.start;
            buf[..count].copy_from_slice(&line.bytes[start..start + count]);
            line.start += count;
            core::task::Poll::Ready(Ok(count))
        })
        .await
    }
}

/// The link's transmit side: digests what it is given.
struct LinkTx;

impl embedded_io_async::ErrorType for LinkTx {
    type Error = Infallible;
}

impl embedded_io_async::Write for LinkTx {
    async fn write(&mut self, bytes: &[u8]) -> Result<usize, Infallible> {
        let mut digest = DIGEST.0.get();
        for &byte in bytes {
            digest = (digest ^ u32::from(byte)).wrapping_mul(0x0100_0193);
        }
        DIGEST.0.set(digest);
        Ok(bytes.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

/// The button: never pressed; an edge never comes.
struct Button;

impl embedded_hal::digital::ErrorType for Button {
    type Error = Infallible;
}

impl embedded_hal::digital::InputPin for Button {
    fn is_high(&mut self) -> Result<bool, Infallible> {
        Ok(true)
    }

    fn is_low(&mut self) -> Result<bool, Infallible> {
        Ok(false)
    }
}

impl embedded_hal_async::digital::Wait for Button {
    async fn wait_for_high(&mut self) -> Result<(), Infallible> {
        core::future::pending().await
    }
    async fn wait_for_low(&mut self) -> Result<(), Infallible> {
        core::future::pending().await
    }
    async fn wait_for_rising_edge(&mut self) -> Result<(), Infallible> {
        core::future::pending().await
    }
    async fn wait_for_falling_edge(&mut self) -> Result<(), Infallible> {
        core::future::pending().await
    }
    async fn wait_for_any_edge(&mut self) -> Result<(), Infallible> {
        core::future::pending().await
    }
}

/// The watchdog's key register.
fn feed() {
    write_register(7, 0xAAAA);
}

/// A reset: the harness stops there (a session has none).
fn restart() -> ! {
    mark(Mark::BadSession, 3, 0, 0);
    halt()
}

static LOGIC: Shared<UnsafeCell<Option<Logic<SLOTS>>>> = Shared(UnsafeCell::new(None));

fn logic() -> &'static Logic<SLOTS> {
    // SAFETY: written once, before any task runs, then only shared.
    match unsafe { &*LOGIC.0.get() } {
        Some(logic) => logic,
        None => halt(),
    }
}

#[embassy_executor::task]
async fn control(motors: Motors) {
    tasks::run_control(Sampler, motors, logic(), feed, restart).await
}

#[embassy_executor::task]
async fn store() {
    tasks::run_store(EmulatedFlash, SoftwareCrc::default(), STORE_RANGE, logic(), feed).await
}

#[embassy_executor::task]
async fn link_rx() {
    tasks::run_link_rx(LinkRx, |_| LineError::Garbled).await
}

#[embassy_executor::task]
async fn link_tx() {
    tasks::run_link_tx(LinkTx).await
}

#[embassy_executor::task]
async fn button() {
    tasks::run_button(Button).await
}

#[embassy_executor::task]
async fn status_led() {
    tasks::run_status_led(Pin(13)).await
}

/// Runs what the CPU runs at `now_us`: the time driver's alarm, then the executor until no task
/// is ready.
///
/// Then every alarm due before `until_us` (the timers standing for the Pico scan's DMA
/// completions, a scan timeout dropped with its timer still queued) in turn: the time driver's
/// interrupt at its time, and the executor again.
fn run_at(executor: &'static Executor, now_us: u64, until_us: u64) {
    let mut now = now_us;
    loop {
        NOW_US.0.set(now);
        let _ = QUEUE.0.borrow_mut().next_expiration(now);
        PENDED.0.set(true);
        while PENDED.0.get() {
            PENDED.0.set(false);
            // SAFETY: not from the pender; one thread.
            unsafe { executor.poll() };
        }
        let next = QUEUE.0.borrow_mut().next_expiration(now);
        if next >= until_us {
            return;
        }
        now = next.max(now);
    }
}

fn tb6612(first: usize) -> Tb6612<Pwm, Pin, Pin, Pwm, Pin, Pin, Pin> {
    match Tb6612::new(
        Pwm(first),
        Pin(first),
        Pin(first + 1),
        Pwm(first + 1),
        Pin(first + 2),
        Pin(first + 3),
        Pin(first + 4),
    ) {
        Ok(chip) => chip,
        Err(_) => halt(),
    }
}

/// The emulator starts here with the stack pointer at the top of RAM.
#[unsafe(no_mangle)]
pub extern "C" fn bench_main() -> ! {
    mark(Mark::CalibrateBegin, 0, 0, 0);
    mark(Mark::CalibrateEnd, 0, 0, 0);

    // SAFETY: the emulator maps the session file at SESSION + 4 and its length at SESSION.
    let bytes = unsafe {
        let length = (SESSION as *const u32).read_volatile() as usize;
        core::slice::from_raw_parts((SESSION + 4) as *const u8, length)
    };
    let mut session = Session { bytes, at: 0 };
    if session.slice(4) != Some(b"MMUQ".as_slice()) {
        mark(Mark::BadSession, 0, 0, 0);
        halt();
    }
    let steps = session.u32().unwrap_or(0);

    // SAFETY: before any task runs.
    unsafe {
        *LOGIC.0.get() = Some(RefCell::new(ControlLoop::new(
            App::new(Config::default()),
            tasks::now(),
        )))
    };
    static EXECUTOR: Shared<UnsafeCell<Option<Executor>>> = Shared(UnsafeCell::new(None));
    // SAFETY: written once, here.
    let executor: &'static Executor =
        unsafe { (*EXECUTOR.0.get()).insert(Executor::new(core::ptr::null_mut())) };
    let spawner = executor.spawner();
    let motors = Bridges::new(tb6612(0), tb6612(5));
    macro_rules! spawn {
        ($($task:expr),*) => {$(
            match $task {
                Ok(token) => spawner.spawn(token),
                Err(_) => halt(),
            }
        )*};
    }
    spawn!(
        store(),
        control(motors),
        link_rx(),
        link_tx(),
        button(),
        status_led()
    );

    // The boot: the store task restores from the blank flash, the control task starts its Ticker.
    mark(Mark::BootBegin, 0, 0, 0);
    run_at(executor, 0, 500);
    mark(Mark::BootEnd, 0, 0, 0);

    let mut waiting = 0usize;
    for index in 0..steps {
        let Some((samples, line)) = session.step() else {
            mark(Mark::BadSession, 2, index, 0);
            halt();
        };
        let tick_us = (u64::from(index) + 1) * 1000;
        // The session's bytes join what the line has still to carry; half a millisecond before
        // the tick, a millisecond's worth of them reaches the link's receive task.
        let arrived = {
            let mut backlog = BACKLOG.0.borrow_mut();
            for &byte in line {
                if backlog.len == BACKLOG_BYTES {
                    mark(Mark::BadSession, 4, index, 0);
                    halt();
                }
                let at = (backlog.head + backlog.len) % BACKLOG_BYTES;
                backlog.bytes[at] = byte;
                backlog.len += 1;
            }
            let mut pending = LINE.0.borrow_mut();
            let count = backlog.len.min(LINE_BYTES_PER_MS);
            for k in 0..count {
                pending.bytes[k] = backlog.bytes[(backlog.head + k) % BACKLOG_BYTES];
            }
            backlog.head = (backlog.head + count) % BACKLOG_BYTES;
            backlog.len -= count;
            pending.start = 0;
            pending.end = count;
            count
        };
        // From here, what the CPU does: the UART's interrupt wakes the link's receive task (the
        // line went idle), the executor runs it; then the tick.
        mark(Mark::StepBegin, index, 0, 0);
        let waker = LINE.0.borrow_mut().waker.take();
        if arrived > 0
            && let Some(waker) = waker
        {
            waker.wake();
        } else if let Some(waker) = waker {
            LINE.0.borrow_mut().waker = Some(waker);
        }
        run_at(executor, tick_us - 500, tick_us);
        waiting += arrived;
        SAMPLES.0.set(Some(samples));
        run_at(executor, tick_us, tick_us + 500);
        mark(Mark::StepEnd, index, 0, 0);
        let taken = waiting.min(mmu_firmware::control::MAX_RX_PER_STEP);
        let (info, code) = match logic().try_borrow() {
            Ok(control) => context(control.app(), taken),
            Err(_) => (0, 0),
        };
        // The step's context, reported with an empty save (the save piece is inside the tick).
        mark(
            Mark::StepContext,
            info,
            code | ((waiting.min(0xffff) as u32) << 16),
            DIGEST.0.get(),
        );
        waiting -= taken;
        let wrote = tasks::STORE_WROTE.load(portable_atomic_ordering());
        mark(Mark::SaveBegin, index, 0, 0);
        mark(Mark::SaveEnd, index, u32::from(wrote), 0);
    }
    // The control task hands a step's answer to the transmit task at the next tick: one more,
    // unmeasured, for the last step's.
    let after_us = (u64::from(steps) + 1) * 1000;
    run_at(executor, after_us, after_us + 500);
    mark(Mark::Done, steps, DIGEST.0.get(), session.u32().unwrap_or(0));
    halt()
}

/// A step's context for the report: the command, its status, the bytes received.
fn context(app: &App<SLOTS>, rx_len: usize) -> (u32, u32) {
    let operation = app.operation();
    let (status, code) = match operation.status() {
        Status::Running(progress) => (0, u32::from(progress.0)),
        Status::Failed(error) => (1, u32::from(error.0)),
        Status::Finished => (2, 0),
    };
    let request = u32::from(operation.request.0.as_byte()) | (u32::from(operation.request.1) << 8);
    (request | (status << 16) | ((rx_len.min(255) as u32) << 24), code)
}

fn portable_atomic_ordering() -> core::sync::atomic::Ordering {
    core::sync::atomic::Ordering::Relaxed
}

fn halt() -> ! {
    loop {
        core::hint::spin_loop();
    }
}

#[panic_handler]
fn panic(info: &PanicInfo) -> ! {
    mark(Mark::Panic, info.location().map_or(0, |l| l.line()), 0, 0);
    halt()
}
