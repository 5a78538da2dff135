//! The console's command language: one command a line, words separated by blanks, numbers in
//! decimal or `0x` hex, registers by name or address. [`parse`] turns a line into a [`Command`];
//! [`HELP`] is what `help` prints and [`WORDS`] what tab completion offers.

use crate::codec_cli::{parse_button, parse_u8, parse_u16};

use super::calibrate::Step;
use super::link::FsensorMode;

/// What `help` prints.
pub const HELP: &str = "\
commands (numbers decimal or 0x hex; slots count from 0):
  t SLOT            tool change: the loaded filament comes out, SLOT's goes to the printer
  load SLOT         preload: feed SLOT's filament to the hub sensor and park it
  unload            pull the loaded filament back to its park position
  eject SLOT        pull SLOT's filament out of the unit (you take it out, then Continue)
  cut SLOT          the printer's cut command (this unit has no cutter: feed to the hub, park)
  home              check the sensors against what the unit knows
  read REG          read a register: a name (bowden_mm or bowden, lane.slot0, ...) or 0x22;
                    a sensor's or slot's name (hub.filament, slot1) reads all its registers
  set REG VALUE     write a register (write REG VALUE is the same); the unit saves it
  retry             press Retry / Continue (B1) and follow the command to its end
  button N          press button N (0 right, 1 middle = Retry, 2 left)
  status            the unit's state, its slots and the printer's filament sensor
  motor SLOT        motor test: SLOT's motor forward and back (a preload), with what its Hall
                    sensor and odometry saw
  slots             each slot: its material and colour (kept on this PC), where its filament is
  slot SLOT MATERIAL COLOUR   note what is loaded in SLOT (slot SLOT clear forgets it)
  stats             tool changes, errors and metres per slot since `stats reset`, and the time of
                    each tool change run here; stats reset starts counting again
  fsensor on|off|auto   the printer's filament sensor: fixed, or (auto) the simulator's / the
                    --fsensor-events file's
  calibrate [all|mm-per-rev|bowden|thresholds|park] [SLOT]   measure and save (see mmu calibrate --help)
  sim fault SPEC    inject a simulator fault (--sim only), e.g. jam:1; sim clear: clear them all
  wait SECONDS      let the unit run (the simulator's clock moves on)
  help, quit";

/// The first words of every command, for completion.
pub const WORDS: &[&str] = &[
    "t",
    "load",
    "unload",
    "eject",
    "cut",
    "home",
    "read",
    "set",
    "write",
    "retry",
    "button",
    "status",
    "motor",
    "slots",
    "slot",
    "stats",
    "fsensor",
    "calibrate",
    "sim",
    "wait",
    "help",
    "quit",
];

/// One console command.
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    /// `T<slot>`.
    Tool(u8),
    /// `L<slot>`.
    Load(u8),
    /// `U0`.
    Unload,
    /// `E<slot>`.
    Eject(u8),
    /// `K<slot>`.
    Cut(u8),
    /// `H0`.
    Home,
    /// `R` of the register(s) a name or number stands for.
    Read(String),
    /// `W` of the register a name or number stands for.
    Write(String, u16),
    /// `B1`, then follow the command.
    Retry,
    /// `B<n>`.
    Button(u8),
    /// The unit's state.
    Status,
    /// The motor test of a slot.
    Motor(u8),
    /// The slot map with the unit's lanes.
    Slots,
    /// Note a slot's material and colour; `None` forgets it.
    SlotNote(u8, Option<(String, String)>),
    /// The statistics; `true`: start counting again.
    Stats(bool),
    /// The printer's filament sensor from now on.
    Fsensor(FsensorMode),
    /// Calibrate, on a slot when given.
    Calibrate(Step, Option<u8>),
    /// Inject a simulator fault.
    SimFault(String),
    /// Clear the simulator's faults.
    SimClear,
    /// Let this many seconds pass.
    Wait(u16),
    /// Print [`HELP`].
    Help,
    /// End the session.
    Quit,
}

