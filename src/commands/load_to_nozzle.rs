//! LoadToNozzle, the second half of a tool change: from before the hub into the extruder.
//!
//! `P5` feed to the hub sensor, `P6` fast through most of the Bowden tube, `P1c` slowly until
//! the printer's sensor triggers (the printer co-feeds), `P7` push into the extruder's gears
//! following the hub tension.

use mmu_protocol::{ButtonCode, ErrorCode};

use super::{Action, Plan, Recovery, extend, retry, unload_from_nozzle};
use crate::config::Config;
use crate::phases::Phase;

/// Feed `slot`'s filament from before the hub (at most `hub_search_mm` away) into the extruder.
pub const fn phases(slot: usize, hub_search_mm: u16) -> [Phase; 4] {
    [
        Phase::FeedToHub {
            slot,
            max_mm: hub_search_mm,
        },
        Phase::FeedThroughBowden { slot },
        Phase::FeedToFsensor { slot },
        Phase::FeedToNozzle { slot },
    ]
}

/// Back to the park position and load again from there, every phase with its full bound (the
/// tip's place is known again once the hub sensor clears).
fn reload_from_park(slot: usize, config: &Config) -> Plan {
    let mut plan = Plan::new();
    extend(&mut plan, &unload_from_nozzle::phases(slot));
    extend(&mut plan, &phases(slot, config.hub_search_mm));
    plan
}

/// Retry after `8003`. The printer's sensor reads filament now (it works again, or the user
/// pushed the tip to it): the search is over, the load goes on from there. Otherwise the user
/// may have moved the filament by hand to look: the load starts over from the park position,
/// searching the full bounded distance again rather than what the first attempt left (MMU 3.0.3's
/// Retry also unloads and loads again).
fn after_no_trigger(slot: usize, fsensor: bool, config: &Config) -> Option<Plan> {
    let mut plan = Plan::new();
    if fsensor {
        extend(
            &mut plan,
            &[Phase::FeedToFsensor { slot }, Phase::FeedToNozzle { slot }],
        );
    } else {
        plan = reload_from_park(slot, config);
    }
    Some(plan)
}

/// Retry after `8009`. While the printer's sensor still reads filament nothing moves and `8009`
/// stays: an unload would only end in `8004` (FSENSOR FIL. STUCK), hiding the first cause. Once it
/// is clear, the load starts over from the park position.
fn after_too_early(slot: usize, fsensor: bool, config: &Config) -> Option<Plan> {
    (!fsensor).then(|| reload_from_park(slot, config))
}

/// What each error of the load means and what Retry does.
pub const RECOVERY: &[Recovery] = &[
    // `8001`: the hub sensor did not see the tip (or the slot is empty).
    retry(ErrorCode::FINDA_DIDNT_SWITCH_ON),
    // `8003`: the printer's sensor did not trigger within the search distance, or the filament
    // stopped on its way there (a Bowden jam, the printer's idle extruder).
    Recovery {
        error: ErrorCode::FSENSOR_DIDNT_SWITCH_ON,
        button: ButtonCode::MIDDLE,
        action: Action::Replan(after_no_trigger),
    },
    // `8009`: the printer's sensor triggered during the fast feed: the Bowden tube is shorter
    // than configured, holds a leftover, or the sensor is stuck on.
    Recovery {
        error: ErrorCode::FSENSOR_TOO_EARLY,
        button: ButtonCode::MIDDLE,
        action: Action::Replan(after_too_early),
    },
];
