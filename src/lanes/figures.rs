//! What the unit keeps of each lane across restarts (in the counters record): the metres taken
//! off its spool, and its health figures. Every figure changes at most once a metre of filament
//! or once a command, so keeping them costs the flash little (book: "Filament left and lane
//! health").

/// Tool changes the success rate looks back over.
pub const WINDOW: u8 = 32;

/// One lane's kept figures. A rolling figure is 0 until its first measurement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LaneFigures {
    /// Whole metres taken off the spool since it was inserted (net of what went back).
    pub used_m: u16,
    /// Rolling drag: the duty the motor needed for the speed it reached, % of a free lane's.
    pub drag_pct: u16,
    /// Rolling slip of the unit's moves: commanded distance against counted, per mille of the
    /// commanded (positive: counted short).
    pub slip_permille: i16,
    /// Rolling time of a tool change to this slot that needed no help, 1/10 s.
    pub load_ds: u16,
    /// Rolling distance from the hub sensor to the printer's sensor on a load, mm.
    pub fsensor_mm: u16,
    /// Stalls of this slot's motor (a command's or the follower's).
    pub stalls: u16,
    /// Outcomes of the last tool changes to this slot, newest in bit 0 (1: it needed no help).
    pub outcomes: u32,
    /// How many of [`LaneFigures::outcomes`] count (up to [`WINDOW`]).
    pub attempts: u8,
}

impl LaneFigures {
    /// Bytes of one lane in the counters record.
    pub const BYTES: usize = 17;

    /// The tool changes that needed no help among the last [`LaneFigures::attempts`], %.
    pub fn success_pct(&self) -> u16 {
        if self.attempts == 0 {
            return 0;
        }
        let mask = if self.attempts >= WINDOW {
            u32::MAX
        } else {
            (1u32 << self.attempts) - 1
        };
        ((self.outcomes & mask).count_ones() * 100 / u32::from(self.attempts)) as u16
    }

    /// Count a tool change's outcome.
    pub fn record_outcome(&mut self, clean: bool) {
        self.outcomes = self.outcomes << 1 | u32::from(clean);
        self.attempts = self.attempts.saturating_add(1).min(WINDOW);
    }

    /// The fields in record order, with their widths in bytes.
    pub fn fields(&self) -> [(u32, usize); 8] {
        [
            (u32::from(self.used_m), 2),
            (u32::from(self.drag_pct), 2),
            (u32::from(self.slip_permille as u16), 2),
            (u32::from(self.load_ds), 2),
            (u32::from(self.fsensor_mm), 2),
            (u32::from(self.stalls), 2),
            (self.outcomes, 4),
            (u32::from(self.attempts), 1),
        ]
    }

    /// The figures from the fields of [`LaneFigures::fields`], in order.
    pub fn from_fields(mut next: impl FnMut(usize) -> u32) -> Self {
        LaneFigures {
            used_m: next(2) as u16,
            drag_pct: next(2) as u16,
            slip_permille: next(2) as u16 as i16,
            load_ds: next(2) as u16,
            fsensor_mm: next(2) as u16,
            stalls: next(2) as u16,
            outcomes: next(4),
            attempts: (next(1) as u8).min(WINDOW),
        }
    }
}

/// A rolling figure: the first measurement as it is, then a quarter of the way to each new one.
pub fn roll(old: u16, new: u16) -> u16 {
    if old == 0 {
        return new;
    }
    (i32::from(old) + (i32::from(new) - i32::from(old)) / 4) as u16
}

/// [`roll`] for a signed figure (no "none": it starts at the first measurement only by being 0).
pub fn roll_signed(old: i16, new: i16, first: bool) -> i16 {
    if first {
        return new;
    }
    (i32::from(old) + (i32::from(new) - i32::from(old)) / 4) as i16
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_success_rate_counts_the_last_window_of_tool_changes() {
        let mut lane = LaneFigures::default();
        assert_eq!((lane.success_pct(), lane.attempts), (0, 0));
        lane.record_outcome(true);
        lane.record_outcome(false);
        assert_eq!((lane.success_pct(), lane.attempts), (50, 2));
        for _ in 0..40 {
            lane.record_outcome(true);
        }
        assert_eq!((lane.success_pct(), lane.attempts), (100, WINDOW));
        lane.record_outcome(false);
        assert_eq!(lane.success_pct(), 96);
    }

    #[test]
    fn fields_round_trip() {
        let lane = LaneFigures {
            used_m: 329,
            drag_pct: 140,
            slip_permille: -12,
            load_ds: 215,
            fsensor_mm: 361,
            stalls: 3,
            outcomes: 0xdead_beef,
            attempts: 32,
        };
        let fields = lane.fields();
        assert_eq!(fields.iter().map(|f| f.1).sum::<usize>(), LaneFigures::BYTES);
        let mut at = 0;
        let back = LaneFigures::from_fields(|width| {
            let (value, w) = fields[at];
            assert_eq!(w, width);
            at += 1;
            value
        });
        assert_eq!(back, lane);
    }

    #[test]
    fn rolling_figures_start_at_the_first_and_move_a_quarter() {
        assert_eq!(roll(0, 400), 400);
        assert_eq!(roll(400, 480), 420);
        assert_eq!(roll(400, 320), 380);
        assert_eq!(roll_signed(0, -40, true), -40);
        assert_eq!(roll_signed(-40, 0, false), -30);
    }
}
