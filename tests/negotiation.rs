//! Every current printer connects with default settings (issue 20, "Negotiation"): Buddy 6.5.3
//! wants MMU 3.0.4, Buddy 6.4 and MK3S 3.14.1 3.0.3, MK3S 3.13.3/3.14.0 3.0.2, older firmware
//! 3.0.1 or 3.0.0. The printer's check is played as Prusa's `protocol_logic.cpp`
//! `ProcessVersionResponse` plays it ([`Rig::negotiate`]): five wrong answers tolerated, the
//! sixth final. The unit keeps the revision a printer accepted and offers it first next time,
//! and gives each printer the contract it was released with.

mod common;

use common::Rig;
use mmu_firmware::App;
use mmu_firmware::config::{Contract, build_of};
use mmu_protocol::{ParamCode, Request, RequestCode, Response, ResultCode};

fn version(part: u8) -> Request {
    Request::new(RequestCode::Version, part)
}

fn started<const N: usize>() -> Rig<N> {
    let mut rig = Rig::<N>::new();
    rig.idle(200);
    rig
}

#[test]
fn a_printer_wanting_any_revision_connects_to_a_fresh_unit_within_its_budget() {
    for wanted in [4u8, 3, 2, 1, 0] {
        let mut rig = started::<3>();
        let wrong = rig.negotiate(wanted);
        let wrong = wrong.unwrap_or_else(|wrong| panic!("3.0.{wanted}: gave up after {wrong:?}"));
        // The cycle 4, 3, 2, 1, 0: a 3.0.4 printer (Buddy 6.5.3) hears no wrong answer, the
        // oldest four.
        assert_eq!(wrong.len(), usize::from(4 - wanted), "3.0.{wanted}: {wrong:?}");
        assert!(wrong.len() <= 5);
    }
}

#[test]
fn the_accepted_revision_is_offered_first_at_the_next_handshake_and_after_a_restart() {
    let mut rig = started::<3>();
    assert_eq!(rig.negotiate(2), Ok(vec![4, 3]));
    assert_eq!(
        rig.send(version(3)).and_then(|a| a.param_value),
        Some(build_of(2))
    );
    assert_eq!(rig.app.config().version.revision, 2);
    assert_eq!(rig.app.read_register(0x52), Some(2));
    // The printer restarts its handshake (a link timeout): no wrong answer now.
    assert_eq!(rig.negotiate(2), Ok(vec![]));
    // What the unit keeps across a restart carries it.
    let snapshot = rig.app.snapshot();
    assert!(snapshot.settings.contains(&(0x52, 2)), "{:?}", snapshot.settings);
    let mut restarted = App::<3>::default();
    restarted.restore(&snapshot);
    assert_eq!(restarted.config().version.revision, 2);
    // Another printer (an MK4 updated to 6.5.3) still connects, and is remembered in turn.
    assert_eq!(rig.negotiate(4), Ok(vec![2]));
    rig.send(version(3));
    assert_eq!(rig.app.config().version.revision, 4);
}

#[test]
fn only_an_s3_right_after_s2_is_taken_as_the_printer_accepting() {
    let mut rig = started::<3>();
    assert_eq!(rig.send(version(2)).and_then(|a| a.param_value), Some(4));
    assert_eq!(rig.send(version(2)).and_then(|a| a.param_value), Some(3));
    rig.query();
    rig.send(version(3));
    assert_eq!(
        rig.app.config().version.revision,
        4,
        "S3 after another request accepts nothing"
    );
}

#[test]
fn s3_reports_the_build_of_the_revision_the_printer_accepted() {
    for (wanted, build) in [(4u8, 936u16), (3, 896), (2, 878), (1, 844), (0, 814)] {
        let mut rig = started::<3>();
        rig.negotiate(wanted).unwrap();
        let answer = rig.send(version(3)).and_then(|a| a.param_value);
        assert_eq!(answer, Some(build), "3.0.{wanted}");
        assert_eq!(rig.app.read_register(0x03), Some(build));
    }
}

