//! Each simulated printer in both extruder geometries (`--extruder sensor-first|gears-first`):
//! tool changes and an unload finish, the filament ends where they put it, and the geometry is
//! the one asked for; and a 5 m Bowden tube on each printer.

use mmu_model::ModelConfig;
use mmu_protocol::{ErrorCode, ParamCode, Request, RequestCode, ResultCode};
use mmu_sim::{
    Decision, ExtruderGeometry, Operator, Outcome, Personality, Printer, PrinterEvent, PrinterOptions, Sim,
    SimLink, SimOptions,
};

/// Gives up on any error, so that an error fails the test.
struct GiveUp;

impl Operator<SimLink> for GiveUp {
    fn event(&mut self, _link: &mut SimLink, _event: &PrinterEvent) {}

    fn decide(&mut self, _link: &mut SimLink, _request: Request, _error: ErrorCode) -> Decision {
        Decision::GiveUp
    }
}

fn connected(personality: Personality, extruder: ExtruderGeometry) -> Printer<SimLink> {
    connected_with(SimOptions {
        printer: personality,
        extruder: Some(extruder),
        ..SimOptions::default()
    })
}

fn connected_with(options: SimOptions) -> Printer<SimLink> {
    let personality = options.printer;
    let sim = Sim::new(options).unwrap();
    let mut printer = Printer::new(SimLink::new(sim), PrinterOptions::of(personality));
    printer.connect(&mut GiveUp).expect("connects");
    printer
}

/// Buddy 6.5.3 with the sensor before its gears (an MK3.5) included: its retract cannot clear
/// that sensor, and MMU 3.0.4's blind wait ends `T1` in `8004`; this unit feels the filament
/// free and pulls (issue 34).
#[test]
fn every_printer_changes_tools_and_unloads_in_both_geometries() {
    for personality in Personality::ALL {
        for extruder in [ExtruderGeometry::SENSOR_FIRST, ExtruderGeometry::GEARS_FIRST] {
            let case = format!("{personality} {extruder}");
            let mut printer = connected(personality, extruder);
            let config = printer.link().sim().model().config().clone();
            assert_eq!(
                config.extruder_gears_mm - config.bowden_length_mm,
                extruder.gears_past_sensor_mm(),
                "{case}"
            );
            for slot in [0u8, 1] {
                let outcome = printer
                    .command(&mut GiveUp, Request::new(RequestCode::Tool, slot))
                    .unwrap();
                assert_eq!(outcome, Outcome::Finished(ResultCode::OK), "{case}: T{slot}");
                printer.print(&mut GiveUp, 6000).unwrap();
                let model = printer.link().sim().model();
                assert_eq!(model.loaded_slot(), Some(usize::from(slot)), "{case}: T{slot}");
                assert_eq!(model.fsensor_state(), 2, "{case}: T{slot} reaches the nozzle");
            }
            let outcome = printer
                .command(&mut GiveUp, Request::new(RequestCode::Unload, 0))
                .unwrap();
            assert_eq!(outcome, Outcome::Finished(ResultCode::OK), "{case}: U0");
            let model = printer.link().sim().model();
            assert_eq!(model.fsensor_state(), 0, "{case}: U0 clears the sensor");
            assert!(
                model.tip_mm(1).unwrap() < 0.0,
                "{case}: parked {:?}",
                model.tip_mm(1)
            );
        }
    }
}

#[test]
fn each_printer_defaults_to_its_own_geometry_and_an_option_overrides_it() {
    let gears = |personality: Personality, extruder: Option<ExtruderGeometry>| {
        let sim = Sim::new(SimOptions {
            printer: personality,
            extruder,
            ..SimOptions::default()
        })
        .unwrap();
        let config = sim.model().config();
        config.extruder_gears_mm - config.bowden_length_mm
    };
    assert_eq!(gears(Personality::Buddy65, None), -10.0);
    assert_eq!(gears(Personality::Buddy64, None), 4.0);
    assert_eq!(gears(Personality::Mk3s, None), 4.0);
    let at_sensor = ExtruderGeometry::gears_past_sensor(0.0);
    assert_eq!(gears(Personality::Mk3s, at_sensor), 0.0);
    assert_eq!(
        gears(Personality::Buddy65, Some(ExtruderGeometry::SENSOR_FIRST)),
        4.0
    );
}

/// A unit outside an enclosure, 5 m of Bowden tube (register 0x22 written 5000, its top): on each
/// printer in its own geometry the tool changes reach the nozzle and the unload parks the
/// filament.
#[test]
fn a_five_metre_bowden_tube_changes_tools_and_unloads_on_every_printer() {
    for personality in Personality::ALL {
        let mut printer = connected_with(SimOptions {
            printer: personality,
            model: ModelConfig::default().with_bowden_length(5000.0),
            ..SimOptions::default()
        });
        let answer = printer.request(&mut GiveUp, Request::write(0x22, 5000)).unwrap();
        assert_eq!(answer.param, ParamCode::Accepted, "{personality}: W22 5000");
        for slot in [0u8, 1] {
            let outcome = printer
                .command(&mut GiveUp, Request::new(RequestCode::Tool, slot))
                .unwrap();
            assert_eq!(
                outcome,
                Outcome::Finished(ResultCode::OK),
                "{personality}: T{slot}"
            );
            printer.print(&mut GiveUp, 6000).unwrap();
            let model = printer.link().sim().model();
            assert_eq!(
                model.fsensor_state(),
                2,
                "{personality}: T{slot} reaches the nozzle"
            );
        }
        let outcome = printer
            .command(&mut GiveUp, Request::new(RequestCode::Unload, 0))
            .unwrap();
        assert_eq!(outcome, Outcome::Finished(ResultCode::OK), "{personality}: U0");
        let tip = printer.link().sim().model().tip_mm(1).unwrap();
        assert!(tip < 0.0, "{personality}: parked at {tip} mm");
    }
}
