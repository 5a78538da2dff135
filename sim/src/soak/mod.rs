//! Soak runs: many tool changes across all slots with random faults injected and later cleared,
//! recovered as the printer and its user would, and the figures that come out.
//!
//! [`run`] plays a printer ([`Printer`] over [`SimLink`](crate::SimLink), the firmware of
//! [`SoakOptions::personality`] in its protocol and its mechanics) against a fresh [`Sim`] and asks for
//! tool changes, each to a random slot other than the loaded one. With random faults, some changes
//! ([`FAULT_PROBABILITY`]) get a fault from a mix that matters to the unit (a jam of the target
//! slot or of the Bowden tube, a slipping or dead drive, sensor noise, a disconnected sensor, a
//! spool runout, a power loss of up to 3 s (the unit restarts with its stored state), a corrupting
//! or lossy UART), injected at a random moment of up to
//! [`MAX_FAULT_DELAY_MS`] after the `T` is sent (to the millisecond: the link steps the simulator
//! one millisecond at a time while the printer waits and strikes in between). Recovery is what a
//! printer and its user do:
//!
//! 1. the printer presses Retry by itself up to three times on errors that have it
//!    ([`crate::printer::AUTO_RETRIES`]);
//! 2. then the simulated user fixes the unit (clears the fault; puts a filament back if a runout
//!    left the slot empty) and presses Retry, up to [`USER_RETRIES`] times; on an error without a
//!    fault to fix the user just presses Retry that often;
//! 3. if the change still does not finish, the user gives up: the change is *unrecovered*. A
//!    change that finishes only after the unit asked for an unload by hand (`8008`, UNLOAD
//!    MANUALLY) is unrecovered too: an unattended print would have stopped there.
//!
//! Faults that raise no error (noise the filters absorb, a tolerated slip, a few lost bytes) are
//! cleared once the change is over. A change whose printer gives up on the link or whose command
//! does not end in time ([`PrinterOptions::command_timeout_ms`]) is *stuck*; a panic in the unit
//! logic or the simulator is caught and counted. After an unrecovered, stuck or panicked change the
//! rig is rebuilt (a fresh unit with every filament parked, a new connection) so the run goes on;
//! [`SoakReport::notes`] says what happened with enough detail to reproduce it (the run is
//! deterministic for its seed and options: the same seed gives the same changes and faults).
//!
//! The times of the fault-free changes (the unit's own time from accepting the `T` to finishing
//! it, as [`Sim::take_finished`] records it) are compared with the physical minimum of
//! [`crate::timing`] and with the printer's floor ([`crate::timing::tool_change_floor`]: the
//! minimum with what the printer's own sequence forces over the same span).

mod restarts;
mod striking;

use std::fmt;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::time::Instant;

use mmu_model::{Fault, Rail, Rng, SensorId};
use mmu_protocol::{ButtonCode, ErrorCode, Request, RequestCode, ResultCode};

use crate::fault::SimFault;
use crate::flash::FlashWear;
use crate::personality::Personality;
use crate::printer::{
    Decision, Link, Operator, Outcome, Printer, PrinterError, PrinterEvent, PrinterOptions,
};
use crate::sim::{CommandRecord, PRINTER_UNLOAD_MM, PRINTER_UNLOAD_MM_S, Sim, SimOptions, status_text};
use crate::timing::{tool_change_floor, tool_change_minimum};

mod spool_end;

pub use restarts::{PhaseRestarts, RestartTally};
pub use spool_end::SpoolEndTally;
use striking::StrikingLink;

/// With random faults, the chance that a tool change gets a fault.
pub const FAULT_PROBABILITY: f64 = 0.3;
/// A fault strikes up to this long after the `T` is sent, ms (uniformly drawn, to the
/// millisecond; a change that ends before its fault's moment runs without it).
pub const MAX_FAULT_DELAY_MS: u64 = 8000;
/// With random faults, the chance that a change's fault strikes while the printer prints after
/// the change rather than during it.
pub const PRINT_FAULT_PROBABILITY: f64 = 0.3;
/// With [`SoakOptions::spool_ends`], the share of loose spool ends among the faults.
pub const SPOOL_END_SHARE: f64 = 0.5;
/// With [`SoakOptions::spool_ends`], the share of spool ends fastened to the core.
pub const FASTENED_END_SHARE: f64 = 0.1;
/// How long the printer prints on after a fault struck while printing, ms: long enough for the
/// unit to notice, the printer's automatic Retries and the user's fix.
pub const PRINT_AFTER_FAULT_MS: u64 = 30_000;
/// Retry presses the simulated user makes on one change's errors (counted again from zero once
/// the fault is fixed) before giving up.
pub const USER_RETRIES: u8 = 3;
/// A finished change must leave the tip at least this close to the extruder gears (where a
/// turning extruder grips it), mm.
const GRIP_TOLERANCE_MM: f32 = 0.01;
/// Keeps the soak's random draws independent of the model's and the UART's ("SOAK").
const SOAK_STREAM: u64 = 0x534f_414b;

/// Times the printer connects again behind a lost link's screen during one command.
const RECONNECTS: u8 = 3;

/// Erase cycles a page of the STM32G071's flash is specified for (datasheet: 10 kcycles).
pub const ENDURANCE_CYCLES: u64 = 10_000;

