//! Rational B-spline (NURBS) patches as a CAD tool exports them: degrees 1..=3, open (clamped),
//! possibly non-uniform knot vectors, control points with weights.
//!
//! Evaluation follows Piegl & Tiller, *The NURBS Book* (2nd ed.): span search (A2.1), basis
//! functions and their derivatives (A2.3), derivatives of the homogeneous surface `Aʷ(u, v) =
//! Σ Nᵢ(u) Nⱼ(v) Pʷᵢⱼ` with `Pʷᵢⱼ = (wᵢⱼ Pᵢⱼ, wᵢⱼ)` (as in A3.6) and the rational derivatives from
//! the quotient rule (A4.4). Everything is generic over the scalar, both in control points and
//! weights and in `(u, v)`; the knots are plain `f64` (they are structural, not design
//! parameters). The span is chosen from the real part of the parameter, so a dual-number
//! parameter differentiates the polynomial piece it lies on.

use super::{check_finite, GeometryError, SurfaceDerivs};
use crate::scalar::Real;
use nalgebra::Vector3;

/// Highest supported degree.
pub const MAX_DEGREE: usize = 3;

/// `ders[k][j]`: k-th derivative (k = 0, 1, 2) of the basis function `N_{span−p+j, p}`,
/// `j = 0..=p` (entries beyond the degree are zero).
pub type BasisDerivs<T> = [[T; MAX_DEGREE + 1]; 3];

/// Knot span index `i` with `knots[i] ≤ u < knots[i+1]` (A2.1), for `n_points` control points of
/// degree `degree`, clamped to the valid spans `degree..=n_points−1`: a parameter below/above the
/// knot range (or NaN) gets the first/last span (NaN: the first), so evaluation extrapolates the
/// end polynomial pieces. `u = knots[n_points]` (the end of the range) gets the last span.
///
/// The caller guarantees `knots.len() == n_points + degree + 1` and `n_points > degree`
/// (checked by [`NurbsSurface::validate`]); otherwise the result is clamped into the slice range
/// and never panics, but is meaningless.
pub fn find_span(n_points: usize, degree: usize, u: f64, knots: &[f64]) -> usize {
    if knots.len() < 2 || n_points == 0 {
        return 0;
    }
    let n = (n_points - 1).min(knots.len() - 2); // last valid span index
    let p = degree.min(n);
    if u.is_nan() || u <= knots[p] {
        // The first non-empty span at or after p (a clamped vector has knots[p] < knots[p+1]).
        let mut i = p;
        while i < n && knots[i + 1] <= knots[p] {
            i += 1;
        }
        return i;
    }
    if u >= knots[n + 1] {
        // The last non-empty span.
        let mut i = n;
        while i > p && knots[i] >= knots[n + 1] {
            i -= 1;
        }
        return i;
    }
    let (mut low, mut high) = (p, n + 1);
    let mut mid = (low + high) / 2;
    while u < knots[mid] || u >= knots[mid + 1] {
        if u < knots[mid] {
            high = mid;
        } else {
            low = mid;
        }
        let next = (low + high) / 2;
        if next == mid {
            break; // only reachable with inconsistent input; never loop forever
        }
        mid = next;
    }
    mid
}

/// Basis functions `N_{span−p+j, p}(u)` and their first and second derivatives (Piegl & Tiller
/// A2.3), generic over the scalar of `u`. Derivatives of order above the degree are zero.
///
/// Errors (instead of panicking) if the degree is outside `1..=3` or `span` is not a valid,
/// non-empty knot span of `knots`.
pub fn basis_function_derivatives<T: Real>(
    span: usize,
    u: T,
    degree: usize,
    knots: &[f64],
) -> Result<BasisDerivs<T>, GeometryError> {
    if !(1..=MAX_DEGREE).contains(&degree) {
        return Err(GeometryError::Degree {
            field: "degree".into(),
            value: degree,
        });
    }
    if span < degree || span + degree >= knots.len() || knots[span + 1] <= knots[span] {
        return Err(GeometryError::ControlNet {
            field: "span".into(),
            got: span,
            expected: format!(
                "a non-empty knot span index in {degree}..{} of {} knots",
                knots.len().saturating_sub(degree + 1),
                knots.len()
            ),
        });
    }
    Ok(basis_derivs_unchecked(span, u, degree, knots))
}

