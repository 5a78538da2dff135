//! The link to the printer beyond any one command: queries answered in the same step while a
//! command runs, bad frames, reset requests, register writes.
//!
//! The handshake is tested with the boot in `tests/start_up.rs`; version negotiation and dropped
//! answers in `tests/printer_truth.rs`.

mod common;

use common::{Rig, t};
use mmu_firmware::Config;
use mmu_model::ModelConfig;
use mmu_protocol::{ButtonCode, ParamCode, Request, RequestCode};

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

/// The persistence keeper snapshots the settings only when [`App::settings_revision`] moved: an
/// accepted setting write moves it; a refused write and the printer's filament sensor (0x09, the
/// Core One's `f`, written every few seconds) do not.
///
/// [`App::settings_revision`]: mmu_firmware::App::settings_revision
#[test]
fn only_an_accepted_setting_write_counts_as_a_settings_change() {
    let mut rig = Rig::<3>::new();
    rig.boot();
    let mut revision = rig.app.settings_revision();
    let mut write = |rig: &mut Rig<3>, address, value| {
        rig.send(Request::write(address, value)).unwrap();
        let moved = rig.app.settings_revision() != revision;
        revision = rig.app.settings_revision();
        moved
    };
    assert!(write(&mut rig, 0x22, 420), "a setting");
    assert!(write(&mut rig, 0x52, 2), "the reported revision");
    let hub_off = rig.read(0xa0).unwrap();
    assert!(write(&mut rig, 0xa0, hub_off - 10), "a threshold");
    assert!(!write(&mut rig, 0x22, 5), "refused: out of range");
    assert!(!write(&mut rig, 0x00, 9), "refused: read only");
    assert!(
        !write(&mut rig, 0x09, 1),
        "the printer's sensor is state, not a setting"
    );
}
