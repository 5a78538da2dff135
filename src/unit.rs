//! The unit's hardware state as the logic knows it: every feeding system, the Filament Hub's
//! sensors, the printer's filament sensor as last reported, and where each slot's filament is.

use mmu_hal_port::{MotorCommand, Samples};

use crate::config::Config;
use crate::drive::SlotDrive;
use crate::feeder::{Feeder, distance_centi};
use crate::profile::{MotionSensor, PresenceInput, Profile, THESIS, TensionAt};
use crate::sensor::{AnalogSensor, FilterKind, PresenceSensor};
use crate::time::Instant;
use crate::tip::TipEstimates;

/// Where one slot's filament is, as far as the unit knows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Lane {
    /// Not known (after start, or after the user fixed an error by hand).
    #[default]
    Unknown,
    /// No filament at the slot sensor.
    Empty,
    /// The tip rests at the park position before the hub.
    Parked,
    /// The tip is past the park position, in the hub or the Bowden tube.
    InHub,
    /// The tip reached the printer's filament sensor.
    AtFsensor,
    /// Loaded into the printer's extruder.
    Loaded,
}

impl Lane {
    /// Every lane state, in declaration order.
    pub const ALL: [Lane; 6] = [
        Lane::Unknown,
        Lane::Empty,
        Lane::Parked,
        Lane::InHub,
        Lane::AtFsensor,
        Lane::Loaded,
    ];

    /// True when this slot's filament occupies the hub path (at most one slot may).
    pub const fn owns_hub(self) -> bool {
        matches!(self, Lane::InHub | Lane::AtFsensor | Lane::Loaded)
    }

    /// The MMU3 `FilamentLoadState` (register 0x07) for a slot in this state.
    pub const fn mmu3_state(self) -> u16 {
        match self {
            Lane::Unknown | Lane::Empty => 0,
            Lane::Parked => 1,
            Lane::InHub => 2,
            Lane::AtFsensor => 4,
            Lane::Loaded => 8,
        }
    }
}

/// Marks ([`crate::odometer`]) of a coasting lane in one burst that prove the printer's extruder
/// moved its filament: 10 mm with the reference drive (a lone edge could be noise or a nudge by
/// hand).
pub const PROOF_MARKS: u8 = 5;
/// The longest pause between two marks of one burst, ms (the printer's extruder moves at 20 mm/s
/// or more: a mark every 100 ms).
pub const PROOF_GAP_MS: u64 = 500;

/// The diagnostic indices of sensors a unit may have at most: a diagnostic register block's.
pub const SENSOR_INDICES: usize = 16;

/// One of the unit's sensors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorId {
    /// Hub filament presence (the unit's FINDA).
    HubFilament,
    /// Hub Bowden tension.
    HubTension,
    /// Hub cutter (reserved).
    HubCutter,
    /// A slot's filament sensor.
    SlotFilament(usize),
    /// A slot's motion sensor (the motor Hall, the encoder, the angle sensor).
    Motion(usize),
    /// A slot's own tension sensor (a profile with [`TensionAt::Lane`]).
    LaneTension(usize),
}

impl SensorId {
    /// The sensor's index in the diagnostic registers of a unit with `slots` slots: hub sensors
    /// 0-2, then per slot k the filament sensor at 3 + 2k and the motion sensor at 4 + 2k, then
    /// each lane's tension sensor at 3 + 2 × `slots` + k. Every index exists on every hardware;
    /// a sensor the profile lacks reads as absent.
    pub const fn index(self, slots: usize) -> usize {
        match self {
            SensorId::HubFilament => 0,
            SensorId::HubTension => 1,
            SensorId::HubCutter => 2,
            SensorId::SlotFilament(slot) => 3 + 2 * slot,
            SensorId::Motion(slot) => 4 + 2 * slot,
            SensorId::LaneTension(slot) => 3 + 2 * slots + slot,
        }
    }

    /// The sensor at a diagnostic index of a unit with `slots` slots.
    pub const fn from_index(index: usize, slots: usize) -> Self {
        match index {
            0 => SensorId::HubFilament,
            1 => SensorId::HubTension,
            2 => SensorId::HubCutter,
            i if i >= 3 + 2 * slots => SensorId::LaneTension(i - 3 - 2 * slots),
            i if i % 2 == 1 => SensorId::SlotFilament((i - 3) / 2),
            i => SensorId::Motion((i - 4) / 2),
        }
    }

