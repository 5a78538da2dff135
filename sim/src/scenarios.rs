//! The scenarios every unit must pass, whatever runs it: the host-built logic (`cargo test`) or
//! a firmware image on an emulated chip (`mmu fil`, the firmware-in-the-loop benches of `fil/`).
//!
//! Each scenario builds its own unit with the `new_unit` it is given, drives it with Prusa's
//! printer logic ([`Printer`]) and checks what the printer saw and what the physical model's
//! filament did, as the host-logic tests do.

use std::time::{Duration, Instant as WallClock};

use mmu_model::{Fault, FaultKind};
use mmu_protocol::{ButtonCode, ErrorCode, ParamCode, Request, RequestCode, ResultCode};

use crate::{
    Decision, Operator, Outcome, Personality, Printer, PrinterEvent, PrinterOptions, Sim, SimFault,
    SimFaultKind, SimLink, SimOptions,
};

/// Builds a unit with these options, just powered on.
pub type NewUnit<'a> = &'a mut dyn FnMut(SimOptions) -> Result<Sim, String>;

/// One scenario: its name and what it runs.
pub struct Scenario {
    /// Short, for the report: `T1`, `power cut during a save`, ...
    pub name: &'static str,
    /// Passes with `Ok`, or says what went wrong.
    pub run: fn(NewUnit) -> Result<(), String>,
}

/// Every scenario, in the order they run.
pub const SCENARIOS: &[Scenario] = &[
    Scenario {
        name: "handshake, Buddy 6.5.3 (MMU 3.0.4)",
        run: |u| handshake(u, Personality::Buddy65),
    },
    Scenario {
        name: "handshake, Buddy 6.4 (MMU 3.0.3)",
        run: |u| handshake(u, Personality::Buddy64),
    },
    Scenario {
        name: "handshake, MK3S (MMU 3.0.2)",
        run: |u| handshake(u, Personality::Mk3s),
    },
    Scenario {
        name: "T0, Buddy 6.5.3",
        run: |u| tool_change(u, Personality::Buddy65, 0),
    },
    Scenario {
        name: "T1",
        run: |u| tool_change(u, Personality::Buddy64, 1),
    },
    Scenario {
        name: "T2",
        run: |u| tool_change(u, Personality::Buddy64, 2),
    },
    Scenario {
        name: "U0",
        run: unload,
    },
    Scenario {
        name: "E1 with Continue",
        run: eject,
    },
    Scenario {
        name: "a jam while printing, then Retry",
        run: jam_while_printing,
    },
    Scenario {
        name: "power cut in a millisecond that writes the flash",
        run: power_cut_during_a_save,
    },
    Scenario {
        name: "watchdog reset while printing",
        run: watchdog_reset,
    },
    Scenario {
        name: "1 % line noise",
        run: line_noise,
    },
];

/// How one scenario went.
#[derive(Debug)]
pub struct Verdict {
    /// The scenario's name.
    pub name: &'static str,
    /// `Ok`, or what went wrong.
    pub result: Result<(), String>,
    /// Wall time it took.
    pub took: Duration,
}

/// Run every scenario (those whose name contains `filter`, if given) on units from `new_unit`,
/// telling `report` each verdict as it comes.
pub fn run_all(new_unit: NewUnit, filter: Option<&str>, report: &mut dyn FnMut(&Verdict)) -> Vec<Verdict> {
    let mut verdicts = Vec::new();
    for scenario in SCENARIOS
        .iter()
        .filter(|s| filter.is_none_or(|f| s.name.contains(f)))
    {
        let started = WallClock::now();
        let result = (scenario.run)(&mut *new_unit);
        let verdict = Verdict {
            name: scenario.name,
            result,
            took: started.elapsed(),
        };
        report(&verdict);
        verdicts.push(verdict);
    }
    verdicts
}

/// The person at the printer: notes what the printer shows; pulls an ejected filament out and
/// presses Continue; clears a jam it is shown and presses Retry; gives up on anything else.
#[derive(Default)]
struct Person {
    events: Vec<PrinterEvent>,
}

impl Operator<SimLink> for Person {
    fn event(&mut self, _link: &mut SimLink, event: &PrinterEvent) {
        if !event.is_routine() {
            self.events.push(event.clone());
        }
    }

    fn decide(&mut self, link: &mut SimLink, request: Request, error: ErrorCode) -> Decision {
        let sim = link.sim_mut();
        if error == ErrorCode::FILAMENT_EJECTED {
            sim.model_mut().remove_filament(usize::from(request.value));
            Decision::Press(ButtonCode::MIDDLE)
        } else if sim.clear(SimFaultKind::Model(FaultKind::Jam(0))) {
            Decision::Press(ButtonCode::MIDDLE)
        } else {
            Decision::GiveUp
        }
    }
}

