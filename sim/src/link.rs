//! The in-process link: a [`Printer`](crate::printer::Printer) talking to a [`Sim`] in virtual
//! time, optionally paced to a multiple of real time so a person can watch.

use std::io;
use std::time::{Duration, Instant};

use crate::printer::Link;
use crate::sim::Sim;

/// The simulator as a [`Link`]: receiving steps the simulator; the printer's filament sensor is
/// the model's.
pub struct SimLink {
    sim: Sim,
    outbox: Vec<u8>,
    pace: Option<(Instant, u64, f64)>,
}

impl SimLink {
    /// A link to `sim` that runs as fast as the CPU allows.
    pub fn new(sim: Sim) -> Self {
        SimLink {
            sim,
            outbox: Vec::new(),
            pace: None,
        }
    }

    /// Run no faster than `scale` × real time from now on (`None`: as fast as possible).
    pub fn set_time_scale(&mut self, scale: Option<f64>) {
        self.pace = scale
            .filter(|k| k.is_finite() && *k > 0.0)
            .map(|k| (Instant::now(), self.sim.now_ms(), k));
    }

    /// The simulator.
    pub fn sim(&self) -> &Sim {
        &self.sim
    }

    /// The simulator, to inject faults or play the user.
    pub fn sim_mut(&mut self) -> &mut Sim {
        &mut self.sim
    }

    /// Run the simulator for `ms` with nothing sent; what the unit says is dropped.
    pub fn idle(&mut self, ms: u64) {
        let mut tx = Vec::new();
        for _ in 0..ms {
            self.step(&mut tx);
            tx.clear();
        }
    }

    fn step(&mut self, tx: &mut Vec<u8>) {
        let rx = std::mem::take(&mut self.outbox);
        self.sim.step(&rx, tx);
        if let Some((wall_start, sim_start, scale)) = self.pace {
            let due = (self.sim.now_ms() - sim_start) as f64 / scale;
            let ahead = due - wall_start.elapsed().as_secs_f64() * 1000.0;
            if ahead > 1.0 {
                std::thread::sleep(Duration::from_secs_f64(ahead / 1000.0));
            }
        }
    }
}

impl Link for SimLink {
    fn send(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.outbox.extend_from_slice(bytes);
        Ok(())
    }

    fn receive(&mut self, max_ms: u64, into: &mut Vec<u8>) -> io::Result<()> {
        let before = into.len();
        for _ in 0..max_ms {
            self.step(into);
            if into.len() > before {
                break;
            }
        }
        Ok(())
    }

    fn now_ms(&self) -> u64 {
        self.sim.now_ms()
    }

    fn fsensor(&mut self) -> u8 {
        self.sim.model().fsensor_state()
    }
}
