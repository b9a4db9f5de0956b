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

/// Calls a built-in function: the first family that knows `name` answers.
pub(crate) fn call<'g>(g: &'g Graph, name: &str, args: &[Val<'g>]) -> Result<Val<'g>, String> {
    unary(name, args)
        .or_else(|| binary(name, args))
        .or_else(|| vectors(g, name, args))
        .or_else(|| quaternions(name, args))
        .or_else(|| rotations(name, args))
        .or_else(|| constructors(g, name, args))
        .unwrap_or_else(|| {
            Err(format!(
                "unknown function `{name}`; the built-in functions are: {FUNCTIONS}"
            ))
        })
}

/// The message of a linear-algebra error.
fn le(e: crate::DslError) -> String {
    e.to_string()
}

/// A built-in function's answer: `None` where its family does not know the name.
type Answer<'g> = Option<Result<Val<'g>, String>>;

/// The element-wise functions of one argument.
fn unary<'g>(name: &str, args: &[Val<'g>]) -> Answer<'g> {
    let f: fn(Expr<'g>) -> Expr<'g> = match name {
        "sin" => Expr::sin,
        "cos" => Expr::cos,
        "tan" => Expr::tan,
        "asin" => Expr::asin,
        "acos" => Expr::acos,
        "atan" => Expr::atan,
        "exp" => Expr::exp,
        "log" => Expr::ln,
        "sqrt" => Expr::sqrt,
        "abs" => Expr::abs,
        "tanh" => Expr::tanh,
        "sign" => Expr::sign,
        "square" => Expr::square,
        _ => return None,
    };
    Some(count(name, args, 1).map(|()| args[0].map(&f)))
}

/// The element-wise functions of two arguments (with scalar broadcasting).
fn binary<'g>(name: &str, args: &[Val<'g>]) -> Answer<'g> {
    let f: fn(Expr<'g>, Expr<'g>) -> Expr<'g> = match name {
        "atan2" => |y, x| y.atan2(x),
        "pow" => |a, b| a.pow(b),
        "min" => |a, b| a.min(b),
        "max" => |a, b| a.max(b),
        "hadamard" => |a, b| a * b,
        _ => return None,
    };
    Some(count(name, args, 2).and_then(|()| zip(name, &args[0], &args[1], f)))
}

/// The functions of vectors: products, norms and sums.
fn vectors<'g>(g: &'g Graph, name: &str, args: &[Val<'g>]) -> Answer<'g> {
    Some(match name {
        "dot" => count(name, args, 2).and_then(|()| {
            linalg::dot(&vector(name, 0, &args[0])?, &vector(name, 1, &args[1])?)
                .map(Val::S)
                .map_err(le)
        }),
        "cross" => count(name, args, 2).and_then(|()| {
            linalg::cross(&vector(name, 0, &args[0])?, &vector(name, 1, &args[1])?)
                .map(Val::V)
                .map_err(le)
        }),
        "norm" | "norm2" | "sum" => reduction(g, name, args),
        _ => return None,
    })
}

/// `norm`, `norm2` and `sum` of a non-empty vector.
fn reduction<'g>(g: &'g Graph, name: &str, args: &[Val<'g>]) -> Result<Val<'g>, String> {
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

/// The quaternions' functions (`w, x, y, z` vectors).
fn quaternions<'g>(name: &str, args: &[Val<'g>]) -> Answer<'g> {
    let two = |f: fn(&[Expr<'g>], &[Expr<'g>]) -> crate::Result<Vector<'g>>| {
        count(name, args, 2)?;
        f(&vector(name, 0, &args[0])?, &vector(name, 1, &args[1])?)
            .map(Val::V)
            .map_err(le)
    };
    Some(match name {
        "quat_mul" => two(linalg::quat_mul),
        "quat_rotate" => two(linalg::quat_rotate),
        "quat_conj" => count(name, args, 1).and_then(|()| {
            linalg::quat_conj(&vector(name, 0, &args[0])?)
                .map(Val::V)
                .map_err(le)
        }),
        "quat_to_rot" => count(name, args, 1).and_then(|()| {
            linalg::quat_to_rotation(&vector(name, 0, &args[0])?)
                .map(Val::M)
                .map_err(le)
        }),
        _ => return None,
    })
}

/// The rotation matrices about an axis and of Euler angles, and the cross-product matrix.
fn rotations<'g>(name: &str, args: &[Val<'g>]) -> Answer<'g> {
    let about = |f: fn(Expr<'g>) -> Matrix<'g>| {
        count(name, args, 1)?;
        Ok(Val::M(f(scalar(name, 0, &args[0])?)))
    };
    Some(match name {
        "rot_x" => about(linalg::rot_x),
        "rot_y" => about(linalg::rot_y),
        "rot_z" => about(linalg::rot_z),
        "euler_zyx" => count(name, args, 3).and_then(|()| {
            Ok(Val::M(linalg::euler_zyx_to_rotation(
                scalar(name, 0, &args[0])?,
                scalar(name, 1, &args[1])?,
                scalar(name, 2, &args[2])?,
            )))
        }),
        "skew" => count(name, args, 1).and_then(|()| {
            linalg::skew(&vector(name, 0, &args[0])?)
                .map(Val::M)
                .map_err(le)
        }),
        _ => return None,
    })
}

/// The constructors (`diag`, `eye`, `zeros`, `mat`) and `transpose`.
fn constructors<'g>(g: &'g Graph, name: &str, args: &[Val<'g>]) -> Answer<'g> {
    Some(match name {
        "diag" => diag(g, name, args),
        "eye" => count(name, args, 1).and_then(|()| {
            let n = dim(name, scalar(name, 0, &args[0])?)?;
            if n > MAX_MATRIX_DIM {
                return Err(format!("eye: at most {MAX_MATRIX_DIM} rows"));
            }
            Ok(Val::M(Matrix::identity(g, n)))
        }),
        "zeros" => count(name, args, 1).and_then(|()| {
            let n = dim(name, scalar(name, 0, &args[0])?)?;
            Ok(Val::V(Vector::zeros(g, n)))
        }),
        "mat" => mat(name, args),
        "transpose" => {
            count(name, args, 1).and_then(|()| Ok(Val::M(matrix(name, 0, &args[0])?.transpose())))
        }
        _ => return None,
    })
}

/// `diag(v)` or `diag(a, b, c, ...)`: scalars and vectors are concatenated.
fn diag<'g>(g: &'g Graph, name: &str, args: &[Val<'g>]) -> Result<Val<'g>, String> {
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

/// `mat(row0, row1, ...)`: rows are vectors of equal length.
fn mat<'g>(name: &str, args: &[Val<'g>]) -> Result<Val<'g>, String> {
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