/// What a soak run does.
#[derive(Debug, Clone)]
pub struct SoakOptions {
    /// Tool changes to run.
    pub changes: u32,
    /// Inject random faults.
    pub random_faults: bool,
    /// Spool ends instead of the random mix: every change gets a fault while the printer prints
    /// after it: a loose spool end one in two ([`SPOOL_END_SHARE`]), a spool end fastened to the
    /// core one in ten ([`FASTENED_END_SHARE`]), else one of the print faults (tangle, seized
    /// drive, noise, power loss, noisy line, a sensor disconnected).
    pub spool_ends: bool,
    /// Instead: every change gets a power loss of 50 ms to 3 s at a random moment of up to
    /// [`MAX_POWER_LOSS_DELAY_MS`] after its `T` is sent ([`SoakReport::restarts`] counts how
    /// the changes ended, by the phase the power went in).
    pub power_losses: bool,
    /// Seed of the run (the simulator's and the fault schedule's).
    pub seed: u64,
    /// The simulated unit.
    pub sim: SimOptions,
    /// The printer.
    pub printer: PrinterOptions,
    /// The printer played, by its protocol logic and by its mechanics in the simulator (it
    /// overrides [`PrinterOptions::personality`] and [`SimOptions::printer`]; the version the
    /// printer wants is [`PrinterOptions::version`]).
    pub personality: Personality,
}

/// How one kind of fault fared.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FaultKindTally {
    /// The fault's name, as in `--fault` without its slot and parameters (`jam`, `slip`,
    /// `disconnect:hub-filament`, `disconnect:motor-hall`, ...).
    pub kind: String,
    /// Times injected.
    pub injected: u32,
    /// Changes that finished after it.
    pub recovered: u32,
    /// Changes that did not finish after it.
    pub unrecovered: u32,
    /// Changes that got stuck after it.
    pub stuck: u32,
    /// Changes that panicked after it.
    pub panics: u32,
}

/// Times of the tool changes that ran without a fault.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ToolChangeTimes {
    /// Tool changes timed.
    pub changes: u32,
    /// Mean time, s (the unit's: from accepting the `T` to finishing it).
    pub mean_s: f64,
    /// Longest time, s.
    pub max_s: f64,
    /// Mean physical minimum of the same changes, s ([`crate::timing`]).
    pub physical_minimum_mean_s: f64,
    /// Mean floor of the same changes on the printer played, s: the physical minimum with what
    /// the printer's own sequence forces ([`crate::timing::tool_change_floor`]).
    pub floor_mean_s: f64,
}

impl ToolChangeTimes {
    /// Mean time over mean physical minimum; `None` without timed changes.
    pub fn ratio_to_minimum(&self) -> Option<f64> {
        (self.changes > 0 && self.physical_minimum_mean_s > 0.0)
            .then(|| self.mean_s / self.physical_minimum_mean_s)
    }

    /// Mean time over mean floor; `None` without timed changes.
    pub fn ratio_to_floor(&self) -> Option<f64> {
        (self.changes > 0 && self.floor_mean_s > 0.0).then(|| self.mean_s / self.floor_mean_s)
    }
}

/// What a soak run found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SoakReport {
    /// Tool changes run.
    pub changes: u32,
    /// The hardest and longest pulls of a lane motor against the extruder's gears while they
    /// gripped its filament, over every rig of the run ([`mmu_model::Model::max_pull_against_grip`]).
    pub pull_against_grip: mmu_model::PullAgainstGrip,
    /// Faults injected.
    pub faults_injected: u32,
    /// Faults after which the tool change completed.
    pub recovered: u32,
    /// Of [`SoakReport::recovered`]: faults that stopped the unit with an error first (the others
    /// were ridden out: noise below the thresholds, a few lost bytes, a mild slip).
    pub recovered_after_error: u32,
    /// Tool changes that failed even once the fault was cleared and Retry pressed; this includes
    /// changes that failed without any fault ([`SoakReport::failed_without_fault`]).
    pub unrecovered: u32,
    /// Commands that never ended, or a link that never came back.
    pub stuck: u32,
    /// Panics caught in the unit logic or the simulator.
    pub panics: u32,
    /// Of [`SoakReport::unrecovered`]: changes that failed with no fault injected.
    pub failed_without_fault: u32,
    /// Times the rig was rebuilt (a fresh unit with every filament parked, a new printer
    /// connection) after an unrecovered, stuck or panicked change.
    pub rig_restarts: u32,
    /// Per fault kind, in the order they first struck.
    pub by_fault_kind: Vec<FaultKindTally>,
    /// Times of the fault-free tool changes.
    pub tool_change_times: ToolChangeTimes,
    /// Spool ends while printing, and runouts the printer saw without one.
    pub spool_ends: SpoolEndTally,
    /// Virtual time simulated, s.
    pub simulated_s: f64,
    /// What the persisted state did to the unit's flash (16 pages of 2 KiB), over every rig.
    pub flash: FlashWear,
    /// Wall time the run took, s.
    pub wall_s: f64,
    /// One line per unrecovered, stuck or panicked change: change number, request, fault and when
    /// it struck, the errors seen, how it ended and where the filaments were. Not part of the
    /// [`Display`](fmt::Display) output: a caller prints them after it if it wants.
    pub notes: Vec<String>,
    /// One line per injected fault, in order: the change, the fault and when it struck, the
    /// errors the unit stopped on, and how the change ended.
    pub fault_log: Vec<String>,
    /// Why the run stopped before its last change (the rig could not be started), if it did.
    pub aborted: Option<String>,
    /// The power losses that struck while the unit ran a tool change, by phase, and how the
    /// changes ended.
    pub restarts: RestartTally,
}

impl SoakReport {
    /// The summary line, exactly:
    /// `soak: <N> tool changes, <F> faults injected, <R> recovered, <U> unrecovered, <S> stuck, <P> panics`.
    pub fn summary_line(&self) -> String {
        format!(
            "soak: {} tool changes, {} faults injected, {} recovered, {} unrecovered, {} stuck, {} panics",
            self.changes, self.faults_injected, self.recovered, self.unrecovered, self.stuck, self.panics
        )
    }

    /// Nothing unrecovered, stuck or panicked, no runout reported without a spool end, every
    /// spool end fastened to the core (on a spool counted as used up) handled by the printer, and
    /// the run was not aborted.
    pub fn passed(&self) -> bool {
        self.unrecovered == 0
            && self.stuck == 0
            && self.panics == 0
            && self.spool_ends.false_total() == 0
            && self.spool_ends.fastened_handled == self.spool_ends.fastened
            && self.aborted.is_none()
            && self.flash.erases_while_driven == 0
    }

