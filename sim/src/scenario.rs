//! Prusa's own expected exchange with an MMU on Buddy 6.5.3, as a script to replay against the
//! simulated unit.
//!
//! Prusa-Firmware-Buddy's unit test `tests/unit/lib/Marlin/MMU2/mmu2-printer_test.cpp` (tag
//! `v6.5.3`, `SimulateCommStart` and the test case "MMU2 toolchange") fixes what the printer
//! sends and what it expects back. Told in our own words:
//!
//! 1. Start-up: `S0` answered 3, `S1` 0, `S2` 4 (the printer's `mmuVersionPatch`), `S3` any
//!    build, then the writes `Wb` and `W14`, then `f0`; then `Q0` answered `X0 F0` and the poll
//!    `R8 R1b R1c R4 R1a R22` (FINDA 0, slots 5, errors 0, pulley 0, Bowden length 360).
//! 2. `T0` accepted; every 100 ms `Q0`, `f<sensor>` and the poll. The unit reports, in this
//!    order, `P1` (engaging the idler), `P5` (to FINDA), `P6` (through the Bowden tube),
//!    `P1c` (to the printer's sensor). During `P1c` the printer's sensor triggers; the printer
//!    leaves the tool change at the next answer, `P7` (to the nozzle): its premature finish.
//!    It keeps polling: `P2` (disengaging), then `T0 F0`, which it only logs.
//!
//! [`ToolChangeScript`] holds that order; [`replay_tool_change`] plays the printer's side of it
//! against a [`Sim`] in 100 ms polls (the printer's sensor is the model's, as Buddy 6.5.3's
//! mechanics move it) and reports what the unit answered and where it left Prusa's script. A
//! unit without an idler may skip `P1` and `P2`; every other step must come, in order.

use mmu_protocol::{ParamCode, ProgressCode, Request, RequestCode, Response, ResponseDecoder};

use crate::sim::Sim;

/// The progress a Buddy 6.5.3 printer expects in a tool change from nothing loaded, in order,
/// and whether a unit may leave it out.
pub const TOOL_CHANGE_PROGRESS: [(ProgressCode, bool); 6] = [
    (ProgressCode::ENGAGING_IDLER, true),
    (ProgressCode::FEEDING_TO_FINDA, false),
    (ProgressCode::FEEDING_TO_BONDTECH, false),
    (ProgressCode::FEEDING_TO_FSENSOR, false),
    (ProgressCode::FEEDING_TO_NOZZLE, false),
    (ProgressCode::DISENGAGING_IDLER, true),
];

/// The start-up answers Prusa's test expects: `S0` 3, `S1` 0, `S2` 4.
pub const HANDSHAKE_VERSION: [(u8, u16); 3] = [(0, 3), (1, 0), (2, 4)];

/// The register poll of Buddy 6.5.3, in order.
pub const POLL: [u8; 6] = [0x08, 0x1b, 0x1c, 0x04, 0x1a, 0x22];

/// What a replay saw.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ToolChangeScript {
    /// Every request with the unit's answer, and the virtual time of the answer, ms.
    pub exchanges: Vec<(u64, Request, Option<Response>)>,
    /// The progress codes the unit reported, each once, in order.
    pub progress: Vec<ProgressCode>,
    /// When the printer's sensor first triggered, ms.
    pub sensor_on_ms: Option<u64>,
    /// The answer at which the printer left early (the first after its sensor triggered during
    /// `P1c`), and when.
    pub premature_finish: Option<(u64, Response)>,
    /// When the unit's `F` came, ms.
    pub finished_ms: Option<u64>,
}

/// Where a replay left Prusa's script.
#[derive(Debug, Clone, PartialEq)]
pub struct Departure {
    /// What was expected, in words.
    pub expected: String,
    /// What came, and everything seen so far.
    pub seen: ToolChangeScript,
}

impl std::fmt::Display for Departure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "expected {}; progress seen {:?}",
            self.expected, self.seen.progress
        )
    }
}

impl std::error::Error for Departure {}

/// The printer's side of the script on the simulator's line, one millisecond per step.
struct Player<'a> {
    sim: &'a mut Sim,
    decoder: ResponseDecoder,
    seen: ToolChangeScript,
}