/// A2.3 with `n = min(2, p)` derivatives. Requires `1 ≤ p ≤ 3`, `p ≤ span`,
/// `span + p < knots.len()` and `knots[span] < knots[span + 1]`.
pub(crate) fn basis_derivs_unchecked<T: Real>(
    span: usize,
    u: T,
    p: usize,
    knots: &[f64],
) -> BasisDerivs<T> {
    const M: usize = MAX_DEGREE + 1;
    let zero = T::zero();
    let one = T::one();
    let nd = p.min(2);
    // ndu: upper triangle basis functions, lower triangle knot differences.
    let mut ndu = [[zero; M]; M];
    let mut left = [zero; M];
    let mut right = [zero; M];
    ndu[0][0] = one;
    for j in 1..=p {
        left[j] = u - knots[span + 1 - j];
        right[j] = -u + knots[span + j];
        let mut saved = zero;
        for r in 0..j {
            ndu[j][r] = right[r + 1] + left[j - r];
            let temp = ndu[r][j - 1] / ndu[j][r];
            ndu[r][j] = saved + right[r + 1] * temp;
            saved = left[j - r] * temp;
        }
        ndu[j][j] = saved;
    }
    let mut ders = [[zero; M]; 3];
    for j in 0..=p {
        ders[0][j] = ndu[j][p];
    }
    let pi = p as isize;
    let mut a = [[zero; M]; 2];
    for r in 0..=p {
        let ri = r as isize;
        let (mut s1, mut s2) = (0usize, 1usize);
        a[0][0] = one;
        for k in 1..=nd {
            let ki = k as isize;
            let mut d = zero;
            let rk = ri - ki;
            let pk = pi - ki;
            if ri >= ki {
                a[s2][0] = a[s1][0] / ndu[(pk + 1) as usize][rk as usize];
                d = a[s2][0] * ndu[rk as usize][pk as usize];
            }
            let j1: isize = if rk >= -1 { 1 } else { -rk };
            let j2: isize = if ri - 1 <= pk { ki - 1 } else { pi - ri };
            let mut j = j1;
            while j <= j2 {
                let ju = j as usize;
                a[s2][ju] = (a[s1][ju] - a[s1][ju - 1]) / ndu[(pk + 1) as usize][(rk + j) as usize];
                d += a[s2][ju] * ndu[(rk + j) as usize][pk as usize];
                j += 1;
            }
            if ri <= pk {
                a[s2][k] = -a[s1][k - 1] / ndu[(pk + 1) as usize][r];
                d += a[s2][k] * ndu[r][pk as usize];
            }
            ders[k][r] = d;
            std::mem::swap(&mut s1, &mut s2);
        }
    }
    // Multiply by p!/(p−k)!.
    let mut f = p as f64;
    for (k, row) in ders.iter_mut().enumerate().take(nd + 1).skip(1) {
        for d in row.iter_mut().take(p + 1) {
            *d *= f;
        }
        f *= (p - k) as f64;
    }
    ders
}

/// Tensor-product NURBS patch. Control point `(i, j)` has index `i` along `u` (row) and `j` along
/// `v`; `knots_u` has `n_u + degree_u + 1` entries, open (clamped), non-decreasing, interior
/// multiplicity at most the degree. The domain is `[knots_u[p], knots_u[n_u]] × [knots_v[q],
/// knots_v[n_v]]`.
///
/// Control points are Cartesian `Pᵢⱼ` with weights `wᵢⱼ > 0`; evaluation works on the homogeneous
/// points `(wᵢⱼ Pᵢⱼ, wᵢⱼ)`. The normal of eq (66) is `x_u × x_v` normalised, so its side follows
/// the ordering of the control net. Design parameters, for each `(i, j)` in row-major order:
/// `cp[i][j].x`, `cp[i][j].y`, `cp[i][j].z`, `weight[i][j]`.
#[derive(Clone, Debug, PartialEq)]
pub struct NurbsSurface<T> {
    degree: [usize; 2],
    knots: [Vec<f64>; 2],
    n: [usize; 2],
    points: Vec<Vector3<T>>,
    weights: Vec<T>,
}

