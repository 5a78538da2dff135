//! What Prusa's own printer code does with the unit's answers (issue 12; research notes in
//! `printer-truth.md`): every error the printer shows has a way out, and nothing the unit answers
//! makes the printer loop. Each test is named after the finding it reproduces.

mod common;

use common::{Rig, error, finished, press, t};
use mmu_protocol::{ButtonCode, ErrorCode, ParamCode, Request, RequestCode, Response};

fn accepted(request: Request) -> Response {
    Response::bare(request.code, request.value, ParamCode::Accepted)
}

// ---- #10: a start-up error turns the next command into an endless reject ---------------------

/// Prusa's printer re-sends a rejected command at once, forever, and can then never send the
/// Retry of the error screen (`protocol_logic.cpp` `CommandRejected` → `CommandRestart`): the
/// command must be accepted and fail with the waiting error, so the screen's Retry works.
#[test]
fn start_up_error_then_tool_change_is_accepted_and_fails_with_the_start_up_error() {
    let mut rig = Rig::<3>::new();
    rig.model.insert_filament(0, 30.0);
    assert_eq!(
        rig.boot(),
        Response::error(RequestCode::Reset, 0, ErrorCode::FINDA_VS_EEPROM_DISREPANCY)
    );
    let before = rig.motor_log.len();
    assert_eq!(rig.send(t(1)), Some(accepted(t(1))));
    assert_eq!(rig.query(), error(t(1), ErrorCode::FINDA_VS_EEPROM_DISREPANCY));
    // The printer's automatic Retry while the filament is still in the hub: the same error.
    press(&mut rig, ButtonCode::MIDDLE);
    rig.idle(50);
    assert_eq!(rig.query(), error(t(1), ErrorCode::FINDA_VS_EEPROM_DISREPANCY));
    assert!(
        rig.nothing_moved_since(before),
        "no motor moves before the check passes"
    );
    // The user pulls the filament back out of the hub and presses Retry on the screen.
    rig.model.insert_filament(0, -15.0);
    rig.idle(100);
    press(&mut rig, ButtonCode::MIDDLE);
    rig.tool_change_goes_on_and_loads(1);
}

/// The same after the user fixed the fault without pressing Retry: still no `R`.
#[test]
fn start_up_error_fixed_without_retry_then_tool_change_runs_after_retry() {
    let mut rig = Rig::<3>::new();
    rig.model.insert_filament(0, 30.0);
    rig.boot();
    rig.model.insert_filament(0, -15.0);
    rig.idle(100);
    assert_eq!(rig.send(t(2)), Some(accepted(t(2))));
    assert_eq!(rig.query(), error(t(2), ErrorCode::FINDA_VS_EEPROM_DISREPANCY));
    press(&mut rig, ButtonCode::MIDDLE);
    rig.tool_change_goes_on_and_loads(2);
}

/// A command sent over any other waiting error (printer-truth §2.3: the printer sends `T<m>`
/// over a pending error) is accepted too, fails with that error before moving, and after Retry
/// runs from where the sensors say the filament is.
#[test]
fn tool_change_over_a_waiting_motion_error_is_accepted_and_runs_after_retry() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(mmu_model::Fault::Jam { slot: 1 });
    let run = rig.command(t(1));
    assert_eq!(run.last, error(t(1), ErrorCode::STALLED_PULLEY));
    let before = rig.motor_log.len();
    assert_eq!(rig.send(t(2)), Some(accepted(t(2))));
    rig.idle(50);
    assert_eq!(rig.query(), error(t(2), ErrorCode::STALLED_PULLEY));
    assert!(rig.nothing_moved_since(before));
    rig.model.clear_all();
    press(&mut rig, ButtonCode::MIDDLE);
    rig.tool_change_goes_on_and_loads(2);
}

/// A command over the eject's question (`E800c`, Continue) takes the question over: Continue
/// answers it, then the command runs.
#[test]
fn tool_change_over_the_eject_question_runs_after_continue() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let eject = Request::new(RequestCode::Eject, 1);
    assert_eq!(rig.command(eject).last, error(eject, ErrorCode::FILAMENT_EJECTED));
    assert_eq!(rig.send(t(0)), Some(accepted(t(0))));
    assert_eq!(rig.query(), error(t(0), ErrorCode::FILAMENT_EJECTED));
    press(&mut rig, ButtonCode::MIDDLE);
    rig.tool_change_goes_on_and_loads(0);
}

