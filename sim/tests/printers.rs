//! The printers the simulator plays ([`Personality`]): each with the protocol timing and the
//! extruder behaviour its firmware was released with, and the line passing the printer's bytes
//! as they come.

use mmu_protocol::{
    ButtonCode, ErrorCode, ParamCode, ProgressCode, Request, RequestCode, Response, ResponseDecoder,
    ResultCode,
};
use mmu_sim::{
    Decision, EventKind, Link, Operator, Outcome, Personality, Printer, PrinterEvent, PrinterOptions, Sim,
    SimFault, SimLink, SimOptions,
};

/// Records what the printer saw, with the printer's clock; gives up on any error.
#[derive(Default)]
struct Watcher {
    events: Vec<(u64, PrinterEvent)>,
}

impl Operator<SimLink> for Watcher {
    fn event(&mut self, link: &mut SimLink, event: &PrinterEvent) {
        self.events.push((link.now_ms(), event.clone()));
    }

    fn decide(&mut self, _link: &mut SimLink, _request: Request, _error: ErrorCode) -> Decision {
        Decision::GiveUp
    }
}

impl Watcher {
    /// When each request went out.
    fn sent(&self) -> Vec<(u64, Request)> {
        self.events
            .iter()
            .filter_map(|(t, e)| match e {
                PrinterEvent::Sent(r) => Some((*t, *r)),
                _ => None,
            })
            .collect()
    }
}

/// A printer of `personality` on a fresh simulator playing the same printer, connected.
fn connected(personality: Personality) -> (Printer<SimLink>, Watcher) {
    let sim = Sim::new(SimOptions {
        printer: personality,
        ..SimOptions::default()
    })
    .unwrap();
    let mut printer = Printer::new(SimLink::new(sim), PrinterOptions::of(personality));
    let mut op = Watcher::default();
    printer.connect(&mut op).expect("connects");
    (printer, op)
}

/// The extruder moves the simulator made since the last call, in order.
fn extruder_moves(link: &mut SimLink) -> Vec<(u64, &'static str, f32)> {
    link.sim_mut()
        .take_events()
        .into_iter()
        .filter_map(|e| match e.what {
            EventKind::Extruder { action, mm } => Some((e.t_ms, action, mm)),
            _ => None,
        })
        .collect()
}

/// The printer prints for `ms`: when it sent each `Q0`, and the gaps between them, ms.
fn polls_while_printing(printer: &mut Printer<SimLink>, op: &mut Watcher, ms: u64) -> (Vec<u64>, Vec<u64>) {
    let start = printer.link().now_ms();
    printer.print(op, ms).unwrap();
    let queries: Vec<u64> = op
        .sent()
        .into_iter()
        .filter(|(t, r)| *t >= start && r.code == RequestCode::Query)
        .map(|(t, _)| t)
        .collect();
    let gaps = queries.windows(2).map(|w| w[1] - w[0]).collect();
    (queries, gaps)
}

#[test]
fn buddy_6_5_polls_every_100_ms_and_gives_up_on_an_answer_after_200_ms() {
    let (mut printer, mut op) = connected(Personality::Buddy65);
    let (queries, gaps) = polls_while_printing(&mut printer, &mut op, 2000);
    // 100 ms after the last exchange of the poll (Q0 and six register reads of a few ms).
    assert!(queries.len() >= 15, "{gaps:?}");
    assert!(gaps.iter().all(|gap| (100..=130).contains(gap)), "{gaps:?}");

    // The unit falls silent: the printer waits 200 ms for an answer, then starts again.
    printer
        .link_mut()
        .sim_mut()
        .inject(SimFault::PowerLoss { off_ms: 1500 });
    op.events.clear();
    printer.print(&mut op, 300).unwrap();
    let first_query = op
        .sent()
        .first()
        .map(|(t, _)| *t)
        .expect("a query after the power loss");
    let lost = op
        .events
        .iter()
        .find(|(_, e)| matches!(e, PrinterEvent::LinkLost(_)))
        .map(|(t, _)| *t)
        .expect("the link is lost");
    assert_eq!(lost - first_query, 200, "{:?}", op.events);
}

