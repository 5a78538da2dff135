//! Faults the simulator can inject: the model's physical faults plus the ones that belong to the
//! harness (a noisy UART, power loss), and the `--fault` text syntax that names them.
//!
//! Syntax: `NAME[:ARG[:ARG]][@START_MS[-END_MS]]`, e.g. `jam:1@2000-9000` (slot 1 jams at 2 s
//! and is freed at 9 s), `slip:0:0.6`, `noise:80`, `disconnect:hub-filament:low`,
//! `uart-corrupt:0.01`, `power-loss:300@5000`. See [`FAULT_HELP`].

use std::fmt;
use std::str::FromStr;

use mmu_model::{Fault, FaultKind, Rail, SensorId};

/// One line per fault name, for `--help` texts and error messages.
pub const FAULT_HELP: &str = "\
jam:SLOT                     the slot's filament cannot move forward
bowden-jam                   nothing passes the middle of the Bowden tube
slip:SLOT:RATIO              the slot's drive gear slips (filament motion = RATIO x motor motion)
motor-dead:SLOT              the slot's motor does not turn
noise:SIGMA                  every sensor's noise has this standard deviation, ADC counts
disconnect:SENSOR[:low|high] a sensor reads its rail (SENSOR: hub-filament, hub-tension,
                             hub-cutter, slot-filament-K, motor-hall-K (the lane's
                             motion sensor), lane-tension-K; default low)
runout:SLOT                  the slot's spool runs out (clearing refills it)
fastened-end:SLOT            the slot's spool ends, its end fastened to the core (clearing: a new spool)
uart-corrupt:P               each UART byte (both directions) has one bit flipped with probability P
uart-drop:P                  each UART byte (both directions) is lost with probability P
power-loss[:OFF_MS]          the unit loses power for OFF_MS (default 500) and restarts
fsensor-late:MS              the printer's filament sensor reads filament MS after it left
tip-catch:SLOT:MM            the slot's tip (deformed, stringy) stays in the extruder's gears
                             until it is MM behind them
slow-retract:FACTOR          the printer's retracts run at FACTOR x their speed (e.g. 0.5)
Append @START_MS or @START_MS-END_MS to inject at a virtual time and clear later.";

/// A fault of the simulated unit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SimFault {
    /// A physical fault of the model.
    Model(Fault),
    /// Each byte on the UART, in either direction, has one random bit flipped with this
    /// probability.
    UartCorrupt {
        /// Per byte, 0..=1.
        probability: f32,
    },
    /// Each byte on the UART, in either direction, is lost with this probability.
    UartDrop {
        /// Per byte, 0..=1.
        probability: f32,
    },
    /// The unit loses power for `off_ms` and boots again. A one-off event: nothing to clear.
    PowerLoss {
        /// How long the unit stays unpowered, ms.
        off_ms: u32,
    },
}

/// Which fault, without its parameters: the key to clear it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SimFaultKind {
    /// A physical fault of the model.
    Model(FaultKind),
    /// [`SimFault::UartCorrupt`].
    UartCorrupt,
    /// [`SimFault::UartDrop`].
    UartDrop,
    /// [`SimFault::PowerLoss`].
    PowerLoss,
}

impl SimFault {
    /// The key that clears this fault.
    pub fn kind(&self) -> SimFaultKind {
        match self {
            SimFault::Model(fault) => SimFaultKind::Model(fault.kind()),
            SimFault::UartCorrupt { .. } => SimFaultKind::UartCorrupt,
            SimFault::UartDrop { .. } => SimFaultKind::UartDrop,
            SimFault::PowerLoss { .. } => SimFaultKind::PowerLoss,
        }
    }
}

/// A fault with the virtual times it is injected and cleared at.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScheduledFault {
    /// The fault.
    pub fault: SimFault,
    /// When it is injected, ms of virtual time.
    pub at_ms: u64,
    /// When it is cleared, if ever.
    pub until_ms: Option<u64>,
}

/// A `--fault` text that does not name a fault.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FaultSpecError(String);

impl fmt::Display for FaultSpecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}; faults are:\n{FAULT_HELP}", self.0)
    }
}

impl std::error::Error for FaultSpecError {}

