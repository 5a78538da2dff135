//! Each printer gets the unload contract it was released with (issue 20; `mmu-3.0.4.md`), and no
//! printer's gears are ever pulled against.
//!
//! A printer that accepted MMU 3.0.4 (Buddy >= 6.5.3) sends `T` before its own 80 mm finishing
//! retract, its gears still gripping the filament: the unit pulls nothing until the printer
//! reports its sensor off, at most 4 s, else `8004` with nothing pulled; then 20 mm slowly, then
//! fast (Prusa-Firmware-MMU `unload_to_finda.cpp`). A printer that accepted 3.0.3 or older pulls
//! its filament out of its gears before `T`, and the unit pulls at once, as 3.0.3 does.
//!
//! For the 3.0.4 printer the model's sensor sits past the extruder gears ([`released_by_retract`]):
//! the printer's retract takes the tip past its sensor while its gears still hold it, which is
//! what Buddy 6.5.3 relies on (its `T` first, `f0` about 0.7 s later). With the default geometry
//! (sensor before the gears) no retract of the printer's can clear its sensor.

mod common;

use common::{Rig, assert_parked, error, finished, loaded, press, t};
use mmu_firmware::drive::FEEL_DUTY;
use mmu_model::ModelConfig;
use mmu_protocol::{ButtonCode, ErrorCode, ParamCode, ProgressCode, Request, RequestCode};

/// A printer whose sensor lies 10 mm past its extruder gears (an MK4 with its MMU rework, as
/// Buddy 6.5.3 expects): its retract clears the sensor while the gears still hold the tip.
fn released_by_retract() -> ModelConfig {
    ModelConfig {
        extruder_gears_mm: 350.0,
        ..ModelConfig::default()
    }
}

/// Whether slot `slot`'s motor pulled back harder than a feel (which no gripped filament yields
/// to, `phases::unload`) in the steps from `from` on.
fn pulled_since(rig: &Rig<3>, slot: usize, from: usize) -> bool {
    rig.hardest_pull_since(slot, from) > FEEL_DUTY.permille()
}

#[test]
fn a_3_0_4_printer_s_tool_change_pulls_nothing_until_its_sensor_clears() {
    let mut rig = loaded(4, released_by_retract());
    let before = rig.motor_log.len();
    rig.issue(t(1));
    rig.follow_until_model(t(1), |model| model.fsensor_state() == 0, 6_000);
    assert!(
        !pulled_since(&rig, 0, before),
        "slot 0 pulled while the printer's gears gripped it"
    );
    let run = rig.follow(t(1), 120_000);
    assert_eq!(run.last, finished(t(1)));
    assert!(pulled_since(&rig, 0, before), "then it unloaded");
    assert_parked(&rig, 0);
    assert_eq!(rig.model.loaded_slot(), Some(1));
    // 3.0.4 reports `P3` throughout the wait, and no `P2` between unload and load.
    assert_eq!(run.progress[0], ProgressCode::UNLOADING_TO_FINDA);
    assert!(!run.progress.contains(&ProgressCode::DISENGAGING_IDLER));
}

/// Once released, the first 20 mm follow the printer's gears, which may still grip the filament
/// (MMU 3.0.4 pulls them at the slow speed, register 0x14): pulled no harder than a feel. Then
/// fast.
#[test]
fn a_3_0_4_unload_starts_with_the_gears_then_pulls_fast() {
    let mut rig = loaded(4, released_by_retract());
    rig.issue(t(1));
    rig.follow_until_model(t(1), |model| model.fsensor_state() == 0, 6_000);
    let from = rig.model.tip_mm(0).unwrap();
    let mut speeds = Vec::new();
    let mut last = from;
    while from - rig.model.tip_mm(0).unwrap() < 60.0 {
        let step = rig.motor_log.len();
        rig.printer_step(Some(ProgressCode::UNLOADING_TO_FINDA));
        let pulled = from - rig.model.tip_mm(0).unwrap();
        assert!(
            pulled > 18.0 || !pulled_since(&rig, 0, step),
            "pulled harder than a feel {pulled} mm into the unload"
        );
        if rig.now.is_multiple_of(100) {
            let tip = rig.model.tip_mm(0).unwrap();
            speeds.push(((from - tip) as i32, ((last - tip) * 10.0) as i32));
            last = tip;
            rig.query();
        }
        assert!(rig.now < 200_000, "the unload never went 60 mm");
    }
    let fast: Vec<_> = speeds.iter().filter(|(at, _)| (30..60).contains(at)).collect();
    assert!(
        fast.iter().any(|(_, mm_s)| *mm_s >= 60),
        "then at the unload speed: {speeds:?}"
    );
}

