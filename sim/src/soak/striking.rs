//! The soak's link: the in-process simulator with a fault that strikes at an exact virtual
//! millisecond, and what it struck (the fault, when, and the phase of a tool change the unit was
//! in).

use mmu_firmware::runner::Status;
use mmu_protocol::{ProgressCode, RequestCode};

use crate::fault::SimFault;
use crate::link::SimLink;
use crate::printer::Link;
use crate::sim::Sim;

/// A fault that has struck.
#[derive(Debug, Clone, Copy)]
pub(super) struct Strike {
    pub(super) fault: SimFault,
    /// When, ms of virtual time.
    pub(super) at_ms: u64,
    /// The phase of a tool change the unit was running then, by its progress.
    pub(super) in_tool_change: Option<ProgressCode>,
}

/// The in-process link with a fault that strikes at an exact virtual millisecond: while the
/// printer waits for the unit, the simulator is stepped one millisecond at a time (as
/// [`SimLink`] does) and an armed fault is injected as soon as its moment comes.
pub(super) struct StrikingLink {
    pub(super) link: SimLink,
    /// The fault waiting to strike and the virtual time it strikes at, ms.
    pub(super) armed: Option<(SimFault, u64)>,
    /// The fault that struck during this change.
    pub(super) struck: Option<Strike>,
}

impl StrikingLink {
    pub(super) fn new(sim: Sim) -> Self {
        StrikingLink {
            link: SimLink::new(sim),
            armed: None,
            struck: None,
        }
    }

    pub(super) fn sim(&self) -> &Sim {
        self.link.sim()
    }

    pub(super) fn sim_mut(&mut self) -> &mut Sim {
        self.link.sim_mut()
    }

    /// Inject the armed fault if its moment has come.
    fn strike_if_due(&mut self) {
        let now = self.link.now_ms();
        if let Some((fault, at_ms)) = self.armed
            && now >= at_ms
        {
            self.armed = None;
            let in_tool_change = match self.link.sim().unit_command() {
                ((RequestCode::Tool, _), Status::Running(progress)) => Some(progress),
                _ => None,
            };
            if self.link.sim_mut().inject(fault) {
                self.struck = Some(Strike {
                    fault,
                    at_ms: now,
                    in_tool_change,
                });
            }
        }
    }
}

impl Link for StrikingLink {
    fn send(&mut self, bytes: &[u8]) -> std::io::Result<()> {
        self.link.send(bytes)
    }

    fn receive(&mut self, max_ms: u64, into: &mut Vec<u8>) -> std::io::Result<()> {
        let before = into.len();
        for _ in 0..max_ms {
            self.strike_if_due();
            self.link.receive(1, into)?;
            if into.len() > before {
                break;
            }
        }
        self.strike_if_due();
        Ok(())
    }

    fn now_ms(&self) -> u64 {
        self.link.now_ms()
    }

    fn fsensor(&mut self) -> u8 {
        self.link.fsensor()
    }
}
