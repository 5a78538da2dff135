//! Records the session the step-cost benchmark replays on the MCU's instruction set.
//!
//! The physical model (`mmu-model`) needs `std`, so it runs here, on the host: the unchanged
//! unit logic (`App<3>`) steps against it once per millisecond while a scripted printer talks to
//! it the way Prusa's firmware does (version handshake, settings writes, `Q0` heartbeat followed
//! by `f` and the register poll, ramming before a command that needs the extruder empty,
//! co-feeding at `FeedingToFSensor`, load to nozzle after `T`). Every step's raw samples and the
//! bytes the printer put on the line in that millisecond are written out. The bytes reach the
//! App as on the board: through a receive queue of which each step takes at most
//! `control::MAX_RX_PER_STEP` (`control::RxQueue`); the harness replays the line through the same
//! queue into the same logic built for thumbv6m, which gives the same steps: it checks that with
//! a digest of everything the App sent.
//!
//! The script covers every command (`T L U E K H`), an error with its Retry, a sensor stuck at a
//! rail, query bursts (64 bytes of requests arriving at once, answered over four steps) while
//! idle, feeding and in an error, and settings writes (each one a save).
//!
//!   mmu-bench-session OUT.bin
//!
//! Format (little endian): `MMUQ`, u32 step count, then per step 9 × u16 samples (slot 0..2
//! motor Hall and filament, hub filament, tension, cutter), u8 length and the bytes that arrived
//! on the line; then u32 digest of every byte the App sent (FNV-1a).

use std::collections::VecDeque;
use std::error::Error;

use mmu_firmware::control::{RX_RING, RxQueue};
use mmu_firmware::persist::Snapshot;
use mmu_firmware::runner::Status;
use mmu_firmware::{App, Config, Instant, Samples};
use mmu_model::{Fault, FaultKind, Model, ModelConfig};
use mmu_protocol::{ButtonCode, ErrorCode, ProgressCode, Request, RequestCode};

const SLOTS: usize = 3;
/// `Q0` this long after the last exchange (Prusa's `heartBeatPeriod`).
const HEARTBEAT_MS: u64 = 1000;
/// Registers the printer reads after every `Q0` (FINDA, pulley, selector, errors, fsensor).
const POLLED_REGISTERS: [u8; 5] = [0x08, 0x1b, 0x1c, 0x04, 0x1a];
/// Printer mechanics, as in `mmu-sim` (sim.rs).
const PRINTER_UNLOAD_MM: f32 = 80.0;
const PRINTER_UNLOAD_MM_S: f32 = 80.0;
const COFEED_MM: f32 = 189.9;
const LOAD_TO_NOZZLE_MM: f32 = 60.0;
const LOAD_TO_NOZZLE_MM_S: f32 = 15.0;
const UNLOAD_HELP_MM: f32 = 20.0;
const EXTRA_LOAD_MM: u16 = 5;
const SLOW_MM_S: u16 = 20;
/// Where a user pushes a fresh filament's tip, mm from the hub sensor (as `mmu demo`).
const FRESH_TIP_MM: f32 = -90.0;
/// A command must end within this, ms.
const COMMAND_LIMIT_MS: u64 = 120_000;
/// A query burst: this many bytes of requests arriving at once.
const BURST_BYTES: usize = 64;

/// What the scripted printer and user do next.
#[derive(Debug, Clone, Copy)]
enum Act {
    /// Run a command to its end, pressing Retry (`B1`) on an error after `retry_after_ms`.
    Command(RequestCode, u8),
    /// Nothing but the heartbeat for a while.
    Idle(u64),
    /// 64 bytes of whole requests at once (a printer catching up after a stall).
    Burst,
    /// The version handshake (`S0`..`S3`).
    Handshake,
    /// A register write (a settings save follows).
    Write(u8, u16),
    /// The user pushes a fresh filament into a slot.
    Insert(usize),
    /// The physical world breaks or heals.
    Inject(Fault),
    Clear(FaultKind),
    /// Run a command that fails; stay in the error for `ms`, then run the next `Act` (which
    /// heals the fault) and press Retry.
    Failing(RequestCode, u8, u64),
}

struct Recorder {
    app: App<SLOTS>,
    model: Model,
    now: u64,
    out: Vec<u8>,
    steps: u32,
    digest: u32,
    /// Requests to send, one per step.
    queue: VecDeque<Request>,
    /// Bytes on their way to the App, as in the board's UART ring.
    received: RxQueue<RX_RING>,
    last_exchange: u64,
    reported_fsensor: Option<u8>,
    cofeeding: bool,
    debug: bool,
}

