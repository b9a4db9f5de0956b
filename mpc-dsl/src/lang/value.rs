//! Values of `.mpc` expressions (scalars, vectors, matrices) and the built-in functions.

use crate::graph::{Expr, Graph};
use crate::linalg::{self, Matrix, Vector};

/// A value: a scalar, a vector or a matrix of expressions.
#[derive(Clone, Debug)]
pub(crate) enum Val<'g> {
    S(Expr<'g>),
    V(Vector<'g>),
    M(Matrix<'g>),
}

/// Largest vector length or matrix dimension the language accepts (keeps hostile input from
/// allocating without bound).
pub(crate) const MAX_DIM: usize = 4096;

/// Largest matrix dimension built by `diag`, `eye` and `mat`.
pub(crate) const MAX_MATRIX_DIM: usize = 256;

impl<'g> Val<'g> {
    pub(crate) fn shape(&self) -> String {
        match self {
            Val::S(_) => "a scalar".into(),
            Val::V(v) => format!("a vector of length {}", v.len()),
            Val::M(m) => format!("a {}x{} matrix", m.nrows(), m.ncols()),
        }
    }

    /// Flattens a scalar or vector into entries.
    pub(crate) fn entries(&self) -> Option<Vec<Expr<'g>>> {
        match self {
            Val::S(e) => Some(vec![*e]),
            Val::V(v) => Some(v.to_vec()),
            Val::M(_) => None,
        }
    }

    fn map(&self, f: &impl Fn(Expr<'g>) -> Expr<'g>) -> Val<'g> {
        match self {
            Val::S(e) => Val::S(f(*e)),
            Val::V(v) => Val::V(v.iter().map(|&e| f(e)).collect()),
            Val::M(m) => {
                let data = m.as_row_major().iter().map(|&e| f(e)).collect();
                Val::M(rebuild(m, data))
            }
        }
    }
}

fn rebuild<'g>(m: &Matrix<'g>, data: Vec<Expr<'g>>) -> Matrix<'g> {
    Matrix::from_row_major(m.nrows(), m.ncols(), data)
        .unwrap_or_else(|_| unreachable!("same number of entries"))
}

/// Element-wise combination with scalar broadcasting.
pub(crate) fn zip<'g>(
    op: &str,
    a: &Val<'g>,
    b: &Val<'g>,
    f: impl Fn(Expr<'g>, Expr<'g>) -> Expr<'g>,
) -> Result<Val<'g>, String> {
    Ok(match (a, b) {
        (Val::S(x), other) => other.map(&|e| f(*x, e)),
        (other, Val::S(y)) => other.map(&|e| f(e, *y)),
        (Val::V(x), Val::V(y)) if x.len() == y.len() => {
            Val::V(x.iter().zip(y.iter()).map(|(&p, &q)| f(p, q)).collect())
        }
        (Val::M(x), Val::M(y)) if x.shape() == y.shape() => {
            let data = x
                .as_row_major()
                .iter()
                .zip(y.as_row_major())
                .map(|(&p, &q)| f(p, q))
                .collect();
            Val::M(rebuild(x, data))
        }
        _ => {
            return Err(format!(
                "`{op}` needs operands of the same shape (or a scalar), found {} and {}",
                a.shape(),
                b.shape()
            ));
        }
    })
}

/// `a * b`: scaling, matrix-vector and matrix-matrix products.
pub(crate) fn mul<'g>(a: &Val<'g>, b: &Val<'g>) -> Result<Val<'g>, String> {
    match (a, b) {
        (Val::S(_), _) | (_, Val::S(_)) => zip("*", a, b, |x, y| x * y),
        (Val::M(m), Val::V(v)) => m.matvec(v).map(Val::V).map_err(|e| e.to_string()),
        (Val::M(m), Val::M(n)) => m.matmul(n).map(Val::M).map_err(|e| e.to_string()),
        _ => Err(format!(
            "`*` of {} and {} is not defined: use dot(a, b) for a scalar product or \
             hadamard(a, b) for an element-wise one",
            a.shape(),
            b.shape()
        )),
    }
}

