//! The power-cut study: random lives of a unit (lane changes, counters, settings written by the
//! printer, `X0`, `X42`, power losses) driven through the unit logic ([`App`]) and the save policy
//! the firmware runs ([`Keeper`]) on a flash that behaves like the STM32G0's ([`MemFlash`]), cut by
//! a power loss at every double-word program and every page erase under every [`CutModel`].
//!
//! After each cut the unit boots again on what the flash holds, and the study checks what a user
//! would notice: every record (lanes, counters, settings) is the one the last completed save left
//! or the one being saved, never older and never a mix; saving goes on (each later save reads back);
//! `X42` forgets everything but the unit's identity (register 0x52); and the store never erases
//! pages in a loop (at most [`MAX_ERASES_AFTER_CUT`] erases in the second after the restart).

use mmu_firmware::persist::{FULL_CHECK_MS, Keeper, Snapshot, Store};
use mmu_firmware::unit::Lane;
use mmu_firmware::{App, BoardAction, Config, Instant, Samples};
use mmu_model::Rng;
use mmu_protocol::{Request, RequestCode};

use crate::flash::{CutModel, G0_PAGE, MemFlash};

/// The longest a unit's start-up check may take before it listens, ms.
const START_UP_MAX_MS: u32 = 5_000;

/// Slots of the studied unit.
pub const SLOTS: usize = 3;
/// The flash of the study: STM32G0 pages.
pub type Flash = MemFlash<G0_PAGE>;
/// Page erases allowed in the 1000 steps (1 ms each) after a restart that follows a cut.
pub const MAX_ERASES_AFTER_CUT: u64 = 4;
/// Actions of the life carried on after a cut and its restart, before the last checks.
const LATER_ACTIONS: usize = 6;
/// The identity register: the revision `S2` reports.
pub const IDENTITY: u8 = 0x52;

/// Settings the printer may write, with the range each accepts (a sensor's thresholds are
/// refused when they do not make a pair: the App answers `R` and keeps the old ones).
const SETTINGS: [(u8, u16, u16); 13] = [
    (0x90, 100, 4000),
    (0xa0, 100, 4000),
    (0x91, 100, 4000),
    (0xa1, 100, 4000),
    (0x0b, 0, 255),
    (0x0c, 0, 255),
    (0x22, 50, 2000),
    (0x41, 1, 200),
    (0x46, 10, 2000),
    (0x47, 5, 500),
    (0x4c, 0, 4095),
    (0x4e, 0, 100),
    (IDENTITY, 2, 3),
];

/// One thing that happens to the unit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Action {
    /// Filament moved: the lanes as the unit now believes them.
    Lanes([Lane; SLOTS]),
    /// A tool change to this slot completed (counters), or with `true`, an error was raised.
    Count(usize, bool),
    /// The printer writes a setting register (`W`).
    Write(u8, u16),
    /// `X0`: save and restart.
    Reset,
    /// `X42`: forget and restart.
    Forget,
    /// The power goes between saves and comes back.
    PowerCycle,
}

/// A random life of `length` actions, with the time (ms) each happens after the previous one.
pub fn life(seed: u64, length: usize) -> Vec<(u64, Action)> {
    let mut rng = Rng::new(seed);
    let mut pick = |n: u64| (rng.next_u64() % n) as usize;
    (0..length)
        .map(|_| {
            let wait = [1, 40, 3_000, 12_000][pick(4)];
            let action = match pick(100) {
                0..=44 => Action::Lanes(core::array::from_fn(|_| Lane::ALL[pick(Lane::ALL.len() as u64)])),
                45..=64 => Action::Count(pick(SLOTS as u64), pick(5) == 0),
                65..=91 => {
                    let (address, min, max) = SETTINGS[pick(SETTINGS.len() as u64)];
                    Action::Write(address, min + pick(u64::from(max - min) + 1) as u16)
                }
                92..=94 => Action::Reset,
                95..=96 => Action::Forget,
                _ => Action::PowerCycle,
            };
            (wait as u64, action)
        })
        .collect()
}

/// The unit: its logic, its save policy and the time.
#[derive(Clone)]
pub struct Unit {
    /// The unit logic.
    pub app: App<SLOTS>,
    /// Its save policy.
    pub keeper: Keeper<Flash, SLOTS>,
    /// The time of the last step.
    pub now: Instant,
    pages: usize,
    /// The most flash work one save, and one call of the keeper, have done.
    pub worst_save: WorstSave,
}

