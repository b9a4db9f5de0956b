//! The soft-bounds test's Rust program (tests/soft_bounds.rs builds it against the crates
//! `mpcc build` generated from soft_box.mpc, its variant N1, soft_row.mpc, and
//! models/cartpole.mpc with its rail a soft bound `|s| <= 0.5`). It prints
//! one `name value` line per measured outcome; the test compares them with the optima it
//! computes by hand and between the two formulations. The run-time API's refusals are
//! checked here (a failed check exits with status 1).

use soft_box::{Real, SetError};

const INF: Real = Real::INFINITY;

/// Every step of `f`'s check, with what failed.
fn check(ok: bool, what: &str) {
    if !ok {
        eprintln!("check failed: {what}");
        std::process::exit(1);
    }
}

/// N = 1: solve from `x0` with the state's (`x`) and the control's (`u`) soft bound and
/// penalties (`None`: that bound removed); print `x_1`, `u_0` and the bound's multiplier.
fn one_step(name: &str, x0: Real, x: Option<(Real, Real, Real)>, u: Option<(Real, Real, Real)>) {
    let mut s = soft_box_n1::Solver::new();
    let (xb, xl1, xl2) = x.unwrap_or((INF, 1.0, 1.0));
    let (ub, ul1, ul2) = u.unwrap_or((INF, 1.0, 1.0));
    check(
        s.set_state_bounds(&[-INF], &[xb]).is_ok(),
        "set_state_bounds",
    );
    check(
        s.set_control_bounds(&[-INF], &[ub]).is_ok(),
        "set_control_bounds",
    );
    check(
        s.set_state_bound_penalties(&[xl1], &[xl2]).is_ok(),
        "set_state_bound_penalties",
    );
    check(
        s.set_control_bound_penalties(&[ul1], &[ul2]).is_ok(),
        "set_control_bound_penalties",
    );
    check(s.set_x0(&[x0]).is_ok(), "set_x0");
    let info = s.solve_sqp();
    check(
        info.status == soft_box_n1::RtiStatus::Ok,
        "solve_sqp status",
    );
    let x1 = s.state(1).map_or(Real::NAN, |v| v[0]);
    println!("{name}_x1 {x1:.17e}");
    println!("{name}_u0 {:.17e}", s.u0()[0]);
    // The bound's multiplier: the soft row's, through the bounds' read-outs.
    let mult = match (x, u) {
        (Some(_), _) => s.state_bound_multipliers(1).map_or(Real::NAN, |m| m[0]),
        _ => s.control_bound_multipliers(0).map_or(Real::NAN, |m| m[0]),
    };
    println!("{name}_mult {mult:.17e}");
}

/// N = 3, soft bounds against soft rows: ten real-time iterations (the plant is the model)
/// from `x0`, after `setup` changed both the same way; prints the largest difference of the
/// applied controls and the last state.
fn closed_loops(name: &str, x0: Real, l1: Real, l2: Real) {
    let mut a = soft_box::Solver::new();
    let mut b = soft_row::Solver::new();
    check(
        a.set_state_bound_penalties(&[l1], &[l2]).is_ok(),
        "box penalties",
    );
    let ok = b.set_soft_penalties(&[5.0, l1], &[0.0, l2]).is_ok()
        && b.set_terminal_soft_penalties(&[l1], &[l2]).is_ok();
    check(ok, "row penalties");
    let (mut xa, mut xb, mut diff) = (x0, x0, 0.0 as Real);
    for _ in 0..10 {
        a.prepare();
        b.prepare();
        check(a.set_x0(&[xa]).is_ok() && b.set_x0(&[xb]).is_ok(), "set_x0");
        let (ia, ib) = (a.feedback(), b.feedback());
        check(ia.status == soft_box::RtiStatus::Ok, "box feedback");
        check(ib.status == soft_row::RtiStatus::Ok, "row feedback");
        diff = diff.max((a.u0()[0] - b.u0()[0]).abs());
        for k in 0..=3 {
            let (sa, sb) = (a.state(k), b.state(k));
            diff = diff.max((sa.map_or(0.0, |v| v[0]) - sb.map_or(0.0, |v| v[0])).abs());
        }
        xa += a.u0()[0];
        xb += b.u0()[0];
    }
    println!("{name}_diff {diff:.17e}");
    println!("{name}_x {xa:.17e}");
}

/// N = 3, `solve_sqp` from `x0` with the state bound's penalties `l1`, `l2`: prints the
/// optimal `x_k`, `u_k` (compared with IPOPT's in the test).
fn converged(name: &str, x0: Real, l1: Real, l2: Real) {
    let mut s = soft_box::Solver::new();
    check(
        s.set_state_bound_penalties(&[l1], &[l2]).is_ok(),
        "penalties",
    );
    check(s.set_x0(&[x0]).is_ok(), "set_x0");
    // Tight, as IPOPT's: the L1 case is degenerate (x_2 on its bound with a zero
    // multiplier), where the default tolerances leave 1e-5 in u.
    let t = s.settings_mut();
    (t.qp.tol_stat, t.qp.tol_eq, t.qp.tol_ineq, t.qp.tol_comp) = (1e-11, 1e-11, 1e-11, 1e-11);
    let info = s.solve_sqp();
    if info.status != soft_box::RtiStatus::Ok {
        eprintln!("{name}: {info:?}");
    }
    check(info.status == soft_box::RtiStatus::Ok, "solve_sqp");
    for k in 0..=soft_box::N {
        println!(
            "{name}_x{k} {:.17e}",
            s.state(k).map_or(Real::NAN, |v| v[0])
        );
    }
    for k in 0..soft_box::N {
        println!(
            "{name}_u{k} {:.17e}",
            s.control(k).map_or(Real::NAN, |v| v[0])
        );
    }
}