impl Recorder {
    fn new() -> Self {
        let mut app = App::new(Config::default());
        // The harness boots through the persistence Keeper on a blank flash, which restores
        // the defaults: do the same so both Apps start equal.
        app.restore(&Snapshot::default());
        Recorder {
            app,
            model: Model::new(ModelConfig::default(), SLOTS, 1),
            now: 0,
            out: Vec::new(),
            steps: 0,
            digest: 0x811c_9dc5,
            queue: VecDeque::new(),
            received: RxQueue::new(),
            last_exchange: 0,
            reported_fsensor: None,
            cofeeding: false,
            debug: std::env::var_os("SESSION_DEBUG").is_some(),
        }
    }

    fn send(&mut self, request: Request) {
        self.queue.push_back(request);
    }

    /// One millisecond: `line` arrives, the App takes its share of what waits, the model moves
    /// with the App's motor commands.
    fn step_with(&mut self, line: Vec<u8>) {
        let samples: Samples<SLOTS> = self.model.samples();
        self.received.receive(&line);
        let rx = self.received.take_step();
        // The firmware's first control tick comes a period after the control task starts its
        // Ticker (at 0): step `k` runs at `k + 1` ms (bench-mcu/harness polls the tasks so).
        let out = self.app.step(Instant::from_millis(self.now + 1), &samples, &rx);
        for slot in samples.slots {
            self.out.extend_from_slice(&slot.motor_hall.to_le_bytes());
            self.out.extend_from_slice(&slot.filament.to_le_bytes());
        }
        for value in [samples.hub.filament, samples.hub.tension, samples.hub.cutter] {
            self.out.extend_from_slice(&value.to_le_bytes());
        }
        self.out.push(line.len() as u8);
        self.out.extend_from_slice(&line);
        for &byte in out.tx.iter() {
            self.digest = (self.digest ^ u32::from(byte)).wrapping_mul(0x0100_0193);
        }
        if self.debug {
            eprintln!("step {} rx {} tx {:?} digest {:08x}", self.steps, rx.len(), String::from_utf8_lossy(&out.tx), self.digest);
        }
        self.model.step(1, &out.motors);
        self.printer_mechanics();
        self.steps += 1;
        self.now += 1;
    }

    /// One millisecond with the next queued request, if any.
    fn step(&mut self) {
        let rx = match self.queue.pop_front() {
            Some(mut request) => {
                self.last_exchange = self.now;
                // `f` tells the sensor's state as it is when sent.
                if request.code == RequestCode::FilamentSensor {
                    request.value = self.model.fsensor_state();
                    self.reported_fsensor = Some(request.value);
                }
                request.encode().as_bytes().to_vec()
            }
            None => Vec::new(),
        };
        self.step_with(rx);
        self.heartbeat();
    }

    /// `f` at once on a change; `Q0`, `f` and the register poll after a second of quiet.
    fn heartbeat(&mut self) {
        if !self.queue.is_empty() || !self.received.is_empty() {
            return;
        }
        let state = self.model.fsensor_state();
        if self.reported_fsensor != Some(state) {
            self.send(Request::new(RequestCode::FilamentSensor, state));
        }
        if self.now >= self.last_exchange + HEARTBEAT_MS {
            self.send(Request::new(RequestCode::Query, 0));
            self.send(Request::new(RequestCode::FilamentSensor, state));
            for address in POLLED_REGISTERS {
                self.send(Request::new(RequestCode::Read, address));
            }
        }
    }

    /// The printer's extruder: co-feeding during `FeedingToFSensor`, then the extra load, and
    /// a helping pull while another command unloads.
    fn printer_mechanics(&mut self) {
        let operation = self.app.operation();
        let state = self.model.fsensor_state();
        let feeding = operation.status() == Status::Running(ProgressCode::FEEDING_TO_FSENSOR);
        if self.cofeeding && state != 0 {
            self.cofeeding = false;
            self.model
                .extruder_move(f32::from(EXTRA_LOAD_MM) + 2.0, f32::from(SLOW_MM_S));
        } else if feeding && !self.cofeeding && state == 0 {
            self.cofeeding = true;
            self.model.extruder_move(COFEED_MM, f32::from(SLOW_MM_S));
        }
        let helps_unload = operation.status() == Status::Running(ProgressCode::UNLOADING_TO_FINDA)
            && !matches!(operation.request.0, RequestCode::Unload | RequestCode::Tool);
        if helps_unload && state != 0 && !self.model.extruder_busy() {
            self.model.extruder_move(-UNLOAD_HELP_MM, UNLOAD_HELP_MM);
        }
    }

