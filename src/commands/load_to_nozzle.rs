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

/// After `8009`: back to the park position and load again from there.
fn reload_from_park(slot: usize, config: &Config) -> Plan {
    let mut plan = Plan::new();
    extend(&mut plan, &unload_from_nozzle::phases(slot));
    extend(&mut plan, &phases(slot, config.hub_search_mm));
    plan
}

/// What each error of the load means and what Retry does.
pub const RECOVERY: &[Recovery] = &[
    // `8001`: the hub sensor did not see the tip (or the slot is empty). When it sees it on Retry
    // (its threshold was wrong), the tip may be far past it: load again from the park position,
    // as MMU 3.0.3 restarts a tool change when FINDA is pressed on Retry.
    Recovery {
        error: ErrorCode::FINDA_DIDNT_SWITCH_ON,
        button: ButtonCode::MIDDLE,
        action: Action::ReplanIfHubSees(reload_from_park),
    },
    // `8003`: the printer's sensor did not trigger within the search distance.
    retry(ErrorCode::FSENSOR_DIDNT_SWITCH_ON),
    // `8009`: the printer's sensor triggered during the fast feed: the Bowden tube is shorter
    // than configured or holds a leftover.
    Recovery {
        error: ErrorCode::FSENSOR_TOO_EARLY,
        button: ButtonCode::MIDDLE,
        action: Action::Replan(reload_from_park),
    },
];
