//! The runner: carries out the current command's plan, phase by phase, and reports where it
//! stands.
//!
//! It steps the running phase ([`crate::phases::step`]), moves on when a phase is done (in the
//! same step when the next can finish at once), stops every motor of the command and holds the
//! error when one fails, and on a button in an error state does what the command's recovery
//! table says ([`Command::on_button`]).

use mmu_protocol::{ButtonCode, ErrorCode, ProgressCode, RequestCode};

use crate::commands::{Action, Command, MAX_PHASES, Plan, extend};
use crate::config::Config;
use crate::phases::{self, Notes, Outcome, Phase, PhaseRun};
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
        }
    }

    /// Start the command `request` asks for on `unit`: its plan, or the error it fails with
    /// before anything moves.
    pub fn start<const N: usize>(request: (RequestCode, u8), unit: &Unit<N>, config: &Config) -> Self {
        let planned = match Command::of(request.0) {
            Some(command) => command.plan(request.1, unit, config),
            None => Err(ErrorCode::INTERNAL),
        };
        match planned {
            Ok(plan) => Self::new(request, &plan),
            Err(error) => Self::failed(request, error),
        }
    }

    /// A command that failed before it moved anything.
    pub fn failed(request: (RequestCode, u8), error: ErrorCode) -> Self {
        let mut runner = Self::new(request, &[]);
        runner.status = Status::Failed(error);
        runner
    }

    /// Where the command stands.
    pub fn status(&self) -> Status {
        self.status
    }

    /// True while the command runs or waits in an error: new commands are refused.
    pub fn is_busy(&self) -> bool {
        match self.status {
            Status::Running(_) => true,
            // An invalid tool needs no recovery: the printer stops the print or resets the unit.
            Status::Failed(error) => error != ErrorCode::INVALID_TOOL,
            Status::Finished => false,
        }
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

    /// The printer (or the unit's own button) pressed `button`: in an error state, what the
    /// command's recovery table says; otherwise nothing.
    pub fn press(&mut self, button: ButtonCode, config: &Config) {
        let (Status::Failed(error), Some(command)) = (self.status, self.command) else {
            return;
        };
        match command.on_button(error, button) {
            None => {}
            Some(Action::Continue) => self.advance(),
            Some(Action::RetryPhase) => {
                self.notes.trust_sensors = true;
                self.run = None;
                self.status = self
                    .phase()
                    .map_or(Status::Finished, |phase| Status::Running(phase.progress()));
            }
            Some(Action::Replan(replan)) => {
                let Some(slot) = self.phase().and_then(Phase::slot) else {
                    return;
                };
                *self = Runner::new(self.request, &replan(slot, config));
                self.notes.trust_sensors = true;
            }
        }
    }

    /// Something went wrong outside the plan (the follower could not follow while printing): the
    /// command reports `error` until a button the recovery table names for it. An error already
    /// shown stays.
    pub fn interrupt(&mut self, error: ErrorCode) {
        if !matches!(self.status, Status::Failed(_)) {
            self.index = self.plan.len();
            self.run = None;
            self.status = Status::Failed(error);
        }
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

    fn fail<const N: usize>(&mut self, error: ErrorCode, unit: &mut Unit<N>, now: Instant) {
        if let Some(slot) = self.phase().and_then(Phase::slot) {
            unit.brake(slot, now);
        }
        self.resume_goal_from = self.run.take().map(|run| run.goal_from_centi());
        self.status = Status::Failed(error);
    }

    /// Advance the command to `now`: step the running phase and move on, finish or fail as the
    /// sensors say.
    pub fn step<const N: usize>(&mut self, unit: &mut Unit<N>, now: Instant, config: &Config) {
        // Phases that finish at once (a check, a move already at its goal) hand over in the same step.
        for _ in 0..MAX_PHASES {
            let Status::Running(_) = self.status else { return };
            let Some(phase) = self.phase() else {
                self.status = Status::Finished;
                return;
            };
            let resume = self.resume_goal_from.take();
            match phases::step(phase, &mut self.run, resume, &mut self.notes, unit, now, config) {
                Outcome::Continue => return,
                Outcome::Done => self.advance(),
                Outcome::Fail(error) => {
                    self.fail(error, unit, now);
                    return;
                }
            }
        }
    }
}
