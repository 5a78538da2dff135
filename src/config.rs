//! The unit's settings: geometry, speeds, bounds, sensor tuning and the version it reports.
//!
//! Every motion the logic makes is bounded by a distance and a time derived from these values.
//! The printer and the user change many of them at run time through registers
//! ([`crate::registers`]); the defaults are for the reference unit (a 360 mm Bowden tube). What
//! the settings may be is checked against the build's [`Hardware`] in one place,
//! [`crate::guards`].

use crate::MAX_SLOTS;
use crate::profile::Profile;
use crate::sensor::Thresholds;

/// The version reported through `S0`..`S3`. The printer checks major, minor and revision for
/// exact equality (`protocol_logic.cpp` `ProcessVersionResponse`); which revision it wants
/// depends on its firmware ([`REVISIONS`]), so the unit negotiates it ([`offered_revision`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Version {
    /// `S0`.
    pub major: u8,
    /// `S1`.
    pub minor: u8,
    /// `S2` as the first answer of a handshake: the revision a printer accepted last (register
    /// 0x52, kept across restarts and `X42`).
    pub revision: u8,
}

impl Version {
    /// `S3`: the build number of MMU firmware 3.0.`revision` (the printer stores it, never checks).
    pub const fn build(&self) -> u16 {
        build_of(self.revision)
    }

    /// The contract a printer that accepted this revision was released with.
    pub const fn contract(&self) -> Contract {
        if self.revision >= 4 {
            Contract::AwaitRelease
        } else {
            Contract::PullAtOnce
        }
    }
}

/// The `S2` revisions of MMU firmware 3.0.x the unit speaks, newest first. The wire is the same
/// for all (3.0.1 added register 0x22, 3.0.2 register 0x23; 3.0.4 left the codec, the error and
/// the progress codes byte for byte as they were: Prusa-Firmware-MMU `git diff v3.0.3 48d4d92 --
/// src/logic/error_codes.h src/logic/progress_codes.h src/modules/protocol.*` is empty); 3.0.4
/// changed the unload ([`Contract`]). Which printer wants which: 3.0.4 Prusa-Firmware-Buddy 6.5.3
/// and later (`mmu2_supported_version.h`, `ccb208bf5af1`), 3.0.3 Buddy 6.4.x and MK3S 3.14.1,
/// 3.0.2 MK3S 3.13.3/3.14.0, 3.0.1 and 3.0.0 older firmware.
pub const REVISIONS: [u8; 5] = [4, 3, 2, 1, 0];

/// The build number MMU firmware 3.0.`revision` reports through `S3`: its commit count
/// (Prusa-Firmware-MMU `cmake/ProjectVersion.cmake`, `git rev-list --count` of tags v3.0.0 to
/// v3.0.3: 814, 844, 878, 896; 3.0.4's release is `MMU3_FW3.0.4+936.hex`).
pub const fn build_of(revision: u8) -> u16 {
    match revision {
        0 => 814,
        1 => 844,
        2 => 878,
        3 => 896,
        _ => 936,
    }
}

/// What a printer expects of an unload that starts with the filament in its extruder, by the
/// MMU revision it accepted (`mmu-3.0.4.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Contract {
    /// MMU 3.0.4 (Buddy >= 6.5.3): the printer sends `T` at the start of its own finishing
    /// retract, its gears still gripping the filament. Nothing pulls until it reports its sensor
    /// off (`f0`/`W9 0`), at most 4 s from the command's acceptance (else `8004` with nothing
    /// pulled); then the first 20 mm at the slow speed (0x14), then fast
    /// (Prusa-Firmware-MMU `src/logic/unload_to_finda.cpp`, `3d32c30`, `9e3b300`).
    AwaitRelease,
    /// MMU 3.0.3 and older: the printer retracts before it sends `T`/`U0`; the unit pulls at once
    /// and the printer's sensor must clear within 0x0c mm (else `8004`, whose Retry makes the
    /// printer help: Buddy `mmu2_mk4.cpp` `CheckUserInput`, `HelpUnloadToFinda`).
    PullAtOnce,
}

/// The revision to answer to the `repeat`-th `S2` of a handshake (0: the first): the one accepted
/// last (`accepted`, register 0x52), then every other of [`REVISIONS`], newest first, then round
/// again. Prusa's printer sends the same `S<n>` again at once on a mismatch and gives up on the
/// sixth (`protocol_logic.cpp` `ProcessVersionResponse`, Buddy and MK3S firmware alike), so every
/// printer finds its revision within four wrong answers.
pub fn offered_revision(accepted: u8, repeat: u8) -> u8 {
    let offers = 1 + REVISIONS.iter().filter(|&&r| r != accepted).count();
    match usize::from(repeat) % offers {
        0 => accepted,
        k => REVISIONS
            .iter()
            .copied()
            .filter(|&r| r != accepted)
            .nth(k - 1)
            .unwrap_or(accepted),
    }
}

