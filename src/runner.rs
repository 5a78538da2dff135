//! The runner: carries out the current command's plan, phase by phase, and reports where it
//! stands.
//!
//! It steps the running phase ([`crate::phases::step`]), moves on when a phase is done (in the
//! same step when the next can finish at once), stops every motor of the command and holds the
//! error when one fails, and on a button in an error state does what the command's recovery
//! table says ([`Command::on_button`]).
//!
//! A command the printer sends while another command's error waits is accepted and takes the
//! error over before anything moves ([`Runner::supersede`]): Prusa's printer re-sends a rejected
//! command at once and forever, so it could never send the Retry of the screen it shows
//! (`protocol_logic.cpp` `CommandRejected` → `CommandRestart`; printer-truth §2.3, §7). Its plan
//! is made once the error is resolved, from what the sensors then say.

use mmu_protocol::{ButtonCode, ErrorCode, ProgressCode, RequestCode};

use crate::commands::{Action, Command, MAX_PHASES, Plan, Retry, clear_hub, extend, fit_to_profile};
use crate::config::Config;
use crate::phases::{self, Notes, Outcome, Phase, PhaseRun, PrinterLink, UnloadStuck};
use crate::time::Instant;
use crate::unit::Unit;

/// Where the current command stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Status {
    /// A phase is running.
    Running(ProgressCode),
    /// Stopped on an error, waiting for the user (or the printer's automatic Retry).
    Failed(ErrorCode),
    /// Done.
    Finished,
}

/// A setting a recovery learned.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Learned {
    /// The Bowden length (register 0x22), mm, measured when the printer's sensor triggered.
    BowdenMm(u16),
}

/// The command being carried out (or the last one).
#[derive(Debug, Clone)]
pub struct Runner {
    /// The request this command answers for (echoed by `Q0`).
    pub request: (RequestCode, u8),
    command: Option<Command>,
    plan: Plan,
    index: usize,
    run: Option<PhaseRun>,
    status: Status,
    notes: Notes,
    /// The failed phase's distance goal start, for the attempt after Retry.
    resume_goal_from: Option<i32>,
    /// How far the failed phase moved its filament from its goal start, 1/100 mm.
    failed_fed_centi: Option<i32>,
    /// When the plan runs out, make the command's own plan (from the sensors as they are then)
    /// instead of finishing: the plan so far only resolved an error in its way.
    then_plan: bool,
    /// The command whose recovery table answers the buttons for the error shown, when the error
    /// was taken over from it ([`Runner::supersede`]).
    inherited: Option<Command>,
    /// The error shown came after the command had finished (the follower's jam while printing):
    /// Retry finishes it again instead of planning it again.
    failed_after_finish: bool,
    /// Why the failed phase's unload stopped on `8004`, when it could tell.
    stuck: Option<UnloadStuck>,
}

impl Runner {
    /// A runner that carries out `plan` for `request`.
    pub fn new(request: (RequestCode, u8), plan: &[Phase]) -> Self {
        let mut phases = Plan::new();
        extend(&mut phases, plan);
        let status = match phases.first() {
            Some(phase) => Status::Running(phase.progress()),
            None => Status::Finished,
        };
        Runner {
            request,
            command: Command::of(request.0),
            plan: phases,
            index: 0,
            run: None,
            status,
            notes: Notes::default(),
            resume_goal_from: None,
            failed_fed_centi: None,
            then_plan: false,
            inherited: None,
            failed_after_finish: false,
            stuck: None,
        }
    }

    /// Start the command `request` asks for on `unit`: its plan, or the error it fails with
    /// before anything moves.
    pub fn start<const N: usize>(request: (RequestCode, u8), unit: &Unit<N>, config: &Config) -> Self {
        let mut plan = Plan::new();
        let planned = match Command::of(request.0) {
            Some(command) => command.plan(request.1, unit, config, &mut plan),
            None => Err(ErrorCode::INTERNAL),
        };
        match planned {
            Ok(()) => Self::new(request, &plan),
            Err(error) => Self::failed(request, error),
        }
    }

    /// A command that failed before it moved anything. Retry plans it again.
    pub fn failed(request: (RequestCode, u8), error: ErrorCode) -> Self {
        let mut runner = Self::new(request, &[]);
        runner.status = Status::Failed(error);
        runner
    }

