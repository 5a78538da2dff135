//! The unit logic with its slot count chosen at run time, and its persisted state.
//!
//! [`App`] takes its slot count as a const generic, as the firmware must; the simulator's
//! `--slots` is a run-time value. [`UnitLogic`] is the object-safe face of an `App<N>` with its
//! [`Store`] that [`new_logic`] builds for any supported count. The flash outlives the logic: a
//! restart takes it back with [`UnitLogic::take_flash`] and boots a new logic on it.
//!
//! Each step is the firmware's control step ([`ControlLoop::step`]), run as the board's control
//! task runs it: received bytes wait in a model of the NUCLEO-G071RB's DMA ring
//! ([`MemoryRing`] of [`G071_DMA_RING`] bytes: what laps the reader is lost, as on the board),
//! the step takes its share, and a save piece runs after the steps the control step says.

use mmu_firmware::control::{ControlLoop, Tick};
use mmu_firmware::persist::{Keeper, Store};
use mmu_firmware::profile::Profile;
use mmu_firmware::runner::Status;
use mmu_firmware::uart::{G071_DMA_RING, MemoryRing, ReceiveRing};
use mmu_firmware::{App, BoardAction, Config, Instant, MAX_SLOTS, MotorCommand};
use mmu_model::Model;
use mmu_protocol::{ButtonCode, RequestCode};

use crate::flash::{FlashWear, G0_ERASE_STALL_US, G0_PAGE, G0_PROGRAM_STALL_US, MemFlash, MotionWatch};

/// The store's flash of the board a simulated unit stands for: its page size and count.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StoreFlash {
    /// The NUCLEO-G071RB's: 16 pages of 2 KiB (32 KiB); the Pico's holds as much.
    G071,
    /// The BMCU-C's: 4 pages of 1 KiB (four 256-byte fast erases each), the last 4 KB of the
    /// CH32V203's rated 64 KB.
    Bmcu,
}

impl StoreFlash {
    /// The board a hardware `profile` runs on: the BMCU-C's lanes on its own board, every other
    /// profile on the NUCLEO-G071RB.
    pub fn of_profile(profile: &Profile) -> StoreFlash {
        if profile.name == mmu_firmware::profile::BMCU_C.name {
            StoreFlash::Bmcu
        } else {
            StoreFlash::G071
        }
    }
}

/// The BMCU-C's store page: four fast-erase pages.
const BMCU_PAGE: usize = 1024;
/// Pages of each board's store.
const G071_PAGES: usize = 16;
const BMCU_PAGES: usize = 4;

/// One App of any slot count, stepped against the model.
pub trait UnitLogic: Send {
    /// One control step at `now`: sample `model`, step the App with `rx` (as much of it and of
    /// what waits from earlier steps as a board's step takes), append what it sends to
    /// `tx`, and run the model for `dt_ms` with the App's motor commands. Returns the board action
    /// the App asked for, if any.
    fn step(
        &mut self,
        now: Instant,
        dt_ms: u32,
        model: &mut Model,
        rx: &[u8],
        tx: &mut Vec<u8>,
    ) -> Option<BoardAction>;

    /// The command the unit is carrying out (the one `Q0` echoes) and where it stands.
    fn command(&self) -> ((RequestCode, u8), Status);

    /// A physical button on the unit was pressed.
    fn press_button(&mut self, button: ButtonCode);

    /// The configuration the logic runs with.
    fn config(&self) -> &Config;

    /// The power goes: nothing runs until [`UnitLogic::power_on`].
    fn power_off(&mut self) {}

    /// The power comes back: the unit boots again from its flash, as it was left, with `config`
    /// until the flash says otherwise.
    fn power_on(&mut self, config: &Config);

    /// From now on the unit's control loop never yields again, as a task stuck in a loop would:
    /// its motors keep what they were last told until the board's watchdog resets the unit
    /// ([`WATCHDOG_MS`] after the last step it fed), which then boots from its flash.
    fn hang(&mut self);

    /// Why the unit can no longer be stepped (a firmware bench that stopped), if it cannot.
    fn failure(&self) -> Option<String> {
        None
    }

    /// How much the flash has been worn so far.
    fn flash_wear(&mut self) -> FlashWear;

    /// The motor commands of the last step, per slot.
    fn motors(&self) -> Vec<MotorCommand>;
}

/// How long a hung control loop goes unnoticed before the board's watchdog resets the unit, ms:
/// the NUCLEO-G071RB's `WATCHDOG_TIMEOUT_US` (the Pico's is the same).
pub const WATCHDOG_MS: u32 = 100;

