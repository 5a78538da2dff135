//! The step-cost harness: the unit logic (`App<3>`) and its persistence policy (`Keeper`),
//! built for thumbv6m-none-eabi with the firmware's profile, replaying a recorded session in an
//! emulator (`bench-mcu/run.py`).
//!
//! Every control step is done as the firmware's control loop does it: the bytes that arrived on
//! the line join the receive queue (`control::RxQueue`, the board's UART ring), `App::step` gets
//! the step's time, samples and at most `control::MAX_RX_PER_STEP` of the waiting bytes, then
//! `Keeper::update_after` (or `Keeper::before` for a reset), told whether the step was busy with
//! the printer (took bytes or answered) as the firmware tells it. The emulator counts the instructions between the calls to [`bench_mark`], which say
//! what is measured and give each step's context. No runtime, no interrupts: the emulator sets
//! the stack pointer and starts at [`bench_main`].

#![no_std]
#![no_main]

use core::panic::PanicInfo;

use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashErrorKind, ReadNorFlash};
use mmu_firmware::control::{RX_RING, RxQueue};
use mmu_firmware::persist::{Keeper, Store};
use mmu_firmware::runner::Status;
use mmu_firmware::{App, Config, HubSamples, Instant, Outputs, Samples, SlotSamples};

const SLOTS: usize = 3;
/// Where the emulator maps the session file's length (u32), followed by the file (read-only).
const SESSION: usize = 0x6000_0000;
/// The persisted state's region of the internal flash, as offsets from its base (board.rs).
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

/// One step of the unit logic, out of line as in the firmware (src/main.rs).
#[inline(never)]
fn step(app: &mut App<SLOTS>, now: Instant, samples: &Samples<SLOTS>, rx: &[u8]) -> Outputs<SLOTS> {
    app.step(now, samples, rx)
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

    mark(Mark::BootBegin, 0, 0, 0);
    let Ok(store) = Store::new(EmulatedFlash, STORE_RANGE) else {
        mark(Mark::BadSession, 1, 0, 0);
        halt();
    };
    let mut app = App::<SLOTS>::new(Config::default());
    let (mut keeper, _) = Keeper::boot(store, &mut app);
    mark(Mark::BootEnd, 0, 0, 0);

    let mut digest: u32 = 0x811c_9dc5;
    let mut received = RxQueue::<RX_RING>::new();
    for index in 0..steps {
        let Some((samples, line)) = session.step() else {
            mark(Mark::BadSession, 2, index, 0);
            halt();
        };
        let now = Instant::from_millis(u64::from(index));
        received.receive(line);
        let waiting = received.len();
        let rx = received.take_step();
        mark(Mark::StepBegin, index, 0, 0);
        let out = step(&mut app, now, &samples, &rx);
        let (info, code) = context(&app, rx.len());
        mark(
            Mark::StepEnd,
            index,
            info,
            code | ((waiting.min(0xffff) as u32) << 16),
        );
        for &byte in out.tx.iter() {
            digest = (digest ^ u32::from(byte)).wrapping_mul(0x0100_0193);
        }
        // As the firmware's control loop: no save piece after a step busy with the printer.
        let busy = !rx.is_empty() || !out.tx.is_empty();
        mark(Mark::SaveBegin, index, 0, 0);
        let wrote = match out.action {
            None => keeper.update_after(&app, now, busy).unwrap_or(true),
            Some(action) => {
                let _ = keeper.before(action, &app);
                true
            }
        };
        mark(Mark::SaveEnd, index, u32::from(wrote), 0);
    }
    let expected = session.u32().unwrap_or(0);
    mark(Mark::Done, steps, digest, expected);
    halt()
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