#[test]
fn buddy_6_4_polls_every_second_with_a_2_s_timeout() {
    let (mut printer, mut op) = connected(Personality::Buddy64);
    let (_, gaps) = polls_while_printing(&mut printer, &mut op, 5000);
    assert!(gaps.iter().all(|gap| (1000..=1030).contains(gap)), "{gaps:?}");
}

#[test]
fn buddy_printers_poll_the_bowden_length_and_the_mk3s_does_not() {
    for personality in Personality::ALL {
        let (mut printer, mut op) = connected(personality);
        op.events.clear();
        printer.print(&mut op, 2500).unwrap();
        let reads: Vec<u8> = op
            .sent()
            .into_iter()
            .filter(|(_, r)| r.code == RequestCode::Read)
            .map(|(_, r)| r.value)
            .collect();
        // Prusa's `regs8Addrs` then `regs16Addrs`, after every `Q0`.
        let poll: &[u8] = match personality {
            Personality::Mk3s => &[0x08, 0x1b, 0x1c, 0x04, 0x1a],
            _ => &[0x08, 0x1b, 0x1c, 0x04, 0x1a, 0x22],
        };
        assert_eq!(reads.get(..poll.len()), Some(poll), "{personality}: {reads:x?}");
        assert!(
            !reads.is_empty() && reads.len().is_multiple_of(poll.len()),
            "{personality}"
        );
        let bowden = printer.polled(0x22);
        assert_eq!(
            bowden.is_some(),
            personality != Personality::Mk3s,
            "{personality}"
        );
    }
}

/// A tool change to slot 0 from parked, then printing until the filament is in the nozzle.
fn loaded(personality: Personality) -> (Printer<SimLink>, Watcher) {
    let (mut printer, mut op) = connected(personality);
    let outcome = printer
        .command(&mut op, Request::new(RequestCode::Tool, 0))
        .unwrap();
    assert_eq!(outcome, Outcome::Finished(ResultCode::OK), "{:?}", op.events);
    printer.print(&mut op, 5000).unwrap();
    let model = printer.link().sim().model();
    assert_eq!((model.loaded_slot(), model.fsensor_state()), (Some(0), 2));
    extruder_moves(printer.link_mut());
    (printer, op)
}

/// Send `T1` on the wire as the printer does and step until the unit runs it or `max_ms` passed;
/// the virtual time it took.
fn send_tool_1(link: &mut SimLink, max_ms: u64) -> Option<u64> {
    let sent = link.now_ms();
    link.send(Request::new(RequestCode::Tool, 1).encode().as_bytes())
        .unwrap();
    while link.now_ms() < sent + max_ms {
        link.receive(1, &mut Vec::new()).unwrap();
        if link.sim().unit_command().0 == (RequestCode::Tool, 1) {
            return Some(link.now_ms() - sent);
        }
    }
    None
}

#[test]
fn buddy_6_5_sends_t_before_its_retract_and_the_unit_has_it_at_once() {
    let (mut printer, _op) = loaded(Personality::Buddy65);
    let link = printer.link_mut();
    let took = send_tool_1(link, 50).expect("the unit runs T1");
    assert!(took <= 2, "{took} ms");
    // The filament is still in the printer's gears and its sensor on when the unit has the T.
    let gears = link.sim().model().config().extruder_gears_mm;
    assert!(link.sim().model().tip_mm(0).unwrap() > gears);
    assert_ne!(link.sim().model().fsensor_state(), 0);
    // Then the printer's own unload: the slicer's ramming (which ends with the tip in the
    // gears) and the 80 mm finishing retract at its register 0x14 copy (20 mm/s).
    link.idle(200);
    let moves: Vec<(&str, f32)> = extruder_moves(link)
        .into_iter()
        .map(|(_, a, mm)| (a, mm))
        .collect();
    assert_eq!(moves.first().map(|m| m.0), Some("ramming"), "{moves:?}");
    let mut off_after = None;
    for ms in 200..3000 {
        link.idle(1);

        if link.sim().model().fsensor_state() == 0 {
            off_after = Some(ms);
            break;
        }
    }
    let moves: Vec<(&str, f32)> = extruder_moves(link)
        .into_iter()
        .map(|(_, a, mm)| (a, mm))
        .collect();
    assert!(moves.contains(&("finishing-retract", -80.0)), "{moves:?}");
    let off_after = off_after.expect("the printer's sensor goes off");
    // The sensor goes off after the ramming and 0.7 s of the retract, well inside the 4 s a
    // 3.0.4 unit waits.
    assert!((1000..2000).contains(&off_after), "{off_after} ms");
}

