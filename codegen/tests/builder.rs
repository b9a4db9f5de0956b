//! `Builder` (the build.rs entry point) from a file and from an `Ocp` made with the Rust
//! builder API: what it writes, that an unchanged model leaves the file untouched, and its
//! errors.

use std::path::Path;

use mpc_codegen::{Builder, CodegenError, Scalar};
use mpc_dsl::ocp::{Decl, Integrator};
use mpc_dsl::{Graph, Matrix, Ocp};

fn tmp(name: &str) -> std::path::PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    d
}

#[test]
fn builder_from_an_ocp_writes_a_module_once() {
    let g = Graph::new();
    let mut b = Ocp::builder(&g, "double_integrator");
    let x = b.state(Decl::vector("x", 2));
    let u = b.control(Decl::scalar("u"));
    b.ode(&[x[1], u[0]], Integrator::Rk4 { steps: 2 });
    b.horizon(10, 0.1);
    let zero = [g.zero(), g.zero()];
    b.state_cost(Matrix::diag(&g, &[g.one(), g.one()]), &zero);
    b.control_cost(Matrix::diag(&g, &[g.constant(0.1).unwrap()]), &[g.zero()]);
    b.bound(&u, -1.0, 1.0);
    let ocp = b.build().unwrap();
    let dir = tmp("builder_ocp");
    let path = Builder::from_ocp()
        .out_dir(&dir)
        .module("di")
        .scalar(Scalar::F32)
        .build_ocp(&ocp)
        .unwrap();
    assert_eq!(path, dir.join("di.rs"));
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("pub mod di {"), "{text}");
    assert!(text.contains("pub type Real = f32;"));
    assert!(!text.contains("extern \"C\""), "no C ABI unless asked");
    let t0 = std::fs::metadata(&path).unwrap().modified().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    Builder::from_ocp()
        .out_dir(&dir)
        .module("di")
        .scalar(Scalar::F32)
        .build_ocp(&ocp)
        .unwrap();
    let t1 = std::fs::metadata(&path).unwrap().modified().unwrap();
    assert_eq!(
        t0, t1,
        "an unchanged module is not rewritten (no needless rebuild)"
    );
    let with_ffi = Builder::from_ocp()
        .out_dir(&dir)
        .module("di_c")
        .c_abi(true)
        .build_ocp(&ocp)
        .unwrap();
    assert!(
        std::fs::read_to_string(with_ffi)
            .unwrap()
            .contains("di_c_feedback")
    );
}

#[test]
fn builder_errors_name_the_problem() {
    let e = Builder::from_ocp()
        .out_dir(tmp("b_err"))
        .build()
        .unwrap_err();
    assert!(matches!(e, CodegenError::Option(_)), "{e}");
    assert!(e.to_string().contains("build_ocp"), "{e}");
    let e = Builder::new("no/such/model.mpc")
        .out_dir(tmp("b_err2"))
        .build()
        .unwrap_err();
    assert!(e.to_string().contains("no/such/model.mpc"), "{e}");
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let e = Builder::new(root.join("models/quadrotor_rates.mpc"))
        .out_dir(tmp("b_err3"))
        .module("fn")
        .build()
        .unwrap_err();
    assert!(e.to_string().contains("`fn` is not usable"), "{e}");
}
