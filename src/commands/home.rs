//! Home (`H0`). Nothing to home on this hardware: the unit checks its sensors instead, as after
//! a restart: all healthy, and the hub sensor agrees with the known state.
//!
//! `P1a`; errors and recovery as the start-up check ([`super::start_up`]).

use super::{Plan, Recovery, start_up};

/// The plan for `H0`, appended to `plan`.
pub fn plan(plan: &mut Plan) {
    start_up::plan(plan)
}

/// The start-up check's.
pub const RECOVERY: &[Recovery] = start_up::RECOVERY;
