//! A test rig: the App stepped against the physical model in virtual time, with the printer's
//! side played the way Prusa's firmware plays it (filament sensor reports, co-feeding on `P1c`).

#![allow(dead_code)] // each test file uses a different part of the rig

pub mod bounds;
mod scenarios;

use mmu_firmware::persist::Snapshot;
use mmu_firmware::unit::Lane;
use mmu_firmware::{App, Config, Direction, Instant, MotorCommand};
use mmu_model::{Fault, Model, ModelConfig};
use mmu_protocol::{
    ButtonCode, ErrorCode, ParamCode, ProgressCode, Request, RequestCode, Response, ResponseDecoder,
    ResultCode,
};

/// A unit connected to a printer wanting 3.0.`revision`, slot 0 loaded into the nozzle.
pub fn loaded(revision: u8, model: ModelConfig) -> Rig<3> {
    let mut rig = Rig::<3>::with(Config::default(), model);
    rig.wants_revision = revision;
    rig.boot();
    let run = rig.command(t(0));
    assert_eq!(run.last, finished(t(0)), "{run:?}");
    // The printer loads the filament on into its nozzle.
    let to_nozzle = rig.model.config().nozzle_mm - rig.model.tip_mm(0).unwrap();
    rig.model.extruder_move(to_nozzle, 20.0);
    rig.idle(to_nozzle as u64 * 50 + 1000);
    assert_eq!(rig.model.fsensor_state(), 2, "slot 0 is in the nozzle");
    rig
}

/// One step of the rig, ms.
pub const STEP_MS: u64 = 1;
/// The printer's heartbeat while a command runs, ms.
pub const POLL_MS: u64 = 100;

/// Where a parked tip rests, mm from the hub sensor.
pub const PARK_MM: f32 = -15.0;

/// `T<slot>`.
pub fn t(slot: u8) -> Request {
    Request::new(RequestCode::Tool, slot)
}

/// The `Q0` answer of `request` finished without error.
pub fn finished(request: Request) -> Response {
    Response::finished(request.code, request.value, ResultCode::OK)
}

/// The `Q0` answer of `request` stopped on `code`.
pub fn error(request: Request, code: ErrorCode) -> Response {
    Response::error(request.code, request.value, code)
}

/// What `Q0` reports while a slot is fed into the printer (`LoadToNozzle`).
pub const LOAD_PROGRESS: [ProgressCode; 4] = [
    ProgressCode::FEEDING_TO_FINDA,
    ProgressCode::FEEDING_TO_BONDTECH,
    ProgressCode::FEEDING_TO_FSENSOR,
    ProgressCode::FEEDING_TO_NOZZLE,
];

/// What `Q0` reports while the loaded slot comes out and is parked (`UnloadFromNozzle`).
pub const UNLOAD_PROGRESS: [ProgressCode; 2] = [
    ProgressCode::UNLOADING_TO_FINDA,
    ProgressCode::RETRACTING_FROM_FINDA,
];

/// What `Q0` reports while a slot is fed to the hub and parked again (preload, re-park).
pub const PARK_PROGRESS: [ProgressCode; 2] = [
    ProgressCode::FEEDING_TO_FINDA,
    ProgressCode::RETRACTING_FROM_FINDA,
];

/// The hub sensor's "off" threshold register: slot *n*'s sensor is at `HUB_OFF_REGISTER + 1 + n`.
pub const HUB_OFF_REGISTER: u8 = 0xa0;

/// An "off" threshold no reading goes below: the sensor seems to hold filament forever.
pub const OFF_THRESHOLD_NEVER: u16 = 50;

/// The default "off" threshold.
pub const OFF_THRESHOLD_DEFAULT: u16 = 2400;

/// Slot `slot`'s tip rests near the park position.
pub fn assert_parked<const N: usize>(rig: &Rig<N>, slot: usize) {
    let tip = rig.model.tip_mm(slot).unwrap();
    assert!(
        (tip - PARK_MM).abs() <= 5.0,
        "slot {slot} should rest near the park position, tip at {tip} mm"
    );
}

