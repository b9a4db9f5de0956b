//! Vector, matrix, quaternion and rotation helpers checked against nalgebra, an independent
//! implementation, on random inputs.

use mpc_dsl::linalg::{
    cross, dot, euler_zyx_to_rotation, norm, quat_conj, quat_mul, quat_rotate, quat_to_rotation,
    skew, vee,
};
use mpc_dsl::{DslError, Expr, Graph, Matrix, Vector};
use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};
use proptest::prelude::*;

const TOL: f64 = 1e-12;

/// Symbols `name[i]` bound to `values`.
fn bound<'g>(g: &'g Graph, name: &str, values: &[f64]) -> (Vector<'g>, Vec<(Expr<'g>, f64)>) {
    let v = g.symbols(name, values.len());
    let b = v.iter().copied().zip(values.iter().copied()).collect();
    (v, b)
}

fn eval_all<'g>(g: &'g Graph, exprs: &[Expr<'g>], b: &[(Expr<'g>, f64)]) -> Vec<f64> {
    g.eval(exprs, b).unwrap()
}

fn assert_close(ours: &[f64], theirs: &[f64]) {
    assert_eq!(ours.len(), theirs.len());
    for (k, (a, b)) in ours.iter().zip(theirs).enumerate() {
        assert!(
            (a - b).abs() <= TOL * b.abs().max(1.0),
            "entry {k}: {a} vs {b}"
        );
    }
}

/// nalgebra matrices are column-major; ours row-major.
fn row_major(m: &Matrix3<f64>) -> Vec<f64> {
    m.transpose().as_slice().to_vec()
}

fn quat() -> impl Strategy<Value = [f64; 4]> {
    prop::array::uniform4(-1.0f64..1.0).prop_filter("not near zero", |q| {
        q.iter().map(|v| v * v).sum::<f64>() > 1e-2
    })
}

fn vec3() -> impl Strategy<Value = [f64; 3]> {
    prop::array::uniform3(-10.0f64..10.0)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn quaternion_product_matches_nalgebra(p in quat(), q in quat()) {
        let g = Graph::new();
        let (ps, mut b) = bound(&g, "p", &p);
        let (qs, bq) = bound(&g, "q", &q);
        b.extend(bq);
        let ours = eval_all(&g, &quat_mul(&ps, &qs).unwrap(), &b);
        let prod = Quaternion::new(p[0], p[1], p[2], p[3]) * Quaternion::new(q[0], q[1], q[2], q[3]);
        assert_close(&ours, &[prod.w, prod.i, prod.j, prod.k]);
        let conj = eval_all(&g, &quat_conj(&ps).unwrap(), &b);
        let c = Quaternion::new(p[0], p[1], p[2], p[3]).conjugate();
        assert_close(&conj, &[c.w, c.i, c.j, c.k]);
    }

    #[test]
    fn quaternion_rotation_matches_nalgebra(q in quat(), v in vec3()) {
        let g = Graph::new();
        let n = q.iter().map(|x| x * x).sum::<f64>().sqrt();
        let qn = q.map(|x| x / n);
        let (qs, mut b) = bound(&g, "q", &qn);
        let (vs, bv) = bound(&g, "v", &v);
        b.extend(bv);
        let unit = UnitQuaternion::from_quaternion(Quaternion::new(qn[0], qn[1], qn[2], qn[3]));
        let r = quat_to_rotation(&qs).unwrap();
        assert_close(&eval_all(&g, r.as_row_major(), &b), &row_major(unit.to_rotation_matrix().matrix()));
        let rotated = unit * Vector3::new(v[0], v[1], v[2]);
        assert_close(&eval_all(&g, &quat_rotate(&qs, &vs).unwrap(), &b), rotated.as_slice());
    }

    #[test]
    fn euler_zyx_matches_nalgebra(roll in -3.2f64..3.2, pitch in -1.6f64..1.6, yaw in -3.2f64..3.2) {
        let g = Graph::new();
        let (a, b) = bound(&g, "a", &[roll, pitch, yaw]);
        let r = euler_zyx_to_rotation(a[0], a[1], a[2]);
        // nalgebra's from_euler_angles(roll, pitch, yaw) is Rz(yaw) Ry(pitch) Rx(roll).
        let want = Rotation3::from_euler_angles(roll, pitch, yaw);
        assert_close(&eval_all(&g, r.as_row_major(), &b), &row_major(want.matrix()));
    }

    #[test]
    fn vector_helpers_match_nalgebra(a in vec3(), c in vec3()) {
        let g = Graph::new();
        let (av, mut b) = bound(&g, "a", &a);
        let (cv, bc) = bound(&g, "c", &c);
        b.extend(bc);
        let (na, nc) = (Vector3::from(a), Vector3::from(c));
        assert_close(&eval_all(&g, &cross(&av, &cv).unwrap(), &b), na.cross(&nc).as_slice());
        assert_close(&eval_all(&g, &[dot(&av, &cv).unwrap()], &b), &[na.dot(&nc)]);
        assert_close(&eval_all(&g, &[norm(&av).unwrap()], &b), &[na.norm()]);
        let s = skew(&av).unwrap();
        assert_close(&eval_all(&g, s.as_row_major(), &b), &row_major(&na.cross_matrix()));
        // skew(a) c = a x c, and vee inverts skew.
        assert_close(&eval_all(&g, &s.matvec(&cv).unwrap(), &b), na.cross(&nc).as_slice());
        assert_eq!(vee(&s).unwrap(), av);
    }

    #[test]
    fn matrix_helpers_match_nalgebra(m in prop::array::uniform9(-5.0f64..5.0),
                                     n in prop::array::uniform9(-5.0f64..5.0), v in vec3()) {
        let g = Graph::new();
        let (ms, mut b) = bound(&g, "m", &m);
        let (ns, bn) = bound(&g, "n", &n);
        let (vs, bv) = bound(&g, "v", &v);
        b.extend(bn);
        b.extend(bv);
        let mm = Matrix::from_row_major(3, 3, ms.into_vec()).unwrap();
        let nm = Matrix::from_row_major(3, 3, ns.into_vec()).unwrap();
        let (am, an) = (Matrix3::from_row_slice(&m), Matrix3::from_row_slice(&n));
        assert_close(&eval_all(&g, mm.matmul(&nm).unwrap().as_row_major(), &b), &row_major(&(am * an)));
        assert_close(&eval_all(&g, mm.transpose().as_row_major(), &b), &row_major(&am.transpose()));
        assert_close(&eval_all(&g, &mm.matvec(&vs).unwrap(), &b), (am * Vector3::from(v)).as_slice());
        assert_close(&eval_all(&g, mm.add(&nm).unwrap().as_row_major(), &b), &row_major(&(am + an)));
        assert_close(&eval_all(&g, mm.sub(&nm).unwrap().as_row_major(), &b), &row_major(&(am - an)));
    }
}