fn bad(spec: &str, why: &str) -> FaultSpecError {
    FaultSpecError(format!("bad fault `{spec}`: {why}"))
}

fn number<T: FromStr>(spec: &str, arg: Option<&str>, what: &str) -> Result<T, FaultSpecError> {
    arg.ok_or_else(|| bad(spec, &format!("missing {what}")))?
        .parse()
        .map_err(|_| bad(spec, &format!("{what} is not a number")))
}

fn probability(spec: &str, arg: Option<&str>) -> Result<f32, FaultSpecError> {
    let p: f32 = number(spec, arg, "probability")?;
    if (0.0..=1.0).contains(&p) {
        Ok(p)
    } else {
        Err(bad(spec, "probability must be within 0..=1"))
    }
}

fn sensor(spec: &str, name: Option<&str>) -> Result<SensorId, FaultSpecError> {
    let name = name.ok_or_else(|| bad(spec, "missing sensor"))?;
    let slot = |prefix: &str| {
        name.strip_prefix(prefix)
            .and_then(|k| k.parse().ok())
            .ok_or_else(|| bad(spec, "unknown sensor"))
    };
    match name {
        "hub-filament" => Ok(SensorId::HubFilament),
        "hub-tension" => Ok(SensorId::HubTension),
        "hub-cutter" => Ok(SensorId::HubCutter),
        _ if name.starts_with("slot-filament-") => slot("slot-filament-").map(SensorId::SlotFilament),
        _ if name.starts_with("motor-hall-") => slot("motor-hall-").map(SensorId::MotorHall),
        _ if name.starts_with("lane-tension-") => slot("lane-tension-").map(SensorId::LaneTension),
        _ => Err(bad(spec, "unknown sensor")),
    }
}

fn sensor_name(sensor: SensorId) -> String {
    match sensor {
        SensorId::HubFilament => "hub-filament".into(),
        SensorId::HubTension => "hub-tension".into(),
        SensorId::HubCutter => "hub-cutter".into(),
        SensorId::SlotFilament(k) => format!("slot-filament-{k}"),
        SensorId::MotorHall(k) => format!("motor-hall-{k}"),
        SensorId::LaneTension(k) => format!("lane-tension-{k}"),
    }
}

impl FromStr for SimFault {
    type Err = FaultSpecError;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let mut parts = spec.split(':');
        let name = parts.next().unwrap_or_default();
        let (a, b) = (parts.next(), parts.next());
        if parts.next().is_some() {
            return Err(bad(spec, "too many arguments"));
        }
        let slot = || number::<usize>(spec, a, "slot");
        let fault = match name {
            "jam" => SimFault::Model(Fault::Jam { slot: slot()? }),
            "bowden-jam" => SimFault::Model(Fault::BowdenJam),
            "slip" => {
                let ratio: f32 = number(spec, b, "ratio")?;
                if !(0.0..=1.0).contains(&ratio) {
                    return Err(bad(spec, "ratio must be within 0..=1"));
                }
                SimFault::Model(Fault::Slip { slot: slot()?, ratio })
            }
            "motor-dead" => SimFault::Model(Fault::MotorDead { slot: slot()? }),
            "noise" => {
                let sigma: f32 = number(spec, a, "sigma")?;
                if !(sigma.is_finite() && sigma >= 0.0) {
                    return Err(bad(spec, "sigma must be a non-negative number"));
                }
                SimFault::Model(Fault::SensorNoise { sigma })
            }
            "disconnect" => {
                let rail = match b {
                    None | Some("low") => Rail::Low,
                    Some("high") => Rail::High,
                    Some(_) => return Err(bad(spec, "the rail is low or high")),
                };
                SimFault::Model(Fault::SensorDisconnected {
                    sensor: sensor(spec, a)?,
                    rail,
                })
            }
            "runout" => SimFault::Model(Fault::SpoolRunout { slot: slot()? }),
            "fsensor-late" => SimFault::Model(Fault::FsensorLate {
                delay_ms: number(spec, a, "delay")?,
            }),
            "tip-catch" => {
                let mm: f32 = number(spec, b, "length")?;
                if !(0.0..=mmu_model::MAX_TIP_CATCH_MM).contains(&mm) {
                    return Err(bad(spec, "the length must be within 0..=100 mm"));
                }
                SimFault::Model(Fault::TipCatch { slot: slot()?, mm })
            }
            "slow-retract" => {
                let factor: f32 = number(spec, a, "factor")?;
                if !(mmu_model::MIN_RETRACT_FACTOR..=1.0).contains(&factor) {
                    return Err(bad(spec, "the factor must be within 0.01..=1"));
                }
                SimFault::Model(Fault::SlowRetract { factor })
            }
            "fastened-end" => SimFault::Model(Fault::SpoolFastened { slot: slot()? }),
            "uart-corrupt" => SimFault::UartCorrupt {
                probability: probability(spec, a)?,
            },
            "uart-drop" => SimFault::UartDrop {
                probability: probability(spec, a)?,
            },
            "power-loss" => SimFault::PowerLoss {
                off_ms: a.map_or(Ok(500), |_| number(spec, a, "off time"))?,
            },
            _ => return Err(bad(spec, "unknown fault")),
        };
        let args = usize::from(a.is_some()) + usize::from(b.is_some());
        let expected = match fault {
            SimFault::Model(Fault::BowdenJam) => 0..=0,
            SimFault::Model(Fault::Slip { .. } | Fault::TipCatch { .. }) => 2..=2,
            SimFault::Model(Fault::SensorDisconnected { .. }) => 1..=2,
            SimFault::PowerLoss { .. } => 0..=1,
            _ => 1..=1,
        };
        if !expected.contains(&args) {
            return Err(bad(spec, "wrong number of arguments"));
        }
        Ok(fault)
    }
}

