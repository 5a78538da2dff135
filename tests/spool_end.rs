//! A spool that ends while the printer prints ([`mmu_firmware::spool_end`]): the loose end that
//! passes the loaded slot's sensor empties FINDA (register 0x08 and `P0`) so that the printer's
//! own runout check starts its filament change; so does an end fastened to the core on a spool
//! counted within its uncertainty of empty; nothing else does. The printer's side of it, with
//! Prusa's logic on every printer family, is `sim/tests/spool_end.rs`.

mod common;

use common::{Rig, finished, t};
use mmu_firmware::spool_end::CONFIRM_MS;
use mmu_model::{Fault, Rail, SensorId};
use mmu_protocol::{ParamCode, Request, RequestCode};

/// Slot 0 loaded by a tool change, the printer printing at 1 mm/s for 5 s.
fn printing() -> Rig<3> {
    let mut rig = Rig::<3>::new();
    rig.boot();
    rig.command(t(0));
    rig.model.set_printing(Some(1.0));
    rig.idle(5_000);
    assert_eq!(rig.read(0x08), Some(1), "FINDA sees the filament while printing");
    rig
}

/// What `P0` answers.
fn p0(rig: &mut Rig<3>) -> Option<u16> {
    rig.send(Request::new(RequestCode::Finda, 0))
        .and_then(|a| a.param_value)
}

#[test]
fn a_loose_spool_end_empties_finda_while_the_hub_still_holds_the_tail() {
    let mut rig = printing();
    rig.inject(Fault::SpoolRunout { slot: 0 });
    rig.idle(CONFIRM_MS + 500);
    assert_eq!(rig.read(0x08), Some(0), "FINDA reports the runout");
    assert_eq!(p0(&mut rig), Some(0));
    assert!(
        rig.model.hub_filament_present(),
        "the tail has not reached the hub"
    );
    // No error: the printer's own runout handling takes it from here.
    assert_eq!(rig.query(), finished(t(0)));
    // The slot's drive grips nothing now: it is not driven while the print goes on.
    let from = rig.motor_log.len();
    rig.idle(5_000);
    assert!(rig.motor_log[from..].iter().all(|m| !m[0].is_driving()));
    assert_eq!(rig.read(0x08), Some(0), "still reported");

    // The printer's M600: it rams and pulls the tail back behind the slot's drive gear, then
    // `U0`; the unit unloads and FINDA tells the hub sensor again.
    rig.model.set_printing(None);
    rig.model.extruder_move(-80.0, 80.0);
    rig.idle(1_500);
    let gear = rig.model.config().drive_gear_mm;
    let tail = rig.model.tail_mm(0).expect("the tail is in the slot");
    assert!(
        tail < gear,
        "ramming brought the tail back to the gear: {tail} mm"
    );
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.last, finished(unload));
    assert!(!rig.model.hub_filament_present());
    assert_eq!(rig.read(0x08), Some(0));
    assert_eq!(p0(&mut rig), Some(0));
}

#[test]
fn a_tangle_while_printing_stays_a_jam_and_finda_keeps_telling_the_hub() {
    let mut rig = printing();
    rig.inject(Fault::Jam { slot: 0 });
    rig.idle(30_000);
    let answer = rig.query();
    assert_eq!((answer.code, answer.param), (RequestCode::Tool, ParamCode::Error));
    assert_eq!(rig.read(0x08), Some(1), "a tangle is never a spool end");
}

/// Slot 0's spool counted as nearly used up: 1 m left (register 0x59), within the count's
/// uncertainty of empty.
fn nearly_used_up(rig: &mut Rig<3>) {
    let write = Request::write(0x59, 1);
    assert_eq!(rig.send(write).map(|a| a.param), Some(ParamCode::Accepted));
    assert_eq!(rig.read(0x59), Some(1));
}

#[test]
fn a_fastened_end_of_a_used_up_spool_empties_finda_and_the_unload_pulls_it_back() {
    let mut rig = printing();
    nearly_used_up(&mut rig);
    rig.inject(Fault::SpoolFastened { slot: 0 });
    rig.idle(10_000);
    assert_eq!(rig.read(0x08), Some(0), "FINDA reports the spool end");
    assert_eq!(p0(&mut rig), Some(0));
    assert_eq!(rig.query(), finished(t(0)), "no jam error");
    assert!(rig.model.hub_filament_present(), "the filament is whole");
    // The printer's M600: ramming, then `U0` pulls the filament back toward the spool.
    rig.model.set_printing(None);
    rig.model.extruder_move(-80.0, 80.0);
    rig.idle(1_500);
    let unload = Request::new(RequestCode::Unload, 0);
    let run = rig.command(unload);
    assert_eq!(run.last, finished(unload));
    assert!(!rig.model.hub_filament_present());
    assert_eq!(rig.read(0x08), Some(0));
}

#[test]
fn a_fastened_end_or_a_tangle_with_filament_left_stays_a_jam() {
    for fault in [Fault::SpoolFastened { slot: 0 }, Fault::Jam { slot: 0 }] {
        let mut rig = printing();
        rig.inject(fault);
        rig.idle(30_000);
        let answer = rig.query();
        assert_eq!(
            (answer.code, answer.param),
            (RequestCode::Tool, ParamCode::Error),
            "{fault:?}"
        );
        assert_eq!(rig.read(0x08), Some(1), "{fault:?}: never a spool end");
    }
}

#[test]
fn a_slot_or_hub_sensor_that_fails_while_printing_is_never_a_spool_end() {
    let sensors = [SensorId::SlotFilament(0), SensorId::HubFilament];
    for (sensor, rail) in sensors
        .into_iter()
        .flat_map(|s| [(s, Rail::Low), (s, Rail::High)])
    {
        let mut rig = printing();
        rig.inject(Fault::SensorDisconnected { sensor, rail });
        for _ in 0..20 {
            rig.idle(500);
            assert_eq!(rig.read(0x08), Some(1), "{sensor:?} {rail:?}");
        }
    }
}

#[test]
fn no_spool_end_while_a_command_runs() {
    // An eject of another slot runs while slot 0 prints; its end comes meanwhile: the report
    // waits for the unit to be idle again.
    let mut rig = printing();
    rig.inject(Fault::SpoolRunout { slot: 0 });
    let eject = Request::new(RequestCode::Eject, 1);
    assert_eq!(rig.send(eject).map(|a| a.param), Some(ParamCode::Accepted));
    rig.idle(CONFIRM_MS + 200);
    let answer = rig.query();
    assert_eq!(
        (answer.code, answer.param),
        (RequestCode::Eject, ParamCode::Processing),
        "{answer:?}"
    );
    assert_eq!(rig.read(0x08), Some(1), "no report while the eject runs");
}
