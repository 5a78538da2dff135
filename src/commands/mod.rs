//! The printer's commands, one module each.
//!
//! A command turns a request (`T1`, `L2`, `E0`...) into a [`Plan`] of phases from the catalogue
//! ([`crate::phases`]), or the error it fails with before anything moves, and says in its
//! [`Recovery`] table what every button the printer may send does after each error it can raise.
//! The runner ([`crate::runner`]) carries the plan out and reads the table; nothing else decides
//! what a button does.
//!
//! | request | command | module |
//! |---|---|---|
//! | `T<n>` | ToolChange = UnloadFromNozzle + LoadToNozzle | [`tool_change`], [`unload_from_nozzle`], [`load_to_nozzle`] |
//! | `L<n>` | Preload | [`preload`] |
//! | `U0` | UnloadFromNozzle | [`unload_from_nozzle`] |
//! | `E<n>` | Eject | [`eject`] |
//! | `K<n>` | Cut | [`cut`] |
//! | `H0` | Home | [`home`] |
//! | `M<n>` | the motor mode: finishes at once, answered only to a printer that accepted 3.0.4 | |
//! | start-up | the start-up check | [`start_up`] |

pub mod cut;
pub mod eject;
pub mod home;
pub mod load_to_nozzle;
pub mod preload;
pub mod start_up;
pub mod tool_change;
pub mod unload_from_nozzle;

use heapless::Vec;
use mmu_protocol::{ButtonCode, ErrorCode, RequestCode};

use crate::config::Config;
use crate::phases::{Phase, sensor_fault_error};
use crate::unit::{Lane, SensorId, Unit};

/// The longest plan: unload (2 phases) + load to nozzle (4) + eject (2) fits with room, and so
/// does a load that first clears the merge of every other slot; without a hub sensor, a proving
/// unload (4), the homing of every other lane not seen since start (2 each) and the load (6).
pub const MAX_PHASES: usize = 16;

/// The phases of one command, in order.
pub type Plan = Vec<Phase, MAX_PHASES>;

/// A printer command (or the start-up check).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// The check after a restart.
    StartUp,
    /// `T<n>`.
    ToolChange,
    /// `L<n>`.
    Preload,
    /// `U0`.
    UnloadFromNozzle,
    /// `E<n>`.
    Eject,
    /// `K<n>`.
    Cut,
    /// `H0`.
    Home,
    /// `M<n>`, as MMU 3.0.4 takes it: accepted and finished at once (a DC-motor unit has no
    /// stealth mode).
    Mode,
}

/// What a button does in an error state.
#[derive(Debug, Clone, Copy)]
pub enum Action {
    /// Run the failed phase again from wherever the sensors say the filament is (the user has
    /// looked: the sensors are trusted over the known lanes). After an error raised before any
    /// phase ran (the command's plan failed), plan the whole command again from the sensors: it
    /// fails again with the cause then present, or runs (never a finish nothing led to).
    RetryPhase,
    /// The error is a question answered: go on with the next phase.
    Continue,
    /// Start over with the plan this [`Replan`] makes from what the failed phase left
    /// ([`Retry`]); `None`: nothing moves and the error stays (its cause is still there).
    Replan(Replan),
    /// Unload whatever owns the hub path and park it, then plan the command again (FIL. ALREADY
    /// LOADED's Unload: "unload it first", then do what was asked).
    UnloadFirst,
}

/// A plan made after Retry from what the failed phase left. A name, not a function pointer:
/// a recovery row is then 6 B instead of 12.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Replan {
    /// Retry of a load after `8001` (`load_to_nozzle::after_missed_hub`).
    AfterMissedHub,
    /// Retry of a load after `8003` (`load_to_nozzle::after_no_trigger`).
    AfterNoTrigger,
    /// Retry of a load after `8009` (`load_to_nozzle::after_too_early`).
    AfterTooEarly,
}

impl Replan {
    /// The new plan after `retry`, appended to `plan` (built in place, as [`Command::plan`]), or
    /// `None` when nothing is to move (`plan` is then left as it was).
    pub fn plan(self, retry: &Retry, config: &Config, plan: &mut Plan) -> Option<Replanned> {
        match self {
            Replan::AfterMissedHub => load_to_nozzle::after_missed_hub(retry, config, plan),
            Replan::AfterNoTrigger => load_to_nozzle::after_no_trigger(retry, config, plan),
            Replan::AfterTooEarly => load_to_nozzle::after_too_early(retry, config, plan),
        }
    }
}

