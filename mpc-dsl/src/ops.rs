//! The operation table: what each node kind computes.
//!
//! Numeric semantics are defined once here and shared by constant folding, the interpreter and
//! [`Program`](crate::Program) evaluation. Transcendental functions go through `libm`, the same
//! implementation generated `no_std` code calls, so host-side evaluation and generated code
//! agree bit for bit.

use core::fmt;

/// Operations with one operand.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum UnaryOp {
    /// `-x`
    Neg,
    /// `sqrt(x)`
    Sqrt,
    /// `sin(x)`
    Sin,
    /// `cos(x)`
    Cos,
    /// `tan(x)`
    Tan,
    /// `asin(x)`
    Asin,
    /// `acos(x)`
    Acos,
    /// `atan(x)`
    Atan,
    /// `exp(x)`
    Exp,
    /// Natural logarithm `ln(x)`.
    Log,
    /// `tanh(x)`
    Tanh,
    /// `|x|`
    Abs,
    /// `sign(x)`: -1, 0 or 1 (0 at 0 and for NaN). Its derivative is 0.
    Sign,
    /// Heaviside step: 1 for `x >= 0`, else 0. Its derivative is 0. Used by the derivatives
    /// of `min` and `max`.
    Step,
}

/// Operations with two operands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum BinaryOp {
    /// `a + b`
    Add,
    /// `a - b`
    Sub,
    /// `a * b`
    Mul,
    /// `a / b`
    Div,
    /// `a^b` with a real exponent.
    Pow,
    /// `atan2(a, b)`: the angle of the point `(b, a)`.
    Atan2,
    /// `min(a, b)`
    Min,
    /// `max(a, b)`
    Max,
}

impl UnaryOp {
    /// All unary operations, in declaration order.
    pub const ALL: [UnaryOp; 14] = [
        UnaryOp::Neg,
        UnaryOp::Sqrt,
        UnaryOp::Sin,
        UnaryOp::Cos,
        UnaryOp::Tan,
        UnaryOp::Asin,
        UnaryOp::Acos,
        UnaryOp::Atan,
        UnaryOp::Exp,
        UnaryOp::Log,
        UnaryOp::Tanh,
        UnaryOp::Abs,
        UnaryOp::Sign,
        UnaryOp::Step,
    ];

    /// Applies the operation to a number.
    #[inline]
    pub fn apply(self, x: f64) -> f64 {
        match self {
            UnaryOp::Neg => -x,
            UnaryOp::Sqrt => libm::sqrt(x),
            UnaryOp::Sin => libm::sin(x),
            UnaryOp::Cos => libm::cos(x),
            UnaryOp::Tan => libm::tan(x),
            UnaryOp::Asin => libm::asin(x),
            UnaryOp::Acos => libm::acos(x),
            UnaryOp::Atan => libm::atan(x),
            UnaryOp::Exp => libm::exp(x),
            UnaryOp::Log => libm::log(x),
            UnaryOp::Tanh => libm::tanh(x),
            UnaryOp::Abs => libm::fabs(x),
            UnaryOp::Sign => {
                if x > 0.0 {
                    1.0
                } else if x < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            }
            UnaryOp::Step => {
                if x >= 0.0 {
                    1.0
                } else {
                    0.0
                }
            }
        }
    }

    /// The function name used when printing (`neg` prints as a prefix minus).
    pub fn name(self) -> &'static str {
        match self {
            UnaryOp::Neg => "neg",
            UnaryOp::Sqrt => "sqrt",
            UnaryOp::Sin => "sin",
            UnaryOp::Cos => "cos",
            UnaryOp::Tan => "tan",
            UnaryOp::Asin => "asin",
            UnaryOp::Acos => "acos",
            UnaryOp::Atan => "atan",
            UnaryOp::Exp => "exp",
            UnaryOp::Log => "log",
            UnaryOp::Tanh => "tanh",
            UnaryOp::Abs => "abs",
            UnaryOp::Sign => "sign",
            UnaryOp::Step => "step",
        }
    }
}

