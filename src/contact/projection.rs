//! Closest-point projection onto a rigid tool (eq 67) and the normal gap (eq 68), generic over
//! the scalar.
//!
//! **Method.** The projection minimises `f(ξ) = ½ |X_ref − X(ξ)|²` on the tool in its built
//! position, with `X_ref = c + Rᵀ (x − a − c)` the slave point mapped back by the tool's rigid
//! motion (distances are invariant, so this is the projection onto the moved surface). The
//! stationarity condition is eq (67), `r_α = (X_ref − X)·X,α = 0`, whose Jacobian is
//! `∂r_α/∂ξ_β = −A_αβ`, `A_αβ = m_αβ − (X_ref − X)·X,αβ` (at the solution
//! `A_αβ = m_αβ − g n·x^c,αβ`, the matrix of eqs 79–80).
//!
//! 1. Initial guess: the nearest sample of the tool's [`CoarseGrid`] (computed once per tool).
//! 2. Newton in f64, `ξ ← ξ + A⁻¹ r`, projected onto the parameter box (active set: a coordinate
//!    at a bound whose descent direction `r_α` points out of the box is held and the Newton step
//!    is taken in the free coordinate(s) only: the constrained projection on an edge or at a
//!    corner). Where `A` is not positive definite (far from the solution on a concave tool) the
//!    Gauss–Newton matrix `m` is used instead; every step is backtracked until `f` does not
//!    increase. Converged when the step moves the tool point by at most `1e-13` of the tool size
//!    (Newton converges quadratically, so the converged `ξ` is exact to round-off).
//! 3. **One Newton correction in the scalar type `T`** at the converged `ξ*`:
//!    `ξ = ξ* + A_FF⁻¹ r_F` on the free coordinates (the held ones are constants). The real part
//!    moves by round-off only; the derivative part is `−(∂r/∂ξ)⁻¹ ∂r/∂p = A⁻¹ ∂r/∂p` for any
//!    seeded input `p` (slave point, tool motion, tool shape parameters): the implicit function
//!    theorem, exact because `r(ξ*) = 0` removes the term `∂(A⁻¹)/∂p r`. This is eq (80)'s `ξ̇`.
//!    The gap and the normal are then evaluated at that `ξ` in `T`. Tested against central
//!    differences and closed forms (`tests/contact_kernels.rs`).

use super::tool::{moved_derivs, CoarseGrid, RigidMotion, RigidTool, Side};
use super::ContactError;
use crate::geometry::{Surface, SurfaceDerivs};
use crate::scalar::Real;
use nalgebra::{Matrix2, Vector2, Vector3};

type V3<T> = Vector3<T>;

/// Maximum Newton iterations of the projection.
pub const MAX_PROJECTION_ITERATIONS: usize = 60;
/// Convergence: a step moving the tool point by at most this fraction of the tool size.
pub const PROJECTION_TOLERANCE: f64 = 1e-13;

/// Where a parameter coordinate of the projection lies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Bound {
    /// Inside the parameter range (free).
    Interior,
    /// Held at the lower bound.
    Lower,
    /// Held at the upper bound.
    Upper,
}

/// The result of a projection: the contact point on the moved tool, its frame and the gap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ContactPoint<T> {
    /// Parameter coordinates `ξ` of the contact point.
    pub xi: [T; 2],
    /// Status of each coordinate (`Interior` for both: eq 67 holds).
    pub bounds: [Bound; 2],
    /// Moved surface at `ξ`: `x^c`, `x^c,α` (eq 66's `e_α`), `x^c,αβ`.
    pub surface: SurfaceDerivs<T>,
    /// Unit normal pointing out of the solid tool (eq 66 times the side's sign).
    pub normal: V3<T>,
    /// Normal gap `g = (x − x^c)·n` (eq 68): negative when the point is inside the tool.
    pub gap: T,
    /// Newton iterations of the f64 phase.
    pub iterations: usize,
}

impl<T: Real> ContactPoint<T> {
    /// Whether the projection is interior (both coordinates free), so that eq (67) holds and
    /// `x − x^c = g n`. Points projecting onto a tool's boundary are not in contact
    /// ([`super::penalty`]).
    pub fn is_interior(&self) -> bool {
        self.bounds == [Bound::Interior; 2]
    }

    /// Whether the point is penetrating the tool at an interior projection (`g < 0`).
    pub fn is_active(&self) -> bool {
        self.is_interior() && self.gap.value() < 0.0
    }

    /// Metric `m_αβ = x^c,α · x^c,β`.
    pub fn metric(&self) -> Matrix2<T> {
        self.surface.metric()
    }

    /// Second fundamental form with the contact normal, `b_αβ = n · x^c,αβ`.
    pub fn curvature(&self) -> Matrix2<T> {
        let s = &self.surface;
        let b12 = self.normal.dot(&s.xuv);
        Matrix2::new(self.normal.dot(&s.xuu), b12, b12, self.normal.dot(&s.xvv))
    }

