//! The decisions of the boards' glue that host tests can check: a flash that may feed the
//! watchdog only a bounded number of times ([`WatchedFlash`]), the CRC unit checked at boot with
//! the software CRC as its fallback ([`CheckedCrc`]), and the age of the samples a control step
//! runs on ([`SampleClock`]). Each board module (src/board/) builds on them; nothing here touches
//! hardware.

use embedded_storage::nor_flash::{ErrorType, NorFlash, ReadNorFlash};

use crate::persist::{BitwiseCrc, EntryCrc, iso_hdlc};

/// A NOR flash that never feeds the watchdog on its own: only before an erase, and only as many
/// times as its owner allowed for the job at hand ([`WatchedFlash::allow_feeds`]).
///
/// The control task feeds the watchdog between the store's pieces (a piece erases one page at
/// most, shorter than the watchdog's timeout). Only a job that must run whole, the save before a
/// reset, erases more in a row than the timeout lasts; its owner allows it as many feeds as it
/// can need. A loop in the save path uses them up and the watchdog resets the MCU, as it must.
pub struct WatchedFlash<F> {
    flash: F,
    feeds: u32,
    feed: fn(),
}

impl<F> WatchedFlash<F> {
    /// `flash`, with `feed` the board's watchdog feed; no feed allowed yet.
    pub const fn new(flash: F, feed: fn()) -> Self {
        WatchedFlash {
            flash,
            feeds: 0,
            feed,
        }
    }

    /// Allows the next `feeds` erases to feed the watchdog first (replacing what was left).
    pub fn allow_feeds(&mut self, feeds: u32) {
        self.feeds = feeds;
    }

    /// Feeds left.
    pub const fn feeds_left(&self) -> u32 {
        self.feeds
    }

    /// The flash underneath.
    pub fn inner(&mut self) -> &mut F {
        &mut self.flash
    }
}

impl<F: ErrorType> ErrorType for WatchedFlash<F> {
    type Error = F::Error;
}

impl<F: ReadNorFlash> ReadNorFlash for WatchedFlash<F> {
    const READ_SIZE: usize = F::READ_SIZE;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        self.flash.read(offset, bytes)
    }

    fn capacity(&self) -> usize {
        self.flash.capacity()
    }
}

impl<F: NorFlash> NorFlash for WatchedFlash<F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;

    /// A write is short (a double word on the G071: 85 µs): it never feeds.
    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        self.flash.write(offset, bytes)
    }

    /// One page at a time, each after a feed while the allowance lasts.
    fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let mut page = from;
        while page < to {
            if self.feeds > 0 {
                self.feeds -= 1;
                (self.feed)();
            }
            let end = page.saturating_add(F::ERASE_SIZE as u32).min(to);
            self.flash.erase(page, end)?;
            page = end;
        }
        Ok(())
    }
}

/// The store's CRC-32/ISO-HDLC: on the MCU's CRC unit when it computes the catalogue's check
/// value at boot, else in software, so that the store stays readable by every build (the host,
/// the simulator and a board without a CRC unit compute it in software).
pub enum CheckedCrc<H> {
    /// The CRC unit, which passed the check.
    Unit(H),
    /// The software CRC, bit by bit: the unit failed the check.
    Software(BitwiseCrc),
}

impl<H: EntryCrc> CheckedCrc<H> {
    /// Checks `unit` on the ASCII bytes `123456789` ([`iso_hdlc::CHECK`]); returns the CRC to
    /// use and the value the unit computed.
    pub fn check(mut unit: H) -> (Self, u32) {
        unit.start();
        unit.add(b"123456789");
        let value = unit.value();
        if value == iso_hdlc::CHECK {
            (CheckedCrc::Unit(unit), value)
        } else {
            (CheckedCrc::Software(BitwiseCrc::default()), value)
        }
    }

    /// True when the CRC unit is in use.
    pub const fn is_unit(&self) -> bool {
        matches!(self, CheckedCrc::Unit(_))
    }
}

impl<H: EntryCrc> EntryCrc for CheckedCrc<H> {
    fn start(&mut self) {
        match self {
            CheckedCrc::Unit(unit) => unit.start(),
            CheckedCrc::Software(software) => software.start(),
        }
    }

