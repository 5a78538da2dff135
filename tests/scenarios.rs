//! Whole operations as the printer drives them, against the physical model in virtual time.

mod common;

use common::{FsensorReports, Rig};
use mmu_firmware::Config;
use mmu_model::{Fault, ModelConfig, Rail, SensorId};
use mmu_protocol::{
    ButtonCode, ErrorCode, ParamCode, ProgressCode as P, Request, RequestCode, Response, ResultCode,
};

fn t(slot: u8) -> Request {
    Request::new(RequestCode::Tool, slot)
}

fn finished(request: Request) -> Response {
    Response::finished(request.code, request.value, ResultCode::OK)
}

fn error(request: Request, code: ErrorCode) -> Response {
    Response::error(request.code, request.value, code)
}

const PARK_MM: f32 = -15.0;

fn assert_parked(rig: &Rig<3>, slot: usize) {
    let tip = rig.model.tip_mm(slot).unwrap();
    assert!(
        (tip - PARK_MM).abs() <= 5.0,
        "slot {slot} should rest near the park position, tip at {tip} mm"
    );
}

#[test]
fn boot_reports_x0_f0_and_the_handshake_matches_mmu_3_0_3() {
    let mut rig = Rig::<3>::new();
    rig.idle(200);
    assert_eq!(rig.query().encode().as_bytes(), b"X0 F0*87\n");
    let wire: Vec<String> = rig.handshake().iter().map(|r| r.encode().to_string()).collect();
    assert_eq!(wire[..4], ["S0 A3*22", "S1 A0*34", "S2 A3*70", "S3 A1*73"]);
    assert_eq!(wire[4..], ["Wb A*5c", "W14 A*52", "f0 A*c5"]);
    assert_eq!(rig.app.config().extra_load_mm, 5);
}

#[test]
fn tool_change_loads_to_the_nozzle_with_the_mmu3_progress_sequence() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let run = rig.command(t(0));
    assert_eq!(
        run.progress,
        [
            P::FEEDING_TO_FINDA,
            P::FEEDING_TO_BONDTECH,
            P::FEEDING_TO_FSENSOR,
            P::FEEDING_TO_NOZZLE
        ]
    );
    assert_eq!(run.last, finished(t(0)));
    assert!(
        rig.model.fsensor_state() >= 1,
        "the filament reached the printer's sensor"
    );
    assert_eq!(rig.model.loaded_slot(), Some(0));
    // The slot motor follows the extruder's last push, then rests.
    rig.idle(2000);
    assert!(rig.motors_stopped());
    // Register 0x07 says InNozzle, the selector register says slot 0.
    assert_eq!(
        rig.send(Request::new(RequestCode::Read, 7)).unwrap().param_value,
        Some(8)
    );
    assert_eq!(
        rig.send(Request::new(RequestCode::Read, 0x1b))
            .unwrap()
            .param_value,
        Some(0)
    );
}

#[test]
fn tool_change_to_another_slot_unloads_first_and_parks_the_old_one() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    let run = rig.command(t(2));
    assert_eq!(
        run.progress,
        [
            P::UNLOADING_TO_FINDA,
            P::RETRACTING_FROM_FINDA,
            P::FEEDING_TO_FINDA,
            P::FEEDING_TO_BONDTECH,
            P::FEEDING_TO_FSENSOR,
            P::FEEDING_TO_NOZZLE
        ]
    );
    assert_eq!(run.last, finished(t(2)));
    assert_parked(&rig, 0);
    assert_eq!(rig.model.loaded_slot(), Some(2));
}

#[test]
fn tool_change_to_the_loaded_slot_finishes_at_once() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(1));
    rig.idle(3000);
    let tip = rig.model.tip_mm(1).unwrap();
    let run = rig.command(t(1));
    assert!(run.progress.is_empty());
    assert_eq!(run.last, finished(t(1)));
    assert!((rig.model.tip_mm(1).unwrap() - tip).abs() < 1.0);
}

#[test]
fn unload_pulls_back_to_the_park_position() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(1));
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.progress, [P::UNLOADING_TO_FINDA, P::RETRACTING_FROM_FINDA]);
    assert_eq!(run.last, finished(unload));
    assert_parked(&rig, 1);
    assert_eq!(rig.model.fsensor_state(), 0);
}

