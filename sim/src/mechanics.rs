//! The printer's mechanics (its extruder), driven by the frames on the wire, and the way the
//! printer's bytes reach the unit.
//!
//! No printer-side program can move the simulated extruder over the wire, so [`Mechanics`]
//! watches the traffic and moves it the way the printer's firmware does (spec §5.7) for the
//! printer [`Personality`] played:
//!
//! - **Before an unload.** Buddy 6.4 and the MK3S send `T` (and every printer `U`, `E`, `K`)
//!   only once the filament is out of their gears (`UnloadObeyAutoRetracted`: ramming first):
//!   the simulator plays that retract when it sees the frame and holds the frame back until it
//!   is done, never longer than [`Personality::max_hold_ms`] (the retract runs as fast as that
//!   needs: 1 s on a printer with a 2 s timeout, 0.1 s on Buddy 6.5.3).
//!   Buddy 6.5.3 sends `T` first (`MMU2::ToolChangeCommonOnce` in BFW v6.5.3 `mmu2_mk4.cpp`):
//!   the frame passes at once, and the slicer's ramming and the printer's own retract (80 mm at
//!   its copy of register 0x14) run while the unit has it. The model's gears hold the filament
//!   while they grip it: a unit pulling then pulls against them.
//! - **Loading.** While the unit reports `P1c` and the printer's sensor is clear, the printer
//!   co-feeds; once its sensor triggers, it pushes register 0x0b + 2 mm at 0x14 (BFW and PFW
//!   `OnMMUProgressMsgSame`). Buddy 6.5.3 then finishes the tool change early, as it does on
//!   `P2` after `P1c` (aborting its moves): it loads on to the nozzle without waiting for `F`.
//!   The others load to the nozzle on `T<n> F`.
//! - **Helping an unload.** When `P3` begins for a command the printer did not send as `U0` or
//!   `T` (a recovery, FIL. ALREADY LOADED's Unload) it retracts 20 mm whatever its sensor reads,
//!   and again at each `P3` after while nothing moves and its sensor still reads filament
//!   (`MMU2::OnMMUProgressMsgChanged` and `OnMMUProgressMsgSame`); so it does with every button it
//!   sends on `FSENSOR_DIDNT_SWITCH_OFF` or `FSENSOR_TOO_EARLY` (`MMU2::CheckUserInput` →
//!   `HelpUnloadToFinda`, BFW v6.5.3 `mmu2_mk4.cpp`, PFW v3.13.3 `Firmware/mmu2.cpp`).
//!
//! Where the simulator departs from the firmware, knowingly: Buddy 6.4.1 retracts 40 mm at
//! 20 mm/s after the slicer's ramming before it sends `T` (2 s, its whole timeout); the
//! simulator plays ramming and retract as 80 mm in the hold of 1 s. It co-feeds as soon as it
//! sees `P1c`, where 6.4.1 waits for the next poll. It pushes the extra load the moment the
//! sensor triggers, where the firmware does at its next look (within one heartbeat). On Buddy
//! 6.5.3 the slicer's ramming, which the printer finishes before it sends `T`, runs right after
//! it (0.6 s at 80 mm/s), so the sensor goes off about 1.3 s after the `T` instead of 0.7 s.
//! The printer's own load check after a tool change (`VerifyFilamentEnteredPTFE`) and its retry
//! path (-60 mm at 10 mm/s and -120 mm at 60 mm/s before `U0`) are not played.
//!
//! The printer takes a `Q0` answer's progress or error as its command's whatever command the
//! answer echoes; only `F` has to echo it (`ProtocolLogic::ProcessCommandQueryResponse`, BFW
//! `M2/protocol_logic.cpp`, PFW `Firmware/mmu2_protocol_logic.cpp`). An answer that shows a
//! command running while the printer thought itself idle puts it into that command
//! (`ProtocolLogic::IdleStep`).
//!
//! The printer's bytes pass to the unit as they arrive, so the silences between them (the MK4's
//! bootloader probe: `S` bytes 500 ms apart, BFW `src/mmu2/mmu2_bootloader.cpp`) reach the
//! unit's decoder as they are on the wire. Only a frame that may have to wait for a retract
//! (it starts with `U`, `E` or `K` at a line start, or `T` on a printer that retracts before it)
//! is gathered until its newline, and a frame never waits past a silence.

use std::collections::VecDeque;

use mmu_model::Model;
use mmu_protocol::{
    ErrorCode, ParamCode, ProgressCode, Request, RequestCode, RequestDecoder, Response, SILENCE_MS,
};

