//! What surrounds a frame in a real log: the time a logger stamped on the line, and whether the
//! line is an MMU frame at all.
//!
//! Formats seen in the wild:
//! - OctoPrint's serial.log: `2026-11-22 10:00:00,123 - Recv: echo:MMU2:<T1 A*27.` and
//!   `... - Send: N12 T1*38` (G-code to the printer, never an MMU frame);
//! - Repetier: `10:00:02.500 : echo:MMU2:<T1 P1c*45.`, sometimes after a `<`/`>` direction mark;
//! - the Arduino IDE's serial monitor with timestamps: `10:00:03.123 -> MMU2:<R1b A5*29.`, or
//!   bare frames when it listens on the MMU wire itself (`10:00:03.123 -> T1*cf`);
//! - Prusa's firmware marks its MMU frames `MMU2:>` (request) and `MMU2:<` (response), Marlin's
//!   `MMU3:>`/`MMU3:<`.

use std::sync::LazyLock;

use regex::Regex;

/// A log line split into the logger's part and the rest.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogLine<'a> {
    /// The time the logger stamped, as written (`2026-11-22 10:00:00,123`, `10:00:02.500`).
    pub time: Option<&'a str>,
    /// The logger said the host sent this line to the printer (`Send:`): G-code, not a frame.
    pub sent_to_printer: bool,
    /// A logger's prefix was found (a time, `Send:`/`Recv:`): the line is a log line, so text
    /// that does not decode is not a broken frame but something else.
    pub logged: bool,
    /// What follows the logger's prefix.
    pub rest: &'a str,
}

/// A time at the start of the line, optionally with a date; then the logger's separator.
static PREFIX: LazyLock<Regex> = LazyLock::new(|| {
    Regex::new(
        r"^\s*(?:[<>]\s*)?(?P<time>(?:\d{4}-\d{2}-\d{2}[ T])?\d{1,2}:\d{2}:\d{2}(?:[.,]\d{1,6})?)\s*(?:->|-|:|\|)?\s*",
    )
    .expect("the pattern is valid")
});

/// `Send:`/`Recv:` (OctoPrint), after the time.
static DIRECTION: LazyLock<Regex> = LazyLock::new(|| {
    Regex::new(r"^(?P<dir>Send|Recv|SENT|RECV|RX|TX)\s*:\s*").expect("the pattern is valid")
});

/// Split `line` (without its newline) into the logger's part and the rest.
pub fn split(line: &str) -> LogLine<'_> {
    let (time, rest) = match PREFIX.captures(line) {
        Some(captures) => {
            let end = captures.get(0).map_or(0, |m| m.end());
            (captures.name("time").map(|m| m.as_str()), &line[end..])
        }
        None => (None, line),
    };
    let (direction, rest) = match DIRECTION.captures(rest) {
        Some(captures) => {
            let end = captures.get(0).map_or(0, |m| m.end());
            (captures.name("dir").map(|m| m.as_str()), &rest[end..])
        }
        None => (None, rest),
    };
    LogLine {
        time,
        sent_to_printer: matches!(direction, Some("Send" | "SENT" | "TX")),
        logged: time.is_some() || direction.is_some(),
        rest,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loggers_prefixes_are_split_off() {
        let octoprint = split("2026-11-22 10:00:00,130 - Recv: echo:MMU2:>T1*cf.");
        assert_eq!(octoprint.time, Some("2026-11-22 10:00:00,130"));
        assert_eq!(octoprint.rest, "echo:MMU2:>T1*cf.");
        assert!(octoprint.logged && !octoprint.sent_to_printer);
        let sent = split("2026-11-22 10:00:00,123 - Send: N12 T1*38");
        assert!(sent.sent_to_printer);
        assert_eq!(sent.rest, "N12 T1*38");
        let repetier = split("< 10:00:02.500 : echo:MMU2:<T1 P1c*45.");
        assert_eq!(repetier.time, Some("10:00:02.500"));
        assert_eq!(repetier.rest, "echo:MMU2:<T1 P1c*45.");
        let arduino = split("10:00:03.123 -> T1*cf");
        assert_eq!((arduino.time, arduino.rest), (Some("10:00:03.123"), "T1*cf"));
        let bare = split("T1*cf");
        assert_eq!((bare.time, bare.rest, bare.logged), (None, "T1*cf", false));
        // A frame is never mistaken for a time.
        assert_eq!(split("S0 A3*22").time, None);
    }
}
