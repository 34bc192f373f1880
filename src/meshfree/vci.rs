//! Variationally consistent integration (VCI) of RK Galerkin weak forms on a rectangular parameter
//! domain: corrected **test**-function gradients at the quadrature points, so that the discrete
//! divergence theorem holds for every test function (Chen, Hillman & Rüter 2013, "An arbitrary
//! order variationally consistent integration for Galerkin meshfree methods", IJNME 95:387). The
//! trial functions keep their RK gradients (a Petrov–Galerkin form). Derivation, measurements and
//! the recommended set-up are in `docs/integration.md`.
//!
//! **Why.** The Galerkin equations of a second-order problem contain `∫_Ω ∇Ψ_I · σ dΩ`. If the exact
//! solution has a stress `σ` of polynomial degree `n − 1` (the `n`-th order patch test) and the
//! loads are integrated by the same rules, the discrete equations are satisfied by it exactly if
//! and only if the quadrature satisfies, for every particle `I`, direction `α` and polynomial `p`
//! of degree `≤ n − 1`,
//!
//! ```text
//! Σ_q w_q [Ψ̃_I,α(x_q) p(x_q) + Ψ_I(x_q) p,α(x_q)] = ∮_∂Ω Ψ_I p n_α ds          (integration constraint)
//! ```
//!
//! the discrete form of `∫_Ω (Ψ_I p),α dΩ = ∮ Ψ_I p n_α ds`. Gauss quadrature of RK functions does
//! not satisfy it (the functions are rational, with kernel breakpoints inside the cells), which is
//! why plain Gauss fails the patch test on irregular particles.
//!
//! **The correction.** With a per-particle polynomial basis `p^I(x) = [1, (x − x_I)/a_I1,
//! (y − y_I)/a_I2]` (centred and scaled by the support for conditioning: the constraint is linear
//! in `p`, so any basis of the same space gives the same conditions), the test gradient is
//!
//! ```text
//! Ψ̃_I,α(x_q) = Ψ_I,α(x_q) + Σ_j c_Iαj p^I_j(x_q)        at the points q of I's support
//! ```
//!
//! with `j` over `{1}` ([`VciOrder::First`]: a constant correction, linear patch test) or over all
//! three terms ([`VciOrder::Second`]: a linear correction, quadratic patch test). Inserting it into
//! the constraint for `p = p^I_k` gives a small moment system per particle and direction,
//!
//! ```text
//! A_I c_Iα = −e_Iα,   A_I,jk = Σ_{q ∈ supp I} w_q p^I_j(x_q) p^I_k(x_q),
//! e_Iαk = Σ_q w_q [Ψ_I,α p^I_k + Ψ_I p^I_k,α](x_q) − ∮ Ψ_I p^I_k n_α ds,
//! ```
//!
//! `e` being the defect of the plain RK gradients. `A_I` (1×1 or 3×3) is the same for both
//! directions. The boundary integrals use a 1-D Gauss rule on each edge ([`BoundaryRule`]); the
//! constraint then holds to round-off *with that rule*, so boundary loads of a patch test must use
//! it too (or a rule of the same accuracy, see [`BoundaryRule::breakpoint_aligned`]).
//!
//! **Coupling.** Computed particle by particle ([`VciCoupling::PerParticle`]), the corrections
//! break the pointwise partition of nullity `Σ_I Ψ̃_I,α(x_q) = 0`, so a rigid test translation has
//! a test strain at the quadrature points. On a thin bending-dominated shell (the pinched
//! hemisphere, R/t = 250) that made the solution 4-6 % too flexible. [`VciCoupling::PartitionOfNullity`]
//! subtracts at each point the mean correction of its neighbours and solves for the coefficients
//! of all particles together, so both the integration constraints and the partition of nullity
//! hold (docs/integration.md §2.4, §4.8).
//!
//! Particles outside the domain (mirror images for symmetry planes) are just more shape
//! functions: they are corrected like the others. A particle whose support contains too few
//! quadrature points for the requested order (e.g. an image whose support reaches only a thin
//! strip of the domain) is corrected to the highest order its moment matrix allows
//! ([`VciCorrection::achieved`], [`VciCorrection::degraded`]).

// Small dense moment systems read most clearly with index loops.
#![allow(clippy::needless_range_loop)]

use super::particles::ParamBox;
use super::quadrature::{gauss_legendre, CellQuadrature, QuadratureError};
use super::{MeshfreeError, ShapeFunctions, ShapeValues};
use std::fmt;

/// Limit on the condition estimate of a particle's (equilibrated) moment matrix `A_I`. Beyond it
/// the correction would amplify round-off of the defect by more than about 1e8 (losing half the
/// digits) and the corrected gradients would become large: such a particle is corrected to the
/// next lower order instead, and reported.
pub const VCI_MAX_CONDITION: f64 = 1e8;

/// Order of the variationally consistent correction.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum VciOrder {
    /// No correction: test gradients equal the RK gradients.
    Off,
    /// Constant correction per particle: the constraint for `p = 1` (linear patch test,
    /// constant stress).
    First,
    /// Linear correction per particle: the constraints for `p ∈ {1, x, y}` (quadratic patch
    /// test, linear stress).
    Second,
}

impl VciOrder {
    /// Number of constraints (and correction coefficients) per particle and direction: 0, 1, 3.
    pub fn terms(self) -> usize {
        match self {
            VciOrder::Off => 0,
            VciOrder::First => 1,
            VciOrder::Second => 3,
        }
    }
}

impl fmt::Display for VciOrder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            VciOrder::Off => "off",
            VciOrder::First => "first order (constant correction)",
            VciOrder::Second => "second order (linear correction)",
        })
    }
}