use crate::event::EventKind;
use crate::personality::Personality;

/// How far the printer pushes its extruder on its own while the unit reports `P1c` on Buddy
/// firmware, mm (`maximumAllowedExtruderMove`, spec §5.7); the MK3S's is
/// [`Personality::cofeed_mm`].
pub const COFEED_MM: f32 = 189.9;
/// The printer's unload before it asks for another tool or an unload on Buddy 6.4 and the MK3S:
/// ramming, then pulling the filament out of its gears, mm.
pub const PRINTER_UNLOAD_MM: f32 = 80.0;
/// Speed of the printer's ramming (and of its whole unload on Buddy 6.4 and the MK3S), mm/s.
pub const PRINTER_UNLOAD_MM_S: f32 = 80.0;
/// Buddy 6.5.3's finishing retract after it sent `T`, mm, at its copy of register 0x14
/// (`MMU2_RETRY_UNLOAD_FINISH_LENGTH`, BFW v6.5.3 `mmu2_config.h`, since `2178f416c2eb`).
pub const FINISH_RETRACT_MM: f32 = 80.0;
/// Where the slicer's ramming leaves the tip on a Buddy 6.5.3 printer, mm past its filament
/// sensor: "ramming which ends with the filament tip still in extruder gears" (`mmu2_mk4.cpp`),
/// and the sensor goes off this far into the finishing retract (`nominalEMotorFSOff`, 14 mm,
/// BFW v6.5.3 `mmu2_mk4.h`): 0.7 s at 20 mm/s, as measured with Prusa's code.
pub const RAMMED_TIP_PAST_SENSOR_MM: f32 = 14.0;
/// After a tool change the printer loads the new filament from its gears into the nozzle, mm.
pub const LOAD_TO_NOZZLE_MM: f32 = 60.0;
/// Speed of the printer's load to the nozzle, mm/s.
pub const LOAD_TO_NOZZLE_MM_S: f32 = 15.0;
/// The printer's help during `P3` of an error recovery (MK4 values, spec §5.7): 20 mm at 20 mm/s.
pub const UNLOAD_HELP_MM: f32 = 20.0;
/// A frame gathered longer than this without a newline is passed on as it is (garbage).
const MAX_FRAME: usize = 32;

/// Milliseconds one direction of the line has been quiet.
#[derive(Debug, Default)]
struct QuietMs(u32);

impl QuietMs {
    /// One millisecond in which `bytes` crossed; true once the line has been silent for
    /// [`SILENCE_MS`].
    fn step(&mut self, bytes: usize) -> bool {
        self.0 = if bytes == 0 { self.0.saturating_add(1) } else { 0 };
        self.0 >= SILENCE_MS
    }
}

/// One planned extruder move.
#[derive(Debug, Clone, Copy)]
struct Move {
    action: &'static str,
    mm: f32,
    mm_s: f32,
}

/// The printer's mechanics. See the [module documentation](self).
#[derive(Debug)]
pub struct Mechanics {
    personality: Personality,
    requests: RequestDecoder,
    responses: mmu_protocol::ResponseDecoder,
    /// How long each direction has been quiet: its decoder learns of a silence (after a broken
    /// frame it accepts nothing before one).
    requests_quiet: QuietMs,
    responses_quiet: QuietMs,
    /// The next printer byte starts a line (after a newline or a silence).
    at_line_start: bool,
    /// A command frame gathered until its newline.
    frame: Vec<u8>,
    /// Bytes held back while the printer unloads its extruder before sending them.
    held: VecDeque<u8>,
    /// The virtual ms until which the held bytes wait at most.
    hold_until_ms: Option<u64>,
    /// The printer's copies of registers 0x0b and 0x14, as it wrote them.
    extra_load_mm: f32,
    slow_mm_s: f32,
    /// The command in progress, as the printer sees it (its `ReqMsg()`).
    command: Option<(RequestCode, u8)>,
    /// The progress the printer last saw (`None` after an error or a finish).
    seen_progress: Option<ProgressCode>,
    /// The printer's `loadFilamentStarted`: set when it sees `P1c` begin, cleared by its push.
    load_started: bool,
    /// The printer's `unloadFilamentStarted`: set when it sees `P3` begin for a command it did
    /// not send as `U0` or `T`, cleared once its sensor reads no filament at a later `P3`.
    unload_help_started: bool,
    /// Buddy 6.5.3 left the tool change early and loads to the nozzle on its own.
    finished_early: bool,
    /// Moves planned after the one in progress (the printer's planner queue).
    planned: VecDeque<Move>,
    print_mm_s: f32,
    /// The error the printer shows (its `lastErrorCode`), until the unit goes on.
    shown_error: Option<ErrorCode>,
}