impl SimFault {
    /// The slot this fault names (a slot's motor, spool or sensor), if any.
    pub fn slot(&self) -> Option<usize> {
        match *self {
            SimFault::Model(
                Fault::Jam { slot }
                | Fault::Slip { slot, .. }
                | Fault::MotorDead { slot }
                | Fault::SpoolRunout { slot }
                | Fault::SpoolFastened { slot }
                | Fault::TipCatch { slot, .. },
            ) => Some(slot),
            SimFault::Model(Fault::SensorDisconnected {
                sensor: SensorId::SlotFilament(slot) | SensorId::MotorHall(slot),
                ..
            }) => Some(slot),
            _ => None,
        }
    }

    /// Refuse a fault naming a slot (or a slot's sensor) that a unit of `slots` slots lacks.
    pub fn check_slots(&self, slots: usize) -> Result<(), FaultSpecError> {
        match self.slot() {
            Some(slot) if slot >= slots => Err(FaultSpecError(format!(
                "bad fault `{self}`: the unit has no slot {slot} (it has {slots} slots, 0 to {})",
                slots.saturating_sub(1)
            ))),
            _ => Ok(()),
        }
    }
}

impl fmt::Display for SimFault {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            SimFault::Model(Fault::Jam { slot }) => write!(f, "jam:{slot}"),
            SimFault::Model(Fault::BowdenJam) => write!(f, "bowden-jam"),
            SimFault::Model(Fault::Slip { slot, ratio }) => write!(f, "slip:{slot}:{ratio}"),
            SimFault::Model(Fault::MotorDead { slot }) => write!(f, "motor-dead:{slot}"),
            SimFault::Model(Fault::SensorNoise { sigma }) => write!(f, "noise:{sigma}"),
            SimFault::Model(Fault::SensorDisconnected { sensor, rail }) => {
                let rail = if rail == Rail::High { "high" } else { "low" };
                write!(f, "disconnect:{}:{rail}", sensor_name(sensor))
            }
            SimFault::Model(Fault::SpoolRunout { slot }) => write!(f, "runout:{slot}"),
            SimFault::Model(Fault::SpoolFastened { slot }) => write!(f, "fastened-end:{slot}"),
            SimFault::Model(Fault::FsensorLate { delay_ms }) => write!(f, "fsensor-late:{delay_ms}"),
            SimFault::Model(Fault::TipCatch { slot, mm }) => write!(f, "tip-catch:{slot}:{mm}"),
            SimFault::Model(Fault::SlowRetract { factor }) => write!(f, "slow-retract:{factor}"),
            SimFault::UartCorrupt { probability } => write!(f, "uart-corrupt:{probability}"),
            SimFault::UartDrop { probability } => write!(f, "uart-drop:{probability}"),
            SimFault::PowerLoss { off_ms } => write!(f, "power-loss:{off_ms}"),
        }
    }
}