/// The most flash work one save did, whole and in one call of the keeper (one control step):
/// what stalls the CPU (each erase up to 40 ms, each double-word program up to 125 µs on the
/// STM32G071).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WorstSave {
    /// Double-word programs of one save.
    pub programs: u64,
    /// Page erases of one save.
    pub erases: u64,
    /// Calls of the keeper (1 ms steps) one save took.
    pub steps: u64,
    /// Double-word programs of one call.
    pub programs_per_step: u64,
    /// Page erases of one call.
    pub erases_per_step: u64,
}

/// Calls of the keeper the simulated control loop makes for one save at most: a save that is
/// still in progress then is a failure of the study (the store bounds its saves well below).
const MAX_SAVE_STEPS: u64 = 500;

fn store(flash: Flash, pages: usize) -> Store<Flash, SLOTS> {
    Store::new(flash, 0..(pages * G0_PAGE) as u32).unwrap_or_else(|_| unreachable!("a valid region"))
}

impl Unit {
    /// Boot on `flash`, a store of `pages` pages, at `now`.
    pub fn boot(flash: Flash, pages: usize, now: Instant) -> Self {
        let mut app = App::new(Config::default());
        let (keeper, _) = Keeper::boot(store(flash, pages), &mut app);
        Unit {
            app,
            keeper,
            now,
            pages,
            worst_save: WorstSave::default(),
        }
    }

    /// The flash operations done so far: (double-word programs, page erases).
    fn flash_work(&mut self) -> (u64, u64) {
        let erases = self.flash().wear().erases;
        (self.flash().operations - erases, erases)
    }

    /// The keeper's calls after a step, as the firmware's control loop makes them: one now, then
    /// one per 1 ms step while a save is in progress. Notes the flash work of the save and of
    /// each call.
    pub fn save_steps(&mut self) {
        self.save_steps_with(&mut |_| {});
    }

    /// As [`Unit::save_steps`], calling `between` after each call that leaves a save in
    /// progress.
    fn save_steps_with(&mut self, between: &mut dyn FnMut(&mut Unit)) {
        let before = self.flash_work();
        let mut steps = 0;
        loop {
            let call = self.flash_work();
            let _ = self.keeper.update(&self.app, self.now);
            let (programs, erases) = self.flash_work();
            let worst = &mut self.worst_save;
            worst.programs_per_step = worst.programs_per_step.max(programs - call.0);
            worst.erases_per_step = worst.erases_per_step.max(erases - call.1);
            steps += 1;
            if !self.keeper.is_saving() || steps >= MAX_SAVE_STEPS {
                break;
            }
            between(self);
            self.now = self.now + 1;
        }
        let (programs, erases) = self.flash_work();
        let worst = &mut self.worst_save;
        worst.programs = worst.programs.max(programs - before.0);
        worst.erases = worst.erases.max(erases - before.1);
        worst.steps = worst.steps.max(steps);
    }

    /// Save before `action` (whole, as the firmware does before a reset), noting the flash work.
    fn save_before(&mut self, action: BoardAction) {
        let before = self.flash_work();
        let _ = self.keeper.before(action, &self.app);
        let (programs, erases) = self.flash_work();
        let worst = &mut self.worst_save;
        worst.programs = worst.programs.max(programs - before.0);
        worst.erases = worst.erases.max(erases - before.1);
    }

    /// The flash.
    pub fn flash(&mut self) -> &mut Flash {
        self.keeper.store().flash()
    }

    /// The power goes and comes back.
    pub fn restart(mut self) -> Self {
        let (now, pages, worst_save) = (self.now, self.pages, self.worst_save);
        let flash = std::mem::replace(self.flash(), Flash::new(0));
        Unit {
            worst_save,
            ..Unit::boot(flash, pages, now)
        }
    }

    /// Change the App's beliefs the way its commands do (lanes and counters).
    pub fn believe(&mut self, change: impl FnOnce(&mut Snapshot<SLOTS>)) {
        let mut snapshot = self.app.snapshot();
        change(&mut snapshot);
        self.app.restore(&snapshot);
    }