// ---- #9: Retry "finishes" a command that never moved -----------------------------------------

/// `>T1 <T1 E8008 >B1 <T1 F0` with nothing moved sends the printer into LOAD TO EXTR. FAILED
/// loops; Retry after an error raised before any phase ran plans the command again.
#[test]
fn retry_after_a_plan_error_plans_again_instead_of_finishing() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    // Filament pushed into the hub by hand: no slot is known to own it.
    rig.model.insert_filament(1, 5.0);
    rig.idle(100);
    assert_eq!(rig.send(t(1)), Some(accepted(t(1))));
    assert_eq!(rig.query(), error(t(1), ErrorCode::FINDA_VS_EEPROM_DISREPANCY));
    let before = rig.motor_log.len();
    press(&mut rig, ButtonCode::MIDDLE);
    rig.idle(50);
    assert_eq!(
        rig.query(),
        error(t(1), ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
        "the cause is still there"
    );
    assert!(rig.nothing_moved_since(before));
    rig.model.insert_filament(1, -15.0);
    rig.idle(100);
    press(&mut rig, ButtonCode::MIDDLE);
    let run = rig.follow(t(1), 120_000);
    assert_eq!(run.last, finished(t(1)));
    assert_eq!(rig.model.loaded_slot(), Some(1), "the finish is a real load");
}

/// The same with the hub sensor stuck at a rail (`800a`) when `T1` arrives.
#[test]
fn retry_after_a_hub_sensor_fault_at_planning_reports_the_fault_again() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let hub_stuck = mmu_model::Fault::SensorDisconnected {
        sensor: mmu_model::SensorId::HubFilament,
        rail: mmu_model::Rail::High,
    };
    rig.inject(hub_stuck);
    rig.idle(1000);
    assert_eq!(rig.send(t(1)), Some(accepted(t(1))));
    assert_eq!(rig.query(), error(t(1), ErrorCode::FINDA_FLICKERS));
    press(&mut rig, ButtonCode::MIDDLE);
    rig.idle(50);
    assert_eq!(rig.query(), error(t(1), ErrorCode::FINDA_FLICKERS));
    rig.model.clear_all();
    rig.idle(1000);
    press(&mut rig, ButtonCode::MIDDLE);
    rig.tool_change_goes_on_and_loads(1);
}

// ---- #1: 8005 FIL. ALREADY LOADED ---------------------------------------------------------------

/// Continue (`B1` from a Buddy printer) leaves the loaded slot as it is and finishes.
#[test]
fn continue_on_filament_already_loaded_finishes_the_preload() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    let preload = Request::new(RequestCode::Load, 1);
    assert_eq!(rig.send(preload), Some(accepted(preload)));
    assert_eq!(rig.query(), error(preload, ErrorCode::FILAMENT_ALREADY_LOADED));
    press(&mut rig, ButtonCode::MIDDLE);
    rig.idle(5);
    assert_eq!(rig.query(), finished(preload));
    assert_eq!(rig.model.loaded_slot(), Some(0));
}

// ---- #2: Home loops the printer ------------------------------------------------------------------

/// The printer's idle check accepts only T/L/U/E/K/M/X echoes (`protocol_logic.cpp` `IdleStep`;
/// printer-truth §3): `H0 F0` once ends the printer's `H0`, then the unit is idle as `X0 F0`.
#[test]
fn home_answers_h0_f0_once_then_x0_f0() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let home = Request::new(RequestCode::Home, 0);
    let run = rig.command(home);
    assert_eq!(run.last, finished(home));
    for _ in 0..3 {
        rig.idle(1000);
        assert_eq!(rig.query().encode().as_bytes(), b"X0 F0*87\n");
    }
    assert_eq!(rig.command(t(0)).last, finished(t(0)));
}

// ---- #3: the first answer after power-up ------------------------------------------------------------

/// Step a freshly powered unit for `ms`, sending `Q0` as often as the line allows (each after a
/// quiet line); every answer, with its time.
fn answers_after_power_up(rig: &mut Rig<3>, ms: u64) -> Vec<(u64, Response)> {
    let period = u64::from(mmu_protocol::SILENCE_MS) + 1;
    let mut answers = Vec::new();
    while rig.now < ms {
        let bytes = if rig.now.is_multiple_of(period) {
            Request::new(RequestCode::Query, 0).encode().as_bytes().to_vec()
        } else {
            Vec::new()
        };
        let now = rig.now;
        answers.extend(rig.step_with(&bytes).into_iter().map(|a| (now, a)));
    }
    answers
}

