//! RK shape functions and their first derivatives: the generic point kernel and the f64 hot path.

// Dense small-matrix kernels read most clearly with index loops.
#![allow(clippy::needless_range_loop)]

use super::kernel::{covers, tensor_kernel_with, KernelFunction};
use super::search::SupportGrid;
use super::{Basis, MeshfreeError};
use crate::scalar::Real;
use rayon::prelude::*;

/// Default limit on the condition estimate of the equilibrated moment matrix. Beyond it the
/// derivatives would keep fewer than about 4 significant digits in f64, and in practice such a
/// matrix comes from a degenerate (near-collinear) or nearly empty neighbourhood.
pub const DEFAULT_MAX_CONDITION: f64 = 1e12;

/// Basis terms `H(d)` and their derivatives with respect to `x` (where `d = (x − x_I)/s`), for the
/// basis of size `N` (3: linear, 6: quadratic).
#[inline(always)]
fn basis_terms<T: Real, const N: usize>(d: [T; 2], inv_s: [T; 2]) -> [[T; N]; 3] {
    let z = T::zero();
    let one = T::one();
    let mut h = [z; N];
    let mut hu = [z; N];
    let mut hv = [z; N];
    h[0] = one;
    h[1] = d[0];
    h[2] = d[1];
    hu[1] = inv_s[0];
    hv[2] = inv_s[1];
    if N >= 6 {
        h[3] = d[0] * d[0];
        h[4] = d[0] * d[1];
        h[5] = d[1] * d[1];
        hu[3] = d[0] * inv_s[0] * 2.0;
        hu[4] = d[1] * inv_s[0];
        hv[4] = d[0] * inv_s[1];
        hv[5] = d[1] * inv_s[1] * 2.0;
    }
    if N >= 10 {
        let (a, b) = (d[0], d[1]);
        h[6] = a * a * a;
        h[7] = a * a * b;
        h[8] = a * b * b;
        h[9] = b * b * b;
        hu[6] = a * a * inv_s[0] * 3.0;
        hu[7] = a * b * inv_s[0] * 2.0;
        hu[8] = b * b * inv_s[0];
        hv[7] = a * a * inv_s[1];
        hv[8] = a * b * inv_s[1] * 2.0;
        hv[9] = b * b * inv_s[1] * 3.0;
    }
    [h, hu, hv]
}

#[inline(always)]
fn dot<T: Real, const N: usize>(a: &[T; N], b: &[T; N]) -> T {
    let mut s = a[0] * b[0];
    for k in 1..N {
        s += a[k] * b[k];
    }
    s
}

/// Cholesky factor of the equilibrated moment matrix `D M D`, `D = diag(dscale)`.
struct Factor<T, const N: usize> {
    l: [[T; N]; N],
    dscale: [T; N],
}

impl<T: Real, const N: usize> Factor<T, N> {
    /// Factor a symmetric matrix (lower triangle read). Returns the condition estimate
    /// `(max L_ii / min L_ii)²` (a lower bound of the condition number of the equilibrated matrix)
    /// as the error when a pivot is not positive or the estimate exceeds `limit`.
    fn new(m: &[[T; N]; N], limit: f64) -> Result<Self, f64> {
        let mut dscale = [T::zero(); N];
        for k in 0..N {
            let d = m[k][k].value();
            if d.is_nan() || d <= 0.0 {
                return Err(f64::INFINITY);
            }
            // A constant scaling: Ψ does not depend on it (see the module documentation).
            dscale[k] = T::cst(1.0 / d.sqrt());
        }
        let mut l = [[T::zero(); N]; N];
        let (mut pmin, mut pmax) = (f64::INFINITY, 0.0_f64);
        for j in 0..N {
            let mut s = m[j][j] * dscale[j] * dscale[j];
            for k in 0..j {
                s -= l[j][k] * l[j][k];
            }
            let sv = s.value();
            if sv.is_nan() || sv <= 0.0 {
                return Err(f64::INFINITY);
            }
            let ljj = s.sqrt();
            let p = ljj.value();
            pmin = pmin.min(p);
            pmax = pmax.max(p);
            l[j][j] = ljj;
            for i in j + 1..N {
                let mut s = m[i][j] * dscale[i] * dscale[j];
                for k in 0..j {
                    s -= l[i][k] * l[j][k];
                }
                l[i][j] = s / ljj;
            }
        }
        let cond = (pmax / pmin) * (pmax / pmin);
        if cond.is_nan() || cond > limit {
            return Err(cond);
        }
        Ok(Factor { l, dscale })
    }