    /// A frame from the printer; the board action it asks for, if any.
    fn receive(&mut self, request: Request) -> Option<BoardAction> {
        self.ask(request).1
    }

    /// A frame from the printer, in one step: what the unit answers and the board action.
    pub fn ask(&mut self, request: Request) -> (String, Option<BoardAction>) {
        // The unit hears nothing before its start-up check has ended, and takes a frame only at
        // the start of a quiet line.
        for _ in 0..START_UP_MAX_MS {
            if self.app.is_listening() {
                break;
            }
            self.now = self.now + 1;
            self.app.step(self.now, &Samples::default(), &[]);
        }
        self.now = self.now + u64::from(mmu_protocol::SILENCE_MS);
        self.app.step(self.now, &Samples::default(), &[]);
        let frame = request.encode();
        let out = self.app.step(self.now, &Samples::default(), frame.as_bytes());
        (String::from_utf8_lossy(&out.tx).into_owned(), out.action)
    }

    /// Carry out `action` `wait` ms after the last one, the way the firmware's control loop does.
    pub fn act(self, wait: u64, action: &Action) -> Self {
        self.act_with(wait, action, &mut |_| {})
    }

    /// As [`Unit::act`], calling `between` between two steps of a save in progress (where the
    /// power may go as well as during a flash operation).
    pub fn act_with(mut self, wait: u64, action: &Action, between: &mut dyn FnMut(&mut Unit)) -> Self {
        self.now = Instant::from_millis(self.now.as_millis() + wait);
        let board = match *action {
            Action::Lanes(lanes) => {
                self.believe(|s| s.lanes = lanes);
                None
            }
            Action::Count(slot, error) => {
                self.believe(|s| {
                    if error {
                        s.counters.drive_errors += 1;
                        s.counters.failures[slot] += 1;
                    } else {
                        s.counters.tool_changes[slot] += 1;
                        s.counters.fed_mm[slot] += 1234;
                    }
                });
                None
            }
            Action::Write(address, value) => self.receive(Request::write(address, value)),
            Action::Reset => self.receive(Request::new(RequestCode::Reset, 0)),
            Action::Forget => self.receive(Request::new(RequestCode::Reset, 42)),
            Action::PowerCycle => return self.restart(),
        };
        match board {
            Some(board) => {
                self.save_before(board);
                self.restart()
            }
            None => {
                // The control loop compares lanes every step, the rest every FULL_CHECK_MS.
                self.save_steps_with(between);
                self.now = Instant::from_millis(self.now.as_millis() + FULL_CHECK_MS);
                self.save_steps_with(between);
                self
            }
        }
    }

    /// What a unit booted on a copy of this flash restores.
    pub fn stored(&mut self) -> Snapshot<SLOTS> {
        let copy = self.flash().clone();
        Unit::boot(copy, self.pages, self.now).app.snapshot()
    }
}

/// What one seed of the study found.
#[derive(Debug, Default)]
pub struct CutReport {
    /// Actions of the life.
    pub actions: usize,
    /// Flash operations (double-word programs and page erases) of the uncut life.
    pub operations: u64,
    /// Page erases of the uncut life.
    pub erases: u64,
    /// Page erases among the cut operations.
    pub erases_cut: usize,
    /// The most flash work one save of the uncut life did.
    pub worst_save: WorstSave,
    /// Cuts tried, per model ([`CutModel::ALL`] order).
    pub cuts: [usize; 3],
    /// Second cuts tried (during the first save after a cut's restart).
    pub second_cuts: usize,
    /// What went wrong, one line each.
    pub failures: Vec<String>,
}

/// Whether `record` of the restored snapshot is the stored one before or after the cut action.
fn old_or_new<T: PartialEq + core::fmt::Debug>(
    failures: &mut Vec<String>,
    what: &str,
    got: &T,
    before: &T,
    after: &T,
) {
    if got != before && got != after {
        failures.push(format!("{what} {got:?}, expected {before:?} or {after:?}"));
    }
}