fn scalar<'g>(name: &str, i: usize, v: &Val<'g>) -> Result<Expr<'g>, String> {
    match v {
        Val::S(e) => Ok(*e),
        other => Err(format!(
            "{name}: argument {} must be a scalar, found {}",
            i + 1,
            other.shape()
        )),
    }
}

fn vector<'g>(name: &str, i: usize, v: &Val<'g>) -> Result<Vector<'g>, String> {
    match v {
        Val::V(x) => Ok(x.clone()),
        Val::S(e) => Ok(Vector::new(vec![*e])),
        other => Err(format!(
            "{name}: argument {} must be a vector, found {}",
            i + 1,
            other.shape()
        )),
    }
}

fn matrix<'g>(name: &str, i: usize, v: &Val<'g>) -> Result<Matrix<'g>, String> {
    match v {
        Val::M(m) => Ok(m.clone()),
        other => Err(format!(
            "{name}: argument {} must be a matrix, found {}",
            i + 1,
            other.shape()
        )),
    }
}

fn count(name: &str, args: &[Val<'_>], n: usize) -> Result<(), String> {
    if args.len() == n {
        Ok(())
    } else {
        Err(format!(
            "{name} takes {n} argument(s), {} given",
            args.len()
        ))
    }
}

fn dim(name: &str, e: Expr<'_>) -> Result<usize, String> {
    match e.as_constant() {
        Some(v) if v.fract() == 0.0 && v >= 0.0 && v <= MAX_DIM as f64 => Ok(v as usize),
        _ => Err(format!(
            "{name}: the size must be an integer constant between 0 and {MAX_DIM}"
        )),
    }
}

/// Names of the built-in functions (for messages).
pub(crate) const FUNCTIONS: &str = "sin cos tan asin acos atan exp log sqrt abs tanh sign \
    square atan2 pow min max dot cross norm norm2 sum hadamard quat_mul quat_conj quat_rotate \
    quat_to_rot rot_x rot_y rot_z euler_zyx skew diag eye zeros mat transpose";

/// Calls a built-in function.
pub(crate) fn call<'g>(g: &'g Graph, name: &str, args: &[Val<'g>]) -> Result<Val<'g>, String> {
    let unary: Option<fn(Expr<'g>) -> Expr<'g>> = match name {
        "sin" => Some(Expr::sin),
        "cos" => Some(Expr::cos),
        "tan" => Some(Expr::tan),
        "asin" => Some(Expr::asin),
        "acos" => Some(Expr::acos),
        "atan" => Some(Expr::atan),
        "exp" => Some(Expr::exp),
        "log" => Some(Expr::ln),
        "sqrt" => Some(Expr::sqrt),
        "abs" => Some(Expr::abs),
        "tanh" => Some(Expr::tanh),
        "sign" => Some(Expr::sign),
        "square" => Some(Expr::square),
        _ => None,
    };
    if let Some(f) = unary {
        count(name, args, 1)?;
        return Ok(args[0].map(&f));
    }
    let le = |e: crate::DslError| e.to_string();
    match name {
        "atan2" => {
            count(name, args, 2)?;
            zip(name, &args[0], &args[1], |y, x| y.atan2(x))
        }
        "pow" => {
            count(name, args, 2)?;
            zip(name, &args[0], &args[1], |a, b| a.pow(b))
        }
        "min" => {
            count(name, args, 2)?;
            zip(name, &args[0], &args[1], |a, b| a.min(b))
        }
        "max" => {
            count(name, args, 2)?;
            zip(name, &args[0], &args[1], |a, b| a.max(b))
        }
        "hadamard" => {
            count(name, args, 2)?;
            zip(name, &args[0], &args[1], |a, b| a * b)
        }
        "dot" => {
            count(name, args, 2)?;
            linalg::dot(&vector(name, 0, &args[0])?, &vector(name, 1, &args[1])?)
                .map(Val::S)
                .map_err(le)
        }
        "cross" => {
            count(name, args, 2)?;
            linalg::cross(&vector(name, 0, &args[0])?, &vector(name, 1, &args[1])?)
                .map(Val::V)
                .map_err(le)
        }
        "norm" | "norm2" | "sum" => {
            count(name, args, 1)?;
            let v = vector(name, 0, &args[0])?;
            if v.is_empty() {
                return Err(format!("{name}: the vector is empty"));
            }
            Ok(Val::S(match name {
                "norm" => linalg::norm(&v).map_err(le)?,
                "norm2" => linalg::norm_squared(&v).map_err(le)?,
                _ => linalg::sum(v.iter().copied()).unwrap_or_else(|| g.zero()),
            }))
        }
        "quat_mul" => {
            count(name, args, 2)?;
            linalg::quat_mul(&vector(name, 0, &args[0])?, &vector(name, 1, &args[1])?)
                .map(Val::V)
                .map_err(le)
        }
        "quat_conj" => {
            count(name, args, 1)?;
            linalg::quat_conj(&vector(name, 0, &args[0])?)
                .map(Val::V)
                .map_err(le)
        }
        "quat_rotate" => {
            count(name, args, 2)?;
            linalg::quat_rotate(&vector(name, 0, &args[0])?, &vector(name, 1, &args[1])?)
                .map(Val::V)
                .map_err(le)
        }
        "quat_to_rot" => {
            count(name, args, 1)?;
            linalg::quat_to_rotation(&vector(name, 0, &args[0])?)
                .map(Val::M)
                .map_err(le)
        }
        "rot_x" | "rot_y" | "rot_z" => {
            count(name, args, 1)?;
            let a = scalar(name, 0, &args[0])?;
            Ok(Val::M(match name {
                "rot_x" => linalg::rot_x(a),
                "rot_y" => linalg::rot_y(a),
                _ => linalg::rot_z(a),
            }))
        }
        "euler_zyx" => {
            count(name, args, 3)?;
            Ok(Val::M(linalg::euler_zyx_to_rotation(
                scalar(name, 0, &args[0])?,
                scalar(name, 1, &args[1])?,
                scalar(name, 2, &args[2])?,
            )))
        }
        "skew" => {
            count(name, args, 1)?;
            linalg::skew(&vector(name, 0, &args[0])?)
                .map(Val::M)
                .map_err(le)
        }
        "diag" => {
            // diag(v) or diag(a, b, c, ...): scalars and vectors are concatenated.
            let mut d = Vec::new();
            for (i, a) in args.iter().enumerate() {
                d.extend(vector(name, i, a)?.iter().copied());
            }
            if d.is_empty() || d.len() > MAX_MATRIX_DIM {
                return Err(format!(
                    "diag: needs between 1 and {MAX_MATRIX_DIM} entries"
                ));
            }
            Ok(Val::M(Matrix::diag(g, &d)))
        }
        "eye" => {
            count(name, args, 1)?;
            let n = dim(name, scalar(name, 0, &args[0])?)?;
            if n > MAX_MATRIX_DIM {
                return Err(format!("eye: at most {MAX_MATRIX_DIM} rows"));
            }
            Ok(Val::M(Matrix::identity(g, n)))
        }
        "zeros" => {
            count(name, args, 1)?;
            let n = dim(name, scalar(name, 0, &args[0])?)?;
            Ok(Val::V(Vector::zeros(g, n)))
        }
        "mat" => {
            // mat(row0, row1, ...): rows are vectors of equal length.
            let rows: Vec<Vector<'g>> = args
                .iter()
                .enumerate()
                .map(|(i, a)| vector(name, i, a))
                .collect::<Result<_, _>>()?;
            if rows.is_empty() || rows.len() > MAX_MATRIX_DIM || rows[0].len() > MAX_MATRIX_DIM {
                return Err(format!(
                    "mat: give between 1 and {MAX_MATRIX_DIM} rows and columns"
                ));
            }
            Matrix::from_rows(&rows).map(Val::M).map_err(le)
        }
        "transpose" => {
            count(name, args, 1)?;
            Ok(Val::M(matrix(name, 0, &args[0])?.transpose()))
        }
        _ => Err(format!(
            "unknown function `{name}`; the built-in functions are: {FUNCTIONS}"
        )),
    }
}