/// Errors of the VCI construction; each names the offending field, its value and what was
/// expected.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum VciError {
    /// Invalid input.
    #[error("VCI: {field} = {value}: expected {expected}")]
    InvalidInput {
        /// Which input.
        field: String,
        /// Its value.
        value: String,
        /// What was expected.
        expected: &'static str,
    },
    /// The RK functions could not be evaluated at a boundary point.
    #[error("VCI boundary integral: {0}")]
    Shape(#[from] MeshfreeError),
    /// The 1-D Gauss rule could not be built.
    #[error("VCI boundary rule: {0}")]
    Quadrature(#[from] QuadratureError),
}

fn invalid(field: impl Into<String>, value: impl fmt::Display, expected: &'static str) -> VciError {
    VciError::InvalidInput {
        field: field.into(),
        value: value.to_string(),
        expected,
    }
}

/// The in-plane quadrature as VCI sees it: points, parameter-domain weights and, at each point,
/// the RK functions `(I, Ψ_I, ∇Ψ_I)` of the particles covering it (the **trial** gradients: a
/// correction is always computed from them, never on top of an earlier one).
pub trait QuadratureShapes {
    /// Number of points.
    fn n_points(&self) -> usize;
    /// `(x_q, w_q)`.
    fn point(&self, k: usize) -> ([f64; 2], f64);
    /// Call `f(I, Ψ_I, ∇Ψ_I)` for every particle covering point `k`.
    fn for_each_shape(&self, k: usize, f: &mut dyn FnMut(usize, f64, [f64; 2]));
}

/// A cell quadrature with the RK functions evaluated at its points: the plain implementation of
/// [`QuadratureShapes`].
#[derive(Clone, Debug)]
pub struct ShapeTable {
    /// Points.
    pub points: Vec<[f64; 2]>,
    /// Parameter-domain weights.
    pub weights: Vec<f64>,
    /// RK functions at each point.
    pub shapes: Vec<ShapeValues>,
}

impl ShapeTable {
    /// Evaluate `sf` at every point of `q` (in parallel).
    pub fn new(sf: &ShapeFunctions, q: &CellQuadrature) -> Result<Self, MeshfreeError> {
        Ok(ShapeTable {
            points: q.points().to_vec(),
            weights: q.weights().to_vec(),
            shapes: sf.evaluate_many(q.points())?,
        })
    }
}

impl QuadratureShapes for ShapeTable {
    fn n_points(&self) -> usize {
        self.points.len()
    }
    fn point(&self, k: usize) -> ([f64; 2], f64) {
        (self.points[k], self.weights[k])
    }
    fn for_each_shape(&self, k: usize, f: &mut dyn FnMut(usize, f64, [f64; 2])) {
        for (i, v, g) in self.shapes[k].iter() {
            f(i, v, g);
        }
    }
}

/// One point of a boundary rule.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BoundaryPoint {
    /// Position on `∂Ω`.
    pub x: [f64; 2],
    /// Weight (parameter-domain arc length).
    pub weight: f64,
    /// Outward unit normal of the edge.
    pub normal: [f64; 2],
}

/// The four edges of the box: `(fixed axis, side (0 = lo, 1 = hi), outward normal)`, in the order
/// v = lo, u = hi, v = hi, u = lo.
const EDGES: [(usize, usize, [f64; 2]); 4] = [
    (1, 0, [0.0, -1.0]),
    (0, 1, [1.0, 0.0]),
    (1, 1, [0.0, 1.0]),
    (0, 0, [-1.0, 0.0]),
];

/// A 1-D Gauss rule on each edge of a rectangular parameter domain, for the contour integrals
/// `∮ Ψ_I p n_α ds` of the integration constraint (and for boundary loads).
#[derive(Clone, Debug, PartialEq)]
pub struct BoundaryRule {
    domain: ParamBox,
    points: Vec<BoundaryPoint>,
}

fn check_box(domain: &ParamBox) -> Result<(), VciError> {
    for (k, axis) in ["u", "v"].into_iter().enumerate() {
        let (lo, hi) = (domain.lo[k], domain.hi[k]);
        if !(lo.is_finite() && hi.is_finite() && hi > lo) {
            return Err(invalid(
                format!("domain along {axis}"),
                format!("[{lo}, {hi}]"),
                "a finite, non-empty interval",
            ));
        }
    }
    Ok(())
}

impl BoundaryRule {
    /// Gauss rule with `points_per_segment` points (`1..=10`) on each segment between
    /// consecutive `breaks` of each edge. `breaks[e]` are interior break coordinates along edge
    /// `e` (order: v = lo, u = hi, v = hi, u = lo; the running coordinate is u on the first and
    /// third, v on the others); values outside the open edge are ignored, near-duplicates (closer
    /// than 1e-12 of the edge length) merged.
    pub fn with_breaks(
        domain: ParamBox,
        breaks: [Vec<f64>; 4],
        points_per_segment: usize,
    ) -> Result<Self, VciError> {
        check_box(&domain)?;
        let rule = gauss_legendre(points_per_segment)?;
        let mut points = Vec::new();
        for ((fixed, side, normal), br) in EDGES.into_iter().zip(breaks) {
            let run = 1 - fixed;
            let c = if side == 0 {
                domain.lo[fixed]
            } else {
                domain.hi[fixed]
            };
            let (lo, hi) = (domain.lo[run], domain.hi[run]);
            let tol = 1e-12 * (hi - lo);
            let mut b: Vec<f64> = br
                .into_iter()
                .filter(|&x| x.is_finite() && x > lo + tol && x < hi - tol)
                .collect();
            b.sort_by(f64::total_cmp);
            let mut cuts = vec![lo];
            for x in b {
                if x - cuts[cuts.len() - 1] > tol {
                    cuts.push(x);
                }
            }
            cuts.push(hi);
            for s in cuts.windows(2) {
                let (nodes, weights) = rule.mapped(s[0], s[1]);
                for (y, w) in nodes.into_iter().zip(weights) {
                    let mut x = [0.0; 2];
                    x[fixed] = c;
                    x[run] = y;
                    points.push(BoundaryPoint {
                        x,
                        weight: w,
                        normal,
                    });
                }
            }
        }
        Ok(BoundaryRule { domain, points })
    }