    /// The command `request` arrives while `waiting`'s error waits for the user: it takes the
    /// error over and moves nothing. The buttons then do what `waiting`'s recovery table says;
    /// once the error is resolved the command is planned from the sensors. An error of the
    /// sensor check (start-up or `H0`) is resolved by checking again, trusting the sensors as
    /// Retry does; any other by the new command's plan itself, which starts by clearing
    /// whatever the failed command left in the hub path.
    pub fn supersede(waiting: &Runner, request: (RequestCode, u8)) -> Self {
        let mut runner = Self::new(request, &[]);
        runner.status = waiting.status;
        runner.stuck = waiting.stuck;
        runner.inherited = waiting.inherited.or(waiting.command);
        runner.then_plan = true;
        if waiting.phase() == Some(Phase::CheckSensors) {
            extend(&mut runner.plan, &[Phase::CheckSensors]);
        }
        runner
    }

    /// Where the command stands.
    pub fn status(&self) -> Status {
        self.status
    }

    /// Why the unload stopped, while its FSENSOR DIDNT CLEAR (`8004`) waits for the user and the
    /// unit could tell.
    pub fn unload_stuck(&self) -> Option<UnloadStuck> {
        match self.status {
            Status::Failed(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF) => self.stuck,
            _ => None,
        }
    }

    /// Whether the phase running began (or resumed) at `now`: its motion's budget was worked
    /// out in this step.
    pub fn phase_began_at(&self, now: Instant) -> bool {
        self.run.as_ref().is_some_and(|run| run.started() == now)
    }

    /// The phase running (or failed), if any.
    pub fn phase(&self) -> Option<Phase> {
        self.plan.get(self.index).copied()
    }

    /// The slot motor this command drives now.
    pub fn driving_slot(&self) -> Option<usize> {
        match self.status {
            Status::Running(_) => self.phase().and_then(Phase::slot),
            _ => None,
        }
    }

    /// A setting the command's phases measured on the way (a Bowden length), once.
    pub fn take_learned(&mut self) -> Option<Learned> {
        self.notes.bowden_measured_mm.take().map(Learned::BowdenMm)
    }

    /// The printer (or the unit's own button) pressed `button`: in an error state, what the
    /// recovery table says; otherwise nothing. A command that failed before any phase ran is
    /// planned again from the sensors on Retry (it fails again with the cause then present, or
    /// runs): its Retry must never report a finish nothing led to. A setting the recovery
    /// learned (the Bowden length after `8009`) goes into `config`, and is returned.
    pub fn press<const N: usize>(
        &mut self,
        button: ButtonCode,
        unit: &Unit<N>,
        config: &mut Config,
    ) -> Option<Learned> {
        let (Status::Failed(error), Some(command)) = (self.status, self.inherited.or(self.command)) else {
            return None;
        };
        let action = command.on_button(error, button)?;
        let mut learned = None;
        let inherited = self.inherited.take();
        match action {
            Action::Continue => self.advance(),
            Action::RetryPhase => self.retry_phase(),
            Action::Replan(replan) => match self.phase().and_then(Phase::slot) {
                Some(slot) => {
                    let retry = Retry {
                        slot,
                        fsensor: unit.fsensor_triggered(),
                        hub: unit.hub_present() == Some(true),
                        fed_mm: self.failed_fed_centi.map(|centi| centi / 100),
                    };
                    let mut plan = Plan::new();
                    let Some(replanned) = replan.plan(&retry, config, &mut plan) else {
                        self.inherited = inherited;
                        return None;
                    };
                    fit_to_profile(&mut plan, unit);
                    if let Some(bowden_mm) = replanned.bowden_mm {
                        config.bowden_mm = bowden_mm;
                        learned = Some(Learned::BowdenMm(bowden_mm));
                    }
                    let then_plan = self.then_plan;
                    *self = Runner::new(self.request, &plan);
                    self.then_plan = then_plan;
                    self.notes.trust_sensors = true;
                }
                None => self.then_plan = true,
            },
            Action::UnloadFirst => {
                let mut unload = Plan::new();
                // The printer helps an unload it did not ask for on `P3` (`mmu2_mk4.cpp`
                // `OnMMUProgressMsgChanged`): wait for it to release the filament.
                if let Err(error) = clear_hub(&mut unload, unit, true) {
                    self.status = Status::Failed(error);
                    return None;
                }
                fit_to_profile(&mut unload, unit);
                *self = Runner::new(self.request, &unload);
                self.then_plan = true;
            }
        }
        self.plan_when_due(unit, config);
        learned
    }

