//! The plant of the paper's point-mass MPC (`models/paper_pointmass.mpc`): per axis a triple
//! integrator (position, velocity, acceleration) driven by the jerk, integrated exactly, as
//! `mpcc bench --model pointmass` and the criterion benches fly it.

/// The state one period `dt` on, from `x = (p, v, a)` (3 axes each) under the jerk `j` held
/// over the period.
pub fn plant(x: &[f64; 9], j: &[f64; 3], dt: f64) -> [f64; 9] {
    let mut next = *x;
    for i in 0..3 {
        let (p, v, a) = (x[i], x[3 + i], x[6 + i]);
        next[i] = p + v * dt + a * dt * dt / 2.0 + j[i] * dt * dt * dt / 6.0;
        next[3 + i] = v + a * dt + j[i] * dt * dt / 2.0;
        next[6 + i] = a + j[i] * dt;
    }
    next
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Against a fine RK4 integration of the same ODE (independent of the closed form), and
    /// periods that compose: two steps of dt are one of 2 dt.
    #[test]
    fn exact_against_rk4_and_composable() {
        let x = [0.3, -1.0, 2.0, 0.5, 0.1, -0.2, 1.5, -0.7, 0.25];
        let j = [2.0, -3.0, 0.5];
        let dt = 0.04;
        let ode = |s: &[f64; 9]| -> [f64; 9] {
            core::array::from_fn(|k| match k {
                0..3 => s[3 + k],
                3..6 => s[3 + k],
                _ => j[k - 6],
            })
        };
        let mut s = x;
        let n = 1000;
        let h = dt / f64::from(n);
        for _ in 0..n {
            let add = |a: &[f64; 9], c: f64, b: &[f64; 9]| -> [f64; 9] {
                core::array::from_fn(|k| a[k] + c * b[k])
            };
            let k1 = ode(&s);
            let k2 = ode(&add(&s, h / 2.0, &k1));
            let k3 = ode(&add(&s, h / 2.0, &k2));
            let k4 = ode(&add(&s, h, &k3));
            s = core::array::from_fn(|k| {
                s[k] + h / 6.0 * (k1[k] + 2.0 * k2[k] + 2.0 * k3[k] + k4[k])
            });
        }
        let exact = plant(&x, &j, dt);
        for k in 0..9 {
            assert!(
                (exact[k] - s[k]).abs() < 1e-12,
                "entry {k}: {} vs {}",
                exact[k],
                s[k]
            );
        }
        let twice = plant(&plant(&x, &j, dt), &j, dt);
        let once = plant(&x, &j, 2.0 * dt);
        for k in 0..9 {
            assert!((twice[k] - once[k]).abs() < 1e-12, "entry {k}");
        }
    }
}
