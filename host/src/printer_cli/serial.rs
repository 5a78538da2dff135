//! The printer's side of a real wire: [`SerialLink`] drives a unit on a serial port at
//! 115200 8N1 (the MMU port of Prusa printers), on the wall clock.
//!
//! A printer-side program cannot see a filament sensor, so [`FsensorSource`] plays it: a fixed
//! state, or the latest `fsensor` event of the JSON-lines file `mmu sim --events PATH` writes
//! (`{"t_ms":N,"kind":"fsensor","state":S}`), read incrementally as the simulator appends to it.

use std::fs::File;
use std::io::{self, Read, Seek, SeekFrom, Write};
use std::path::PathBuf;
use std::time::{Duration, Instant};

use mmu_sim::{Link, PrinterEvent};
use serde::Deserialize;
use serialport::{DataBits, FlowControl, Parity, SerialPort, StopBits};

use super::console::Target;

/// The MMU port's speed.
pub const BAUD: u32 = 115_200;
/// The events file is looked at no more often than this.
const EVENTS_LOOK_MS: u64 = 20;

/// Where the printer's filament sensor state comes from for a unit outside the simulator.
#[derive(Debug)]
pub enum FsensorSource {
    /// Always this state: 0 no filament, 1 at the sensor, 2 in the nozzle.
    Fixed(u8),
    /// The latest `fsensor` event of a `mmu sim --events` file.
    Events(EventsTail),
}

impl FsensorSource {
    /// The state now.
    pub fn state(&mut self) -> u8 {
        match self {
            FsensorSource::Fixed(state) => *state,
            FsensorSource::Events(tail) => tail.state(),
        }
    }
}

/// Follows a `mmu sim --events` file as it grows and keeps the latest `fsensor` state (0 until
/// one is seen). A missing file reads as 0 and is looked for again; a file that shrank (a new
/// simulator run) is read again from its start.
#[derive(Debug)]
pub struct EventsTail {
    path: PathBuf,
    file: Option<File>,
    offset: u64,
    partial: Vec<u8>,
    state: u8,
    last_look: Option<Instant>,
}

impl EventsTail {
    /// Follow `path`.
    pub fn new(path: PathBuf) -> Self {
        EventsTail {
            path,
            file: None,
            offset: 0,
            partial: Vec::new(),
            state: 0,
            last_look: None,
        }
    }

    /// The latest `fsensor` state, after reading what was appended since the last look.
    pub fn state(&mut self) -> u8 {
        let due = self
            .last_look
            .is_none_or(|at| at.elapsed() >= Duration::from_millis(EVENTS_LOOK_MS));
        if due {
            self.last_look = Some(Instant::now());
            if self.read_new().is_err() {
                // Not there (yet) or unreadable: look again next time.
                self.file = None;
            }
        }
        self.state
    }

    fn read_new(&mut self) -> io::Result<()> {
        let file = match &mut self.file {
            Some(file) => file,
            None => {
                self.offset = 0;
                self.partial.clear();
                self.file.insert(File::open(&self.path)?)
            }
        };
        if file.metadata()?.len() < self.offset {
            file.seek(SeekFrom::Start(0))?;
            self.offset = 0;
            self.partial.clear();
        }
        let mut fresh = Vec::new();
        let read = file.read_to_end(&mut fresh)?;
        self.offset += read as u64;
        self.partial.extend_from_slice(&fresh);
        while let Some(end) = self.partial.iter().position(|&b| b == b'\n') {
            let line: Vec<u8> = self.partial.drain(..=end).collect();
            if let Some(state) = fsensor_state(&line) {
                self.state = state;
            }
        }
        Ok(())
    }
}

/// The state of an `fsensor` event line; `None` for other lines and anything unreadable.
fn fsensor_state(line: &[u8]) -> Option<u8> {
    #[derive(Deserialize)]
    struct EventLine {
        kind: String,
        state: Option<u8>,
    }
    let event: EventLine = serde_json::from_slice(line).ok()?;
    (event.kind == "fsensor").then_some(event.state).flatten()
}

/// A unit on a serial port. See the [module documentation](self).
pub struct SerialLink {
    port: Box<dyn SerialPort>,
    /// The port's path, as the person named it.
    path: String,
    started: Instant,
    /// The port's read timeout now, ms (set only when it changes).
    timeout_ms: u64,
    fsensor: FsensorSource,
    /// Bytes read from the port since it was opened.
    received: u64,
}

impl SerialLink {
    /// Open `path` at 115200 8N1 without flow control, dropping whatever waits in its buffers.
    pub fn open(path: &str, fsensor: FsensorSource) -> Result<Self, String> {
        let timeout_ms = 5;
        let port = serialport::new(path, BAUD)
            .data_bits(DataBits::Eight)
            .parity(Parity::None)
            .stop_bits(StopBits::One)
            .flow_control(FlowControl::None)
            .timeout(Duration::from_millis(timeout_ms))
            .open()
            .map_err(|error| format!("cannot open serial port {path}: {error}"))?;
        port.clear(serialport::ClearBuffer::All)
            .map_err(|error| format!("cannot flush serial port {path}: {error}"))?;
        Ok(SerialLink {
            port,
            path: path.to_string(),
            started: Instant::now(),
            timeout_ms,
            fsensor,
            received: 0,
        })
    }
}

