//! The physical minimum of a tool change: how long the unit's motion takes if every path segment
//! ran at exactly its configured speed from its first millimetre to its last (no acceleration, no
//! sensor filtering, no polling). A measured tool change divided by this is the logic's overhead.
//!
//! A tool change (`T<slot>`, see `mmu_firmware::commands::tool_change`) runs these segments, positions in mm from
//! the hub filament sensor (0), the printer's filament sensor at
//! [`ModelConfig::bowden_length_mm`]:
//!
//! | segment | from | to | speed |
//! |---|---|---|---|
//! | unload (`P3`) | the loaded tip | the hub sensor (0) | `unload_speed` |
//! | park (`P19`) | 0 | `-park_mm` | `load_speed` |
//! | feed to the hub (`P5`) | `-park_mm` | 0 | `load_speed` |
//! | fast Bowden feed (`P6`) | 0 | `bowden_mm - bowden_slowdown_mm` | `load_speed` |
//! | slow feed to the printer's sensor (`P1c`) | end of the fast feed | `bowden_length_mm` | `slow_speed` |
//! | extra load (`P7`) | the printer's sensor | `extra_load_mm` further | `slow_speed` |
//!
//! The first two only run when a filament is loaded. The new slot's filament is taken to rest at
//! the park position (`park_mm` behind the hub sensor), where the unit parks every filament it
//! pulls back. The extra load is the value *in effect*: the printer writes register 0x0b at every
//! connect (5 mm on Prusa's firmware), so pass the unit's configuration as the logic has it then
//! (e.g. [`Sim::unit_config`](crate::Sim::unit_config) after the handshake).
//!
//! The Bowden's fast part is measured from the hub sensor with the *configured* `bowden_mm`; the
//! slow part ends at the *real* printer sensor of the geometry, so a Bowden length configured
//! shorter than the real tube shows up as a longer slow feed (a fast part configured past the
//! real sensor is cut at it).
//!
//! ## A printer's floor
//!
//! [`tool_change_floor`] adds what the printer's own sequence forces on the unit's time, over the
//! same span as the time measured: from the unit accepting the `T`
//! ([`CommandRecord::started_ms`](crate::CommandRecord::started_ms)) to its `F`
//! ([`CommandRecord::finished_ms`](crate::CommandRecord::finished_ms)).
//!
//! - Buddy 6.4 and the MK3S send `T` once their ramming and retract have pulled the tip out of
//!   their gears ([`crate::mechanics`]): the unit's time starts after it, so the printer adds
//!   nothing and the floor is the physical minimum.
//! - Buddy 6.5.3 sends `T` first ([`Personality::sends_tool_before_retract`]); the simulator
//!   then plays the slicer's ramming down to [`RAMMED_TIP_PAST_SENSOR_MM`] past the printer's
//!   sensor at [`PRINTER_UNLOAD_MM_S`], and the finishing retract at the printer's copy of
//!   register 0x14 (the slow speed it wrote: the unit's `slow_speed` in effect). While the tip is
//!   in the printer's gears ([`ModelConfig::extruder_gears_mm`], 10 mm before its sensor there)
//!   they hold it: no unit pulls it faster. So the unload splits in three: the ramming, the
//!   retract from where the ramming left the tip to the gears, and from the gears to the hub
//!   sensor at the unit's unload speed.
//!
//! The end is the same on every printer: the extra load runs at the slow speed, the printer's
//! own push's pace. Nothing of the unit's own making counts (acceleration, sensor filters, the
//! wait for a sensor state reported over the wire, the proof that the gears hold the tip).

use mmu_firmware::Config;
use mmu_model::ModelConfig;

use crate::mechanics::{FINISH_RETRACT_MM, PRINTER_UNLOAD_MM_S, RAMMED_TIP_PAST_SENSOR_MM};
use crate::personality::Personality;