/// An App in the firmware's control loop, with its store kept by the firmware's own policy
/// ([`Keeper`]).
struct PersistentApp<const N: usize, const PAGE: usize> {
    control: ControlLoop<N>,
    keeper: Keeper<MemFlash<PAGE>, N>,
    /// Pages of the store.
    pages: usize,
    motors: [MotorCommand; N],
    received: ReceiveRing<MemoryRing<G071_DMA_RING>, G071_DMA_RING>,
    /// Since the loop hung, ms; `None` while it runs.
    hung_ms: Option<u32>,
    /// What it booted with: a watchdog reset boots with it again.
    boot_config: Config,
    /// Page erases after a step that drove a motor, over every boot.
    motion: MotionWatch,
}

impl<const N: usize, const PAGE: usize> PersistentApp<N, PAGE> {
    /// Boot on `flash` of `pages` pages: what it holds is restored before the first step.
    fn boot(profile: &'static Profile, config: Config, flash: MemFlash<PAGE>, pages: usize) -> Option<Self> {
        let range = 0..(pages * PAGE) as u32;
        let store = Store::new(flash, range).unwrap_or_else(|_| unreachable!("a valid region"));
        let mut app = App::with_profile(profile, config.clone())?;
        let (keeper, _) = Keeper::boot(store, &mut app);
        Some(PersistentApp {
            control: ControlLoop::new(app, Instant::ZERO),
            keeper,
            pages,
            motors: mmu_firmware::drive::stopped(),
            received: ReceiveRing::new(MemoryRing::new()),
            hung_ms: None,
            boot_config: config,
            motion: MotionWatch::default(),
        })
    }

    /// The flash goes to a fresh App booted on it; this one is left with a blank store.
    fn reboot(&mut self, config: Config) {
        let flash = std::mem::replace(self.keeper.store().flash(), MemFlash::new(0));
        let motion = self.motion;
        let profile = self.control.app().profile();
        *self = PersistentApp::boot(profile, config, flash, self.pages)
            .unwrap_or_else(|| unreachable!("booted once"));
        self.motion = motion;
    }
}

impl<const N: usize, const PAGE: usize> UnitLogic for PersistentApp<N, PAGE> {
    fn step(
        &mut self,
        now: Instant,
        dt_ms: u32,
        model: &mut Model,
        rx: &[u8],
        tx: &mut Vec<u8>,
    ) -> Option<BoardAction> {
        if let Some(hung) = &mut self.hung_ms {
            // Nothing runs and the bridges hold their last inputs until the watchdog bites.
            model.step(dt_ms, &self.motors);
            *hung += dt_ms;
            if *hung >= WATCHDOG_MS {
                self.reboot(self.boot_config.clone());
            }
            return None;
        }
        let samples = model.samples::<N>();
        self.received.source_mut().receive(rx);
        let tick = Tick {
            now,
            lateness_us: 0,
            sample_age_us: 0,
            samples: &samples,
            button_down: false,
        };
        let step = self.control.step(&tick, &mut self.received);
        tx.extend_from_slice(&step.out.tx);
        // A failed write leaves the old record; the keeper tries again.
        let app = self.control.app();
        let before = self.keeper.store().flash().wear();
        let _ = match step.out.action {
            Some(action) => self.keeper.before(action, app),
            None if step.save_piece => self.keeper.update(app, now).map(drop),
            None => Ok(()),
        };
        let motors = if step.out.action.is_some() {
            [MotorCommand::Coast; N]
        } else {
            step.out.motors
        };
        let after = self.keeper.store().flash().wear();
        self.motion.step(
            &motors,
            (
                after.erases - before.erases,
                (after.bytes_written - before.bytes_written) / 8,
            ),
            (G0_ERASE_STALL_US, G0_PROGRAM_STALL_US),
            self.control.app().config().full_duty_speed,
        );
        model.step(dt_ms, &motors);
        self.motors = motors;
        step.out.action
    }

    fn command(&self) -> ((RequestCode, u8), Status) {
        let operation = self.control.app().operation();
        (operation.request, operation.status())
    }

    fn press_button(&mut self, button: ButtonCode) {
        self.control.app_mut().press_button(button);
    }

    fn config(&self) -> &Config {
        self.control.app().config()
    }

    fn power_on(&mut self, config: &Config) {
        self.reboot(config.clone());
    }

    fn hang(&mut self) {
        self.hung_ms.get_or_insert(0);
    }

    fn flash_wear(&mut self) -> FlashWear {
        self.motion.wear(self.keeper.store().flash().wear())
    }

    fn motors(&self) -> Vec<MotorCommand> {
        self.motors.to_vec()
    }
}