#[test]
fn unload_with_nothing_loaded_finishes_at_once() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert!(run.progress.is_empty());
    assert_eq!(run.last, finished(unload));
}

#[test]
fn preload_feeds_to_the_hub_and_parks() {
    let mut rig = Rig::<3>::new();
    rig.model.insert_filament(1, -90.0);
    rig.boot();
    let load = Request::new(RequestCode::Load, 1);
    let run = rig.command(load);
    assert_eq!(run.progress, [P::FEEDING_TO_FINDA, P::RETRACTING_FROM_FINDA]);
    assert_eq!(run.last, finished(load));
    assert_parked(&rig, 1);
}

#[test]
fn eject_waits_for_continue_then_finishes() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let eject = Request::new(RequestCode::Eject, 1);
    let run = rig.command(eject);
    assert_eq!(run.progress, [P::EJECTING_FILAMENT]);
    assert_eq!(run.last, error(eject, ErrorCode::FILAMENT_EJECTED));
    assert_eq!(rig.model.slot_filament_present(1), Some(false));
    assert!(rig.motors_stopped());
    assert_eq!(
        rig.send(Request::new(RequestCode::Button, 1)).unwrap().param,
        ParamCode::Accepted
    );
    rig.idle(5);
    assert_eq!(rig.query(), finished(eject));
}

#[test]
fn eject_of_the_loaded_slot_unloads_it_first() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    let eject = Request::new(RequestCode::Eject, 0);
    let run = rig.command(eject);
    assert_eq!(
        run.progress,
        [
            P::UNLOADING_TO_FINDA,
            P::RETRACTING_FROM_FINDA,
            P::EJECTING_FILAMENT
        ]
    );
    assert_eq!(run.last, error(eject, ErrorCode::FILAMENT_EJECTED));
}

#[test]
fn a_slot_the_unit_does_not_have_is_accepted_then_reported_invalid() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    assert_eq!(rig.send(t(3)).unwrap().encode().as_bytes(), b"T3 A*75\n");
    assert_eq!(rig.query(), error(t(3), ErrorCode::INVALID_TOOL));
    assert!(rig.motors_stopped());
    // The printer stops the print or resets the unit: the next command is not refused forever.
    assert_eq!(rig.send(t(0)).unwrap().param, ParamCode::Accepted);
}

#[test]
fn cut_reparks_the_slot_as_this_unit_has_no_blade() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(2));
    let cut = Request::new(RequestCode::Cut, 2);
    let run = rig.command(cut);
    assert_eq!(
        run.progress,
        [
            P::UNLOADING_TO_FINDA,
            P::RETRACTING_FROM_FINDA,
            P::FEEDING_TO_FINDA,
            P::RETRACTING_FROM_FINDA
        ]
    );
    assert_eq!(run.last, finished(cut));
    assert_parked(&rig, 2);
}

#[test]
fn home_checks_the_sensors_against_the_known_state() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let home = Request::new(RequestCode::Home, 0);
    let run = rig.command(home);
    assert_eq!(run.last, finished(home));
    // Filament pushed into the hub by hand: the unit does not know whose it is.
    rig.model.insert_filament(1, 5.0);
    rig.idle(100);
    let run = rig.command(home);
    assert_eq!(run.last, error(home, ErrorCode::FINDA_VS_EEPROM_DISREPANCY));
}

#[test]
fn filament_in_the_hub_at_start_asks_for_a_manual_unload() {
    let mut rig = Rig::<3>::new();
    rig.model.insert_filament(0, 30.0);
    assert_eq!(rig.boot().encode().as_bytes(), b"X0 E8008*1b\n");
    rig.model.insert_filament(0, -15.0);
    rig.idle(100);
    rig.send(Request::new(RequestCode::Button, 1));
    rig.idle(5);
    assert_eq!(rig.query().encode().as_bytes(), b"X0 F0*87\n");
}

// ---- error paths: the right code, every motor stopped --------------------------------------

fn failing_tool_change(rig: &mut Rig<3>, slot: u8, code: ErrorCode) {
    let run = rig.command(t(slot));
    assert_eq!(run.last, error(t(slot), code), "progress {:?}", run.progress);
    rig.idle(10);
    assert!(rig.motors_stopped(), "every motor stops on {code}");
}