    /// Simulated seconds per wall-clock second (0 if no wall time passed).
    pub fn speed(&self) -> f64 {
        if self.wall_s > 0.0 {
            self.simulated_s / self.wall_s
        } else {
            0.0
        }
    }

    fn tally(&mut self, kind: String) -> &mut FaultKindTally {
        let index = match self.by_fault_kind.iter().position(|t| t.kind == kind) {
            Some(index) => index,
            None => {
                self.by_fault_kind.push(FaultKindTally {
                    kind,
                    ..FaultKindTally::default()
                });
                self.by_fault_kind.len() - 1
            }
        };
        &mut self.by_fault_kind[index]
    }
}

/// The summary line first, then the statistics: tool-change times against the physical
/// minimum, simulation speed, faults by kind, failures without a fault, rig restarts, an abort.
impl fmt::Display for SoakReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "{}", self.summary_line())?;
        let times = &self.tool_change_times;
        match (times.ratio_to_minimum(), times.ratio_to_floor()) {
            (Some(ratio), Some(floor_ratio)) => writeln!(
                f,
                "tool change: mean {:.2} s, max {:.2} s, physical minimum {:.2} s (mean/minimum {ratio:.2}), printer's floor {:.2} s (mean/floor {floor_ratio:.2}) over {} fault-free changes",
                times.mean_s, times.max_s, times.physical_minimum_mean_s, times.floor_mean_s, times.changes
            )?,
            (Some(ratio), None) => writeln!(
                f,
                "tool change: mean {:.2} s, max {:.2} s, physical minimum {:.2} s (mean/minimum {ratio:.2}) over {} fault-free changes",
                times.mean_s, times.max_s, times.physical_minimum_mean_s, times.changes
            )?,
            (None, _) => writeln!(f, "tool change: no fault-free tool change was timed")?,
        }
        write!(
            f,
            "simulated {:.0} s in {:.1} s wall ({:.0} sim s per wall s)",
            self.simulated_s,
            self.wall_s,
            self.speed()
        )?;
        let flash = self.flash;
        if flash.bytes_written > 0 {
            write!(
                f,
                "\nflash: {} B written, {} page erases (at most {} of one page, {} while a motor was driven)",
                flash.bytes_written, flash.erases, flash.max_page_erases, flash.erases_while_driven
            )?;
            if flash.max_page_erases > 0 {
                let lifetime =
                    f64::from(self.changes) * ENDURANCE_CYCLES as f64 / flash.max_page_erases as f64;
                write!(
                    f,
                    ": {:.1} million tool changes before a page reaches {ENDURANCE_CYCLES} erases",
                    lifetime / 1e6
                )?;
            }
        }
        if self.recovered > 0 {
            write!(
                f,
                "\n{} of the {} recovered faults had stopped the unit with an error",
                self.recovered_after_error, self.recovered
            )?;
        }
        if self.spool_ends != SpoolEndTally::default() {
            write!(f, "\n{}", self.spool_ends)?;
        }
        if !self.by_fault_kind.is_empty() {
            write!(f, "\nfaults by kind:")?;
            for t in &self.by_fault_kind {
                write!(
                    f,
                    "\n  {}: {} injected, {} recovered, {} unrecovered, {} stuck, {} panics",
                    t.kind, t.injected, t.recovered, t.unrecovered, t.stuck, t.panics
                )?;
            }
        }
        if self.failed_without_fault > 0 {
            write!(
                f,
                "\n{} of the unrecovered changes failed without any fault",
                self.failed_without_fault
            )?;
        }
        if self.rig_restarts > 0 {
            write!(
                f,
                "\nrig restarted {} times (a fresh unit with every filament parked) after unrecovered, stuck or panicked changes",
                self.rig_restarts
            )?;
        }
        if self.restarts.struck() > 0 {
            write!(f, "\n{}", self.restarts)?;
        }
        if let Some(why) = &self.aborted {
            write!(f, "\naborted: {why}")?;
        }
        Ok(())
    }
}

/// With [`SoakOptions::power_losses`], a change's power loss strikes up to this long after the
/// `T` is sent, ms: a fault-free change from a loaded slot takes about 9 s.
pub const MAX_POWER_LOSS_DELAY_MS: u64 = 10_000;

/// The `--fault` name of a fault's kind, without slot and parameters.
/// A random fault that strikes while the printer prints with `loaded` loaded: a jam or a tangled
/// spool, a seized drive, sensor noise, a power loss, a noisy line, the spool's end, or its slot
/// sensor or the hub sensor disconnected.
fn draw_print_fault(rng: &mut Rng, loaded: usize) -> SimFault {
    match rng.next_u64() % 8 {
        0 | 1 => SimFault::Model(Fault::Jam { slot: loaded }),
        2 => SimFault::Model(Fault::MotorDead { slot: loaded }),
        3 => SimFault::Model(Fault::SensorNoise {
            sigma: draw(rng, 30.0, 90.0, 1.0),
        }),
        4 => SimFault::PowerLoss {
            off_ms: draw(rng, 50.0, 3_000.0, 1.0) as u32,
        },
        5 => SimFault::UartCorrupt {
            probability: draw(rng, 0.001, 0.01, 10_000.0),
        },
        6 => SimFault::Model(Fault::SpoolRunout { slot: loaded }),
        _ => {
            // The sensors a spool end is read from: one that fails must not look like one.
            let sensor = if rng.uniform() < 0.5 {
                SensorId::SlotFilament(loaded)
            } else {
                SensorId::HubFilament
            };
            let rail = if rng.uniform() < 0.5 {
                Rail::Low
            } else {
                Rail::High
            };
            SimFault::Model(Fault::SensorDisconnected { sensor, rail })
        }
    }
}

/// When a planned fault strikes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Moment {
    /// This long after the `T` is sent, ms.
    Change(u64),
    /// This long into the print after the change, ms.
    Print(u64),
}