#[test]
fn every_printer_unloads_its_extruder_before_u0_within_its_timeout() {
    for personality in Personality::ALL {
        let (mut printer, _op) = loaded(personality);
        let link = printer.link_mut();
        let sent = link.now_ms();
        link.send(Request::new(RequestCode::Unload, 0).encode().as_bytes())
            .unwrap();
        let mut took = None;
        while link.now_ms() < sent + 2000 {
            link.receive(1, &mut Vec::new()).unwrap();
            if link.sim().unit_command().0 == (RequestCode::Unload, 0) {
                took = Some(link.now_ms() - sent);
                break;
            }
        }
        let took = took.expect("the unit runs U0");
        assert!(
            took <= personality.link_timeout_ms() / 2 + 10,
            "{personality}: {took} ms"
        );
        let model = link.sim().model();
        let gears = model.config().extruder_gears_mm;
        assert!(model.tip_mm(0).unwrap() <= gears + 1e-3, "{personality}");
        if personality.gears_before_sensor_mm().is_some() {
            // On Buddy 6.5.3 `U0` goes out with the printer's sensor off already.
            assert_eq!(model.fsensor_state(), 0, "{personality}");
        }
    }
}

#[test]
fn a_command_sent_again_does_not_restart_the_printers_moves() {
    // The printer sends a command again at once when the unit answered `R` or the answer was
    // lost; its own moves (here Buddy 6.5.3's retract after `T`) go on meanwhile.
    let (mut printer, _op) = loaded(Personality::Buddy65);
    let link = printer.link_mut();
    send_tool_1(link, 50).expect("the unit runs T1");
    link.idle(700);
    let t1 = Request::new(RequestCode::Tool, 1);
    link.send(t1.encode().as_bytes()).unwrap();
    link.idle(3000);
    let moves: Vec<&str> = extruder_moves(link).into_iter().map(|(_, a, _)| a).collect();
    let count = |what: &str| moves.iter().filter(|&&m| m == what).count();
    assert_eq!(
        (count("ramming"), count("finishing-retract")),
        (1, 1),
        "{moves:?}"
    );
}

#[test]
fn buddy_6_4_and_the_mk3s_send_t_once_the_filament_is_out_of_their_gears() {
    for personality in [Personality::Buddy64, Personality::Mk3s] {
        let (mut printer, _op) = loaded(personality);
        let link = printer.link_mut();
        let took = send_tool_1(link, 2000).expect("the unit runs T1");
        // The printer's ramming and retract come first, within half its 2 s timeout.
        assert!((900..=1010).contains(&took), "{personality}: {took} ms");
        let model = link.sim().model();
        let gears = model.config().extruder_gears_mm;
        assert!(model.tip_mm(0).unwrap() <= gears + 1e-3, "{personality}");
    }
}

#[test]
fn the_printer_gears_hold_the_filament_while_buddy_6_5_retracts() {
    let (mut printer, _op) = loaded(Personality::Buddy65);
    let link = printer.link_mut();
    send_tool_1(link, 50).expect("the unit runs T1");
    let model = link.sim().model();
    let gears = model.config().extruder_gears_mm;
    let slack = model.config().buffer_limit_mm;
    let (tip0, e0) = (model.tip_mm(0).unwrap(), model.extruder_position_mm());
    while link.sim().model().tip_mm(0).is_some_and(|tip| tip > gears) {
        link.idle(1);
        let model = link.sim().model();
        let (tip, e) = (model.tip_mm(0).unwrap(), model.extruder_position_mm());
        // However hard the unit pulls, the tip comes back no faster than the extruder lets it
        // (the hub buffer's travel aside).
        assert!(tip0 - tip <= (e0 - e) + slack + 1e-3, "tip {tip}, extruder {e}");
    }
}

