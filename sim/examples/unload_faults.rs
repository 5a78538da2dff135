//! The unload fault table: `cargo run --release -p mmu-sim --example unload_faults -- [SEEDS]
//! [--longer-bowden]` (default 200 seeds; `--longer-bowden` adds a row for 2-5 m tubes, minutes
//! more) prints, per fault users report, how often a tool change on Buddy 6.5.3 stops on
//! an error screen or stays stranded with the unit's strict mode (MMU 3.0.4's unload) and with
//! this unit, and the hardest pull on gripping gears. Exits non-zero when this unit strands a
//! change or pulls on gripping gears harder than a feel.

use std::process::ExitCode;

use mmu_firmware::drive::FEEL_DUTY;
use mmu_sim::Personality;
use mmu_sim::unload_faults::{HEADER, Row, TrialSetup, UnloadFault, play};

fn main() -> ExitCode {
    let seeds: u64 = std::env::args()
        .nth(1)
        .and_then(|arg| arg.parse().ok())
        .unwrap_or(200);
    let setup = |strict| TrialSetup {
        printer: Personality::Buddy65,
        extruder: None,
        strict,
    };
    println!("{HEADER}");
    let mut ok = true;
    let longer = std::env::args().any(|arg| arg == "--longer-bowden");
    let extra: &[UnloadFault] = if longer { &[UnloadFault::LongerBowden] } else { &[] };
    for &fault in UnloadFault::ALL.iter().chain(extra) {
        // The two modes side by side: a machine's second core halves the wait.
        let (strict, feel) = std::thread::scope(|scope| {
            let strict = scope.spawn(|| play(fault, setup(true), 0..seeds));
            let feel = play(fault, setup(false), 0..seeds);
            (strict.join(), feel)
        });
        let Ok(strict) = strict else {
            eprintln!("unload_faults: the strict mode's trials panicked");
            return ExitCode::FAILURE;
        };
        let row = Row { fault, strict, feel };
        println!("{row}");
        ok &= row.feel.stranded == 0 && row.feel.hardest_pull_permille <= FEEL_DUTY.permille();
    }
    if ok { ExitCode::SUCCESS } else { ExitCode::FAILURE }
}
