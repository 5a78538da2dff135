//! `mmu demo`: a scripted session against the in-process simulator, shown live.
//!
//! The printer (the same [`Session`] and console as `mmu printer --sim`) connects, changes
//! tools T0, T1, T2, T0, ejects slot 1 with its Continue dialog (the simulated user pulls the
//! filament out), the user puts a fresh spool into slot 1 and the printer preloads it, and a
//! last tool change brings it to the nozzle. Paced at `--time-scale` × real time (default 10)
//! so a person can follow; `--fast` runs as fast as possible.

use std::error::Error;
use std::time::Instant;

use mmu_protocol::{Request, RequestCode};
use mmu_sim::{PrinterOptions, Sim, SimLink, SimOptions};

use crate::explain::request_label;
use crate::printer_cli::console::{Console, FinishedCommand};
use crate::printer_cli::{Details, Failure, Session, parse_time_scale};

/// Where the user pushes a fresh filament's tip, mm from the hub sensor: through the slot's drive
/// gear (−100 mm) and just past its slot sensor (−95 mm), which tells the unit the slot is full.
const FRESH_TIP_MM: f32 = -90.0;
/// How long the user takes between putting the filament in and choosing the preload, ms.
const USER_MS: u64 = 2000;
/// The slot ejected and preloaded again.
const SWAP_SLOT: u8 = 1;

/// `mmu demo` options.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Run at K × real time (0: as fast as possible).
    #[arg(long, value_name = "K", default_value_t = 10.0, value_parser = parse_time_scale)]
    pub time_scale: f64,
    /// As fast as possible (the same as --time-scale 0).
    #[arg(long, conflicts_with = "time_scale")]
    pub fast: bool,
    /// Seed of the simulator's random draws.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// One JSON object per line per event, and a final `result` object.
    #[arg(long)]
    pub json: bool,
    /// Show every frame sent (`>`) and received (`<`).
    #[arg(short, long)]
    pub verbose: bool,
}

/// Run `mmu demo`.
pub fn run(args: &DemoArgs) -> Result<(), Box<dyn Error>> {
    let wall = Instant::now();
    let sim = Sim::new(SimOptions {
        slots: 3,
        seed: args.seed,
        ..SimOptions::default()
    })?;
    let mut link = SimLink::new(sim);
    let scale = (!args.fast && args.time_scale > 0.0).then_some(args.time_scale);
    link.set_time_scale(scale);
    let console = Console::new(args.json, args.verbose);
    let mut session = Session::new(link, PrinterOptions::default(), console);

    let result = script(&mut session).map(|()| {
        let wall_s = wall.elapsed().as_secs_f64();
        summary(&session, wall_s)
    });
    session.finish("demo", &result);
    result.map(|_| ()).map_err(Into::into)
}

/// The session, step by step.
fn script(session: &mut Session<SimLink>) -> Result<(), Failure> {
    let tool = |slot| Request::new(RequestCode::Tool, slot);
    session.console().heading(
        "1/5 handshake: the printer checks the unit's version (exactly 3.0.3, as Buddy 6.4 does), writes its settings and polls",
    );
    session.connect()?;

    session.console().heading(
        "2/5 tool changes T0, T1, T2, T0: the loaded slot goes back to park, the next one to the \
         nozzle (at FeedingToFSensor the printer's extruder pulls too)",
    );
    for slot in [0, 1, 2, 0] {
        session.command(tool(slot))?;
    }

    session.console().heading(&format!(
        "3/5 eject slot {SWAP_SLOT}: the hub filament sensor sees filament, so the printer unloads first; the unit \
         pulls the filament out of its slot and the printer shows the Continue dialog"
    ));
    session.eject(SWAP_SLOT)?;

    session.console().heading(&format!(
        "4/5 preload slot {SWAP_SLOT}: a fresh spool goes in, L{SWAP_SLOT} feeds it to the hub sensor and parks it"
    ));
    let t_ms = session.now_ms();
    let inserted = session
        .link_mut()
        .sim_mut()
        .model_mut()
        .insert_filament(usize::from(SWAP_SLOT), FRESH_TIP_MM);
    if !inserted {
        return Err(Failure::new(format!("the simulator has no slot {SWAP_SLOT}")));
    }
    session.console().note(
        t_ms,
        &format!(
            "the simulated user pushes a fresh filament through slot {SWAP_SLOT}'s drive gear, past its slot sensor"
        ),
    );
    // The user walks to the printer's menu; the unit just sits there meanwhile.
    session.link_mut().idle(USER_MS);
    session.command(Request::new(RequestCode::Load, SWAP_SLOT))?;

    session.console().heading(&format!(
        "5/5 tool change T{SWAP_SLOT}: the fresh filament goes to the nozzle"
    ));
    session.command(tool(SWAP_SLOT))?;
    Ok(())
}

/// The closing lines: tool changes and their times, virtual and wall time.
fn summary(session: &Session<SimLink>, wall_s: f64) -> Details {
    let console = session.console();
    let changes: Vec<&FinishedCommand> = console
        .finished()
        .iter()
        .filter(|done| done.request.code == RequestCode::Tool)
        .collect();
    let seconds = |done: &FinishedCommand| done.duration_ms as f64 / 1000.0;
    let times: Vec<String> = changes
        .iter()
        .map(|done| format!("{} {:.1} s", request_label(&done.request), seconds(done)))
        .collect();
    let virtual_s = session.now_ms() as f64 / 1000.0;
    console.say("");
    console.say(&format!(
        "demo: {} tool changes ({}), 1 eject, 1 preload: {virtual_s:.1} s of printer time in {wall_s:.1} s wall time",
        changes.len(),
        times.join(", "),
    ));
    let mut details = Details::new();
    let list: Vec<serde_json::Value> = changes
        .iter()
        .map(|done| serde_json::json!({"request": request_label(&done.request), "seconds": seconds(done)}))
        .collect();
    details.insert("tool_changes".into(), list.into());
    details.insert("virtual_s".into(), virtual_s.into());
    details.insert("wall_s".into(), wall_s.into());
    details
}