impl Mechanics {
    /// The mechanics of `personality`, with the unit's default 0x0b and 0x14 until the printer
    /// writes its own, printing at `print_mm_s` after a tool change.
    pub fn new(personality: Personality, extra_load_mm: f32, slow_mm_s: f32, print_mm_s: f32) -> Self {
        Mechanics {
            personality,
            requests: RequestDecoder::new(),
            responses: mmu_protocol::ResponseDecoder::new(),
            requests_quiet: QuietMs::default(),
            responses_quiet: QuietMs::default(),
            at_line_start: true,
            frame: Vec::new(),
            held: VecDeque::new(),
            hold_until_ms: None,
            extra_load_mm,
            slow_mm_s,
            command: None,
            seen_progress: None,
            unload_help_started: false,
            load_started: false,
            finished_early: false,
            planned: VecDeque::new(),
            print_mm_s,
            shown_error: None,
        }
    }

    /// The printer played.
    pub fn personality(&self) -> Personality {
        self.personality
    }

    /// The printer's bytes `rx` of this millisecond (`now_ms`): what reaches the unit's line now.
    pub fn pass_printer_bytes(
        &mut self,
        now_ms: u64,
        rx: &[u8],
        model: &mut Model,
        events: &mut Vec<EventKind>,
    ) -> Vec<u8> {
        let mut out = Vec::new();
        if self.requests_quiet.step(rx.len()) {
            let _ = self.requests.line_silent();
            self.at_line_start = true;
            // A frame cut short by a silence is garbage: it goes on as it is.
            self.release_frame(&mut out);
        }
        for &byte in rx {
            let may_wait = match byte {
                b'T' => !self.personality.sends_tool_before_retract(),
                b'U' | b'E' | b'K' => true,
                _ => false,
            };
            let gather = self.at_line_start && self.frame.is_empty() && may_wait;
            if gather || !self.frame.is_empty() {
                self.frame.push(byte);
            } else if self.hold_until_ms.is_some() {
                self.held.push_back(byte);
            } else {
                out.push(byte);
            }
            self.at_line_start = byte == b'\n';
            if let Some(Ok(request)) = self.requests.feed(byte)
                && self.printer_sends(&request, model, events)
            {
                let hold_ms = self.personality.max_hold_ms();
                self.hold_until_ms = Some(now_ms + hold_ms);
            }
            if byte == b'\n' || self.frame.len() >= MAX_FRAME {
                self.release_frame(&mut out);
            }
        }
        if self
            .hold_until_ms
            .is_some_and(|until| now_ms >= until || !model.extruder_busy())
        {
            self.hold_until_ms = None;
            out.extend(self.held.drain(..));
        }
        out
    }

    /// The gathered frame goes on: now, or after the bytes held.
    fn release_frame(&mut self, out: &mut Vec<u8>) {
        if self.hold_until_ms.is_some() {
            self.held.extend(self.frame.drain(..));
        } else {
            out.append(&mut self.frame);
        }
    }

    /// A millisecond of the unit's answer `bytes` reached the printer (after the line's faults).
    pub fn unit_bytes(&mut self, bytes: &[u8], model: &mut Model, events: &mut Vec<EventKind>) {
        if self.responses_quiet.step(bytes.len()) {
            let _ = self.responses.line_silent();
        }
        for &byte in bytes {
            if let Some(Ok(response)) = self.responses.feed(byte) {
                self.printer_reacts(&response, model, events);
            }
        }
    }

