//! Preload (`L<n>`, `src/commands/preload.rs`): slot *n* is fed until the hub sensor sees its
//! tip, then parked. Its happy path, and every error of its recovery table and the shared motion
//! rows raised on the rig, with what the printer's buttons then do.
//!
//! Also testing `L`: `tests/printer_truth.rs` (`8005` FILAMENT ALREADY LOADED: Continue, and
//! Unload from a Buddy printer and an MK3S).

mod common;

use common::{Rig, assert_parked, finished};
use mmu_protocol::{ProgressCode as P, Request, RequestCode};

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