const DIR: [&str; 2] = ["u", "v"];

impl<T: Real> NurbsSurface<T> {
    /// Validated constructor: `points[i][j]` and `weights[i][j]` with `i` along `u`.
    pub fn new(
        degree: [usize; 2],
        knots: [Vec<f64>; 2],
        points: Vec<Vec<Vector3<T>>>,
        weights: Vec<Vec<T>>,
    ) -> Result<Self, GeometryError> {
        let n_u = points.len();
        if n_u == 0 {
            return Err(GeometryError::ControlNet {
                field: "control_points".into(),
                got: 0,
                expected: "at least degree_u + 1 rows".into(),
            });
        }
        let n_v = points[0].len();
        for (i, row) in points.iter().enumerate() {
            if row.len() != n_v || n_v == 0 {
                return Err(GeometryError::ControlNet {
                    field: format!("control_points[{i}]"),
                    got: row.len(),
                    expected: format!("{} points, as in row 0 (at least degree_v + 1)", n_v.max(1)),
                });
            }
        }
        if weights.len() != n_u {
            return Err(GeometryError::ControlNet {
                field: "weights".into(),
                got: weights.len(),
                expected: format!("{n_u} rows, one per control-point row"),
            });
        }
        for (i, row) in weights.iter().enumerate() {
            if row.len() != n_v {
                return Err(GeometryError::ControlNet {
                    field: format!("weights[{i}]"),
                    got: row.len(),
                    expected: format!("{n_v} weights, one per control point"),
                });
            }
        }
        let s = NurbsSurface {
            degree,
            knots,
            n: [n_u, n_v],
            points: points.into_iter().flatten().collect(),
            weights: weights.into_iter().flatten().collect(),
        };
        s.validate()?;
        Ok(s)
    }

    /// Degrees `[p, q]`.
    pub fn degree(&self) -> [usize; 2] {
        self.degree
    }
    /// Knot vectors `[knots_u, knots_v]`.
    pub fn knots(&self) -> &[Vec<f64>; 2] {
        &self.knots
    }
    /// Number of control points `[n_u, n_v]`.
    pub fn n_points(&self) -> [usize; 2] {
        self.n
    }
    /// Control point `(i, j)` (Cartesian), if it exists.
    pub fn point(&self, i: usize, j: usize) -> Option<Vector3<T>> {
        (i < self.n[0] && j < self.n[1]).then(|| self.points[i * self.n[1] + j])
    }
    /// Weight `(i, j)`, if it exists.
    pub fn weight(&self, i: usize, j: usize) -> Option<T> {
        (i < self.n[0] && j < self.n[1]).then(|| self.weights[i * self.n[1] + j])
    }

    /// Parameter box from the clamped knot vectors.
    pub fn domain(&self) -> [[f64; 2]; 2] {
        let r = |d: usize| {
            let (k, p, n) = (&self.knots[d], self.degree[d], self.n[d]);
            match (k.get(p), k.get(n)) {
                (Some(&a), Some(&b)) => [a, b],
                _ => [f64::NAN, f64::NAN],
            }
        };
        [r(0), r(1)]
    }

    /// Degrees, knot vectors (length, order, clamping, interior multiplicity, non-empty range),
    /// finite coordinates and positive weights.
    pub fn validate(&self) -> Result<(), GeometryError> {
        for (d, &dn) in DIR.iter().enumerate() {
            let p = self.degree[d];
            if !(1..=MAX_DEGREE).contains(&p) {
                return Err(GeometryError::Degree {
                    field: format!("degree_{dn}"),
                    value: p,
                });
            }
            let n = self.n[d];
            if n < p + 1 {
                return Err(GeometryError::ControlNet {
                    field: if d == 0 {
                        "control_points".into()
                    } else {
                        "control_points[0]".into()
                    },
                    got: n,
                    expected: format!(
                        "at least degree_{dn} + 1 = {} control points along {dn}",
                        p + 1
                    ),
                });
            }
            check_knots(&format!("knots_{dn}"), &self.knots[d], n, p)?;
        }
        if self.points.len() != self.n[0] * self.n[1] || self.weights.len() != self.points.len() {
            return Err(GeometryError::ControlNet {
                field: "control_points".into(),
                got: self.points.len(),
                expected: format!("{} × {} points and weights", self.n[0], self.n[1]),
            });
        }
        for i in 0..self.n[0] {
            for j in 0..self.n[1] {
                let k = i * self.n[1] + j;
                let p = &self.points[k];
                for (c, name) in p.iter().zip(["x", "y", "z"]) {
                    check_finite(&format!("cp[{i}][{j}].{name}"), c.value())?;
                }
                let w = self.weights[k].value();
                let field = format!("weight[{i}][{j}]");
                check_finite(&field, w)?;
                if w <= 0.0 {
                    return Err(GeometryError::NonPositiveWeight { field, value: w });
                }
            }
        }
        Ok(())
    }