    /// `M⁻¹ r`.
    fn solve(&self, r: &[T; N]) -> [T; N] {
        let mut y = [T::zero(); N];
        for i in 0..N {
            let mut s = r[i] * self.dscale[i];
            for k in 0..i {
                s -= self.l[i][k] * y[k];
            }
            y[i] = s / self.l[i][i];
        }
        for i in (0..N).rev() {
            let mut s = y[i];
            for k in i + 1..N {
                s -= self.l[k][i] * y[k];
            }
            y[i] = s / self.l[i][i];
        }
        for i in 0..N {
            y[i] *= self.dscale[i];
        }
        y
    }
}

/// The RK kernel on an explicit neighbour list. `w` is scratch; `vals`/`grads` receive `Ψ_I` and
/// `∇Ψ_I` aligned with `nbrs`.
#[allow(clippy::too_many_arguments)]
fn rk_core<T: Real, const N: usize>(
    x: [T; 2],
    basis: Basis,
    kernel: KernelFunction,
    nbrs: &[usize],
    pts: &[[T; 2]],
    sup: &[[T; 2]],
    limit: f64,
    w: &mut Vec<[T; 3]>,
    vals: &mut Vec<T>,
    grads: &mut Vec<[T; 2]>,
) -> Result<(), MeshfreeError> {
    debug_assert_eq!(N, basis.size());
    vals.clear();
    grads.clear();
    w.clear();
    let point = [x[0].value(), x[1].value()];
    if nbrs.len() < N {
        return Err(MeshfreeError::TooFewNeighbours {
            point,
            neighbours: nbrs.len(),
            required: N,
            basis,
        });
    }
    // Basis scale: the largest support half-width among the neighbours, per axis (a constant).
    let mut s = [0.0_f64; 2];
    for &i in nbrs {
        s[0] = s[0].max(sup[i][0].value());
        s[1] = s[1].max(sup[i][1].value());
    }
    let inv_s = [T::cst(1.0 / s[0]), T::cst(1.0 / s[1])];

    let zero = T::zero();
    let mut m = [[zero; N]; N];
    let mut mu = [[zero; N]; N];
    let mut mv = [[zero; N]; N];
    for &i in nbrs {
        let d = [x[0] - pts[i][0], x[1] - pts[i][1]];
        let k = tensor_kernel_with(kernel, d, sup[i]);
        w.push(k);
        let [h, hu, hv] = basis_terms::<T, N>([d[0] * inv_s[0], d[1] * inv_s[1]], inv_s);
        for a in 0..N {
            let ha_phi = h[a] * k[0];
            let dha_u = hu[a] * k[0] + h[a] * k[1];
            let dha_v = hv[a] * k[0] + h[a] * k[2];
            for b in 0..=a {
                // ∂(H_a H_b φ) = (∂H_a φ + H_a ∂φ) H_b + H_a φ ∂H_b
                m[a][b] += ha_phi * h[b];
                mu[a][b] += dha_u * h[b] + ha_phi * hu[b];
                mv[a][b] += dha_v * h[b] + ha_phi * hv[b];
            }
        }
    }
    for a in 0..N {
        for b in a + 1..N {
            m[a][b] = m[b][a];
            mu[a][b] = mu[b][a];
            mv[a][b] = mv[b][a];
        }
    }
    let fac = Factor::new(&m, limit).map_err(|condition| MeshfreeError::IllConditioned {
        point,
        neighbours: nbrs.len(),
        condition,
        limit,
        basis,
    })?;
    // b = M⁻¹ H(0), ∂_j b = −M⁻¹ (∂_j M) b.
    let mut e1 = [zero; N];
    e1[0] = T::one();
    let b = fac.solve(&e1);
    let mut rbu = [zero; N];
    let mut rbv = [zero; N];
    for a in 0..N {
        rbu[a] = -dot(&mu[a], &b);
        rbv[a] = -dot(&mv[a], &b);
    }
    let bu = fac.solve(&rbu);
    let bv = fac.solve(&rbv);

    for (&i, k) in nbrs.iter().zip(w.iter()) {
        let d = [x[0] - pts[i][0], x[1] - pts[i][1]];
        let [h, hu, hv] = basis_terms::<T, N>([d[0] * inv_s[0], d[1] * inv_s[1]], inv_s);
        let c = dot(&b, &h);
        vals.push(c * k[0]);
        grads.push([
            (dot(&bu, &h) + dot(&b, &hu)) * k[0] + c * k[1],
            (dot(&bv, &h) + dot(&b, &hv)) * k[0] + c * k[2],
        ]);
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)]
fn rk_dispatch<T: Real>(
    x: [T; 2],
    basis: Basis,
    kernel: KernelFunction,
    nbrs: &[usize],
    pts: &[[T; 2]],
    sup: &[[T; 2]],
    limit: f64,
    w: &mut Vec<[T; 3]>,
    vals: &mut Vec<T>,
    grads: &mut Vec<[T; 2]>,
) -> Result<(), MeshfreeError> {
    match basis {
        Basis::Linear => rk_core::<T, 3>(x, basis, kernel, nbrs, pts, sup, limit, w, vals, grads),
        Basis::Quadratic => {
            rk_core::<T, 6>(x, basis, kernel, nbrs, pts, sup, limit, w, vals, grads)
        }
        Basis::Cubic => rk_core::<T, 10>(x, basis, kernel, nbrs, pts, sup, limit, w, vals, grads),
    }
}