/// MMU 3.0.3 enables its receiver only after the start-up check (`main.cpp` `setup2`;
/// printer-truth §4): no `X0 P1a`, which opens Buddy's Homing dialog, only silence and then the
/// check's result, within about a second.
#[test]
fn first_answer_after_power_up_is_the_start_up_result_not_p1a() {
    let mut rig = Rig::<3>::new();
    let answers = answers_after_power_up(&mut rig, 2000);
    let (first_at, first) = answers.first().cloned().expect("the unit answers within 2 s");
    assert_eq!(first.encode().as_bytes(), b"X0 F0*87\n");
    assert!(first_at <= 1000, "silent for {first_at} ms");
    assert!(answers.iter().all(|(_, a)| a.param != ParamCode::Processing));
}

/// The same with filament in the hub at power-up: the first answer is the error.
#[test]
fn first_answer_after_power_up_with_a_start_up_error_is_the_error() {
    let mut rig = Rig::<3>::new();
    rig.model.insert_filament(0, 30.0);
    let answers = answers_after_power_up(&mut rig, 2000);
    let (first_at, first) = answers.first().cloned().expect("the unit answers within 2 s");
    assert_eq!(first.encode().as_bytes(), b"X0 E8008*1b\n");
    assert!(first_at <= 1000, "silent for {first_at} ms");
}

/// Nothing the printer sends during the check is acted on either (the board ignores `X0`): whole
/// frames after a quiet line, at every moment of the check.
#[test]
fn requests_during_the_start_up_check_get_no_answer_and_no_action() {
    use mmu_firmware::{App, Config, Instant, Samples};
    let samples = Samples::<3>::uniform(2048);
    let mut bytes = Vec::new();
    for request in [
        Request::new(RequestCode::Version, 0),
        Request::new(RequestCode::Reset, 0),
        t(0),
        Request::new(RequestCode::Query, 0),
    ] {
        bytes.extend_from_slice(request.encode().as_bytes());
    }
    let mut during_check = 0;
    for at in u64::from(mmu_protocol::SILENCE_MS)..=40 {
        let mut app = App::<3>::new(Config::default());
        for ms in 0..at {
            assert!(app.step(Instant::from_millis(ms), &samples, &[]).tx.is_empty());
        }
        if app.is_listening() {
            continue;
        }
        during_check += 1;
        let out = app.step(Instant::from_millis(at), &samples, &bytes);
        assert!(out.tx.is_empty(), "at {at} ms answered {:?}", out.tx);
        assert_eq!(out.action, None, "at {at} ms");
        assert_eq!(
            app.operation().request.0,
            RequestCode::Reset,
            "no command started"
        );
    }
    assert!(during_check > 0, "the check ended before a frame could arrive");
}

// ---- Any Prusa printer, no configuration: version negotiation -----------------------------------

fn version(rig: &mut Rig<3>, part: u8) -> Option<u16> {
    rig.send(Request::new(RequestCode::Version, part))
        .and_then(|a| a.param_value)
}

/// On a version answer that does not match, Prusa's printer sends the same `S<n>` again at once,
/// up to six mismatches per handshake (`protocol_logic.cpp` `ProcessVersionResponse`;
/// printer-truth §5). `S2` asked again with nothing between is answered with the next
/// revision of the cycle 4, 3, 2, 1, 0 (MMU 3.0.0 to 3.0.4 speak the same wire).
#[test]
fn s2_asked_again_answers_the_next_revision_of_the_cycle() {
    let mut rig = Rig::<3>::new();
    rig.idle(200);
    assert_eq!(version(&mut rig, 0), Some(3));
    assert_eq!(version(&mut rig, 1), Some(0));
    let answers: Vec<_> = (0..6).map(|_| version(&mut rig, 2)).collect();
    assert_eq!(answers, [Some(4), Some(3), Some(2), Some(1), Some(0), Some(4)]);
    // Any other request starts the sequence over.
    rig.query();
    assert_eq!(version(&mut rig, 2), Some(4));
    assert_eq!(version(&mut rig, 2), Some(3));
    rig.query();
    assert_eq!(version(&mut rig, 2), Some(4));
}

