//! The soak's spool ends: a spool that ends while the printer prints ([`Fault::SpoolRunout`]
//! among the print faults), how the printer's own runout handling fared with it, and every
//! runout the printer saw when no spool had ended (the unit guessed wrong).

use std::fmt;

use mmu_model::Fault;

use crate::fault::SimFault;

/// How the spool ends of a soak run fared.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SpoolEndTally {
    /// Spool ends that struck while the printer printed.
    pub injected: u32,
    /// Of them: the printer's runout check saw FINDA empty and started its filament change.
    pub reported: u32,
    /// Of them: the printer's handling succeeded without the user's hands: with SpoolJoin the print
    /// went on with the next slot; without it the print stopped on the filament-change screen
    /// with the path clear. The others ended on an error screen (the user pulled the tail out).
    pub handled: u32,
    /// Spool ends fastened to the core that struck while the printer printed: the unit cannot
    /// tell them from a tangle and reports a jam.
    pub fastened: u32,
    /// Of them: reported as a runout (FINDA empty).
    pub fastened_reported: u32,
    /// Runouts the printer saw although no spool had ended (the fault that struck was a tangle,
    /// a jam, a sensor fault, ..., or none): per fault kind, in the order first seen. Must stay
    /// empty.
    pub false_reports: Vec<(String, u32)>,
}

impl SpoolEndTally {
    /// Runouts seen without a spool end, all kinds together.
    pub fn false_total(&self) -> u32 {
        self.false_reports.iter().map(|(_, n)| n).sum()
    }

    /// Count `runouts` runouts the printer saw during a change whose struck fault was `struck`
    /// (named `kind`), `handled` telling whether its handling succeeded.
    pub(super) fn count(
        &mut self,
        struck: Option<SimFault>,
        kind: Option<&str>,
        runouts: &[u8],
        handled: bool,
    ) {
        let spool_end = match struck {
            Some(SimFault::Model(Fault::SpoolRunout { slot })) => Some(slot),
            _ => None,
        };
        if let (Some(SimFault::Model(Fault::SpoolFastened { slot })), Some(kind)) = (struck, kind)
            && kind.ends_with("(printing)")
        {
            self.fastened += 1;
            let reported = runouts.iter().any(|&r| usize::from(r) == slot);
            self.fastened_reported += u32::from(reported);
            return;
        }
        if let (Some(slot), Some(kind)) = (spool_end, kind)
            && kind.ends_with("(printing)")
        {
            self.injected += 1;
            self.reported += u32::from(runouts.iter().any(|&r| usize::from(r) == slot));
            self.handled += u32::from(handled);
        }
        let wrong = runouts
            .iter()
            .filter(|&&r| spool_end != Some(usize::from(r)))
            .count();
        if wrong > 0 {
            let kind = kind.unwrap_or("no fault").to_string();
            let wrong = u32::try_from(wrong).unwrap_or(u32::MAX);
            match self.false_reports.iter_mut().find(|(k, _)| *k == kind) {
                Some((_, n)) => *n += wrong,
                None => self.false_reports.push((kind, wrong)),
            }
        }
    }
}

/// `spool ends: <I> while printing, <R> reported, <H> handled; false spool ends: <F>`, and the
/// kinds of the false ones.
impl fmt::Display for SpoolEndTally {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "spool ends: {} while printing, {} reported (FINDA empty), {} handled by the printer; false spool ends: {}",
            self.injected,
            self.reported,
            self.handled,
            self.false_total()
        )?;
        if self.fastened > 0 {
            write!(
                f,
                "\nfastened spool ends: {} while printing, {} reported as a runout (the others stay a jam)",
                self.fastened, self.fastened_reported
            )?;
        }
        for (kind, n) in &self.false_reports {
            write!(f, "\n  false spool end after {kind}: {n}")?;
        }
        Ok(())
    }
}