#[test]
fn a_motor_pulling_against_retracting_gears_stalls_to_their_pace() {
    use mmu_model::{Direction, Duty, Model, ModelConfig, MotorCommand};
    let mut model = Model::new(ModelConfig::default(), 1, 1);
    model.insert_filament(0, 374.0);
    // Buddy 6.5.3's finishing retract: 80 mm at 20 mm/s.
    model.extruder_move(-80.0, 20.0);
    let pull = MotorCommand::Drive {
        direction: Direction::Reverse,
        duty: Duty::from_permille(1000),
    };
    for _ in 0..300 {
        model.step(1, &[pull]);
    }
    // 0.3 s at 20 mm/s is 6 mm, plus the hub buffer's travel: the motor (150 mm/s free) got
    // no more, and turns no faster than the gears let the filament go.
    let tip = model.tip_mm(0).unwrap();
    assert!(374.0 - tip <= 6.0 + 6.0 + 1e-3, "tip {tip}");
    assert!(model.motor_speed_mm_s(0).unwrap() > -25.0);
}

#[test]
fn buddy_6_5_finishes_a_tool_change_early_on_its_own_sensor_and_loads_on() {
    let (mut printer, mut op) = connected(Personality::Buddy65);
    let outcome = printer
        .command(&mut op, Request::new(RequestCode::Tool, 1))
        .unwrap();
    assert_eq!(outcome, Outcome::Finished(ResultCode::OK), "{:?}", op.events);
    let early = op
        .events
        .iter()
        .position(|(_, e)| matches!(e, PrinterEvent::PrematureFinish(r) if r.value == 1))
        .expect("a premature finish");
    let finished = op
        .events
        .iter()
        .position(|(_, e)| matches!(e, PrinterEvent::Finished(..)))
        .unwrap();
    assert!(early < finished);
    // It had seen `P1c`, and leaves at the answer after its sensor triggered (Prusa's expected
    // exchange: "premature finish on the next T0 P7"), long before the unit's `F`.
    let seen: Vec<ProgressCode> = op.events[..early]
        .iter()
        .filter_map(|(_, e)| match e {
            PrinterEvent::Progress(_, p) => Some(*p),
            _ => None,
        })
        .collect();
    assert!(seen.contains(&ProgressCode::FEEDING_TO_FSENSOR), "{seen:?}");
    let finished_ms = op.events[finished].0;
    // Its extruder: co-feed from `P1c`, the push of 0x0b + 2 mm once its sensor triggers, then
    // on to the nozzle without waiting for the unit's `F`.
    printer.print(&mut op, 1000).unwrap();
    let moves = extruder_moves(printer.link_mut());
    let actions: Vec<(&str, f32)> = moves.iter().map(|&(_, a, mm)| (a, mm)).collect();
    assert_eq!(
        actions,
        [("co-feed", 189.9), ("extra-load", 7.0), ("load-to-nozzle", 60.0)],
        "{moves:?}"
    );
    // The load follows the push (7 mm at 20 mm/s) at once, wherever the unit's `F` falls.
    assert!(
        (349..=352).contains(&(moves[2].0 - moves[1].0)),
        "{moves:?}, F at {finished_ms}"
    );
    let model = printer.link().sim().model();
    assert_eq!(model.loaded_slot(), Some(1));
}

