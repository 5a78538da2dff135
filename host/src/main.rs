//! `mmu`: the host-side tool of the MMU firmware.
//!
//! Subcommands live in sibling modules; this file only parses the command line and dispatches:
//! - `mmu encode request|response ...`: print a frame exactly as on the wire ([`codec_cli`]);
//! - `mmu decode [--json] [--frames-only]`: explain frames or printer log lines read from stdin
//!   ([`codec_cli::decode`]);
//! - `mmu sim`: the simulated unit on stdin/stdout or a pseudo-terminal ([`sim_cli`]);
//! - `mmu printer`: the printer's side against a real unit or the simulator ([`printer_cli`]);
//! - `mmu sensors`: every sensor of a unit live, as a table, CSV or a plotted PNG ([`sensors_cli`]);
//! - `mmu console`: plain commands to a unit or the simulator, by hand or from a script, and
//!   `mmu calibrate`: measure and save its distances and sensor thresholds ([`console`]);
//! - `mmu motor`: a slot's motor test, and `mmu slots`: the slot map (material, colour, where
//!   each filament is) ([`console::motor`], [`console::pc_files`]);
//! - `mmu demo`: a scripted session against the simulator ([`demo`]);
//! - `mmu fil`: the firmware-in-the-loop scenarios on a board's firmware image ([`fil_cli`]).
//!
//! Exit status: 0 success, 1 a failure (the unit stopped on an error, a port cannot be opened),
//! 2 a usage mistake (as clap's own), 130 stopped by Ctrl-C.

mod codec_cli;
mod console;
mod demo;
mod explain;
mod fil_cli;
mod lanes_text;
mod printer_cli;
mod sensors_cli;
mod sim_cli;
mod usage;

use std::error::Error;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// The command line.
#[derive(Debug, Parser)]
#[command(
    name = "mmu",
    version,
    about = "Host tool for the MMU firmware: simulator, printer emulator, Prusa MMU3 frame encoder and decoder"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
enum Command {
    /// Print a frame exactly as on the wire, without the newline. Numbers are decimal or 0x hex.
    #[command(subcommand)]
    Encode(codec_cli::EncodeCommand),
    /// Explain frames read from stdin, one output line per input line (--frames-only: per
    /// frame), keeping the time a logger stamped on it. A line is a bare frame (`T0*a4`) or a
    /// printer log line (`MMU2:>T0*a4.` request, `MMU2:<T0 E8003*13.` response).
    Decode(codec_cli::DecodeArgs),
    /// Serve the simulated unit (the unit logic on a physical model) on stdin/stdout or a
    /// pseudo-terminal, bytes exactly as on the UART.
    Sim(sim_cli::SimArgs),
    /// Play the printer: handshake, commands, register access, soak runs; against a unit on a
    /// serial port or the simulator.
    Printer(printer_cli::PrinterArgs),
    /// Every sensor of the unit live: raw and filtered readings, thresholds and state, as a table
    /// refreshed in place, CSV rows (--csv) or a plotted trace (--plot FILE.png), to tune the
    /// thresholds. Only reads: nothing in the unit changes.
    Sensors(sensors_cli::SensorsArgs),
    /// A scripted session against the simulator: handshake, tool changes, preload, eject.
    Demo(demo::DemoArgs),
    /// Plain commands (`t 1`, `read bowden`, `set bowden 410`, `retry`, `help`) to a unit on a
    /// serial port or the simulator, typed (history, tab completion) or piped, one a line.
    Console(console::ConsoleArgs),
    /// Measure and save the unit's mm per motor revolution, Bowden length, sensor thresholds and
    /// park distance.
    Calibrate(console::CalibrateArgs),
    /// Motor test of a slot: its filament forward to the hub sensor and back to park (a
    /// preload), with how far the odometry counted each way and how the motor Hall sensor swung.
    Motor(console::MotorArgs),
    /// The slot map: each slot's material and colour (kept on this PC) and where its filament is
    /// ("unknown" apart from "empty"); `set SLOT MATERIAL COLOUR`, `clear SLOT`.
    Slots(console::SlotsArgs),
    /// Run the firmware image of a board, unchanged, on its emulated chip (fil/) against the
    /// simulated unit and printer: the firmware-in-the-loop scenarios, one line each.
    Fil(fil_cli::FilArgs),
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result: Result<(), Box<dyn Error>> = match &cli.command {
        Command::Encode(command) => codec_cli::encode(command),
        Command::Decode(args) => codec_cli::decode(args),
        Command::Sim(args) => sim_cli::run(args),
        Command::Printer(args) => printer_cli::run(args),
        Command::Sensors(args) => sensors_cli::run(args),
        Command::Demo(args) => demo::run(args),
        Command::Console(args) => console::run(args),
        Command::Calibrate(args) => console::run_calibrate(args),
        Command::Motor(args) => console::run_motor(args),
        Command::Slots(args) => console::run_slots(args),
        Command::Fil(args) => fil_cli::run(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(err) => {
            eprintln!("mmu: error: {err}");
            usage::exit_code(err.as_ref())
        }
    }
}