    /// Each edge split into equal segments, `segments[0]` along u (edges v = lo, hi) and
    /// `segments[1]` along v, with `points_per_segment` Gauss points each (e.g. aligned with the
    /// background cells).
    pub fn uniform(
        domain: ParamBox,
        segments: [usize; 2],
        points_per_segment: usize,
    ) -> Result<Self, VciError> {
        check_box(&domain)?;
        for (k, &n) in segments.iter().enumerate() {
            if n == 0 {
                return Err(invalid(format!("segments[{k}]"), n, "at least 1"));
            }
        }
        let cuts = |k: usize| -> Vec<f64> {
            let (lo, hi) = (domain.lo[k], domain.hi[k]);
            (1..segments[k])
                .map(|i| lo + (hi - lo) * i as f64 / segments[k] as f64)
                .collect()
        };
        let (cu, cv) = (cuts(0), cuts(1));
        Self::with_breaks(domain, [cu.clone(), cv.clone(), cu, cv], points_per_segment)
    }

    /// Segments between the kernel breakpoints of the particles whose supports cross each edge
    /// (`x_I`, `x_I ± a_I/2`, `x_I ± a_I` along the edge: the cubic B-spline is piecewise cubic in
    /// `|x − x_I|/a`), so that every RK function is smooth (rational) on every segment and the
    /// Gauss rule converges geometrically with `points_per_segment`. Measured on a jittered set
    /// with images (`tests/vci.rs`, `docs/integration.md`): a factor of about 30 per point, 6
    /// points per segment give the contour integrals to 3e-11 and 8 points to 4e-14 relative.
    pub fn breakpoint_aligned(
        domain: ParamBox,
        particles: &[[f64; 2]],
        supports: &[[f64; 2]],
        points_per_segment: usize,
    ) -> Result<Self, VciError> {
        check_box(&domain)?;
        if particles.len() != supports.len() {
            return Err(invalid(
                "supports.len()",
                supports.len(),
                "one support per particle",
            ));
        }
        let mut breaks: [Vec<f64>; 4] = Default::default();
        for (e, (fixed, side, _)) in EDGES.into_iter().enumerate() {
            let run = 1 - fixed;
            let c = if side == 0 {
                domain.lo[fixed]
            } else {
                domain.hi[fixed]
            };
            for (i, (p, a)) in particles.iter().zip(supports).enumerate() {
                if !(p[0].is_finite() && p[1].is_finite()) {
                    return Err(invalid(
                        format!("particle {i}"),
                        format!("({}, {})", p[0], p[1]),
                        "finite coordinates",
                    ));
                }
                if !(a[0] > 0.0 && a[1] > 0.0 && a[0].is_finite() && a[1].is_finite()) {
                    return Err(invalid(
                        format!("support of particle {i}"),
                        format!("({}, {})", a[0], a[1]),
                        "positive, finite half-widths",
                    ));
                }
                if (c - p[fixed]).abs() < a[fixed] {
                    for m in [-1.0, -0.5, 0.0, 0.5, 1.0] {
                        breaks[e].push(p[run] + m * a[run]);
                    }
                }
            }
        }
        Self::with_breaks(domain, breaks, points_per_segment)
    }

    /// The domain.
    pub fn domain(&self) -> ParamBox {
        self.domain
    }
    /// The points.
    pub fn points(&self) -> &[BoundaryPoint] {
        &self.points
    }
    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }
    /// No points (never the case for a constructed rule).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
    /// `Σ_b w_b f(x_b, n_b)`.
    pub fn integrate(&self, f: impl Fn([f64; 2], [f64; 2]) -> f64) -> f64 {
        self.points
            .iter()
            .map(|b| b.weight * f(b.x, b.normal))
            .sum()
    }
}

/// Per-particle polynomial basis `[1, (x − x_I)/a_1, (y − y_I)/a_2]`.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Frame {
    centre: [f64; 2],
    inv_scale: [f64; 2],
}

impl Frame {
    #[inline]
    fn p(&self, x: [f64; 2]) -> [f64; 3] {
        [
            1.0,
            (x[0] - self.centre[0]) * self.inv_scale[0],
            (x[1] - self.centre[1]) * self.inv_scale[1],
        ]
    }
    /// `∂p_k/∂x_α`.
    #[inline]
    fn dp(&self, alpha: usize, k: usize) -> f64 {
        if k == alpha + 1 {
            self.inv_scale[alpha]
        } else {
            0.0
        }
    }
}

/// Per particle: `[α][k]` sums.
type Moments = Vec<[[f64; 3]; 2]>;

