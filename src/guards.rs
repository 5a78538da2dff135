//! What a configuration may be: the one place that decides whether the unit takes a setting.
//!
//! Settings come from outside: the printer's and the user's register writes, and the store
//! (flash is outside input). A setting that contradicts the build ([`Hardware`]: where the slot
//! paths join, where the slot sensors sit, what a revolution can move, how noisy the sensors
//! read) or another setting makes the unit believe something physically impossible (a tip
//! "parked" inside the merge), blinds a sensor, or bounds a move by a rule it cannot keep (a
//! stall timeout shorter than a revolution). [`check`] holds a whole candidate configuration to
//! the [`Rule`]s, each short and named: a register write is applied to a copy, and only a copy
//! that keeps every rule replaces the settings ([`crate::registers::write`]); a stored
//! configuration that breaks one is dropped whole ([`crate::App::restore`]). The rules and their
//! reasons are in the book's register map (`book/src/registers.md`), by code (register 0x8f shows
//! the rule the last refusal named).

use crate::config::{Config, Hardware};
use crate::sensor::{RAIL_HIGH, RAIL_LOW, Thresholds};

/// The filtered reading of each presence sensor that sees filament the unit knows is there
/// (index 0: the hub sensor, `1 + k`: slot *k*'s), `None` for the others: what
/// [`Rule::OnAtFilamentSeen`] holds a threshold to.
pub type FilamentReadings = [Option<u16>; 1 + crate::MAX_SLOTS];

/// No presence sensor known to see filament (before the first step, a stored configuration): the
/// rule on what is seen now has nothing to hold a threshold to.
pub const NO_FILAMENT_READINGS: FilamentReadings = [None; 1 + crate::MAX_SLOTS];

/// A rule every configuration the unit runs on keeps. The number is its code (register 0x8f,
/// the book's table).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Rule {
    /// Every sensor's "off" threshold is below its "on" one (the hysteresis exists).
    ThresholdsOrdered = 1,
    /// Every threshold lies between the rails: a reading at a rail is a faulty sensor and never
    /// filtered ([`RAIL_LOW`], [`RAIL_HIGH`]), so an "on" at or above the high rail is never
    /// reached (the sensor is blind) and an "off" at or below the low rail never left.
    ThresholdsWithinRails = 2,
    /// "on" − "off" is at least twice the noise of the filtered reading: narrower, the noise
    /// alone crosses both and the sensor flickers (a motor Hall sensor counts revolutions that
    /// never were).
    HysteresisAboveNoise = 3,
    /// A presence sensor that sees filament the unit knows is there keeps its "on" threshold at
    /// or below its reading: above, it could never see that filament again.
    OnAtFilamentSeen = 4,
    /// Filament per revolution (0x42) within what the build's drive train can move: every
    /// distance the unit counts is that far off otherwise.
    RevolutionFitsDrive = 5,
    /// The park distance (0x41) reaches two revolutions past the merge: a parked tip is counted
    /// in whole revolutions from where the hub sensor cleared, known to one, and the other
    /// covers filament per revolution set up to a quarter off.
    ParkClearsMerge = 6,
    /// The park distance leaves a parked tip two revolutions in front of its slot sensor, which
    /// must still see it.
    ParkBeforeSlotSensor = 7,
    /// The hub search (0x47), the longest feed from the park position to the hub sensor, is at
    /// least the park distance and two revolutions.
    HubSearchReachesHub = 8,
    /// The preload bound (0x46), the longest feed from a slot sensor to the hub sensor, is at
    /// least the slot path and two revolutions. It is also how far a proving pull goes before
    /// it takes a slot sensor still seeing filament as proof of a tip past the hub: shorter than
    /// the slot path, a slot that does not hold the path would be taken for its owner.
    PreloadReachesHub = 9,
    /// The eject bound (0x49) is at least the slot path and two revolutions: an eject pulls the
    /// tip past its slot sensor.
    EjectClearsSlotSensor = 10,
    /// The stall duty (0x44) is at most the highest duty (0x43): no duty reaches it otherwise,
    /// and the stall rule is off.
    StallDutyWithinMax = 11,
    /// Every speed a phase schedules (load and unload speed, twice the slow speed for the push
    /// into the extruder) is within what the highest duty gives at the speed at full duty
    /// (0x4b): a schedule the motor cannot keep runs out its time bound.
    SpeedsWithinMaxDuty = 12,
    /// The stall timeout (0x45) spans two revolutions at the speed the stall duty gives: a motor
    /// that turns must show a revolution within it from any point of its wave, or every start
    /// is a stall.
    StallTimeoutSpansRevolutions = 13,
    /// The tension dead band (0x4d) is at least twice the tension sensor's noise: the push into
    /// the extruder stops on the tube reading compressed by half of it, and the follower drives
    /// beyond it; narrower, both act on noise (a follower pushing into an idle extruder).
    DeadBandAboveNoise = 14,
    /// The tension neutral reading (0x4c) with the dead band either side lies between the rails:
    /// outside, the tube never reads taut (no load is proved) or compressed.
    TensionBandWithinRails = 15,
    /// The distance from a lane's presence sensor to the hub (0x5f) is set only on hardware
    /// without a hub sensor, where it places the hub; with a hub sensor it stays 0.
    HubDistanceOnlyWithoutHubSensor = 16,
}