    fn idle(&mut self, ms: u64) {
        for _ in 0..ms {
            self.step();
        }
    }

    /// Send everything queued, one request per step, until the App has taken it all.
    fn drain(&mut self) {
        while !self.queue.is_empty() || !self.received.is_empty() {
            self.step();
        }
    }

    /// Start `code value`: the printer rams its filament out first when the command needs it.
    fn start(&mut self, code: RequestCode, value: u8) -> Result<(), Box<dyn Error>> {
        self.drain();
        self.cofeeding = false;
        self.model.extruder_move(0.0, PRINTER_UNLOAD_MM_S);
        let same_tool = code == RequestCode::Tool && self.model.loaded_slot() == Some(usize::from(value));
        let needs_unload = matches!(
            code,
            RequestCode::Unload | RequestCode::Tool | RequestCode::Eject | RequestCode::Cut
        ) && !same_tool;
        let in_gears = self
            .model
            .loaded_slot()
            .and_then(|slot| self.model.tip_mm(slot))
            .is_some_and(|tip| tip >= self.model.config().extruder_gears_mm);
        if needs_unload && in_gears {
            self.model.extruder_move(-PRINTER_UNLOAD_MM, PRINTER_UNLOAD_MM_S);
            while self.model.extruder_busy() {
                self.step();
            }
        }
        self.drain();
        self.send(Request::new(code, value));
        self.drain();
        if self.debug {
            eprintln!(
                "{} ms: {code:?}{value}: fsensor {}, tips {:?}, lanes {:?}",
                self.now,
                self.model.fsensor_state(),
                (0..SLOTS).map(|s| self.model.tip_mm(s)).collect::<Vec<_>>(),
                self.app.lanes()
            );
        }
        if self.app.operation().request != (code, value) {
            return Err(format!("{code:?}{value} was not accepted").into());
        }
        Ok(())
    }

    /// Until the running command stops; its final status.
    fn run_to_end(&mut self) -> Result<Status, Box<dyn Error>> {
        let start = self.now;
        loop {
            match self.app.operation().status() {
                Status::Running(_) => {}
                status => return Ok(status),
            }
            if self.now - start > COMMAND_LIMIT_MS {
                return Err(format!("command {:?} did not end", self.app.operation().request).into());
            }
            self.step();
        }
    }

    /// Until `code value` has finished (an eject: after the user took the filament and pressed
    /// Continue); a tool change then loads the nozzle.
    fn finished(&mut self, code: RequestCode, value: u8) -> Result<(), Box<dyn Error>> {
        let status = self.run_to_end()?;
        if code == RequestCode::Tool && status == Status::Finished {
            self.model.extruder_move(LOAD_TO_NOZZLE_MM, LOAD_TO_NOZZLE_MM_S);
        }
        match status {
            Status::Finished => Ok(()),
            Status::Failed(ErrorCode::FILAMENT_EJECTED) => {
                self.model.remove_filament(usize::from(value));
                self.idle(2000);
                self.press_retry();
                self.finished(code, value)
            }
            other => Err(format!(
                "{code:?}{value} ended in {other:?} at {} ms (unit fsensor {}, model {}, tips {:?})",
                self.now,
                self.app.unit().fsensor,
                self.model.fsensor_state(),
                (0..SLOTS).map(|s| self.model.tip_mm(s)).collect::<Vec<_>>()
            )
            .into()),
        }
    }

    fn press_retry(&mut self) {
        self.send(Request::new(RequestCode::Button, ButtonCode::MIDDLE.0));
        self.drain();
    }

    /// 64 bytes of whole requests at once: `Q0`, `P0` and the polled registers, as many as fit
    /// exactly.
    fn burst(&mut self) {
        self.drain();
        let frames: Vec<Vec<u8>> = [
            Request::new(RequestCode::Query, 0),
            Request::new(RequestCode::Finda, 0),
        ]
        .into_iter()
        .chain(POLLED_REGISTERS.map(|address| Request::new(RequestCode::Read, address)))
        .map(|request| request.encode().as_bytes().to_vec())
        .collect();
        let shortest = frames.iter().map(Vec::len).min().unwrap_or(1);
        let mut rx = Vec::new();
        for frame in frames.iter().cycle() {
            let left = BURST_BYTES - rx.len();
            // Leave room for a whole frame, never a part of one.
            if frame.len() == left || frame.len() + shortest <= left {
                rx.extend_from_slice(frame);
            }
            if frames.iter().all(|f| f.len() > BURST_BYTES - rx.len()) {
                break;
            }
        }
        if self.debug {
            eprintln!("{} ms: burst of {} bytes", self.now, rx.len());
        }
        self.step_with(rx);
    }