/// The run-time API: constants, bounds read back, refusals that change nothing.
fn api() {
    check(
        soft_box::NG == 0 && soft_box::NGN == 0,
        "NG, NGN are the model's rows",
    );
    check(
        soft_box::NG_QP == 2 && soft_box::NGN_QP == 1,
        "NG_QP, NGN_QP",
    );
    check(
        soft_box::SOFT_STATE_BOUNDS == [0] && soft_box::SOFT_CONTROL_BOUNDS == [0],
        "idx",
    );
    let mut s = soft_box::Solver::new();
    check(
        s.state_bounds() == ([-INF], [1.0]),
        "state bounds from the model",
    );
    check(
        s.control_bounds() == ([-INF], [5.0]),
        "control bounds from the model",
    );
    check(
        s.state_bound_penalties() == ([0.0], [10.0]),
        "state penalties from the model",
    );
    check(
        s.control_bound_penalties() == ([5.0], [0.0]),
        "control penalties from the model",
    );
    // The runtime's box bounds of soft entries are infinite: the rows hold them.
    let (lbx, ubx, lbu, ubu) = s.rti().bounds();
    check(
        ubx[0] == INF && lbx[0] == -INF && ubu[0] == INF && lbu[0] == -INF,
        "boxes free",
    );
    let refused: [(Real, Real, SetError); 4] = [
        (Real::NAN, 1.0, SetError::NonFinite),
        (1.0, INF, SetError::NonFinite),
        (-1.0, 1.0, SetError::NegativePenalty),
        (0.0, 0.0, SetError::InvalidSetting),
    ];
    for (a, b, e) in refused {
        check(
            s.set_state_bound_penalties(&[a], &[b]) == Err(e),
            "state penalty refused",
        );
        check(
            s.set_control_bound_penalties(&[a], &[b]) == Err(e),
            "control penalty refused",
        );
    }
    check(
        s.state_bound_penalties() == ([0.0], [10.0]),
        "refusals changed nothing",
    );
    check(
        s.control_bound_penalties() == ([5.0], [0.0]),
        "refusals changed nothing",
    );
    check(
        s.set_state_bound_penalties(&[3.0], &[0.5]).is_ok(),
        "penalties set",
    );
    check(
        s.state_bound_penalties() == ([3.0], [0.5]),
        "penalties read back",
    );
    let (l1, l2, l1n, l2n) = s.rti().soft_penalties();
    check(
        l1[1] == 3.0 && l2[1] == 0.5 && l1n[0] == 3.0 && l2n[0] == 0.5,
        "rows follow",
    );
    check(l1[0] == 5.0, "the control's row keeps its penalty");
    // Bounds of soft entries: refused ones change nothing, accepted ones read back.
    check(
        s.set_state_bounds(&[2.0], &[1.0]) == Err(SetError::CrossedBounds),
        "crossed",
    );
    check(
        s.set_state_bounds(&[Real::NAN], &[1.0]) == Err(SetError::NonFinite),
        "NaN",
    );
    check(
        s.set_control_bounds(&[INF], &[INF]) == Err(SetError::NonFinite),
        "lower +inf",
    );
    check(
        s.state_bounds() == ([-INF], [1.0]),
        "refused bounds changed nothing",
    );
    check(
        s.control_bounds() == ([-INF], [5.0]),
        "refused bounds changed nothing",
    );
    check(
        s.set_state_bounds(&[-2.0], &[0.5]).is_ok(),
        "state bounds set",
    );
    check(
        s.state_bounds() == ([-2.0], [0.5]),
        "state bounds read back",
    );
    let (lg, ug, lgn, ugn) = s.rti().constraint_bounds();
    check(
        lg[1] == -2.0 && ug[1] == 0.5 && lgn[0] == -2.0 && ugn[0] == 0.5,
        "rows hold them",
    );
    check(
        lg[0] == -INF && ug[0] == 5.0,
        "the control's row keeps its bounds",
    );
    check(
        s.set_control_bounds(&[-1.0], &[1.5]).is_ok(),
        "control bounds set",
    );
    check(
        s.control_bounds() == ([-1.0], [1.5]),
        "control bounds read back",
    );
    check(
        s.constraint_bounds() == ([], []),
        "the model's own rows: none",
    );
    println!("api ok");
}