    /// Run the failed phase again, trusting the sensors (or plan the command again when the
    /// error came before any phase).
    fn retry_phase(&mut self) {
        self.notes.trust_sensors = true;
        self.run = None;
        // Only `P1c` seen anew makes the printer push its extruder again, and only its push can
        // show the gears taking the tip (printer-truth §8): the push into the extruder is retried
        // from the phase before it, the feed to the printer's sensor (every plan has one there).
        // The printer helps an unload after `8004`'s Retry with its own extruder (Buddy
        // `mmu2_mk4.cpp` `CheckUserInput`, `HelpUnloadToFinda`): an unload retried waits for it
        // to release the filament before it pulls, whatever the printer.
        if let Some(Phase::UnloadToHub { await_release, .. }) = self.plan.get_mut(self.index) {
            *await_release = true;
        }
        // A feed to the park position counts from the presence sensor's edge: retried from the
        // homing before it, which finds the edge again.
        let before = self.index.checked_sub(1);
        let from_before = matches!(
            (self.phase(), before.and_then(|before| self.plan.get(before))),
            (
                Some(Phase::FeedToNozzle { .. }),
                Some(Phase::FeedToFsensor { .. } | Phase::SearchFsensor { .. })
            ) | (Some(Phase::FeedToPark { .. }), Some(Phase::HomeLane { .. }))
        );
        if let (true, Some(before)) = (from_before, before) {
            self.index = before;
            self.resume_goal_from = None;
        }
        match self.phase() {
            Some(phase) => self.status = Status::Running(phase.progress()),
            // The command had done its work: planning it again would ask its question again
            // (FIL. ALREADY LOADED, FILAMENT EJECTED) or move filament it moved.
            None if self.failed_after_finish => self.status = Status::Finished,
            None => self.then_plan = true,
        }
        self.failed_after_finish = false;
    }

    /// Something went wrong outside the plan (the follower could not follow while printing): the
    /// command reports `error` until a button the recovery table names for it. An error already
    /// shown stays.
    ///
    /// A command still running is stopped at once, its motor braked in this very step as when a
    /// phase of its own fails (otherwise it would be driven once more, then coast). The error is
    /// reported on this command, the one the printer follows: Prusa's printer shows whatever
    /// error a `Q0` answer carries, but waits for its own command's `F0` to go on (another
    /// command's finish means to it that its command was lost). So the printer shows PULLEY
    /// CANNOT MOVE and presses Retry (every command's table retries `804b`: [`JAM_ERROR`]);
    /// Retry lets the follower try again and, the interrupted plan being cut short, plans this
    /// command again from the sensors, so that the printer still gets its command carried out
    /// and its `F0`. A command that had finished is finished again by Retry instead.
    ///
    /// [`JAM_ERROR`]: crate::follower::JAM_ERROR
    pub fn interrupt<const N: usize>(&mut self, error: ErrorCode, unit: &mut Unit<N>, now: Instant) {
        if matches!(self.status, Status::Failed(_)) {
            return;
        }
        if let Some(slot) = self.driving_slot() {
            unit.brake(slot, now);
        }
        self.failed_after_finish = self.status == Status::Finished;
        self.index = self.plan.len();
        self.run = None;
        self.resume_goal_from = None;
        self.failed_fed_centi = None;
        self.status = Status::Failed(error);
    }

    /// Run [`Phase::ClearMerge`] for each suspect slot, then the blocked phase again.
    /// False, planning nothing, when the clearances do not fit the plan: the stall is then the
    /// error, never a loop of stalls that plans nothing.
    fn clear_merge_first(&mut self, suspects: phases::SlotSet) -> bool {
        if self.plan.len() + suspects.count_ones() as usize > MAX_PHASES {
            return false;
        }
        // Highest slot first, each before the blocked phase: they run in slot order. Every plan
        // fits with a clearance of each other slot (MAX_PHASES).
        // Pushed and swapped into place rather than `Vec::insert`, which alone links `memmove`
        // (1.3 KiB) into the image.
        for slot in (0..8).rev().filter(|slot| suspects & (1 << slot) != 0) {
            if self.plan.push(Phase::ClearMerge { slot }).is_ok() {
                for at in (self.index + 1..self.plan.len()).rev() {
                    // The pair taken as one slice: no bounds-check panic (`swap` had two).
                    if let Some([before, after]) = self.plan.get_mut(at - 1..=at) {
                        core::mem::swap(before, after);
                    }
                }
            }
        }
        self.run = None;
        self.resume_goal_from = None;
        self.status = self
            .phase()
            .map_or(Status::Finished, |phase| Status::Running(phase.progress()));
        true
    }

    fn advance(&mut self) {
        self.index += 1;
        self.run = None;
        self.resume_goal_from = None;
        self.status = match self.phase() {
            Some(phase) => Status::Running(phase.progress()),
            None => Status::Finished,
        };
    }

