//! A load is reported done (`F0`) only when something other than a stopped tube shows the tip in
//! the extruder's gears (issue 11, case 2): a Bowden jam just short of the gears during the final
//! push (`P7`) compresses the tube exactly as the gears holding the tip do. What tells them apart
//! is the printer's own push after its sensor triggers (printer-truth §8): gears that hold the
//! tip pull the filament on, a jam does not. Checked against the three ways Prusa's printers
//! co-feed (MK4, MK3.5, MK3S) and with the printer's sensor unavailable (`f3`).

mod common;

use common::{FsensorReports, PrinterKind, Rig, error, finished, t};
use mmu_model::{Fault, FaultKind, Model, ModelConfig};
use mmu_protocol::{ErrorCode, ParamCode, ProgressCode as P};

/// The printer's sensor sits at 360 mm, its extruder's gears at 364 mm (the model's defaults).
const FSENSOR_MM: f32 = 360.0;

fn gears_mm<const N: usize>(rig: &Rig<N>) -> f32 {
    rig.model.config().extruder_gears_mm
}

/// `T0` on a fresh one-slot unit played by `printer`, until slot 0's tip is `past_fsensor_mm`
/// beyond the printer's sensor.
fn load_until_past_fsensor(printer: PrinterKind, past_fsensor_mm: f32) -> Rig<1> {
    let mut rig = Rig::<1>::new();
    rig.printer = printer;
    boot_and_load_until_past_fsensor(&mut rig, past_fsensor_mm);
    rig
}

/// Boot `rig` and issue `T0`, until slot 0's tip is `past_fsensor_mm` beyond the printer's
/// sensor.
fn boot_and_load_until_past_fsensor(rig: &mut Rig<1>, past_fsensor_mm: f32) {
    rig.boot();
    rig.issue(t(0));
    rig.follow_until_model(
        t(0),
        |model| {
            model
                .tip_mm(0)
                .is_some_and(|tip| tip >= FSENSOR_MM + past_fsensor_mm)
        },
        120_000,
    );
}

#[test]
fn a_bowden_jam_short_of_the_gears_during_the_final_push_is_not_reported_loaded_and_retry_loads_once_cleared()
{
    // The soak's case (`--slots 1 soak --changes 553 --faults random --seed 7`): the jam
    // strikes with the tip 2 mm past the printer's sensor, 2 mm short of the gears.
    let mut rig = load_until_past_fsensor(PrinterKind::Mk4, 2.0);
    rig.inject(Fault::BowdenJam);
    let run = rig.follow(t(0), 120_000);
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(tip < gears_mm(&rig), "the jam holds the tip at {tip} mm");
    assert_eq!(
        run.last,
        error(t(0), ErrorCode::FSENSOR_DIDNT_SWITCH_ON),
        "tip at {tip} mm, short of the gears: never F0 (progress {:?})",
        run.progress
    );
    // The printer's automatic Retry with the jam still there: the same error, still no F0.
    rig.retry();
    let run = rig.follow(t(0), 120_000);
    assert_eq!(run.last, error(t(0), ErrorCode::FSENSOR_DIDNT_SWITCH_ON));
    assert_eq!(run.progress, [P::FEEDING_TO_FSENSOR, P::FEEDING_TO_NOZZLE]);

    // The user clears the jam and presses Retry: the load goes on from the printer's sensor.
    assert!(rig.model.clear(FaultKind::BowdenJam));
    rig.idle(100);
    let run = rig.retry_finishes(t(0));
    assert_eq!(run.progress, [P::FEEDING_TO_FSENSOR, P::FEEDING_TO_NOZZLE]);
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(tip >= gears_mm(&rig), "loaded: tip at {tip} mm");
}

#[test]
fn a_jam_at_the_printers_sensor_is_not_reported_loaded_by_any_printer() {
    for printer in [PrinterKind::Mk4, PrinterKind::Mk35, PrinterKind::Mk3s] {
        let mut rig = load_until_past_fsensor(printer, 0.0);
        rig.inject(Fault::BowdenJam);
        let run = rig.follow(t(0), 120_000);
        let tip = rig.model.tip_mm(0).unwrap();
        assert!(
            tip < gears_mm(&rig),
            "{printer:?}: the jam holds the tip at {tip} mm"
        );
        assert_eq!(
            run.last,
            error(t(0), ErrorCode::FSENSOR_DIDNT_SWITCH_ON),
            "{printer:?}: tip at {tip} mm"
        );
    }
}