/// The printer (or the user) presses `button`; the unit accepts it.
pub fn press<const N: usize>(rig: &mut Rig<N>, button: ButtonCode) {
    let answer = rig.send(Request::new(RequestCode::Button, button.0));
    assert_eq!(answer.map(|a| a.param), Some(ParamCode::Accepted), "{button:?}");
}

/// How the printer reports its filament sensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FsensorReports {
    /// As the model's sensor reads, at once (the printer's `CheckAndReportAsyncEvents`).
    Truthful,
    /// Always this state (a broken or misplaced printer sensor).
    Stuck(u8),
}

/// Which printer firmware plays the printer's side of the load (they co-feed differently;
/// printer-truth §8, Prusa-Firmware-Buddy `mmu2_mk4.cpp` and Prusa-Firmware `Firmware/mmu2.cpp`
/// `OnMMUProgressMsgSame`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PrinterKind {
    /// MK4, MK3.9, Core One (Buddy): co-feeds 189.9 mm moves, then pushes the extra load + 2 mm.
    Mk4,
    /// MK3.5 (Buddy): its sensor reports 0.175 mm per mm/s of the slow feed late (3.5 mm at
    /// 20 mm/s), so it pushes that much less after it triggers.
    Mk35,
    /// MK3S (Prusa-Firmware 3.14): co-feeds 350 mm moves, then pushes the extra load + 2 mm.
    Mk3s,
}

/// What a command run looked like from the printer's side.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Run {
    /// Every distinct progress code reported by `Q0`, in order.
    pub progress: Vec<ProgressCode>,
    /// The `Q0` answer that ended the run (`F` or `E`).
    pub last: Response,
}

pub struct Rig<const N: usize> {
    pub app: App<N>,
    pub model: Model,
    pub now: u64,
    pub fsensor: FsensorReports,
    decoder: ResponseDecoder,
    reported_fsensor: u8,
    /// Every motor command the App gave, per step.
    pub motor_log: Vec<[MotorCommand; N]>,
    /// Per step: the App said a phase began in it (`Outputs::phase_began`).
    pub phase_began_log: Vec<bool>,
    /// The printer's firmware.
    pub printer: PrinterKind,
    /// The progress the printer last saw (`None` between runs and after an error: the printer's
    /// `ERRWaitingForUser`).
    seen_progress: Option<ProgressCode>,
    /// The printer's `loadFilamentStarted`: set when it sees `P1c` begin, cleared by its push.
    load_started: bool,
    /// The model's sensor state and since when (for a printer whose sensor reports late).
    sensed: (u8, u64),
    /// The command the printer is following (`Q0` echoes it).
    following: Option<RequestCode>,
    /// The MMU revision the printer's firmware requires (`S2`): 4 for Buddy >= 6.5.3, 3 (the
    /// rig's default) for Buddy 6.4 and MK3S 3.14.1, 2 for MK3S 3.13.3/3.14.0.
    pub wants_revision: u8,
}

impl<const N: usize> Rig<N> {
    pub fn new() -> Self {
        Self::with(Config::default(), ModelConfig::default())
    }

    pub fn with(config: Config, model: ModelConfig) -> Self {
        Rig {
            app: App::new(config),
            model: Model::new(model, N, 7),
            now: 0,
            fsensor: FsensorReports::Truthful,
            decoder: ResponseDecoder::new(),
            reported_fsensor: 0,
            motor_log: Vec::new(),
            phase_began_log: Vec::new(),
            printer: PrinterKind::Mk4,
            seen_progress: None,
            load_started: false,
            sensed: (0, 0),
            wants_revision: 3,
            following: None,
        }
    }

    /// One step: sample the model, step the App with `rx`, apply its motors to the model.
    /// Returns the responses the unit sent in this step.
    pub fn step_with(&mut self, rx: &[u8]) -> Vec<Response> {
        let samples = self.model.samples::<N>();
        let out = self.app.step(Instant::from_millis(self.now), &samples, rx);
        self.model.step(STEP_MS as u32, &out.motors);
        self.motor_log.push(out.motors);
        self.phase_began_log.push(out.phase_began);
        self.now += STEP_MS;
        let mut responses = Vec::new();
        for &byte in out.tx.iter() {
            match self.decoder.feed(byte) {
                Some(Ok(response)) => responses.push(response),
                Some(Err(error)) => panic!("the unit sent a bad frame: {error}"),
                None => {}
            }
        }
        responses
    }