/// The cycle moves only on an `S2` that came after the unit's answer to the previous one: `S2`s
/// queued in one step were sent before the printer heard any answer, and are answered alike.
#[test]
fn s2_requests_queued_in_one_step_get_one_answer() {
    let mut rig = started::<3>();
    let mut burst = Vec::new();
    for _ in 0..4 {
        burst.extend_from_slice(version(2).encode().as_bytes());
    }
    let answers: Vec<_> = rig.step_with(&burst).iter().map(|a| a.param_value).collect();
    assert_eq!(answers, [Some(4); 4]);
    assert_eq!(rig.send(version(2)).and_then(|a| a.param_value), Some(3));
}

/// A printer whose answer to `S1` came late runs two handshakes interleaved (Buddy 6.5.3 with an
/// answer 350 ms late: `S1 S1 S2 S2`): the second `S2` is the second handshake's first ask, not
/// the printer refusing the first answer, and gets the same revision. The unit used to answer it
/// with the next one (3) and lock a 3.0.4 printer to the 3.0.3 contract.
#[test]
fn two_interleaved_handshakes_each_get_the_first_offer() {
    let mut rig = started::<3>();
    for part in [0, 0, 1, 1] {
        assert!(rig.send(version(part)).is_some());
    }
    assert_eq!(rig.send(version(2)).and_then(|a| a.param_value), Some(4));
    assert_eq!(rig.send(version(2)).and_then(|a| a.param_value), Some(4));
    rig.send(version(3));
    assert_eq!(rig.app.config().version.revision, 4);
    assert_eq!(rig.app.config().version.contract(), Contract::AwaitRelease);
    // A real refusal after them still moves the cycle on.
    for part in [0, 1] {
        rig.send(version(part));
    }
    assert_eq!(rig.send(version(2)).and_then(|a| a.param_value), Some(4));
    assert_eq!(rig.send(version(2)).and_then(|a| a.param_value), Some(3));
}

#[test]
fn each_printer_gets_the_contract_of_the_revision_it_accepted() {
    let m0 = Request::new(RequestCode::Mode, 0);
    let mut rig = started::<3>();
    rig.wants_revision = 3;
    rig.handshake();
    assert_eq!(rig.app.config().version.contract(), Contract::PullAtOnce);
    assert_eq!(rig.send(m0), None, "MMU 3.0.3 does not answer M");

    rig.wants_revision = 4;
    rig.handshake();
    assert_eq!(rig.app.config().version.contract(), Contract::AwaitRelease);
    // MMU 3.0.4 plans `M` as a command that finishes at once.
    assert_eq!(
        rig.send(m0),
        Some(Response::bare(RequestCode::Mode, 0, ParamCode::Accepted))
    );
    assert_eq!(
        rig.query(),
        Response::finished(RequestCode::Mode, 0, ResultCode::OK)
    );
    assert_eq!(rig.app.unit().selected, None, "M0 selects no slot");
}

/// Buddy 6.5.3 sends `S0` at once after power-on and again after each 200 ms answer timeout;
/// about 2 s of silence shows MMU_NOT_RESPONDING (`f60a5b03b156`). The unit answers once its
/// start-up check has run: well within that, and in the step the request completes in.
#[test]
fn the_first_s0_of_a_printer_without_a_bootloader_probe_is_answered_within_2_s() {
    let mut rig = Rig::<3>::new();
    let s0 = version(0);
    let answered_at = (0..10).find_map(|_| {
        let answer = rig.send(s0);
        if answer.is_some() {
            return Some(rig.now);
        }
        rig.idle(199);
        None
    });
    let answered_at = answered_at.expect("no S0 answered in 2 s");
    assert!(answered_at < 2_000, "first S0 answered at {answered_at} ms");
}