impl Rule {
    /// Every rule, by code.
    pub const ALL: [Rule; 16] = [
        Rule::ThresholdsOrdered,
        Rule::ThresholdsWithinRails,
        Rule::HysteresisAboveNoise,
        Rule::OnAtFilamentSeen,
        Rule::RevolutionFitsDrive,
        Rule::ParkClearsMerge,
        Rule::ParkBeforeSlotSensor,
        Rule::HubSearchReachesHub,
        Rule::PreloadReachesHub,
        Rule::EjectClearsSlotSensor,
        Rule::StallDutyWithinMax,
        Rule::SpeedsWithinMaxDuty,
        Rule::StallTimeoutSpansRevolutions,
        Rule::DeadBandAboveNoise,
        Rule::TensionBandWithinRails,
        Rule::HubDistanceOnlyWithoutHubSensor,
    ];

    /// Its code: register 0x8f, the book's table.
    pub const fn code(self) -> u8 {
        self as u8
    }

    /// The rule of `code`, if there is one.
    pub fn from_code(code: u16) -> Option<Rule> {
        Rule::ALL.into_iter().find(|rule| u16::from(rule.code()) == code)
    }

    /// Its short name, as the book and the tools show it.
    pub const fn name(self) -> &'static str {
        match self {
            Rule::ThresholdsOrdered => "thresholds_ordered",
            Rule::ThresholdsWithinRails => "thresholds_within_rails",
            Rule::HysteresisAboveNoise => "hysteresis_above_noise",
            Rule::OnAtFilamentSeen => "on_at_filament_seen",
            Rule::RevolutionFitsDrive => "revolution_fits_drive",
            Rule::ParkClearsMerge => "park_clears_merge",
            Rule::ParkBeforeSlotSensor => "park_before_slot_sensor",
            Rule::HubSearchReachesHub => "hub_search_reaches_hub",
            Rule::PreloadReachesHub => "preload_reaches_hub",
            Rule::EjectClearsSlotSensor => "eject_clears_slot_sensor",
            Rule::StallDutyWithinMax => "stall_duty_within_max",
            Rule::SpeedsWithinMaxDuty => "speeds_within_max_duty",
            Rule::StallTimeoutSpansRevolutions => "stall_timeout_spans_revolutions",
            Rule::DeadBandAboveNoise => "dead_band_above_noise",
            Rule::TensionBandWithinRails => "tension_band_within_rails",
            Rule::HubDistanceOnlyWithoutHubSensor => "hub_distance_only_without_hub_sensor",
        }
    }

    /// What it asks, in a sentence a tool can show beside a refused write (the figures of the
    /// build are in the book's register map).
    pub const fn meaning(self) -> &'static str {
        match self {
            Rule::ThresholdsOrdered => "a sensor's \"off\" threshold must stay below its \"on\" one",
            Rule::ThresholdsWithinRails => {
                "thresholds must lie between the rails: a reading at a rail is a faulty sensor, none reaches one beyond"
            }
            Rule::HysteresisAboveNoise => {
                "\"on\" and \"off\" must be at least twice the sensor's noise apart"
            }
            Rule::OnAtFilamentSeen => {
                "a presence sensor's \"on\" may not go above the reading of the filament it sees now"
            }
            Rule::RevolutionFitsDrive => "filament per revolution must be one the drive train can move",
            Rule::ParkClearsMerge => {
                "the park distance must reach two revolutions past the merge, where the slot paths join"
            }
            Rule::ParkBeforeSlotSensor => {
                "the park distance must leave the tip two revolutions in front of its slot sensor"
            }
            Rule::HubSearchReachesHub => {
                "the hub search must be at least the park distance and two revolutions"
            }
            Rule::PreloadReachesHub => "the preload bound must be at least the slot path and two revolutions",
            Rule::EjectClearsSlotSensor => {
                "the eject bound must be at least the slot path and two revolutions"
            }
            Rule::StallDutyWithinMax => "the stall duty may not exceed the highest duty",
            Rule::SpeedsWithinMaxDuty => {
                "the load and unload speeds and twice the slow speed must be within what the highest duty gives"
            }
            Rule::StallTimeoutSpansRevolutions => {
                "the stall timeout must span two revolutions at the speed the stall duty gives"
            }
            Rule::DeadBandAboveNoise => {
                "the tension dead band must be at least twice the tension sensor's noise"
            }
            Rule::TensionBandWithinRails => {
                "the tension neutral reading, the dead band either side, must lie between the rails"
            }
            Rule::HubDistanceOnlyWithoutHubSensor => {
                "the distance from a lane's presence sensor to the hub is set only on hardware without a hub sensor"
            }
        }
    }
}

