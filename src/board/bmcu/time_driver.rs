//! embassy-time's driver on the QingKe core's SysTick: a 64-bit counter of HCLK / 8 (15 MHz)
//! that counts up from start-up and never wraps in practice (39 000 years), and one compare
//! register whose match raises the SysTick interrupt (core interrupt 12) for the next alarm.
//! Ticks are 1 µs (`tick-hz-1_000_000`): 15 counts each.
//!
//! Registers (QingKe V4 processor manual, SysTick: STK_CTLR, STK_SR, STK_CNTL/H, STK_CMPLR/HR).
//! The 64-bit count is read as high, low, high again, so a carry between the halves is never
//! seen as a jump of 2³² counts.

use core::cell::RefCell;

use ch32_metapac as pac;
use critical_section::CriticalSection;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_time_driver::Driver;
use embassy_time_queue_utils::Queue;
use pac::systick::vals::{Mode, Stclk};

use mmu_firmware::time::div_rem_u64;

use super::clock::SYSTICK_HZ;

/// SysTick counts per embassy-time tick.
const COUNTS_PER_TICK: u16 = (SYSTICK_HZ as u64 / embassy_time_driver::TICK_HZ) as u16;
const _: () = assert!(COUNTS_PER_TICK as u64 * embassy_time_driver::TICK_HZ == SYSTICK_HZ as u64);
/// The SysTick's number among the core interrupts (qingke-rt's `CoreInterrupt::SysTick`).
const SYSTICK_IRQ: u8 = 12;

struct SysTickDriver {
    queue: Mutex<CriticalSectionRawMutex, RefCell<Queue>>,
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver {
    queue: Mutex::new(RefCell::new(Queue::new())),
});

/// The count since start-up (HCLK / 8).
pub fn counts() -> u64 {
    let systick = pac::SYSTICK;
    loop {
        let high = systick.cnth().read();
        let low = systick.cntl().read();
        if systick.cnth().read() == high {
            return (u64::from(high) << 32) | u64::from(low);
        }
    }
}

/// The count in embassy-time ticks.
fn ticks() -> u64 {
    div_rem_u64(counts(), COUNTS_PER_TICK).0
}

/// Busy-waits until the count reaches `until`: the bit timings of the board's bit-banged lines
/// (the AS5600s' I2C, the WS2812).
pub fn spin_until(until: u64) {
    while counts() < until {}
}

impl SysTickDriver {
    /// Arms the compare for `at` (counts), or says `false` when `at` has passed already (the
    /// match would never come).
    fn arm(&self, at: u64) -> bool {
        let systick = pac::SYSTICK;
        if at <= counts() {
            return false;
        }
        systick.cmph().write_value((at >> 32) as u32);
        systick.cmpl().write_value(at as u32);
        systick.sr().write(|w| w.set_cntif(false));
        systick.ctlr().modify(|w| w.set_stie(true));
        if at <= counts() {
            systick.ctlr().modify(|w| w.set_stie(false));
            systick.sr().write(|w| w.set_cntif(false));
            return false;
        }
        true
    }

    /// Arms the next alarm of the queue, waking what has expired meanwhile.
    fn arm_next(&self, cs: CriticalSection) {
        let mut queue = self.queue.borrow(cs).borrow_mut();
        let mut next = queue.next_expiration(ticks());
        while next != u64::MAX && !self.arm(next.saturating_mul(u64::from(COUNTS_PER_TICK))) {
            next = queue.next_expiration(ticks());
        }
        if next == u64::MAX {
            pac::SYSTICK.ctlr().modify(|w| w.set_stie(false));
        }
    }
}

impl Driver for SysTickDriver {
    fn now(&self) -> u64 {
        ticks()
    }

    fn schedule_wake(&self, at: u64, waker: &core::task::Waker) {
        critical_section::with(|cs| {
            let scheduled = self.queue.borrow(cs).borrow_mut().schedule_wake(at, waker);
            if scheduled {
                self.arm_next(cs);
            }
        })
    }
}

/// The compare matched: wake what is due and arm the next alarm.
#[qingke_rt::interrupt(core)]
fn SysTick() {
    pac::SYSTICK.sr().write(|w| w.set_cntif(false));
    critical_section::with(|cs| DRIVER.arm_next(cs));
}

/// Starts the counter from 0, counting up at HCLK / 8 without reload, and enables its interrupt
/// at the PFIC (the interrupt itself is enabled per alarm, STK_CTLR.STIE).
pub fn init() {
    let systick = pac::SYSTICK;
    systick.ctlr().write(|w| {
        w.set_init(true);
        w.set_mode(Mode::UPCOUNT);
        w.set_stre(false);
        w.set_stclk(Stclk::HCLK_DIV8);
        w.set_ste(true);
    });
    systick.sr().write(|w| w.set_cntif(false));
    // SAFETY: the handler above is in place; nothing else uses the SysTick.
    unsafe { qingke::pfic::enable_interrupt(SYSTICK_IRQ) };
}
