//! The constant data of a lowered problem: bounds, guesses, the input-rate parameter's
//! entries and the named ranges.

use mpc_dsl::Ocp;
use mpc_dsl::ocp::Variable;

use super::{Named, Symbols};
use crate::error::CodegenError;

/// The state bounds of the solver's states: the model's, none for `u_last`.
pub(super) fn state_bounds(ocp: &Ocp<'_>, v: &Symbols<'_>) -> (Vec<f64>, Vec<f64>) {
    let mut lbx = ocp.state_bounds.lower.clone();
    let mut ubx = ocp.state_bounds.upper.clone();
    lbx.extend(std::iter::repeat_n(f64::NEG_INFINITY, v.u_last.len()));
    ubx.extend(std::iter::repeat_n(f64::INFINITY, v.u_last.len()));
    (lbx, ubx)
}

/// The initial guesses of the solver's states (`u_last`'s is the control's) and of the
/// control.
pub(super) fn guesses(ocp: &Ocp<'_>) -> (Vec<f64>, Vec<f64>) {
    let mut x_guess = ocp.x_guess();
    let u_guess = ocp.u_guess();
    if ocp.cost.input_rate.is_some() {
        x_guess.extend_from_slice(&u_guess);
    }
    (x_guess, u_guess)
}

/// With an input-rate cost, the parameter entries that hold `u_{-1}`.
///
/// # Errors
/// [`CodegenError::Unsupported`] if the term's `prev` is not made of parameter entries.
pub(super) fn u_prev_entries(
    ocp: &Ocp<'_>,
    v: &Symbols<'_>,
) -> Result<Option<Vec<usize>>, CodegenError> {
    let Some(r) = &ocp.cost.input_rate else {
        return Ok(None);
    };
    let mut idx = Vec::new();
    for e in r.prev.iter() {
        match v.p.iter().position(|s| s == e) {
            Some(i) => idx.push(i),
            None => {
                return Err(CodegenError::Unsupported(
                    "the input-rate term's `prev` must be parameter entries".into(),
                ));
            }
        }
    }
    Ok(Some(idx))
}

pub(super) fn named(vars: &[Variable<'_>], per_stage: impl Fn(usize) -> bool) -> Vec<Named> {
    let mut off = 0;
    vars.iter()
        .enumerate()
        .map(|(i, v)| {
            let mut doc = v.description.clone().unwrap_or_default();
            if let Some(unit) = &v.unit {
                if !doc.is_empty() {
                    doc.push(' ');
                }
                doc.push_str(&format!("[{unit}]"));
            }
            let n = Named {
                name: v.name.clone(),
                offset: off,
                len: v.len(),
                scalar: v.scalar,
                doc,
                per_stage: per_stage(i),
            };
            off += v.len();
            n
        })
        .collect()
}