    /// How many diagnostic indices a unit with `slots` slots has: three in the hub and three
    /// per slot, within the 16 of a diagnostic block (a profile with a tension sensor per lane
    /// has at most 4 lanes; a 5-slot unit's indices stop at its third lane's tension sensor,
    /// which only such a profile has).
    pub const fn count(slots: usize) -> usize {
        let all = 3 + 3 * slots;
        if all < SENSOR_INDICES { all } else { SENSOR_INDICES }
    }
}

impl core::fmt::Display for SensorId {
    /// `hub.filament`, `hub.tension`, `hub.cutter`, `slot<k>.filament`, `slot<k>.motion`,
    /// `slot<k>.tension`.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            SensorId::HubFilament => f.write_str("hub.filament"),
            SensorId::HubTension => f.write_str("hub.tension"),
            SensorId::HubCutter => f.write_str("hub.cutter"),
            SensorId::SlotFilament(slot) => write!(f, "slot{slot}.filament"),
            SensorId::Motion(slot) => write!(f, "slot{slot}.motion"),
            SensorId::LaneTension(slot) => write!(f, "slot{slot}.tension"),
        }
    }
}

/// One sensor among the hub's and the slots' feeders, if `profile` has it.
pub fn sensor_in<'a>(
    profile: &Profile,
    hub: &'a Hub,
    feeders: &'a [Feeder],
    id: SensorId,
) -> Option<&'a AnalogSensor> {
    let hub_tension = profile.tension == TensionAt::Hub;
    match id {
        SensorId::HubFilament => profile.hub_sensor.then_some(&hub.filament.analog),
        SensorId::HubTension => hub_tension.then_some(&hub.tension),
        SensorId::HubCutter => profile.hub_sensor.then_some(&hub.cutter),
        SensorId::SlotFilament(slot) => feeders.get(slot).map(|f| &f.filament.analog),
        SensorId::Motion(slot) => feeders.get(slot).map(|f| &f.motion.sensor),
        SensorId::LaneTension(slot) => feeders.get(slot).filter(|_| !hub_tension).map(|f| &f.tension),
    }
}

/// The Filament Hub's sensors.
#[derive(Debug, Clone, Copy)]
pub struct Hub {
    /// Filament present in the hub.
    pub filament: PresenceSensor,
    /// Bowden tension.
    pub tension: AnalogSensor,
    /// Reserved cutter sensor.
    pub cutter: AnalogSensor,
}

/// The link name of the hardware profile a firmware binary fixes at build time (feature
/// `fixed-profile`): an immutable `Profile` it defines, the one it builds its App with.
pub const FIXED_PROFILE_SYMBOL: &str = "mmu_fixed_profile";

#[cfg(feature = "fixed-profile")]
unsafe extern "Rust" {
    #[link_name = "mmu_fixed_profile"]
    static FIXED_PROFILE: Profile;
}

/// Everything the logic knows about the hardware.
#[derive(Debug, Clone)]
pub struct Unit<const N: usize> {
    /// What senses each lane (read through [`Unit::profile`]).
    pub(crate) profile: &'static Profile,
    /// Per slot feeding systems' sensors.
    pub feeders: [Feeder; N],
    /// Per slot motors: the only way to move one ([`crate::drive`]).
    pub drives: [SlotDrive; N],
    /// The hub.
    pub hub: Hub,
    /// Where each slot's filament is.
    pub lanes: [Lane; N],
    /// The printer's filament sensor as last reported by `f` or register 9: 0 no filament,
    /// 1 at the sensor, 2 in the nozzle, 3 sensor unavailable (taken as triggered, as MMU3 does).
    pub fsensor: u8,
    /// The slot last asked for (MMU3 "selector slot").
    pub selected: Option<usize>,
    /// The slot this unit itself fed past its park position since it started: its ownership of
    /// the hub path is known, not a stored belief.
    pub proven_owner: Option<usize>,
    /// Per slot, marks counted in one burst (each within [`PROOF_GAP_MS`] of the last) while the
    /// motor coasted, since the last command ended: the printer's extruder moved that slot's
    /// filament, so it holds the hub path. A lone edge (noise, a nudge) never adds up.
    pub moved_by_printer: [u8; N],
    /// When each slot's last coasting mark came.
    coasting_mark_at: [Instant; N],
    /// Per slot: pulled back out of the merge since it was last fed towards the hub.
    pub clear_of_merge: [bool; N],
    /// On hardware without a hub sensor: where each lane's tip is ([`Unit::tip_centi`]).
    tips: TipEstimates<N>,
}