#[test]
fn a_3_0_4_printer_whose_sensor_stays_on_gets_8004_after_4_s_without_a_pull() {
    let mut rig = loaded(4, released_by_retract());
    let tip = rig.model.tip_mm(0).unwrap();
    let before = rig.motor_log.len();
    // The printer's sensor reads filament and its extruder does not retract.
    rig.fsensor = common::FsensorReports::Stuck(1);
    let accepted_at = rig.now;
    assert_eq!(rig.send(t(1)).map(|a| a.param), Some(ParamCode::Accepted));
    let run = rig.follow(t(1), 10_000);
    assert_eq!(run.last, error(t(1), ErrorCode::FSENSOR_DIDNT_SWITCH_OFF));
    // 4 s after the feel took up the tube's give, the filament still.
    let waited = rig.now - accepted_at;
    assert!((4_000..=4_600).contains(&waited), "8004 after {waited} ms");
    assert_eq!(run.progress, [ProgressCode::UNLOADING_TO_FINDA]);
    assert!(!pulled_since(&rig, 0, before), "nothing pulled");
    assert!((rig.model.tip_mm(0).unwrap() - tip).abs() < 1.0);

    // Retry waits for the printer again, the same way: still nothing pulled.
    press(&mut rig, ButtonCode::MIDDLE);
    let run = rig.follow(t(1), 10_000);
    assert_eq!(run.last, error(t(1), ErrorCode::FSENSOR_DIDNT_SWITCH_OFF));
    assert!(!pulled_since(&rig, 0, before));

    // The printer retracts and reports truthfully: Retry unloads and the tool change finishes.
    rig.fsensor = common::FsensorReports::Truthful;
    rig.model.extruder_move(-80.0, 20.0);
    press(&mut rig, ButtonCode::MIDDLE);
    let run = rig.follow(t(1), 120_000);
    assert_eq!(run.last, finished(t(1)));
    assert_parked(&rig, 0);
    assert_eq!(rig.model.loaded_slot(), Some(1));
}

/// A printer that accepted 3.0.3 has pulled its filament out of its gears before it sends `T`:
/// the unit pulls at once, as MMU 3.0.3 does, even while the printer's sensor still reads it.
#[test]
fn a_3_0_3_printer_s_tool_change_pulls_at_once() {
    let mut rig = loaded(3, ModelConfig::default());
    retract(&mut rig, 60.0);
    assert_ne!(rig.model.fsensor_state(), 0, "the sensor still sees the tip");
    let before = rig.motor_log.len();
    assert_eq!(rig.send(t(1)).map(|a| a.param), Some(ParamCode::Accepted));
    rig.idle(500);
    assert!(
        pulled_since(&rig, 0, before),
        "pulled within 500 ms, once felt free"
    );
    let run = rig.follow(t(1), 120_000);
    assert_eq!(run.last, finished(t(1)));
    assert_parked(&rig, 0);
}

/// The printer's extruder retracts `mm` (at 40 mm/s, as its unload does), nothing else sent.
fn retract(rig: &mut Rig<3>, mm: f32) {
    rig.model.extruder_move(-mm, 40.0);
    while rig.model.extruder_busy() {
        rig.printer_step(None);
    }
}

fn l(slot: u8) -> Request {
    Request::new(RequestCode::Load, slot)
}

