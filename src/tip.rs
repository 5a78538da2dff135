//! Where each lane's tip is on hardware without a hub sensor: counted from the lane's presence
//! sensor, so that the unit can still tell FINDA ([`crate::unit::Unit::hub_present`]).
//!
//! The presence sensor's edge places a tip exactly, but only an edge the unit's own drive makes
//! is the tip: fed in past the sensor, or pulled back out past it. A sensor that clears while the
//! printer pulls the lane is the spool's end leaving it (the tip goes on being counted), and one
//! that comes on undriven is a filament pushed in by hand or a tail pulled back (the tip is then
//! not known). Between edges the lane's odometry carries the tip.

use mmu_hal_port::Direction;

use crate::unit::Lane;

/// Every lane's tip estimate.
#[derive(Debug, Clone, Copy)]
pub struct TipEstimates<const N: usize> {
    /// Per lane: where its tip is, 1/100 mm past its presence sensor; `None` until the sensor's
    /// edge was seen since start.
    tips: [Option<i32>; N],
    /// Per lane: the presence sensor's last decision.
    was_present: [Option<bool>; N],
    /// Where a tip counts as in the hub, 1/100 mm past its presence sensor.
    hub_centi: i32,
}

impl<const N: usize> TipEstimates<N> {
    /// No tip known.
    pub const NEW: TipEstimates<N> = TipEstimates {
        tips: [None; N],
        was_present: [None; N],
        hub_centi: 0,
    };

    /// A tip counts as in the hub `lane_to_hub_mm` past its presence sensor.
    pub fn place_hub(&mut self, lane_to_hub_mm: u16) {
        self.hub_centi = i32::from(lane_to_hub_mm) * 100;
    }

    /// Follows `slot`'s tip by `moved` (1/100 mm) and homes it at its presence sensor's edge
    /// (`present` is the sensor's decision this step, `driven` the way the unit drives the lane).
    pub fn follow(&mut self, slot: usize, moved: i32, present: Option<bool>, driven: Option<Direction>) {
        let (Some(tip), Some(was_present)) = (self.tips.get_mut(slot), self.was_present.get_mut(slot)) else {
            return;
        };
        *tip = tip.map(|tip| tip.saturating_add(moved));
        match (*was_present, present, driven) {
            (Some(false), Some(true), Some(Direction::Forward))
            | (Some(true), Some(false), Some(Direction::Reverse)) => *tip = Some(0),
            (Some(false), Some(true), _) => *tip = None,
            _ => {}
        }
        if present.is_some() {
            *was_present = present;
        }
    }

    /// `slot`'s tip, 1/100 mm past its presence sensor, if known.
    pub fn tip_centi(&self, slot: usize) -> Option<i32> {
        self.tips.get(slot).copied().flatten()
    }

    /// Some tip is at or past the hub. A lane whose tip has not been seen since start counts as
    /// there by its record (`lanes`; `present`, its presence sensor's decision), the only word on
    /// it until its sensor's edge homes it: loaded (its sensor may be empty: the spool's end has
    /// passed it), or between the hub and its park position with its sensor still seeing it (one
    /// whose sensor is empty was pulled back past it on the way to park).
    pub fn in_hub(&self, lanes: &[Lane; N], present: impl Fn(usize) -> Option<bool>) -> bool {
        let unseen_in_hub = |slot: usize, lane: Lane| match lane {
            Lane::Loaded | Lane::AtFsensor => true,
            Lane::InHub => present(slot) != Some(false),
            Lane::Unknown | Lane::Empty | Lane::Parked => false,
        };
        self.tips
            .iter()
            .zip(lanes.iter())
            .enumerate()
            .any(|(slot, (tip, &lane))| tip.map_or(unseen_in_hub(slot, lane), |tip| tip >= self.hub_centi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Lane 0 from a tip at `tip` (its sensor seeing filament) over steps of (moved, present,
    /// driven).
    fn follow(tip: Option<i32>, steps: &[(i32, bool, Option<Direction>)]) -> Option<i32> {
        let mut tips = TipEstimates::<1> {
            tips: [tip],
            was_present: [Some(true)],
            hub_centi: 9_500,
        };
        for &(moved, present, driven) in steps {
            tips.follow(0, moved, Some(present), driven);
        }
        tips.tip_centi(0)
    }

    #[test]
    fn only_an_edge_the_drive_makes_homes_the_tip() {
        let back = Some(Direction::Reverse);
        let fed = Some(Direction::Forward);
        // Pulled back out past the sensor: the tip is there, then counted on.
        let pulled = [(-50, true, back), (-30, false, back), (-20, false, back)];
        assert_eq!(follow(Some(8_000), &pulled), Some(-20));
        // Fed in past it from behind: homed at the edge.
        let fed_in = [(0, false, fed), (40, true, fed), (60, true, fed)];
        assert_eq!(follow(None, &fed_in), Some(60));
        // The spool's end leaving the sensor while the printer pulls: the tip is where it was.
        assert_eq!(follow(Some(45_000), &[(100, false, None)]), Some(45_100));
        // A filament pushed in by hand, or a tail pulled back in: no tip is known.
        assert_eq!(follow(Some(-2_000), &[(0, false, None), (0, true, None)]), None);
        assert_eq!(follow(Some(45_000), &[(0, false, None), (-50, true, back)]), None);
    }

    #[test]
    fn a_tip_at_the_merge_or_a_recorded_lane_not_yet_seen_fills_the_hub() {
        let mut tips = TipEstimates::<2>::NEW;
        tips.place_hub(95);
        let seen = |_| Some(true);
        let empty = |_| Some(false);
        assert!(!tips.in_hub(&[Lane::Parked, Lane::Parked], seen));
        assert!(
            tips.in_hub(&[Lane::Parked, Lane::Loaded], seen),
            "a record unproven"
        );
        assert!(
            tips.in_hub(&[Lane::Parked, Lane::Loaded], empty),
            "a spool's end passed"
        );
        assert!(tips.in_hub(&[Lane::Parked, Lane::InHub], seen));
        assert!(
            !tips.in_hub(&[Lane::Parked, Lane::InHub], empty),
            "pulled back past it"
        );
        tips.tips = [Some(9_499), Some(-100)];
        assert!(
            !tips.in_hub(&[Lane::Parked, Lane::Loaded], seen),
            "seen behind the hub"
        );
        tips.tips[0] = Some(9_500);
        assert!(tips.in_hub(&[Lane::InHub, Lane::Parked], seen));
    }
}
