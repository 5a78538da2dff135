//! LoadToNozzle, the second half of a tool change: from before the hub into the extruder.
//!
//! `P5` feed to the hub sensor, `P6` fast through most of the Bowden tube, `P1c` slowly until
//! the printer's sensor triggers (the printer co-feeds) and the printer has seen `P1c`, `P7` push
//! into the extruder's gears while the printer pushes its own extruder: done only once that push
//! pulls the Bowden tube taut ([`crate::phases::Phase::FeedToNozzle`]).

use mmu_protocol::{ButtonCode, ErrorCode};

use super::{Action, Plan, Recovery, Replan, Replanned, Retry, extend, unload_from_nozzle};
use crate::config::Config;
use crate::phases::Phase;

/// Feed `slot`'s filament from before the hub (at most `hub_search_mm` away) into the extruder.
pub const fn phases(slot: usize, hub_search_mm: u16) -> [Phase; 4] {
    [
        Phase::FeedToHub {
            slot: slot as u8,
            max_mm: hub_search_mm,
        },
        Phase::FeedThroughBowden { slot: slot as u8 },
        Phase::FeedToFsensor { slot: slot as u8 },
        Phase::FeedToNozzle { slot: slot as u8 },
    ]
}

/// Back to the park position and load again from there, every phase with its full bound (the
/// tip's place is known again once the hub sensor clears).
fn reload_from_park(slot: usize, config: &Config, plan: &mut Plan) {
    extend(plan, &unload_from_nozzle::phases(slot, true));
    extend(plan, &phases(slot, config.hub_search_mm));
}

/// The phases of the load from the printer's sensor on.
fn from_fsensor(slot: usize, plan: &mut Plan) {
    extend(
        plan,
        &[
            Phase::FeedToFsensor { slot: slot as u8 },
            Phase::FeedToNozzle { slot: slot as u8 },
        ],
    );
}

/// Retry after `8001`. The hub sensor sees the filament now (its threshold was wrong, or the
/// user pushed the tip): the tip may be far past it, so the load starts over from the park
/// position. It still sees nothing: the feed to the hub runs again from where the tip is, as far
/// as from an unknown position.
pub(crate) fn after_missed_hub(retry: &Retry, config: &Config, plan: &mut Plan) -> Option<Replanned> {
    if retry.hub {
        reload_from_park(retry.slot, config, plan);
    } else {
        extend(plan, &phases(retry.slot, config.preload_max_mm));
    }
    Some(Replanned::default())
}

/// Retry after `8003`. The printer's sensor reads filament now (it works again, the user pushed
/// the tip to it, or the tip stopped between it and the extruder's gears in `P7`): the search is
/// over, the load goes on from there (`P1c`, whose `Q0` makes the printer push again, then `P7`). The tip is still past
/// the hub sensor: search again from where it is, slowly, over the whole Bowden length plus the
/// search distance, not only what the first attempt left (the user may have pulled it back to
/// look, a slipping drive fed less than it counted). The hub sensor sees nothing (the filament
/// was taken out): the load starts over from the park position.
pub(crate) fn after_no_trigger(retry: &Retry, config: &Config, plan: &mut Plan) -> Option<Replanned> {
    let slot = retry.slot;
    if retry.fsensor {
        from_fsensor(slot, plan);
    } else if retry.hub {
        extend(
            plan,
            &[
                Phase::SearchFsensor { slot: slot as u8 },
                Phase::FeedToNozzle { slot: slot as u8 },
            ],
        );
    } else {
        reload_from_park(slot, config, plan);
    }
    Some(Replanned::default())
}

/// Retry after `8009`. The printer cannot write register 0x22 while `T` runs (printer-truth §9:
/// Marlin runs no G-code inside `manage_response`), so a Bowden length longer than the tube would
/// fail every Retry the same way. The fast feed measured the length: from where the hub sensor
/// saw the tip to where the printer's sensor triggered. With the sensor still reading filament
/// and that length one a tube can have ([`learned_bowden_mm`]), it becomes register 0x22 and the
/// load goes on from the printer's sensor. A sensor that reads filament where no tube could end
/// teaches nothing: nothing moves and `8009` stays (an unload would only end in `8004` FSENSOR
/// FIL. STUCK, hiding the first cause). With the sensor clear, the load starts over from the park
/// position.
pub(crate) fn after_too_early(retry: &Retry, config: &Config, plan: &mut Plan) -> Option<Replanned> {
    if !retry.fsensor {
        reload_from_park(retry.slot, config, plan);
        return Some(Replanned::default());
    }
    let learned = learned_bowden_mm(retry.fed_mm?, config)?;
    from_fsensor(retry.slot, plan);
    Some(Replanned {
        bowden_mm: Some(learned),
    })
}

/// The shortest Bowden length learned, mm: register 0x22's own lower bound.
pub const MIN_LEARNED_BOWDEN_MM: u16 = 50;

/// The Bowden length that a fast feed of `fed_mm` from the hub sensor to the printer's
/// triggering sensor shows, if it is one to keep: never longer than the length in force (the
/// sensor triggered before it, so the tube is not longer), never shorter than what was fed (the
/// tip got that far; the printer reports its sensor within a few ms, under 1 mm at the fast
/// speed), within register 0x22's range, and a setting the guards take as a write of it
/// ([`crate::guards`]).
pub fn learned_bowden_mm(fed_mm: i32, config: &Config) -> Option<u16> {
    let fed = u16::try_from(fed_mm).ok()?;
    let learned = Config {
        bowden_mm: fed,
        ..config.clone()
    };
    ((MIN_LEARNED_BOWDEN_MM..config.bowden_mm).contains(&fed)
        && crate::guards::check(&learned, &crate::guards::NO_FILAMENT_READINGS).is_ok())
    .then_some(fed)
}

/// What each error of the load means and what Retry does.
pub const RECOVERY: &[Recovery] = &[
    // `8001`: the hub sensor did not see the tip (or the slot is empty). When it sees it on Retry
    // (its threshold was wrong), the tip may be far past it: load again from the park position,
    // as MMU 3.0.3 restarts a tool change when FINDA is pressed on Retry.
    Recovery {
        error: ErrorCode::FINDA_DIDNT_SWITCH_ON,
        button: ButtonCode::MIDDLE,
        action: Action::Replan(Replan::AfterMissedHub),
    },
    // `8003`: the printer's sensor did not trigger within the search distance, or the filament
    // stopped on its way there (a Bowden jam, the printer's idle extruder), or the printer's push
    // did not pull it in after its sensor triggered (`P7`: a jam just before the gears).
    Recovery {
        error: ErrorCode::FSENSOR_DIDNT_SWITCH_ON,
        button: ButtonCode::MIDDLE,
        action: Action::Replan(Replan::AfterNoTrigger),
    },
    // `8009`: the printer's sensor triggered during the fast feed: the Bowden tube is shorter
    // than configured, holds a leftover, or the sensor is stuck on.
    Recovery {
        error: ErrorCode::FSENSOR_TOO_EARLY,
        button: ButtonCode::MIDDLE,
        action: Action::Replan(Replan::AfterTooEarly),
    },
];