impl Player<'_> {
    /// Send `request` and wait up to 200 ms (Buddy 6.5.3's timeout) for its answer.
    fn ask(&mut self, request: Request) -> Option<Response> {
        let mut rx = request.encode().as_bytes().to_vec();
        for _ in 0..200 {
            let mut tx = Vec::new();
            self.sim.step(&std::mem::take(&mut rx), &mut tx);
            if let Some(answer) = tx.iter().find_map(|&b| self.decoder.feed(b)).and_then(Result::ok) {
                self.seen
                    .exchanges
                    .push((self.sim.now_ms(), request, Some(answer)));
                return Some(answer);
            }
        }
        self.seen.exchanges.push((self.sim.now_ms(), request, None));
        None
    }

    fn idle(&mut self, ms: u64) {
        for _ in 0..ms {
            self.sim.step(&[], &mut Vec::new());
        }
    }

    fn depart(self, expected: impl Into<String>) -> Departure {
        Departure {
            expected: expected.into(),
            seen: self.seen,
        }
    }
}

/// Play Buddy 6.5.3's start-up and a `T<slot>` from nothing loaded against `sim` (which should
/// play [`Personality::Buddy65`](crate::Personality::Buddy65) and have booted), as Prusa's test
/// expects them; what came, or where the unit left the script.
pub fn replay_tool_change(sim: &mut Sim, slot: u8) -> Result<ToolChangeScript, Departure> {
    let mut player = Player {
        sim,
        decoder: ResponseDecoder::new(),
        seen: ToolChangeScript::default(),
    };
    for (part, version) in HANDSHAKE_VERSION {
        let request = Request::new(RequestCode::Version, part);
        if player.ask(request) != Some(Response::read(&request, version)) {
            return Err(player.depart(format!("S{part} answered {version}")));
        }
    }
    let build = player.ask(Request::new(RequestCode::Version, 3));
    if build.is_none_or(|b| b.param != ParamCode::Accepted) {
        return Err(player.depart("S3 answered with a build"));
    }
    for request in [
        Request::write(0x0b, 5),
        Request::write(0x14, 20),
        Request::new(RequestCode::FilamentSensor, 0),
    ] {
        if player.ask(request).is_none_or(|a| a.param != ParamCode::Accepted) {
            return Err(player.depart(format!("{} accepted", request.encode().as_str())));
        }
    }
    let tool = Request::new(RequestCode::Tool, slot);
    if player.ask(tool) != Some(Response::accepted(&tool)) {
        return Err(player.depart(format!("T{slot} accepted")));
    }
    let mut expected = TOOL_CHANGE_PROGRESS.iter().peekable();
    for _ in 0..600 {
        player.idle(100);
        let Some(answer) = player.ask(Request::new(RequestCode::Query, 0)) else {
            return Err(player.depart("an answer to Q0 within 200 ms"));
        };
        let sensor = player.sim.model().fsensor_state();
        if sensor != 0 && player.seen.sensor_on_ms.is_none() {
            player.seen.sensor_on_ms = Some(player.sim.now_ms());
        }
        match answer.param {
            ParamCode::Processing if (answer.code, answer.value) == (tool.code, tool.value) => {
                let progress = ProgressCode(answer.param_value.unwrap_or(0) as u8);
                if player.seen.progress.last() != Some(&progress) {
                    // Skippable steps may be left out; the others come in order.
                    loop {
                        match expected.next() {
                            Some(&(code, _)) if code == progress => break,
                            Some(&(_, true)) => continue,
                            Some(&(code, false)) => {
                                return Err(player.depart(format!("{code:?} before {progress:?}")));
                            }
                            None => return Err(player.depart(format!("nothing more than {progress:?}"))),
                        }
                    }
                    player.seen.progress.push(progress);
                }
                let in_load = player.seen.progress.contains(&ProgressCode::FEEDING_TO_FSENSOR);
                if in_load && sensor != 0 && player.seen.premature_finish.is_none() {
                    player.seen.premature_finish = Some((player.sim.now_ms(), answer));
                }
            }
            ParamCode::Finished if (answer.code, answer.value) == (tool.code, tool.value) => {
                player.seen.finished_ms = Some(player.sim.now_ms());
                let missing = expected.find(|&&(_, skippable)| !skippable);
                return match missing {
                    Some(&(code, _)) => Err(player.depart(format!("{code:?} before F0"))),
                    None => Ok(player.seen),
                };
            }
            _ => return Err(player.depart(format!("progress of T{slot}, not {answer:?}"))),
        }
        // After every progress answer the printer reports its sensor (`SendAndUpdateFilamentSensor`).
        player.ask(Request::new(RequestCode::FilamentSensor, sensor));
        for address in POLL {
            if player.ask(Request::new(RequestCode::Read, address)).is_none() {
                return Err(player.depart(format!("an answer to R{address:x}")));
            }
        }
    }
    Err(player.depart("T0 F0 within a minute"))
}