    /// `A_αβ = m_αβ − g b_αβ` (eqs 79–80).
    pub fn a_matrix(&self) -> Matrix2<T> {
        self.metric() - self.curvature() * self.gap
    }

    /// Real parts.
    pub fn value(&self) -> ContactPoint<f64> {
        ContactPoint {
            xi: self.xi.map(|v| v.value()),
            bounds: self.bounds,
            surface: self.surface.value(),
            normal: self.normal.map(|v| v.value()),
            gap: self.gap.value(),
            iterations: self.iterations,
        }
    }
}

/// Residual `r_α = d·X,α` and matrix `A_αβ = m_αβ − d·X,αβ` with `d = x − X`.
fn residual_and_matrix<T: Real>(s: &SurfaceDerivs<T>, x: &V3<T>) -> (Vector2<T>, Matrix2<T>) {
    let d = x - s.x;
    let r = Vector2::new(d.dot(&s.xu), d.dot(&s.xv));
    let m = s.metric();
    let h12 = d.dot(&s.xuv);
    let a = m - Matrix2::new(d.dot(&s.xuu), h12, h12, d.dot(&s.xvv));
    (r, a)
}

/// Solve the free block `a_FF δ = r_F` (`free` lists the free coordinates); `None` when the
/// block is not positive definite.
fn solve_free<T: Real>(a: &Matrix2<T>, r: &Vector2<T>, free: &[usize]) -> Option<Vector2<T>> {
    let mut out = Vector2::zeros();
    match free {
        [k] => {
            if a[(*k, *k)].value() <= 0.0 {
                return None;
            }
            out[*k] = r[*k] / a[(*k, *k)];
        }
        [_, _] => {
            let det = a[(0, 0)] * a[(1, 1)] - a[(0, 1)] * a[(1, 0)];
            if a[(0, 0)].value() <= 0.0 || det.value() <= 0.0 {
                return None;
            }
            out[0] = (r[0] * a[(1, 1)] - r[1] * a[(0, 1)]) / det;
            out[1] = (r[1] * a[(0, 0)] - r[0] * a[(1, 0)]) / det;
        }
        _ => {}
    }
    Some(out)
}

/// The f64 phase: the closest point of `x_ref` on `surface` (built position) from the coarse
/// guess, with the active set of the parameter box.
fn newton_f64<T: Real>(
    surface: &Surface<T>,
    grid: &CoarseGrid,
    x_ref: &V3<f64>,
    name: &str,
) -> Result<([f64; 2], [Bound; 2], usize), ContactError> {
    let dom = surface.domain();
    let eval = |xi: [f64; 2]| surface.eval(T::cst(xi[0]), T::cst(xi[1])).value();
    let mut xi = grid.nearest(x_ref);
    let tol = PROJECTION_TOLERANCE * grid.size;
    let mut s = eval(xi);
    let mut f = (x_ref - s.x).norm_squared();
    let mut last_step = f64::INFINITY;
    for it in 0..MAX_PROJECTION_ITERATIONS {
        let (r, a) = residual_and_matrix(&s, x_ref);
        // Active set: hold a coordinate at a bound whose descent direction leaves the box.
        let mut bounds = [Bound::Interior; 2];
        for k in 0..2 {
            if xi[k] <= dom[k][0] && r[k] <= 0.0 {
                bounds[k] = Bound::Lower;
            } else if xi[k] >= dom[k][1] && r[k] >= 0.0 {
                bounds[k] = Bound::Upper;
            }
        }
        let free: Vec<usize> = (0..2).filter(|&k| bounds[k] == Bound::Interior).collect();
        if free.is_empty() {
            return Ok((xi, bounds, it));
        }
        let step = solve_free(&a, &r, &free)
            .or_else(|| solve_free(&s.metric(), &r, &free))
            .ok_or_else(|| ContactError::ProjectionNotConverged {
                tool: name.to_string(),
                point: [x_ref[0], x_ref[1], x_ref[2]],
                iterations: it,
                step: f64::NAN,
                tolerance: tol,
                xi,
            })?;
        // Backtrack until f does not increase (a Gauss–Newton or Newton step on a positive
        // definite matrix is a descent direction, so a small enough step always passes).
        let mut lambda = 1.0;
        let mut accepted = None;
        for _ in 0..40 {
            let trial = [
                (xi[0] + step[0] * lambda).clamp(dom[0][0], dom[0][1]),
                (xi[1] + step[1] * lambda).clamp(dom[1][0], dom[1][1]),
            ];
            let st = eval(trial);
            let ft = (x_ref - st.x).norm_squared();
            if ft <= f * (1.0 + 4.0 * f64::EPSILON) + tol * tol {
                accepted = Some((trial, st, ft));
                break;
            }
            lambda *= 0.5;
        }
        let Some((trial, st, ft)) = accepted else {
            return Err(ContactError::ProjectionNotConverged {
                tool: name.to_string(),
                point: [x_ref[0], x_ref[1], x_ref[2]],
                iterations: it,
                step: last_step,
                tolerance: tol,
                xi,
            });
        };
        let moved = s.xu * (trial[0] - xi[0]) + s.xv * (trial[1] - xi[1]);
        last_step = moved.norm();
        xi = trial;
        s = st;
        f = ft;
        if last_step <= tol {
            // Re-check the active set at the converged point.
            let (r, _) = residual_and_matrix(&s, x_ref);
            let mut bounds = [Bound::Interior; 2];
            for k in 0..2 {
                if xi[k] <= dom[k][0] && r[k] <= 0.0 {
                    bounds[k] = Bound::Lower;
                } else if xi[k] >= dom[k][1] && r[k] >= 0.0 {
                    bounds[k] = Bound::Upper;
                }
            }
            return Ok((xi, bounds, it + 1));
        }
    }
    Err(ContactError::ProjectionNotConverged {
        tool: name.to_string(),
        point: [x_ref[0], x_ref[1], x_ref[2]],
        iterations: MAX_PROJECTION_ITERATIONS,
        step: last_step,
        tolerance: tol,
        xi,
    })
}