/// What the build is, as far as the settings must agree with it: where its parts sit along the
/// filament path, what its drive train can move per revolution, how noisy its sensors read. The
/// guards ([`crate::guards`]) check every setting against it. No register writes it: it is the
/// build's, like the pin map.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hardware {
    /// From the hub sensor back to where the slot paths join into the hub path, mm. A tip
    /// resting closer to the hub than this blocks every other slot.
    pub merge_mm: u16,
    /// From the hub sensor back to each slot's filament sensor, mm: the slot path.
    pub slot_sensor_mm: u16,
    /// The least filament a motor revolution of this drive train can move, 1/100 mm.
    pub min_mm_per_rev_centi: u16,
    /// The most filament a motor revolution of this drive train can move, 1/100 mm.
    pub max_mm_per_rev_centi: u16,
    /// How far the filtered reading of a presence or tension sensor strays from its level when
    /// nothing moves, counts (the presence filter's output).
    pub sensor_noise: u16,
    /// How far the filtered reading of a motor Hall sensor strays when the motor stands still,
    /// counts (the motor filter's output, lighter: noisier).
    pub hall_noise: u16,
    /// The lanes' motion sensors count fractions of a turn (an encoder, an angle sensor): a
    /// counted distance is known to a mark ([`crate::odometer::MARK_CENTI`]), not to a whole
    /// revolution of register 0x42.
    pub counts_fractions: bool,
    /// A filament sensor where the lanes merge. Without one, `lane_to_hub_mm` (0x5f) is the slot
    /// path: the distance from a lane's presence sensor to where its tip counts as in the hub.
    pub hub_sensor: bool,
}

impl Hardware {
    /// The reference unit (the thesis build, and the simulator's model): the slot paths join
    /// 8 mm before the hub sensor, the slot sensors sit 95 mm before it; the drive train moves
    /// 2.00 mm per revolution, a quarter either way allowed for a calibration of another gear or
    /// filament; filtered readings stray up to 25 counts (presence filter, the model's 15 counts
    /// of raw noise) and 45 counts (motor filter) at rest.
    pub const REFERENCE: Hardware = Hardware {
        merge_mm: 8,
        slot_sensor_mm: 95,
        min_mm_per_rev_centi: 150,
        max_mm_per_rev_centi: 250,
        sensor_noise: 25,
        hall_noise: 45,
        counts_fractions: false,
        hub_sensor: true,
    };

    /// The build of the hardware `profile`: the reference unit's path and sensors, with the
    /// profile's drive train (its start value of register 0x42, a quarter either way) and motion
    /// and hub sensors.
    pub const fn of_profile(profile: &Profile) -> Hardware {
        let centi = profile.mm_per_rev_centi;
        Hardware {
            min_mm_per_rev_centi: centi - centi / 4,
            max_mm_per_rev_centi: centi.saturating_add(centi / 4),
            counts_fractions: !matches!(profile.motion, crate::profile::MotionSensor::HallWave),
            hub_sensor: profile.hub_sensor,
            ..Hardware::REFERENCE
        }
    }
}

