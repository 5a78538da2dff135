//! Cut (`K<n>`, `src/commands/cut.rs`): this unit has no blade, so `K` unloads whatever is loaded
//! and re-parks slot *n* (fed to the hub, parked again). Its happy path, and every error of its
//! recovery tables (its own, the unload's, the preload's motions, the shared motion rows) raised
//! on the rig, with what Retry then does.

mod common;

use common::{Rig, assert_parked, finished, t};
use mmu_protocol::{ProgressCode as P, Request, RequestCode};

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