/// The physical minimum of one tool change, per segment, in seconds. A segment with a positive
/// distance and a zero speed takes forever ([`f64::INFINITY`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ToolChangeMinimum {
    /// The printer's ramming after the unit accepted the `T`, at [`PRINTER_UNLOAD_MM_S`] (only
    /// in a [floor](tool_change_floor) of a printer that sends `T` before it; else 0).
    pub ramming_s: f64,
    /// The printer's retract while its gears hold the tip, at its slow speed (only in a
    /// [floor](tool_change_floor) of a printer that sends `T` before it; else 0).
    pub in_gears_s: f64,
    /// Unload of the loaded filament from its tip (or, in a floor, from the printer's gears) to
    /// the hub sensor, at the unload speed.
    pub unload_s: f64,
    /// Park of the unloaded filament, `park_mm` back from the hub sensor, at the load speed.
    pub park_s: f64,
    /// Feed of the new filament from the park position to the hub sensor, at the load speed.
    pub feed_to_hub_s: f64,
    /// Fast feed through the Bowden tube, `bowden_mm - bowden_slowdown_mm`, at the load speed.
    pub bowden_s: f64,
    /// Slow feed from the end of the fast feed to the printer's filament sensor.
    pub to_fsensor_s: f64,
    /// Extra load past the printer's sensor into the extruder, at the slow speed.
    pub extra_load_s: f64,
}

impl ToolChangeMinimum {
    /// The whole tool change, s.
    pub fn total_s(&self) -> f64 {
        self.ramming_s
            + self.in_gears_s
            + self.unload_s
            + self.park_s
            + self.feed_to_hub_s
            + self.bowden_s
            + self.to_fsensor_s
            + self.extra_load_s
    }
}

/// Time to move `distance_mm` at `speed_mm_s`: nothing for no distance, forever at no speed.
fn segment_s(distance_mm: f64, speed_mm_s: u16) -> f64 {
    segment_at_s(distance_mm, f64::from(speed_mm_s))
}

/// [`segment_s`] at a speed that need not be whole.
fn segment_at_s(distance_mm: f64, speed_mm_s: f64) -> f64 {
    let distance_mm = distance_mm.max(0.0);
    if distance_mm == 0.0 {
        0.0
    } else if speed_mm_s <= 0.0 {
        f64::INFINITY
    } else {
        distance_mm / speed_mm_s
    }
}

/// The physical minimum of a tool change with the unit's `config` (the extra load in effect) on
/// `geometry`, when the loaded filament's tip starts at `start_tip_mm` (mm past the hub sensor, as
/// [`CommandRecord::start_tip_mm`](crate::CommandRecord::start_tip_mm) records it; `None`: nothing
/// loaded, no unload). See the [module documentation](self) for the segments.
pub fn tool_change_minimum(
    config: &Config,
    geometry: &ModelConfig,
    start_tip_mm: Option<f32>,
) -> ToolChangeMinimum {
    let park_mm = f64::from(config.park_mm);
    let (unload_s, park_s) = match start_tip_mm {
        Some(tip) => (
            segment_s(f64::from(tip), config.unload_speed),
            segment_s(park_mm, config.load_speed),
        ),
        None => (0.0, 0.0),
    };
    let fsensor_mm = f64::from(geometry.bowden_length_mm).max(0.0);
    let fast_mm = f64::from(config.bowden_mm.saturating_sub(config.bowden_slowdown_mm)).min(fsensor_mm);
    ToolChangeMinimum {
        ramming_s: 0.0,
        in_gears_s: 0.0,
        unload_s,
        park_s,
        feed_to_hub_s: segment_s(park_mm, config.load_speed),
        bowden_s: segment_s(fast_mm, config.load_speed),
        to_fsensor_s: segment_s(fsensor_mm - fast_mm, config.slow_speed),
        extra_load_s: segment_s(f64::from(config.extra_load_mm), config.slow_speed),
    }
}