/// The paper's attitude error e_R = 1/2 (Rd' R - R' Rd)^vee is zero at R = Rd and, for a small
/// rotation about one axis, equals the rotation vector.
#[test]
fn attitude_error_of_the_paper() {
    let g = Graph::new();
    let (a, b) = bound(&g, "a", &[0.3, -0.2, 1.1, 0.3, -0.2, 1.1 + 1e-4]);
    let r = euler_zyx_to_rotation(a[0], a[1], a[2]);
    let rd = euler_zyx_to_rotation(a[3], a[4], a[5]);
    let diff = rd
        .transpose()
        .matmul(&r)
        .unwrap()
        .sub(&r.transpose().matmul(&rd).unwrap())
        .unwrap();
    let e_r = vee(&diff).unwrap().scale(0.5);
    let got = g.eval(&e_r, &b).unwrap();
    // Rd = R Rz'(1e-4) with the yaw step taken in the world frame: expressed in the body frame
    // the error is R' (0, 0, -1e-4).
    let rn = Rotation3::from_euler_angles(0.3, -0.2, 1.1);
    let want = rn.transpose() * Vector3::new(0.0, 0.0, -1e-4);
    for k in 0..3 {
        assert!((got[k] - want[k]).abs() < 1e-8, "{got:?} vs {want:?}");
    }
}

#[test]
fn shape_errors_name_the_operation_and_shapes() {
    let g = Graph::new();
    let v2 = g.symbols("v", 2);
    let v3 = g.symbols("w", 3);
    let q = g.symbols("q", 4);
    let err = cross(&v2, &v3).unwrap_err();
    assert_eq!(
        err.to_string(),
        "cross: expected two vectors of length 3, found lengths 2 and 3; fix the shape of the operand"
    );
    assert!(matches!(
        dot(&v2, &v3),
        Err(DslError::DimensionMismatch { op: "dot", .. })
    ));
    assert!(matches!(dot(&[], &[]), Err(DslError::Empty { op: "dot" })));
    assert!(matches!(
        skew(&q),
        Err(DslError::DimensionMismatch { op: "skew", .. })
    ));
    assert!(matches!(
        quat_mul(&q, &v3),
        Err(DslError::DimensionMismatch { op: "quat_mul", .. })
    ));
    assert!(matches!(
        quat_to_rotation(&v3),
        Err(DslError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        quat_rotate(&q, &q),
        Err(DslError::DimensionMismatch { .. })
    ));
    let m23 = Matrix::from_rows(&[v3.clone(), v3.clone()]).unwrap();
    assert!(matches!(
        m23.matvec(&v2),
        Err(DslError::DimensionMismatch { op: "matvec", .. })
    ));
    assert!(matches!(
        m23.matmul(&m23),
        Err(DslError::DimensionMismatch { op: "matmul", .. })
    ));
    assert!(matches!(
        vee(&m23),
        Err(DslError::DimensionMismatch { op: "vee", .. })
    ));
    assert!(matches!(
        Matrix::from_rows(&[v2.clone(), v3.clone()]),
        Err(DslError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        Matrix::from_row_major(2, 2, v3.into_vec()),
        Err(DslError::DimensionMismatch { .. })
    ));
    assert!(matches!(
        Vector::from(v2.clone().into_vec()).add(&q),
        Err(DslError::DimensionMismatch { .. })
    ));
}