/// The first rule `config` breaks, with `seen` the filament the presence sensors see now; `Ok`
/// when it keeps them all.
pub fn check(config: &Config, seen: &FilamentReadings) -> Result<(), Rule> {
    sensors(config, seen)?;
    distances(config)?;
    drive(config)?;
    tension(config)
}

/// The filament between two signs of life of a lane's motion sensor, 1/100 mm: a revolution of
/// a Hall wave, a mark of a sensor that counts fractions of a turn ([`crate::odometer`]).
fn step_centi(config: &Config) -> u16 {
    if config.hardware.counts_fractions {
        crate::odometer::MARK_CENTI
    } else {
        config.mm_per_rev_centi
    }
}

/// How precisely the unit knows a distance it counted, whole mm rounded up: two steps
/// ([`step_centi`]), one for where the first edge falls, one for filament per revolution set up
/// to a quarter off the drive train ([`Rule::ParkClearsMerge`]).
fn two_revolutions_mm(config: &Config) -> u32 {
    (2 * u32::from(step_centi(config))).div_ceil(100)
}

/// The threshold pairs: every presence sensor's ([`Rule::OnAtFilamentSeen`] with what `seen`
/// says it sees), every motor Hall sensor's.
fn sensors(config: &Config, seen: &FilamentReadings) -> Result<(), Rule> {
    let Hardware {
        sensor_noise,
        hall_noise,
        ..
    } = config.hardware;
    let presence = core::iter::once(&config.hub_thresholds)
        .chain(&config.slot_thresholds)
        .zip(seen);
    for (&pair, &reading) in presence {
        pair_within(pair, sensor_noise)?;
        if reading.is_some_and(|reading| pair.on > reading) {
            return Err(Rule::OnAtFilamentSeen);
        }
    }
    for &pair in &config.motor_thresholds {
        pair_within(pair, hall_noise)?;
    }
    Ok(())
}

/// One sensor's threshold pair against its filtered reading's `noise`.
fn pair_within(pair: Thresholds, noise: u16) -> Result<(), Rule> {
    if pair.off >= pair.on {
        Err(Rule::ThresholdsOrdered)
    } else if pair.off <= RAIL_LOW || pair.on >= RAIL_HIGH {
        Err(Rule::ThresholdsWithinRails)
    } else if u32::from(pair.on - pair.off) < 2 * u32::from(noise) {
        Err(Rule::HysteresisAboveNoise)
    } else {
        Ok(())
    }
}