impl Default for Hub {
    fn default() -> Self {
        Self::NEW
    }
}

impl Hub {
    /// Sensors that have seen no sample.
    pub const NEW: Hub = Hub {
        filament: PresenceSensor::NEW,
        tension: AnalogSensor::NEW,
        cutter: AnalogSensor::NEW,
    };
}

impl<const N: usize> Default for Unit<N> {
    /// A unit that has seen no sample, every lane unknown.
    fn default() -> Self {
        Unit {
            profile: &THESIS,
            feeders: [Feeder::NEW; N],
            drives: [SlotDrive::NEW; N],
            hub: Hub::NEW,
            lanes: [Lane::Unknown; N],
            fsensor: 0,
            selected: None,
            proven_owner: None,
            moved_by_printer: [0; N],
            coasting_mark_at: [Instant::ZERO; N],
            clear_of_merge: [false; N],
            tips: TipEstimates::NEW,
        }
    }
}

impl<const N: usize> Unit<N> {
    /// Take a round of raw samples at `now`, read as the profile says.
    pub fn sense(&mut self, samples: &Samples<N>, now: Instant, config: &Config) {
        let profile = self.profile();
        self.tips.place_hub(config.lane_to_hub_mm);
        for (slot, ((feeder, sample), drive)) in self
            .feeders
            .iter_mut()
            .zip(samples.slots.iter())
            .zip(self.drives.iter())
            .enumerate()
        {
            let before = feeder.odometry_centi();
            let mark = feeder.sense(slot, *sample, drive.counting(), now, config, profile);
            if !profile.hub_sensor {
                let moved = distance_centi(before, feeder.odometry_centi());
                let driven = match drive.command() {
                    MotorCommand::Drive { direction, .. } => Some(direction),
                    MotorCommand::Coast | MotorCommand::Brake => None,
                };
                self.tips.follow(slot, moved, feeder.filament.present(), driven);
            }
            if mark
                && drive.is_coasting()
                && let (Some(moved), Some(last)) = (
                    self.moved_by_printer.get_mut(slot),
                    self.coasting_mark_at.get_mut(slot),
                )
            {
                let in_burst = now.millis_since(*last) <= PROOF_GAP_MS;
                *moved = if in_burst { moved.saturating_add(1) } else { 1 };
                *last = now;
            }
        }
        let hub = &samples.hub;
        if profile.hub_sensor {
            self.hub
                .filament
                .update(hub.filament, now, PresenceInput::Analog, config.hub_thresholds);
            self.hub.cutter.update(hub.cutter, now, FilterKind::Presence);
        }
        if profile.tension == TensionAt::Hub {
            self.hub.tension.update(hub.tension, now, FilterKind::Presence);
        }
    }

    /// The filament's motion between two marks of a lane ([`crate::odometer`]), 1/100 mm.
    pub fn mark_centi(&self, config: &Config) -> u16 {
        match self.profile().motion {
            MotionSensor::HallWave => config.mm_per_rev_centi,
            _ => crate::odometer::MARK_CENTI,
        }
    }

    /// The tension sensor that reads `slot`'s filament: the hub's, or the lane's own.
    pub fn tension_id(&self, slot: usize) -> SensorId {
        match self.profile().tension {
            TensionAt::Hub => SensorId::HubTension,
            TensionAt::Lane => SensorId::LaneTension(slot),
        }
    }

    /// The tension sensor that reads `slot`'s filament ([`Unit::tension_id`]).
    pub fn tension(&self, slot: usize) -> Option<&AnalogSensor> {
        self.sensor(self.tension_id(slot))
    }

    /// `slot`'s tension reading, if its sensor is healthy and warm.
    pub fn tension_reading(&self, slot: usize) -> Option<u16> {
        self.tension(slot).and_then(AnalogSensor::reading)
    }

