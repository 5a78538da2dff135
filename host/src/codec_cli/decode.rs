//! `mmu decode`: explains frames or printer log lines read from stdin, one line each (with
//! `--frames-only`, only the lines holding a frame), so it can sit at the end of a pipe
//! (`tail -f serial.log | mmu decode`). A line holds either a bare frame (`T0*a4`) or a printer
//! log line with a direction marker (`MMU2:>T0*a4.` for a request, `MMU2:<T0 E8003*13.` for a
//! response; the trailing `.` is the log's newline marker), after the time a logger stamped
//! ([`super::log_line`]), which is kept. Without a marker both decoders are tried. A line that is
//! no MMU frame at all is said to be one, not reported as broken.

use std::error::Error;
use std::io::{self, BufRead, Write};

use clap::Args;
use mmu_protocol::{
    DecodeError, ErrorCode, ParamCode, Request, RequestCode, RequestDecoder, Response, ResponseDecoder,
};
use serde::Serialize;

use super::log_line;
use crate::explain::{error_help, request_meaning, response_meaning};

/// Options of `mmu decode`.
#[derive(Debug, Args)]
pub struct DecodeArgs {
    /// Print one JSON object per line instead of text.
    #[arg(long)]
    pub json: bool,
    /// Print only the lines that hold an MMU frame (or a broken one); drop the rest of the log.
    #[arg(long)]
    pub frames_only: bool,
}

/// Runs `mmu decode`: explains every stdin line on stdout.
pub fn decode(args: &DecodeArgs) -> Result<(), Box<dyn Error>> {
    let stdin = io::stdin();
    let stdout = io::stdout();
    match decode_stream(stdin.lock(), stdout.lock(), args.json, args.frames_only) {
        // A closed pipe (`mmu decode | head`) is the reader's choice, not an error.
        Err(err) if err.kind() == io::ErrorKind::BrokenPipe => Ok(()),
        other => Ok(other?),
    }
}

/// Explains every line of `input` on `output`, one line each (`frames_only`: only the lines
/// holding a frame).
pub fn decode_stream(
    mut input: impl BufRead,
    mut output: impl Write,
    json: bool,
    frames_only: bool,
) -> io::Result<()> {
    let mut line = Vec::new();
    loop {
        line.clear();
        if input.read_until(b'\n', &mut line)? == 0 {
            return output.flush();
        }
        // Logs are ASCII; anything else is kept visible rather than refused.
        let text = String::from_utf8_lossy(&line);
        let decoded = decode_line(&text);
        if frames_only && matches!(decoded.what, Decoded::Other { .. }) {
            continue;
        }
        if json {
            let object = serde_json::to_string(&decoded.to_json()).map_err(io::Error::other)?;
            writeln!(output, "{object}")?;
        } else {
            writeln!(output, "{}", decoded.to_human())?;
        }
        output.flush()?;
    }
}

/// Which side sent a frame, as a log line's marker says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Direction {
    /// Printer → unit (`>`).
    Request,
    /// Unit → printer (`<`).
    Response,
    /// No marker: try both decoders.
    Unknown,
}

/// The frame text in a line, and the direction its marker gives; `None` when there is no text.
fn extract_frame(line: &str) -> Option<(Direction, &str)> {
    let line = line.trim();
    let marker = ["MMU2:>", "MMU2:<", "MMU3:>", "MMU3:<"]
        .iter()
        .filter_map(|m| line.find(m).map(|at| (at, m)))
        .min_by_key(|(at, _)| *at);
    let (direction, rest) = if let Some((at, m)) = marker {
        let direction = if m.ends_with('>') {
            Direction::Request
        } else {
            Direction::Response
        };
        (direction, &line[at + m.len()..])
    } else if let Some(rest) = line.strip_prefix('>') {
        (Direction::Request, rest)
    } else if let Some(rest) = line.strip_prefix('<') {
        (Direction::Response, rest)
    } else {
        (Direction::Unknown, line)
    };
    // The log marks the frame's newline with a `.`; a frame never contains one.
    let frame = rest.split('.').next().unwrap_or("").trim();
    (!frame.is_empty()).then_some((direction, frame))
}

/// One decoder's verdict on a frame text.
#[derive(Debug)]
enum Verdict<T> {
    /// The frame parsed; `crc_ok` says whether its CRC matched. `clean` is false when bytes were
    /// rejected before it (a request letter interrupting a broken frame).
    Frame {
        frame: T,
        received_crc: u8,
        computed_crc: u8,
        clean: bool,
    },
    /// No frame: why.
    Rejected(String),
}