impl Person {
    fn errors(&self) -> Vec<ErrorCode> {
        self.events
            .iter()
            .filter_map(|e| match e {
                PrinterEvent::Error(_, error) => Some(*error),
                _ => None,
            })
            .collect()
    }

    fn count(&self, what: impl Fn(&PrinterEvent) -> bool) -> usize {
        self.events.iter().filter(|e| what(e)).count()
    }
}

/// A unit from `new_unit` playing `personality`, and that printer connected to it.
fn connected(new_unit: NewUnit, personality: Personality) -> Result<(Printer<SimLink>, Person), String> {
    let sim = new_unit(SimOptions {
        printer: personality,
        ..SimOptions::default()
    })?;
    let mut printer = Printer::new(SimLink::new(sim), PrinterOptions::of(personality));
    let mut person = Person::default();
    let first = printer
        .connect(&mut person)
        .map_err(|e| failed(&printer, format!("no handshake: {e}")))?;
    expect(
        &printer,
        first.code == RequestCode::Reset && first.param == ParamCode::Finished,
        || format!("a unit at rest answers `Q0` with `X0 F`, not {first:?}"),
    )?;
    Ok((printer, person))
}

/// A failure, with why the unit could no longer run if that is the cause.
fn failed(printer: &Printer<SimLink>, what: String) -> String {
    match printer.link().sim().unit_failure() {
        Some(why) => format!("{what} ({why})"),
        None => what,
    }
}

fn expect(printer: &Printer<SimLink>, holds: bool, what: impl FnOnce() -> String) -> Result<(), String> {
    if holds {
        Ok(())
    } else {
        Err(failed(printer, what()))
    }
}

/// Run `code value` to its end; anything but `F` with OK fails.
fn command(
    printer: &mut Printer<SimLink>,
    person: &mut Person,
    code: RequestCode,
    value: u8,
) -> Result<(), String> {
    let request = Request::new(code, value);
    match printer.command(person, request) {
        Ok(Outcome::Finished(ResultCode::OK)) => Ok(()),
        Ok(outcome) => Err(failed(
            printer,
            format!("{request:?} ended {outcome:?}; errors {:?}", person.errors()),
        )),
        Err(e) => Err(failed(printer, format!("{request:?}: {e}"))),
    }
}

/// Print for `ms`; any error the unit reports meanwhile that the person cannot clear fails.
fn print(printer: &mut Printer<SimLink>, person: &mut Person, ms: u64) -> Result<(), String> {
    match printer.print(person, ms) {
        Ok(None | Some(Outcome::Finished(ResultCode::OK))) => Ok(()),
        Ok(Some(outcome)) => Err(failed(
            printer,
            format!("printing ended {outcome:?}; errors {:?}", person.errors()),
        )),
        Err(e) => Err(failed(printer, format!("printing: {e}"))),
    }
}

/// Slot `slot` is loaded into the nozzle and no other slot is in the path.
fn loaded_into_the_nozzle(printer: &Printer<SimLink>, slot: usize) -> Result<(), String> {
    let model = printer.link().sim().model();
    let state = (model.loaded_slot(), model.fsensor_state());
    expect(printer, state == (Some(slot), 2), || {
        format!("slot {slot} should be in the nozzle: loaded slot and printer sensor are {state:?}")
    })
}

fn handshake(new_unit: NewUnit, personality: Personality) -> Result<(), String> {
    let (printer, person) = connected(new_unit, personality)?;
    let version = person.events.iter().find_map(|e| match e {
        PrinterEvent::Connected { version, .. } => Some(*version),
        _ => None,
    });
    expect(&printer, version == Some(personality.version()), || {
        format!(
            "{personality} wants {:?}; the unit said {version:?}",
            personality.version()
        )
    })
}

fn tool_change(new_unit: NewUnit, personality: Personality, slot: u8) -> Result<(), String> {
    let (mut printer, mut person) = connected(new_unit, personality)?;
    command(&mut printer, &mut person, RequestCode::Tool, slot)?;
    print(&mut printer, &mut person, 6000)?;
    loaded_into_the_nozzle(&printer, usize::from(slot))
}

fn unload(new_unit: NewUnit) -> Result<(), String> {
    let (mut printer, mut person) = connected(new_unit, Personality::Buddy64)?;
    command(&mut printer, &mut person, RequestCode::Tool, 0)?;
    print(&mut printer, &mut person, 6000)?;
    command(&mut printer, &mut person, RequestCode::Unload, 0)?;
    let park = -f32::from(printer.link().sim().unit_config().park_mm);
    let model = printer.link().sim().model();
    let tip = model.tip_mm(0).unwrap_or(f32::NAN);
    expect(
        &printer,
        model.loaded_slot().is_none() && (tip - park).abs() < 3.0,
        || format!("slot 0 should be parked at {park} mm: its tip is at {tip} mm"),
    )
}

