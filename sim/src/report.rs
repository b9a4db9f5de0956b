//! Trial and run summaries ([`mpc_mission::report`], shared with the PX4 shim) for the
//! simulator's trials: [`summarize`] and [`summarize_with`] read a [`TrialResult`].

pub use mpc_mission::report::*;

use crate::run::TrialResult;

/// Summarizes one trial and judges it by the simulator's criteria.
pub fn summarize(res: &TrialResult) -> TrialSummary {
    summarize_with(res, &Criteria::SIMULATOR)
}

/// [`summarize`] with other thresholds.
pub fn summarize_with(res: &TrialResult, c: &Criteria) -> TrialSummary {
    summarize_flight(&res.flight(), c)
}