/// Everything the unit logic can be tuned with.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// The MMU firmware version the unit claims to be compatible with.
    pub version: Version,
    /// Register 0x0b: mm pushed after the printer's sensor triggers (the printer writes 5).
    pub extra_load_mm: u16,
    /// Register 0x0c: mm of unloading within which the printer's sensor must clear.
    pub unload_check_mm: u16,
    /// Register 0x0d: unloading speed, mm/s.
    pub unload_speed: u16,
    /// Register 0x11: loading speed, mm/s.
    pub load_speed: u16,
    /// Register 0x14: slow feed speed near the printer's sensor, mm/s (the printer writes 20).
    pub slow_speed: u16,
    /// Register 0x22: Bowden tube length from the hub sensor to the printer's sensor, mm.
    pub bowden_mm: u16,
    /// How far before the hub sensor a parked tip rests, mm.
    pub park_mm: u16,
    /// On hardware without a hub sensor, how far past a lane's presence sensor its tip counts as
    /// in the hub (FINDA), mm: where the lanes merge, calibrated. 0 on hardware with a hub sensor.
    pub lane_to_hub_mm: u16,
    /// How much of the Bowden tube is fed fast before slowing down for the printer's sensor, as mm
    /// left before its nominal position.
    pub bowden_slowdown_mm: u16,
    /// Longest feed searching for the printer's sensor (beyond the fast part), mm.
    pub fsensor_search_mm: u16,
    /// Longest feed from the slot entry to the hub sensor when preloading, mm.
    pub preload_max_mm: u16,
    /// Longest feed from the park position to the hub sensor, mm.
    pub hub_search_mm: u16,
    /// Longest reverse run of an eject, mm.
    pub eject_max_mm: u16,
    /// Filament moved per motor revolution, in 1/100 mm.
    pub mm_per_rev_centi: u16,
    /// Filament speed at full duty, mm/s: the open-loop part of the speed control.
    pub full_duty_speed: u16,
    /// The highest duty the logic commands, per mille.
    pub max_duty: u16,
    /// A motor driven at or above this duty must turn, per mille.
    pub stall_min_duty: u16,
    /// A motor driven at or above `stall_min_duty` without a revolution for this long is stalled, ms.
    pub stall_timeout_ms: u16,
    /// Slack added to every phase's time bound on top of twice its nominal duration, ms.
    pub phase_slack_ms: u16,
    /// Tension sensor reading with the Bowden tube at rest.
    pub tension_neutral: u16,
    /// Deviation from neutral the motor ignores while following the extruder, in ADC counts.
    pub tension_deadband: u16,
    /// Duty added per ADC count of tension above the deadband, per mille per count.
    pub tension_gain: u16,
    /// The most duty the tension follower applies, per mille.
    pub tension_max_duty: u16,
    /// Presence thresholds of the hub filament sensor.
    pub hub_thresholds: Thresholds,
    /// Presence thresholds of each slot's filament sensor.
    pub slot_thresholds: [Thresholds; MAX_SLOTS],
    /// Edge thresholds of each slot's motor Hall sine.
    pub motor_thresholds: [Thresholds; MAX_SLOTS],
    /// Length of the filament on each slot's spool when it is inserted, m (register `0x54 + k`).
    pub spool_m: [u16; MAX_SLOTS],
    /// What the build is: what the settings are checked against (no register).
    pub hardware: Hardware,
    /// Unload as MMU 3.0.4 does: wait blind for the printer's sensor, pull at once on 3.0.3 (no
    /// register; the simulator compares it with the unload that feels, `phases::unload`).
    #[cfg(feature = "strict-unload")]
    pub strict_unload: bool,
}

impl Config {
    /// The reference unit's settings. A constant, so that building them copies them from flash
    /// (code storing each field took twice the room).
    pub const DEFAULT: Config = Config {
        version: Version {
            major: 3,
            minor: 0,
            revision: 4,
        },
        extra_load_mm: 30,
        unload_check_mm: 40,
        unload_speed: 95,
        load_speed: 95,
        slow_speed: 20,
        bowden_mm: 360,
        park_mm: 15,
        lane_to_hub_mm: 0,
        bowden_slowdown_mm: 30,
        fsensor_search_mm: 90,
        preload_max_mm: 150,
        hub_search_mm: 45,
        eject_max_mm: 150,
        mm_per_rev_centi: 200,
        full_duty_speed: 150,
        max_duty: 1000,
        stall_min_duty: 250,
        stall_timeout_ms: 400,
        phase_slack_ms: 1000,
        tension_neutral: 2048,
        tension_deadband: 60,
        tension_gain: 2,
        tension_max_duty: 600,
        hub_thresholds: Thresholds { on: 2600, off: 2400 },
        slot_thresholds: [Thresholds { on: 2600, off: 2400 }; MAX_SLOTS],
        motor_thresholds: [Thresholds { on: 2300, off: 1800 }; MAX_SLOTS],
        spool_m: [crate::lanes::DEFAULT_SPOOL_M; MAX_SLOTS],
        hardware: Hardware::REFERENCE,
        #[cfg(feature = "strict-unload")]
        strict_unload: false,
    };
}

/// The default distance from a lane's presence sensor to where the lanes merge, on hardware
/// without a hub sensor, mm: the simulator's geometry until a calibration measures the unit's.
pub const LANE_TO_HUB_MM: u16 = 95;

impl Config {
    /// The default settings on the hardware `profile`: the reference unit's, with the profile's
    /// distance per turn of its motion sensor.
    pub const fn for_profile(profile: &Profile) -> Config {
        Config::DEFAULT.on_profile(profile)
    }

    /// These settings on the hardware `profile`: those that depend on it (the distance per turn
    /// of the motion sensor, the merge's distance without a hub sensor) are the profile's.
    pub const fn on_profile(self, profile: &Profile) -> Config {
        Config {
            mm_per_rev_centi: profile.mm_per_rev_centi,
            lane_to_hub_mm: if profile.hub_sensor { 0 } else { LANE_TO_HUB_MM },
            hardware: Hardware::of_profile(profile),
            ..self
        }
    }
}

impl Default for Config {
    fn default() -> Self {
        Self::DEFAULT
    }
}