#[test]
fn older_printers_wait_for_the_unit_to_finish() {
    for personality in [Personality::Buddy64, Personality::Mk3s] {
        let (mut printer, mut op) = connected(personality);
        printer
            .command(&mut op, Request::new(RequestCode::Tool, 1))
            .unwrap();
        assert!(
            !op.events
                .iter()
                .any(|(_, e)| matches!(e, PrinterEvent::PrematureFinish(_))),
            "{personality}"
        );
        let moves: Vec<&str> = extruder_moves(printer.link_mut())
            .into_iter()
            .map(|(_, a, _)| a)
            .collect();
        assert_eq!(
            moves,
            ["co-feed", "extra-load", "load-to-nozzle"],
            "{personality}"
        );
    }
}

/// A bare wire to a simulator: bytes in, answers out, one millisecond per step.
struct Wire {
    sim: Sim,
    decoder: ResponseDecoder,
    answers: Vec<(u64, Response)>,
}

impl Wire {
    fn new() -> Self {
        Wire {
            sim: Sim::new(SimOptions::default()).unwrap(),
            decoder: ResponseDecoder::new(),
            answers: Vec::new(),
        }
    }

    /// One millisecond with `bytes` from the printer.
    fn step(&mut self, bytes: &[u8]) {
        let mut tx = Vec::new();
        self.sim.step(bytes, &mut tx);
        for byte in tx {
            if let Some(Ok(answer)) = self.decoder.feed(byte) {
                self.answers.push((self.sim.now_ms(), answer));
            }
        }
    }

    fn idle(&mut self, ms: u64) {
        for _ in 0..ms {
            self.step(&[]);
        }
    }

    /// Send `request` and wait up to 20 ms for its answer.
    fn ask(&mut self, request: Request) -> Option<Response> {
        let before = self.answers.len();
        self.step(request.encode().as_bytes());
        for _ in 0..20 {
            if self.answers.len() > before {
                return Some(self.answers[before].1);
            }
            self.step(&[]);
        }
        None
    }
}

#[test]
fn the_bootloader_probe_reaches_the_unit_as_it_is_sent_and_costs_no_frame() {
    let mut wire = Wire::new();
    wire.idle(300);
    // The MK4's bootloader probe (BFW `src/mmu2/mmu2_bootloader.cpp`): `S`, no answer within
    // 500 ms, again; no newline ever. Then the printer's handshake.
    for _ in 0..3 {
        wire.step(b"S");
        wire.idle(500);
    }
    let answer = wire.ask(Request::new(RequestCode::Version, 0));
    assert_eq!(
        answer.map(|a| (a.code, a.param)),
        Some((RequestCode::Version, ParamCode::Accepted)),
        "the first S0 is answered"
    );
}

#[test]
fn a_frame_split_across_milliseconds_still_reaches_the_unit_whole() {
    let mut wire = Wire::new();
    wire.idle(300);
    let frame = Request::new(RequestCode::Query, 0).encode();
    let (head, tail) = frame.as_bytes().split_at(2);
    wire.step(head);
    wire.step(tail);
    wire.idle(10);
    assert_eq!(wire.answers.len(), 1, "{:?}", wire.answers);
}

