//! A firmware image on an emulated chip, as the simulator's unit: the binary a user flashes, in
//! the loop.
//!
//! A [`FirmwareUnit`] starts a bench (`fil/`: rp2040js for the Pico, Unicorn with register
//! models for the NUCLEO-G071RB and the BMCU-C's CH32V203) on the image and steps it in lockstep
//! with the physical model over the bench line protocol (`fil/PROTOCOL.md`): each millisecond
//! the model's sensor levels and the printer's bytes go in, the bridges' input pins and the
//! UART's bytes come out. The simulator speaks the protocol's version the bench's `ready` line
//! names: the second (each slot's motion and filament, then the hub's three sensors) unless the
//! line ends in `v3` (each lane's motion, filament and tension, then the hub's). Nothing
//! of the unit logic runs on the host: what the unit is doing ([`UnitLogic::command`]) is read
//! off its answers on the wire, as the printer reads it.

use std::fmt::Write as _;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::sync::{Arc, Mutex};

use mmu_firmware::profile::{self, Profile};
use mmu_firmware::runner::Status;
use mmu_firmware::{BoardAction, Config, Direction, Duty, Instant, MotorCommand};
use mmu_model::Model;
use mmu_protocol::{ButtonCode, ErrorCode, ParamCode, ProgressCode, RequestCode, ResponseDecoder};

use crate::flash::{
    BMCU_ERASE_STALL_US, BMCU_PROGRAM_STALL_US, FlashWear, G0_ERASE_STALL_US, G0_PROGRAM_STALL_US,
    MotionWatch,
};
use crate::logic::UnitLogic;

/// A board whose firmware image a bench can run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Board {
    /// The reference board, NUCLEO-G071RB: `python3 fil/g071/bench.py`.
    G071,
    /// The Raspberry Pi Pico: `node fil/pico/bench.mjs`.
    Pico,
    /// The BMCU-C kit's WCH CH32V203 (RISC-V): `python3 fil/bmcu/bench.py`.
    Bmcu,
}

impl Board {
    /// Every board.
    pub const ALL: [Board; 3] = [Board::G071, Board::Pico, Board::Bmcu];

    /// The name `cargo fw` / `cargo fw-pico` / `cargo fw-bmcu` and the bench use: `g071`,
    /// `pico` or `bmcu`.
    pub const fn name(self) -> &'static str {
        match self {
            Board::G071 => "g071",
            Board::Pico => "pico",
            Board::Bmcu => "bmcu",
        }
    }

    /// The board named `name`.
    pub fn from_name(name: &str) -> Option<Board> {
        Board::ALL.into_iter().find(|board| board.name() == name)
    }

    /// Bytes one flash program operation of the board writes (a G0 double word, an RP2040 page,
    /// a CH32V203 half-word).
    const fn program_bytes(self) -> u64 {
        match self {
            Board::G071 => 8,
            Board::Pico => 256,
            Board::Bmcu => 2,
        }
    }

    /// The longest the board's flash stalls its CPU for one erase and for one program, µs: the
    /// G071's page erase and double-word program, the Pico's W25Q16JV sector erase and page
    /// program (datasheet maxima: 400 ms, and 3 ms plus embassy-rp's driver with interrupts off),
    /// the CH32V203's 256-byte fast erase and half-word program (assumptions: none found).
    pub const fn stall_us(self) -> (u64, u64) {
        match self {
            Board::G071 => (G0_ERASE_STALL_US, G0_PROGRAM_STALL_US),
            Board::Pico => (400_000, 3_400),
            Board::Bmcu => (BMCU_ERASE_STALL_US, BMCU_PROGRAM_STALL_US),
        }
    }

    /// The command that runs this board's bench on `image`, from the benches in `fil_dir`.
    fn bench_command(self, fil_dir: &Path, image: &Path) -> Command {
        let mut command = match self {
            Board::G071 => {
                let mut c = Command::new("python3");
                c.arg(fil_dir.join("g071/bench.py"));
                c
            }
            Board::Pico => {
                let mut c = Command::new("node");
                c.arg(fil_dir.join("pico/bench.mjs"));
                c
            }
            Board::Bmcu => {
                let mut c = Command::new("python3");
                c.arg(fil_dir.join("bmcu/bench.py"));
                c
            }
        };
        command.arg(image);
        command
    }
}