impl BinaryOp {
    /// All binary operations, in declaration order.
    pub const ALL: [BinaryOp; 8] = [
        BinaryOp::Add,
        BinaryOp::Sub,
        BinaryOp::Mul,
        BinaryOp::Div,
        BinaryOp::Pow,
        BinaryOp::Atan2,
        BinaryOp::Min,
        BinaryOp::Max,
    ];

    /// Applies the operation to two numbers.
    #[inline]
    pub fn apply(self, a: f64, b: f64) -> f64 {
        match self {
            BinaryOp::Add => a + b,
            BinaryOp::Sub => a - b,
            BinaryOp::Mul => a * b,
            BinaryOp::Div => a / b,
            BinaryOp::Pow => libm::pow(a, b),
            BinaryOp::Atan2 => libm::atan2(a, b),
            BinaryOp::Min => libm::fmin(a, b),
            BinaryOp::Max => libm::fmax(a, b),
        }
    }

    /// Whether `a op b == b op a` exactly (in IEEE arithmetic too).
    pub fn is_commutative(self) -> bool {
        matches!(
            self,
            BinaryOp::Add | BinaryOp::Mul | BinaryOp::Min | BinaryOp::Max
        )
    }

    /// The infix symbol (`+`, `-`, `*`, `/`) or the function name (`pow`, `atan2`, ...).
    pub fn name(self) -> &'static str {
        match self {
            BinaryOp::Add => "+",
            BinaryOp::Sub => "-",
            BinaryOp::Mul => "*",
            BinaryOp::Div => "/",
            BinaryOp::Pow => "pow",
            BinaryOp::Atan2 => "atan2",
            BinaryOp::Min => "min",
            BinaryOp::Max => "max",
        }
    }

    /// Whether the operation prints as an infix operator.
    pub fn is_infix(self) -> bool {
        matches!(
            self,
            BinaryOp::Add | BinaryOp::Sub | BinaryOp::Mul | BinaryOp::Div
        )
    }
}

/// Integer power by repeated squaring, the evaluation rule of [`Expr::powi`](crate::Expr::powi).
///
/// Generated code uses the same sequence of multiplications, so results match bit for bit.
#[inline]
pub fn powi(x: f64, n: i32) -> f64 {
    let mut base = x;
    let mut e = n.unsigned_abs();
    let mut acc = 1.0;
    let mut first = true;
    while e > 0 {
        if e & 1 == 1 {
            acc = if first { base } else { acc * base };
            first = false;
        }
        e >>= 1;
        if e > 0 {
            base *= base;
        }
    }
    if n < 0 { 1.0 / acc } else { acc }
}

impl fmt::Display for UnaryOp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl fmt::Display for BinaryOp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn powi_matches_repeated_multiplication() {
        for &x in &[0.0, 1.5, -2.25, 3.0e10, -7.0e-3] {
            let mut p = 1.0;
            for n in 0..12 {
                let got = powi(x, n);
                assert!(
                    (got - p).abs() <= 1e-14 * p.abs().max(1e-300),
                    "x={x} n={n} got={got} want={p}"
                );
                let inv = powi(x, -n);
                if p != 0.0 {
                    assert!((inv - 1.0 / p).abs() <= 1e-14 * (1.0 / p).abs());
                }
                p *= x;
            }
        }
    }

    #[test]
    fn step_and_sign_at_zero() {
        assert_eq!(UnaryOp::Step.apply(0.0), 1.0);
        assert_eq!(UnaryOp::Step.apply(-1e-300), 0.0);
        assert_eq!(UnaryOp::Sign.apply(0.0), 0.0);
        assert_eq!(UnaryOp::Sign.apply(-3.0), -1.0);
        assert_eq!(UnaryOp::Sign.apply(f64::NAN), 0.0);
    }
}