/// A unit logic with `slots` slots on the hardware `profile` booted on a blank `store`, or
/// `None` when the count is not 1 to what the profile has.
pub fn new_logic(
    slots: usize,
    profile: &'static Profile,
    config: Config,
    store: StoreFlash,
) -> Option<Box<dyn UnitLogic>> {
    const _: () = assert!(MAX_SLOTS == 5, "new_logic lists every slot count");
    fn boxed<const N: usize>(
        profile: &'static Profile,
        config: Config,
        store: StoreFlash,
    ) -> Option<Box<dyn UnitLogic>> {
        fn on<const N: usize, const PAGE: usize>(
            profile: &'static Profile,
            config: Config,
            pages: usize,
        ) -> Option<Box<dyn UnitLogic>> {
            PersistentApp::<N, PAGE>::boot(profile, config, MemFlash::new(pages), pages)
                .map(|app| Box::new(app) as Box<dyn UnitLogic>)
        }
        match store {
            StoreFlash::G071 => on::<N, G0_PAGE>(profile, config, G071_PAGES),
            StoreFlash::Bmcu => on::<N, BMCU_PAGE>(profile, config, BMCU_PAGES),
        }
    }
    match slots {
        1 => boxed::<1>(profile, config, store),
        2 => boxed::<2>(profile, config, store),
        3 => boxed::<3>(profile, config, store),
        4 => boxed::<4>(profile, config, store),
        5 => boxed::<5>(profile, config, store),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mmu_model::ModelConfig;

    #[test]
    fn every_supported_slot_count_boots_and_no_other() {
        for slots in 1..=MAX_SLOTS {
            let mut logic = new_logic(
                slots,
                &mmu_firmware::profile::THESIS,
                Config::default(),
                StoreFlash::G071,
            )
            .expect("supported count");
            let mut model = Model::new(ModelConfig::default(), slots, 1);
            let mut tx = Vec::new();
            for ms in 0..300 {
                logic.step(Instant::from_millis(ms), 1, &mut model, &[], &mut tx);
            }
            assert_eq!(logic.command(), ((RequestCode::Reset, 0), Status::Finished));
        }
        assert!(
            new_logic(
                0,
                &mmu_firmware::profile::THESIS,
                Config::default(),
                StoreFlash::G071
            )
            .is_none()
        );
        assert!(
            new_logic(
                MAX_SLOTS + 1,
                &mmu_firmware::profile::THESIS,
                Config::default(),
                StoreFlash::G071
            )
            .is_none()
        );
    }

    /// The BMCU-C's lanes run on its board's 4 KB store (four 1 KiB pages: the store's entries
    /// must fit a quarter page), and a unit boots on it.
    #[test]
    fn the_bmcu_profile_keeps_its_state_in_the_bmcu_store() {
        let profile = &mmu_firmware::profile::BMCU_C;
        assert_eq!(StoreFlash::of_profile(profile), StoreFlash::Bmcu);
        assert_eq!(
            StoreFlash::of_profile(&mmu_firmware::profile::THESIS),
            StoreFlash::G071
        );
        let mut logic =
            new_logic(4, profile, Config::for_profile(profile), StoreFlash::Bmcu).expect("4 lanes");
        let mut model = Model::new(crate::sim::model_for(profile, &ModelConfig::default()), 4, 1);
        let mut tx = Vec::new();
        for ms in 0..300 {
            logic.step(Instant::from_millis(ms), 1, &mut model, &[], &mut tx);
        }
        assert_eq!(logic.command(), ((RequestCode::Reset, 0), Status::Finished));
    }

    #[test]
    fn a_hung_loop_keeps_its_motors_until_the_watchdog_boots_the_unit_again() {
        let mut logic = new_logic(
            3,
            &mmu_firmware::profile::THESIS,
            Config::default(),
            StoreFlash::G071,
        )
        .expect("3 slots");
        let mut model = Model::new(ModelConfig::default(), 3, 1);
        let mut tx = Vec::new();
        let tool_0 = mmu_protocol::Request::new(RequestCode::Tool, 0).encode();
        for ms in 0..400 {
            let rx = if ms == 300 { tool_0.as_bytes() } else { &[] };
            logic.step(Instant::from_millis(ms), 1, &mut model, rx, &mut tx);
        }
        assert_eq!(logic.command().0, (RequestCode::Tool, 0));
        let driven = logic.motors();
        assert_ne!(driven[0], MotorCommand::Coast);
        logic.hang();
        for ms in 400..400 + u64::from(WATCHDOG_MS) - 1 {
            logic.step(Instant::from_millis(ms), 1, &mut model, &[], &mut tx);
        }
        assert_eq!(
            (logic.command().0, logic.motors()),
            ((RequestCode::Tool, 0), driven)
        );
        logic.step(Instant::from_millis(499), 1, &mut model, &[], &mut tx);
        // Booted again: its start-up check runs under `X0`.
        assert_eq!(logic.command().0, (RequestCode::Reset, 0));
    }
}