/// Defect of the integration constraint of one particle (all directions and terms of the order).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ParticleDefect {
    /// Largest `|e_Iαk|`.
    pub abs: f64,
    /// Largest `|e_Iαk|` relative to the sum of the magnitudes of the terms it is made of
    /// (`Σ_q w_q (|Ψ̃_I,α p_k| + |Ψ_I p_k,α|) + Σ_b w_b |Ψ_I p_k n_α|`): round-off makes this
    /// a small multiple of machine epsilon when the constraint holds exactly. Zero for a particle
    /// that touches neither the domain points nor the boundary.
    pub rel: f64,
}

/// The variationally consistent correction of every particle's test gradients.
#[derive(Clone, Debug)]
pub struct VciCorrection {
    order: VciOrder,
    coupling: VciCoupling,
    frames: Vec<Frame>,
    boundary: Moments,
    boundary_mag: Moments,
    coefficients: Vec<[[f64; 3]; 2]>,
    achieved: Vec<VciOrder>,
    /// Per quadrature point, the mean correction `μ_qα` subtracted from every neighbour
    /// ([`VciCoupling::PartitionOfNullity`]); empty for [`VciCoupling::PerParticle`].
    offsets: Vec<[f64; 2]>,
    iterations: usize,
    solve_residual: f64,
}

/// How the particles' corrections are computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum VciCoupling {
    /// Each particle on its own (Chen, Hillman & Rüter 2013): `Ψ̃_I,α = Ψ_I,α + c_Iα·p^I`, one
    /// small moment system per particle. The integration constraints hold, but the corrected
    /// gradients lose the pointwise partition of nullity `Σ_I Ψ̃_I,α(x_q) = 0`: a rigid test
    /// translation has a non-zero test strain at the quadrature points (docs/integration.md §4.8).
    PerParticle,
    /// The same constraints, and the partition of nullity at every quadrature point:
    /// `Ψ̃_I,α(x_q) = Ψ_I,α(x_q) + c_Iα·p^I(x_q) − μ_α(x_q)`, with `μ_α(x_q)` the mean of the
    /// neighbours' corrections at the point. The coefficients of all particles are coupled
    /// through `μ`: one sparse symmetric positive semi-definite system, solved by conjugate
    /// gradients preconditioned with the per-particle moment matrices (whose single step is the
    /// [`VciCoupling::PerParticle`] correction). The recommended form for shells.
    PartitionOfNullity,
}

/// Relative residual (2-norm, against the right-hand side) at which the coupled conjugate
/// gradient solve of [`VciCoupling::PartitionOfNullity`] stops: the constraints then hold to
/// about this relative accuracy.
pub const VCI_CG_TOLERANCE: f64 = 1e-14;
/// The coupled solve stops when this many iterations brought no new smallest residual (the
/// round-off floor of the singular system, about 3e-14 relative on a jittered patch).
pub const VCI_CG_STALL: usize = 10;
/// Iteration limit of that solve (measured: 37 iterations on the 17² hemisphere, 11 to 77 on the
/// 9² jittered shell patches; docs/integration.md §2.4).
pub const VCI_CG_MAX_ITERATIONS: usize = 2000;

/// Solve `A c = r` for the 1×1 or 3×3 moment matrix by an equilibrated Cholesky factorisation;
/// `None` if a pivot is not positive or the condition estimate exceeds [`VCI_MAX_CONDITION`].
fn solve_moments(a: &[[f64; 3]; 3], n: usize, r: [[f64; 3]; 2]) -> Option<[[f64; 3]; 2]> {
    let mut d = [0.0; 3];
    for k in 0..n {
        if a[k][k].is_nan() || a[k][k] <= 0.0 {
            return None;
        }
        d[k] = 1.0 / a[k][k].sqrt();
    }
    let mut l = [[0.0; 3]; 3];
    let (mut pmin, mut pmax) = (f64::INFINITY, 0.0_f64);
    for j in 0..n {
        let mut s = a[j][j] * d[j] * d[j];
        for k in 0..j {
            s -= l[j][k] * l[j][k];
        }
        if s.is_nan() || s <= 0.0 {
            return None;
        }
        let ljj = s.sqrt();
        pmin = pmin.min(ljj);
        pmax = pmax.max(ljj);
        l[j][j] = ljj;
        for i in j + 1..n {
            let mut s = a[i][j] * d[i] * d[j];
            for k in 0..j {
                s -= l[i][k] * l[j][k];
            }
            l[i][j] = s / ljj;
        }
    }
    let cond = (pmax / pmin) * (pmax / pmin);
    if cond.is_nan() || cond > VCI_MAX_CONDITION {
        return None;
    }
    let mut out = [[0.0; 3]; 2];
    for (alpha, rhs) in r.iter().enumerate() {
        let mut y = [0.0; 3];
        for i in 0..n {
            let mut s = rhs[i] * d[i];
            for k in 0..i {
                s -= l[i][k] * y[k];
            }
            y[i] = s / l[i][i];
        }
        for i in (0..n).rev() {
            let mut s = y[i];
            for k in i + 1..n {
                s -= l[k][i] * y[k];
            }
            y[i] = s / l[i][i];
        }
        for i in 0..n {
            out[alpha][i] = y[i] * d[i];
        }
    }
    Some(out)
}

impl VciCorrection {
    /// Compute the correction of `order` for every particle of `sf` from the domain quadrature
    /// `points` (which must cover exactly `boundary.domain()`, with the RK functions of `sf`) and
    /// the contour integrals by `boundary`.
    pub fn new<Q: QuadratureShapes + ?Sized>(
        sf: &ShapeFunctions,
        boundary: &BoundaryRule,
        points: &Q,
        order: VciOrder,
    ) -> Result<Self, VciError> {
        Self::with_coupling(sf, boundary, points, order, VciCoupling::PerParticle)
    }