fn check_lengths<T>(particles: &[[T; 2]], supports: &[[T; 2]]) -> Result<(), MeshfreeError> {
    if particles.len() != supports.len() {
        return Err(MeshfreeError::InvalidInput(format!(
            "{} particles but {} supports",
            particles.len(),
            supports.len()
        )));
    }
    Ok(())
}

/// RK shape functions and gradients of **every** particle at `x` (zero for particles whose support
/// does not cover `x`), generic over the scalar: evaluation point, particle coordinates and support
/// half-widths may all be dual numbers. The neighbours are found by brute force on the real parts
/// (O(number of particles)); use [`rk_shape_functions_sparse`] with a [`SupportGrid`] query for
/// large particle sets.
///
/// Returns `(Ψ_I, [∂Ψ_I/∂u, ∂Ψ_I/∂v])`, both of length `particles.len()`.
pub fn rk_shape_functions<T: Real>(
    x: [T; 2],
    particles: &[[T; 2]],
    supports: &[[T; 2]],
    basis: Basis,
) -> Result<(Vec<T>, Vec<[T; 2]>), MeshfreeError> {
    check_lengths(particles, supports)?;
    let xv = [x[0].value(), x[1].value()];
    let nbrs: Vec<usize> = (0..particles.len())
        .filter(|&i| {
            let p = [particles[i][0].value(), particles[i][1].value()];
            let a = [supports[i][0].value(), supports[i][1].value()];
            covers(p, a, xv)
        })
        .collect();
    let (v, g) = rk_shape_functions_sparse(x, particles, supports, basis, &nbrs)?;
    let mut vals = vec![T::zero(); particles.len()];
    let mut grads = vec![[T::zero(); 2]; particles.len()];
    for (k, &i) in nbrs.iter().enumerate() {
        vals[i] = v[k];
        grads[i] = g[k];
    }
    Ok((vals, grads))
}

/// RK shape functions and gradients at `x` for the listed `neighbours` only (the particles whose
/// supports cover `x`, e.g. from [`SupportGrid::covering`]); results are aligned with
/// `neighbours`. Generic over the scalar like [`rk_shape_functions`]. Listing a particle that does
/// not cover `x` is harmless (its kernel is zero) but counts towards the neighbour minimum.
pub fn rk_shape_functions_sparse<T: Real>(
    x: [T; 2],
    particles: &[[T; 2]],
    supports: &[[T; 2]],
    basis: Basis,
    neighbours: &[usize],
) -> Result<(Vec<T>, Vec<[T; 2]>), MeshfreeError> {
    check_lengths(particles, supports)?;
    if let Some(&bad) = neighbours.iter().find(|&&i| i >= particles.len()) {
        return Err(MeshfreeError::InvalidInput(format!(
            "neighbour index {bad} out of range ({} particles)",
            particles.len()
        )));
    }
    let mut w = Vec::with_capacity(neighbours.len());
    let mut vals = Vec::with_capacity(neighbours.len());
    let mut grads = Vec::with_capacity(neighbours.len());
    rk_dispatch(
        x,
        basis,
        KernelFunction::CubicSpline,
        neighbours,
        particles,
        supports,
        DEFAULT_MAX_CONDITION,
        &mut w,
        &mut vals,
        &mut grads,
    )?;
    Ok((vals, grads))
}

/// Shape-function values and gradients at one point, for the particles covering it. Reused across
/// evaluations: the buffers keep their capacity, so the hot path does not allocate.
#[derive(Clone, Debug, Default)]
pub struct ShapeValues {
    neighbours: Vec<usize>,
    values: Vec<f64>,
    grads: Vec<[f64; 2]>,
    kernel: Vec<[f64; 3]>,
}