/// The distances the unit counts against the slot path: the park position between the merge and
/// the slot sensor, and the bounds of the moves that cross the slot path.
fn distances(config: &Config) -> Result<(), Rule> {
    let hardware = config.hardware;
    let centi = config.mm_per_rev_centi;
    if !(hardware.min_mm_per_rev_centi..=hardware.max_mm_per_rev_centi).contains(&centi) {
        return Err(Rule::RevolutionFitsDrive);
    }
    let slack = two_revolutions_mm(config);
    let park = u32::from(config.park_mm);
    // Without a hub sensor the slot path is the setting that places the hub (0x5f); with one,
    // that setting means nothing and stays 0.
    let slot_path = if hardware.hub_sensor {
        if config.lane_to_hub_mm != 0 {
            return Err(Rule::HubDistanceOnlyWithoutHubSensor);
        }
        u32::from(hardware.slot_sensor_mm)
    } else {
        u32::from(config.lane_to_hub_mm)
    };
    if park < u32::from(hardware.merge_mm) + slack {
        Err(Rule::ParkClearsMerge)
    } else if park + slack > slot_path {
        Err(Rule::ParkBeforeSlotSensor)
    } else if u32::from(config.hub_search_mm) < park + slack {
        Err(Rule::HubSearchReachesHub)
    } else if u32::from(config.preload_max_mm) < slot_path + slack {
        Err(Rule::PreloadReachesHub)
    } else if u32::from(config.eject_max_mm) < slot_path + slack {
        Err(Rule::EjectClearsSlotSensor)
    } else {
        Ok(())
    }
}

/// The duties, speeds and the stall rule against one another.
fn drive(config: &Config) -> Result<(), Rule> {
    if config.stall_min_duty > config.max_duty {
        return Err(Rule::StallDutyWithinMax);
    }
    // Speeds in mm/s × 1000 against full-duty speed × duty ‰: at most 65 535 × 1000, 32 bits.
    let fastest = config
        .load_speed
        .max(config.unload_speed)
        .max(config.slow_speed.saturating_mul(2));
    let reachable = u32::from(config.full_duty_speed) * u32::from(config.max_duty.min(1000));
    if u32::from(fastest) * 1000 > reachable {
        return Err(Rule::SpeedsWithinMaxDuty);
    }
    // Two revolutions at the stall duty's speed (`full_duty_speed × stall_min_duty / 1000`
    // mm/s) take `2 × centi × 10 × 1000 / (full_duty_speed × stall_min_duty)` ms; no speed
    // (a stall duty of 0) takes forever.
    let stall_speed_milli = u64::from(config.full_duty_speed) * u64::from(config.stall_min_duty);
    let two_revolutions = 20_000 * u64::from(step_centi(config));
    if u64::from(config.stall_timeout_ms) * stall_speed_milli < two_revolutions {
        return Err(Rule::StallTimeoutSpansRevolutions);
    }
    Ok(())
}

