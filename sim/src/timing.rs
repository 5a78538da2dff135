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

use mmu_firmware::Config;
use mmu_model::ModelConfig;

/// The physical minimum of one tool change, per segment, in seconds. A segment with a positive
/// distance and a zero speed takes forever ([`f64::INFINITY`]).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ToolChangeMinimum {
    /// Unload of the loaded filament from its tip to the hub sensor, at the unload speed.
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
        self.unload_s
            + self.park_s
            + self.feed_to_hub_s
            + self.bowden_s
            + self.to_fsensor_s
            + self.extra_load_s
    }
}

/// Time to move `distance_mm` at `speed_mm_s`: nothing for no distance, forever at no speed.
fn segment_s(distance_mm: f64, speed_mm_s: u16) -> f64 {
    let distance_mm = distance_mm.max(0.0);
    if distance_mm == 0.0 {
        0.0
    } else if speed_mm_s == 0 {
        f64::INFINITY
    } else {
        distance_mm / f64::from(speed_mm_s)
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
        unload_s,
        park_s,
        feed_to_hub_s: segment_s(park_mm, config.load_speed),
        bowden_s: segment_s(fast_mm, config.load_speed),
        to_fsensor_s: segment_s(fsensor_mm - fast_mm, config.slow_speed),
        extra_load_s: segment_s(f64::from(config.extra_load_mm), config.slow_speed),
    }
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
}
