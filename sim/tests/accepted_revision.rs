//! The revision a printer accepted is the unit's identity (register 0x52): kept in the store,
//! across a power cut and across `X42`, even when the store has not saved it yet.

use mmu_firmware::Instant;
use mmu_protocol::{Request, RequestCode};
use mmu_sim::cut::{Action, Flash, Unit};

const PAGES: usize = 3;

fn unit() -> Unit {
    Unit::boot(Flash::new(PAGES), PAGES, Instant::ZERO)
}

/// What the next `S2` answers, as text.
fn s2(unit: &mut Unit) -> String {
    unit.ask(Request::new(RequestCode::Version, 2)).0
}

#[test]
fn x42_right_after_a_revision_write_keeps_the_new_revision() {
    let mut unit = unit();
    // The write, and at once the erase: no save ran between them.
    unit.ask(Request::write(0x52, 2));
    unit = unit.act(0, &Action::Forget);
    assert!(s2(&mut unit).starts_with("S2 A2*"), "{}", s2(&mut unit));
}

#[test]
fn the_revision_a_printer_accepted_survives_a_power_cut_and_x42() {
    let mut unit = unit();
    // An MK3S on 3.14.1 connects to a fresh unit: 4 is wrong, 3 matches, then `S3`.
    assert!(s2(&mut unit).starts_with("S2 A4*"));
    assert!(s2(&mut unit).starts_with("S2 A3*"));
    let build = unit.ask(Request::new(RequestCode::Version, 3)).0;
    assert!(build.starts_with("S3 A380*"), "3.0.3's build, 896: {build}");
    // The printer's handshake goes on with its register writes; the unit saves meanwhile.
    unit = unit.act(10, &Action::Write(0x0b, 5));
    unit = unit.act(10, &Action::PowerCycle);
    assert!(s2(&mut unit).starts_with("S2 A3*"), "after the power cut");
    unit = unit.act(10, &Action::Forget);
    assert!(s2(&mut unit).starts_with("S2 A3*"), "after X42");
}