/// The floor of a tool change on `printer`: [`tool_change_minimum`] with what the printer's own
/// sequence forces on the unit's time from accepting the `T` to finishing it (see the [module
/// documentation](self#a-printers-floor)). `geometry` is the model's as the simulator runs it for
/// that printer ([`Sim::model`](crate::Sim::model)), with its extruder gears where the printer
/// has them.
pub fn tool_change_floor(
    config: &Config,
    geometry: &ModelConfig,
    printer: Personality,
    start_tip_mm: Option<f32>,
) -> ToolChangeMinimum {
    let mut floor = tool_change_minimum(config, geometry, start_tip_mm);
    let gears_mm = f64::from(geometry.extruder_gears_mm);
    let Some(tip_mm) = start_tip_mm.map(f64::from).filter(|&tip| tip > gears_mm) else {
        return floor;
    };
    if !printer.sends_tool_before_retract() {
        return floor;
    }
    // The slicer's ramming stops with the tip this far; the retract then runs its 80 mm, and
    // the gears hold the tip until it leaves them (or the retract ends, as far as it took it).
    let rammed_mm = f64::from(geometry.bowden_length_mm + RAMMED_TIP_PAST_SENSOR_MM);
    floor.ramming_s = segment_at_s(tip_mm - rammed_mm, f64::from(PRINTER_UNLOAD_MM_S));
    let retract_from_mm = tip_mm.min(rammed_mm);
    let released_mm = gears_mm.max(retract_from_mm - f64::from(FINISH_RETRACT_MM));
    floor.in_gears_s = segment_s(retract_from_mm - released_mm, config.slow_speed);
    floor.unload_s = segment_s(released_mm, config.unload_speed);
    floor
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    /// The reference unit with the printer's extra load (5 mm).
    fn session_config() -> Config {
        Config {
            extra_load_mm: 5,
            ..Config::default()
        }
    }

    #[test]
    fn reference_tool_change_by_hand() {
        // Defaults: unload 95 mm/s, load 95 mm/s, slow 20 mm/s, Bowden 360 with 30 slow, park 15.
        let minimum = tool_change_minimum(&session_config(), &ModelConfig::default(), Some(340.0));
        assert!(close(minimum.unload_s, 340.0 / 95.0));
        assert!(close(minimum.park_s, 15.0 / 95.0));
        assert!(close(minimum.feed_to_hub_s, 15.0 / 95.0));
        assert!(close(minimum.bowden_s, 330.0 / 95.0));
        assert!(close(minimum.to_fsensor_s, 30.0 / 20.0));
        assert!(close(minimum.extra_load_s, 5.0 / 20.0));
        // 340/95 + 15/95 + 15/95 + 330/95 + 1.5 + 0.25 = 700/95 + 1.75 = 9.1184...
        assert!(close(minimum.total_s(), 700.0 / 95.0 + 1.75));
        assert!((minimum.total_s() - 9.1184).abs() < 1e-4);
    }

    #[test]
    fn nothing_loaded_means_no_unload_and_no_park() {
        let minimum = tool_change_minimum(&session_config(), &ModelConfig::default(), None);
        assert_eq!((minimum.unload_s, minimum.park_s), (0.0, 0.0));
        // 345/95 + 35/20 = 3.6316 + 1.75
        assert!(close(minimum.total_s(), 345.0 / 95.0 + 1.75));
    }

    #[test]
    fn speeds_and_lengths_each_count_where_they_should() {
        let config = Config {
            extra_load_mm: 10,
            unload_speed: 50,
            load_speed: 100,
            slow_speed: 10,
            bowden_mm: 500,
            bowden_slowdown_mm: 40,
            park_mm: 20,
            ..Config::default()
        };
        let geometry = ModelConfig {
            bowden_length_mm: 520.0,
            ..ModelConfig::default()
        };
        let minimum = tool_change_minimum(&config, &geometry, Some(100.0));
        // Unload 100 mm at 50 = 2 s; park 20 at 100 = 0.2 s; to hub 20 at 100 = 0.2 s;
        // fast 460 at 100 = 4.6 s; slow 520 - 460 = 60 at 10 = 6 s; extra 10 at 10 = 1 s.
        assert!(close(minimum.unload_s, 2.0));
        assert!(close(minimum.park_s, 0.2));
        assert!(close(minimum.feed_to_hub_s, 0.2));
        assert!(close(minimum.bowden_s, 4.6));
        assert!(close(minimum.to_fsensor_s, 6.0));
        assert!(close(minimum.extra_load_s, 1.0));
        assert!(close(minimum.total_s(), 14.0));
    }

    #[test]
    fn a_fast_part_past_the_real_sensor_is_cut_at_it() {
        let config = Config {
            bowden_mm: 500,
            bowden_slowdown_mm: 30,
            ..session_config()
        };
        let minimum = tool_change_minimum(&config, &ModelConfig::default(), None);
        assert!(close(minimum.bowden_s, 360.0 / 95.0));
        assert_eq!(minimum.to_fsensor_s, 0.0);
    }

    #[test]
    fn zero_speed_takes_forever_and_no_distance_takes_nothing() {
        let config = Config {
            slow_speed: 0,
            ..session_config()
        };
        let minimum = tool_change_minimum(&config, &ModelConfig::default(), Some(-3.0));
        assert_eq!(minimum.unload_s, 0.0);
        assert_eq!(minimum.extra_load_s, f64::INFINITY);
        assert_eq!(minimum.total_s(), f64::INFINITY);
    }

    /// The model as the simulator runs it for Buddy 6.5.3: its gears 10 mm before its sensor.
    fn buddy_6_5_geometry() -> ModelConfig {
        let geometry = ModelConfig::default();
        let before = Personality::Buddy65.gears_before_sensor_mm().unwrap();
        ModelConfig {
            extruder_gears_mm: geometry.bowden_length_mm - before,
            ..geometry
        }
    }

    #[test]
    fn buddy_6_5_floor_by_hand_ramming_then_the_retract_until_the_gears_let_go() {
        let geometry = buddy_6_5_geometry();
        assert_eq!(geometry.extruder_gears_mm, 350.0);
        let floor = tool_change_floor(&session_config(), &geometry, Personality::Buddy65, Some(420.0));
        // Ramming 420 -> 374 (360 + 14) at 80 mm/s; the retract 374 -> 350 (the gears) at the
        // slow speed, 20 mm/s; then 350 mm to the hub sensor at 95 mm/s.
        assert!(close(floor.ramming_s, 46.0 / 80.0));
        assert!(close(floor.in_gears_s, 24.0 / 20.0));
        assert!(close(floor.unload_s, 350.0 / 95.0));
        let minimum = tool_change_minimum(&session_config(), &geometry, Some(420.0));
        assert!(close(minimum.unload_s, 420.0 / 95.0));
        assert_eq!((minimum.ramming_s, minimum.in_gears_s), (0.0, 0.0));
        // Everything after the unload is the same.
        assert!(close(
            floor.total_s() - minimum.total_s(),
            46.0 / 80.0 + 24.0 / 20.0 + 350.0 / 95.0 - 420.0 / 95.0
        ));
        // 0.575 + 1.2 + 350 / 95 + (15 + 15 + 330) / 95 + 1.5 + 0.25 = 10.9987
        assert!((floor.total_s() - 10.9987).abs() < 1e-4, "{}", floor.total_s());
    }

    #[test]
    fn printers_that_retract_before_they_send_t_add_nothing() {
        for printer in [Personality::Buddy64, Personality::Mk3s] {
            for tip in [Some(364.0), Some(420.0), None] {
                let geometry = ModelConfig::default();
                assert_eq!(
                    tool_change_floor(&session_config(), &geometry, printer, tip),
                    tool_change_minimum(&session_config(), &geometry, tip),
                    "{printer} {tip:?}"
                );
            }
        }
    }

    #[test]
    fn buddy_6_5_adds_nothing_when_the_tip_is_not_in_its_gears() {
        let geometry = buddy_6_5_geometry();
        for tip in [None, Some(350.0), Some(200.0)] {
            assert_eq!(
                tool_change_floor(&session_config(), &geometry, Personality::Buddy65, tip),
                tool_change_minimum(&session_config(), &geometry, tip),
                "{tip:?}"
            );
        }
    }

    #[test]
    fn a_tip_short_of_the_rammed_position_is_not_rammed() {
        let floor = tool_change_floor(
            &session_config(),
            &buddy_6_5_geometry(),
            Personality::Buddy65,
            Some(370.0),
        );
        assert_eq!(floor.ramming_s, 0.0);
        assert!(close(floor.in_gears_s, 20.0 / 20.0));
        assert!(close(floor.unload_s, 350.0 / 95.0));
    }

    #[test]
    fn gears_the_retract_cannot_clear_hold_the_tip_for_the_whole_retract_only() {
        // Gears 200 mm back: the 80 mm retract from 374 leaves the tip at 294, still in them as
        // the model has it; only the retract's own distance is paced by the printer.
        let geometry = ModelConfig {
            extruder_gears_mm: 200.0,
            ..ModelConfig::default()
        };
        let config = Config {
            slow_speed: 40,
            ..session_config()
        };
        let floor = tool_change_floor(&config, &geometry, Personality::Buddy65, Some(374.0));
        assert_eq!(floor.ramming_s, 0.0);
        assert!(close(floor.in_gears_s, 80.0 / 40.0));
        assert!(close(floor.unload_s, 294.0 / 95.0));
    }

    #[test]
    fn a_printer_retract_at_no_speed_takes_forever() {
        let config = Config {
            slow_speed: 0,
            ..session_config()
        };
        let floor = tool_change_floor(&config, &buddy_6_5_geometry(), Personality::Buddy65, Some(420.0));
        assert_eq!(floor.in_gears_s, f64::INFINITY);
        assert!(close(floor.ramming_s, 46.0 / 80.0));
    }
}
