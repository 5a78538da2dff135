//! The uptime clock that paces the control loop: TIM2 counting microseconds, read directly.
//!
//! Not embassy-time: its driver (an alarm timer and its interrupt), timer queue and the executor
//! it wakes took 1.9 KB more of the 32 KiB flash than this free-running 32-bit counter, for a
//! firmware with one loop.

use core::cell::Cell;

use cortex_m::interrupt::Mutex;
use embassy_stm32::Peri;
use embassy_stm32::pac;
use embassy_stm32::peripherals;
use embassy_stm32::rcc;

/// The uptime, µs: TIM2's 32-bit count extended to 64 bits at each reading (it wraps every 71
/// minutes; the control loop reads it every millisecond).
static UPTIME_US: Mutex<Cell<u64>> = Mutex::new(Cell::new(0));

/// Microseconds since [`init`](super::init) started the clock.
pub fn uptime_us() -> u64 {
    cortex_m::interrupt::free(|cs| {
        let uptime = UPTIME_US.borrow(cs);
        let last = uptime.get();
        let count = pac::TIM2.cnt().read();
        let now = last + u64::from(count.wrapping_sub(last as u32));
        uptime.set(now);
        now
    })
}

/// Waits until the uptime reaches `deadline_us`; returns the uptime then.
pub fn wait_until(deadline_us: u64) -> u64 {
    loop {
        let now = uptime_us();
        if now >= deadline_us {
            return now;
        }
    }
}

/// Starts TIM2 counting microseconds: prescaler = timer clock / 1 MHz, the 32-bit auto-reload
/// at its reset value 0xFFFF_FFFF (RM0444, TIM2/TIM3 registers), an update event to load the
/// prescaler, then the counter on.
pub(super) fn start_clock(_timer: Peri<'static, peripherals::TIM2>) {
    rcc::enable_and_reset::<peripherals::TIM2>();
    let per_us = rcc::frequency::<peripherals::TIM2>().0 / 1_000_000;
    let timer = pac::TIM2;
    timer.psc().write_value(per_us.saturating_sub(1) as u16);
    timer.egr().write(|w| w.set_ug(true));
    timer.cr1().write(|w| w.set_cen(true));
}

defmt::timestamp!("{=u64:us}", uptime_us());
