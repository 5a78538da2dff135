//! Home (`H0`, `src/commands/home.rs`): nothing to home on this hardware; the unit checks its
//! sensors against the known state, as after a restart. Its happy path, and every error of the
//! start-up check's recovery table raised by `H0` on the rig, with what Retry then does.
//!
//! Also testing `H0`: `tests/printer_truth.rs` (`H0 F0` once, then `X0 F0`; a dropped `B1` after
//! an `H0` error).

mod common;

use common::{Rig, error, finished};
use mmu_protocol::{ErrorCode, Request, RequestCode};

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
