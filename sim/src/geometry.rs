//! Where a printer's extruder gears sit against its filament sensor: the order in which a tip
//! fed from the unit meets them, as Prusa's sources show it for each printer.
//!
//! Sources (BFW = Prusa-Firmware-Buddy at tag v6.5.3, read in nomadsgalaxy/Prusa-Firmware-Buddy;
//! `M2/` = `lib/Marlin/Marlin/src/feature/prusa/MMU2/`; PFW = prusa3d/Prusa-Firmware at v3.13.3):
//!
//! - **MK4, MK3.9, Core One (Nextruder): gears first.** After the slicer's ramming, "which ends
//!   with the filament tip still in extruder gears" (BFW `M2/mmu2_mk4.cpp:582-585`), the printer
//!   retracts 80 mm (`MMU2_RETRY_UNLOAD_FINISH_LENGTH`, `M2/mmu2_config.h:44`) and records the E
//!   position at which its sensor goes off (`UnloadDistanceDetector`, `M2/mmu2_mk4.cpp:594-600`,
//!   `M2/mmu2_marlin2.cpp:66-79`), nominally 14 mm (`nominalEMotorFSOff`, `M2/mmu2_mk4.h:434`),
//!   shorter when filament stays in the melt zone. Only an extruder whose gears still move the
//!   tip when it leaves the sensor can clear the sensor by its own retract: the sensor sits at or
//!   after the drive gear. Prusa's maintainer says the same of the Core One
//!   (Prusa-Firmware-Buddy issue #5158, 2026-03-12 and 2026-03-27): the sensor is the idler
//!   door's lever, which returns to "no filament" only once the extruder has pushed the filament
//!   out of the drive gear, and a bad tip still held by the gear keeps it on. The loads agree:
//!   once the sensor triggers the printer feeds `MMU2_FEED_DISTANCE` (50 mm,
//!   `M2/mmu2_config.h:69`) less the nominal 14 (`M2/mmu2_mk4.cpp:517-518`), its gears already
//!   holding the tip. No source gives the distance in mm; the simulator puts the gears
//!   [`GEARS_FIRST_MM`] before the sensor, so that the sensor clears while the gears still grip
//!   (what the 14 mm figure and the 80 mm retract "to get the filament (including a potential
//!   string) completely out" imply), the hard case for a unit that must not pull against them.
//! - **MK3S, MK3.5: sensor first.** PFW's MK3S configuration puts the sensor at the gears'
//!   position (`MMU2_FILAMENT_SENSOR_POSITION = 0`) and has the tool change push
//!   `MMU2_LOAD_DISTANCE_PAST_GEARS` (5 mm) past the sensor to reach past the gears
//!   (PFW `Firmware/mmu2/variants/config_MMU2S.h:26-28`): the IR sensor's lever sits on the
//!   chimney just above the Bondtech gears, a retract leaves the tip in the sensor. Buddy's MK3.5
//!   branch (`USE_TRY_LOAD`) carries the same values, "copied from MK3S" (BFW
//!   `M2/mmu2_config.h:47-53`). The simulator's default model puts the gears
//!   [`SENSOR_FIRST_MM`] past the sensor (`ModelConfig`: sensor 360, gears 364).

use std::fmt;
use std::str::FromStr;

use mmu_model::ModelConfig;

/// How far the gears sit past the sensor in [`ExtruderGeometry::SENSOR_FIRST`], mm.
pub const SENSOR_FIRST_MM: f32 = 4.0;
/// How far the gears sit before the sensor in [`ExtruderGeometry::GEARS_FIRST`], mm.
pub const GEARS_FIRST_MM: f32 = 10.0;
/// The farthest the gears may sit from the sensor either way, mm (beyond it the printer's
/// extra load push, register 0x0b, could no longer reach them).
pub const MAX_OFFSET_MM: f32 = 30.0;

/// Where the extruder gears sit against the printer's filament sensor: how far past it (towards
/// the nozzle) they are, mm; negative when the gears come first. See the [module
/// documentation](self) for each printer's order and its sources.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExtruderGeometry {
    gears_past_sensor_mm: f32,
}

