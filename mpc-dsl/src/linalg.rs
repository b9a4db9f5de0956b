//! Vectors and small dense matrices of expressions.
//!
//! Shapes are checked at run time: an operation on incompatible shapes returns
//! [`DslError::DimensionMismatch`] naming the operation and both shapes.

use core::ops::{Deref, Index};

use crate::error::{DslError, Result};
use crate::graph::{Expr, Graph, IntoExpr};

/// A column vector of expressions.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Vector<'g>(Vec<Expr<'g>>);

fn mismatch(op: &'static str, expected: impl Into<String>, found: impl Into<String>) -> DslError {
    DslError::DimensionMismatch {
        op,
        expected: expected.into(),
        found: found.into(),
    }
}

fn expect_len(op: &'static str, v: &[Expr<'_>], n: usize, what: &str) -> Result<()> {
    if v.len() == n {
        Ok(())
    } else {
        Err(mismatch(
            op,
            format!("{what} of length {n}"),
            format!("length {}", v.len()),
        ))
    }
}

/// The sum of expressions, or `None` for an empty iterator.
pub fn sum<'g>(terms: impl IntoIterator<Item = Expr<'g>>) -> Option<Expr<'g>> {
    terms.into_iter().reduce(|a, b| a + b)
}

/// Dot product `a' b`.
///
/// # Errors
/// [`DslError::DimensionMismatch`] if the lengths differ, [`DslError::Empty`] if both are
/// empty.
pub fn dot<'g>(a: &[Expr<'g>], b: &[Expr<'g>]) -> Result<Expr<'g>> {
    if a.len() != b.len() {
        return Err(mismatch(
            "dot",
            "two vectors of the same length",
            format!("lengths {} and {}", a.len(), b.len()),
        ));
    }
    sum(a.iter().zip(b).map(|(&x, &y)| x * y)).ok_or(DslError::Empty { op: "dot" })
}

/// Cross product `a x b` of two 3-vectors.
///
/// # Errors
/// [`DslError::DimensionMismatch`] unless both have length 3.
pub fn cross<'g>(a: &[Expr<'g>], b: &[Expr<'g>]) -> Result<Vector<'g>> {
    if a.len() != 3 || b.len() != 3 {
        return Err(mismatch(
            "cross",
            "two vectors of length 3",
            format!("lengths {} and {}", a.len(), b.len()),
        ));
    }
    Ok(Vector(vec![
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]))
}

/// Squared Euclidean norm `a' a`.
///
/// # Errors
/// [`DslError::Empty`] for an empty vector.
pub fn norm_squared<'g>(a: &[Expr<'g>]) -> Result<Expr<'g>> {
    sum(a.iter().map(|&x| x.square())).ok_or(DslError::Empty { op: "norm" })
}

/// Euclidean norm `sqrt(a' a)`.
///
/// # Errors
/// [`DslError::Empty`] for an empty vector.
pub fn norm<'g>(a: &[Expr<'g>]) -> Result<Expr<'g>> {
    norm_squared(a).map(Expr::sqrt)
}

