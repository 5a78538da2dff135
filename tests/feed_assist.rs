//! The feed assist against a long Bowden tube's drag (issue 34): while the printer prints, the
//! extruder alone pulls the filament through the tube, and the tube's friction holds it taut
//! against a coasting lane. The loaded lane's motor follows the hub tension and takes that pull
//! off the extruder. The drag is the model's assumption (`bowden_drag_mm_per_m`: no tube's
//! friction was measured); the buffer's deflection stands for the force.

mod common;

use common::{Rig, finished, t};
use mmu_firmware::Config;
use mmu_model::ModelConfig;

/// Tube length, mm: a unit outside an enclosure.
const TUBE_MM: u16 = 5000;
/// Drag assumed, buffer mm per metre of tube: 5 mm over 5 m, within the buffer's 6 mm travel.
const DRAG_MM_PER_M: f32 = 1.0;
/// How fast the printer pulls filament while it prints, mm/s (a fast print: about 12 mm³/s).
const PRINT_MM_S: f32 = 5.0;

/// The mean tension the extruder pulls against while printing for a minute through the long
/// tube, mm of buffer, with register 0x4f (the assist's most duty) at `assist_max_duty`.
fn mean_tension_while_printing(assist_max_duty: u16) -> f32 {
    let config = Config {
        bowden_mm: TUBE_MM,
        tension_max_duty: assist_max_duty,
        ..Config::default()
    };
    let model = ModelConfig {
        bowden_drag_mm_per_m: DRAG_MM_PER_M,
        ..ModelConfig::default()
    }
    .with_bowden_length(f32::from(TUBE_MM));
    let mut rig = Rig::<3>::with(config, model);
    rig.boot();
    let run = rig.command(t(0));
    assert_eq!(run.last, finished(t(0)), "{run:?}");
    rig.model.set_printing(Some(PRINT_MM_S));
    // Settled first, then measured.
    rig.idle(10_000);
    let mut sum = 0.0;
    let samples = 60_000 / 10;
    for _ in 0..samples {
        rig.idle(10);
        sum += rig.model.tension_mm();
    }
    sum / samples as f32
}

/// Measured: 5.0 mm coasting, 1.0 mm assisted (the extruder pulls a fifth of the drag).
#[test]
fn the_assist_takes_a_long_tubes_drag_off_the_extruder() {
    let coasting = mean_tension_while_printing(0);
    let assisted = mean_tension_while_printing(Config::default().tension_max_duty);
    assert!(
        coasting > 4.0,
        "without the assist the extruder pulls the tube's drag: {coasting} mm"
    );
    // A proportional follow: it keeps the tension a millimetre past its dead band.
    assert!(
        assisted < coasting / 4.0,
        "with it the extruder pulls {assisted} mm (without: {coasting} mm)"
    );
}