    /// Position and derivatives at `(u, v)`: basis derivatives by A2.3, homogeneous surface
    /// derivatives `Aᵏˡ`, `wᵏˡ` (k + l ≤ 2), rational derivatives by A4.4.
    pub fn eval(&self, u: T, v: T) -> SurfaceDerivs<T> {
        let [p, q] = self.degree;
        let [nu, nv] = self.n;
        let su = find_span(nu, p, u.value(), &self.knots[0]);
        let sv = find_span(nv, q, v.value(), &self.knots[1]);
        let nan = T::cst(f64::NAN);
        let valid = |s: usize, p: usize, k: &[f64]| {
            (1..=MAX_DEGREE).contains(&p) && s >= p && s + p < k.len() && k[s] < k[s + 1]
        };
        if !valid(su, p, &self.knots[0])
            || !valid(sv, q, &self.knots[1])
            || self.points.len() != nu * nv
            || self.weights.len() != self.points.len()
            || su >= nu
            || sv >= nv
        {
            let z = Vector3::from_element(nan);
            return SurfaceDerivs {
                x: z,
                xu: z,
                xv: z,
                xuu: z,
                xuv: z,
                xvv: z,
            };
        }
        let bu = basis_derivs_unchecked(su, u, p, &self.knots[0]);
        let bv = basis_derivs_unchecked(sv, v, q, &self.knots[1]);
        let zero = T::zero();
        let z3 = Vector3::zeros();
        // Homogeneous derivatives a[k][l] (Cartesian part) and w[k][l], k + l ≤ 2.
        let mut a = [[z3; 3]; 3];
        let mut w = [[zero; 3]; 3];
        for (jj, j) in (sv - q..=sv).enumerate() {
            // Curve derivatives along u of row j: temp[k] = Σ_i N_i^(k)(u) Pʷ_ij.
            let mut ta = [z3; 3];
            let mut tw = [zero; 3];
            for (ii, i) in (su - p..=su).enumerate() {
                let idx = i * nv + j;
                let wij = self.weights[idx];
                let pw = self.points[idx] * wij;
                for k in 0..3 {
                    ta[k] += pw * bu[k][ii];
                    tw[k] += wij * bu[k][ii];
                }
            }
            for k in 0..3 {
                for l in 0..(3 - k) {
                    a[k][l] += ta[k] * bv[l][jj];
                    w[k][l] += tw[k] * bv[l][jj];
                }
            }
        }
        // A4.4: SKL = (Aᵏˡ − Σ_{j=1..l} C(l,j) w⁰ʲ S^{k,l−j}
        //              − Σ_{i=1..k} C(k,i) [w^{i0} S^{k−i,l} + Σ_{j=1..l} C(l,j) w^{ij} S^{k−i,l−j}]) / w⁰⁰
        const BIN: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 2.0, 1.0]];
        let mut s = [[z3; 3]; 3];
        for k in 0..3 {
            for l in 0..(3 - k) {
                let mut val = a[k][l];
                for j in 1..=l {
                    val -= s[k][l - j] * (w[0][j] * BIN[l][j]);
                }
                for i in 1..=k {
                    val -= s[k - i][l] * (w[i][0] * BIN[k][i]);
                    let mut v2 = z3;
                    for j in 1..=l {
                        v2 += s[k - i][l - j] * (w[i][j] * BIN[l][j]);
                    }
                    val -= v2 * T::cst(BIN[k][i]);
                }
                s[k][l] = val / w[0][0];
            }
        }
        SurfaceDerivs {
            x: s[0][0],
            xu: s[1][0],
            xv: s[0][1],
            xuu: s[2][0],
            xuv: s[1][1],
            xvv: s[0][2],
        }
    }

    pub(crate) fn n_scalars(&self) -> usize {
        4 * self.n[0] * self.n[1]
    }

    pub(crate) fn scalars(&self) -> Vec<T> {
        let mut out = Vec::with_capacity(self.n_scalars());
        for (p, w) in self.points.iter().zip(&self.weights) {
            out.extend([p.x, p.y, p.z, *w]);
        }
        out
    }

    pub(crate) fn names(&self) -> Vec<String> {
        let mut out = Vec::with_capacity(self.n_scalars());
        for i in 0..self.n[0] {
            for j in 0..self.n[1] {
                for c in ["x", "y", "z"] {
                    out.push(format!("cp[{i}][{j}].{c}"));
                }
                out.push(format!("weight[{i}][{j}]"));
            }
        }
        out
    }

    /// Same structure, scalars `p` (length [`Self::n_scalars`], checked by the caller).
    pub(crate) fn with_scalars<U: Real>(&self, p: &[U]) -> NurbsSurface<U> {
        let (points, weights) = p
            .chunks_exact(4)
            .map(|c| (Vector3::new(c[0], c[1], c[2]), c[3]))
            .unzip();
        NurbsSurface {
            degree: self.degree,
            knots: self.knots.clone(),
            n: self.n,
            points,
            weights,
        }
    }
}