/// Where the benches are: `fil/` of the source tree this crate was built from.
pub fn default_fil_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../fil")
}

/// The firmware image on its bench, stepped as the simulator's unit. See the
/// [module documentation](self).
pub struct FirmwareUnit {
    board: Board,
    child: Child,
    to_bench: ChildStdin,
    from_bench: BufReader<ChildStdout>,
    slots: usize,
    /// What senses each lane on the image's build, as its bench's `ready` line names it.
    profile: &'static Profile,
    /// The protocol's version the bench speaks: 2, or 3 when its `ready` line ends in `v3`.
    version: u8,
    config: Config,
    motors: Vec<MotorCommand>,
    wire: WireWatch,
    resets: u64,
    erases: u64,
    programs: u64,
    /// What the image's flash operations could do to the filament, at the board's longest
    /// stalls.
    motion: MotionWatch,
    /// Where the unit's flash wear goes when it is dropped ([`FirmwareUnit::report_wear`]).
    wear_sink: Option<Arc<Mutex<FlashWear>>>,
    failure: Option<String>,
    line: String,
}

impl FirmwareUnit {
    /// Start `board`'s bench (from `fil_dir`) on `image` and wait for it to be ready; what the
    /// bench logs goes to `log`. `config` is what the image was built with (the defaults, unless
    /// the build changed them), but for the distance per turn of the sensed shaft, which is the
    /// image's profile's (`Config::for_profile`, as the firmware's `main` takes it).
    pub fn start(
        board: Board,
        image: &Path,
        fil_dir: &Path,
        config: Config,
        log: Stdio,
    ) -> Result<FirmwareUnit, String> {
        let mut child = board
            .bench_command(fil_dir, image)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(log)
            .spawn()
            .map_err(|e| format!("cannot start the {} bench: {e}", board.name()))?;
        let (Some(to_bench), Some(from_bench)) = (child.stdin.take(), child.stdout.take()) else {
            return Err(String::from("the bench has no stdin or stdout"));
        };
        let mut unit = FirmwareUnit {
            board,
            child,
            to_bench,
            from_bench: BufReader::new(from_bench),
            slots: 0,
            profile: &profile::THESIS,
            version: 2,
            config,
            motors: Vec::new(),
            wire: WireWatch::default(),
            resets: 0,
            erases: 0,
            programs: 0,
            motion: MotionWatch::default(),
            wear_sink: None,
            failure: None,
            line: String::new(),
        };
        let ready = unit.read_line()?;
        let words: Vec<&str> = ready.split_whitespace().collect();
        let (slots, hardware, version) = match words[..] {
            ["ready", name, slots, hardware] if name == board.name() => (slots, hardware, 2),
            ["ready", name, slots, hardware, "v3"] if name == board.name() => (slots, hardware, 3),
            _ => return Err(format!("the {} bench says {ready:?}, not `ready`", board.name())),
        };
        unit.slots = slots.parse().map_err(|_| format!("bench says {ready:?}"))?;
        unit.profile = profile::by_name(hardware)
            .ok_or_else(|| format!("the {} bench names no known profile: {ready:?}", board.name()))?;
        unit.version = version;
        unit.config.mm_per_rev_centi = unit.profile.mm_per_rev_centi;
        unit.motors = vec![MotorCommand::Coast; unit.slots];
        Ok(unit)
    }

    /// Add this unit's flash wear to `sink` when it is dropped (at the end of a scenario).
    pub fn report_wear(&mut self, sink: Arc<Mutex<FlashWear>>) {
        self.wear_sink = Some(sink);
    }

    /// Slots of the board the image runs on.
    pub fn slots(&self) -> usize {
        self.slots
    }