    /// As [`VciCorrection::new`], with the corrections coupled as `coupling` says. With
    /// [`VciCoupling::PartitionOfNullity`] the corrected gradients depend on the quadrature
    /// point: evaluate them with [`VciCorrection::corrected_gradient_at`] and the point's index in
    /// `points`.
    pub fn with_coupling<Q: QuadratureShapes + ?Sized>(
        sf: &ShapeFunctions,
        boundary: &BoundaryRule,
        points: &Q,
        order: VciOrder,
        coupling: VciCoupling,
    ) -> Result<Self, VciError> {
        let n = sf.len();
        let frames: Vec<Frame> = sf
            .particles()
            .iter()
            .zip(sf.supports())
            .map(|(&c, a)| Frame {
                centre: c,
                inv_scale: [1.0 / a[0], 1.0 / a[1]],
            })
            .collect();
        // Validate the domain quadrature (and find its total weight).
        let mut area = 0.0;
        for k in 0..points.n_points() {
            let (x, w) = points.point(k);
            if !(w > 0.0 && w.is_finite()) {
                return Err(invalid(
                    format!("weight of quadrature point {k}"),
                    w,
                    "positive and finite",
                ));
            }
            if !boundary_contains(&boundary.domain, x) {
                return Err(invalid(
                    format!("quadrature point {k}"),
                    format!("({}, {})", x[0], x[1]),
                    "a point of the boundary rule's domain",
                ));
            }
            area += w;
            let mut bad = None;
            points.for_each_shape(k, &mut |i, v, g| {
                if bad.is_none()
                    && (i >= n || !(v.is_finite() && g[0].is_finite() && g[1].is_finite()))
                {
                    bad = Some(i);
                }
            });
            if let Some(i) = bad {
                return Err(invalid(
                    format!("shape function entry of particle {i} at quadrature point {k}"),
                    if i >= n {
                        format!("index {i} of {n} particles")
                    } else {
                        "non-finite".into()
                    },
                    "an index into the shape functions' particles with finite Ψ and ∇Ψ",
                ));
            }
        }
        let d = &boundary.domain;
        let box_area = (d.hi[0] - d.lo[0]) * (d.hi[1] - d.lo[1]);
        if (area - box_area).abs() > 1e-10 * box_area {
            return Err(invalid(
                "sum of quadrature weights",
                area,
                "the area of the boundary rule's domain (the points must cover exactly that box)",
            ));
        }

        let nt = order.terms();
        let (bmom, boundary_mag) = boundary_moments(sf, boundary, &frames)?;
        let mut coefficients = vec![[[0.0; 3]; 2]; n];
        let mut achieved = vec![order; n];
        let mut offsets = Vec::new();
        let (mut iterations, mut solve_residual) = (0, 0.0);
        if nt > 0 {
            let (dmom, amat) = domain_moments(points, &frames, None);
            let mut rhs = vec![[[0.0; 3]; 2]; n];
            for i in 0..n {
                let mut r = [[0.0; 3]; 2];
                for alpha in 0..2 {
                    for k in 0..3 {
                        r[alpha][k] = bmom[i][alpha][k] - dmom[i][alpha][k];
                    }
                }
                rhs[i] = r;
                let mut m = nt;
                loop {
                    if m == 0 {
                        // Nothing can be corrected: exact only if there is nothing to correct.
                        let any = (0..2).any(|a| r[a][0] != 0.0);
                        achieved[i] = if any { VciOrder::Off } else { order };
                        break;
                    }
                    if let Some(c) = solve_moments(&amat[i], m, r) {
                        coefficients[i] = c;
                        achieved[i] = if m == 3 {
                            VciOrder::Second
                        } else {
                            VciOrder::First
                        };
                        break;
                    }
                    m = if m == 3 { 1 } else { 0 };
                }
            }
            if coupling == VciCoupling::PartitionOfNullity {
                let terms: Vec<usize> = achieved.iter().map(|a| a.terms()).collect();
                let sol = coupled_solve(points, &frames, &amat, &terms, rhs, coefficients);
                coefficients = sol.coefficients;
                offsets = sol.offsets;
                iterations = sol.iterations;
                solve_residual = sol.residual;
            }
        }
        Ok(VciCorrection {
            order,
            coupling,
            frames,
            boundary: bmom,
            boundary_mag,
            coefficients,
            achieved,
            offsets,
            iterations,
            solve_residual,
        })
    }

    /// How the corrections were coupled.
    pub fn coupling(&self) -> VciCoupling {
        self.coupling
    }
    /// Conjugate-gradient iterations of the coupled solve (0 for [`VciCoupling::PerParticle`]).
    pub fn iterations(&self) -> usize {
        self.iterations
    }
    /// Final relative residual of the coupled solve (0 for [`VciCoupling::PerParticle`]).
    pub fn solve_residual(&self) -> f64 {
        self.solve_residual
    }
    /// The mean correction `μ_α(x_k)` subtracted at quadrature point `k`
    /// ([`VciCoupling::PartitionOfNullity`]; zero otherwise).
    pub fn point_offset(&self, k: usize) -> [f64; 2] {
        self.offsets.get(k).copied().unwrap_or([0.0; 2])
    }

    /// Corrected test gradient of particle `i` at quadrature point `k` (index in the points the
    /// correction was built from) at `x`, from its RK gradient `grad` there:
    /// [`VciCorrection::corrected_gradient`] minus the point's offset `μ(x_k)` when the
    /// corrections are coupled by [`VciCoupling::PartitionOfNullity`].
    #[inline]
    pub fn corrected_gradient_at(
        &self,
        i: usize,
        k: usize,
        x: [f64; 2],
        grad: [f64; 2],
    ) -> [f64; 2] {
        let g = self.corrected_gradient(i, x, grad);
        match self.offsets.get(k) {
            Some(m) => [g[0] - m[0], g[1] - m[1]],
            None => g,
        }
    }