impl<T> Verdict<T> {
    /// How good this reading is: a clean, matching frame is best; a rejection worst.
    fn score(&self) -> u8 {
        match self {
            Verdict::Frame {
                received_crc,
                computed_crc,
                clean,
                ..
            } => 1 + 2 * u8::from(received_crc == computed_crc) + u8::from(*clean),
            Verdict::Rejected(_) => 0,
        }
    }
}

/// Feeds `text` and a newline to a decoder and keeps what the newline produced.
fn run_decoder<T: Copy>(
    text: &str,
    crc_of: impl Fn(&T) -> u8,
    mut feed: impl FnMut(u8) -> Option<Result<T, DecodeError<T>>>,
) -> Verdict<T> {
    let results: Vec<_> = text.bytes().chain([b'\n']).filter_map(&mut feed).collect();
    let clean = results.len() == 1;
    match results.last() {
        Some(Ok(frame)) => Verdict::Frame {
            frame: *frame,
            received_crc: crc_of(frame),
            computed_crc: crc_of(frame),
            clean,
        },
        Some(Err(DecodeError::BadCrc {
            frame,
            computed,
            received,
        })) => Verdict::Frame {
            frame: *frame,
            received_crc: *received,
            computed_crc: *computed,
            clean,
        },
        Some(Err(err)) => Verdict::Rejected(err.to_string()),
        None => Verdict::Rejected("no frame".to_string()),
    }
}

/// A decoded line.
#[derive(Debug)]
enum Decoded {
    Request {
        request: Request,
        received_crc: u8,
        computed_crc: u8,
    },
    Response {
        response: Response,
        received_crc: u8,
        computed_crc: u8,
    },
    /// Looks like a frame (or is marked as one) but does not decode.
    Invalid { input: String, reason: String },
    /// Not an MMU frame: another device's line, G-code, a log message.
    Other { input: String, reason: String },
}

/// A decoded line with the time its logger stamped on it.
#[derive(Debug)]
struct DecodedLine {
    time: Option<String>,
    what: Decoded,
}

/// Decodes one input line, keeping its time.
fn decode_line(line: &str) -> DecodedLine {
    let input = line.trim_end_matches(['\r', '\n']);
    let log = log_line::split(input);
    let other = |reason: &str| Decoded::Other {
        input: input.to_string(),
        reason: reason.to_string(),
    };
    let what = if input.trim().is_empty() {
        other("empty line")
    } else if log.sent_to_printer {
        other("not an MMU line (the host's G-code to the printer)")
    } else {
        match decode_frame(input, log.rest) {
            // A logged line that holds no frame is the log's own business.
            Decoded::Invalid { .. } if log.logged && !has_marker(log.rest) => other("not an MMU line"),
            decoded => decoded,
        }
    };
    DecodedLine {
        time: log.time.map(str::to_string),
        what,
    }
}

/// Whether `text` carries a printer's MMU frame marker.
fn has_marker(text: &str) -> bool {
    ["MMU2:>", "MMU2:<", "MMU3:>", "MMU3:<"]
        .iter()
        .any(|m| text.contains(m))
}

/// Decodes the frame in `text` (the line after its logger's prefix; `line` is the whole line).
fn decode_frame(line: &str, text: &str) -> Decoded {
    let input = line.to_string();
    let Some((direction, text)) = extract_frame(text) else {
        return Decoded::Invalid {
            input,
            reason: "a frame marker without a frame".to_string(),
        };
    };
    if direction == Direction::Unknown && !text.contains('*') {
        // Every MMU frame ends in `*<crc>`; anything without one is another device's line or a
        // log message.
        let reason = if text.contains("MMU2:") || text.contains("MMU3:") {
            "not a frame: an MMU log message"
        } else {
            "not an MMU line"
        };
        return Decoded::Other {
            input,
            reason: reason.to_string(),
        };
    }

    let request = || {
        let mut decoder = RequestDecoder::new();
        run_decoder(text, Request::crc, |b| decoder.feed(b))
    };
    let response = || {
        let mut decoder = ResponseDecoder::new();
        run_decoder(text, Response::crc, |b| decoder.feed(b))
    };

    let from_request = |verdict: Verdict<Request>| match verdict {
        Verdict::Frame {
            frame,
            received_crc,
            computed_crc,
            ..
        } => Ok(Decoded::Request {
            request: frame,
            received_crc,
            computed_crc,
        }),
        Verdict::Rejected(reason) => Err(reason),
    };
    let from_response = |verdict: Verdict<Response>| match verdict {
        Verdict::Frame {
            frame,
            received_crc,
            computed_crc,
            ..
        } => Ok(Decoded::Response {
            response: frame,
            received_crc,
            computed_crc,
        }),
        Verdict::Rejected(reason) => Err(reason),
    };

    if direction == Direction::Unknown && (text.contains("MMU2:") || text.contains("MMU3:")) {
        // A printer log line without a `>`/`<` marker is a log message, not a frame.
        return Decoded::Other {
            input,
            reason: "not a frame: an MMU log message".to_string(),
        };
    }

    let result = match direction {
        Direction::Request => from_request(request()).map_err(|r| format!("not a valid request: {r}")),
        Direction::Response => from_response(response()).map_err(|r| format!("not a valid response: {r}")),
        Direction::Unknown => {
            let (req, rsp) = (request(), response());
            if req.score() == 0 && rsp.score() == 0 {
                match (req, rsp) {
                    (Verdict::Rejected(a), Verdict::Rejected(b)) => {
                        Err(format!("not a request ({a}) nor a response ({b})"))
                    }
                    _ => Err("no frame".to_string()),
                }
            } else if rsp.score() > req.score() {
                from_response(rsp)
            } else {
                from_request(req)
            }
        }
    };
    result.unwrap_or_else(|reason| Decoded::Invalid { input, reason })
}