/// `models/cartpole.mpc`'s ODE (as `tests/examples.rs`'s plant), `x = [s, theta, ds, dtheta]`.
fn cartpole_ode(x: &[f64; 4], force: f64) -> [f64; 4] {
    let (g, mc, mp, l) = (9.81, 0.5, 0.2, 0.5);
    let (st, ct) = x[1].sin_cos();
    let d = mc + mp * st * st;
    let dds = (force + mp * st * (l * x[3] * x[3] + g * ct)) / d;
    let ddth = (-force * ct - mp * l * x[3] * x[3] * st * ct - (mc + mp) * g * st) / (l * d);
    [x[2], x[3], dds, ddth]
}

/// Classical RK4 over `dt` in 10 substeps, the control held (the plant).
fn plant(x: &[f64; 4], force: f64, dt: f64) -> [f64; 4] {
    let h = dt / 10.0;
    let add = |x: &[f64; 4], k: &[f64; 4], c: f64| std::array::from_fn(|i| x[i] + c * k[i]);
    let mut x = *x;
    for _ in 0..10 {
        let k1 = cartpole_ode(&x, force);
        let k2 = cartpole_ode(&add(&x, &k1, h / 2.0), force);
        let k3 = cartpole_ode(&add(&x, &k2, h / 2.0), force);
        let k4 = cartpole_ode(&add(&x, &k3, h), force);
        x = std::array::from_fn(|i| x[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]));
    }
    x
}

/// The cart-pole swing-up (300 real-time iterations from hanging at rest, default settings
/// but for the `shift`) with the rail a soft bound `|s| <= 0.5` of penalty `l1`: prints the steps not `Ok`, the
/// first step from which the pole stays within 0.05 rad of upright, the largest |s| of the
/// cart and of the plans, the largest multiplier of the bound's rows (stages 1..N-1), and
/// the largest distance of the last state from upright at rest.
fn cartpole(name: &str, l1: f64, shift: bool) {
    let mut s = Box::new(cartpole_soft::Solver::new());
    s.settings_mut().shift = shift;
    check(
        s.set_state_bound_penalties(&[l1], &[0.0]).is_ok(),
        "cart-pole penalty",
    );
    let (mut x, mut not_ok, mut since) = ([0.0; 4], 0, None);
    let (mut s_max, mut plan_max, mut mult) = (0.0_f64, 0.0_f64, 0.0_f64);
    for step in 0..300 {
        s.prepare();
        check(s.set_x0(&x).is_ok(), "set_x0");
        not_ok += usize::from(s.feedback().status != cartpole_soft::RtiStatus::Ok);
        for k in 1..=cartpole_soft::N {
            plan_max = plan_max.max(s.state(k).map_or(0.0, |v| v[0].abs()));
            let m = s
                .rti()
                .constraint_multipliers(k)
                .map_or(0.0, |m| m[0].abs());
            mult = mult.max(m);
        }
        x = plant(&x, s.u0()[0], cartpole_soft::DT);
        s_max = s_max.max(x[0].abs());
        let off = x[1].rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
        since = if off.abs() < 0.05 {
            since.or(Some(step + 1))
        } else {
            None
        };
    }
    let rest = (x[0].abs())
        .max(x[2].abs())
        .max(x[3].abs())
        .max((x[1] - std::f64::consts::PI).abs());
    println!("{name}_not_ok {not_ok}");
    println!("{name}_upright_since {}", since.unwrap_or(usize::MAX));
    println!("{name}_s_max {s_max:.17e}");
    println!("{name}_plan_max {plan_max:.17e}");
    println!("{name}_multiplier {mult:.17e}");
    println!("{name}_rest {rest:.17e}");
}

fn main() {
    // x_1 <= 1 soft: L2 only, L1 above and below the bound's multiplier 3, both.
    one_step("x_l2", 0.0, Some((1.0, 0.0, 10.0)), None);
    one_step("x_l1_above", 0.0, Some((1.0, 5.0, 0.0)), None);
    one_step("x_l1_below", 0.0, Some((1.0, 2.0, 0.0)), None);
    one_step("x_l1_l2", 0.0, Some((1.0, 2.0, 10.0)), None);
    // The measured state outside the bound: its stage-0 row is a constant.
    one_step("x_l2_outside", 1.5, Some((1.0, 0.0, 10.0)), None);
    // u_0 <= 1 soft.
    one_step("u_l2", 0.0, None, Some((1.0, 0.0, 10.0)));
    one_step("u_l1_above", 0.0, None, Some((1.0, 5.0, 0.0)));
    one_step("u_l1_below", 0.0, None, Some((1.0, 2.0, 0.0)));
    closed_loops("loop_l2", 0.0, 0.0, 10.0);
    closed_loops("loop_l1", 1.8, 5.0, 1.0);
    converged("ipopt_l2_inside", 0.0, 0.0, 10.0);
    converged("ipopt_l2_outside", 1.8, 0.0, 10.0);
    converged("ipopt_l1_l2_outside", 1.8, 5.0, 1.0);
    converged("ipopt_l1_below", 0.0, 2.0, 0.0);
    api();
    cartpole("cart_l1_100", 100.0, true);
    cartpole("cart_l1_1000", 1000.0, true);
    cartpole("cart_noshift_l1_1000", 1000.0, false);
    cartpole("cart_noshift_l1_10000", 10000.0, false);
}