    /// The requested order.
    pub fn order(&self) -> VciOrder {
        self.order
    }
    /// Number of particles.
    pub fn len(&self) -> usize {
        self.frames.len()
    }
    /// No particles.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
    /// The order achieved for particle `i` (lower than requested when its moment matrix was
    /// singular or too ill-conditioned, e.g. too few quadrature points in its support).
    pub fn achieved(&self, i: usize) -> VciOrder {
        self.achieved[i]
    }
    /// Particles corrected to a lower order than requested, with the order achieved.
    pub fn degraded(&self) -> Vec<(usize, VciOrder)> {
        self.achieved
            .iter()
            .enumerate()
            .filter(|(_, &a)| a < self.order)
            .map(|(i, &a)| (i, a))
            .collect()
    }
    /// Correction coefficients `c_Iαj` of particle `i` (`[α][j]`, unused terms zero).
    pub fn coefficients(&self, i: usize) -> [[f64; 3]; 2] {
        self.coefficients[i]
    }
    /// The contour integrals `∮ Ψ_I p^I_k n_α ds` of particle `i` by the boundary rule
    /// (`[α][k]`), with `p^I = [1, (x − x_I)/a_1, (y − y_I)/a_2]`.
    pub fn boundary_moments(&self, i: usize) -> [[f64; 3]; 2] {
        self.boundary[i]
    }

    /// Corrected test gradient `Ψ̃_I,α(x) = Ψ_I,α(x) + Σ_j c_Iαj p^I_j(x)` of particle `i` at a
    /// quadrature point `x` of its support, from its RK gradient `grad` there (without the
    /// point offset of [`VciCoupling::PartitionOfNullity`]: see
    /// [`VciCorrection::corrected_gradient_at`]).
    #[inline]
    pub fn corrected_gradient(&self, i: usize, x: [f64; 2], grad: [f64; 2]) -> [f64; 2] {
        let p = self.frames[i].p(x);
        let c = &self.coefficients[i];
        [
            grad[0] + c[0][0] * p[0] + c[0][1] * p[1] + c[0][2] * p[2],
            grad[1] + c[1][0] * p[0] + c[1][1] * p[1] + c[1][2] * p[2],
        ]
    }

    /// Defect of the integration constraint of the requested order (`p = 1` for
    /// [`VciOrder::First`], `p ∈ {1, x, y}` otherwise; `p = 1` for [`VciOrder::Off`]) for every
    /// particle, with the RK gradients (`corrected = false`, the control) or the corrected ones.
    pub fn defects<Q: QuadratureShapes + ?Sized>(
        &self,
        points: &Q,
        corrected: bool,
    ) -> Vec<ParticleDefect> {
        let nt = self.order.terms().max(1);
        let (dmom, _) = domain_moments(points, &self.frames, corrected.then_some(self));
        let mag = magnitudes(points, &self.frames, corrected.then_some(self));
        (0..self.len())
            .map(|i| {
                let mut out = ParticleDefect::default();
                for alpha in 0..2 {
                    for k in 0..nt {
                        let e = (dmom[i][alpha][k] - self.boundary[i][alpha][k]).abs();
                        let m = mag[i][alpha][k] + self.boundary_mag[i][alpha][k];
                        out.abs = out.abs.max(e);
                        if m > 0.0 {
                            out.rel = out.rel.max(e / m);
                        }
                    }
                }
                out
            })
            .collect()
    }
}

fn boundary_contains(b: &ParamBox, x: [f64; 2]) -> bool {
    // Quadrature points are interior (Gauss), so the closed box is the right test.
    (0..2).all(|k| x[k] >= b.lo[k] && x[k] <= b.hi[k])
}

/// `∮ Ψ_I p^I_k n_α ds` for every particle, and the sums of the magnitudes of their terms.
fn boundary_moments(
    sf: &ShapeFunctions,
    rule: &BoundaryRule,
    frames: &[Frame],
) -> Result<(Moments, Moments), VciError> {
    let mut m = vec![[[0.0; 3]; 2]; sf.len()];
    let mut mag = vec![[[0.0; 3]; 2]; sf.len()];
    let mut sv = ShapeValues::new();
    for b in rule.points() {
        sf.evaluate(b.x, &mut sv)?;
        for (i, v, _) in sv.iter() {
            let p = frames[i].p(b.x);
            for alpha in 0..2 {
                let wn = b.weight * b.normal[alpha] * v;
                if wn != 0.0 {
                    for k in 0..3 {
                        m[i][alpha][k] += wn * p[k];
                        mag[i][alpha][k] += (wn * p[k]).abs();
                    }
                }
            }
        }
    }
    Ok((m, mag))
}

/// Domain sums `Σ_q w_q [g_Iα p_k + Ψ_I p_k,α]` (with the corrected gradients when `corr` is
/// given) and the moment matrices `A_I`.
fn domain_moments<Q: QuadratureShapes + ?Sized>(
    points: &Q,
    frames: &[Frame],
    corr: Option<&VciCorrection>,
) -> (Moments, Vec<[[f64; 3]; 3]>) {
    let n = frames.len();
    let mut d = vec![[[0.0; 3]; 2]; n];
    let mut a = vec![[[0.0; 3]; 3]; n];
    for q in 0..points.n_points() {
        let (x, w) = points.point(q);
        points.for_each_shape(q, &mut |i, v, g| {
            let f = &frames[i];
            let p = f.p(x);
            let g = corr.map_or(g, |c| c.corrected_gradient_at(i, q, x, g));
            for alpha in 0..2 {
                for k in 0..3 {
                    d[i][alpha][k] += w * (g[alpha] * p[k] + v * f.dp(alpha, k));
                }
            }
            for j in 0..3 {
                for k in 0..3 {
                    a[i][j][k] += w * p[j] * p[k];
                }
            }
        });
    }
    (d, a)
}