fn eject(new_unit: NewUnit) -> Result<(), String> {
    let (mut printer, mut person) = connected(new_unit, Personality::Buddy64)?;
    command(&mut printer, &mut person, RequestCode::Eject, 1)?;
    expect(&printer, person.errors() == [ErrorCode::FILAMENT_EJECTED], || {
        format!(
            "the eject should wait on FILAMENT_EJECTED and nothing else: {:?}",
            person.errors()
        )
    })?;
    expect(&printer, printer.link().sim().model().tip_mm(1).is_none(), || {
        String::from("slot 1's filament should be out of the unit")
    })
}

fn jam_while_printing(new_unit: NewUnit) -> Result<(), String> {
    let (mut printer, mut person) = connected(new_unit, Personality::Buddy64)?;
    command(&mut printer, &mut person, RequestCode::Tool, 0)?;
    print(&mut printer, &mut person, 6000)?;
    printer
        .link_mut()
        .sim_mut()
        .inject(SimFault::Model(Fault::Jam { slot: 0 }));
    print(&mut printer, &mut person, 30_000)?;
    let errors = person.errors();
    expect(&printer, !errors.is_empty(), || {
        String::from("the unit should report the jam")
    })?;
    let jam_active = printer
        .link()
        .sim()
        .active_faults()
        .iter()
        .any(|f| matches!(f, SimFault::Model(Fault::Jam { .. })));
    expect(&printer, !jam_active, || {
        format!("the person should have been asked to clear the jam: {errors:?}")
    })?;
    print(&mut printer, &mut person, 5000)?;
    loaded_into_the_nozzle(&printer, 0)
}

fn power_cut_during_a_save(new_unit: NewUnit) -> Result<(), String> {
    let (mut printer, mut person) = connected(new_unit, Personality::Buddy64)?;
    command(&mut printer, &mut person, RequestCode::Tool, 1)?;
    print(&mut printer, &mut person, 1000)?;
    let sim = printer.link_mut().sim_mut();
    let before = sim.flash_wear().bytes_written;
    sim.cut_power_at_next_flash_write(500);
    // Unload: the unit saves that slot 1 left the path.
    command(&mut printer, &mut person, RequestCode::Unload, 1)?;
    let written = printer.link_mut().sim_mut().flash_wear().bytes_written;
    expect(&printer, written > before, || {
        String::from("the unit should have written its flash")
    })?;
    let restarts = person.count(|e| matches!(e, PrinterEvent::Interrupted(_) | PrinterEvent::LinkLost(_)));
    expect(&printer, restarts > 0, || {
        String::from("the power cut should have interrupted the unload")
    })?;
    command(&mut printer, &mut person, RequestCode::Tool, 2)?;
    print(&mut printer, &mut person, 6000)?;
    loaded_into_the_nozzle(&printer, 2)
}

fn watchdog_reset(new_unit: NewUnit) -> Result<(), String> {
    let (mut printer, mut person) = connected(new_unit, Personality::Buddy64)?;
    command(&mut printer, &mut person, RequestCode::Tool, 0)?;
    print(&mut printer, &mut person, 6000)?;
    printer.link_mut().sim_mut().hang();
    print(&mut printer, &mut person, 1500)?;
    // A unit that booted again has run no command since: `Q0` echoes `X0`.
    let (request, _) = printer.link().sim().unit_command();
    expect(&printer, request == (RequestCode::Reset, 0), || {
        format!("the watchdog should have reset the unit; it still runs {request:?}")
    })?;
    print(&mut printer, &mut person, 5000)?;
    loaded_into_the_nozzle(&printer, 0)?;
    command(&mut printer, &mut person, RequestCode::Tool, 1)?;
    print(&mut printer, &mut person, 6000)?;
    loaded_into_the_nozzle(&printer, 1)
}

fn line_noise(new_unit: NewUnit) -> Result<(), String> {
    let (mut printer, mut person) = connected(new_unit, Personality::Buddy64)?;
    printer
        .link_mut()
        .sim_mut()
        .inject(SimFault::UartCorrupt { probability: 0.01 });
    command(&mut printer, &mut person, RequestCode::Tool, 1)?;
    print(&mut printer, &mut person, 6000)?;
    loaded_into_the_nozzle(&printer, 1)?;
    let lost = person.count(|e| matches!(e, PrinterEvent::LinkLost(_)));
    expect(&printer, lost > 0, || {
        String::from("1 % of the bytes corrupted should have cost the link at least once")
    })
}