impl<'g> Vector<'g> {
    /// A vector of the given expressions.
    pub fn new(entries: Vec<Expr<'g>>) -> Vector<'g> {
        Vector(entries)
    }

    /// A vector of constants.
    pub fn constants(graph: &'g Graph, values: &[f64]) -> Vector<'g> {
        values
            .iter()
            .map(|&v| graph.constant_unchecked(v))
            .collect()
    }

    /// `n` zeros.
    pub fn zeros(graph: &'g Graph, n: usize) -> Vector<'g> {
        Vector(vec![graph.zero(); n])
    }

    /// The entries.
    pub fn as_slice(&self) -> &[Expr<'g>] {
        &self.0
    }

    /// The entries, by value.
    pub fn into_vec(self) -> Vec<Expr<'g>> {
        self.0
    }

    /// Dot product; see [`dot`].
    ///
    /// # Errors
    /// As [`dot`].
    pub fn dot(&self, other: &[Expr<'g>]) -> Result<Expr<'g>> {
        dot(self, other)
    }

    /// Cross product; see [`cross`].
    ///
    /// # Errors
    /// As [`cross`].
    pub fn cross(&self, other: &[Expr<'g>]) -> Result<Vector<'g>> {
        cross(self, other)
    }

    /// Euclidean norm; see [`norm`].
    ///
    /// # Errors
    /// As [`norm`].
    pub fn norm(&self) -> Result<Expr<'g>> {
        norm(self)
    }

    fn zip_with(
        &self,
        other: &[Expr<'g>],
        op: &'static str,
        f: impl Fn(Expr<'g>, Expr<'g>) -> Expr<'g>,
    ) -> Result<Vector<'g>> {
        if self.len() != other.len() {
            return Err(mismatch(
                op,
                "two vectors of the same length",
                format!("lengths {} and {}", self.len(), other.len()),
            ));
        }
        Ok(self.iter().zip(other).map(|(&a, &b)| f(a, b)).collect())
    }

    /// Entry-wise sum.
    ///
    /// # Errors
    /// [`DslError::DimensionMismatch`] if the lengths differ.
    pub fn add(&self, other: &[Expr<'g>]) -> Result<Vector<'g>> {
        self.zip_with(other, "vector add", |a, b| a + b)
    }

    /// Entry-wise difference.
    ///
    /// # Errors
    /// [`DslError::DimensionMismatch`] if the lengths differ.
    pub fn sub(&self, other: &[Expr<'g>]) -> Result<Vector<'g>> {
        self.zip_with(other, "vector sub", |a, b| a - b)
    }

    /// Every entry times `s`.
    pub fn scale(&self, s: impl IntoExpr<'g> + Copy) -> Vector<'g> {
        self.iter().map(|&a| a * s.into_expr(a.graph)).collect()
    }

    /// Every entry negated.
    pub fn neg(&self) -> Vector<'g> {
        self.iter().map(|&a| -a).collect()
    }
}

impl<'g> Deref for Vector<'g> {
    type Target = [Expr<'g>];
    fn deref(&self) -> &[Expr<'g>] {
        &self.0
    }
}

impl<'g> AsRef<[Expr<'g>]> for Vector<'g> {
    fn as_ref(&self) -> &[Expr<'g>] {
        &self.0
    }
}

impl<'g> FromIterator<Expr<'g>> for Vector<'g> {
    fn from_iter<I: IntoIterator<Item = Expr<'g>>>(iter: I) -> Self {
        Vector(iter.into_iter().collect())
    }
}

impl<'g> From<Vec<Expr<'g>>> for Vector<'g> {
    fn from(v: Vec<Expr<'g>>) -> Self {
        Vector(v)
    }
}

impl<'g, const N: usize> From<[Expr<'g>; N]> for Vector<'g> {
    fn from(v: [Expr<'g>; N]) -> Self {
        Vector(v.to_vec())
    }
}

impl<'g> IntoIterator for Vector<'g> {
    type Item = Expr<'g>;
    type IntoIter = std::vec::IntoIter<Expr<'g>>;
    fn into_iter(self) -> Self::IntoIter {
        self.0.into_iter()
    }
}

impl<'a, 'g> IntoIterator for &'a Vector<'g> {
    type Item = &'a Expr<'g>;
    type IntoIter = core::slice::Iter<'a, Expr<'g>>;
    fn into_iter(self) -> Self::IntoIter {
        self.0.iter()
    }
}

/// A dense matrix of expressions, stored row by row.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Matrix<'g> {
    rows: usize,
    cols: usize,
    data: Vec<Expr<'g>>,
}

impl<'g> Matrix<'g> {
    /// A `rows x cols` matrix from its entries row by row.
    ///
    /// # Errors
    /// [`DslError::DimensionMismatch`] if `data.len() != rows * cols`.
    pub fn from_row_major(rows: usize, cols: usize, data: Vec<Expr<'g>>) -> Result<Matrix<'g>> {
        if data.len() != rows * cols {
            return Err(mismatch(
                "matrix from row-major data",
                format!("{} entries for {rows}x{cols}", rows * cols),
                format!("{} entries", data.len()),
            ));
        }
        Ok(Matrix { rows, cols, data })
    }

    /// A matrix from its rows.
    ///
    /// # Errors
    /// [`DslError::DimensionMismatch`] if the rows differ in length.
    pub fn from_rows<R: AsRef<[Expr<'g>]>>(rows: &[R]) -> Result<Matrix<'g>> {
        let cols = rows.first().map_or(0, |r| r.as_ref().len());
        let mut data = Vec::with_capacity(rows.len() * cols);
        for (i, r) in rows.iter().enumerate() {
            let r = r.as_ref();
            if r.len() != cols {
                return Err(mismatch(
                    "matrix from rows",
                    format!("every row of length {cols}"),
                    format!("row {i} of length {}", r.len()),
                ));
            }
            data.extend_from_slice(r);
        }
        Ok(Matrix {
            rows: rows.len(),
            cols,
            data,
        })
    }

    /// The `n x n` identity.
    pub fn identity(graph: &'g Graph, n: usize) -> Matrix<'g> {
        let mut m = Matrix::zeros(graph, n, n);
        for i in 0..n {
            m.data[i * n + i] = graph.one();
        }
        m
    }

    /// The `rows x cols` zero matrix.
    pub fn zeros(graph: &'g Graph, rows: usize, cols: usize) -> Matrix<'g> {
        Matrix {
            rows,
            cols,
            data: vec![graph.zero(); rows * cols],
        }
    }

    /// A diagonal matrix.
    pub fn diag(graph: &'g Graph, d: &[Expr<'g>]) -> Matrix<'g> {
        let n = d.len();
        let mut m = Matrix::zeros(graph, n, n);
        for (i, &e) in d.iter().enumerate() {
            m.data[i * n + i] = e;
        }
        m
    }

    /// A matrix of constants given row by row.
    ///
    /// # Errors
    /// [`DslError::DimensionMismatch`] if the rows differ in length.
    pub fn constants<R: AsRef<[f64]>>(graph: &'g Graph, rows: &[R]) -> Result<Matrix<'g>> {
        let rows: Vec<Vector<'g>> = rows
            .iter()
            .map(|r| Vector::constants(graph, r.as_ref()))
            .collect();
        Matrix::from_rows(&rows)
    }

    /// Number of rows.
    pub fn nrows(&self) -> usize {
        self.rows
    }

    /// Number of columns.
    pub fn ncols(&self) -> usize {
        self.cols
    }

    /// `(rows, cols)`.
    pub fn shape(&self) -> (usize, usize) {
        (self.rows, self.cols)
    }

    fn shape_str(&self) -> String {
        format!("{}x{}", self.rows, self.cols)
    }

    /// The entry at `(i, j)`, or `None` outside the matrix.
    pub fn get(&self, i: usize, j: usize) -> Option<Expr<'g>> {
        (i < self.rows && j < self.cols).then(|| self.data[i * self.cols + j])
    }

    /// The entries row by row.
    pub fn as_row_major(&self) -> &[Expr<'g>] {
        &self.data
    }

    /// Row `i`.
    ///
    /// # Panics
    /// If `i` is out of range.
    pub fn row(&self, i: usize) -> Vector<'g> {
        self.data[i * self.cols..(i + 1) * self.cols]
            .iter()
            .copied()
            .collect()
    }

    /// Column `j`.
    ///
    /// # Panics
    /// If `j` is out of range.
    pub fn col(&self, j: usize) -> Vector<'g> {
        assert!(j < self.cols, "column {j} of a {} matrix", self.shape_str());
        (0..self.rows)
            .map(|i| self.data[i * self.cols + j])
            .collect()
    }

    /// The transpose.
    pub fn transpose(&self) -> Matrix<'g> {
        let mut data = Vec::with_capacity(self.data.len());
        for j in 0..self.cols {
            for i in 0..self.rows {
                data.push(self.data[i * self.cols + j]);
            }
        }
        Matrix {
            rows: self.cols,
            cols: self.rows,
            data,
        }
    }

    /// Matrix-vector product `M v`.
    ///
    /// # Errors
    /// [`DslError::DimensionMismatch`] unless `v` has `ncols` entries;
    /// [`DslError::Empty`] if the matrix has no columns.
    pub fn matvec(&self, v: &[Expr<'g>]) -> Result<Vector<'g>> {
        if v.len() != self.cols {
            return Err(mismatch(
                "matvec",
                format!(
                    "a vector of length {} for a {} matrix",
                    self.cols,
                    self.shape_str()
                ),
                format!("length {}", v.len()),
            ));
        }
        (0..self.rows)
            .map(|i| dot(&self.data[i * self.cols..(i + 1) * self.cols], v))
            .collect::<Result<Vector<'g>>>()
            .map_err(|_| DslError::Empty { op: "matvec" })
    }

    /// Matrix product `self * other`.
    ///
    /// # Errors
    /// [`DslError::DimensionMismatch`] unless `other` has `ncols` rows;
    /// [`DslError::Empty`] if the inner dimension is 0.
    pub fn matmul(&self, other: &Matrix<'g>) -> Result<Matrix<'g>> {
        if self.cols != other.rows {
            return Err(mismatch(
                "matmul",
                format!("a right operand with {} rows", self.cols),
                format!("{} times {}", self.shape_str(), other.shape_str()),
            ));
        }
        if self.cols == 0 {
            return Err(DslError::Empty { op: "matmul" });
        }
        let mut data = Vec::with_capacity(self.rows * other.cols);
        for i in 0..self.rows {
            for j in 0..other.cols {
                let terms = (0..self.cols)
                    .map(|k| self.data[i * self.cols + k] * other.data[k * other.cols + j]);
                data.push(sum(terms).ok_or(DslError::Empty { op: "matmul" })?);
            }
        }
        Ok(Matrix {
            rows: self.rows,
            cols: other.cols,
            data,
        })
    }

    fn zip_with(
        &self,
        other: &Matrix<'g>,
        op: &'static str,
        f: impl Fn(Expr<'g>, Expr<'g>) -> Expr<'g>,
    ) -> Result<Matrix<'g>> {
        if self.shape() != other.shape() {
            return Err(mismatch(
                op,
                format!("two matrices of shape {}", self.shape_str()),
                format!("{} and {}", self.shape_str(), other.shape_str()),
            ));
        }
        Ok(Matrix {
            rows: self.rows,
            cols: self.cols,
            data: self
                .data
                .iter()
                .zip(&other.data)
                .map(|(&a, &b)| f(a, b))
                .collect(),
        })
    }

    /// Entry-wise sum.
    ///
    /// # Errors
    /// [`DslError::DimensionMismatch`] if the shapes differ.
    pub fn add(&self, other: &Matrix<'g>) -> Result<Matrix<'g>> {
        self.zip_with(other, "matrix add", |a, b| a + b)
    }

    /// Entry-wise difference.
    ///
    /// # Errors
    /// [`DslError::DimensionMismatch`] if the shapes differ.
    pub fn sub(&self, other: &Matrix<'g>) -> Result<Matrix<'g>> {
        self.zip_with(other, "matrix sub", |a, b| a - b)
    }

    /// Every entry times `s`.
    pub fn scale(&self, s: impl IntoExpr<'g> + Copy) -> Matrix<'g> {
        Matrix {
            rows: self.rows,
            cols: self.cols,
            data: self
                .data
                .iter()
                .map(|&a| a * s.into_expr(a.graph))
                .collect(),
        }
    }
}

impl<'g> Index<(usize, usize)> for Matrix<'g> {
    type Output = Expr<'g>;
    /// # Panics
    /// Outside the matrix.
    fn index(&self, (i, j): (usize, usize)) -> &Expr<'g> {
        assert!(
            i < self.rows && j < self.cols,
            "index ({i}, {j}) outside a {} matrix",
            self.shape_str()
        );
        &self.data[i * self.cols + j]
    }
}

/// Skew-symmetric (hat) matrix of a 3-vector: `skew(a) b = a x b`.
///
/// # Errors
/// [`DslError::DimensionMismatch`] unless `a` has length 3.
pub fn skew<'g>(a: &[Expr<'g>]) -> Result<Matrix<'g>> {
    expect_len("skew", a, 3, "a vector")?;
    let z = a[0].graph.zero();
    Matrix::from_row_major(3, 3, vec![z, -a[2], a[1], a[2], z, -a[0], -a[1], a[0], z])
}

/// The inverse of [`skew`] ("vee"): `(m[2][1], m[0][2], m[1][0])`. For a matrix that is not
/// skew-symmetric this reads those three entries; the paper's attitude error
/// `e_R = 1/2 (Rd' R - R' Rd)^vee` applies it to a skew-symmetric difference.
///
/// # Errors
/// [`DslError::DimensionMismatch`] unless `m` is 3x3.
pub fn vee<'g>(m: &Matrix<'g>) -> Result<Vector<'g>> {
    if m.shape() != (3, 3) {
        return Err(mismatch(
            "vee",
            "a 3x3 matrix",
            format!("{}x{}", m.rows, m.cols),
        ));
    }
    Ok(Vector(vec![m[(2, 1)], m[(0, 2)], m[(1, 0)]]))
}

/// Hamilton quaternion product `p ⊗ q`, quaternions scalar first `(w, x, y, z)`.
///
/// # Errors
/// [`DslError::DimensionMismatch`] unless both have length 4.
pub fn quat_mul<'g>(p: &[Expr<'g>], q: &[Expr<'g>]) -> Result<Vector<'g>> {
    if p.len() != 4 || q.len() != 4 {
        return Err(mismatch(
            "quat_mul",
            "two quaternions (w, x, y, z) of length 4",
            format!("lengths {} and {}", p.len(), q.len()),
        ));
    }
    let (pw, px, py, pz) = (p[0], p[1], p[2], p[3]);
    let (qw, qx, qy, qz) = (q[0], q[1], q[2], q[3]);
    Ok(Vector(vec![
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    ]))
}

/// Conjugate `(w, -x, -y, -z)`.
///
/// # Errors
/// [`DslError::DimensionMismatch`] unless `q` has length 4.
pub fn quat_conj<'g>(q: &[Expr<'g>]) -> Result<Vector<'g>> {
    expect_len("quat_conj", q, 4, "a quaternion (w, x, y, z)")?;
    Ok(Vector(vec![q[0], -q[1], -q[2], -q[3]]))
}