fn kind_name(fault: &SimFault) -> String {
    let name = match fault {
        SimFault::Model(Fault::Jam { .. }) => "jam",
        SimFault::Model(Fault::BowdenJam) => "bowden-jam",
        SimFault::Model(Fault::Slip { .. }) => "slip",
        SimFault::Model(Fault::MotorDead { .. }) => "motor-dead",
        SimFault::Model(Fault::SensorNoise { .. }) => "noise",
        SimFault::Model(Fault::SensorDisconnected { sensor, .. }) => match sensor {
            SensorId::HubFilament => "disconnect:hub-filament",
            SensorId::HubTension => "disconnect:hub-tension",
            SensorId::HubCutter => "disconnect:hub-cutter",
            SensorId::SlotFilament(_) => "disconnect:slot-filament",
            SensorId::MotorHall(_) => "disconnect:motor-hall",
            SensorId::LaneTension(_) => "disconnect:lane-tension",
        },
        SimFault::Model(Fault::SpoolRunout { .. }) => "runout",
        SimFault::Model(Fault::SpoolFastened { .. }) => "fastened-end",
        SimFault::Model(Fault::FsensorLate { .. }) => "fsensor-late",
        SimFault::Model(Fault::TipCatch { .. }) => "tip-catch",
        SimFault::Model(Fault::SlowRetract { .. }) => "slow-retract",
        SimFault::UartCorrupt { .. } => "uart-corrupt",
        SimFault::UartDrop { .. } => "uart-drop",
        SimFault::PowerLoss { .. } => "power-loss",
    };
    name.to_string()
}

/// A uniform draw in `low..high`, rounded to `1/scale` so the fault prints as it was injected.
fn draw(rng: &mut Rng, low: f64, high: f64, scale: f64) -> f32 {
    ((low + (high - low) * rng.uniform()) * scale).round() as f32 / scale as f32
}

/// A random fault that concerns a change to `target`.
fn draw_fault(rng: &mut Rng, target: usize) -> SimFault {
    let rail = if rng.uniform() < 0.5 {
        Rail::Low
    } else {
        Rail::High
    };
    match rng.next_u64() % 10 {
        0 => SimFault::Model(Fault::Jam { slot: target }),
        1 => SimFault::Model(Fault::BowdenJam),
        2 => SimFault::Model(Fault::Slip {
            slot: target,
            ratio: draw(rng, 0.3, 0.9, 100.0),
        }),
        3 => SimFault::Model(Fault::MotorDead { slot: target }),
        4 => SimFault::Model(Fault::SensorNoise {
            sigma: draw(rng, 30.0, 90.0, 1.0),
        }),
        5 => {
            let sensor = match rng.next_u64() % 4 {
                0 => SensorId::HubFilament,
                1 => SensorId::HubTension,
                2 => SensorId::SlotFilament(target),
                _ => SensorId::MotorHall(target),
            };
            SimFault::Model(Fault::SensorDisconnected { sensor, rail })
        }
        6 => SimFault::Model(Fault::SpoolRunout { slot: target }),
        7 => SimFault::PowerLoss {
            off_ms: draw(rng, 50.0, 3_000.0, 1.0) as u32,
        },
        8 => SimFault::UartCorrupt {
            probability: draw(rng, 0.001, 0.01, 10_000.0),
        },
        _ => SimFault::UartDrop {
            probability: draw(rng, 0.001, 0.01, 10_000.0),
        },
    }
}

/// The person at the printer during a soak: arms the change's fault when the `T` goes out, and on
/// an error the printer does not retry away, fixes the unit and presses Retry.
#[derive(Debug, Default)]
struct SoakUser {
    /// The slot the change loads.
    target: u8,
    /// The change's fault and when it strikes, until it is armed.
    planned: Option<(SimFault, Moment)>,
    /// When the `T` was first sent, ms of virtual time.
    sent_ms: Option<u64>,
    /// The struck fault has been fixed.
    fixed: bool,
    /// Retry presses since the start of the change or the fix.
    presses: u8,
    /// The errors seen, in order (repeats of the same error in a row once).
    errors: Vec<ErrorCode>,
    /// The slots the printer saw run out (FINDA empty while printing), in order.
    runouts: Vec<u8>,
    /// The printer's handling of a runout succeeded (joined, or a clear filament-change screen).
    runout_handled: bool,
    /// The user pulled a spool's loose end out by hand.
    pulled_by_hand: bool,
}

impl SoakUser {
    /// Ready for a change to `target` with the fault `planned` (and its moment).
    fn for_change(target: u8, planned: Option<(SimFault, Moment)>) -> Self {
        SoakUser {
            target,
            planned,
            ..SoakUser::default()
        }
    }

    /// Fix the unit if a fault struck and is not fixed yet: clear it, put a filament back into a
    /// slot a runout emptied, and pull the old filament out of the extruder's gears if the fault
    /// kept the printer's own unload from doing so. True if there was something to fix.
    fn fix(&mut self, link: &mut StrikingLink) -> bool {
        let Some(strike) = link.struck.filter(|_| !self.fixed) else {
            return false;
        };
        self.fixed = true;
        let sim = link.sim_mut();
        if let SimFault::Model(Fault::SpoolRunout { slot }) = strike.fault {
            // A spool's loose end that got past the slot's drive gear is out of the unit's reach:
            // the user pulls the piece out by hand.
            let model = sim.model();
            let gear = model.config().drive_gear_mm;
            if model.tail_mm(slot).is_some_and(|tail| tail > gear) {
                sim.model_mut().remove_filament(slot);
                self.pulled_by_hand = true;
            }
        }
        sim.clear(strike.fault.kind());
        if let SimFault::Model(Fault::SpoolRunout { slot }) = strike.fault
            && sim.model().tip_mm(slot).is_none()
        {
            let park_mm = -f32::from(sim.unit_config().park_mm);
            sim.model_mut().insert_filament(slot, park_mm);
        }
        let model = sim.model();
        let gears = model.config().extruder_gears_mm;
        let old_in_gears = model
            .loaded_slot()
            .filter(|&slot| slot != usize::from(self.target))
            .and_then(|slot| model.tip_mm(slot))
            .is_some_and(|tip| tip >= gears);
        if old_in_gears {
            // From the printer's menu: heat and retract.
            sim.model_mut()
                .extruder_move(-PRINTER_UNLOAD_MM, PRINTER_UNLOAD_MM_S);
        }
        true
    }