    fn play(&mut self, script: &[Act]) -> Result<(), Box<dyn Error>> {
        let mut acts = script.iter().copied();
        while let Some(act) = acts.next() {
            match act {
                Act::Command(code, value) => {
                    self.start(code, value)?;
                    self.finished(code, value)?;
                }
                Act::Idle(ms) => self.idle(ms),
                Act::Burst => self.burst(),
                Act::Handshake => {
                    // A printer that wants 3.0.3 (Buddy 6.4.x): it asks S2 again after the
                    // unit's first offer (3.0.4), which the unit answers with 3.0.3, then S3.
                    // The script's unloads are the 3.0.3 contract's: the unit pulls at once
                    // (a 3.0.4 printer retracts past its own sensor first).
                    for part in [0, 1, 2, 2, 3] {
                        self.send(Request::new(RequestCode::Version, part));
                    }
                    self.drain();
                }
                Act::Write(address, value) => {
                    self.send(Request::write(address, value));
                    self.drain();
                }
                Act::Insert(slot) => {
                    self.model.insert_filament(slot, FRESH_TIP_MM);
                }
                Act::Inject(fault) => {
                    self.model.inject(fault);
                }
                Act::Clear(kind) => {
                    self.model.clear(kind);
                }
                Act::Failing(code, value, error_ms) => {
                    self.start(code, value)?;
                    match self.run_to_end()? {
                        Status::Failed(_) => {}
                        other => return Err(format!("{code:?}{value} should fail, ended {other:?}").into()),
                    }
                    // In the error: the printer polls, bursts once, the user looks.
                    self.idle(error_ms / 2);
                    self.burst();
                    self.idle(error_ms / 2);
                    // The next act heals the fault; then Retry.
                    if let Some(heal) = acts.next() {
                        self.play(&[heal])?;
                    }
                    self.press_retry();
                    self.finished(code, value)?;
                }
            }
        }
        Ok(())
    }
}

fn script() -> Vec<Act> {
    use RequestCode::*;
    vec![
        // Boot: the start-up check, then the printer's handshake and settings.
        Act::Idle(500),
        Act::Handshake,
        Act::Write(0x0b, EXTRA_LOAD_MM),
        Act::Write(0x14, SLOW_MM_S),
        Act::Idle(1500),
        Act::Burst,
        Act::Command(Tool, 0),
        Act::Idle(1500),
        Act::Command(Tool, 1),
        Act::Command(Tool, 2),
        Act::Idle(1000),
        Act::Burst,
        Act::Command(Unload, 0),
        Act::Command(Eject, 1),
        Act::Insert(1),
        Act::Idle(1000),
        Act::Command(Load, 1),
        Act::Command(Tool, 1),
        Act::Command(Cut, 0),
        Act::Command(Home, 0),
        // A jammed slot: the tool change stalls, the user clears it and presses Retry.
        Act::Inject(Fault::Jam { slot: 0 }),
        Act::Failing(Tool, 0, 3000),
        Act::Clear(FaultKind::Jam(0)),
        Act::Idle(1000),
        Act::Write(0x11, 90),
        Act::Idle(1000),
    ]
}

fn main() -> Result<(), Box<dyn Error>> {
    let path = std::env::args()
        .nth(1)
        .ok_or("usage: mmu-bench-session OUT.bin")?;
    let mut recorder = Recorder::new();
    recorder.play(&script())?;
    if recorder.received.lost() > 0 {
        return Err(format!("{} received bytes lost to a full queue", recorder.received.lost()).into());
    }
    let mut file = b"MMUQ".to_vec();
    file.extend_from_slice(&recorder.steps.to_le_bytes());
    file.extend_from_slice(&recorder.out);
    file.extend_from_slice(&recorder.digest.to_le_bytes());
    std::fs::write(&path, &file)?;
    eprintln!(
        "session: {} steps ({} s of unit time), {} bytes, digest {:08x}",
        recorder.steps,
        recorder.now / 1000,
        file.len(),
        recorder.digest
    );
    Ok(())
}