#[test]
fn hub_never_sees_the_tip() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    // A hub threshold no reading reaches: the tip passes unseen.
    assert_eq!(
        rig.send(Request::write(0x90, 4090)).unwrap().param,
        ParamCode::Accepted
    );
    failing_tool_change(&mut rig, 0, ErrorCode::FINDA_DIDNT_SWITCH_ON);
    // Before a preload the unit does not know where the tip is: the bound is the preload distance.
    let tip = rig.model.tip_mm(0).unwrap();
    let bound = PARK_MM + f32::from(rig.app.config().preload_max_mm) + 5.0;
    assert!(
        tip < bound,
        "the search is bounded: tip at {tip} mm, bound {bound} mm"
    );
}

#[test]
fn hub_never_clears_on_unload() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    // An "off" threshold no reading goes below: the hub seems to hold filament forever.
    assert_eq!(
        rig.send(Request::write(0xa0, 50)).unwrap().param,
        ParamCode::Accepted
    );
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.last, error(unload, ErrorCode::FINDA_DIDNT_SWITCH_OFF));
    assert!(rig.motors_stopped());
}

#[test]
fn printer_sensor_never_triggers_then_retry_recovers() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.fsensor = FsensorReports::Stuck(0);
    failing_tool_change(&mut rig, 1, ErrorCode::FSENSOR_DIDNT_SWITCH_ON);
    // The sensor works again (the printer reports it at once); the printer (or the user)
    // presses Retry.
    rig.fsensor = FsensorReports::Truthful;
    rig.printer_step(None);
    assert_eq!(
        rig.send(Request::new(RequestCode::Button, 1)).unwrap().param,
        ParamCode::Accepted
    );
    let run = rig.follow(t(1), 120_000);
    assert_eq!(run.last, finished(t(1)));
    assert_eq!(rig.model.loaded_slot(), Some(1));
}

#[test]
fn printer_sensor_never_clears_on_unload() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.fsensor = FsensorReports::Stuck(1);
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.last, error(unload, ErrorCode::FSENSOR_DIDNT_SWITCH_OFF));
    assert!(rig.motors_stopped());
}

#[test]
fn printer_sensor_triggering_too_early() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.fsensor = FsensorReports::Stuck(1);
    failing_tool_change(&mut rig, 2, ErrorCode::FSENSOR_TOO_EARLY);
}

#[test]
fn stalled_motor() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::Jam { slot: 1 });
    failing_tool_change(&mut rig, 1, ErrorCode::STALLED_PULLEY);
}

#[test]
fn empty_slot_fails_without_moving() {
    let mut rig = Rig::<3>::new();
    rig.model.remove_filament(2);
    rig.boot();
    failing_tool_change(&mut rig, 2, ErrorCode::FINDA_DIDNT_SWITCH_ON);
    assert!(
        rig.motor_log.iter().all(|motors| !motors[2].is_driving()),
        "slot 2's motor never ran"
    );
}

#[test]
fn disconnected_hub_sensor_is_reported_not_believed() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::SensorDisconnected {
        sensor: SensorId::HubFilament,
        rail: Rail::High,
    });
    failing_tool_change(&mut rig, 0, ErrorCode::FINDA_FLICKERS);
    assert_eq!(
        rig.send(Request::new(RequestCode::Read, 0x50))
            .unwrap()
            .param_value,
        Some(1)
    );
}

#[test]
fn disconnected_motor_hall_sensor() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.inject(Fault::SensorDisconnected {
        sensor: SensorId::MotorHall(0),
        rail: Rail::Low,
    });
    failing_tool_change(&mut rig, 0, ErrorCode::MOVE_PULLEY_FAILED);
}

// ---- the protocol while commands run ---------------------------------------------------------