    /// The printer sent `request`: stop printing for a command, and unload the extruder when the
    /// command needs the filament out of it (spec §5.6: ramming, then `U0`/`T`). True when the
    /// request has to wait for that unload.
    fn printer_sends(&mut self, request: &Request, model: &mut Model, events: &mut Vec<EventKind>) -> bool {
        match request.code {
            RequestCode::Write if request.value == 0x0b => {
                self.extra_load_mm = f32::from(request.value2);
                false
            }
            RequestCode::Write if request.value == 0x14 => {
                self.slow_mm_s = f32::from(request.value2);
                false
            }
            RequestCode::Button => {
                let helps = matches!(
                    self.shown_error,
                    Some(ErrorCode::FSENSOR_DIDNT_SWITCH_OFF | ErrorCode::FSENSOR_TOO_EARLY)
                );
                if helps {
                    self.plan(model, events, "retry-help", -UNLOAD_HELP_MM, UNLOAD_HELP_MM);
                }
                false
            }
            code if code.is_command() && self.command == Some((code, request.value)) => {
                // The same command again (the unit answered `R`, or the answer was lost): the
                // printer resends it at once and its moves go on.
                false
            }
            code if code.is_command() => {
                // The printer matches the answers against the command it sent (`ReqMsg()`),
                // whether or not it heard the unit accept it.
                self.command = Some((code, request.value));
                self.seen_progress = None;
                self.load_started = false;
                self.finished_early = false;
                model.set_printing(None);
                let same_tool =
                    code == RequestCode::Tool && model.loaded_slot() == Some(usize::from(request.value));
                let needs_unload = matches!(
                    code,
                    RequestCode::Unload | RequestCode::Tool | RequestCode::Eject | RequestCode::Cut
                ) && !same_tool;
                let unloading = self.hold_until_ms.is_some();
                if !unloading {
                    // A command ends whatever the extruder was doing (its load into the nozzle):
                    // the printer's own moves come before it sends the next command.
                    self.abort(model);
                }
                let Some(tip) = needs_unload
                    .then(|| tip_in_gears(model))
                    .flatten()
                    .filter(|_| !unloading)
                else {
                    return false;
                };
                if code == RequestCode::Tool && self.personality.sends_tool_before_retract() {
                    // The slicer's ramming ends with the tip still in the gears; the printer's
                    // finishing retract follows at its 0x14 copy, the command already out.
                    let rammed = model.config().bowden_length_mm + RAMMED_TIP_PAST_SENSOR_MM;
                    if tip > rammed {
                        self.plan(model, events, "ramming", rammed - tip, PRINTER_UNLOAD_MM_S);
                    }
                    let speed = self.slow_mm_s;
                    self.plan(model, events, "finishing-retract", -FINISH_RETRACT_MM, speed);
                    false
                } else {
                    // Ramming and the retract out of the gears, done before the frame passes, in
                    // no more than the hold allows.
                    let hold_s = self.personality.max_hold_ms() as f32 / 1000.0;
                    let speed = PRINTER_UNLOAD_MM_S.max(PRINTER_UNLOAD_MM / hold_s);
                    self.plan(model, events, "ramming", -PRINTER_UNLOAD_MM, speed);
                    true
                }
            }
            _ => false,
        }
    }

    fn printer_reacts(&mut self, response: &Response, model: &mut Model, events: &mut Vec<EventKind>) {
        let echo = (response.code, response.value);
        if !response.code.is_command() {
            return;
        }
        match response.param {
            ParamCode::Accepted => {
                self.command = Some(echo);
                return;
            }
            ParamCode::Rejected => return,
            // An answer to `Q0`: the printer's command's state, whatever it echoes; an idle
            // printer takes up the command the unit runs.
            ParamCode::Processing | ParamCode::Error | ParamCode::Button => {
                self.command.get_or_insert(echo);
            }
            ParamCode::Finished => {}
        }
        self.shown_error = match response.param {
            ParamCode::Error => Some(ErrorCode(response.param_value.unwrap_or(0))),
            _ => None,
        };
        match response.param {
            ParamCode::Processing => {
                let progress = ProgressCode(response.param_value.unwrap_or(0) as u8);
                let changed = self.seen_progress != Some(progress);
                if changed {
                    // `OnMMUProgressMsgChanged`: `P1c` begins the load.
                    if progress == ProgressCode::FEEDING_TO_FSENSOR {
                        self.load_started = true;
                    }
                    if progress == ProgressCode::DISENGAGING_IDLER
                        && self.load_started
                        && self.personality.premature_finish()
                    {
                        // BFW v6.5.3 `OnMMUProgressMsgChanged`: "safe to kill the E-moves", then
                        // the tool change returns early.
                        self.load_started = false;
                        self.abort(model);
                        self.finish_early(model, events);
                    }
                    self.seen_progress = Some(progress);
                }
                // BFW `mmu2_mk4.cpp`: `OnMMUProgressMsgChanged` helps at once, after the moves
                // under way, whatever its sensor reads (`HelpUnloadToFinda`, 20 mm at 20 mm/s),
                // unless the printer sent the command as `U0` or `T` (its ramming has released
                // the filament); `OnMMUProgressMsgSame` helps again while nothing moves and its
                // sensor still reads filament, and stops helping once it does not.
                let unloading = progress == ProgressCode::UNLOADING_TO_FINDA;
                if unloading && changed && !matches!(response.code, RequestCode::Unload | RequestCode::Tool) {
                    self.unload_help_started = true;
                    self.plan(model, events, "unload-help", -UNLOAD_HELP_MM, UNLOAD_HELP_MM);
                } else if unloading
                    && self.unload_help_started
                    && !model.extruder_busy()
                    && self.planned.is_empty()
                {
                    if model.fsensor_state() != 0 {
                        self.plan(model, events, "unload-help", -UNLOAD_HELP_MM, UNLOAD_HELP_MM);
                    } else {
                        self.unload_help_started = false;
                    }
                }
            }
            ParamCode::Finished if self.command == Some(echo) => {
                self.command = None;
                self.seen_progress = None;
                self.load_started = false;
                self.unload_help_started = false;
                if response.code == RequestCode::Tool {
                    let rate = self.print_mm_s;
                    model.set_printing((rate > 0.0).then_some(rate));
                    if !std::mem::take(&mut self.finished_early) && model.fsensor_state() != 2 {
                        self.load_to_nozzle(model, events);
                    }
                }
            }
            // `F` of another command: the printer's command was interrupted; its mmu2 layer
            // decides what comes next.
            ParamCode::Finished => {}
            // `ERRWaitingForUser`: the next `P1c` is seen anew.
            _ => self.seen_progress = None,
        }
    }