    /// The change finished and the printer prints: arm a fault planned for the print; returns
    /// how long to print (0 without one).
    fn start_print(&mut self, link: &mut StrikingLink) -> u64 {
        let Some((fault, Moment::Print(delay_ms))) = self.planned.take() else {
            return 0;
        };
        link.armed = Some((fault, link.now_ms() + delay_ms));
        delay_ms + PRINT_AFTER_FAULT_MS
    }

    /// The change is over: a fault that has not struck yet never will, and one still active
    /// (it raised no error) is cleared.
    fn change_over(&mut self, link: &mut StrikingLink) {
        self.planned = None;
        link.armed = None;
        self.fix(link);
    }
}

impl Operator<StrikingLink> for SoakUser {
    fn event(&mut self, link: &mut StrikingLink, event: &PrinterEvent) {
        match event {
            PrinterEvent::Sent(request)
                if request.code == RequestCode::Tool
                    && request.value == self.target
                    && self.sent_ms.is_none() =>
            {
                let now = link.now_ms();
                self.sent_ms = Some(now);
                if let Some((fault, Moment::Change(delay_ms))) = self.planned {
                    self.planned = None;
                    link.armed = Some((fault, now + delay_ms));
                }
            }
            PrinterEvent::Error(_, error) if self.errors.last() != Some(error) => self.errors.push(*error),
            PrinterEvent::Runout { slot, .. } => self.runouts.push(*slot),
            _ => {}
        }
    }

    fn decide(&mut self, link: &mut StrikingLink, request: Request, error: ErrorCode) -> Decision {
        if error == ErrorCode::FILAMENT_EJECTED && request.code == RequestCode::Eject {
            // The filament change's eject: the screen asks to take the filament out.
            let slot = usize::from(request.value);
            link.sim_mut().model_mut().remove_filament(slot);
            return Decision::Press(ButtonCode::MIDDLE);
        }
        if self.fix(link) {
            self.presses = 0;
        }
        if error == ErrorCode::FINDA_VS_EEPROM_DISREPANCY && link.sim_mut().unload_manually() > 0 {
            // The screen says UNLOAD MANUALLY: done by hand; Retry at the next look.
            self.presses = 0;
            return Decision::Wait;
        }
        if link.sim().model().extruder_busy() {
            return Decision::Wait;
        }
        if self.presses < USER_RETRIES {
            self.presses += 1;
            Decision::Press(ButtonCode::MIDDLE)
        } else {
            Decision::GiveUp
        }
    }
}

/// The printer on a simulated unit, and the slot it has loaded.
struct Rig {
    printer: Printer<StrikingLink>,
    loaded: Option<u8>,
}

impl Rig {
    /// A fresh unit (every filament parked, nothing loaded) and a printer connected to it. The
    /// first rig's simulator has the run's seed; rebuilt ones derive theirs from it.
    fn start(options: &SoakOptions, generation: u64) -> Result<Rig, String> {
        let seed = options
            .seed
            .wrapping_add(generation.wrapping_mul(0x9e37_79b9_7f4a_7c15));
        let sim = Sim::new(SimOptions {
            seed,
            printer: options.personality,
            ..options.sim.clone()
        })
        .map_err(|error| error.to_string())?;
        let printer_options = PrinterOptions {
            personality: options.personality,
            // The user joins each slot to the next of the unit's.
            join_cycle: u8::try_from(options.sim.slots).unwrap_or(u8::MAX),
            ..options.printer
        };
        let mut printer = Printer::new(StrikingLink::new(sim), printer_options);
        printer
            .connect(&mut SoakUser::default())
            .map_err(|error| format!("the printer could not connect: {error}"))?;
        Ok(Rig {
            printer,
            loaded: None,
        })
    }

    fn sim(&self) -> &Sim {
        self.printer.link().sim()
    }
}

/// How a tool change ended.
enum ChangeEnd {
    /// Finished, with the new filament in the extruder.
    Done,
    /// Ended without the filament loaded: why.
    Failed(String),
    /// The printer gave up on the unit or the command did not end: why.
    Stuck(String),
}

/// Where the unit and the filaments stand, for a note.
fn describe(sim: &Sim) -> String {
    let ((code, value), status) = sim.unit_command();
    let status = status_text(status);
    let model = sim.model();
    let tips: Vec<String> = (0..model.slot_count())
        .map(|slot| match model.tip_mm(slot) {
            Some(tip) => format!("{slot}:{tip:.1}"),
            None => format!("{slot}:none"),
        })
        .collect();
    format!(
        "unit {}{value:x} {status}; tips {}; fsensor {}; t {:.1} s",
        code.as_char(),
        tips.join(" "),
        model.fsensor_state(),
        sim.now_ms() as f64 / 1000.0
    )
}

