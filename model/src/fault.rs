//! Injectable faults.

/// One analog sensor of the unit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SensorId {
    /// The motor Hall sensor of a slot.
    MotorHall(usize),
    /// The filament sensor at a slot's entry.
    SlotFilament(usize),
    /// The hub filament sensor (the unit's FINDA).
    HubFilament,
    /// The hub tension (buffer) sensor.
    HubTension,
    /// A lane's own tension sensor (a profile with one per lane).
    LaneTension(usize),
    /// The hub cutter sensor.
    HubCutter,
}

impl SensorId {
    /// The slot this sensor belongs to, if it is a per-slot sensor.
    pub fn slot(self) -> Option<usize> {
        match self {
            SensorId::MotorHall(slot) | SensorId::SlotFilament(slot) | SensorId::LaneTension(slot) => {
                Some(slot)
            }
            SensorId::HubFilament | SensorId::HubTension | SensorId::HubCutter => None,
        }
    }
}

/// The supply rail a disconnected sensor's input floats to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Rail {
    /// Pulled to ground: reads 0.
    Low,
    /// Pulled to the supply: reads [`ADC_MAX`](mmu_hal_port::ADC_MAX) (4095).
    High,
}

impl Rail {
    /// The raw sample a sensor stuck at this rail reads.
    pub fn counts(self) -> u16 {
        match self {
            Rail::Low => 0,
            Rail::High => mmu_hal_port::ADC_MAX,
        }
    }
}

/// A fault that can be injected into the [`Model`](crate::Model) and cleared again.
///
/// At most one fault of each [`FaultKind`] is active: injecting another one of the same kind
/// replaces it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Fault {
    /// The filament of `slot` cannot move forward past where it is when the fault is injected
    /// (a knot or a crushed tube in the slot path). It can still be pulled back and pushed up
    /// to that point again. A motor pushing against it stalls.
    Jam {
        /// The slot.
        slot: usize,
    },
    /// Nothing passes [`ModelConfig::bowden_jam_mm`](crate::ModelConfig::bowden_jam_mm) in the
    /// Bowden tube: a tip before it stops there; a filament already through it cannot move at
    /// all at that point.
    BowdenJam,
    /// The drive gear of `slot` slips: the filament moves `ratio` × the motor's motion
    /// (`ratio` is clamped to 0..=1; e.g. 0.7).
    Slip {
        /// The slot.
        slot: usize,
        /// Filament motion per motor motion.
        ratio: f32,
    },
    /// The motor of `slot` has no torque and does not turn (a seized or disconnected
    /// gearmotor): no motion, no Hall change; its gearbox holds the filament like a brake.
    MotorDead {
        /// The slot.
        slot: usize,
    },
    /// Every sensor's Gaussian noise has σ = `sigma` counts instead of the configured one.
    SensorNoise {
        /// Standard deviation, counts (non-negative, finite).
        sigma: f32,
    },
    /// `sensor` is disconnected and reads exactly `rail`.
    SensorDisconnected {
        /// Which sensor.
        sensor: SensorId,
        /// Where its input floats.
        rail: Rail,
    },
    /// The spool of `slot` has run out: the filament's tail is just past the slot sensor,
    /// which reads empty. The motor can push the rest of the filament only while its tail is
    /// still in the drive gear: with the default layout (sensor just after the gear) the tail has
    /// already left it, so nothing moves the filament but an extruder that holds its tip.
    /// Clearing it refills the spool behind the filament.
    SpoolRunout {
        /// The slot.
        slot: usize,
    },
    /// The spool of `slot` has ended with its end fastened to the spool's core, where the
    /// filament is when the fault is injected: it cannot move forward past that point (the slot
    /// sensor still reads filament), as under a [`Fault::Jam`], and can be pulled back. Clearing
    /// it puts a new spool behind the filament. It shares the slot's jam limit: with a
    /// [`Fault::Jam`] of the same slot active, clearing either frees both.
    SpoolFastened {
        /// The slot.
        slot: usize,
    },
    /// The printer's filament sensor clears late: it reads filament `delay_ms` after the
    /// filament has left it (a sticky lever or a badly calibrated threshold; users report
    /// "fsensor still on" 0.5 to 8 s into an unload, Prusa-Firmware-Buddy #5158, #5344).
    FsensorLate {
        /// How long the sensor goes on reading filament, ms.
        delay_ms: u32,
    },
    /// A deformed or stringy tip on `slot`'s filament: the extruder's gears keep gripping it
    /// until its tip is `mm` behind them (a string or a flattened, widened end still between
    /// the gears). While they hold it, it moves only with the extruder, and a motor pulling
    /// back pulls against the gears (which win). Prusa's maintainers describe it so: "filament
    /// is still held by the drive gear, fsensor doesn't turn off" (Prusa-Firmware-Buddy #5158),
    /// "the drive gear can hold even thin long strings" (Prusa-Firmware-MMU #271). Injected
    /// while the tip is in the gears it applies at once; otherwise from the next time the tip
    /// enters them. `mm` is clamped to 0..=[`MAX_TIP_CATCH_MM`](crate::MAX_TIP_CATCH_MM).
    TipCatch {
        /// The slot.
        slot: usize,
        /// How far behind the gears the tip must be for them to let go, mm.
        mm: f32,
    },
    /// The printer retracts more slowly than it commands: every extruder move back runs at
    /// `factor` × its speed (clamped to [`MIN_RETRACT_FACTOR`](crate::MIN_RETRACT_FACTOR)..=1;
    /// e.g. 0.5 or 0.25: a worn or hot extruder, a stiff filament path).
    SlowRetract {
        /// Fraction of the commanded retract speed.
        factor: f32,
    },
}

