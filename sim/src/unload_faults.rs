//! The unload faults MMU3 users report, each played over many seeds on this unit and on the unit
//! in its strict mode (the unload as MMU 3.0.4 does it: a blind 4 s wait for the printer's
//! sensor, `Config::strict_unload`): how often a tool change stops on an error screen the
//! printer's own automatic Retries do not clear, how often it stays stranded after a person's
//! Retries, and the hardest pull against gripping extruder gears.
//!
//! One trial: a printer (Buddy 6.5.3 by default, whose unload is 3.0.4's) loads slot 0, prints
//! for 2 s, the fault strikes, and the printer changes to slot 1. The person at the printer
//! presses Retry on an error screen up to [`PERSON_RETRIES`] times, 2 s after it shows.

use std::fmt;

use mmu_model::{Fault, ModelConfig, Rng};
use mmu_protocol::{ButtonCode, ErrorCode, Request, RequestCode, ResultCode};

use crate::printer::{Decision, Link, Operator, Outcome, Printer, PrinterEvent, PrinterOptions};
use crate::{ExtruderGeometry, Personality, Sim, SimLink, SimOptions};

/// Retries the person presses on an error screen before leaving the print stranded.
pub const PERSON_RETRIES: u8 = 3;
/// How long the person takes to press Retry, ms.
const PERSON_DELAY_MS: u64 = 2_000;

/// What users report going wrong around an unload.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum UnloadFault {
    /// The printer's sensor clears 0.5 to 8 s late (Prusa-Firmware-Buddy #5158, #5344).
    LateSensor,
    /// A deformed or stringy tip the gears keep gripping for 2 to 30 mm more of the retract
    /// (Prusa-Firmware-Buddy #5158, Prusa-Firmware-MMU #271).
    StringyTip,
    /// A Bowden tube of 1 to 2 m (a unit outside an enclosure), set in register 0x22.
    LongBowden,
    /// A Bowden tube of 2 to 5 m (register 0x22's top): not in [`UnloadFault::ALL`], since it
    /// takes minutes of simulation over 200 seeds.
    LongerBowden,
    /// The printer retracts at a quarter to a half of its speed.
    SlowRetract,
    /// No fault, but the printer's sensor sits before its gears (an MK3.5 on Buddy 6.5.3): no
    /// retract of the printer's can clear it.
    SensorFirst,
}

impl UnloadFault {
    /// Every fault, in the table's order.
    pub const ALL: [UnloadFault; 5] = [
        UnloadFault::LateSensor,
        UnloadFault::StringyTip,
        UnloadFault::LongBowden,
        UnloadFault::SlowRetract,
        UnloadFault::SensorFirst,
    ];

    /// The row's name.
    pub const fn name(self) -> &'static str {
        match self {
            UnloadFault::LateSensor => "sensor clears 0.5-8 s late",
            UnloadFault::StringyTip => "stringy tip held 2-30 mm",
            UnloadFault::LongBowden => "Bowden tube 1-2 m",
            UnloadFault::LongerBowden => "Bowden tube 2-5 m",
            UnloadFault::SlowRetract => "retract at 0.25-0.5x speed",
            UnloadFault::SensorFirst => "sensor before the gears (MK3.5)",
        }
    }
}

/// How one fault's trials ended in one mode.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FaultOutcomes {
    /// Trials played.
    pub trials: u32,
    /// Trials in which the unit reported an error: each costs one of the printer's three
    /// automatic Retries, which Buddy 6.5.3 refills only when a command ends `Finished` (its
    /// tool changes end `PrematureFinish`), so from the fourth a person is needed.
    pub errors: u32,
    /// Trials that stopped on an error screen the printer's automatic Retries did not clear.
    pub error_screens: u32,
    /// Trials whose tool change was not done after the person's Retries.
    pub stranded: u32,
    /// The hardest reverse duty against gripping extruder gears over every trial, per mille.
    pub hardest_pull_permille: u16,
}

/// One trial's options: which printer, in which geometry, which unit.
#[derive(Debug, Clone, Copy)]
pub struct TrialSetup {
    /// The printer played.
    pub printer: Personality,
    /// Its extruder geometry (`None`: the printer's own).
    pub extruder: Option<ExtruderGeometry>,
    /// The unit in its strict mode (MMU 3.0.4's unload).
    pub strict: bool,
}

/// Play `fault` on `setup` with every seed in `seeds`.
pub fn play(fault: UnloadFault, setup: TrialSetup, seeds: std::ops::Range<u64>) -> FaultOutcomes {
    let mut outcomes = FaultOutcomes::default();
    for seed in seeds {
        let trial = trial(fault, setup, seed);
        outcomes.trials += 1;
        outcomes.errors += u32::from(trial.errors > 0);
        outcomes.error_screens += u32::from(trial.screens > 0);
        outcomes.stranded += u32::from(!trial.done);
        outcomes.hardest_pull_permille = outcomes.hardest_pull_permille.max(trial.hardest_pull_permille);
    }
    outcomes
}

/// How one trial went.
struct Trial {
    errors: u32,
    screens: u32,
    done: bool,
    hardest_pull_permille: u16,
}

/// A uniform draw in `low..high`.
fn draw(rng: &mut Rng, low: f64, high: f64) -> f64 {
    low + (high - low) * rng.uniform()
}