/// Knot vector checks, in order: finite, length, non-decreasing, clamped, non-empty range,
/// interior multiplicity.
fn check_knots(field: &str, k: &[f64], n: usize, p: usize) -> Result<(), GeometryError> {
    for (i, &x) in k.iter().enumerate() {
        check_finite(&format!("{field}[{i}]"), x)?;
    }
    let expected = n + p + 1;
    if k.len() != expected {
        return Err(GeometryError::KnotCount {
            field: field.into(),
            value: k.len(),
            expected,
            n_points: n,
            degree: p,
        });
    }
    for i in 1..k.len() {
        if k[i] < k[i - 1] {
            return Err(GeometryError::KnotsDecreasing {
                field: field.into(),
                index: i,
                value: k[i],
                previous: k[i - 1],
            });
        }
    }
    let m = k.len() - 1;
    if k[..=p].iter().any(|&x| x != k[0]) || k[m - p..].iter().any(|&x| x != k[m]) {
        return Err(GeometryError::KnotsNotClamped {
            field: field.into(),
            knots: k.to_vec(),
            multiplicity: p + 1,
        });
    }
    if k[m] <= k[0] {
        return Err(GeometryError::InvalidRange {
            field: field.into(),
            start: k[0],
            end: k[m],
            expected: "a non-empty knot range, last knot > first knot".into(),
        });
    }
    // Multiplicity of every distinct knot: exactly p + 1 at the ends, at most p inside.
    let mut i = 0;
    while i <= m {
        let mut j = i;
        while j < m && k[j + 1] == k[i] {
            j += 1;
        }
        let mult = j - i + 1;
        let end = i == 0 || j == m;
        if (end && mult != p + 1) || (!end && mult > p) {
            return Err(GeometryError::KnotMultiplicity {
                field: field.into(),
                value: k[i],
                multiplicity: mult,
                expected: if end {
                    format!("exactly degree + 1 = {} at an end knot", p + 1)
                } else {
                    format!("at most the degree {p} at an interior knot")
                },
            });
        }
        i = j + 1;
    }
    Ok(())
}