    /// What senses each lane on the image's build (the simulated unit's sensors must read as it
    /// says: [`crate::SimOptions::on_hardware`]).
    pub fn profile(&self) -> &'static Profile {
        self.profile
    }

    /// Chip resets since the bench started (watchdog, reset requests, power-ons).
    pub fn resets(&self) -> u64 {
        self.resets
    }

    fn read_line(&mut self) -> Result<String, String> {
        self.line.clear();
        match self.from_bench.read_line(&mut self.line) {
            Ok(0) => Err(format!("the {} bench exited", self.board.name())),
            Ok(_) if self.line.starts_with("error") => {
                Err(format!("the {} bench: {}", self.board.name(), self.line.trim()))
            }
            Ok(_) => Ok(self.line.trim_end().to_owned()),
            Err(e) => Err(format!("reading the {} bench: {e}", self.board.name())),
        }
    }

    /// Send one request and read its answer; the first failure stops the unit for good.
    fn request(&mut self, request: &str) -> Option<String> {
        if self.failure.is_some() {
            return None;
        }
        let answer = writeln!(self.to_bench, "{request}")
            .and_then(|()| self.to_bench.flush())
            .map_err(|e| format!("writing to the {} bench: {e}", self.board.name()))
            .and_then(|()| self.read_line());
        match answer {
            Ok(answer) => Some(answer),
            Err(why) => {
                self.failure = Some(why);
                None
            }
        }
    }

    /// Carry out one `ok` answer to a `step`; the error says what was wrong with it.
    fn take_step_answer(&mut self, answer: &str, tx: &mut Vec<u8>) -> Result<(), String> {
        let fields: Vec<&str> = answer.split_whitespace().collect();
        let [ok, rest @ ..] = &fields[..] else {
            return Err(String::from("an empty answer"));
        };
        if *ok != "ok" || rest.len() != self.slots + 4 {
            return Err(format!("{answer:?} is not a step answer"));
        }
        let (motors, counts) = rest.split_at(self.slots);
        for (slot, pins) in motors.iter().enumerate() {
            self.motors[slot] = bridge_command(pins).ok_or_else(|| format!("bad bridge inputs {pins:?}"))?;
        }
        let sent = from_hex(counts[0]).ok_or_else(|| format!("bad tx {:?}", counts[0]))?;
        let number = |text: &str| text.parse::<u64>().map_err(|_| format!("bad count {text:?}"));
        let resets = number(counts[1])?;
        if resets != self.resets {
            self.wire = WireWatch::default();
        }
        self.resets = resets;
        let erases = number(counts[2])?;
        let programs = number(counts[3])?;
        // The image writes its flash after a step, with the motors as that step left them.
        self.motion.step(
            &self.motors,
            (
                erases.saturating_sub(self.erases),
                programs.saturating_sub(self.programs),
            ),
            self.board.stall_us(),
            self.config.full_duty_speed,
        );
        (self.erases, self.programs) = (erases, programs);
        self.wire.watch(&sent);
        tx.extend_from_slice(&sent);
        Ok(())
    }
}