/// Lanes and settings are saved by the save that follows their change (the calls of
/// [`Unit::save_steps`]): what a copy of the flash restores.
fn saved_now(unit: &mut Unit) -> Result<(), String> {
    let stored = unit.stored();
    let live = unit.app.snapshot();
    if stored.lanes != live.lanes || stored.settings != live.settings {
        return Err(format!(
            "not saved: lanes {:?} settings {:?} stored, lanes {:?} settings {:?} live",
            stored.lanes, stored.settings, live.lanes, live.settings
        ));
    }
    Ok(())
}

/// Which cuts a study tries.
#[derive(Debug, Clone)]
pub struct Plan {
    /// Pages of the store's region.
    pub pages: usize,
    /// Actions of each life.
    pub length: usize,
    /// Every `stride`-th flash operation is cut (1: every one).
    pub stride: u64,
    /// Cut page erases only.
    pub erases_only: bool,
    /// Check after every action of the uncut life that lanes and settings are saved.
    pub check_every_save: bool,
    /// Cuts start at this action (the ones before age the flash: the region wraps).
    pub first_cut_action: usize,
    /// After each cut, also cut the first save after the restart at each of its first this many
    /// operations (one life each; torn, with unreadable double words).
    pub second_cuts: u64,
    /// The cut models tried.
    pub models: Vec<CutModel>,
}

impl Plan {
    /// Every operation of a life of `length` actions on `pages` pages, every model.
    pub fn every_cut(pages: usize, length: usize) -> Self {
        Plan {
            pages,
            length,
            stride: 1,
            erases_only: false,
            check_every_save: true,
            first_cut_action: 0,
            second_cuts: 0,
            models: CutModel::ALL.to_vec(),
        }
    }
}

/// Run `seed`'s life as `plan` says, cut it at each chosen flash operation under each model, and
/// check each cut.
pub fn study(seed: u64, plan: &Plan) -> CutReport {
    let (pages, length) = (plan.pages, plan.length);
    let life = life(seed, length);
    let mut report = CutReport {
        actions: length,
        ..CutReport::default()
    };
    // The uncut life: the unit before each action (to fork cut lives from, with the flash
    // operations done until then), and the unit at its end.
    let mut unit = Unit::boot(Flash::new(pages), pages, Instant::ZERO);
    let mut forks = Vec::with_capacity(length + 1);
    for (wait, action) in &life {
        forks.push((unit.flash().operations, unit.clone()));
        unit = unit.act(*wait, action);
        let restarted = matches!(action, Action::PowerCycle | Action::Reset | Action::Forget);
        if plan.check_every_save
            && !restarted
            && let Err(e) = saved_now(&mut unit)
        {
            report
                .failures
                .push(format!("seed {seed}, uncut, after {action:?}: {e}"));
        }
    }
    forks.push((unit.flash().operations, unit.clone()));
    report.worst_save = unit.worst_save;
    report.operations = unit.flash().operations;
    report.erases = unit.flash().wear().erases;
    let first = forks.get(plan.first_cut_action).map_or(u64::MAX, |(ops, _)| *ops);
    let cuts: Vec<u64> = if plan.erases_only {
        unit.flash().erase_operations.clone()
    } else {
        (0..report.operations).collect()
    };
    let cuts: Vec<u64> = cuts.into_iter().filter(|&op| op >= first).collect();

    let erase_operations = &unit.flash().erase_operations;
    report.erases_cut = cuts.iter().filter(|op| erase_operations.contains(op)).count();
    for &model in &plan.models {
        let model_index = CutModel::ALL.iter().position(|&m| m == model).unwrap_or(0);
        for &cut in cuts.iter().step_by(plan.stride.max(1) as usize) {
            report.cuts[model_index] += 1;
            let place = format!("seed {seed}, {model:?} cut at operation {cut}");
            if let Err(e) = cut_once(&life, &mut forks, cut, model, seed ^ cut, None) {
                report.failures.push(format!("{place}: {e}"));
            }
            for offset in 0..plan.second_cuts {
                let second = Some((offset, CutModel::TornUnreadable));
                match cut_once(&life, &mut forks, cut, model, seed ^ cut, second) {
                    Ok(true) => report.second_cuts += 1,
                    Ok(false) => break,
                    Err(e) => {
                        report.second_cuts += 1;
                        report.failures.push(format!("{place}: {e}"));
                    }
                }
            }
        }
    }
    report
}