#[test]
fn queries_are_answered_in_the_same_step_while_a_command_runs() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    assert_eq!(rig.send(t(0)).unwrap().param, ParamCode::Accepted);
    rig.idle(300);
    // Feeding to the hub at the load speed (95 mm/s): the motor Hall sensor measures it.
    let speed = rig
        .send(Request::new(RequestCode::Read, 0xd0))
        .unwrap()
        .param_value
        .unwrap();
    assert!((80..=110).contains(&speed), "slot 0 feeds at {speed} mm/s");
    for request in [
        Request::new(RequestCode::Query, 0),
        Request::new(RequestCode::Read, 8),
        Request::new(RequestCode::Version, 2),
        Request::new(RequestCode::Finda, 0),
        Request::write(0x0b, 7),
        Request::new(RequestCode::FilamentSensor, 0),
        Request::new(RequestCode::Button, 0),
    ] {
        let answer = rig
            .send(request)
            .unwrap_or_else(|| panic!("{request:?} unanswered"));
        assert_eq!(
            (answer.code, answer.value),
            if request.code == RequestCode::Query {
                (RequestCode::Tool, 0)
            } else {
                (request.code, request.value)
            }
        );
    }
    assert_eq!(
        rig.send(t(1)).unwrap().param,
        ParamCode::Rejected,
        "busy: commands are refused"
    );
    assert_eq!(rig.query().param, ParamCode::Processing);
}

#[test]
fn bad_frames_get_silence_and_the_next_frame_is_answered() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    for garbage in [
        &b"T0*00\n"[..],
        b"Q0*EA\n",
        b"ok\n",
        b"\r\n",
        b"zzzz\n",
        b"F0*ef\n",
        b"M1*e\n",
    ] {
        assert_eq!(
            rig.send_bytes(garbage),
            None,
            "{:?}",
            String::from_utf8_lossy(garbage)
        );
    }
    // The MK4 bootloader probe bytes do not cost the next frame, sent after the printer's 1 s pause.
    assert_eq!(rig.send_bytes(b"SSE").map(|r| r.param), None);
    rig.idle(1000);
    assert_eq!(
        rig.send_bytes(b"S0*c6\n").unwrap().encode().as_bytes(),
        b"S0 A3*22\n"
    );
    assert!(rig.motors_stopped());
}

#[test]
fn reset_requests_a_board_action_without_an_answer() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let samples = rig.model.samples::<3>();
    let out = rig
        .app
        .step(mmu_firmware::Instant::from_millis(rig.now), &samples, b"X2a*88\n");
    assert!(out.tx.is_empty());
    assert_eq!(out.action, Some(mmu_firmware::BoardAction::EraseAndReset));
    let out = rig.app.step(
        mmu_firmware::Instant::from_millis(rig.now + 1),
        &samples,
        b"X0*4c\n",
    );
    assert_eq!(out.action, Some(mmu_firmware::BoardAction::Reset));
}

#[test]
fn register_writes_are_validated() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let param = |rig: &mut Rig<3>, request| rig.send(request).unwrap().param;
    assert_eq!(param(&mut rig, Request::write(0x22, 420)), ParamCode::Accepted);
    assert_eq!(
        rig.send(Request::new(RequestCode::Read, 0x22))
            .unwrap()
            .param_value,
        Some(420)
    );
    assert_eq!(
        param(&mut rig, Request::write(0x22, 5)),
        ParamCode::Rejected,
        "out of range"
    );
    assert_eq!(
        param(&mut rig, Request::write(0x0b, 256)),
        ParamCode::Rejected,
        "u8 register"
    );
    assert_eq!(
        param(&mut rig, Request::write(0x00, 9)),
        ParamCode::Rejected,
        "read only"
    );
    assert_eq!(
        param(&mut rig, Request::write(0x99, 1)),
        ParamCode::Rejected,
        "no such register"
    );
    assert_eq!(
        param(&mut rig, Request::write(0x90, 100)),
        ParamCode::Rejected,
        "on must stay above off"
    );
    assert_eq!(
        rig.send(Request::new(RequestCode::Read, 0x81)).unwrap().param,
        ParamCode::Rejected
    );
    // Diagnostics: raw and filtered hub readings, the slot count.
    assert_eq!(
        rig.send(Request::new(RequestCode::Read, 0x40))
            .unwrap()
            .param_value,
        Some(3)
    );
    let filtered = rig
        .send(Request::new(RequestCode::Read, 0x70))
        .unwrap()
        .param_value
        .unwrap();
    assert!(
        (1900..2200).contains(&filtered),
        "hub at rest filters to about mid-scale: {filtered}"
    );
    let _ = (Config::default(), ModelConfig::default(), ButtonCode::MIDDLE);
}