/// Rotation matrix (body to world) of a unit quaternion `(w, x, y, z)`.
///
/// Uses the unit-quaternion formula (entries like `1 - 2(y^2 + z^2)`), as QR-bench and most
/// NMPC models do; the quaternion is not normalized.
///
/// # Errors
/// [`DslError::DimensionMismatch`] unless `q` has length 4.
pub fn quat_to_rotation<'g>(q: &[Expr<'g>]) -> Result<Matrix<'g>> {
    expect_len("quat_to_rotation", q, 4, "a quaternion (w, x, y, z)")?;
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    let two = 2.0;
    Matrix::from_row_major(
        3,
        3,
        vec![
            1.0 - two * (y.square() + z.square()),
            two * (x * y - w * z),
            two * (x * z + w * y),
            two * (x * y + w * z),
            1.0 - two * (x.square() + z.square()),
            two * (y * z - w * x),
            two * (x * z - w * y),
            two * (y * z + w * x),
            1.0 - two * (x.square() + y.square()),
        ],
    )
}

/// Rotates the 3-vector `v` by the unit quaternion `q`: `R(q) v`.
///
/// # Errors
/// [`DslError::DimensionMismatch`] unless `q` has length 4 and `v` length 3.
pub fn quat_rotate<'g>(q: &[Expr<'g>], v: &[Expr<'g>]) -> Result<Vector<'g>> {
    expect_len("quat_rotate", v, 3, "a vector")?;
    quat_to_rotation(q)?.matvec(v)
}

/// Rotation about the x axis by `a` (roll).
pub fn rot_x<'g>(a: Expr<'g>) -> Matrix<'g> {
    let (g, c, s) = (a.graph, a.cos(), a.sin());
    let (o, z) = (g.one(), g.zero());
    Matrix {
        rows: 3,
        cols: 3,
        data: vec![o, z, z, z, c, -s, z, s, c],
    }
}