/// Closest-point projection of the slave point `x` onto the surface `surface` moved by `motion`
/// (eq 67), with the normal pointing out of the solid (`side`) and the normal gap (eq 68).
///
/// Generic: every input may carry derivatives (`x`, the motion, the surface's parameters), and
/// the derivative of `ξ`, `x^c`, `n` and `g` comes out exactly through the final Newton
/// correction in `T` (module documentation). `grid` is the coarse grid of the real surface and
/// `name` names the tool in errors.
pub fn closest_point<T: Real>(
    surface: &Surface<T>,
    motion: &RigidMotion<T>,
    side: Side,
    grid: &CoarseGrid,
    x: &V3<T>,
    name: &str,
) -> Result<ContactPoint<T>, ContactError> {
    let x_ref = motion.to_reference(x);
    let x_ref_f = x_ref.map(|v| v.value());
    if !x_ref_f.iter().all(|v| v.is_finite()) {
        return Err(super::invalid(
            "slave point",
            [x_ref_f[0], x_ref_f[1], x_ref_f[2]],
            "finite coordinates",
        ));
    }
    let (xi_f, bounds, iterations) = newton_f64(surface, grid, &x_ref_f, name)?;
    // One Newton correction in T on the free coordinates (implicit derivative, eq 80).
    let s0 = surface.eval(T::cst(xi_f[0]), T::cst(xi_f[1]));
    let (r, a) = residual_and_matrix(&s0, &x_ref);
    let free: Vec<usize> = (0..2).filter(|&k| bounds[k] == Bound::Interior).collect();
    let step = solve_free(&a, &r, &free)
        .or_else(|| solve_free(&s0.metric(), &r, &free))
        .unwrap_or_else(Vector2::zeros);
    let xi = [T::cst(xi_f[0]) + step[0], T::cst(xi_f[1]) + step[1]];
    let s_ref = surface.eval(xi[0], xi[1]);
    let n_ref = s_ref.normal().map_err(|e| ContactError::Geometry {
        tool: name.to_string(),
        source: e,
    })? * T::cst(side.sign());
    let gap = (x_ref - s_ref.x).dot(&n_ref);
    let surface_moved = moved_derivs(&s_ref, motion);
    Ok(ContactPoint {
        xi,
        bounds,
        surface: surface_moved,
        normal: motion.rotation * n_ref,
        gap,
        iterations,
    })
}

/// Project `x` onto every tool at pseudo-time `t` and return the nearest: the interior
/// projection with the smallest gap (the most penetrated tool), or `None` when no tool has an
/// interior projection. `surfaces[i]` is tool `i`'s surface in scalar `T` (lifted once by the
/// caller; its real part must be `tools[i].surface`).
pub fn nearest_tool<T: Real>(
    tools: &[RigidTool],
    surfaces: &[Surface<T>],
    t: f64,
    x: &V3<T>,
) -> Result<Option<(usize, ContactPoint<T>)>, ContactError> {
    let mut best: Option<(usize, ContactPoint<T>)> = None;
    for (i, (tool, surf)) in tools.iter().zip(surfaces).enumerate() {
        let motion = tool.motion(t).lift::<T>();
        let cp = closest_point(surf, &motion, tool.side, &tool.grid, x, &tool.name)?;
        if !cp.is_interior() {
            continue;
        }
        if best
            .as_ref()
            .is_none_or(|(_, b)| cp.gap.value() < b.gap.value())
        {
            best = Some((i, cp));
        }
    }
    Ok(best)
}
