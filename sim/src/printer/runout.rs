//! The printer's runout check and its filament change, as Prusa's firmware plays them when the
//! unit's FINDA (register 0x08, our hub sensor) reads empty while the printer prints (book:
//! "Spool end").
//!
//! - **The check.** `MMU2::CheckFINDARunout` runs whenever the protocol logic's step returns
//!   `Finished`, i.e. in idle scope once a `Q0` and its register poll are through (BFW v6.5.3
//!   `mmu2_mk4.cpp` `LogicStep`, `protocol_logic.cpp` `IdleStep`; PFW v3.13.3 `mmu2.cpp`
//!   `LogicStep`). With FINDA empty while the filament is believed in the nozzle (Buddy:
//!   `WhereIsFilament() == IN_NOZZLE`; MK3S: `check_fsensor()`, a print job on and no `M600` in
//!   progress) it queues `M600 A` (Buddy, a join configured for the current slot) or
//!   `M600 AUTO` (MK3S, SpoolJoin on), else `M600`.
//! - **The delay.** Buddy appends the `M600` to the G-code queue (`enqueue_gcode`): what is
//!   queued prints first ([`runout_delay_ms`]). The MK3S stops the print at once
//!   (`marlin_stop_and_save_print_to_ram`, `enquecommand_front_P`).
//! - **The filament change.** Every path unloads first: the printer parks, rams and pulls the
//!   filament out of its gears (played by the simulator's mechanics on the `U` frame), then
//!   sends `U0` (BFW `MMU2::unload` → `UnloadInner`; PFW `mmu_M600_unload_filament` →
//!   `MMU2::unload`). Then SpoolJoin sends `T<next>` and loads to the nozzle (BFW
//!   `SpoolJoin::do_join` → `MMU2::tool_change_full`; PFW `mmu_M600_load_filament` →
//!   `load_filament_to_nozzle`), and the print goes on. Without it Buddy sends `E<slot>`
//!   (`Pause::mmu_unload_start_process` → `eject_filament`) and both wait on the
//!   filament-change screen for the user.

use mmu_protocol::{Request, RequestCode, ResultCode};

use super::{Link, Operator, Outcome, Printer, PrinterError, PrinterEvent};
use crate::Personality;

/// How long the printer prints on after it saw FINDA empty before its `M600` begins, ms. Buddy
/// queues the `M600` behind the G-code already queued (`enqueue_gcode`); the simulator takes 4 s
/// of printing for that queue and the planner's moves (an assumption, not measured). The MK3S
/// stops at once.
pub fn runout_delay_ms(personality: Personality) -> u64 {
    match personality {
        Personality::Buddy65 | Personality::Buddy64 => 4000,
        Personality::Mk3s => 0,
    }
}

/// The slot SpoolJoin continues with after `slot`, going round `cycle` slots: the next one, as
/// the MK3S's `SpoolJoin::nextSlot` does with 5 (Buddy follows the joins the user set up; the
/// simulator's user joins each slot to the next).
pub fn join_slot(slot: u8, cycle: u8) -> u8 {
    slot.saturating_add(1) % cycle.max(1)
}

impl<L: Link> Printer<L> {
    /// The slot the printer believes loaded into its nozzle (after a finished `T`).
    pub fn loaded_tool(&self) -> Option<u8> {
        self.tool
    }

    /// `CheckFINDARunout` after an idle poll: true when FINDA read empty while a filament is
    /// believed in the nozzle.
    pub(super) fn runout_seen(&self) -> bool {
        self.tool.is_some() && self.polled(0x08) == Some(0)
    }

    /// Remember what a finished command left in the nozzle.
    pub(super) fn note_outcome(&mut self, request: Request, outcome: Outcome) {
        if outcome != Outcome::Finished(ResultCode::OK) {
            return;
        }
        match request.code {
            RequestCode::Tool | RequestCode::Load => self.tool = Some(request.value),
            RequestCode::Unload | RequestCode::Eject => self.tool = None,
            _ => {}
        }
    }

    /// The `M600` (or `M600 A` / `M600 AUTO`) a runout of the loaded slot starts. `None` when
    /// the print goes on (joined to the next slot); else how it stopped: on the filament-change
    /// screen, or on an error the user gave up on.
    pub(super) fn filament_change(
        &mut self,
        op: &mut impl Operator<L>,
    ) -> Result<Option<Outcome>, PrinterError> {
        let Some(slot) = self.tool else {
            return Ok(None);
        };
        let personality = self.options.personality;
        let join = self
            .options
            .spool_join
            .then(|| join_slot(slot, self.options.join_cycle));
        op.event(&mut self.link, &PrinterEvent::Runout { slot, join });
        // The queued print runs first; the check does not fire again meanwhile (Buddy's
        // `FS_EventAutolock` and M600 in progress, the MK3S's `mcode_in_progress`).
        if let Some(outcome) = self.print_for(op, runout_delay_ms(personality), false)? {
            return Ok(Some(outcome));
        }
        let ok = Outcome::Finished(ResultCode::OK);
        let unload = self.command(op, Request::new(RequestCode::Unload, 0))?;
        if unload != ok {
            return Ok(Some(unload));
        }
        if let Some(next) = join {
            let change = self.command(op, Request::new(RequestCode::Tool, next))?;
            return Ok((change != ok).then_some(change));
        }
        if personality != Personality::Mk3s {
            let eject = self.command(op, Request::new(RequestCode::Eject, slot))?;
            if eject != ok {
                return Ok(Some(eject));
            }
        }
        Ok(Some(Outcome::FilamentChange(slot)))
    }
}