impl Drop for FirmwareUnit {
    /// `quit`, and a bench that has not ended a second later is killed.
    fn drop(&mut self) {
        if let Some(sink) = self.wear_sink.take()
            && let Ok(mut total) = sink.lock()
        {
            *total = total.combined(self.flash_wear());
        }
        let _ = writeln!(self.to_bench, "quit").and_then(|()| self.to_bench.flush());
        for _ in 0..100 {
            if !matches!(self.child.try_wait(), Ok(None)) {
                return;
            }
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl UnitLogic for FirmwareUnit {
    fn step(
        &mut self,
        _now: Instant,
        dt_ms: u32,
        model: &mut Model,
        rx: &[u8],
        tx: &mut Vec<u8>,
    ) -> Option<BoardAction> {
        let mut request = format!("step {}", dt_ms * 1000);
        for level in sensor_levels(model, self.slots, self.version) {
            let _ = write!(request, " {level}");
        }
        let _ = write!(request, " {}", to_hex(rx));
        if let Some(answer) = self.request(&request)
            && let Err(why) = self.take_step_answer(&answer, tx)
        {
            self.failure = Some(format!("the {} bench: {why}", self.board.name()));
        }
        if self.failure.is_some() {
            self.motors.fill(MotorCommand::Coast);
        }
        model.step(dt_ms, &self.motors);
        // The image resets itself (`X42`, its watchdog): no action is left to the simulator.
        None
    }

    fn command(&self) -> ((RequestCode, u8), Status) {
        self.wire.command
    }

    fn press_button(&mut self, _button: ButtonCode) {
        // The bench protocol has no button yet: see `fil/PROTOCOL.md`.
        self.failure
            .get_or_insert_with(|| String::from("the firmware bench cannot press the unit's buttons"));
    }

    fn config(&self) -> &Config {
        &self.config
    }

    fn power_off(&mut self) {
        self.request("power off");
        self.motors.fill(MotorCommand::Coast);
    }

    fn power_on(&mut self, _config: &Config) {
        self.request("power on");
        self.wire = WireWatch::default();
    }

    fn hang(&mut self) {
        self.request("hang");
    }

    fn failure(&self) -> Option<String> {
        self.failure.clone()
    }

    fn flash_wear(&mut self) -> FlashWear {
        // The bench counts operations, not pages: every erase counts against the most worn page.
        self.motion.wear(FlashWear {
            bytes_written: self.programs * self.board.program_bytes(),
            erases: self.erases,
            max_page_erases: self.erases,
            ..FlashWear::default()
        })
    }

    fn motors(&self) -> Vec<MotorCommand> {
        self.motors.clone()
    }
}

/// The sensor values of a step in the protocol's order (`mmu_hal_port::Samples`): each slot's
/// motion sample and filament sensor (version 2), or each lane's motion, filament and tension
/// (version 3), then the hub's filament, tension and cutter sensor. A lane's motion sample is
/// what its profile's sensor reads: a Hall level, an encoder count, an angle (or its fault).
fn sensor_levels(model: &mut Model, slots: usize, version: u8) -> Vec<u16> {
    let mut levels = Vec::with_capacity(3 * slots + 3);
    for slot in 0..slots {
        let s = model.sample_slot(slot).unwrap_or_default();
        levels.extend([s.motion, s.filament]);
        if version >= 3 {
            levels.push(s.tension);
        }
    }
    let hub = model.sample_hub();
    levels.extend([hub.filament, hub.tension, hub.cutter]);
    levels
}

/// A TB6612FNG bridge's inputs `<STBY><IN1><IN2>:<duty per mille>` as the command they carry
/// out, by the datasheet's truth table (see `mmu_hal_port::tb6612`): standby or IN1 = IN2 = L
/// leaves the outputs open, IN1 = IN2 = H short-brakes, and a driven direction with the PWM
/// input low short-brakes too. The BMCU-C's AT8236 reports in the same form (STBY 1, the driven
/// input and its duty, both inputs full for its brake: fil/PROTOCOL.md), and the model takes a
/// drive at a duty alike whether the PWM's off-time brakes (TB6612) or coasts (AT8236).
fn bridge_command(pins: &str) -> Option<MotorCommand> {
    let (levels, duty) = pins.split_once(':')?;
    let duty: u16 = duty.parse().ok().filter(|&d| d <= 1000)?;
    let level = |i: usize| match levels.as_bytes().get(i) {
        Some(b'0') => Some(false),
        Some(b'1') => Some(true),
        _ => None,
    };
    if levels.len() != 3 {
        return None;
    }
    let (standby_off, in1, in2) = (level(0)?, level(1)?, level(2)?);
    Some(match (standby_off, in1, in2) {
        (false, _, _) | (true, false, false) => MotorCommand::Coast,
        (true, true, true) => MotorCommand::Brake,
        _ if duty == 0 => MotorCommand::Brake,
        (true, in1, _) => MotorCommand::Drive {
            direction: if in1 {
                Direction::Forward
            } else {
                Direction::Reverse
            },
            duty: Duty::from_permille(duty),
        },
    })
}

/// What the unit says it is doing, read off its answers the way the printer reads them: the
/// command it last accepted, and the progress, error or finish its `Q0` answers report.
#[derive(Debug, Clone)]
struct WireWatch {
    decoder: ResponseDecoder,
    command: ((RequestCode, u8), Status),
}

impl Default for WireWatch {
    /// A unit just booted: its reset "command" finished, as the host logic reports it.
    fn default() -> Self {
        WireWatch {
            decoder: ResponseDecoder::new(),
            command: ((RequestCode::Reset, 0), Status::Finished),
        }
    }
}

impl WireWatch {
    fn watch(&mut self, bytes: &[u8]) {
        for &byte in bytes {
            let Some(Ok(answer)) = self.decoder.feed(byte) else {
                continue;
            };
            let request = (answer.code, answer.value);
            let value = answer.param_value.unwrap_or(0);
            self.command = match answer.param {
                ParamCode::Accepted if answer.code.is_command() => {
                    (request, Status::Running(ProgressCode::OK))
                }
                ParamCode::Processing => (request, Status::Running(ProgressCode(value as u8))),
                ParamCode::Error => (request, Status::Failed(ErrorCode(value))),
                ParamCode::Finished => (request, Status::Finished),
                _ => continue,
            };
        }
    }
}

fn to_hex(bytes: &[u8]) -> String {
    if bytes.is_empty() {
        return String::from("-");
    }
    bytes
        .iter()
        .fold(String::with_capacity(2 * bytes.len()), |mut out, b| {
            let _ = write!(out, "{b:02x}");
            out
        })
}

fn from_hex(text: &str) -> Option<Vec<u8>> {
    if text == "-" {
        return Some(Vec::new());
    }
    if !text.len().is_multiple_of(2) {
        return None;
    }
    (0..text.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(text.get(i..i + 2)?, 16).ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bridge_inputs_read_as_the_tb6612_truth_table() {
        let forward = |d| MotorCommand::forward(Duty::from_permille(d));
        assert_eq!(bridge_command("110:750"), Some(forward(750)));
        assert_eq!(
            bridge_command("101:1000"),
            Some(MotorCommand::Drive {
                direction: Direction::Reverse,
                duty: Duty::MAX
            })
        );
        assert_eq!(bridge_command("111:1000"), Some(MotorCommand::Brake));
        assert_eq!(bridge_command("110:0"), Some(MotorCommand::Brake));
        assert_eq!(bridge_command("100:500"), Some(MotorCommand::Coast));
        assert_eq!(bridge_command("011:1000"), Some(MotorCommand::Coast), "standby");
        for bad in ["11:5", "1101:5", "110", "110:1001", "1x0:5", "110:-1"] {
            assert_eq!(bridge_command(bad), None, "{bad}");
        }
    }

    #[test]
    fn version_3_steps_carry_each_lanes_tension_and_version_2_does_not() {
        let model = || Model::new(mmu_model::ModelConfig::default(), 4, 1);
        let v2 = sensor_levels(&mut model(), 3, 2);
        let v3 = sensor_levels(&mut model(), 4, 3);
        assert_eq!((v2.len(), v3.len()), (2 * 3 + 3, 3 * 4 + 3));
        // The same model sampled in the same order (its sensors' noise is seeded).
        let mut same = model();
        for slot in 0..4 {
            let s = same.sample_slot(slot).expect("a slot");
            assert_eq!(&v3[3 * slot..3 * slot + 3], &[s.motion, s.filament, s.tension]);
        }
        let hub = same.sample_hub();
        assert_eq!(&v3[12..], &[hub.filament, hub.tension, hub.cutter]);
    }

    #[test]
    fn hex_goes_both_ways_and_refuses_what_is_not_hex() {
        assert_eq!(to_hex(b"S0*c6\n"), "53302a63360a");
        assert_eq!(from_hex("53302a63360a").as_deref(), Some(&b"S0*c6\n"[..]));
        assert_eq!(from_hex("-"), Some(Vec::new()));
        assert_eq!(to_hex(&[]), "-");
        for bad in ["5", "zz", "5é"] {
            assert_eq!(from_hex(bad), None, "{bad}");
        }
    }

    #[test]
    fn the_wire_tells_what_the_unit_is_doing() {
        let mut wire = WireWatch::default();
        let tool = |param, value| mmu_protocol::Response::with_value(RequestCode::Tool, 1, param, value);
        let answer = |response: mmu_protocol::Response| response.encode().as_bytes().to_vec();
        assert_eq!(wire.command, ((RequestCode::Reset, 0), Status::Finished));
        wire.watch(&answer(mmu_protocol::Response::bare(
            RequestCode::Tool,
            1,
            ParamCode::Accepted,
        )));
        assert_eq!(
            wire.command,
            ((RequestCode::Tool, 1), Status::Running(ProgressCode::OK))
        );
        wire.watch(&answer(tool(ParamCode::Processing, 0x1c)));
        assert_eq!(wire.command.1, Status::Running(ProgressCode(0x1c)));
        wire.watch(&answer(tool(ParamCode::Error, 0x8008)));
        assert_eq!(wire.command.1, Status::Failed(ErrorCode(0x8008)));
        // Register reads and the version answers say nothing of the command.
        wire.watch(&answer(mmu_protocol::Response::with_value(
            RequestCode::Read,
            8,
            ParamCode::Accepted,
            1,
        )));
        assert_eq!(wire.command.1, Status::Failed(ErrorCode(0x8008)));
        wire.watch(&answer(tool(ParamCode::Finished, 0)));
        assert_eq!(wire.command, ((RequestCode::Tool, 1), Status::Finished));
    }
}