impl FromStr for ScheduledFault {
    type Err = FaultSpecError;

    fn from_str(spec: &str) -> Result<Self, Self::Err> {
        let (fault, when) = match spec.split_once('@') {
            Some((fault, when)) => (fault, Some(when)),
            None => (spec, None),
        };
        let fault = fault.parse()?;
        let time = |text: &str| {
            text.parse::<u64>()
                .map_err(|_| bad(spec, "times are whole milliseconds"))
        };
        let (at_ms, until_ms) = match when.map(|w| w.split_once('-').ok_or(w)) {
            None => (0, None),
            Some(Err(at)) => (time(at)?, None),
            Some(Ok((at, until))) => (time(at)?, Some(time(until)?)),
        };
        if until_ms.is_some_and(|until| until <= at_ms) {
            return Err(bad(spec, "the end time must come after the start"));
        }
        Ok(ScheduledFault {
            fault,
            at_ms,
            until_ms,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_fault_prints_as_it_parses() {
        for spec in [
            "jam:1",
            "bowden-jam",
            "slip:0:0.6",
            "motor-dead:2",
            "noise:80",
            "disconnect:hub-filament:low",
            "disconnect:motor-hall-2:high",
            "disconnect:slot-filament-0:low",
            "runout:1",
            "fastened-end:2",
            "uart-corrupt:0.01",
            "uart-drop:0.5",
            "power-loss:300",
        ] {
            let fault: SimFault = spec.parse().unwrap();
            assert_eq!(fault.to_string(), spec);
        }
    }

    #[test]
    fn defaults_and_schedules() {
        assert_eq!(
            "power-loss".parse::<SimFault>(),
            Ok(SimFault::PowerLoss { off_ms: 500 })
        );
        assert_eq!(
            "disconnect:hub-tension".parse::<SimFault>(),
            Ok(SimFault::Model(Fault::SensorDisconnected {
                sensor: SensorId::HubTension,
                rail: Rail::Low
            }))
        );
        let scheduled: ScheduledFault = "jam:1@2000-9000".parse().unwrap();
        assert_eq!((scheduled.at_ms, scheduled.until_ms), (2000, Some(9000)));
        let scheduled: ScheduledFault = "bowden-jam@500".parse().unwrap();
        assert_eq!((scheduled.at_ms, scheduled.until_ms), (500, None));
    }

    #[test]
    fn bad_specs_say_why() {
        for (spec, why) in [
            ("", "unknown fault"),
            ("jam", "missing slot"),
            ("jam:x", "slot is not a number"),
            ("jam:1:2", "wrong number of arguments"),
            ("slip:0:1.5", "ratio must be within 0..=1"),
            ("uart-drop:2", "probability must be within 0..=1"),
            ("disconnect:elbow", "unknown sensor"),
            ("disconnect:hub-filament:sideways", "the rail is low or high"),
            ("jam:1@9000-2000", "the end time must come after the start"),
            ("jam:1@soon", "times are whole milliseconds"),
            ("bowden-jam:1", "wrong number of arguments"),
        ] {
            let error = spec.parse::<ScheduledFault>().unwrap_err().to_string();
            assert!(error.contains(why), "{spec}: {error}");
            assert!(error.contains("faults are:"), "{spec}: {error}");
        }
    }

    #[test]
    fn faults_naming_a_missing_slot_are_refused() {
        for spec in [
            "jam:3",
            "slip:7:0.5",
            "motor-dead:3",
            "runout:4",
            "disconnect:slot-filament-3",
            "disconnect:motor-hall-9:high",
        ] {
            let fault: SimFault = spec.parse().unwrap();
            let error = fault.check_slots(3).unwrap_err().to_string();
            assert!(error.contains("the unit has no slot"), "{spec}: {error}");
        }
        for spec in [
            "jam:2",
            "disconnect:hub-filament",
            "disconnect:motor-hall-2",
            "noise:5",
            "bowden-jam",
        ] {
            let fault: SimFault = spec.parse().unwrap();
            assert_eq!(fault.check_slots(3), Ok(()), "{spec}");
        }
    }
}
