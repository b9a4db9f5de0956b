//! `mpc-models`' solvers, which its build script generates, are the checked-in crates of
//! `generated/` of the same name without their C ABI: the same sizes, and the same closed
//! loop bit for bit. A difference means that `models/build.rs` and the commands of
//! `generated/README.md` generate with different options.

/// Five closed-loop steps of `mpc_models::$name` and of the crate `$name` from the model's
/// guess moved by a few centimetres; every status and control must be identical.
macro_rules! same_solver {
    ($name:ident) => {{
        use mpc_models::$name as a;
        use $name as b;
        let name = stringify!($name);
        assert_eq!(
            [a::N, a::NX, a::NU, a::NP, a::NY, a::NYN, a::NG, a::NGN],
            [b::N, b::NX, b::NU, b::NP, b::NY, b::NYN, b::NG, b::NGN],
            "{name}"
        );
        assert_eq!([a::NC, a::NR, a::NH], [b::NC, b::NR, b::NH], "{name}");
        assert_eq!(format!("{:?}", a::DT), format!("{:?}", b::DT), "{name}");
        let mut sa = Box::new(a::Solver::new());
        let mut sb = Box::new(b::Solver::new());
        let mut x = sa.state(0).expect("stage 0");
        for k in 0..5 {
            x[0] += 0.01 * (k + 1) as a::Real;
            sa.prepare();
            sb.prepare();
            sa.set_x0(&x).expect("a finite state");
            sb.set_x0(&x).expect("a finite state");
            let (ia, ib) = (sa.feedback(), sb.feedback());
            assert_eq!(
                format!("{:?} {:?}", ia.status, sa.u0()),
                format!("{:?} {:?}", ib.status, sb.u0()),
                "{name}, step {k}"
            );
            assert!(sa.u0().iter().all(|u| u.is_finite()), "{name}, step {k}");
            x = sa.state(1).expect("stage 1");
        }
    }};
}

#[test]
fn the_paper_solvers_of_mpc_models_are_the_checked_in_crates() {
    same_solver!(paper_pointmass);
    same_solver!(quadrotor_probe);
    same_solver!(quadrotor_rates);
    same_solver!(quadrotor_rates_a);
    same_solver!(quadrotor_rates_a_exact);
    same_solver!(quadrotor_rates_b_exact);
    same_solver!(quadrotor_rates_f32);
    same_solver!(quadrotor_rates_b_f32);
    same_solver!(quadrotor_rates_n40);
    same_solver!(quadrotor_rates_n40_f32);
}

/// `mpc_models::source` embeds every `.mpc` file of `models/`, and each text parses as the
/// model its file is named after.
#[test]
fn every_model_file_is_embedded_and_parses() {
    use mpc_dsl::Graph;
    use mpc_dsl::lang::{ParseOptions, parse};
    use mpc_models::source as s;
    let embedded = [
        ("paper_pointmass", s::PAPER_POINTMASS),
        ("quadrotor_rates", s::QUADROTOR_RATES),
        ("quadrotor_probe", s::QUADROTOR_PROBE),
        ("cartpole", s::CARTPOLE),
        ("bicycle", s::BICYCLE),
        ("planar_quadrotor", s::PLANAR_QUADROTOR),
        ("stiff_actuator", s::STIFF_ACTUATOR),
    ];
    for (name, text) in embedded {
        let g = Graph::new();
        let parsed = parse(&g, text, &ParseOptions::default())
            .unwrap_or_else(|d| panic!("{}", d.render(name, text)));
        assert_eq!(parsed.ocp.name, name);
    }
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("models");
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| {
            let path = e.ok()?.path();
            let stem = path.file_stem()?.to_str()?.to_string();
            path.extension().is_some_and(|x| x == "mpc").then_some(stem)
        })
        .collect();
    files.sort();
    let mut names: Vec<String> = embedded.iter().map(|(n, _)| n.to_string()).collect();
    names.sort();
    assert_eq!(
        files, names,
        "a model file of models/ is not in mpc_models::source"
    );
}