/// What a failed motion phase leaves for a [`Action::Replan`] to decide on.
#[derive(Debug, Clone, Copy)]
pub struct Retry {
    /// The failed phase's slot.
    pub slot: usize,
    /// The printer's sensor reads filament now.
    pub fsensor: bool,
    /// The hub sensor sees filament now (a faulty one counts as not).
    pub hub: bool,
    /// How far the failed phase moved the filament from where it first started (its first
    /// attempt), mm, in its own direction; `None` when no attempt ran.
    pub fed_mm: Option<i32>,
}

/// What a [`Replan`] learned on the way to its new plan.
#[derive(Debug, Clone, Copy, Default)]
pub struct Replanned {
    /// A Bowden length (register 0x22) measured by the failed attempt, to keep.
    pub bowden_mm: Option<u16>,
}

/// One row of a command's recovery table: after `error`, the printer's `button` does `action`.
/// A button no row names is acknowledged and does nothing.
#[derive(Debug, Clone, Copy)]
pub struct Recovery {
    /// The error shown.
    pub error: ErrorCode,
    /// The button sent (`B<n>`).
    pub button: ButtonCode,
    /// What the unit does.
    pub action: Action,
}

/// Retry (the Middle button) after `error` runs the failed phase again.
pub(crate) const fn retry(error: ErrorCode) -> Recovery {
    Recovery {
        error,
        button: ButtonCode::MIDDLE,
        action: Action::RetryPhase,
    }
}

/// What every motion phase can raise: a stalled motor, a sensor stuck at a rail, a bound a
/// drive could not keep. Retry runs the phase again once the cause is fixed.
const MOTION: &[Recovery] = &[
    retry(ErrorCode::STALLED_PULLEY),
    retry(ErrorCode::FINDA_FLICKERS),
    retry(ErrorCode::MOVE_PULLEY_FAILED),
    retry(ErrorCode::INTERNAL),
];

impl Command {
    /// The command a request starts, if it is one.
    pub const fn of(code: RequestCode) -> Option<Command> {
        Some(match code {
            RequestCode::Tool => Command::ToolChange,
            RequestCode::Load => Command::Preload,
            RequestCode::Unload => Command::UnloadFromNozzle,
            RequestCode::Eject => Command::Eject,
            RequestCode::Cut => Command::Cut,
            RequestCode::Home => Command::Home,
            RequestCode::Reset => Command::StartUp,
            RequestCode::Mode => Command::Mode,
            _ => return None,
        })
    }

    /// The plan for this command with argument `value` (a slot for `T L E K`), appended to `plan`
    /// (built in place: a plan returned by value was copied at every level), or the error it
    /// fails with before anything moves. An empty plan finishes at once.
    pub fn plan<const N: usize>(
        self,
        value: u8,
        unit: &Unit<N>,
        config: &Config,
        plan: &mut Plan,
    ) -> Result<(), ErrorCode> {
        let slot = usize::from(value);
        let needs_slot = matches!(
            self,
            Command::ToolChange | Command::Preload | Command::Eject | Command::Cut
        );
        if needs_slot && slot >= N {
            return Err(ErrorCode::INVALID_TOOL);
        }
        match self {
            Command::StartUp => start_up::plan(plan),
            Command::ToolChange => tool_change::plan(slot, unit, config, plan)?,
            Command::Preload => preload::plan(slot, unit, config, plan)?,
            Command::UnloadFromNozzle => unload_from_nozzle::plan(unit, config, plan)?,
            Command::Eject => eject::plan(slot, unit, config, plan),
            Command::Cut => cut::plan(slot, unit, config, plan)?,
            Command::Home => home::plan(plan),
            Command::Mode => {}
        }
        fit_to_profile(plan, unit);
        Ok(())
    }

    /// The recovery tables that apply to this command, its own first.
    const fn recovery(self) -> &'static [&'static [Recovery]] {
        match self {
            Command::StartUp => &[start_up::RECOVERY, MOTION],
            Command::ToolChange => &[
                tool_change::RECOVERY,
                unload_from_nozzle::RECOVERY,
                load_to_nozzle::RECOVERY,
                MOTION,
            ],
            Command::Preload => &[preload::RECOVERY, MOTION],
            Command::UnloadFromNozzle => &[unload_from_nozzle::RECOVERY, MOTION],
            Command::Eject => &[eject::RECOVERY, unload_from_nozzle::RECOVERY, MOTION],
            Command::Cut => &[
                cut::RECOVERY,
                unload_from_nozzle::RECOVERY,
                preload::RECOVERY,
                MOTION,
            ],
            Command::Home => &[home::RECOVERY, MOTION],
            Command::Mode => &[],
        }
    }

    /// What `button` does after this command failed with `error`.
    pub fn on_button(self, error: ErrorCode, button: ButtonCode) -> Option<Action> {
        // Plain loops: the iterator chain (`flat_map`, `find`) took more flash.
        for table in self.recovery() {
            for row in *table {
                if row.error == error && row.button == button {
                    return Some(row.action);
                }
            }
        }
        None
    }
}

