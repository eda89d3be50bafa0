//! Forward-mode dual numbers (value + one derivative) for the refractivity stage.
//!
//! In: the air state and its height derivatives as `Dual { value, deriv }` pairs. Out: the same
//! arithmetic carried through the Ciddor formula, so the derivative part of the result is dn/dh by
//! the chain rule, exact to rounding — no finite differences.
//!
//! Written by hand: the Ciddor formula needs only `+ − × ÷` on one tangent direction, and the
//! automatic-differentiation crates available are either general multi-variable frameworks far
//! larger than these few dozen lines or unmaintained; none is worth a dependency here.

use std::ops::{Add, Div, Mul, Neg, Sub};

/// A number with one derivative: `value + deriv·ε`, ε² = 0.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Dual {
    /// The value.
    pub value: f64,
    /// Its derivative with respect to the seeded variable (here: height, per metre).
    pub deriv: f64,
}

impl Dual {
    /// A variable with the given value and derivative.
    #[inline]
    pub const fn new(value: f64, deriv: f64) -> Self {
        Self { value, deriv }
    }

    /// A constant (derivative 0).
    #[inline]
    pub const fn constant(value: f64) -> Self {
        Self { value, deriv: 0.0 }
    }

    /// The square.
    #[inline]
    pub fn square(self) -> Self {
        self * self
    }
}

impl From<f64> for Dual {
    #[inline]
    fn from(value: f64) -> Self {
        Self::constant(value)
    }
}

impl Add for Dual {
    type Output = Dual;
    #[inline]
    fn add(self, o: Dual) -> Dual {
        Dual::new(self.value + o.value, self.deriv + o.deriv)
    }
}

impl Sub for Dual {
    type Output = Dual;
    #[inline]
    fn sub(self, o: Dual) -> Dual {
        Dual::new(self.value - o.value, self.deriv - o.deriv)
    }
}

impl Mul for Dual {
    type Output = Dual;
    #[inline]
    fn mul(self, o: Dual) -> Dual {
        Dual::new(
            self.value * o.value,
            self.deriv * o.value + self.value * o.deriv,
        )
    }
}

impl Div for Dual {
    type Output = Dual;
    #[inline]
    fn div(self, o: Dual) -> Dual {
        let q = self.value / o.value;
        Dual::new(q, (self.deriv - q * o.deriv) / o.value)
    }
}

impl Neg for Dual {
    type Output = Dual;
    #[inline]
    fn neg(self) -> Dual {
        Dual::new(-self.value, -self.deriv)
    }
}

impl Add<f64> for Dual {
    type Output = Dual;
    #[inline]
    fn add(self, o: f64) -> Dual {
        Dual::new(self.value + o, self.deriv)
    }
}

impl Sub<f64> for Dual {
    type Output = Dual;
    #[inline]
    fn sub(self, o: f64) -> Dual {
        Dual::new(self.value - o, self.deriv)
    }
}

impl Mul<f64> for Dual {
    type Output = Dual;
    #[inline]
    fn mul(self, o: f64) -> Dual {
        Dual::new(self.value * o, self.deriv * o)
    }
}

impl Div<f64> for Dual {
    type Output = Dual;
    #[inline]
    fn div(self, o: f64) -> Dual {
        Dual::new(self.value / o, self.deriv / o)
    }
}

impl Add<Dual> for f64 {
    type Output = Dual;
    #[inline]
    fn add(self, o: Dual) -> Dual {
        o + self
    }
}

impl Sub<Dual> for f64 {
    type Output = Dual;
    #[inline]
    fn sub(self, o: Dual) -> Dual {
        Dual::new(self - o.value, -o.deriv)
    }
}

impl Mul<Dual> for f64 {
    type Output = Dual;
    #[inline]
    fn mul(self, o: Dual) -> Dual {
        o * self
    }
}

impl Div<Dual> for f64 {
    type Output = Dual;
    #[inline]
    fn div(self, o: Dual) -> Dual {
        Dual::constant(self) / o
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f(x) = (3x² + 1)/(x − 5) · 2 − 1/x, checked against its hand-derived derivative.
    #[test]
    fn rational_function_derivative_matches_calculus() {
        for &x in &[0.3, 1.7, 2.0, 7.5, -3.0] {
            let d = Dual::new(x, 1.0);
            let f = (3.0 * d.square() + 1.0) / (d - 5.0) * 2.0 - 1.0 / d;
            let value = (3.0 * x * x + 1.0) / (x - 5.0) * 2.0 - 1.0 / x;
            let deriv = 2.0 * (6.0 * x * (x - 5.0) - (3.0 * x * x + 1.0)) / (x - 5.0).powi(2)
                + 1.0 / (x * x);
            assert!((f.value - value).abs() <= 1e-13 * value.abs().max(1.0));
            assert!(
                (f.deriv - deriv).abs() <= 1e-13 * deriv.abs().max(1.0),
                "{x}"
            );
        }
    }

    #[test]
    fn constants_have_no_derivative_and_negation_flips() {
        let c = Dual::from(4.0);
        assert_eq!((c * c + c / 2.0 - c).deriv, 0.0);
        assert_eq!(-Dual::new(1.0, 2.0), Dual::new(-1.0, -2.0));
    }
}