impl ExtruderGeometry {
    /// The MK3S's and MK3.5's order: the sensor a few mm before the gears.
    pub const SENSOR_FIRST: ExtruderGeometry = ExtruderGeometry {
        gears_past_sensor_mm: SENSOR_FIRST_MM,
    };
    /// The Nextruder's order (MK4, MK3.9, Core One): the gears before the sensor, which clears
    /// while they still grip the filament.
    pub const GEARS_FIRST: ExtruderGeometry = ExtruderGeometry {
        gears_past_sensor_mm: -GEARS_FIRST_MM,
    };

    /// The gears `mm` past the sensor (negative: before it), if within [`MAX_OFFSET_MM`].
    pub fn gears_past_sensor(mm: f32) -> Option<ExtruderGeometry> {
        (mm.is_finite() && mm.abs() <= MAX_OFFSET_MM).then_some(ExtruderGeometry {
            gears_past_sensor_mm: mm,
        })
    }

    /// How far the gears sit past the sensor, mm (negative: before it).
    pub const fn gears_past_sensor_mm(self) -> f32 {
        self.gears_past_sensor_mm
    }

    /// How far the gears sit before the sensor, mm, if they come first (or at it: 0).
    pub fn gears_before_sensor_mm(self) -> Option<f32> {
        (self.gears_past_sensor_mm <= 0.0).then_some(-self.gears_past_sensor_mm)
    }

    /// The sensor comes first: no retract of the printer's own clears it.
    pub fn sensor_first(self) -> bool {
        self.gears_past_sensor_mm > 0.0
    }

    /// `model` with its gears placed against its sensor (the end of its Bowden tube).
    pub fn apply(self, model: &ModelConfig) -> ModelConfig {
        ModelConfig {
            extruder_gears_mm: model.bowden_length_mm + self.gears_past_sensor_mm,
            ..model.clone()
        }
    }
}

impl fmt::Display for ExtruderGeometry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if *self == ExtruderGeometry::SENSOR_FIRST {
            f.write_str("sensor-first")
        } else if *self == ExtruderGeometry::GEARS_FIRST {
            f.write_str("gears-first")
        } else {
            write!(f, "{}", self.gears_past_sensor_mm)
        }
    }
}

/// A text that is no extruder geometry.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BadGeometry(pub String);

impl fmt::Display for BadGeometry {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:?} is no extruder geometry: sensor-first, gears-first, or the gears' distance past \
             the sensor in mm (-{MAX_OFFSET_MM} to {MAX_OFFSET_MM}; negative: gears first)",
            self.0
        )
    }
}

impl std::error::Error for BadGeometry {}

impl FromStr for ExtruderGeometry {
    type Err = BadGeometry;

    /// `sensor-first`, `gears-first`, or the gears' distance past the sensor in mm (`-10`).
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        match text {
            "sensor-first" => Ok(ExtruderGeometry::SENSOR_FIRST),
            "gears-first" => Ok(ExtruderGeometry::GEARS_FIRST),
            _ => text
                .parse::<f32>()
                .ok()
                .and_then(ExtruderGeometry::gears_past_sensor)
                .ok_or_else(|| BadGeometry(text.to_string())),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_distances_parse_and_show_back() {
        for geometry in [ExtruderGeometry::SENSOR_FIRST, ExtruderGeometry::GEARS_FIRST] {
            assert_eq!(geometry.to_string().parse(), Ok(geometry));
        }
        let custom: ExtruderGeometry = "-2.5".parse().unwrap();
        assert_eq!(custom.gears_before_sensor_mm(), Some(2.5));
        assert_eq!(custom.to_string().parse(), Ok(custom));
        assert!(ExtruderGeometry::SENSOR_FIRST.sensor_first());
        assert_eq!(ExtruderGeometry::SENSOR_FIRST.gears_before_sensor_mm(), None);
        for bad in ["gears", "31", "NaN", "-inf", ""] {
            let error = bad.parse::<ExtruderGeometry>().unwrap_err().to_string();
            assert!(error.contains("sensor-first, gears-first"), "{error}");
        }
    }

    #[test]
    fn the_default_model_is_sensor_first_and_gears_first_moves_its_gears() {
        let model = ModelConfig::default();
        assert_eq!(ExtruderGeometry::SENSOR_FIRST.apply(&model), model);
        let long = ModelConfig {
            bowden_length_mm: 1000.0,
            ..model
        };
        let gears_first = ExtruderGeometry::GEARS_FIRST.apply(&long);
        assert_eq!(gears_first.extruder_gears_mm, 990.0);
        assert_eq!(gears_first.bowden_length_mm, 1000.0);
    }
}
