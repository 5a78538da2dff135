//! The power losses that struck in the middle of a tool change, by the phase the unit was in, and
//! how each change ended after the printer's recovery (the mmu2 layer's `U0`, then the same `T`):
//! completed without UNLOAD MANUALLY, completed after `8008` and an unload by hand, or not at all.

use std::fmt;

use mmu_protocol::ProgressCode;

/// How the changes whose power loss struck in one phase ended.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct PhaseRestarts {
    /// The progress the unit reported when the power went (`None`: no tool change phase ran,
    /// e.g. the printer was still ramming, or the unit stood on an error).
    pub phase: Option<ProgressCode>,
    /// Power losses that struck there.
    pub struck: u32,
    /// Changes completed after the printer's recovery without `8008`.
    pub completed: u32,
    /// Changes that showed `8008` (UNLOAD MANUALLY) on the way.
    pub unload_manually: u32,
    /// Changes that did not complete (unrecovered, stuck or panicked).
    pub failed: u32,
}

/// Every phase's [`PhaseRestarts`], in the order they first struck.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RestartTally {
    /// Per phase.
    pub phases: Vec<PhaseRestarts>,
}

impl RestartTally {
    /// A power loss struck in `phase`; the change completed (`done`), after `8008` or not.
    pub fn record(&mut self, phase: Option<ProgressCode>, done: bool, unload_manually: bool) {
        let index = match self.phases.iter().position(|p| p.phase == phase) {
            Some(index) => index,
            None => {
                self.phases.push(PhaseRestarts {
                    phase,
                    ..PhaseRestarts::default()
                });
                self.phases.len() - 1
            }
        };
        let tally = &mut self.phases[index];
        tally.struck += 1;
        tally.unload_manually += u32::from(unload_manually);
        tally.completed += u32::from(done && !unload_manually);
        tally.failed += u32::from(!done);
    }

    /// Power losses counted, over every phase.
    pub fn struck(&self) -> u32 {
        self.phases.iter().map(|p| p.struck).sum()
    }

    /// Of those, changes completed without `8008`.
    pub fn completed(&self) -> u32 {
        self.phases.iter().map(|p| p.completed).sum()
    }

    /// Of those, changes that showed `8008`.
    pub fn unload_manually(&self) -> u32 {
        self.phases.iter().map(|p| p.unload_manually).sum()
    }
}

/// `power losses mid tool change: <n>, <c> completed after the printer's recovery, <e> with 8008,
/// <f> failed`, then one line per phase.
impl fmt::Display for RestartTally {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let failed: u32 = self.phases.iter().map(|p| p.failed).sum();
        write!(
            f,
            "power losses mid tool change: {}, {} completed after the printer's recovery, {} with 8008 (unload manually), {failed} failed",
            self.struck(),
            self.completed(),
            self.unload_manually()
        )?;
        for p in &self.phases {
            let phase = p
                .phase
                .map_or("no phase running".to_string(), |code| code.to_string());
            write!(
                f,
                "\n  {phase}: {} struck, {} completed, {} with 8008, {} failed",
                p.struck, p.completed, p.unload_manually, p.failed
            )?;
        }
        Ok(())
    }
}
