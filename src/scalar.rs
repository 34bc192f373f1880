//! The one scalar trait every point kernel is generic over.
//!
//! `f64` (analysis), [`num_dual::Dual64`] (one design direction) and
//! [`num_dual::DualSVec64`] (several design directions in one pass) all satisfy [`Real`], so the
//! same kernel code yields values, dual-number reference derivatives and finite differences.

use num_dual::DualNum;

/// Scalar type of every kernel: a real number or a first-order dual number over `f64`.
///
/// Write generic arithmetic as `x * 2.0` (scalar on the right) and build constants with
/// [`Real::cst`]. The real part is read with [`Real::value`].
pub trait Real:
    DualNum<Primitive = f64> + nalgebra::RealField + Copy + Send + Sync + std::fmt::Debug
{
    /// A constant (derivative part zero).
    #[inline]
    fn cst(x: f64) -> Self {
        Self::from(x)
    }
    /// The real (value) part.
    #[inline]
    fn value(&self) -> f64 {
        num_dual::DualStruct::re(self)
    }
}

impl<T> Real for T where
    T: DualNum<Primitive = f64> + nalgebra::RealField + Copy + Send + Sync + std::fmt::Debug
{
}

/// First-order dual number in one direction (re-exported for convenience).
pub type Dual = num_dual::Dual64;
/// First-order dual number in `N` directions at once.
pub type DualN<const N: usize> = num_dual::DualSVec64<N>;

/// The derivative parts of an `N`-direction dual number as an array.
pub fn dual_parts<const N: usize>(x: &DualN<N>) -> [f64; N] {
    let v = x.eps.unwrap_generic(nalgebra::Const::<N>, nalgebra::U1);
    let mut out = [0.0; N];
    for (o, e) in out.iter_mut().zip(v.iter()) {
        *o = *e;
    }
    out
}

/// Seed: a dual number with value `x` and unit derivative in direction `k` of `N`.
pub fn seed<const N: usize>(x: f64, k: usize) -> DualN<N> {
    DualN::<N>::from_re(x).derivative(k)
}

/// A dual scalar that carries the derivatives of `DIRECTIONS` design variables.
pub trait DesignDual: Real {
    /// Number of directions per value.
    const DIRECTIONS: usize;
    /// The value `x` with derivative parts `parts` (length [`Self::DIRECTIONS`]).
    fn from_parts(x: f64, parts: &[f64]) -> Self;
    /// Derivative part `k`.
    fn part(&self, k: usize) -> f64;
}

impl DesignDual for num_dual::Dual64 {
    const DIRECTIONS: usize = 1;
    fn from_parts(x: f64, parts: &[f64]) -> Self {
        num_dual::Dual64::new(x, parts[0])
    }
    fn part(&self, k: usize) -> f64 {
        debug_assert_eq!(k, 0);
        self.eps
    }
}

impl<const N: usize> DesignDual for num_dual::DualSVec64<N> {
    const DIRECTIONS: usize = N;
    fn from_parts(x: f64, parts: &[f64]) -> Self {
        if parts.iter().all(|p| *p == 0.0) {
            // No derivative stored: constants stay cheap in num-dual's arithmetic.
            num_dual::DualSVec64::new(x, num_dual::Derivative::none())
        } else {
            num_dual::DualSVec64::new(
                x,
                num_dual::Derivative::some(nalgebra::SVector::<f64, N>::from_column_slice(parts)),
            )
        }
    }
    fn part(&self, k: usize) -> f64 {
        self.eps.0.as_ref().map_or(0.0, |v| v[k])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Matrix3;

    fn kernel<T: Real>(x: T) -> T {
        let m = Matrix3::new(
            x,
            T::cst(1.0),
            T::zero(),
            T::zero(),
            x * 2.0,
            T::zero(),
            T::zero(),
            T::zero(),
            T::one(),
        );
        let inv = m.try_inverse().expect("invertible");
        inv[(0, 0)] + x.sqrt() * 3.0
    }

    #[test]
    fn f64_dual_and_vector_dual_pass_through_one_kernel() {
        let x = 2.0;
        let f = kernel(x);
        let d = kernel(Dual::from_re(x).derivative());
        let v = kernel(seed::<3>(x, 1));
        assert_eq!(f, d.re);
        assert_eq!(f, v.re);
        // d/dx (1/x + 3 sqrt x) = -1/x^2 + 1.5/sqrt(x); exact to round-off.
        let exact = -1.0 / (x * x) + 1.5 / x.sqrt();
        assert!((d.eps - exact).abs() <= 1e-15 * exact.abs().max(1.0));
        assert_eq!(dual_parts(&v), [0.0, d.eps, 0.0]);
        assert_eq!(v.value(), f);
    }
}
