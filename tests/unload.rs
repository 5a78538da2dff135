//! UnloadFromNozzle (`U0`, `src/commands/unload_from_nozzle.rs`): the slot that owns the hub path
//! comes back out of the printer and the hub and is parked. Its happy paths, and every error of
//! its recovery table and the shared motion rows raised on the rig, with what Retry then does.
//!
//! Also testing `U0`: `tests/safe_motion.rs` (Retry with the printer's sensor still stuck never
//! pulls the filament out of its drive), `tests/tool_change.rs`, `tests/eject.rs` and
//! `tests/cut.rs` (the unload as the first half of those commands).

mod common;

use common::{FsensorReports, Rig, assert_parked, error, finished, t};
use mmu_protocol::{ErrorCode, ParamCode, ProgressCode as P, Request, RequestCode};

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
