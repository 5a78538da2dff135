//! The start-up check (`X0` to the printer, `src/commands/start_up.rs`) and the boot: after a
//! restart the unit checks its sensors and the stored lanes before any command, then answers the
//! printer's handshake. The happy path, and every error of the check's recovery table raised on
//! the rig, with what Retry then does.
//!
//! Also testing the start-up: `tests/printer_truth.rs` (the first answer after power-up, requests
//! during the check, a command sent over a start-up error), `tests/safe_motion.rs` (no motion
//! while the check reports `8008`).

mod common;

use common::Rig;
use mmu_protocol::{Request, RequestCode};

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