/// The tension follower's and the load's band around the neutral reading.
fn tension(config: &Config) -> Result<(), Rule> {
    let deadband = u32::from(config.tension_deadband);
    if deadband < 2 * u32::from(config.hardware.sensor_noise) {
        return Err(Rule::DeadBandAboveNoise);
    }
    let neutral = u32::from(config.tension_neutral);
    if neutral < u32::from(RAIL_LOW) + deadband + 1 || neutral + deadband >= u32::from(RAIL_HIGH) {
        return Err(Rule::TensionBandWithinRails);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn broken(config: &Config) -> Option<Rule> {
        check(config, &NO_FILAMENT_READINGS).err()
    }

    /// `config` changed by `change`: the rule it breaks, if any.
    fn with(change: impl FnOnce(&mut Config)) -> Option<Rule> {
        let mut config = Config::default();
        change(&mut config);
        broken(&config)
    }

    #[test]
    fn the_defaults_keep_every_rule() {
        assert_eq!(broken(&Config::DEFAULT), None);
    }

    #[test]
    fn every_profile_is_held_to_its_own_drive_train_and_hub() {
        use crate::profile::{ALL, BMCU_C, N20_QUADRATURE, THESIS};
        for profile in ALL {
            assert_eq!(broken(&Config::for_profile(profile)), None, "{}", profile.name);
        }
        let on = |profile, change: fn(&mut Config)| {
            let mut config = Config::for_profile(profile);
            change(&mut config);
            broken(&config)
        };
        // The thesis's 2 mm a revolution is no N20 drive train's, and the other way round.
        assert_eq!(
            on(&N20_QUADRATURE, |c| c.mm_per_rev_centi = 200),
            Some(Rule::RevolutionFitsDrive)
        );
        assert_eq!(
            on(&THESIS, |c| c.mm_per_rev_centi = 2356),
            Some(Rule::RevolutionFitsDrive)
        );
        // A counting sensor's distances are known to a mark, not a 23.56 mm turn: the thesis's
        // park distance fits.
        assert_eq!(on(&N20_QUADRATURE, |c| c.park_mm = 12), None);
        assert_eq!(
            on(&N20_QUADRATURE, |c| c.park_mm = 11),
            Some(Rule::ParkClearsMerge)
        );
        // The distance to the hub places the hub only where no sensor does.
        assert_eq!(
            on(&THESIS, |c| c.lane_to_hub_mm = 95),
            Some(Rule::HubDistanceOnlyWithoutHubSensor)
        );
        assert_eq!(
            on(&BMCU_C, |c| c.lane_to_hub_mm = 0),
            Some(Rule::ParkBeforeSlotSensor)
        );
        // The park (15 mm) and two marks (4 mm) before the hub from the presence sensor.
        assert_eq!(
            on(&BMCU_C, |c| c.lane_to_hub_mm = 18),
            Some(Rule::ParkBeforeSlotSensor)
        );
        assert_eq!(on(&BMCU_C, |c| c.lane_to_hub_mm = 19), None);
    }

    #[test]
    fn every_rule_has_its_code_name_and_meaning() {
        for (i, rule) in Rule::ALL.into_iter().enumerate() {
            assert_eq!(usize::from(rule.code()), i + 1, "{rule:?}");
            assert_eq!(Rule::from_code(u16::from(rule.code())), Some(rule));
            assert!(!rule.name().is_empty() && !rule.meaning().is_empty());
        }
        assert_eq!(Rule::from_code(0), None);
        assert_eq!(Rule::from_code(17), None);
    }

    /// Each threshold rule at its edge, on every kind of sensor: the last value it takes and the
    /// first it refuses.
    #[test]
    fn thresholds_are_ordered_within_the_rails_and_wider_than_the_noise() {
        let pair = |on, off| Thresholds { on, off };
        let presence = |thresholds| with(|c| c.slot_thresholds[4] = thresholds);
        let hall = |thresholds| with(|c| c.motor_thresholds[2] = thresholds);
        let hub = |thresholds| with(|c| c.hub_thresholds = thresholds);
        for check in [presence, hub] {
            assert_eq!(check(pair(2600, 2600)), Some(Rule::ThresholdsOrdered));
            assert_eq!(check(pair(2400, 2600)), Some(Rule::ThresholdsOrdered));
            assert_eq!(check(pair(4054, 2400)), None);
            for on in [4055, 4095, u16::MAX] {
                assert_eq!(check(pair(on, 2400)), Some(Rule::ThresholdsWithinRails), "{on}");
            }
            assert_eq!(check(pair(2600, 41)), None);
            assert_eq!(check(pair(2600, 40)), Some(Rule::ThresholdsWithinRails));
            assert_eq!(check(pair(2450, 2400)), None);
            assert_eq!(check(pair(2449, 2400)), Some(Rule::HysteresisAboveNoise));
        }
        assert_eq!(hall(pair(2300, 2210)), None);
        assert_eq!(hall(pair(2300, 2211)), Some(Rule::HysteresisAboveNoise));
        assert_eq!(hall(pair(4055, 1800)), Some(Rule::ThresholdsWithinRails));
    }

    #[test]
    fn an_on_threshold_above_the_filament_seen_now_is_refused() {
        let mut seen = NO_FILAMENT_READINGS;
        seen[0] = Some(3000);
        seen[2] = Some(2800);
        let config = |change: fn(&mut Config)| {
            let mut config = Config::default();
            change(&mut config);
            check(&config, &seen).err()
        };
        assert_eq!(config(|c| c.hub_thresholds.on = 3000), None);
        assert_eq!(
            config(|c| c.hub_thresholds.on = 3001),
            Some(Rule::OnAtFilamentSeen)
        );
        assert_eq!(
            config(|c| c.slot_thresholds[1].on = 2801),
            Some(Rule::OnAtFilamentSeen)
        );
        // Slot 0 (index 1) sees no filament the unit knows of.
        assert_eq!(config(|c| c.slot_thresholds[0].on = 3500), None);
    }

    /// The park position between the merge and the slot sensor, two revolutions clear of each,
    /// for every revolution the drive train can have; the bounds of the moves across the slot
    /// path at their edges.
    #[test]
    fn the_park_lies_between_the_merge_and_the_slot_sensor_and_the_bounds_cross_the_slot_path() {
        for (centi, slack) in [(150, 3), (199, 4), (200, 4), (201, 5), (250, 5)] {
            let at = |park_mm| {
                with(|c| {
                    c.mm_per_rev_centi = centi;
                    c.park_mm = park_mm;
                    c.hub_search_mm = 100;
                })
            };
            assert_eq!(at(8 + slack), None, "{centi}");
            assert_eq!(at(7 + slack), Some(Rule::ParkClearsMerge), "{centi}");
            assert_eq!(at(95 - slack), None, "{centi}");
            assert_eq!(at(96 - slack), Some(Rule::ParkBeforeSlotSensor), "{centi}");
        }
        for centi in [10, 149, 251, 5000] {
            assert_eq!(
                with(|c| c.mm_per_rev_centi = centi),
                Some(Rule::RevolutionFitsDrive)
            );
        }
        // The reported findings: a 1 mm park, 50 mm a revolution.
        assert_eq!(with(|c| c.park_mm = 1), Some(Rule::ParkClearsMerge));
        assert_eq!(
            with(|c| c.mm_per_rev_centi = 5000),
            Some(Rule::RevolutionFitsDrive)
        );
        assert_eq!(with(|c| c.hub_search_mm = 19), None);
        assert_eq!(with(|c| c.hub_search_mm = 18), Some(Rule::HubSearchReachesHub));
        assert_eq!(with(|c| c.preload_max_mm = 99), None);
        assert_eq!(with(|c| c.preload_max_mm = 98), Some(Rule::PreloadReachesHub));
        assert_eq!(with(|c| c.eject_max_mm = 99), None);
        assert_eq!(with(|c| c.eject_max_mm = 98), Some(Rule::EjectClearsSlotSensor));
    }

    #[test]
    fn speeds_duties_and_the_stall_rule_agree() {
        assert_eq!(with(|c| c.stall_min_duty = c.max_duty), None);
        assert_eq!(
            with(|c| {
                c.max_duty = 400;
                c.stall_min_duty = 401;
            }),
            Some(Rule::StallDutyWithinMax)
        );
        // 150 mm/s at full duty: 95 mm/s needs 634 ‰.
        assert_eq!(with(|c| c.max_duty = 634), None);
        assert_eq!(with(|c| c.max_duty = 633), Some(Rule::SpeedsWithinMaxDuty));
        assert_eq!(with(|c| c.unload_speed = 151), Some(Rule::SpeedsWithinMaxDuty));
        assert_eq!(with(|c| c.slow_speed = 75), None);
        assert_eq!(with(|c| c.slow_speed = 76), Some(Rule::SpeedsWithinMaxDuty));
        assert_eq!(with(|c| c.full_duty_speed = 94), Some(Rule::SpeedsWithinMaxDuty));
        // At the stall duty (250 ‰ of 150 mm/s: 37.5 mm/s) two 2 mm revolutions take 106.7 ms.
        assert_eq!(with(|c| c.stall_timeout_ms = 107), None);
        assert_eq!(
            with(|c| c.stall_timeout_ms = 106),
            Some(Rule::StallTimeoutSpansRevolutions)
        );
        assert_eq!(
            with(|c| c.stall_min_duty = 0),
            Some(Rule::StallTimeoutSpansRevolutions),
            "no duty that turns the motor"
        );
        // Every setting at its register's extreme: no overflow.
        assert_eq!(
            with(|c| {
                c.full_duty_speed = 2000;
                c.max_duty = 1000;
                c.stall_min_duty = 1000;
                c.stall_timeout_ms = 10_000;
                c.load_speed = 1000;
                c.unload_speed = 1000;
                c.slow_speed = 1000;
            }),
            None
        );
        assert_eq!(with(|c| c.slow_speed = u16::MAX), Some(Rule::SpeedsWithinMaxDuty));
    }

    #[test]
    fn the_tension_band_clears_the_noise_and_the_rails() {
        assert_eq!(with(|c| c.tension_deadband = 50), None);
        for deadband in [0, 1, 49] {
            assert_eq!(
                with(|c| c.tension_deadband = deadband),
                Some(Rule::DeadBandAboveNoise),
                "{deadband}"
            );
        }
        assert_eq!(with(|c| c.tension_neutral = 101), None);
        assert_eq!(
            with(|c| c.tension_neutral = 100),
            Some(Rule::TensionBandWithinRails)
        );
        assert_eq!(with(|c| c.tension_neutral = 3994), None);
        assert_eq!(
            with(|c| c.tension_neutral = 3995),
            Some(Rule::TensionBandWithinRails)
        );
        assert_eq!(
            with(|c| {
                c.tension_neutral = 4095;
                c.tension_deadband = 2000;
            }),
            Some(Rule::TensionBandWithinRails)
        );
    }
}
