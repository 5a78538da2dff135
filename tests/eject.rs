//! Eject (`E<n>`, `src/commands/eject.rs`): slot *n*'s filament is pulled out past its slot
//! sensor, then the unit asks the user to take it (`E800c`) and waits for Continue. Its happy
//! paths, and every error of its recovery tables (its own, the unload's when slot *n* is loaded,
//! the shared motion rows) raised on the rig, with what the printer's buttons then do.
//!
//! Also testing `E`: `tests/printer_truth.rs` (a `T` sent over the eject's question).

mod common;

use common::{Rig, error, finished, t};
use mmu_protocol::{ErrorCode, ParamCode, ProgressCode as P, Request, RequestCode};

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