impl NurbsSurface<f64> {
    /// `∂/∂p` of [`NurbsSurface::eval`] for design parameter `k` (ordered as
    /// [`NurbsSurface::names`]: `cp[i][j].x|y|z`, `weight[i][j]`), hand-derived.
    ///
    /// With `W = Σ Nₖₗ wₖₗ` and `g = Nᵢⱼ / W` (so the rational basis function is
    /// `Rᵢⱼ = wᵢⱼ g`): a control-point coordinate enters linearly, `∂S/∂Pᵢⱼ = Rᵢⱼ I`, and a
    /// weight rationally, `∂S/∂wᵢⱼ = g (Pᵢⱼ − S)`. The parametric derivatives follow by the
    /// Leibniz rule, with `g`'s from the quotient rule of A4.4 applied to the scalar
    /// `Nᵢⱼ = g W`. Zero where `(i, j)` has no support on the span of `(u, v)`.
    pub(crate) fn design_velocity(&self, k: usize, u: f64, v: f64) -> SurfaceDerivs<f64> {
        let s = self.eval(u, v);
        let z3 = Vector3::zeros();
        let zero = SurfaceDerivs {
            x: z3,
            xu: z3,
            xv: z3,
            xuu: z3,
            xuv: z3,
            xvv: z3,
        };
        if !s.x.iter().all(|c| c.is_finite()) || k >= self.n_scalars() {
            // eval already screened the structure; keep its NaN signal.
            return SurfaceDerivs {
                x: Vector3::from_element(f64::NAN),
                ..zero
            };
        }
        let [p, q] = self.degree;
        let [nu, nv] = self.n;
        let (cp, comp) = (k / 4, k % 4);
        let (i, j) = (cp / nv, cp % nv);
        let su = find_span(nu, p, u, &self.knots[0]);
        let sv = find_span(nv, q, v, &self.knots[1]);
        if i + p < su || i > su || j + q < sv || j > sv {
            return zero;
        }
        let bu = basis_derivs_unchecked(su, u, p, &self.knots[0]);
        let bv = basis_derivs_unchecked(sv, v, q, &self.knots[1]);
        let (ii, jj) = (i + p - su, j + q - sv);
        // Denominator derivatives w[k][l] = Σ N⁽ᵏ⁾ N⁽ˡ⁾ w and numerator a[k][l] = Nᵢ⁽ᵏ⁾ Nⱼ⁽ˡ⁾.
        let mut w = [[0.0; 3]; 3];
        for (b, jb) in (sv - q..=sv).enumerate() {
            for (a, ia) in (su - p..=su).enumerate() {
                let wt = self.weights[ia * nv + jb];
                for kk in 0..3 {
                    for l in 0..(3 - kk) {
                        w[kk][l] += bu[kk][a] * bv[l][b] * wt;
                    }
                }
            }
        }
        const BIN: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 2.0, 1.0]];
        let mut g = [[0.0; 3]; 3];
        for kk in 0..3 {
            for l in 0..(3 - kk) {
                let mut val = bu[kk][ii] * bv[l][jj];
                for m in 1..=l {
                    val -= g[kk][l - m] * w[0][m] * BIN[l][m];
                }
                for n in 1..=kk {
                    val -= g[kk - n][l] * w[n][0] * BIN[kk][n];
                    let mut v2 = 0.0;
                    for m in 1..=l {
                        v2 += g[kk - n][l - m] * w[n][m] * BIN[l][m];
                    }
                    val -= v2 * BIN[kk][n];
                }
                g[kk][l] = val / w[0][0];
            }
        }
        if comp < 3 {
            let mut e = Vector3::zeros();
            e[comp] = self.weights[cp];
            return SurfaceDerivs {
                x: e * g[0][0],
                xu: e * g[1][0],
                xv: e * g[0][1],
                xuu: e * g[2][0],
                xuv: e * g[1][1],
                xvv: e * g[0][2],
            };
        }
        let d = self.points[cp] - s.x;
        SurfaceDerivs {
            x: d * g[0][0],
            xu: d * g[1][0] - s.xu * g[0][0],
            xv: d * g[0][1] - s.xv * g[0][0],
            xuu: d * g[2][0] - s.xu * (2.0 * g[1][0]) - s.xuu * g[0][0],
            xuv: d * g[1][1] - s.xv * g[1][0] - s.xu * g[0][1] - s.xuv * g[0][0],
            xvv: d * g[0][2] - s.xv * (2.0 * g[0][1]) - s.xvv * g[0][0],
        }
    }
}