/// One life cut at operation `cut`: `Err` with what went wrong. The life is forked from the
/// uncut one just before the action during which the cut falls (`forks`: the unit before each
/// action and the flash operations done until then).
///
/// With `second`, the first save after the restart is cut too, at that operation under that
/// model; `Ok(false)` when that save has fewer operations (nothing was cut a second time).
fn cut_once(
    life: &[(u64, Action)],
    forks: &mut [(u64, Unit)],
    cut: u64,
    model: CutModel,
    seed: u64,
    second: Option<(u64, CutModel)>,
) -> Result<bool, String> {
    let index = forks.partition_point(|(ops, _)| *ops <= cut).saturating_sub(1);
    let (Some((ops_before, fork)), Some((wait, action))) = (forks.get(index), life.get(index)) else {
        return Ok(false);
    };
    let mut unit = fork.clone();
    unit.flash().cut_power_at(cut - ops_before, model, seed);
    unit = unit.act(*wait, action);
    if !unit.flash().is_cut() {
        return Ok(false); // The cut falls after the life's last operation.
    }
    unit.flash().power_on();
    let erases_before = unit.flash().wear().erases;
    let mut unit = unit.restart();
    let (before, after) = (forks[index].1.stored(), forks[index + 1].1.stored());
    let during = &life[index].1;
    check_restored(&unit, &before, &after).map_err(|e| format!("during {during:?}: {e}"))?;
    // A second cut, during the first save after the restart (a fresh page being opened).
    if let Some((offset, second_model)) = second {
        let recovery = Action::Lanes([Lane::Parked, Lane::Unknown, Lane::Empty]);
        let before = unit.stored();
        let after = unit.clone().act(1, &recovery).stored();
        unit.flash()
            .cut_power_at(offset, second_model, seed.rotate_left(17));
        unit = unit.act(1, &recovery);
        if !unit.flash().is_cut() {
            return Ok(false);
        }
        unit.flash().power_on();
        unit = unit.restart();
        check_restored(&unit, &before, &after)
            .map_err(|e| format!("second {second_model:?} cut {offset} operations after the restart: {e}"))?;
    }

    // The save loop after the restart: a lane change, then a second of 1 ms steps.
    unit.believe(|s| s.lanes = [Lane::Parked, Lane::Unknown, Lane::Empty]);
    for _ in 0..1000 {
        unit.now = Instant::from_millis(unit.now.as_millis() + 1);
        let _ = unit.keeper.update(&unit.app, unit.now);
    }
    let erases = unit.flash().wear().erases - erases_before;
    if erases > MAX_ERASES_AFTER_CUT {
        return Err(format!(
            "during {during:?}: {erases} page erases in the second after the restart"
        ));
    }
    // Saving goes on for the rest of the life.
    for (wait, action) in life.iter().skip(index + 1).take(LATER_ACTIONS) {
        unit = unit.act(*wait, action);
    }
    saved_now(&mut unit).map_err(|e| format!("later in the life: {e}"))?;
    // `X42` forgets everything but the identity.
    let identity = unit
        .app
        .snapshot()
        .settings
        .into_iter()
        .find(|&(a, _)| a == IDENTITY);
    unit = unit.act(1, &Action::Forget);
    let forgotten = unit.app.snapshot();
    let expected = Snapshot::<SLOTS> {
        settings: identity.into_iter().collect(),
        ..Snapshot::default()
    };
    if forgotten != expected {
        return Err(format!("after X42: {forgotten:?}, expected {expected:?}"));
    }
    Ok(true)
}

/// Each record the restarted `unit` restored is the stored one before or after the cut action.
fn check_restored(unit: &Unit, before: &Snapshot<SLOTS>, after: &Snapshot<SLOTS>) -> Result<(), String> {
    let restored = unit.app.snapshot();
    let mut failures = Vec::new();
    old_or_new(
        &mut failures,
        "lanes",
        &restored.lanes,
        &before.lanes,
        &after.lanes,
    );
    old_or_new(
        &mut failures,
        "counters",
        &restored.counters,
        &before.counters,
        &after.counters,
    );
    old_or_new(
        &mut failures,
        "settings",
        &restored.settings,
        &before.settings,
        &after.settings,
    );
    if failures.is_empty() {
        Ok(())
    } else {
        Err(format!("restored {}", failures.join("; ")))
    }
}