fn trial(fault: UnloadFault, setup: TrialSetup, seed: u64) -> Trial {
    let mut rng = Rng::new(seed ^ 0x5eed_u64.rotate_left(40));
    let mut options = SimOptions {
        seed,
        printer: setup.printer,
        extruder: setup.extruder,
        ..SimOptions::default()
    };
    options.unit.strict_unload = setup.strict;
    if fault == UnloadFault::SensorFirst {
        options.extruder = Some(ExtruderGeometry::SENSOR_FIRST);
    }
    let tube = match fault {
        UnloadFault::LongBowden => Some((1000.0, 2000.0)),
        UnloadFault::LongerBowden => Some((2000.0, 5000.0)),
        _ => None,
    };
    if let Some((shortest, longest)) = tube {
        let mm = draw(&mut rng, shortest, longest).round();
        options.model = ModelConfig::default().with_bowden_length(mm as f32);
        options.unit.bowden_mm = mm as u16;
    }
    let Ok(sim) = Sim::new(options) else {
        return Trial {
            errors: 0,
            screens: 0,
            done: false,
            hardest_pull_permille: 0,
        };
    };
    let mut printer = Printer::new(SimLink::new(sim), PrinterOptions::of(setup.printer));
    let mut person = Person::default();
    let loaded = printer.connect(&mut person).is_ok()
        && matches!(
            printer.command(&mut person, Request::new(RequestCode::Tool, 0)),
            Ok(Outcome::Finished(ResultCode::OK))
        )
        && printer.print(&mut person, 2_000).is_ok();
    let strike = match fault {
        UnloadFault::LateSensor => Some(Fault::FsensorLate {
            delay_ms: draw(&mut rng, 500.0, 8000.0) as u32,
        }),
        UnloadFault::StringyTip => Some(Fault::TipCatch {
            slot: 0,
            mm: draw(&mut rng, 2.0, 30.0) as f32,
        }),
        UnloadFault::SlowRetract => Some(Fault::SlowRetract {
            factor: draw(&mut rng, 0.25, 0.5) as f32,
        }),
        UnloadFault::LongBowden | UnloadFault::LongerBowden | UnloadFault::SensorFirst => None,
    };
    if let Some(strike) = strike {
        printer.link_mut().sim_mut().model_mut().inject(strike);
    }
    // Only the change under the fault counts.
    person = Person::default();
    let done = loaded
        && matches!(
            printer.command(&mut person, Request::new(RequestCode::Tool, 1)),
            Ok(Outcome::Finished(_))
        )
        && printer.link().sim().model().loaded_slot() == Some(1);
    Trial {
        errors: person.errors,
        screens: person.screens,
        done,
        hardest_pull_permille: printer
            .link()
            .sim()
            .model()
            .max_pull_against_grip()
            .max_duty_permille,
    }
}

/// The person at the printer: waits [`PERSON_DELAY_MS`] on an error screen, then presses Retry,
/// at most [`PERSON_RETRIES`] times.
#[derive(Default)]
struct Person {
    errors: u32,
    screens: u32,
    presses: u8,
    shown_ms: Option<u64>,
}

impl Operator<SimLink> for Person {
    fn event(&mut self, _link: &mut SimLink, event: &PrinterEvent) {
        if matches!(event, PrinterEvent::Error(..)) {
            self.errors += 1;
        }
    }

    fn decide(&mut self, link: &mut SimLink, _request: Request, _error: ErrorCode) -> Decision {
        let now = link.now_ms();
        let shown = *self.shown_ms.get_or_insert_with(|| {
            self.screens += 1;
            now
        });
        if now < shown + PERSON_DELAY_MS {
            Decision::Wait
        } else if self.presses < PERSON_RETRIES {
            self.presses += 1;
            self.shown_ms = None;
            Decision::Press(ButtonCode::MIDDLE)
        } else {
            Decision::GiveUp
        }
    }
}

/// One row of the table: a fault, both modes.
#[derive(Debug, Clone, Copy)]
pub struct Row {
    /// The fault.
    pub fault: UnloadFault,
    /// The unit in its strict mode.
    pub strict: FaultOutcomes,
    /// This unit.
    pub feel: FaultOutcomes,
}

/// `| fault | trials | errors, both | strict: screens, stranded | this unit: screens, stranded |
/// hardest pull |`
impl fmt::Display for Row {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let pct = |n: u32, of: u32| {
            if of == 0 {
                0.0
            } else {
                f64::from(n) * 100.0 / f64::from(of)
            }
        };
        write!(
            f,
            "| {} | {} | {:.0} % | {:.0} % | {:.0} % | {:.0} % | {:.0} % | {:.0} % | {} / {} |",
            self.fault.name(),
            self.feel.trials,
            pct(self.strict.errors, self.strict.trials),
            pct(self.feel.errors, self.feel.trials),
            pct(self.strict.error_screens, self.strict.trials),
            pct(self.strict.stranded, self.strict.trials),
            pct(self.feel.error_screens, self.feel.trials),
            pct(self.feel.stranded, self.feel.trials),
            self.strict.hardest_pull_permille,
            self.feel.hardest_pull_permille,
        )
    }
}

/// The table's header, in Markdown.
pub const HEADER: &str = "| fault | seeds | 3.0.4: error | this unit: error | 3.0.4: error screen | 3.0.4: stranded | this unit: error screen | this unit: stranded | hardest pull on gripping gears, 3.0.4 / this unit (per mille) |\n|---|---|---|---|---|---|---|---|---|";