    /// With the plan run out and the command's own plan still to make, make it now from what
    /// the unit knows (the sensors, after a Retry).
    fn plan_when_due<const N: usize>(&mut self, unit: &Unit<N>, config: &Config) {
        if !self.then_plan || self.phase().is_some() {
            return;
        }
        self.then_plan = false;
        self.plan.clear();
        let planned = match self.command {
            Some(command) => command.plan(self.request.1, unit, config, &mut self.plan),
            None => Err(ErrorCode::INTERNAL),
        };
        self.index = 0;
        self.run = None;
        self.resume_goal_from = None;
        self.status = match planned {
            Ok(()) => self
                .plan
                .first()
                .map_or(Status::Finished, |phase| Status::Running(phase.progress())),
            Err(error) => {
                // Nothing of a refused plan runs.
                self.plan.clear();
                Status::Failed(error)
            }
        };
    }

    fn fail<const N: usize>(&mut self, error: ErrorCode, unit: &mut Unit<N>, now: Instant) {
        if let Some(slot) = self.phase().and_then(Phase::slot) {
            unit.brake(slot, now);
        }
        let run = self.run.take();
        self.stuck = run.and_then(|run| run.stuck());
        self.resume_goal_from = run.map(|run| run.goal_from_centi());
        self.failed_fed_centi = match (run, self.phase().and_then(Phase::slot)) {
            (Some(run), Some(slot)) => unit
                .feeders
                .get(slot)
                .map(|feeder| run.fed_centi(feeder.odometry_centi())),
            _ => None,
        };
        self.status = Status::Failed(error);
    }

    /// Advance the command to `now`: step the running phase and move on, finish or fail as the
    /// sensors say. A phase that depends on the printer holds its motor while the `printer` link
    /// is in doubt ([`PrinterLink::in_doubt`]).
    pub fn step<const N: usize>(
        &mut self,
        unit: &mut Unit<N>,
        now: Instant,
        config: &Config,
        printer: PrinterLink,
    ) {
        self.notes.printer = printer;
        // Phases that finish at once (a check, a move already at its goal) hand over in the same step.
        for _ in 0..MAX_PHASES {
            let Status::Running(_) = self.status else { return };
            self.plan_when_due(unit, config);
            let Some(phase) = self.phase() else {
                if let Status::Running(_) = self.status {
                    self.status = Status::Finished;
                }
                return;
            };
            let resume = self.resume_goal_from.take();
            match phases::step(phase, &mut self.run, resume, &mut self.notes, unit, now, config) {
                Outcome::Continue => return,
                Outcome::Done => {
                    self.advance();
                    self.plan_when_due(unit, config);
                }
                Outcome::Fail(error) => {
                    self.fail(error, unit, now);
                    return;
                }
                Outcome::Blocked(suspects) => {
                    if !self.clear_merge_first(suspects) {
                        self.fail(ErrorCode::STALLED_PULLEY, unit, now);
                    }
                    return;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn merge_clearances_run_in_slot_order_before_the_blocked_phase() {
        let plan = [
            Phase::CheckSensors,
            Phase::FeedToHub { slot: 1, max_mm: 100 },
            Phase::FeedThroughBowden { slot: 1 },
            Phase::FeedToFsensor { slot: 1 },
        ];
        let mut runner = Runner::new((RequestCode::Load, 1), &plan);
        runner.advance();
        assert!(runner.clear_merge_first(0b101));
        let expected = [
            Phase::CheckSensors,
            Phase::ClearMerge { slot: 0 },
            Phase::ClearMerge { slot: 2 },
            Phase::FeedToHub { slot: 1, max_mm: 100 },
            Phase::FeedThroughBowden { slot: 1 },
            Phase::FeedToFsensor { slot: 1 },
        ];
        assert_eq!(runner.plan.as_slice(), &expected);
        assert_eq!(runner.phase(), Some(Phase::ClearMerge { slot: 0 }));
        assert_eq!(
            runner.status(),
            Status::Running(ProgressCode::RETRACTING_FROM_FINDA)
        );
    }

    #[test]
    fn clearances_that_do_not_fit_the_plan_plan_nothing() {
        let plan = [Phase::FeedToHub { slot: 1, max_mm: 100 }; MAX_PHASES - 1];
        let mut runner = Runner::new((RequestCode::Load, 1), &plan);
        assert!(!runner.clear_merge_first(0b101));
        assert_eq!(runner.plan.as_slice(), &plan);
        assert!(runner.clear_merge_first(0b100));
    }
}