/// Register 0x52 stays the first answer (and the override); the other revisions follow.
#[test]
fn s2_negotiation_starts_from_register_0x52() {
    let mut rig = Rig::<3>::new();
    rig.idle(200);
    assert_eq!(
        rig.send(Request::write(0x52, 2)).map(|a| a.param),
        Some(ParamCode::Accepted)
    );
    let answers: Vec<_> = (0..5).map(|_| version(&mut rig, 2)).collect();
    assert_eq!(answers, [Some(2), Some(4), Some(3), Some(1), Some(0)]);
    assert_eq!(
        rig.send(Request::write(0x52, 5)).map(|a| a.param),
        Some(ParamCode::Rejected),
        "no MMU 3.0.5 to offer"
    );
}

// ---- #8: dropped answers are invisible ------------------------------------------------------------

/// Requests for one step: `reads` register reads, then `last`.
fn burst(reads: usize, last: Request) -> Vec<u8> {
    let mut bytes = Vec::new();
    for _ in 0..reads {
        bytes.extend_from_slice(Request::new(RequestCode::Read, 0x08).encode().as_bytes());
    }
    bytes.extend_from_slice(last.encode().as_bytes());
    bytes
}

/// A burst of requests in one step overflows the step's answers: the request whose answer does
/// not fit is not acted on (the printer, getting no answer, sends it again) and the drop is
/// counted in register 0x51.
#[test]
fn a_request_whose_answer_does_not_fit_is_not_acted_on_and_is_counted() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.model.insert_filament(1, 5.0);
    rig.idle(100);
    rig.send(Request::new(RequestCode::Home, 0));
    rig.idle(10);
    assert_eq!(rig.query().param, ParamCode::Error);
    rig.model.insert_filament(1, -15.0);
    rig.idle(100);
    let b1 = Request::new(RequestCode::Button, 1);
    let answers = rig.step_with(&burst(10, b1));
    assert!(answers.len() < 11, "the burst overflows one step: {answers:?}");
    assert!(!answers.contains(&accepted(b1)));
    rig.idle(10);
    assert_eq!(
        rig.query().param,
        ParamCode::Error,
        "the unanswered B1 was not acted on"
    );
    let dropped = rig
        .send(Request::new(RequestCode::Read, 0x51))
        .and_then(|a| a.param_value);
    assert_eq!(dropped, Some((11 - answers.len()) as u16));
    // The printer sends it again and it works.
    assert_eq!(rig.send(b1), Some(accepted(b1)));
    rig.idle(10);
    assert_eq!(rig.query(), finished(Request::new(RequestCode::Home, 0)));
}

/// `L1` while slot 0 is loaded, then the screen's Unload: `B0` from a Buddy printer, `B2` from
/// an MK3S (printer-truth §1.2: Buddy's `ButtonAvailable` sends the first button's index, the
/// MK3S's sends Left for Unload). The loaded slot comes out and is parked, then slot 1 is
/// preloaded as asked.
#[test]
fn unload_on_filament_already_loaded_unloads_then_preloads() {
    for unload in [ButtonCode::RIGHT, ButtonCode::LEFT] {
        let mut rig = Rig::<3>::new();
        rig.boot();
        rig.command(t(0));
        rig.idle(2000);
        let preload = Request::new(RequestCode::Load, 1);
        assert_eq!(rig.send(preload), Some(accepted(preload)));
        assert_eq!(rig.query(), error(preload, ErrorCode::FILAMENT_ALREADY_LOADED));
        // The filament is out of the extruder's gears (the printer does not pull it out for
        // this screen: its `CheckUserInput` helps only on 8004/8009; gripped, the unload stalls).
        rig.unload_extruder();
        press(&mut rig, unload);
        let run = rig.follow(preload, 120_000);
        assert_eq!(run.last, finished(preload), "B{}: {:?}", unload.0, run.progress);
        assert_eq!(rig.model.loaded_slot(), None, "B{}", unload.0);
        for slot in [0, 1] {
            let tip = rig.model.tip_mm(slot).unwrap();
            assert!(
                (tip + 15.0).abs() <= 5.0,
                "B{}: slot {slot} parked, tip at {tip} mm",
                unload.0
            );
        }
    }
}