/// Append as much of `phases` as fits (every plan built here fits).
/// `plan` made right for hardware without a hub sensor, where a lane's tip is known only from
/// its presence sensor's edge: every park homes the lane there first ([`Phase::HomeLane`], then
/// [`Phase::FeedToPark`] in place of [`Phase::RetractToPark`]), and a feed to the hub first homes
/// the fed lane and every other lane with filament whose tip the unit has not seen since start
/// (one may rest in the merge). With a hub sensor, `plan` as it is.
pub(crate) fn fit_to_profile<const N: usize>(plan: &mut Plan, unit: &Unit<N>) {
    if unit.profile().hub_sensor {
        return;
    }
    let mut fitted = Plan::new();
    for &phase in plan.iter() {
        match phase {
            Phase::RetractToPark { slot } => {
                extend(
                    &mut fitted,
                    &[Phase::HomeLane { slot }, Phase::FeedToPark { slot }],
                );
            }
            Phase::FeedToHub { slot, .. } => {
                // Every lane whose tip nobody has seen since start may rest in the merge: each
                // with filament is homed and parked first (safe wherever its tip is: a pull back
                // to its own sensor), the fed lane last. A lane recorded in the hub comes out
                // with the unload before (`clear_hub`), homed there.
                let fed = usize::from(slot);
                let unseen = (0..N)
                    .filter(|&lane| lane != fed)
                    .chain(core::iter::once(fed))
                    .filter(|&lane| unit.tip_centi(lane).is_none() && !unit.lane(lane).owns_hub())
                    .filter(|&lane| {
                        lane == fed
                            || unit.feeders.get(lane).and_then(|f| f.filament.present()) != Some(false)
                    });
                for lane in unseen {
                    let lane = lane as u8;
                    extend(
                        &mut fitted,
                        &[Phase::HomeLane { slot: lane }, Phase::FeedToPark { slot: lane }],
                    );
                }
                extend(&mut fitted, &[phase]);
            }
            phase => extend(&mut fitted, &[phase]),
        }
    }
    *plan = fitted;
}

pub(crate) fn extend(plan: &mut Plan, phases: &[Phase]) {
    for &phase in phases {
        if plan.push(phase).is_err() {
            return;
        }
    }
}

/// Whatever occupies the hub path comes out first. With filament in the hub but no slot known
/// to own it, no motor moves on a guess.
///
/// `await_release`: an unload from the printer first waits for it to release the filament
/// ([`Phase::UnloadToHub`]).
pub(crate) fn clear_hub<const N: usize>(
    plan: &mut Plan,
    unit: &Unit<N>,
    await_release: bool,
) -> Result<(), ErrorCode> {
    match (unit.active(), unit.hub_present()) {
        // With the hub sensor seeing filament, an unload may pull a long way: a slot only believed
        // to hold the path (a stored lane) is first pulled back a distance safe for any slot,
        // until the hub sensor proves it ([`Phase::ProveOwner`]).
        (Some(active), Some(true)) if unit.owner_contradicted(active) => {
            Err(ErrorCode::FINDA_VS_EEPROM_DISREPANCY)
        }
        (Some(active), Some(true)) if !unit.owner_proven(active) => {
            extend(
                plan,
                &[
                    Phase::PushProof { slot: active as u8 },
                    Phase::ProveOwner { slot: active as u8 },
                    Phase::RetractToPark { slot: active as u8 },
                ],
            );
            Ok(())
        }
        (Some(active), _) => {
            extend(plan, &unload_from_nozzle::phases(active, await_release));
            Ok(())
        }
        (None, Some(false)) => Ok(()),
        (None, Some(true)) => Err(ErrorCode::FINDA_VS_EEPROM_DISREPANCY),
        (None, None) => Err(sensor_fault_error(SensorId::HubFilament)),
    }
}

/// How far the hub may be from `slot`'s tip: close from the park position, a slot away from an
/// unknown position.
pub(crate) fn hub_search<const N: usize>(slot: usize, unit: &Unit<N>, config: &Config) -> u16 {
    match unit.lane(slot) {
        Lane::Parked => config.hub_search_mm,
        _ => config.preload_max_mm,
    }
}
