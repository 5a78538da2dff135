//! The settings part of a snapshot, gathered a register per call. [`App::snapshot`] reads every
//! setting register of the unit and of a default configuration at once, a bounded but long job
//! for one control step; the keeper instead compares the registers one per call against defaults
//! read once at boot, and gets the same list. Both take
//! the settings from `registers::settings`; a test holds the two lists equal.

use heapless::Vec;

use super::{MAX_SETTINGS, Settings};
use crate::app::App;
use crate::config::Config;
use crate::registers;

/// Setting registers compared per call.
pub(super) const REGISTERS_PER_CALL: usize = 1;

/// Every setting register of a unit with `N` slots and its value in the default configuration,
/// in the register table's order (the order of [`App::snapshot`]'s settings).
#[derive(Clone)]
pub(super) struct Defaults(Vec<(u8, u16), MAX_SETTINGS>);

impl Defaults {
    /// Read the defaults through the register table (once, at boot). `app` only completes the
    /// view (its slots decide which registers exist): setting registers read only the
    /// configuration.
    pub(super) fn new<const N: usize>(app: &App<N>) -> Self {
        let profile = app.profile();
        let config = Config::for_profile(profile);
        let view = registers::settings_view(profile, &config, &app.unit().hub, N);
        let mut defaults = Vec::new();
        for setting in registers::settings(N) {
            if let Some(value) = setting.read(&view) {
                // MAX_SETTINGS holds every setting of a 5-slot unit.
                let _ = defaults.push((setting.address(), value));
            }
        }
        Defaults(defaults)
    }
}

/// A comparison of the unit's settings with their defaults in progress.
#[derive(Clone, Default)]
pub(super) struct Scan {
    /// The next register, as an index into [`Defaults`].
    next: usize,
    /// The settings that differ so far.
    settings: Settings,
}

impl Scan {
    /// Compare the next [`REGISTERS_PER_CALL`] registers: `true` once every one is compared
    /// (in a call that compares none: starting a save with them costs a call of its own), the
    /// settings that differ then in [`Scan::settings`].
    pub(super) fn compare_next<const N: usize>(&mut self, app: &App<N>, defaults: &Defaults) -> bool {
        if self.next >= defaults.0.len() {
            return true;
        }
        for _ in 0..REGISTERS_PER_CALL {
            let Some(&(address, default)) = defaults.0.get(self.next) else {
                break;
            };
            if let Some(value) = app.read_register(address).filter(|&value| value != default) {
                let _ = self.settings.push((address, value));
            }
            self.next += 1;
        }
        false
    }

    /// The settings of `app` that differ from their defaults: every register compared at once.
    pub(super) fn all<const N: usize>(app: &App<N>, defaults: &Defaults) -> Settings {
        let mut scan = Scan::default();
        while !scan.compare_next(app, defaults) {}
        scan.settings
    }

    /// The settings that differ from their defaults, of the registers compared so far.
    pub(super) fn settings(&self) -> &Settings {
        &self.settings
    }

    /// [`Scan::compare_next`], handing the settings over once every register is compared.
    #[cfg(test)]
    fn step<const N: usize>(&mut self, app: &App<N>, defaults: &Defaults) -> Option<Settings> {
        self.compare_next(app, defaults)
            .then(|| core::mem::take(&mut self.settings))
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use crate::registers::Access;

    /// The whole scan, a call at a time.
    fn scanned<const N: usize>(app: &App<N>, defaults: &Defaults) -> Settings {
        let mut scan = Scan::default();
        for _ in 0..=MAX_SETTINGS + 1 {
            if let Some(settings) = scan.step(app, defaults) {
                return settings;
            }
        }
        panic!("the scan does not end");
    }

    /// Every setting register of the unit, changed or not, as (address, a valid other value).
    fn every_setting<const N: usize>(app: &App<N>) -> std::vec::Vec<(u8, u16)> {
        registers::all(N)
            .filter(|r| r.row.access() == Access::ReadWrite && r.address != registers::FSENSOR)
            .filter_map(|r| {
                let (min, max) = r.row.range()?;
                let value = app.read_register(r.address)?;
                Some((
                    r.address,
                    if value > min {
                        value - 1
                    } else {
                        max.min(value + 1)
                    },
                ))
            })
            .collect()
    }

    fn check<const N: usize>() {
        let mut app = App::<N>::new(Config::default());
        let defaults = Defaults::new(&app);
        assert!(defaults.0.len() > 20, "{} setting registers", defaults.0.len());
        assert_eq!(
            scanned(&app, &defaults),
            app.snapshot().settings,
            "nothing changed"
        );
        // Change the settings one more at a time: the scan must see what the snapshot sees.
        for (address, value) in every_setting(&app) {
            app.write_register(address, value);
            let settings = app.snapshot().settings;
            assert_eq!(scanned(&app, &defaults), settings, "after writing {address:#04x}");
        }
        assert!(app.snapshot().settings.len() > 20, "most settings changed");
    }

    #[test]
    fn the_scan_finds_the_settings_the_snapshot_holds() {
        check::<3>();
        check::<1>();
        check::<5>();
    }
}