/// Run one tool change to `target` (unloading first when it is the loaded slot: a unit with one
/// slot).
fn tool_change(rig: &mut Rig, user: &mut SoakUser, target: u8) -> ChangeEnd {
    if rig.loaded == Some(target) {
        match command(rig, user, Request::new(RequestCode::Unload, 0)) {
            Ok(Outcome::Finished(ResultCode::OK)) => rig.loaded = None,
            Ok(outcome) => return ChangeEnd::Failed(format!("the unload before it ended {outcome:?}")),
            Err(error) => return ChangeEnd::Stuck(error.to_string()),
        }
    }
    let end = match command(rig, user, Request::new(RequestCode::Tool, target)) {
        Ok(Outcome::Finished(ResultCode::OK)) => {
            let model = rig.sim().model();
            let gears_mm = model.config().extruder_gears_mm;
            match model.tip_mm(usize::from(target)) {
                _ if model.loaded_slot() != Some(usize::from(target)) => {
                    ChangeEnd::Failed("reported finished, but another filament is loaded".into())
                }
                Some(tip) if tip >= gears_mm - GRIP_TOLERANCE_MM && model.fsensor_state() != 0 => {
                    rig.loaded = Some(target);
                    print(rig, user, target)
                }
                tip => ChangeEnd::Failed(format!(
                    "reported finished, but the tip stopped at {} before the extruder gears at {gears_mm} mm",
                    tip.map_or("none".to_string(), |tip| format!("{tip:.2} mm"))
                )),
            }
        }
        Ok(Outcome::Finished(result)) => ChangeEnd::Failed(format!("finished with result {}", result.0)),
        Ok(Outcome::Rejected) => ChangeEnd::Failed("the unit rejected it".into()),
        Ok(Outcome::FilamentChange(slot)) => {
            ChangeEnd::Failed(format!("stopped on the filament-change screen for slot {slot}"))
        }
        Ok(Outcome::GaveUp(error)) => ChangeEnd::Failed(format!("gave up on {error}")),
        Err(error) => ChangeEnd::Stuck(error.to_string()),
    };
    user.change_over(rig.printer.link_mut());
    end
}

/// Run `request` as the printer does, riding out a lost link: behind its MMU_NOT_RESPONDING or
/// COMMUNICATION_ERROR screen a Buddy printer goes on connecting (`MMU2::LogicStep` sets
/// `xState::Connecting`, BFW v6.5.3 `mmu2_mk4.cpp`) and takes the command up again once the
/// unit answers. On Buddy 6.5.3 ten 200 ms timeouts, a power cut of 2 s, are enough for the
/// screen. A unit that stays silent through [`RECONNECTS`] tries is stuck.
///
/// Taken up means followed: the printer still has the command as its request (`ReqMsg`), so a
/// unit that restarted meanwhile answers `X0 F0` to its `Q0` and the printer sees the command
/// `Interrupted` (`protocol_logic.cpp` `IdleStep`, `ProcessCommandQueryResponse`): for a tool
/// change, `U0` and then the `T` again ([`Printer::follow`]).
fn command(rig: &mut Rig, user: &mut SoakUser, request: Request) -> Result<Outcome, PrinterError> {
    let mut tries = 0;
    let mut result = rig.printer.command(user, request);
    loop {
        match result {
            Err(PrinterError::NotResponding | PrinterError::ProtocolError) if tries < RECONNECTS => {
                tries += 1;
                match rig.printer.connect(user) {
                    Ok(_) => result = rig.printer.follow(user, request),
                    Err(PrinterError::NotResponding | PrinterError::ProtocolError) => {}
                    Err(error) => return Err(error),
                }
            }
            other => return other,
        }
    }
}

/// Print after a finished change to `target` (when a fault is planned for the print): the change
/// counts as done if the printer still prints with `target` loaded when the print ends.
fn print(rig: &mut Rig, user: &mut SoakUser, target: u8) -> ChangeEnd {
    let print_ms = user.start_print(rig.printer.link_mut());
    if print_ms == 0 {
        return ChangeEnd::Done;
    }
    // A spool that ends fastened to its core is one the unit counts as used up.
    let fastened = spool_end::fastened_slot(rig.printer.link().armed.map(|(fault, _)| fault));
    if let Some(slot) = fastened
        && let Err(why) = spool_end::set_left(&mut rig.printer, user, slot, spool_end::FASTENED_LEFT_M)
    {
        return ChangeEnd::Failed(why);
    }
    let end = print_on(rig, user, target, print_ms);
    // The user puts a fresh spool behind that filament, and says so (`M708 A0x59+k X330`).
    if let Some(slot) = fastened {
        let spool_m = rig.sim().unit_config().spool_m.get(slot).copied().unwrap_or(0);
        if let Err(why) = spool_end::set_left(&mut rig.printer, user, slot, spool_m) {
            return ChangeEnd::Failed(why);
        }
    }
    end
}

/// [`print`] for `print_ms` once its fault is armed.
fn print_on(rig: &mut Rig, user: &mut SoakUser, target: u8, print_ms: u64) -> ChangeEnd {
    let until = rig.printer.link().now_ms() + print_ms;
    let mut tries = 0;
    let printed = loop {
        let left = until.saturating_sub(rig.printer.link().now_ms());
        match rig.printer.print(user, left) {
            // As during a command: the printer connects again behind the screen.
            Err(PrinterError::NotResponding | PrinterError::ProtocolError) if tries < RECONNECTS => {
                tries += 1;
                match rig.printer.connect(user) {
                    Ok(_) | Err(PrinterError::NotResponding | PrinterError::ProtocolError) => {}
                    Err(error) => break Err(error),
                }
            }
            other => break other,
        }
    };
    match printed {
        Ok(Some(Outcome::GaveUp(error))) => ChangeEnd::Failed(format!("while printing, gave up on {error}")),
        Ok(Some(Outcome::FilamentChange(slot))) => {
            // The filament-change screen: the old filament must be out of the path.
            rig.loaded = None;
            let model = rig.sim().model();
            if model.hub_filament_present() || model.fsensor_state() != 0 {
                ChangeEnd::Failed(format!(
                    "the filament change after slot {slot} ran out left filament in the path"
                ))
            } else {
                // The screen asks for the new filament: the user clears the spool end and puts a
                // fresh spool's filament in, as at any runout.
                user.runout_handled = true;
                user.fix(rig.printer.link_mut());
                let sim = rig.printer.link_mut().sim_mut();
                if sim.model().tip_mm(usize::from(slot)).is_none() {
                    let park_mm = -f32::from(sim.unit_config().park_mm);
                    sim.model_mut().insert_filament(usize::from(slot), park_mm);
                }
                ChangeEnd::Done
            }
        }
        Ok(_) if !user.runouts.is_empty() => {
            // SpoolJoin: the print goes on with the slot the printer joined to.
            let joined = rig.printer.loaded_tool();
            rig.loaded = joined;
            let model = rig.sim().model();
            if joined.is_some()
                && model.loaded_slot() == joined.map(usize::from)
                && model.fsensor_state() != 0
            {
                user.runout_handled = true;
                ChangeEnd::Done
            } else {
                ChangeEnd::Failed(format!(
                    "after SpoolJoin to {joined:?}, that filament is not loaded"
                ))
            }
        }
        Ok(_) => {
            let model = rig.sim().model();
            if model.loaded_slot() == Some(usize::from(target)) && model.fsensor_state() != 0 {
                ChangeEnd::Done
            } else {
                ChangeEnd::Failed("after printing, the filament is no longer loaded".into())
            }
        }
        Err(error) => ChangeEnd::Stuck(error.to_string()),
    }
}