impl ShapeValues {
    /// Empty buffers.
    pub fn new() -> Self {
        Self::default()
    }
    /// Empty buffers with room for `n` neighbours.
    pub fn with_capacity(n: usize) -> Self {
        ShapeValues {
            neighbours: Vec::with_capacity(n),
            values: Vec::with_capacity(n),
            grads: Vec::with_capacity(n),
            kernel: Vec::with_capacity(n),
        }
    }
    /// Indices of the particles whose supports cover the point, ascending.
    pub fn neighbours(&self) -> &[usize] {
        &self.neighbours
    }
    /// `Ψ_I` aligned with [`neighbours`](Self::neighbours).
    pub fn values(&self) -> &[f64] {
        &self.values
    }
    /// `[∂Ψ_I/∂u, ∂Ψ_I/∂v]` aligned with [`neighbours`](Self::neighbours).
    pub fn gradients(&self) -> &[[f64; 2]] {
        &self.grads
    }
    /// Number of neighbours.
    pub fn len(&self) -> usize {
        self.neighbours.len()
    }
    /// No neighbours (also the state after a failed evaluation).
    pub fn is_empty(&self) -> bool {
        self.neighbours.is_empty()
    }
    /// `(I, Ψ_I, ∇Ψ_I)` for every neighbour.
    pub fn iter(&self) -> impl Iterator<Item = (usize, f64, [f64; 2])> + '_ {
        self.neighbours
            .iter()
            .zip(&self.values)
            .zip(&self.grads)
            .map(|((&i, &v), &g)| (i, v, g))
    }
    fn clear(&mut self) {
        self.neighbours.clear();
        self.values.clear();
        self.grads.clear();
    }
}

/// RK shape functions of a fixed particle set (f64 hot path): particles, supports, basis and the
/// neighbour-search grid, built once.
#[derive(Clone, Debug)]
pub struct ShapeFunctions {
    particles: Vec<[f64; 2]>,
    supports: Vec<[f64; 2]>,
    basis: Basis,
    kernel: KernelFunction,
    grid: SupportGrid,
    max_condition: f64,
}

impl ShapeFunctions {
    /// Build for `particles` with support half-widths `supports` (same length, positive, finite).
    pub fn new(
        particles: Vec<[f64; 2]>,
        supports: Vec<[f64; 2]>,
        basis: Basis,
    ) -> Result<Self, MeshfreeError> {
        let grid = SupportGrid::new(&particles, &supports)?;
        Ok(ShapeFunctions {
            particles,
            supports,
            basis,
            kernel: KernelFunction::default(),
            grid,
            max_condition: DEFAULT_MAX_CONDITION,
        })
    }

    /// Replace the kernel function (the cubic B-spline by default).
    pub fn with_kernel(mut self, kernel: KernelFunction) -> Self {
        self.kernel = kernel;
        self
    }

    /// Replace the limit on the moment-matrix condition estimate ([`DEFAULT_MAX_CONDITION`]).
    pub fn with_max_condition(mut self, limit: f64) -> Self {
        self.max_condition = limit;
        self
    }

    /// Particle coordinates.
    pub fn particles(&self) -> &[[f64; 2]] {
        &self.particles
    }
    /// Support half-widths `(a_u, a_v)` per particle.
    pub fn supports(&self) -> &[[f64; 2]] {
        &self.supports
    }
    /// The basis.
    pub fn basis(&self) -> Basis {
        self.basis
    }
    /// The kernel function.
    pub fn kernel(&self) -> KernelFunction {
        self.kernel
    }
    /// The neighbour-search grid.
    pub fn grid(&self) -> &SupportGrid {
        &self.grid
    }
    /// Number of particles.
    pub fn len(&self) -> usize {
        self.particles.len()
    }
    /// No particles.
    pub fn is_empty(&self) -> bool {
        self.particles.is_empty()
    }

    /// `Ψ_I(x)` and `∇Ψ_I(x)` for every particle covering `x`, written into `out` (previous contents
    /// replaced; on error `out` is left empty). Does not allocate once `out` has grown to the
    /// largest neighbourhood.
    pub fn evaluate(&self, x: [f64; 2], out: &mut ShapeValues) -> Result<(), MeshfreeError> {
        out.clear();
        self.grid.covering(x, &mut out.neighbours);
        let res = rk_dispatch(
            x,
            self.basis,
            self.kernel,
            &out.neighbours,
            &self.particles,
            &self.supports,
            self.max_condition,
            &mut out.kernel,
            &mut out.values,
            &mut out.grads,
        );
        if res.is_err() {
            out.clear();
        }
        res
    }

    /// Evaluate at many points in parallel (rayon); results in the order of `points`.
    pub fn evaluate_many(&self, points: &[[f64; 2]]) -> Result<Vec<ShapeValues>, MeshfreeError> {
        points
            .par_iter()
            .map(|&x| {
                let mut out = ShapeValues::new();
                self.evaluate(x, &mut out).map(|()| out)
            })
            .collect()
    }
}