/// Says once what to check when a serial port gives no answer: at the first link loss before
/// any answer decoded (a serial port's [`Target::no_answer_hint`]). Nothing for the simulator.
#[derive(Debug, Default)]
pub struct NoAnswerHint {
    answered: bool,
    told: bool,
}

impl NoAnswerHint {
    /// Follow `event` on `link`; the hint, once, when it is due.
    pub fn on_event<L: Target>(&mut self, link: &L, event: &PrinterEvent) -> Option<String> {
        match event {
            PrinterEvent::Received(_) => self.answered = true,
            PrinterEvent::LinkLost(_) if !self.answered && !self.told => {
                let hint = link.no_answer_hint()?;
                self.told = true;
                return Some(hint);
            }
            _ => {}
        }
        None
    }
}

impl Link for SerialLink {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.port.write_all(bytes)?;
        self.port.flush()
    }

    fn receive(&mut self, max_ms: u64, into: &mut Vec<u8>) -> io::Result<()> {
        let wait = max_ms.max(1);
        if wait != self.timeout_ms {
            self.port.set_timeout(Duration::from_millis(wait))?;
            self.timeout_ms = wait;
        }
        let mut buffer = [0u8; 256];
        match self.port.read(&mut buffer) {
            Ok(read) => {
                into.extend_from_slice(buffer.get(..read).unwrap_or(&[]));
                self.received += read as u64;
            }
            Err(error)
                if matches!(
                    error.kind(),
                    io::ErrorKind::TimedOut | io::ErrorKind::WouldBlock | io::ErrorKind::Interrupted
                ) => {}
            Err(error) => return Err(error),
        }
        Ok(())
    }

    fn now_ms(&self) -> u64 {
        u64::try_from(self.started.elapsed().as_millis()).unwrap_or(u64::MAX)
    }

    fn fsensor(&mut self) -> u8 {
        self.fsensor.state()
    }
}

impl Target for SerialLink {
    fn remove_filament(&mut self, _slot: u8) -> bool {
        false
    }

    fn notes(&mut self) -> Vec<(u64, String)> {
        Vec::new()
    }

    /// What to check when the handshake got no answer: nothing came back at all (the wrong
    /// port, the wires, the unit), or bytes that never made a frame (the speed, noise).
    fn no_answer_hint(&self) -> Option<String> {
        let path = &self.path;
        Some(if self.received == 0 {
            format!(
                "no answer from {path} yet, not one byte came back. If it stays silent, check: that {path} is the \
                 USB-serial adapter wired to the unit (`ls -l /dev/serial/by-id/`; not the NUCLEO's ST-LINK port, \
                 /dev/ttyACM0); that TX and RX are crossed (the adapter's TX to the unit's RX, its RX to the unit's \
                 TX: swap them if unsure); that GND is wired to the unit's GND; that the unit is powered and flashed \
                 with this firmware. The line runs at {BAUD} 8N1."
            )
        } else {
            format!(
                "{} bytes came back from {path}, but none decoded as an answer: the line is not at {BAUD} 8N1 \
                 (a wrong baud rate: an adapter or unit set to another speed), or noise garbles it (a loose GND, \
                 long wires beside the motors), or another device answers on this port.",
                self.received
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fresh path in the temporary directory.
    fn temp_path(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("mmu-printer-{}-{name}.jsonl", std::process::id()))
    }

    fn append(path: &PathBuf, text: &str) {
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .unwrap();
        file.write_all(text.as_bytes()).unwrap();
    }

    /// Looks at the file now, whatever the throttle says.
    fn look(tail: &mut EventsTail) -> u8 {
        tail.last_look = None;
        tail.state()
    }

    #[test]
    fn event_lines() {
        assert_eq!(
            fsensor_state(br#"{"t_ms":5,"kind":"fsensor","state":2}"#),
            Some(2)
        );
        assert_eq!(
            fsensor_state(br#"{"t_ms":5,"kind":"slot","slot":1,"tip_mm":null}"#),
            None
        );
        assert_eq!(fsensor_state(b"garbage"), None);
        assert_eq!(fsensor_state(br#"{"kind":"fsensor","state":300}"#), None);
    }

    #[test]
    fn follows_the_file_as_it_grows() {
        let path = temp_path("grows");
        let _ = std::fs::remove_file(&path);
        let mut tail = EventsTail::new(path.clone());
        assert_eq!(look(&mut tail), 0, "no file yet");
        append(
            &path,
            "{\"t_ms\":1,\"kind\":\"fsensor\",\"state\":1}\n{\"t_ms\":2,\"kind\":\"fs",
        );
        assert_eq!(look(&mut tail), 1);
        append(
            &path,
            "ensor\",\"state\":2}\n{\"t_ms\":3,\"kind\":\"power\",\"on\":true}\n",
        );
        assert_eq!(look(&mut tail), 2, "the line split across two writes counts");
        // A new simulator run starts the file again.
        std::fs::write(&path, "{\"t_ms\":0,\"kind\":\"fsensor\",\"state\":0}\n").unwrap();
        assert_eq!(look(&mut tail), 0);
        std::fs::remove_file(&path).unwrap();
    }
}