#[test]
fn a_command_lost_on_the_line_does_not_stop_the_printers_extruder() {
    // Under line corruption the printer may send a command the unit never gets (its bytes
    // garbled on the way) while the unit goes on with the one it runs. Prusa's printer takes the
    // progress of a `Q0` answer whatever command it echoes (`ProcessCommandQueryResponse`), so
    // it co-feeds when the unit reports `P1c` and pushes the extra load once its sensor triggers;
    // the simulated extruder must do the same, or the unit waits for a pull that never comes.
    let mut wire = Wire::new();
    wire.idle(300);
    let accepted = wire.ask(Request::new(RequestCode::Tool, 1)).unwrap();
    assert_eq!(accepted.param, ParamCode::Accepted);
    let progress = |wire: &mut Wire| {
        let answer = wire.ask(Request::new(RequestCode::Query, 0)).unwrap();
        (answer, answer.param_value.map(|v| ProgressCode(v as u8)))
    };
    let mut waited = 0;
    while progress(&mut wire).1 != Some(ProgressCode::FEEDING_TO_BONDTECH) {
        wire.idle(100);
        waited += 100;
        assert!(waited < 5000, "the unit feeds on");
    }
    wire.sim.inject(SimFault::UartCorrupt { probability: 1.0 });
    wire.step(Request::new(RequestCode::Unload, 0).encode().as_bytes());
    wire.sim.clear(mmu_sim::SimFaultKind::UartCorrupt);
    wire.idle(100);
    wire.sim.take_events();
    // The printer polls on, reporting its sensor, as it does every second.
    let mut reported = 0;
    let mut end = None;
    for _ in 0..60 {
        wire.idle(500);
        let state = wire.sim.model().fsensor_state();
        if state != reported {
            wire.ask(Request::new(RequestCode::FilamentSensor, state));
            reported = state;
        }
        let (answer, _) = progress(&mut wire);
        if answer.param != ParamCode::Processing {
            end = Some(answer);
            break;
        }
    }
    let moves: Vec<&str> = wire
        .sim
        .take_events()
        .into_iter()
        .filter_map(|e| match e.what {
            EventKind::Extruder { action, .. } => Some(action),
            _ => None,
        })
        .collect();
    assert!(moves.starts_with(&["co-feed", "extra-load"]), "{moves:?}");
    let end = end.expect("T1 ends");
    assert_eq!((end.code, end.param), (RequestCode::Tool, ParamCode::Finished));
}

#[test]
fn prusas_expected_6_5_3_tool_change_replays_against_the_unit() {
    let mut sim = Sim::new(SimOptions {
        printer: Personality::Buddy65,
        ..SimOptions::default()
    })
    .unwrap();
    for _ in 0..300 {
        sim.step(&[], &mut Vec::new());
    }
    let seen =
        mmu_sim::scenario::replay_tool_change(&mut sim, 0).unwrap_or_else(|departure| panic!("{departure}"));
    let (left_ms, answer) = seen.premature_finish.expect("the printer left early");
    assert!(seen.sensor_on_ms.is_some_and(|on| on <= left_ms), "{seen:?}");
    assert_eq!(answer.code, RequestCode::Tool);
    // The unit's order: P5, P6, P1c, P7 (it has no idler to engage or disengage).
    assert!(
        seen.progress.starts_with(&[ProgressCode::FEEDING_TO_FINDA]),
        "{seen:?}"
    );
    assert!(seen.finished_ms.is_some_and(|f| f >= left_ms));
    assert_eq!(sim.model().loaded_slot(), Some(0));
}

#[test]
fn buddy_6_5_retract_alone_clears_its_sensor_when_the_unit_lets_the_filament_go() {
    // What a 3.0.4 unit counts on: with its motor free (coasting), the printer's ramming and
    // finishing retract push the filament back through the tube and clear the printer's sensor
    // while its gears still hold it, then let it go.
    use mmu_model::{Model, ModelConfig, MotorCommand};
    let mut geometry = ModelConfig::default();
    let before = Personality::Buddy65
        .gears_before_sensor_mm()
        .expect("gears before the sensor");
    geometry.extruder_gears_mm = geometry.bowden_length_mm - before;
    let gears = geometry.extruder_gears_mm;
    let mut model = Model::new(geometry, 1, 1);
    model.insert_filament(0, 420.0);
    let rammed = 360.0 + mmu_sim::mechanics::RAMMED_TIP_PAST_SENSOR_MM;
    let ramming_ms = ((420.0 - rammed) / mmu_sim::mechanics::PRINTER_UNLOAD_MM_S * 1000.0) as u64;
    model.extruder_move(rammed - 420.0, mmu_sim::mechanics::PRINTER_UNLOAD_MM_S);
    for _ in 0..ramming_ms {
        model.step(1, &[MotorCommand::Coast]);
    }
    assert!(
        (model.tip_mm(0).unwrap() - rammed).abs() < 0.5,
        "{:?}",
        model.tip_mm(0)
    );
    model.extruder_move(-mmu_sim::mechanics::FINISH_RETRACT_MM, 20.0);
    let mut off_ms = None;
    let mut released_ms = None;
    for ms in 1..=4000u64 {
        model.step(1, &[MotorCommand::Coast]);
        let tip = model.tip_mm(0).unwrap();
        if off_ms.is_none() && model.fsensor_state() == 0 {
            off_ms = Some(ms);
            assert!(tip > gears, "the gears still hold it when the sensor goes off");
        }
        if released_ms.is_none() && tip <= gears {
            released_ms = Some(ms);
        }
    }
    // 14 mm at 20 mm/s (`nominalEMotorFSOff`), then 10 mm more in the gears.
    let off_ms = off_ms.expect("the sensor goes off");
    assert!((650..=800).contains(&off_ms), "{off_ms} ms");
    let released_ms = released_ms.expect("the gears let go");
    assert!((1100..=1300).contains(&released_ms), "{released_ms} ms");
}