    fn add(&mut self, bytes: &[u8]) {
        match self {
            CheckedCrc::Unit(unit) => unit.add(bytes),
            CheckedCrc::Software(software) => software.add(bytes),
        }
    }

    fn value(&mut self) -> u32 {
        match self {
            CheckedCrc::Unit(unit) => unit.value(),
            CheckedCrc::Software(software) => software.value(),
        }
    }
}

/// When the newest complete sensor scan was taken, for the age a control step reports
/// (`control::Tick::sample_age_us`): a scan that failed or timed out leaves the old samples in
/// use, and their age grows until [`crate::control::MAX_SAMPLE_AGE_US`] stops the watchdog feed.
#[derive(Debug, Clone, Copy)]
pub struct SampleClock {
    taken_us: u64,
}

impl SampleClock {
    /// No scan yet: the samples count as taken at `now_us` (the boot's defaults).
    pub const fn new(now_us: u64) -> Self {
        SampleClock { taken_us: now_us }
    }

    /// A scan completed at `now_us`.
    pub fn fresh(&mut self, now_us: u64) {
        self.taken_us = now_us;
    }

    /// How old the samples in use are at `now_us`, µs.
    pub const fn age_us(&self, now_us: u64) -> u64 {
        now_us.saturating_sub(self.taken_us)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::{ControlLoop, MAX_SAMPLE_AGE_US, Tick};
    use crate::uart::{MemoryRing, ReceiveRing};
    use crate::{App, Instant, Samples};
    use core::sync::atomic::{AtomicU32, Ordering};

    extern crate std;
    use std::vec::Vec;

    use crate::persist::SoftwareCrc;
    use crate::persist::ram_flash::{PAGE, RamFlash};

    static FEEDS: AtomicU32 = AtomicU32::new(0);
    fn feed() {
        FEEDS.fetch_add(1, Ordering::SeqCst);
    }

    #[test]
    fn the_flash_feeds_the_watchdog_only_as_often_as_allowed() {
        let mut flash = WatchedFlash::new(RamFlash::<PAGE, 8>::new(std::vec![0; 16 * PAGE]), feed);
        let before = FEEDS.load(Ordering::SeqCst);
        // Ordinary pieces: writes and a page erase never feed.
        flash.write(0, &[1; 8]).unwrap();
        flash.erase(0, PAGE as u32).unwrap();
        assert_eq!(FEEDS.load(Ordering::SeqCst), before);
        // A whole save before a reset is allowed 4: an erase loop in it runs out of feeds, and
        // the watchdog (whose timeout is longer than one erase) then resets the MCU.
        flash.allow_feeds(4);
        for _ in 0..10 {
            flash.erase(PAGE as u32, 2 * PAGE as u32).unwrap();
        }
        assert_eq!(FEEDS.load(Ordering::SeqCst), before + 4);
        assert_eq!(flash.feeds_left(), 0);
        // A multi-page erase feeds before each page, within the allowance.
        flash.allow_feeds(2);
        flash.erase(0, 8 * PAGE as u32).unwrap();
        assert_eq!(FEEDS.load(Ordering::SeqCst), before + 6);
        assert_eq!(flash.inner().erases, 1 + 10 + 8);
    }

    /// A CRC unit set up wrong: it forgets to reverse its output.
    struct WrongUnit(SoftwareCrc);

    impl EntryCrc for WrongUnit {
        fn start(&mut self) {
            self.0.start();
        }
        fn add(&mut self, bytes: &[u8]) {
            self.0.add(bytes);
        }
        fn value(&mut self) -> u32 {
            self.0.value().reverse_bits()
        }
    }

    fn crc_of(crc: &mut impl EntryCrc, bytes: &[u8]) -> u32 {
        crc.start();
        crc.add(bytes);
        crc.value()
    }

    #[test]
    fn a_crc_unit_that_fails_the_check_value_is_replaced_by_the_software_crc() {
        let (mut checked, value) = CheckedCrc::check(WrongUnit(SoftwareCrc::default()));
        assert_ne!(value, iso_hdlc::CHECK);
        assert!(!checked.is_unit());
        // The store's entries then carry the CRC every other build computes.
        let entry = b"an entry of the store";
        assert_eq!(
            crc_of(&mut checked, entry),
            crc_of(&mut SoftwareCrc::default(), entry)
        );

        let (checked, value) = CheckedCrc::check(SoftwareCrc::default());
        assert_eq!(value, iso_hdlc::CHECK);
        assert!(checked.is_unit());
    }

    #[test]
    fn samples_from_a_stalled_scan_grow_old_and_stop_the_watchdog_feed() {
        let mut control = ControlLoop::new(App::<3>::default(), Instant::ZERO);
        let samples = Samples::<3>::uniform(2048);
        let mut clock = SampleClock::new(0);
        let mut fed = Vec::new();
        let mut received = ReceiveRing::new(MemoryRing::<16>::new());
        for ms in 1..=20u64 {
            let now_us = ms * 1000;
            // The scan completes until 10 ms, then times out at every step.
            if ms <= 10 {
                clock.fresh(now_us);
            }
            let step = control.step(
                &Tick {
                    now: Instant::from_millis(ms),
                    lateness_us: 0,
                    sample_age_us: clock.age_us(now_us),
                    samples: &samples,
                    button_down: false,
                },
                &mut received,
            );
            fed.push(step.feed_watchdog);
        }
        let last_fed = fed.iter().rposition(|&f| f).map(|i| i as u64 + 1);
        assert_eq!(last_fed, Some(10 + MAX_SAMPLE_AGE_US / 1000));
        assert!(fed[..10].iter().all(|&f| f));
    }

    /// The Pico's flash as the store sees it through embassy-rp's driver: 4 KiB sectors, byte
    /// writes and reads (`embassy_rp::flash`: ERASE_SIZE 4096, WRITE_SIZE 1, READ_SIZE 1).
    type QspiFlash = RamFlash<SECTOR, 1>;

    const SECTOR: usize = 4096;

    #[test]
    fn the_store_keeps_the_state_in_the_picos_4_kib_sectors() {
        use crate::persist::{Keeper, Snapshot, Store};
        use crate::unit::Lane;
        // The Pico's store: its last 16 sectors, here at offset 0 of a 64 KiB flash.
        let range = 0..16 * SECTOR as u32;
        let flash = WatchedFlash::new(QspiFlash::erased(16), feed);
        let (crc, _) = CheckedCrc::check(SoftwareCrc::default());
        let mut app = App::<3>::default();
        let store =
            Store::with_crc(flash, crc, range.clone()).expect("4 KiB sectors fit the store's page model");
        let (mut keeper, _) = Keeper::boot(store, &mut app);
        let lanes = [
            [Lane::Parked, Lane::Empty, Lane::InHub],
            [Lane::Empty, Lane::Parked, Lane::Parked],
            [Lane::InHub, Lane::Parked, Lane::Empty],
        ];
        let mut now = Instant::ZERO;
        // Enough saves to fill sectors and move on to fresh ones (4 KiB erases).
        let rounds = 3000;
        for round in 0..rounds {
            // A minute between changes: the keeper's erase allowance (60 an hour) refills.
            now = now + 60_000;
            let snapshot = Snapshot {
                lanes: lanes[round % lanes.len()],
                ..app.snapshot()
            };
            app.restore(&snapshot);
            for _ in 0..5000 {
                keeper.update(&app, now).expect("the save goes on");
                now = now + 1;
                if !keeper.is_saving() && keeper.snapshot(&app).lanes == snapshot.lanes {
                    break;
                }
            }
        }
        let last = lanes[(rounds - 1) % lanes.len()];
        let erased = keeper.store().flash().inner().erases;
        // The 16 sectors start blank; an erase means the log came round to a used sector.
        assert!(erased > 0, "the saves never came round to a used sector");
        // A restart restores the last state from the sectors.
        let flash = keeper.into_store().into_flash();
        let (crc, _) = CheckedCrc::check(SoftwareCrc::default());
        let mut store = Store::<_, 3, _>::with_crc(flash, crc, range).expect("fits");
        assert_eq!(store.load().lanes, last);
    }
}