/// FIL. ALREADY LOADED (`L1` while slot 0 is in the nozzle), then `button`, which unloads: the
/// unit waits for the printer's help with its own extruder (it retracts on `P3`, Buddy
/// `OnMMUProgressMsgChanged`), pulls only then, parks slot 0 and preloads slot 1.
fn unload_button_unloads_then_preloads(revision: u8, model: ModelConfig, button: ButtonCode) {
    let mut rig = loaded(revision, model);
    let run = rig.command(l(1));
    assert_eq!(run.last, error(l(1), ErrorCode::FILAMENT_ALREADY_LOADED));
    let before = rig.motor_log.len();
    press(&mut rig, button);
    let run = rig.follow(l(1), 120_000);
    assert_eq!(run.last, finished(l(1)), "3.0.{revision}, {button:?}: {run:?}");
    assert_eq!(run.progress[0], ProgressCode::UNLOADING_TO_FINDA);
    assert_eq!(rig.model.loaded_slot(), None);
    assert_parked(&rig, 0);
    assert_parked(&rig, 1);
    // Never stalled against the printer's gears on the way.
    assert_eq!(rig.read(0x04), Some(0), "no error counted");
    assert!(pulled_since(&rig, 0, before));
}

#[test]
fn fil_already_loaded_unload_waits_for_the_printer_on_buddy_6_5_3() {
    unload_button_unloads_then_preloads(4, released_by_retract(), ButtonCode::LEFT);
}

#[test]
fn fil_already_loaded_unload_waits_for_the_printer_on_buddy_6_4() {
    unload_button_unloads_then_preloads(3, ModelConfig::default(), ButtonCode::LEFT);
}

/// The MK3S's screen has Unload on its Right button (`B2`) and Done (`B0`), which this unit
/// cannot tell from Buddy's Unload: both unload.
#[test]
fn fil_already_loaded_unload_and_done_wait_for_the_printer_on_the_mk3s() {
    for button in [ButtonCode::RIGHT, ButtonCode::LEFT] {
        unload_button_unloads_then_preloads(2, ModelConfig::default(), button);
    }
}

/// Continue (`B1`) leaves the loaded slot where it is.
#[test]
fn fil_already_loaded_continue_leaves_the_filament_loaded_on_every_printer() {
    for (revision, model) in [(4, released_by_retract()), (3, ModelConfig::default())] {
        let mut rig = loaded(revision, model);
        let run = rig.command(l(1));
        assert_eq!(run.last, error(l(1), ErrorCode::FILAMENT_ALREADY_LOADED));
        press(&mut rig, ButtonCode::MIDDLE);
        let run = rig.follow(l(1), 10_000);
        assert_eq!(run.last, finished(l(1)));
        assert_eq!(rig.model.loaded_slot(), Some(0));
    }
}

/// `U0` on a 3.0.3 printer whose sensor is still on after its own unload: the unit pulls at
/// once, the printer's gears hold the tip and the motor stalls against them; that is `8004`
/// (FSENSOR DIDNT CLEAR, as MMU 3.0.3 reports it), not `8047`, and its Retry, on which the printer
/// helps with its extruder, waits for that help before it pulls, and unloads.
#[test]
fn a_3_0_3_unload_held_by_the_printer_s_gears_is_8004_and_retry_unloads() {
    let mut rig = loaded(3, ModelConfig::default());
    let unload = Request::new(RequestCode::Unload, 0);
    // The printer's own retract fell short: its gears still hold the tip.
    retract(&mut rig, 45.0);
    assert!(rig.model.tip_mm(0).unwrap() > rig.model.config().extruder_gears_mm);
    assert_eq!(rig.send(unload).map(|a| a.param), Some(ParamCode::Accepted));
    let run = rig.follow(unload, 10_000);
    assert_eq!(run.last, error(unload, ErrorCode::FSENSOR_DIDNT_SWITCH_OFF));
    // The Retry: the printer helps with its own extruder (`CheckUserInput`) and sends `B1`.
    rig.help_unload();
    let before = rig.motor_log.len();
    press(&mut rig, ButtonCode::MIDDLE);
    rig.idle(500);
    assert!(!pulled_since(&rig, 0, before), "no pull while the printer helps");
    let run = rig.follow(unload, 60_000);
    assert_eq!(run.last, finished(unload), "{run:?}");
    assert_parked(&rig, 0);
}