    pub fn idle(&mut self, ms: u64) {
        for _ in 0..ms / STEP_MS {
            self.step_with(&[]);
        }
    }

    /// Send one request; its answer comes in the same step (or nothing, for `X` and bad frames).
    pub fn send(&mut self, request: Request) -> Option<Response> {
        self.send_bytes(request.encode().as_bytes())
    }

    pub fn send_bytes(&mut self, bytes: &[u8]) -> Option<Response> {
        let mut responses = self.step_with(bytes);
        assert!(responses.len() <= 1, "one request, one answer: {responses:?}");
        responses.pop()
    }

    pub fn query(&mut self) -> Response {
        self.send(Request::new(RequestCode::Query, 0))
            .expect("Q0 is always answered")
    }

    /// Let the unit finish its start-up check, then play the printer's handshake; returns the
    /// first `Q0` answer.
    pub fn boot(&mut self) -> Response {
        self.idle(200);
        let first = self.query();
        self.handshake();
        first
    }

    /// The printer's handshake: versions (as Prusa's printer checks them, wanting
    /// [`Rig::wants_revision`]), the two register writes, the filament sensor.
    pub fn handshake(&mut self) -> Vec<Response> {
        let mut answers = Vec::new();
        let wrong = self.negotiate(self.wants_revision);
        assert!(
            wrong.is_ok(),
            "the printer wanting 3.0.{} gave up",
            self.wants_revision
        );
        answers.extend(self.send(Request::new(RequestCode::Version, 3)));
        answers.extend(self.send(Request::write(0x0b, 5)));
        answers.extend(self.send(Request::write(0x14, 20)));
        answers.extend(self.send(Request::new(
            RequestCode::FilamentSensor,
            self.model.fsensor_state(),
        )));
        answers
    }

    /// The version check of Prusa's printer for 3.0.`revision` (`protocol_logic.cpp`
    /// `StartSeqRestart`, `ProcessVersionResponse`): `S0`, `S1`, `S2`, each asked again at once
    /// after a wrong answer, six wrong answers and it gives up. The wrong answers it got, or
    /// `Err` with them when it gave up. `S3` is left to the caller.
    pub fn negotiate(&mut self, revision: u8) -> Result<Vec<u16>, Vec<u16>> {
        let expected = [3, 0, u16::from(revision)];
        let mut wrong = Vec::new();
        let mut stage = 0;
        while stage < expected.len() {
            let answer = self.send(Request::new(RequestCode::Version, stage as u8));
            let value = answer.and_then(|a| a.param_value);
            if value == Some(expected[stage]) {
                stage += 1;
                continue;
            }
            wrong.push(value.unwrap_or(u16::MAX));
            if wrong.len() == 6 {
                return Err(wrong);
            }
        }
        Ok(wrong)
    }

    /// The slow feed the printer co-feeds and pushes at (register 0x14, as it wrote it).
    fn printer_slow_mm_s(&self) -> f32 {
        f32::from(self.app.config().slow_speed)
    }

    fn printer_fsensor(&mut self) -> u8 {
        match self.fsensor {
            FsensorReports::Truthful => {
                let state = self.model.fsensor_state();
                if state != self.sensed.0 {
                    self.sensed = (state, self.now);
                }
                let lag_ms = match self.printer {
                    // 0.175 mm per mm/s of feed, at that feed: 175 ms whatever the speed.
                    PrinterKind::Mk35 => 175,
                    PrinterKind::Mk4 | PrinterKind::Mk3s => 0,
                };
                if self.now - self.sensed.1 >= lag_ms {
                    state
                } else {
                    self.reported_fsensor
                }
            }
            FsensorReports::Stuck(state) => state,
        }
    }

    /// Issue a command and play the printer until it finishes or fails: `Q0` every
    /// [`POLL_MS`], filament sensor changes reported at once, co-feeding during `P1c`.
    pub fn command(&mut self, request: Request) -> Run {
        self.issue(request);
        self.follow(request, 600_000)
    }