    /// Filament in the hub, `None` while the hub sensor is faulty or warming up. Without a hub
    /// sensor: a lane's tip estimate at or past the merge (`lane_to_hub_mm`), or a lane recorded
    /// in the hub whose tip has not been seen since start (the record is the only word on it
    /// until its presence sensor's edge homes it: see [`crate::commands::fit_to_profile`]).
    pub fn hub_present(&self) -> Option<bool> {
        if self.profile().hub_sensor {
            return self.hub.filament.present();
        }
        let present = |slot: usize| self.feeders.get(slot).and_then(|f| f.filament.present());
        Some(self.tips.in_hub(&self.lanes, present))
    }

    /// Where `slot`'s tip is, 1/100 mm past its presence sensor, on hardware without a hub
    /// sensor: counted from the sensor's last edge (an edge is the tip passing it: a tip that
    /// comes in, or one pulled back out; a tail leaving forwards is a spool's end, not a tip).
    /// `None` on hardware with a hub sensor, and until such an edge since start.
    pub fn tip_centi(&self, slot: usize) -> Option<i32> {
        self.tips.tip_centi(slot)
    }

    /// The printer reports filament at (or past) its sensor.
    pub fn fsensor_triggered(&self) -> bool {
        self.fsensor != 0
    }

    /// True when `slot`'s claim on the hub path is more than a stored belief: this unit fed it
    /// there since it started, or the printer's extruder moved its filament (and no other) since
    /// the last command ended. Moving a slot backwards on a belief alone could drag the wrong
    /// filament out of its drive (README, "How the unit knows where the filament is").
    pub fn owner_proven(&self, slot: usize) -> bool {
        self.proven_owner == Some(slot) || (self.moved_by_printer(slot) && !self.owner_contradicted(slot))
    }

    /// True when the printer's extruder moved another slot's filament since the last command
    /// ended: `slot` cannot be the one holding the path, whatever the stored lanes say.
    pub fn owner_contradicted(&self, slot: usize) -> bool {
        self.proven_owner.is_none_or(|owner| owner != slot)
            && (0..N).any(|other| other != slot && self.moved_by_printer(other))
    }

    fn moved_by_printer(&self, slot: usize) -> bool {
        self.moved_by_printer
            .get(slot)
            .is_some_and(|&revolutions| revolutions >= PROOF_MARKS)
    }

    /// The slot whose filament occupies the hub path.
    pub fn active(&self) -> Option<usize> {
        self.lanes.iter().position(|lane| lane.owns_hub())
    }

    /// Brake `slot`'s motor (a slot the unit does not have: nothing).
    pub fn brake(&mut self, slot: usize, now: Instant) {
        if let Some(drive) = self.drives.get_mut(slot) {
            drive.brake(now);
        }
    }

    /// The lane of `slot` (`Unknown` for a slot the unit does not have).
    pub fn lane(&self, slot: usize) -> Lane {
        self.lanes.get(slot).copied().unwrap_or_default()
    }

    /// Record where `slot`'s filament is.
    pub fn set_lane(&mut self, slot: usize, lane: Lane) {
        if let Some(entry) = self.lanes.get_mut(slot) {
            *entry = lane;
        }
    }

    /// What senses each lane: the profile the unit was built with, or with the feature
    /// `fixed-profile` the one the firmware's binary fixes at build time
    /// ([`FIXED_PROFILE_SYMBOL`]), which lets the compiler drop every other profile's code.
    pub fn profile(&self) -> &'static Profile {
        #[cfg(feature = "fixed-profile")]
        {
            // SAFETY: the binary defines the symbol as an immutable `Profile` (the firmware's
            // `main`), the one it also builds the App with.
            unsafe { &FIXED_PROFILE }
        }
        #[cfg(not(feature = "fixed-profile"))]
        self.profile
    }

    /// One sensor, if the profile has it.
    pub fn sensor(&self, id: SensorId) -> Option<&AnalogSensor> {
        sensor_in(self.profile(), &self.hub, &self.feeders, id)
    }

    /// Every sensor the unit may have, in diagnostic order.
    pub fn sensor_ids() -> impl Iterator<Item = SensorId> {
        (0..SensorId::count(N)).map(|index| SensorId::from_index(index, N))
    }

    /// The first faulty sensor, if any.
    pub fn first_fault(&self) -> Option<SensorId> {
        Self::sensor_ids().find(|&id| self.sensor(id).is_some_and(|s| s.fault().is_some()))
    }
}