/// `Σ_q w_q (|g_Iα p_k| + |Ψ_I p_k,α|)`: the magnitude of the domain terms.
fn magnitudes<Q: QuadratureShapes + ?Sized>(
    points: &Q,
    frames: &[Frame],
    corr: Option<&VciCorrection>,
) -> Moments {
    let mut m = vec![[[0.0; 3]; 2]; frames.len()];
    for q in 0..points.n_points() {
        let (x, w) = points.point(q);
        points.for_each_shape(q, &mut |i, v, g| {
            let f = &frames[i];
            let p = f.p(x);
            let g = corr.map_or(g, |c| c.corrected_gradient_at(i, q, x, g));
            for alpha in 0..2 {
                for k in 0..3 {
                    m[i][alpha][k] += w * ((g[alpha] * p[k]).abs() + (v * f.dp(alpha, k)).abs());
                }
            }
        });
    }
    m
}

/// Result of [`coupled_solve`].
struct Coupled {
    coefficients: Vec<[[f64; 3]; 2]>,
    offsets: Vec<[f64; 2]>,
    iterations: usize,
    residual: f64,
}

/// The neighbours of every point with their basis values `p^I(x_q)`, and the weights.
struct PointBasis {
    weights: Vec<f64>,
    start: Vec<usize>,
    entries: Vec<(usize, [f64; 3])>,
}

impl PointBasis {
    fn new<Q: QuadratureShapes + ?Sized>(points: &Q, frames: &[Frame]) -> Self {
        let mut weights = Vec::with_capacity(points.n_points());
        let mut start = vec![0];
        let mut entries = Vec::new();
        for q in 0..points.n_points() {
            let (x, w) = points.point(q);
            weights.push(w);
            points.for_each_shape(q, &mut |i, _, _| entries.push((i, frames[i].p(x))));
            start.push(entries.len());
        }
        PointBasis {
            weights,
            start,
            entries,
        }
    }
    fn at(&self, q: usize) -> &[(usize, [f64; 3])] {
        &self.entries[self.start[q]..self.start[q + 1]]
    }
    /// Corrections `δ_I(x_q) = Σ_{j < m_I} c_Iαj p^I_j(x_q)` of the neighbours of `q`, and their
    /// mean `μ_qα`, passed to `f(I, p^I(x_q), δ_I − μ)` per neighbour; returns `μ_q`.
    fn projected(
        &self,
        q: usize,
        c: &[[[f64; 3]; 2]],
        terms: &[usize],
        mut f: impl FnMut(usize, &[f64; 3], [f64; 2]),
    ) -> [f64; 2] {
        let nb = self.at(q);
        if nb.is_empty() {
            return [0.0; 2];
        }
        let delta = |i: usize, p: &[f64; 3], a: usize| -> f64 {
            (0..terms[i]).map(|j| c[i][a][j] * p[j]).sum()
        };
        let mut mu = [0.0; 2];
        for (i, p) in nb {
            for (a, m) in mu.iter_mut().enumerate() {
                *m += delta(*i, p, a);
            }
        }
        for m in &mut mu {
            *m /= nb.len() as f64;
        }
        for (i, p) in nb {
            f(*i, p, [delta(*i, p, 0) - mu[0], delta(*i, p, 1) - mu[1]]);
        }
        mu
    }
}

/// `Σ` over particles, directions and active terms of `a·b`.
fn dot(a: &[[[f64; 3]; 2]], b: &[[[f64; 3]; 2]]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            (0..2)
                .map(|al| (0..3).map(|k| x[al][k] * y[al][k]).sum::<f64>())
                .sum::<f64>()
        })
        .sum()
}