/// The command on `line`; `None` for a blank line or a `#` comment.
pub fn parse(line: &str) -> Result<Option<Command>, String> {
    let words: Vec<&str> = line.split_whitespace().collect();
    let Some((&first, args)) = words.split_first() else {
        return Ok(None);
    };
    if first.starts_with('#') {
        return Ok(None);
    }
    let slot = |what: &str| -> Result<u8, String> {
        match args {
            [value] => parse_u8(value).map_err(|e| format!("{what}: {e}")),
            _ => Err(format!("usage: {what} SLOT")),
        }
    };
    let command = match first.to_ascii_lowercase().as_str() {
        "t" | "tool" => Command::Tool(slot("t")?),
        "load" | "l" | "preload" => Command::Load(slot("load")?),
        "unload" | "u" => Command::Unload,
        "eject" | "e" => Command::Eject(slot("eject")?),
        "cut" | "k" => Command::Cut(slot("cut")?),
        "home" | "h" => Command::Home,
        "read" | "r" => match args {
            [name] => Command::Read(name.to_string()),
            _ => return Err("usage: read REGISTER".into()),
        },
        "set" | "write" | "w" => match args {
            [name, value] => Command::Write(name.to_string(), parse_u16(value)?),
            _ => return Err("usage: set REGISTER VALUE".into()),
        },
        "retry" | "continue" => Command::Retry,
        "button" | "b" => match args {
            [button] => Command::Button(parse_button(button)?),
            _ => return Err("usage: button N (0 right, 1 middle = Retry, 2 left)".into()),
        },
        "motor" => Command::Motor(slot("motor")?),
        "slots" => Command::Slots,
        "slot" => match args {
            [slot, word] if word.eq_ignore_ascii_case("clear") => Command::SlotNote(parse_u8(slot)?, None),
            [slot, material, colour] => {
                Command::SlotNote(parse_u8(slot)?, Some((material.to_string(), colour.to_string())))
            }
            _ => return Err("usage: slot SLOT MATERIAL COLOUR, or slot SLOT clear".into()),
        },
        "stats" => match args {
            [] => Command::Stats(false),
            ["reset"] => Command::Stats(true),
            _ => return Err("usage: stats, or stats reset".into()),
        },
        "status" | "q" => Command::Status,
        "fsensor" | "f" => Command::Fsensor(match args {
            ["on" | "1"] => FsensorMode::Fixed(1),
            ["off" | "0"] => FsensorMode::Fixed(0),
            ["nozzle" | "2"] => FsensorMode::Fixed(2),
            ["auto"] => FsensorMode::Auto,
            _ => return Err("usage: fsensor on|off|auto".into()),
        }),
        "calibrate" => {
            let (step, rest) = match args.split_first() {
                Some((word, rest)) if parse_u8(word).is_err() => (
                    word.parse::<Step>().map_err(|_| {
                        format!("calibrate what? {word:?}: all, mm-per-rev, bowden, thresholds or park")
                    })?,
                    rest,
                ),
                _ => (Step::All, args),
            };
            let slot = match rest {
                [] => None,
                [slot] => Some(parse_u8(slot)?),
                _ => return Err("usage: calibrate [STEP] [SLOT]".into()),
            };
            Command::Calibrate(step, slot)
        }
        "sim" => match args {
            ["fault", spec] => Command::SimFault(spec.to_string()),
            ["clear"] => Command::SimClear,
            _ => return Err("usage: sim fault SPEC | sim clear".into()),
        },
        "wait" => match args {
            [seconds] => Command::Wait(parse_u16(seconds)?),
            _ => return Err("usage: wait SECONDS".into()),
        },
        "help" | "?" => Command::Help,
        "quit" | "exit" => Command::Quit,
        other => return Err(format!("unknown command {other:?}: type help")),
    };
    Ok(Some(command))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines() {
        assert_eq!(parse("t 1"), Ok(Some(Command::Tool(1))));
        assert_eq!(parse("  "), Ok(None));
        assert_eq!(parse("# a comment"), Ok(None));
        let read = |name: &str| Ok(Some(Command::Read(name.into())));
        assert_eq!(parse("read hub.filament"), read("hub.filament"));
        assert_eq!(parse("read 0x22"), read("0x22"));
        assert_eq!(
            parse("set bowden 410"),
            Ok(Some(Command::Write("bowden".into(), 410)))
        );
        assert_eq!(
            parse("write 0x22 410"),
            Ok(Some(Command::Write("0x22".into(), 410)))
        );
        assert_eq!(
            parse("fsensor on"),
            Ok(Some(Command::Fsensor(FsensorMode::Fixed(1))))
        );
        assert_eq!(parse("calibrate"), Ok(Some(Command::Calibrate(Step::All, None))));
        assert_eq!(
            parse("calibrate bowden 1"),
            Ok(Some(Command::Calibrate(Step::Bowden, Some(1))))
        );
        assert_eq!(
            parse("calibrate 2"),
            Ok(Some(Command::Calibrate(Step::All, Some(2))))
        );
        assert!(parse("t").is_err());
        assert!(parse("t 300").is_err());
        assert!(parse("set bowden x").is_err());
        assert!(parse("frobnicate").is_err());
        assert_eq!(parse("motor 2"), Ok(Some(Command::Motor(2))));
        assert_eq!(
            parse("slot 1 PETG red"),
            Ok(Some(Command::SlotNote(1, Some(("PETG".into(), "red".into())))))
        );
        assert_eq!(parse("slot 1 clear"), Ok(Some(Command::SlotNote(1, None))));
        assert_eq!(parse("stats reset"), Ok(Some(Command::Stats(true))));
        for word in WORDS {
            assert!(HELP.contains(word), "help lacks {word}");
        }
    }

    /// Before: `button 9` was sent to the unit; the printer has three buttons.
    #[test]
    fn only_the_printer_s_three_buttons_are_pressed() {
        assert_eq!(parse("button 2"), Ok(Some(Command::Button(2))));
        let error = parse("button 9").unwrap_err();
        assert!(error.contains("0 (right), 1 (middle"), "{error}");
    }
}