    /// Send a command as the printer does (its own unload when the command unloads) and check
    /// that it is accepted; nothing more is played. A printer that wants MMU 3.0.4 (Buddy
    /// 6.5.3) sends `T` first and retracts while the unit waits (`ccb208bf5af1`); an older one
    /// pulls the filament out of its gears before it sends the command.
    pub fn issue(&mut self, request: Request) {
        let same_tool =
            request.code == RequestCode::Tool && self.model.loaded_slot() == Some(request.value.into());
        let unloads = matches!(
            request.code,
            RequestCode::Unload | RequestCode::Tool | RequestCode::Eject | RequestCode::Cut
        ) && !same_tool;
        let retract_after = unloads && self.wants_revision >= 4 && request.code == RequestCode::Tool;
        if unloads && !retract_after {
            self.unload_extruder();
        }
        let answer = self.send(request).expect("a command is answered");
        assert_eq!(
            answer.param,
            ParamCode::Accepted,
            "{request:?} was not accepted: {answer:?}"
        );
        if retract_after && self.model.fsensor_state() != 0 {
            // Buddy 6.5.3's finishing retract: 80 mm at its slow feed (`2178f416c2eb`).
            let slow = self.printer_slow_mm_s();
            self.model.extruder_move(-80.0, slow);
        }
    }

    /// What a printer that wants MMU 3.0.3 or older does before it asks for an unload or another
    /// tool (and Buddy 6.5.3 before `U0`, `E`, `K`): ram and pull the filament out of its
    /// extruder gears.
    pub fn unload_extruder(&mut self) {
        if self.model.fsensor_state() == 0 {
            return;
        }
        self.model.extruder_move(-40.0, 40.0);
        while self.model.extruder_busy() {
            self.printer_step(None);
        }
    }

    /// Keep playing the printer for the command in progress.
    pub fn follow(&mut self, request: Request, timeout_ms: u64) -> Run {
        self.follow_until(request, None, timeout_ms)
    }

    /// Keep playing the printer for the command in progress until `Q0` reports `until` (then the
    /// run's `last` is that `P` answer) or the command ends.
    pub fn follow_until(&mut self, request: Request, until: Option<ProgressCode>, timeout_ms: u64) -> Run {
        self.following = Some(request.code);
        let mut progress: Vec<ProgressCode> = Vec::new();
        let start = self.now;
        loop {
            assert!(
                self.now - start < timeout_ms,
                "{request:?} did not end; progress {progress:?}"
            );
            for _ in 0..POLL_MS / STEP_MS {
                self.printer_step(progress.last().copied());
            }
            let answer = self.query();
            assert_eq!(
                (answer.code, answer.value),
                (request.code, request.value),
                "Q0 echoes the command"
            );
            match answer.param {
                ParamCode::Processing => {
                    let code = ProgressCode(answer.param_value.unwrap_or(0) as u8);
                    if progress.last() != Some(&code) {
                        progress.push(code);
                    }
                    if until == Some(code) {
                        return Run {
                            progress,
                            last: answer,
                        };
                    }
                }
                ParamCode::Finished | ParamCode::Error => {
                    return Run {
                        progress,
                        last: answer,
                    };
                }
                other => panic!("unexpected Q0 answer {other:?}"),
            }
        }
    }