/// The coupled constraints of [`VciCoupling::PartitionOfNullity`]. With `δ_I(x_q) = c_I·p^I(x_q)`
/// and `μ_q` the mean of `δ` over the neighbours of `q`, the integration constraints of the
/// corrected gradients `Ψ_I,α + δ_I − μ` read, per particle, direction and active term `k`,
///
/// ```text
/// (K c)_Iαk = Σ_q w_q p^I_k(x_q) (δ_Iα(x_q) − μ_qα) = r_Iαk     (r: boundary minus domain moments)
/// ```
///
/// `K` is symmetric positive semi-definite (`cᵀKc = Σ_q w_q Σ_I (δ_I − μ_q)²`); its null space
/// (one global linear `δ`, which the mean removes) is orthogonal to `r` when the domain and
/// boundary rules integrate constants and linears exactly, so conjugate gradients converge.
/// The preconditioner is the block diagonal of per-particle moment matrices `A_I`, started from
/// the per-particle solution `c0`.
fn coupled_solve<Q: QuadratureShapes + ?Sized>(
    points: &Q,
    frames: &[Frame],
    amat: &[[[f64; 3]; 3]],
    terms: &[usize],
    rhs: Moments,
    c0: Vec<[[f64; 3]; 2]>,
) -> Coupled {
    let n = frames.len();
    let basis = PointBasis::new(points, frames);
    let mut r = rhs;
    for (ri, &m) in r.iter_mut().zip(terms) {
        for row in ri.iter_mut() {
            row[m..].fill(0.0);
        }
    }
    let apply = |c: &[[[f64; 3]; 2]]| -> Moments {
        let mut out = vec![[[0.0; 3]; 2]; n];
        for q in 0..basis.weights.len() {
            let w = basis.weights[q];
            basis.projected(q, c, terms, |i, p, d| {
                for a in 0..2 {
                    for k in 0..terms[i] {
                        out[i][a][k] += w * p[k] * d[a];
                    }
                }
            });
        }
        out
    };
    let precondition = |res: &Moments| -> Moments {
        res.iter()
            .enumerate()
            .map(|(i, ri)| {
                if terms[i] == 0 {
                    return [[0.0; 3]; 2];
                }
                // The per-particle systems were solvable at this order (that is how `terms`
                // was chosen), so this succeeds.
                solve_moments(&amat[i], terms[i], *ri).unwrap_or([[0.0; 3]; 2])
            })
            .collect()
    };
    // The null space of K: a global linear correction `g`, as coefficients in every particle's
    // frame (`g ∈ {1, u, v}` per direction, a linear `g` only when every particle at a point has
    // all three terms). The right-hand side is orthogonal to it unless a particle touching the
    // domain cannot be corrected to the requested order (degraded): then the constraints of the
    // others and the partition of nullity cannot all hold, and the null-space part of `r` (the
    // degraded particles' defect, spread over all) is removed so that the rest is solved.
    let at_points: Vec<bool> = {
        let mut v = vec![false; n];
        for (i, _) in &basis.entries {
            v[*i] = true;
        }
        v
    };
    let full = (0..n).all(|i| !at_points[i] || terms[i] == 3);
    let mut null: Vec<Moments> = Vec::new();
    for a in 0..2 {
        for g in 0..if full { 3 } else { 1 } {
            let mut v = vec![[[0.0; 3]; 2]; n];
            for i in (0..n).filter(|&i| at_points[i] && terms[i] > 0) {
                let f = &frames[i];
                // g = 1, u, v in frame I: [g(x_I), ∂g/∂u a_1, ∂g/∂v a_2].
                v[i][a] = match g {
                    0 => [1.0, 0.0, 0.0],
                    1 => [f.centre[0], 1.0 / f.inv_scale[0], 0.0],
                    _ => [f.centre[1], 0.0, 1.0 / f.inv_scale[1]],
                };
            }
            for u in &null {
                let s = dot(&v, u);
                for (vi, ui) in v.iter_mut().zip(u) {
                    for b in 0..2 {
                        for k in 0..3 {
                            vi[b][k] -= s * ui[b][k];
                        }
                    }
                }
            }
            let norm = dot(&v, &v).sqrt();
            if norm > 0.0 {
                v.iter_mut()
                    .for_each(|vi| vi.iter_mut().flatten().for_each(|x| *x /= norm));
                null.push(v);
            }
        }
    }
    for u in &null {
        let s = dot(&r, u);
        for (ri, ui) in r.iter_mut().zip(u) {
            for b in 0..2 {
                for k in 0..3 {
                    ri[b][k] -= s * ui[b][k];
                }
            }
        }
    }
    let norm_r = dot(&r, &r).sqrt();
    let mut c = c0;
    for (ci, &m) in c.iter_mut().zip(terms) {
        for row in ci.iter_mut() {
            row[m..].fill(0.0);
        }
    }
    let kc = apply(&c);
    let mut res: Moments = r
        .iter()
        .zip(&kc)
        .map(|(a, b)| std::array::from_fn(|al| std::array::from_fn(|k| a[al][k] - b[al][k])))
        .collect();
    let mut iterations = 0;
    let mut rel = if norm_r > 0.0 {
        dot(&res, &res).sqrt() / norm_r
    } else {
        0.0
    };
    // K is singular: round-off puts a small component of the residual in its null space, which
    // conjugate gradients cannot remove; once the residual reaches that floor it stagnates and
    // then grows. Keep the best iterate and stop when no progress was made for a while.
    let mut best = (rel, c.clone(), iterations);
    if rel > VCI_CG_TOLERANCE {
        let mut z = precondition(&res);
        let mut d = z.clone();
        let mut rz = dot(&res, &z);
        while iterations < VCI_CG_MAX_ITERATIONS
            && rel > VCI_CG_TOLERANCE
            && iterations < best.2 + VCI_CG_STALL
        {
            iterations += 1;
            let kd = apply(&d);
            let dkd = dot(&d, &kd);
            if !(dkd > 0.0 && rz.is_finite()) {
                break; // only the null space is left
            }
            let step = rz / dkd;
            for i in 0..n {
                for a in 0..2 {
                    for k in 0..3 {
                        c[i][a][k] += step * d[i][a][k];
                        res[i][a][k] -= step * kd[i][a][k];
                    }
                }
            }
            rel = dot(&res, &res).sqrt() / norm_r;
            if rel < best.0 {
                best = (rel, c.clone(), iterations);
            }
            z = precondition(&res);
            let rz_new = dot(&res, &z);
            let beta = rz_new / rz;
            rz = rz_new;
            for i in 0..n {
                for a in 0..2 {
                    for k in 0..3 {
                        d[i][a][k] = z[i][a][k] + beta * d[i][a][k];
                    }
                }
            }
        }
    }
    let (residual, c, _) = best;
    let offsets = (0..basis.weights.len())
        .map(|q| basis.projected(q, &c, terms, |_, _, _| {}))
        .collect();
    Coupled {
        coefficients: c,
        offsets,
        iterations,
        residual,
    }
}