/// Which fault, without its parameters: the key for [`Model::clear`](crate::Model::clear).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum FaultKind {
    /// [`Fault::Jam`] of a slot.
    Jam(usize),
    /// [`Fault::BowdenJam`].
    BowdenJam,
    /// [`Fault::Slip`] of a slot.
    Slip(usize),
    /// [`Fault::MotorDead`] of a slot.
    MotorDead(usize),
    /// [`Fault::SensorNoise`].
    SensorNoise,
    /// [`Fault::SensorDisconnected`] of a sensor.
    SensorDisconnected(SensorId),
    /// [`Fault::SpoolRunout`] of a slot.
    SpoolRunout(usize),
    /// [`Fault::SpoolFastened`] of a slot.
    SpoolFastened(usize),
    /// [`Fault::FsensorLate`].
    FsensorLate,
    /// [`Fault::TipCatch`] of a slot.
    TipCatch(usize),
    /// [`Fault::SlowRetract`].
    SlowRetract,
}

impl FaultKind {
    /// The slot this fault concerns, if it concerns one slot.
    pub fn slot(self) -> Option<usize> {
        match self {
            FaultKind::Jam(slot)
            | FaultKind::Slip(slot)
            | FaultKind::MotorDead(slot)
            | FaultKind::SpoolRunout(slot)
            | FaultKind::SpoolFastened(slot)
            | FaultKind::TipCatch(slot) => Some(slot),
            FaultKind::SensorDisconnected(sensor) => sensor.slot(),
            FaultKind::BowdenJam
            | FaultKind::SensorNoise
            | FaultKind::FsensorLate
            | FaultKind::SlowRetract => None,
        }
    }
}

impl Fault {
    /// This fault's kind.
    pub fn kind(&self) -> FaultKind {
        match *self {
            Fault::Jam { slot } => FaultKind::Jam(slot),
            Fault::BowdenJam => FaultKind::BowdenJam,
            Fault::Slip { slot, .. } => FaultKind::Slip(slot),
            Fault::MotorDead { slot } => FaultKind::MotorDead(slot),
            Fault::SensorNoise { .. } => FaultKind::SensorNoise,
            Fault::SensorDisconnected { sensor, .. } => FaultKind::SensorDisconnected(sensor),
            Fault::SpoolRunout { slot } => FaultKind::SpoolRunout(slot),
            Fault::SpoolFastened { slot } => FaultKind::SpoolFastened(slot),
            Fault::FsensorLate { .. } => FaultKind::FsensorLate,
            Fault::TipCatch { slot, .. } => FaultKind::TipCatch(slot),
            Fault::SlowRetract { .. } => FaultKind::SlowRetract,
        }
    }
}

impl From<Fault> for FaultKind {
    fn from(fault: Fault) -> Self {
        fault.kind()
    }
}

impl From<&Fault> for FaultKind {
    fn from(fault: &Fault) -> Self {
        fault.kind()
    }
}

impl From<&FaultKind> for FaultKind {
    fn from(kind: &FaultKind) -> Self {
        *kind
    }
}