/// One line of `mmu decode --json`. Absent fields are left out.
#[derive(Debug, Serialize)]
struct JsonLine {
    /// `request`, `response`, `invalid` (a broken frame) or `other` (no MMU frame).
    kind: &'static str,
    /// The time the logger stamped on the line, as written.
    #[serde(skip_serializing_if = "Option::is_none")]
    time: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    code: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    value: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    value2: Option<u16>,
    #[serde(skip_serializing_if = "Option::is_none")]
    param: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    param_value: Option<u16>,
    #[serde(skip_serializing_if = "Option::is_none")]
    crc: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    crc_expected: Option<u8>,
    #[serde(skip_serializing_if = "Option::is_none")]
    crc_ok: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    meaning: Option<String>,
    /// An error answer: what it means on this unit, and what to check.
    #[serde(skip_serializing_if = "Option::is_none")]
    error_meaning: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    check: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    reason: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    input: Option<String>,
}

impl JsonLine {
    fn empty(kind: &'static str) -> Self {
        JsonLine {
            kind,
            time: None,
            code: None,
            value: None,
            value2: None,
            param: None,
            param_value: None,
            crc: None,
            crc_expected: None,
            crc_ok: None,
            meaning: None,
            error_meaning: None,
            check: None,
            reason: None,
            input: None,
        }
    }

    fn with_crc(mut self, received: u8, computed: u8) -> Self {
        self.crc = Some(received);
        self.crc_ok = Some(received == computed);
        self.crc_expected = (received != computed).then_some(computed);
        self
    }
}

/// The frame as the encoder writes it, without `*<crc>`: `T0 E8003`, `Wb 5`.
fn summary(frame: &str) -> &str {
    frame.split('*').next().unwrap_or(frame)
}

/// `CRC ok`, or `CRC BAD (carries 00, expected cf)`.
fn crc_text(received: u8, computed: u8) -> String {
    if received == computed {
        "CRC ok".to_string()
    } else {
        format!("CRC BAD (carries {received:x}, expected {computed:x})")
    }
}

impl Decoded {
    fn to_human(&self) -> String {
        match self {
            Decoded::Request {
                request,
                received_crc,
                computed_crc,
            } => format!(
                "request {} {}, {}",
                summary(request.encode().as_str()),
                request_meaning(request),
                crc_text(*received_crc, *computed_crc)
            ),
            Decoded::Response {
                response,
                received_crc,
                computed_crc,
            } => format!(
                "response {} {}, {}",
                summary(response.encode().as_str()),
                response_meaning(response),
                crc_text(*received_crc, *computed_crc)
            ),
            Decoded::Invalid { reason, .. } => format!("invalid: {reason}"),
            Decoded::Other { reason, input } => other_text(reason, input),
        }
    }

