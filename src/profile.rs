//! What senses a lane on this hardware: a hardware profile.
//!
//! The thesis build, a lane made of a buyable encoder gear motor and the BMCU-C kit differ in
//! what counts the motion, where the tension is read and whether a hub sensor exists at all. A
//! board declares its profile at compile time, the simulator picks one at run time; the logic
//! reads motion as distance and direction ([`crate::feeder::Feeder`]) and sensors as facts
//! ([`crate::unit::Unit`]), never as a sensor kind.

pub use mmu_hal_port::{ANGLE_COUNTS, ANGLE_FAULT, MotionSensor};

/// How a lane's presence sensor is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PresenceInput {
    /// An analog level (a Hall sensor, an opto) through the noise filter, a level stuck at a rail
    /// a fault.
    Analog,
    /// A switch on a digital input: 0 or [`mmu_hal_port::ADC_MAX`], unfiltered, never a fault.
    Digital,
}

/// Where the Bowden tension is read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum TensionAt {
    /// One sensor at the hub, for whichever lane is loaded.
    Hub,
    /// One sensor per lane (a sprung slider in each lane's path).
    Lane,
}

/// What senses a lane on one build, and how many lanes it has.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Profile {
    /// The name `--hardware` takes.
    pub name: &'static str,
    /// What counts each lane's motion.
    pub motion: MotionSensor,
    /// How each lane's presence is read.
    pub presence: PresenceInput,
    /// Where the tension is read.
    pub tension: TensionAt,
    /// Whether a filament sensor sits where the lanes merge (the unit's FINDA). Without one the
    /// unit tells FINDA from the loaded lane's odometry.
    pub hub_sensor: bool,
    /// The most lanes this hardware has.
    pub max_slots: usize,
    /// The filament's motion per turn of the sensed shaft before any calibration, 1/100 mm.
    pub mm_per_rev_centi: u16,
}

impl Profile {
    /// The profile as register 0x8d shows it: bits 0-1 the motion sensor (0 a Hall wave, 1 a
    /// quadrature encoder, 2 an angle sensor, 3 one channel of pulses), bit 2 a digital presence input, bit 3 a tension
    /// sensor per lane, bit 4 a hub sensor.
    pub const fn code(&self) -> u16 {
        let motion = match self.motion {
            MotionSensor::HallWave => 0,
            MotionSensor::Quadrature { .. } => 1,
            MotionSensor::Angle => 2,
            MotionSensor::Pulses { .. } => 3,
        };
        let digital = matches!(self.presence, PresenceInput::Digital) as u16;
        let lane_tension = matches!(self.tension, TensionAt::Lane) as u16;
        motion | digital << 2 | lane_tension << 3 | (self.hub_sensor as u16) << 4
    }
}

/// The thesis build: an analog Hall per motor reading one magnet per revolution, analog Hall
/// presence sensors, the hub's filament and tension sensors.
pub const THESIS: Profile = Profile {
    name: "thesis",
    motion: MotionSensor::HallWave,
    presence: PresenceInput::Analog,
    tension: TensionAt::Hub,
    hub_sensor: true,
    max_slots: crate::MAX_SLOTS,
    mm_per_rev_centi: 200,
};

/// Lanes of N20 gear motors with a magnetic quadrature encoder (7 pulses per channel per motor
/// turn, 100:1), on an MK8-type drive gear of 7.5 mm effective diameter; the hub as in the
/// thesis build.
pub const N20_QUADRATURE: Profile = Profile {
    name: "n20-quadrature",
    motion: MotionSensor::Quadrature {
        counts_per_rev: 4 * 7 * 100,
    },
    presence: PresenceInput::Analog,
    tension: TensionAt::Hub,
    hub_sensor: true,
    max_slots: crate::MAX_SLOTS,
    mm_per_rev_centi: 2356,
};

/// The BMCU-C kit: four lanes, an AS5600 on each drive gear (7.5 mm effective diameter), an
/// opto presence sensor and a sprung tension slider per lane, no hub sensor.
pub const BMCU_C: Profile = Profile {
    name: "bmcu-c",
    motion: MotionSensor::Angle,
    presence: PresenceInput::Analog,
    tension: TensionAt::Lane,
    hub_sensor: false,
    max_slots: 4,
    mm_per_rev_centi: 2356,
};

/// Every profile, the default first.
pub const ALL: [&Profile; 3] = [&THESIS, &N20_QUADRATURE, &BMCU_C];

/// The profile called `name`.
pub fn by_name(name: &str) -> Option<&'static Profile> {
    ALL.iter().copied().find(|profile| profile.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_profile_is_found_by_its_name_and_fits_the_printers_menus() {
        for profile in ALL {
            assert_eq!(by_name(profile.name), Some(profile));
            assert!((1..=crate::MAX_SLOTS).contains(&profile.max_slots));
            assert!(profile.motion.counts_per_rev() >= 1);
            // A tension sensor per lane takes a diagnostic index of its own: 4 lanes fit.
            assert!(profile.tension == TensionAt::Hub || profile.max_slots <= 4);
        }
        let codes: [u16; 3] = ALL.map(Profile::code);
        assert_eq!(codes, [0b1_0000, 0b1_0001, 0b0_1010]);
        assert_eq!(by_name("mk3"), None);
    }
}