#[test]
fn every_printer_family_gets_the_load_confirmed_by_its_own_push() {
    for printer in [PrinterKind::Mk4, PrinterKind::Mk35, PrinterKind::Mk3s] {
        let mut rig = Rig::<3>::new();
        rig.printer = printer;
        rig.boot();
        for slot in [0, 2, 1] {
            let run = rig.command(t(slot));
            assert_eq!(
                run.last,
                finished(t(slot)),
                "{printer:?} T{slot}: {:?}",
                run.progress
            );
            let tip = rig.model.tip_mm(slot.into()).unwrap();
            assert!(tip >= gears_mm(&rig), "{printer:?} T{slot}: tip at {tip} mm");
        }
    }
}

#[test]
fn with_the_printers_sensor_unavailable_the_load_is_reported_done_only_with_the_tip_in_the_gears() {
    // The unit takes `f3` (sensor unavailable) for triggered, as MMU 3.0.3 does; the printer
    // neither co-feeds nor pushes with its sensor unavailable (`OnMMUProgressMsgSame`: "houston,
    // we have a problem"), only a co-feed move already under way runs to its end.
    //
    // Unavailable before the printer co-feeds: nothing can show the gears holding the tip.
    let mut rig = Rig::<1>::new();
    rig.boot();
    rig.command_until(t(0), P::FEEDING_TO_FSENSOR);
    rig.fsensor = FsensorReports::Stuck(3);
    let run = rig.follow(t(0), 120_000);
    let tip = rig.model.tip_mm(0).unwrap();
    assert_eq!(
        run.last,
        error(t(0), ErrorCode::FSENSOR_DIDNT_SWITCH_ON),
        "tip at {tip} mm: {:?}",
        run.progress
    );
    assert!(tip < gears_mm(&rig), "tip at {tip} mm");
    // The sensor is back: Retry loads.
    rig.fsensor = FsensorReports::Truthful;
    rig.retry_finishes(t(0));
    let tip = rig.model.tip_mm(0).unwrap();
    assert!(tip >= gears_mm(&rig), "loaded: tip at {tip} mm");

    // Unavailable 3 mm before the sensor while the printer co-feeds: its move under way takes
    // the tip into its gears and pulls it on, and that is what the unit sees.
    let mut rig = Rig::<1>::new();
    rig.boot();
    rig.issue(t(0));
    rig.follow_until_model(
        t(0),
        |model| model.tip_mm(0).is_some_and(|tip| tip >= FSENSOR_MM - 3.0),
        120_000,
    );
    rig.fsensor = FsensorReports::Stuck(3);
    let run = rig.follow(t(0), 120_000);
    let tip = rig.model.tip_mm(0).unwrap();
    assert_eq!(run.last, finished(t(0)), "tip at {tip} mm: {:?}", run.progress);
    assert!(tip >= gears_mm(&rig), "tip at {tip} mm");
}

#[test]
fn a_jam_anywhere_between_the_sensor_and_the_gears_is_never_reported_loaded() {
    // Every printer family, the jam from the printer's sensor to just short of the gears, with
    // sensor noise from none to six times the usual (σ 0 to 90 counts): an error, never F0.
    for seed in 0..4u64 {
        for printer in [PrinterKind::Mk4, PrinterKind::Mk35, PrinterKind::Mk3s] {
            for past_fsensor_mm in [0.0, 1.0, 2.0, 3.0, 3.8] {
                let mut rig = Rig::<1>::new();
                rig.model = Model::new(ModelConfig::default(), 1, seed);
                rig.printer = printer;
                boot_and_load_until_past_fsensor(&mut rig, past_fsensor_mm);
                rig.inject(Fault::BowdenJam);
                rig.inject(Fault::SensorNoise {
                    sigma: seed as f32 * 30.0,
                });
                let run = rig.follow(t(0), 120_000);
                let tip = rig.model.tip_mm(0).unwrap();
                assert!(
                    tip < gears_mm(&rig),
                    "{printer:?}: the jam holds the tip at {tip} mm"
                );
                assert_eq!(
                    run.last.param,
                    ParamCode::Error,
                    "{printer:?}, jam {past_fsensor_mm} mm past the sensor, noise seed {seed}: tip at {tip} mm"
                );
            }
        }
    }
}