    /// One step of the printer's side: report the sensor when it changed, co-feed on `P1c`, help
    /// an unload on `P3`. As Prusa's printers do (`OnMMUProgressMsgChanged`/
    /// `OnMMUProgressMsgSame`): `P1c` newly seen starts the load; while it lasts, with its sensor
    /// clear the printer co-feeds, with it triggered it aborts that and pushes the extra load
    /// distance + 2 mm once (less on an MK3.5); with it unavailable (`f3`) it does nothing.
    /// `P3` of a command other than `U`/`T` (an unload the printer did not prepare itself) makes
    /// it retract 20 mm at 20 mm/s whenever its extruder is idle and its sensor reads filament
    /// (`HelpUnloadToFinda`).
    pub fn printer_step(&mut self, progress: Option<ProgressCode>) {
        if progress != self.seen_progress {
            self.seen_progress = progress;
            self.load_started |= progress == Some(ProgressCode::FEEDING_TO_FSENSOR);
        }
        let state = self.printer_fsensor();
        if state != self.reported_fsensor {
            let answer = self.send(Request::new(RequestCode::FilamentSensor, state));
            assert_eq!(answer.map(|a| a.param), Some(ParamCode::Accepted));
            self.reported_fsensor = state;
            return;
        }
        let prepared_itself = matches!(self.following, Some(RequestCode::Unload | RequestCode::Tool));
        if progress == Some(ProgressCode::UNLOADING_TO_FINDA)
            && !prepared_itself
            && state != 0
            && !self.model.extruder_busy()
        {
            self.help_unload();
        }
        if self.load_started && progress == Some(ProgressCode::FEEDING_TO_FSENSOR) {
            let slow = self.printer_slow_mm_s();
            match state {
                1 | 2 => {
                    let compensation = match self.printer {
                        PrinterKind::Mk35 => 0.175 * slow,
                        PrinterKind::Mk4 | PrinterKind::Mk3s => 0.0,
                    };
                    let extra = f32::from(self.app.config().extra_load_mm) + 2.0 - compensation;
                    self.model.extruder_move(extra, slow);
                    self.load_started = false;
                }
                0 if !self.model.extruder_busy() => {
                    let search = match self.printer {
                        PrinterKind::Mk3s => 350.0,
                        PrinterKind::Mk4 | PrinterKind::Mk35 => 189.9,
                    };
                    self.model.extruder_move(search, slow);
                }
                _ => {}
            }
        }
        self.step_with(&[]);
    }

    /// The printer's help with an unload: 20 mm back at 20 mm/s (Buddy `mmu2_config.h`
    /// `MMU2_RETRY_UNLOAD_TO_FINDA_LENGTH`, `_FEED_RATE`); also what it does on the Retry of
    /// `8004` and `8009` (`CheckUserInput`).
    pub fn help_unload(&mut self) {
        self.model.extruder_move(-20.0, 20.0);
    }

    /// Play the printer for the command in progress until `until` holds for the model (checked
    /// every millisecond); `Q0` every [`POLL_MS`] as in [`Rig::follow`]. Panics if the command
    /// ends first.
    pub fn follow_until_model(&mut self, request: Request, until: impl Fn(&Model) -> bool, timeout_ms: u64) {
        self.following = Some(request.code);
        let mut progress: Vec<ProgressCode> = Vec::new();
        let start = self.now;
        while !until(&self.model) {
            assert!(
                self.now - start < timeout_ms,
                "{request:?}: never got there; {progress:?}"
            );
            for _ in 0..POLL_MS / STEP_MS {
                self.printer_step(progress.last().copied());
                if until(&self.model) {
                    return;
                }
            }
            let answer = self.query();
            match answer.param {
                ParamCode::Processing => {
                    let code = ProgressCode(answer.param_value.unwrap_or(0) as u8);
                    if progress.last() != Some(&code) {
                        progress.push(code);
                    }
                }
                other => panic!("{request:?} ended before: {other:?} {answer:?}"),
            }
        }
    }

    pub fn inject(&mut self, fault: Fault) {
        assert!(self.model.inject(fault));
    }

    /// The hardest reverse duty slot `slot`'s motor got in the steps from `from` on, per mille
    /// (0: none).
    pub fn hardest_pull_since(&self, slot: usize, from: usize) -> u16 {
        self.motor_log[from..]
            .iter()
            .filter_map(|motors| match motors.get(slot) {
                Some(&MotorCommand::Drive {
                    direction: Direction::Reverse,
                    duty,
                }) => Some(duty.permille()),
                _ => None,
            })
            .max()
            .unwrap_or(0)
    }

    /// The unit restarted with `lanes` stored (everything else a fresh store's), on the model as
    /// it is: its start-up check, then the printer's handshake.
    pub fn restart_with(&mut self, lanes: [Lane; N]) {
        self.app = App::new(Config::default());
        self.app.restore(&Snapshot {
            lanes,
            ..Snapshot::default()
        });
        self.boot();
    }

    /// True when no motor was driven in the last `steps` steps.
    pub fn motors_stopped(&self) -> bool {
        self.motor_log
            .last()
            .is_some_and(|motors| motors.iter().all(|m| !m.is_driving()))
    }
}