    fn to_json(&self) -> JsonLine {
        match self {
            Decoded::Request {
                request,
                received_crc,
                computed_crc,
            } => JsonLine {
                code: Some(request.code.to_string()),
                value: Some(request.value),
                value2: (request.code == RequestCode::Write).then_some(request.value2),
                meaning: Some(request_meaning(request)),
                ..JsonLine::empty("request")
            }
            .with_crc(*received_crc, *computed_crc),
            Decoded::Response {
                response,
                received_crc,
                computed_crc,
            } => JsonLine {
                code: Some(response.code.to_string()),
                value: Some(response.value),
                param: Some(response.param.to_string()),
                param_value: response.param_value,
                meaning: Some(response_meaning(response)),
                error_meaning: error_of(response).map(|e| error_help(e).meaning),
                check: error_of(response).map(|e| error_help(e).check),
                ..JsonLine::empty("response")
            }
            .with_crc(*received_crc, *computed_crc),
            Decoded::Invalid { input, reason } => JsonLine {
                reason: Some(reason.clone()),
                input: Some(input.clone()),
                ..JsonLine::empty("invalid")
            },
            Decoded::Other { input, reason } => JsonLine {
                reason: Some(reason.clone()),
                input: Some(input.clone()),
                ..JsonLine::empty("other")
            },
        }
    }
}

/// The error an `E` answer carries.
fn error_of(response: &Response) -> Option<ErrorCode> {
    (response.param == ParamCode::Error)
        .then_some(response.param_value)
        .flatten()
        .map(ErrorCode)
}

/// A line that holds no frame, with its text: what a log says between the frames (the host's
/// G-code, the printer's `ok`, the printer's own MMU messages such as `Command rejected`) is
/// often what explains them.
fn other_text(reason: &str, input: &str) -> String {
    let text = log_line::split(input).rest.trim();
    if text.is_empty() {
        return reason.to_string();
    }
    let message = ["MMU2:", "MMU3:"]
        .iter()
        .find_map(|marker| text.split_once(marker).map(|(_, message)| message.trim()));
    match message {
        Some(message) if reason.contains("MMU log message") => {
            format!("the printer's MMU message: {message}")
        }
        _ => format!("{reason}: {text}"),
    }
}

impl DecodedLine {
    /// `TIME  explanation`, or the explanation alone.
    fn to_human(&self) -> String {
        match &self.time {
            Some(time) => format!("{time}  {}", self.what.to_human()),
            None => self.what.to_human(),
        }
    }

    fn to_json(&self) -> JsonLine {
        JsonLine {
            time: self.time.clone(),
            ..self.what.to_json()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn decode_line_what(line: &str) -> Decoded {
        decode_line(line).what
    }

    #[test]
    fn frames_in_lines() {
        assert_eq!(extract_frame("T0*a4"), Some((Direction::Unknown, "T0*a4")));
        assert_eq!(
            extract_frame("12:00:01 MMU2:>T0*a4.\r\n"),
            Some((Direction::Request, "T0*a4"))
        );
        assert_eq!(
            extract_frame("MMU2:<T0 E8003*13."),
            Some((Direction::Response, "T0 E8003*13"))
        );
        assert_eq!(extract_frame(">S0*c6."), Some((Direction::Request, "S0*c6")));
        assert_eq!(extract_frame("MMU2:>."), None);
        assert_eq!(extract_frame("   "), None);
    }

    #[test]
    fn direction_is_guessed_without_a_marker() {
        assert!(matches!(decode_line_what("Wb 5*33"), Decoded::Request { .. }));
        assert!(matches!(decode_line_what("Wb A*5c"), Decoded::Response { .. }));
        assert!(matches!(decode_line_what("Wb R*63"), Decoded::Response { .. }));
        assert!(matches!(decode_line_what("T1*cf"), Decoded::Request { .. }));
        assert!(matches!(decode_line_what("T1 A*27"), Decoded::Response { .. }));
        assert!(matches!(decode_line_what("hello"), Decoded::Other { .. }));
        assert!(matches!(
            decode_line_what("MMU2:Command rejected"),
            Decoded::Other { .. }
        ));
    }

    #[test]
    fn a_marker_forces_the_direction() {
        assert!(matches!(
            decode_line_what("MMU2:<T1*cf."),
            Decoded::Invalid { .. }
        ));
        assert!(matches!(
            decode_line_what("MMU2:>T1 A*27."),
            Decoded::Invalid { .. }
        ));
    }

    #[test]
    fn stream_gives_one_line_per_line() {
        let input = b"T1*cf\n\nnonsense\nMMU2:<T0 E8003*13.\n";
        let mut out = Vec::new();
        decode_stream(&input[..], &mut out, false, false).expect("in-memory io");
        let text = String::from_utf8(out).expect("ascii");
        let lines: Vec<_> = text.lines().collect();
        assert_eq!(
            lines,
            [
                "request T1 tool change slot 1, CRC ok",
                "empty line",
                "not an MMU line: nonsense",
                "response T0 E8003 FSENSOR_DIDNT_SWITCH_ON (printer screen 04103), CRC ok",
            ]
        );
    }
}