/// Running sums of the fault-free tool-change times.
#[derive(Debug, Default)]
struct TimeSums {
    changes: u32,
    sum_s: f64,
    max_s: f64,
    minimum_sum_s: f64,
    floor_sum_s: f64,
}

impl TimeSums {
    /// Add the tool changes among `records` that finished without an error on `printer`.
    fn add(&mut self, sim: &Sim, printer: Personality, records: &[CommandRecord]) {
        for record in records {
            if record.request.0 != RequestCode::Tool || record.had_error {
                continue;
            }
            let (config, geometry) = (sim.unit_config(), sim.model().config());
            let minimum = tool_change_minimum(config, geometry, record.start_tip_mm).total_s();
            let floor = tool_change_floor(config, geometry, printer, record.start_tip_mm).total_s();
            if !minimum.is_finite() || !floor.is_finite() {
                continue;
            }
            let took_s = record.finished_ms.saturating_sub(record.started_ms) as f64 / 1000.0;
            self.changes += 1;
            self.sum_s += took_s;
            self.max_s = self.max_s.max(took_s);
            self.minimum_sum_s += minimum;
            self.floor_sum_s += floor;
        }
    }

    fn times(&self) -> ToolChangeTimes {
        if self.changes == 0 {
            return ToolChangeTimes::default();
        }
        let n = f64::from(self.changes);
        ToolChangeTimes {
            changes: self.changes,
            mean_s: self.sum_s / n,
            max_s: self.max_s,
            physical_minimum_mean_s: self.minimum_sum_s / n,
            floor_mean_s: self.floor_sum_s / n,
        }
    }
}

/// The text of a caught panic.
fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic without a message".into())
}

/// Run `options.changes` tool changes as the [module documentation](self) describes; `progress`
/// is called with the number of changes done after each one.
pub fn run(options: &SoakOptions, progress: &mut dyn FnMut(u32)) -> SoakReport {
    run_until(options, progress, &|| false)
}