/// Rotation about the y axis by `a` (pitch).
pub fn rot_y<'g>(a: Expr<'g>) -> Matrix<'g> {
    let (g, c, s) = (a.graph, a.cos(), a.sin());
    let (o, z) = (g.one(), g.zero());
    Matrix {
        rows: 3,
        cols: 3,
        data: vec![c, z, s, z, o, z, -s, z, c],
    }
}

/// Rotation about the z axis by `a` (yaw).
pub fn rot_z<'g>(a: Expr<'g>) -> Matrix<'g> {
    let (g, c, s) = (a.graph, a.cos(), a.sin());
    let (o, z) = (g.one(), g.zero());
    Matrix {
        rows: 3,
        cols: 3,
        data: vec![c, -s, z, s, c, z, z, z, o],
    }
}

/// Body-to-world rotation from Z-Y-X Euler angles: `R = Rz(yaw) Ry(pitch) Rx(roll)`, the
/// paper's `R = Rz(psi) Ry(phi) Rx(theta)` with theta = roll, phi = pitch, psi = yaw.
pub fn euler_zyx_to_rotation<'g>(roll: Expr<'g>, pitch: Expr<'g>, yaw: Expr<'g>) -> Matrix<'g> {
    let rz_ry = rot_z(yaw)
        .matmul(&rot_y(pitch))
        .unwrap_or_else(|_| unreachable!("3x3 times 3x3"));
    rz_ry
        .matmul(&rot_x(roll))
        .unwrap_or_else(|_| unreachable!("3x3 times 3x3"))
}