/// Presses a button on `FILAMENT_ALREADY_LOADED` (`button`), Retry on any other error, up to
/// `retries` times; records every error.
struct AlreadyLoaded {
    button: ButtonCode,
    retries: u8,
    errors: Vec<ErrorCode>,
}

impl Operator<SimLink> for AlreadyLoaded {
    fn event(&mut self, _link: &mut SimLink, _event: &PrinterEvent) {}

    fn decide(&mut self, _link: &mut SimLink, _request: Request, error: ErrorCode) -> Decision {
        self.errors.push(error);
        match error {
            ErrorCode::FILAMENT_ALREADY_LOADED => Decision::Press(self.button),
            _ if self.retries > 0 => {
                self.retries -= 1;
                Decision::Press(ButtonCode::MIDDLE)
            }
            _ => Decision::GiveUp,
        }
    }
}

/// Buddy's help on `P3` of a command it did not send as `U0` or `T` is a 20 mm retract at 20 mm/s
/// whatever its sensor reads (`MMU2::OnMMUProgressMsgChanged` → `HelpUnloadToFinda`, BFW
/// `lib/Marlin/Marlin/src/feature/prusa/MMU2/mmu2_mk4.cpp`, lines 1438-1468 at `818d812`;
/// `MMU2_RETRY_UNLOAD_TO_FINDA_LENGTH` and `_FEED_RATE` in `mmu2_config.h`). On Buddy 6.5.3 the
/// gears sit 10 mm before the sensor: a tip left between them is gripped with the sensor off, and
/// only that help frees it. The simulator played the help only while the sensor read filament, so
/// FIL. ALREADY LOADED's Unload pulled against the gears and every Retry ended in `8047`.
#[test]
fn buddy_s_unload_help_retracts_whatever_its_sensor_reads() {
    let (mut printer, _) = loaded(Personality::Buddy65);
    // The tip between the gears and the sensor: gripped, the sensor off.
    let geometry = printer.link().sim().model().config();
    let between = (geometry.extruder_gears_mm + geometry.bowden_length_mm) / 2.0;
    let back = printer.link().sim().model().tip_mm(0).unwrap() - between;
    printer
        .link_mut()
        .sim_mut()
        .model_mut()
        .extruder_move(-back, 40.0);
    printer.print(&mut Watcher::default(), 3000).unwrap();
    assert_eq!(
        printer.link().sim().model().fsensor_state(),
        0,
        "the sensor is off"
    );
    extruder_moves(printer.link_mut());
    let mut op = AlreadyLoaded {
        button: ButtonCode::RIGHT,
        retries: 3,
        errors: Vec::new(),
    };
    let outcome = printer
        .command(&mut op, Request::new(RequestCode::Load, 0))
        .unwrap();
    let moves = extruder_moves(printer.link_mut());
    assert!(
        moves
            .iter()
            .any(|(_, action, mm)| *action == "unload-help" && *mm < 0.0),
        "the printer helped: {moves:?}"
    );
    assert_eq!(
        outcome,
        Outcome::Finished(ResultCode::OK),
        "errors {:?}",
        op.errors
    );
    assert!(
        !op.errors.contains(&ErrorCode::STALLED_PULLEY),
        "errors {:?}",
        op.errors
    );
}