    /// Buddy 6.5.3 returns from the tool change before the unit's `F`: once its sensor sees the
    /// filament it loads on to the nozzle (`VerifyFilamentEnteredPTFE`).
    fn finish_early(&mut self, model: &mut Model, events: &mut Vec<EventKind>) {
        self.finished_early = true;
        if model.fsensor_state() != 0 {
            self.load_to_nozzle(model, events);
        }
    }

    /// After a tool change the printer loads the filament from its gears on into the nozzle.
    fn load_to_nozzle(&mut self, model: &mut Model, events: &mut Vec<EventKind>) {
        self.plan(
            model,
            events,
            "load-to-nozzle",
            LOAD_TO_NOZZLE_MM,
            LOAD_TO_NOZZLE_MM_S,
        );
    }

    /// Co-feeding during `P1c` (spec §5.7), as Prusa's printers do it (`OnMMUProgressMsgSame`,
    /// printer-truth §8): while the printer last saw `P1c` and the load it began is on, with its
    /// sensor clear it keeps a co-feed move going; once its sensor triggers it aborts that and
    /// pushes the extra load distance + 2 mm, once. Then the next planned move starts when the
    /// extruder is free.
    pub fn step(&mut self, model: &mut Model, events: &mut Vec<EventKind>) {
        if self.load_started && self.seen_progress == Some(ProgressCode::FEEDING_TO_FSENSOR) {
            if model.fsensor_state() != 0 {
                self.load_started = false;
                self.abort(model);
                let (mm, speed) = (self.extra_load_mm + 2.0, self.slow_mm_s);
                self.plan(model, events, "extra-load", mm, speed);
                if self.personality.premature_finish() {
                    self.finish_early(model, events);
                }
            } else if !model.extruder_busy() {
                let (mm, speed) = (self.personality.cofeed_mm(), self.slow_mm_s);
                self.plan(model, events, "co-feed", mm, speed);
            }
        }
        if !model.extruder_busy()
            && let Some(next) = self.planned.pop_front()
        {
            start(model, events, next);
        }
    }

    /// Plan a move: it starts now if the extruder is free, else after the moves before it.
    fn plan(
        &mut self,
        model: &mut Model,
        events: &mut Vec<EventKind>,
        action: &'static str,
        mm: f32,
        mm_s: f32,
    ) {
        let planned = Move { action, mm, mm_s };
        if model.extruder_busy() || !self.planned.is_empty() {
            self.planned.push_back(planned);
        } else {
            start(model, events, planned);
        }
    }

    /// `planner_abort_queued_moves`: the move in progress stops, the planned ones are dropped.
    fn abort(&mut self, model: &mut Model) {
        self.planned.clear();
        model.extruder_move(0.0, PRINTER_UNLOAD_MM_S);
    }
}

/// Start `planned` on the extruder and say so.
fn start(model: &mut Model, events: &mut Vec<EventKind>, planned: Move) {
    model.extruder_move(planned.mm, planned.mm_s);
    events.push(EventKind::Extruder {
        action: planned.action,
        mm: planned.mm,
    });
}

/// The tip of the loaded filament if it reaches into the extruder's gears.
fn tip_in_gears(model: &Model) -> Option<f32> {
    let gears = model.config().extruder_gears_mm;
    model
        .loaded_slot()
        .and_then(|slot| model.tip_mm(slot))
        .filter(|&tip| tip >= gears)
}