/// [`run`], stopping early once `stop` says so (checked after each change, e.g. on Ctrl-C): the
/// report covers the changes run and says in [`SoakReport::aborted`] that it was stopped.
pub fn run_until(
    options: &SoakOptions,
    progress: &mut dyn FnMut(u32),
    stop: &dyn Fn() -> bool,
) -> SoakReport {
    let wall = Instant::now();
    let mut report = SoakReport::default();
    let mut rng = Rng::new(options.seed ^ SOAK_STREAM);
    let mut times = TimeSums::default();
    let mut simulated_ms = 0u64;
    let mut generation = 0u64;
    let mut rig: Option<Rig> = None;
    let slots = u8::try_from(options.sim.slots).unwrap_or(u8::MAX);

    for change in 1..=options.changes {
        let mut current = match rig.take() {
            Some(current) => current,
            None => {
                let started = catch_unwind(|| Rig::start(options, generation));
                generation += 1;
                match started {
                    Ok(Ok(current)) => {
                        if generation > 1 {
                            report.rig_restarts += 1;
                        }
                        current
                    }
                    Ok(Err(why)) => {
                        report.aborted = Some(format!("before change {change}: {why}"));
                        break;
                    }
                    Err(payload) => {
                        report.panics += 1;
                        report.aborted = Some(format!(
                            "before change {change}: starting the rig panicked: {}",
                            panic_text(payload.as_ref())
                        ));
                        break;
                    }
                }
            }
        };

        let others: Vec<u8> = (0..slots).filter(|&slot| Some(slot) != current.loaded).collect();
        let target = match others.len() {
            0 => 0,
            n => others[(rng.next_u64() % n as u64) as usize],
        };
        let power_loss = options.power_losses.then(|| {
            let fault = SimFault::PowerLoss {
                off_ms: draw(&mut rng, 50.0, 3_000.0, 1.0) as u32,
            };
            (
                fault,
                Moment::Change(rng.next_u64() % (MAX_POWER_LOSS_DELAY_MS + 1)),
            )
        });
        let planned = if options.spool_ends {
            let draw_share = rng.uniform();
            let slot = usize::from(target);
            let fault = if draw_share < SPOOL_END_SHARE {
                SimFault::Model(Fault::SpoolRunout { slot })
            } else if draw_share < SPOOL_END_SHARE + FASTENED_END_SHARE {
                SimFault::Model(Fault::SpoolFastened { slot })
            } else {
                draw_print_fault(&mut rng, usize::from(target))
            };
            Some((fault, Moment::Print(rng.next_u64() % (MAX_FAULT_DELAY_MS + 1))))
        } else {
            (options.random_faults && rng.uniform() < FAULT_PROBABILITY).then(|| {
                if rng.uniform() < PRINT_FAULT_PROBABILITY {
                    let fault = draw_print_fault(&mut rng, usize::from(target));
                    (fault, Moment::Print(rng.next_u64() % (MAX_FAULT_DELAY_MS + 1)))
                } else {
                    let fault = draw_fault(&mut rng, usize::from(target));
                    (fault, Moment::Change(rng.next_u64() % (MAX_FAULT_DELAY_MS + 1)))
                }
            })
        };
        let planned = planned.or(power_loss);
        let while_printing = matches!(planned, Some((_, Moment::Print(_))));
        let from = current.loaded;
        let mut user = SoakUser::for_change(target, planned);
        current.printer.link_mut().struck = None;

        let end = catch_unwind(AssertUnwindSafe(|| tool_change(&mut current, &mut user, target)));
        report.changes += 1;

        let struck = current.printer.link().struck;
        let kind = struck.map(|strike| {
            let name = kind_name(&strike.fault);
            if while_printing {
                format!("{name} (printing)")
            } else {
                name
            }
        });
        if let Some(kind) = &kind {
            report.faults_injected += 1;
            report.tally(kind.clone()).injected += 1;
        }
        let handled = user.runout_handled && !user.pulled_by_hand;
        report
            .spool_ends
            .count(struck.map(|s| s.fault), kind.as_deref(), &user.runouts, handled);
        let context = || {
            let loaded = from.map_or("nothing loaded".to_string(), |slot| format!("slot {slot} loaded"));
            let fault = match struck {
                Some(strike) => format!(
                    "{} struck {:.1} s after T{target} was sent",
                    strike.fault,
                    strike.at_ms.saturating_sub(user.sent_ms.unwrap_or(strike.at_ms)) as f64 / 1000.0
                ),
                None => "no fault".to_string(),
            };
            let errors: Vec<String> = user.errors.iter().map(ToString::to_string).collect();
            let errors = if errors.is_empty() {
                "no error".to_string()
            } else {
                format!("errors {}", errors.join(", "))
            };
            format!("change {change} (T{target}, {loaded}): {fault}; {errors}")
        };

        // How the change ended, and for a failure where the unit and the filaments were.
        let (verdict, failure_detail): (String, Option<String>) = match end {
            Ok(ChangeEnd::Done) if user.errors.contains(&ErrorCode::FINDA_VS_EEPROM_DISREPANCY) => {
                // UNLOAD MANUALLY: the change went on only after a person took the filament out
                // by hand, which stops an unattended print: a failure of the unit, whatever the
                // fault. The rig goes on as the user left it.
                report.unrecovered += 1;
                match &kind {
                    Some(kind) => report.tally(kind.clone()).unrecovered += 1,
                    None => report.failed_without_fault += 1,
                }
                let verdict = "unrecovered: completed only after UNLOAD MANUALLY (8008) by hand".to_string();
                report.notes.push(format!("{} -> {verdict}", context()));
                (verdict, None)
            }
            Ok(ChangeEnd::Done) => {
                if let Some(kind) = &kind {
                    report.recovered += 1;
                    report.recovered_after_error += u32::from(!user.errors.is_empty());
                    report.tally(kind.clone()).recovered += 1;
                }
                ("recovered".to_string(), None)
            }
            Ok(ChangeEnd::Failed(why)) => {
                report.unrecovered += 1;
                match &kind {
                    Some(kind) => report.tally(kind.clone()).unrecovered += 1,
                    None => report.failed_without_fault += 1,
                }
                (
                    format!("unrecovered: {why}"),
                    Some(format!("; {}", describe(current.sim()))),
                )
            }
            Ok(ChangeEnd::Stuck(why)) => {
                report.stuck += 1;
                if let Some(kind) = &kind {
                    report.tally(kind.clone()).stuck += 1;
                }
                (
                    format!("stuck: {why}"),
                    Some(format!("; {}", describe(current.sim()))),
                )
            }
            Err(payload) => {
                report.panics += 1;
                if let Some(kind) = &kind {
                    report.tally(kind.clone()).panics += 1;
                }
                // A simulator that panicked is not asked where things are.
                (
                    format!("panic: {}", panic_text(payload.as_ref())),
                    Some(String::new()),
                )
            }
        };
        if let Some(strike) = struck
            && matches!(strike.fault, SimFault::PowerLoss { .. })
            && !while_printing
        {
            let manual = user.errors.contains(&ErrorCode::FINDA_VS_EEPROM_DISREPANCY);
            let phase = strike.in_tool_change;
            report.restarts.record(phase, failure_detail.is_none(), manual);
        }
        if struck.is_some() {
            report.fault_log.push(format!("{} -> {verdict}", context()));
        }
        let keep = failure_detail.is_none();
        if let Some(detail) = failure_detail {
            report.notes.push(format!("{} -> {verdict}{detail}", context()));
        }

        if keep {
            let sim = current.printer.link_mut().sim_mut();
            let records = sim.take_finished();
            sim.take_events();
            if struck.is_none() {
                times.add(current.sim(), options.personality, &records);
            }
            rig = Some(current);
        } else {
            simulated_ms += current.sim().now_ms();
            report.pull_against_grip = report
                .pull_against_grip
                .merged(current.sim().model().max_pull_against_grip());
            report.flash = report
                .flash
                .combined(current.printer.link_mut().sim_mut().flash_wear());
        }
        progress(change);
        if stop() && change < options.changes {
            report.aborted = Some(format!("stopped after change {change} of {}", options.changes));
            break;
        }
    }

    if let Some(current) = &mut rig {
        simulated_ms += current.sim().now_ms();
        report.pull_against_grip = report
            .pull_against_grip
            .merged(current.sim().model().max_pull_against_grip());
        report.flash = report
            .flash
            .combined(current.printer.link_mut().sim_mut().flash_wear());
    }
    report.tool_change_times = times.times();
    report.simulated_s = simulated_ms as f64 / 1000.0;
    report.wall_s = wall.elapsed().as_secs_f64();
    report
}
