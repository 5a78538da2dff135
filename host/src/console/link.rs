//! The console's wire: the simulator or a serial port, with the printer's filament sensor as the
//! person at the bench sets it (`fsensor on|off|auto`).

use std::io;

use mmu_sim::{Link, ScheduledFault, Sim, SimLink};

use crate::printer_cli::console::Target;
use crate::printer_cli::serial::SerialLink;

/// Where the printer's filament sensor state comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FsensorMode {
    /// The simulator's printer, or for a serial port its `--fsensor-events` file (else 0).
    Auto,
    /// Always this state: 0 no filament, 1 at the sensor, 2 in the nozzle.
    Fixed(u8),
}

/// The unit behind the console.
pub enum Wire {
    /// The in-process simulator (boxed: it is large).
    Sim(Box<SimLink>),
    /// A unit (or `mmu sim --pty`) on a serial port.
    Serial(SerialLink),
}

/// The wire with the printer's filament sensor the console plays.
pub struct BenchLink {
    wire: Wire,
    /// The sensor from now on.
    pub fsensor: FsensorMode,
}

impl BenchLink {
    /// `wire`, its sensor read as it says ([`FsensorMode::Auto`]).
    pub fn new(wire: Wire) -> Self {
        BenchLink {
            wire,
            fsensor: FsensorMode::Auto,
        }
    }

    /// The simulator, when the unit is one.
    pub fn sim_mut(&mut self) -> Option<&mut Sim> {
        match &mut self.wire {
            Wire::Sim(link) => Some(link.sim_mut()),
            Wire::Serial(_) => None,
        }
    }

    /// The simulator, when the unit is one.
    pub fn sim(&self) -> Option<&Sim> {
        match &self.wire {
            Wire::Sim(link) => Some(link.sim()),
            Wire::Serial(_) => None,
        }
    }

    /// Let `ms` pass on the printer's clock, dropping whatever the unit says meanwhile.
    pub fn pause(&mut self, ms: u64) -> io::Result<()> {
        let end = self.now_ms() + ms;
        while self.now_ms() < end {
            let step = (end - self.now_ms()).min(5);
            self.receive(step, &mut Vec::new())?;
        }
        Ok(())
    }
}

impl Link for BenchLink {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        match &mut self.wire {
            Wire::Sim(link) => link.send(bytes),
            Wire::Serial(link) => link.send(bytes),
        }
    }

    fn receive(&mut self, max_ms: u64, into: &mut Vec<u8>) -> io::Result<()> {
        match &mut self.wire {
            Wire::Sim(link) => link.receive(max_ms, into),
            Wire::Serial(link) => link.receive(max_ms, into),
        }
    }

    fn now_ms(&self) -> u64 {
        match &self.wire {
            Wire::Sim(link) => link.now_ms(),
            Wire::Serial(link) => link.now_ms(),
        }
    }

    fn fsensor(&mut self) -> u8 {
        match (self.fsensor, &mut self.wire) {
            (FsensorMode::Fixed(state), _) => state,
            (FsensorMode::Auto, Wire::Sim(link)) => link.fsensor(),
            (FsensorMode::Auto, Wire::Serial(link)) => link.fsensor(),
        }
    }
}

impl Target for BenchLink {
    fn remove_filament(&mut self, slot: u8) -> bool {
        match &mut self.wire {
            Wire::Sim(link) => link.remove_filament(slot),
            Wire::Serial(link) => link.remove_filament(slot),
        }
    }

    fn notes(&mut self) -> Vec<(u64, String)> {
        match &mut self.wire {
            Wire::Sim(link) => link.notes(),
            Wire::Serial(link) => link.notes(),
        }
    }

    fn no_answer_hint(&self) -> Option<String> {
        match &self.wire {
            Wire::Sim(_) => None,
            Wire::Serial(link) => link.no_answer_hint(),
        }
    }
}

/// Inject the simulator fault `spec`; what happened, in words.
pub fn sim_fault(link: &mut BenchLink, spec: &str) -> String {
    let Some(sim) = link.sim_mut() else {
        return "sim fault: only with --sim".into();
    };
    match spec.parse::<ScheduledFault>() {
        Ok(fault) if sim.inject(fault.fault) => format!("sim: fault {spec} injected"),
        Ok(_) => format!("sim: fault {spec} could not be injected (already active, or no such slot)"),
        Err(error) => error.to_string(),
    }
}

/// Clear every simulator fault.
pub fn sim_clear(link: &mut BenchLink) -> String {
    let Some(sim) = link.sim_mut() else {
        return "sim clear: only with --sim".into();
    };
    let faults = sim.active_faults();
    for fault in &faults {
        sim.clear(fault.kind());
    }
    format!("sim: {} fault(s) cleared", faults.len())
}
