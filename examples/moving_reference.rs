//! QR-bench A (`mpc_models::quadrotor_rates_a`, the code of `generated/quadrotor_rates_a`)
//! tracking a reference that moves at every control step: the target position slides from (0,
//! 0, 2) to (4, 0, 2) over the 4 s, set with `set_xref_all` before each preparation, as a
//! tracking controller does. For instruction counts:
//!
//! ```sh
//! cargo build --release --example moving_reference
//! valgrind --tool=callgrind target/release/examples/moving_reference
//! callgrind_annotate --inclusive=yes callgrind.out.<pid> | grep -E "Solver::(prepare|feedback) "
//! ```
//!
//! (divide by the 100 steps). Prints the final state.

use mpc_models::quadrotor_rates_a as m;
use mpc_sim::qrbench::{X0, plant};

fn main() {
    let mut s = Box::new(m::Solver::new());
    if s.set_guess(&X0, &[0.0; 4]).is_err() {
        eprintln!("guess refused");
        std::process::exit(1);
    }
    let mut x = X0;
    for k in 0..100 {
        let px = 4.0 * k as f64 / 100.0;
        let xref = [px, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        if s.set_xref_all(&xref).is_err() {
            eprintln!("step {k}: reference refused");
            std::process::exit(1);
        }
        s.prepare();
        if s.set_x0(&x).is_err() {
            eprintln!("step {k}: state refused");
            std::process::exit(1);
        }
        let info = s.feedback();
        if info.status != m::RtiStatus::Ok {
            eprintln!("step {k}: {:?}", info.status);
        }
        x = plant(&x, &s.u0(), m::DT, 10);
    }
    println!("final state {x:?}");
}
