//! The soak's spool ends: a spool that ends while the printer prints ([`Fault::SpoolRunout`]
//! among the print faults), how the printer's own runout handling fared with it, and every
//! runout the printer saw when no spool had ended (the unit guessed wrong).

use std::fmt;

use mmu_firmware::registers::LEFT;
use mmu_model::Fault;
use mmu_protocol::{ParamCode, Request};

use super::{SoakUser, StrikingLink};
use crate::fault::SimFault;
use crate::printer::Printer;

/// What the unit counts left on a spool that will end fastened to its core, as a user's start
/// G-code sets it (`M708 A0x59+k X1`), m: within the count's uncertainty (± 1 m) of empty, as a
/// spool that ends is when its length was set right.
pub const FASTENED_LEFT_M: u16 = 1;

/// The slot of a spool end fastened to the core (`fault`).
pub(super) fn fastened_slot(fault: Option<SimFault>) -> Option<usize> {
    match fault {
        Some(SimFault::Model(Fault::SpoolFastened { slot })) => Some(slot),
        _ => None,
    }
}

/// Set the filament the unit counts left on `slot`'s spool to `m` metres, through the printer's
/// register write (register `0x59 + k`).
pub(super) fn set_left(
    printer: &mut Printer<StrikingLink>,
    user: &mut SoakUser,
    slot: usize,
    m: u16,
) -> Result<(), String> {
    let address = u8::try_from(slot)
        .ok()
        .and_then(|k| LEFT.checked_add(k))
        .ok_or_else(|| format!("no register for slot {slot}"))?;
    match printer.request(user, Request::write(address, m)) {
        Ok(answer) if answer.param == ParamCode::Accepted => Ok(()),
        Ok(answer) => Err(format!("writing {m} m left on slot {slot}: {answer:?}")),
        Err(error) => Err(format!("writing {m} m left on slot {slot}: {error}")),
    }
}

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
    /// Spool ends fastened to the core that struck while the printer printed, on a spool the
    /// unit counts as used up ([`FASTENED_LEFT_M`]): told from a tangle by the filament left.
    pub fastened: u32,
    /// Of them: reported as a runout (FINDA empty).
    pub fastened_reported: u32,
    /// Of them: the printer's handling succeeded without the user's hands (as [`Self::handled`]).
    pub fastened_handled: u32,
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
            Some(SimFault::Model(Fault::SpoolRunout { slot } | Fault::SpoolFastened { slot })) => Some(slot),
            _ => None,
        };
        let fastened = matches!(struck, Some(SimFault::Model(Fault::SpoolFastened { .. })));
        if let (Some(slot), Some(kind)) = (spool_end, kind)
            && kind.ends_with("(printing)")
        {
            let reported = u32::from(runouts.iter().any(|&r| usize::from(r) == slot));
            let handled = u32::from(handled);
            if fastened {
                self.fastened += 1;
                self.fastened_reported += reported;
                self.fastened_handled += handled;
            } else {
                self.injected += 1;
                self.reported += reported;
                self.handled += handled;
            }
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
                "\nfastened spool ends (spool used up): {} while printing, {} reported (FINDA empty), {} handled by the printer",
                self.fastened, self.fastened_reported, self.fastened_handled
            )?;
        }
        for (kind, n) in &self.false_reports {
            write!(f, "\n  false spool end after {kind}: {n}")?;
        }
        Ok(())
    }
}
