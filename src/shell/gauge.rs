//! Coefficient modes that the RK field does not see, and the rows that fix them
//! (docs/stability.md §6).
//!
//! The cubic B-spline kernel of half-width `a` has knots `a/2` apart; its Fourier transform
//! `sinc⁴(ω a/4)` vanishes at the two-spacing wavelength `ω = π/h` when `a` is a multiple of
//! `4h`, with a zero of fourth order, so on a regular lattice the RK functions satisfy
//! `Σ_i (−1)^i Ψ_I = 0` and `Σ_i (−1)^i ∇Ψ_I = 0` along a lattice line wherever the alternating
//! sum is complete. Symmetry planes on the two edges across the line mirror it into a complete
//! sum: a translation coefficient field `ū_I = (−1)^i v` on one lattice line (a fixed vector `v`
//! that both reflections keep) then passes no displacement and no strain to any point. The
//! tangent has one exact null vector per such line, while the field, and so the solution, is
//! unique: the coefficients are not.
//!
//! The trial field cannot see the mode; the test functions can when they are corrected (VCI
//! changes the test gradients of each particle by its own amount), so the system is singular
//! and its residual not orthogonal to the mode. [`gauge_modes`] finds the modes and
//! [`super::problem::ShellProblem`] adds one row `Σ_i (−1)^i v·ū_I = 0` per mode, held by a
//! Lagrange multiplier like every other linear constraint: the row fixes the coefficient
//! representation (the field is unchanged when the mode is exactly invisible), and its
//! multiplier takes the residual's component along the mode, i.e. the one test equation per
//! mode that the trial space cannot meet is the one dropped. The bordered tangent is then
//! regular; the Newton updates, the design sensitivity equation of every derivative path and
//! the output all carry the rows as they carry a support's.
//!
//! Detection, for a model whose real particles form a complete lattice in the parameter box
//! (no jitter): for each lattice line along `u` and along `v`, candidate patterns `± E(s_I) c`
//! alternating from particle to particle with a smooth envelope `E` (Legendre polynomials of
//! degree 0–3 in the position `s` along the line) and a Cartesian direction `c`; for the
//! translations `ū_I = ± E c`, for the rotations the `α_I` whose director increment `α_I × d_I`
//! is the tangential part of `± E c` (an alternating pattern of the rotation parameters
//! themselves is not invisible: the lamina frames turn, and flip at a plane). The fields of the
//! candidates (value and spacing-scaled gradient at every quadrature point, images mapped by
//! their reflections) give per line and field the Gram matrices `M_alt` of the alternating and
//! `M_const` of the same patterns without the alternation; a mode's transfer is the square root
//! of a generalised eigenvalue `t²` of `M_alt v = t² M_const v`: how much of the alternating
//! pattern the points see relative to the smooth one. Modes with `t <` [`INVISIBLE_TRANSFER`]
//! are fixed. An exactly invisible mode gives `t` at round-off and a row that leaves the field
//! unchanged; a nearly invisible one (a support just off a multiple of 4) a row that holds a
//! pattern the field barely sees.

use super::constraints::{LinearConstraint, RowKind};
use super::model::ShellModel;
use super::point::DOFS_PER_PARTICLE;
use nalgebra::{DMatrix, DVector, Matrix3, SymmetricEigen, Vector3};

/// Alternating patterns whose transfer (relative to the same pattern without alternation) is
/// below this are fixed by a row. On the quarter hemisphere (17 × 17, quadratic basis, 2 × 2
/// Gauss points, symmetry planes on both `u` edges) the constant-envelope `ū_z` pattern of each
/// line along `u` passes round-off at support 4 (≤ 1e-16) and 8e-4 at 4.1; at support 4 the
/// 70 patterns below the bound pass at most 1.9e-3, at 4.2 and 3.8 none is below it (4.2 runs
/// without rows, 4 and 4.1 fail the solver's singularity probe without them).
pub const INVISIBLE_TRANSFER: f64 = 2e-3;

/// One coefficient mode the field does not see: an alternating translation pattern along a
/// lattice line.
#[derive(Clone, Debug, PartialEq)]
pub struct GaugeMode {
    /// What the mode is, for reports (line, direction, vector).
    pub label: String,
    /// `(generalised DOF, coefficient)` of the unit-amplitude pattern.
    pub terms: Vec<(usize, f64)>,
    /// A translation or a rotation pattern.
    pub kind: RowKind,
    /// The transfer `t` of the pattern (module documentation).
    pub transfer: f64,
}

impl GaugeMode {
    /// The row `Σ terms · q = 0` that fixes the mode.
    pub fn constraint(&self) -> LinearConstraint {
        LinearConstraint {
            label: self.label.clone(),
            terms: self.terms.clone(),
            value: 0.0,
            kind: self.kind,
        }
    }
}

/// Distinct sorted values of `xs` (to `tol`), and each value's index.
fn lattice_axis(xs: impl Iterator<Item = f64>, tol: f64) -> (Vec<f64>, Vec<usize>) {
    let xs: Vec<f64> = xs.collect();
    let mut sorted = xs.clone();
    sorted.sort_by(f64::total_cmp);
    let mut levels: Vec<f64> = Vec::new();
    for x in sorted {
        if levels.last().is_none_or(|l| x - l > tol) {
            levels.push(x);
        }
    }
    let index = xs
        .iter()
        .map(|x| levels.partition_point(|l| *l < x - tol))
        .collect();
    (levels, index)
}

/// The lattice indices `(i, j)` of the real particles of `model`, with the spacings, when they
/// fill a complete `n_u × n_v` lattice (each site once, uniform spacing in each direction);
/// `None` otherwise.
/// `(indices, counts, spacings, first levels)`.
type Lattice = (Vec<[usize; 2]>, [usize; 2], [f64; 2], [f64; 2]);

fn lattice(model: &ShellModel) -> Option<Lattice> {
    let uv = &model.particle_uv;
    let d = model.domain;
    let mut index = vec![[0usize; 2]; uv.len()];
    let mut counts = [0usize; 2];
    let mut spacing = [0.0; 2];
    let mut origin = [0.0; 2];
    for a in 0..2 {
        let tol = 1e-9 * (d[a][1] - d[a][0]).abs();
        let (levels, idx) = lattice_axis(uv.iter().map(|p| p[a]), tol);
        if levels.len() < 2 {
            return None;
        }
        let h = (levels[levels.len() - 1] - levels[0]) / (levels.len() - 1) as f64;
        if levels
            .iter()
            .enumerate()
            .any(|(k, l)| (l - levels[0] - k as f64 * h).abs() > tol)
        {
            return None;
        }
        for (p, i) in idx.into_iter().enumerate() {
            index[p][a] = i;
        }
        counts[a] = levels.len();
        spacing[a] = h;
        origin[a] = levels[0];
    }
    if counts[0] * counts[1] != uv.len() {
        return None;
    }
    let mut seen = vec![false; uv.len()];
    for ij in &index {
        let s = &mut seen[ij[1] * counts[0] + ij[0]];
        if *s {
            return None;
        }
        *s = true;
    }
    Some((index, counts, spacing, origin))
}

/// Smooth envelopes of the alternating patterns along a line: Legendre polynomials of degree
/// `0..ENVELOPES` in the position along the line (`−1` to `1`). A complete alternating sum
/// annihilates a polynomial envelope up to degree 3 at supports of 4 spacings (`sinc⁴` has a
/// zero of fourth order), and a smooth tangent field (a director increment) is such an envelope.
const ENVELOPES: usize = 4;

/// Cartesian directions of the patterns: each translation pattern is `ū_I = ± E(s_I) c`, each
/// rotation pattern the director increment `α_I × d_I = ± E(s_I) (c − (c·d_I) d_I)`.
const DIRECTIONS: usize = 3;

/// Candidates per line and field.
const CANDIDATES: usize = ENVELOPES * DIRECTIONS;

fn legendre(k: usize, s: f64) -> f64 {
    match k {
        0 => 1.0,
        1 => s,
        2 => 1.5 * s * s - 0.5,
        _ => 2.5 * s * s * s - 1.5 * s,
    }
}

/// The generalised eigenpairs `t² ≥ 0`, `v` of `M_alt v = t² M_const v` for symmetric positive
/// semi-definite matrices, on the range of `M_const` (directions with eigenvalues below `1e-10`
/// of its largest are patterns the points cannot tell apart even without alternation, left
/// out), `v` scaled to unit largest entry.
fn transfers(m_alt: &DMatrix<f64>, m_const: &DMatrix<f64>) -> Vec<(f64, DVector<f64>)> {
    let sym = |m: &DMatrix<f64>| (m + m.transpose()) * 0.5;
    let c = SymmetricEigen::new(sym(m_const));
    let top = c.eigenvalues.amax();
    let kept: Vec<usize> = (0..c.eigenvalues.len())
        .filter(|&k| top > 0.0 && c.eigenvalues[k] > 1e-10 * top)
        .collect();
    if kept.is_empty() {
        return Vec::new();
    }
    // Columns u_k / √λ_k of the kept eigenvectors: the whitening map W with Wᵀ M_const W = I.
    let w = DMatrix::from_fn(m_const.nrows(), kept.len(), |r, k| {
        c.eigenvectors[(r, kept[k])] / c.eigenvalues[kept[k]].sqrt()
    });
    let b = SymmetricEigen::new(sym(&(w.transpose() * m_alt * &w)));
    (0..kept.len())
        .map(|k| {
            let mut v: DVector<f64> = &w * b.eigenvectors.column(k);
            v /= v.amax();
            (b.eigenvalues[k].max(0.0).sqrt(), v)
        })
        .collect()
}

/// The coefficient modes of `model` that its RK field does not see (module documentation),
/// in the order: lines along `u` by `v` index (translations, then rotations), then lines along
/// `v` by `u` index.
pub fn gauge_modes(model: &ShellModel) -> Vec<GaugeMode> {
    let Some((index, counts, h, origin)) = lattice(model) else {
        return Vec::new();
    };
    // The cubic B-spline's blind spot is at supports of (near) a multiple of 4 spacings only.
    let kernel = model.shape_functions.kernel();
    let supports = model.shape_functions.supports();
    if !supports
        .iter()
        .any(|s| (0..2).any(|a| kernel.blind_at(s[a] / h[a])))
    {
        return Vec::new();
    }
    let n = model.n_particles();
    // Per real particle and direction c: the rotation coefficients (α1, α2) whose director
    // increment is the tangential part of c.
    let alpha: Vec<[[f64; 2]; DIRECTIONS]> = (0..n)
        .map(|j| {
            let st = model.particle_state(j);
            let mut out = [[0.0; 2]; DIRECTIONS];
            for (c, o) in out.iter_mut().enumerate() {
                let mut w = Vector3::zeros();
                w[c] = 1.0;
                let w = w - st.d * st.d.dot(&w);
                for (k, ok) in o.iter_mut().enumerate() {
                    let g = st.e[k].cross(&st.d);
                    *ok = g.dot(&w) / g.norm_squared();
                }
            }
            out
        })
        .collect();
    let mut modes = Vec::new();
    // Per line touched by a point: the fields (value and scaled gradient) of the alternating
    // and of the constant candidates, translations then rotations.
    type Fields = [[Vector3<f64>; 3]; 2 * CANDIDATES];
    let mut fields: Vec<(usize, Box<Fields>, Box<Fields>)> = Vec::new();
    // Direction `a` alternates along lattice axis `a`; its lines are indexed by the other axis.
    for a in 0..2 {
        let b = 1 - a;
        let n_lines = counts[b];
        let pos = |i: usize| 2.0 * i as f64 / (counts[a] - 1) as f64 - 1.0;
        let zero = || DMatrix::<f64>::zeros(CANDIDATES, CANDIDATES);
        // Per line and field: Gram matrices of the alternating and of the constant candidates
        // (the displacement and the director increment are distinct fields: no cross terms).
        let mut m_alt = vec![[zero(), zero()]; n_lines];
        let mut m_const = vec![[zero(), zero()]; n_lines];
        for p in &model.points {
            fields.clear();
            for (&j, sd) in p.neighbours.iter().zip(&p.shape) {
                // The shape-function particle's state (an image's mapped from its source) and
                // the map of its DOFs: ū_img = Q ū, α_img = det(Q) α.
                let st = model.particle_state(j);
                let (src, q, det) = if j < n {
                    (j, Matrix3::identity(), 1.0)
                } else {
                    let im = &model.symmetry.images[j - n];
                    (im.source, im.map, im.det)
                };
                let ij = index[src];
                let sign = if ij[a] % 2 == 0 { 1.0 } else { -1.0 };
                let f = [sd.psi, sd.dpsi[0] * h[0], sd.dpsi[1] * h[1]];
                let slot = match fields.iter().position(|e| e.0 == ij[b]) {
                    Some(s) => s,
                    None => {
                        let z = Box::new([[Vector3::zeros(); 3]; 2 * CANDIDATES]);
                        fields.push((ij[b], z.clone(), z));
                        fields.len() - 1
                    }
                };
                let e = &mut fields[slot];
                let s = pos(ij[a]);
                for (c, &[a1, a2]) in alpha[src].iter().enumerate() {
                    let ut: Vector3<f64> = q.column(c).into();
                    let ur = (st.e[0] * a1 + st.e[1] * a2).cross(&st.d) * det;
                    for k in 0..ENVELOPES {
                        let env = legendre(k, s);
                        let cand = k * DIRECTIONS + c;
                        for (m, fm) in f.iter().enumerate() {
                            e.1[cand][m] += ut * (sign * env * fm);
                            e.2[cand][m] += ut * (env * fm);
                            e.1[CANDIDATES + cand][m] += ur * (sign * env * fm);
                            e.2[CANDIDATES + cand][m] += ur * (env * fm);
                        }
                    }
                }
            }
            let gram = |x: &Fields, r: usize, c: usize| -> f64 {
                (0..3).map(|m| x[r][m].dot(&x[c][m])).sum()
            };
            for (line, alt, cst) in &fields {
                for fld in 0..2 {
                    let o = fld * CANDIDATES;
                    for r in 0..CANDIDATES {
                        for c in 0..CANDIDATES {
                            m_alt[*line][fld][(r, c)] += gram(alt, o + r, o + c);
                            m_const[*line][fld][(r, c)] += gram(cst, o + r, o + c);
                        }
                    }
                }
            }
        }
        let (along, across) = (["u", "v"][a], ["v", "u"][a]);
        for line in 0..n_lines {
            for fld in 0..2 {
                for (t, v) in transfers(&m_alt[line][fld], &m_const[line][fld]) {
                    if t >= INVISIBLE_TRANSFER {
                        continue;
                    }
                    let mut terms = Vec::new();
                    for (p, ij) in index.iter().enumerate() {
                        if ij[b] != line {
                            continue;
                        }
                        let sign = if ij[a] % 2 == 0 { 1.0 } else { -1.0 };
                        let s = pos(ij[a]);
                        let mut x = [0.0; 3];
                        for k in 0..ENVELOPES {
                            for c in 0..DIRECTIONS {
                                let vc = v[k * DIRECTIONS + c] * sign * legendre(k, s);
                                if fld == 0 {
                                    x[c] += vc;
                                } else {
                                    x[0] += vc * alpha[p][c][0];
                                    x[1] += vc * alpha[p][c][1];
                                }
                            }
                        }
                        let width = if fld == 0 { 3 } else { 2 };
                        let first = if fld == 0 { 0 } else { 3 };
                        for (c, xc) in x.iter().enumerate().take(width) {
                            if xc.abs() > 1e-12 {
                                terms.push((DOFS_PER_PARTICLE * p + first + c, *xc));
                            }
                        }
                    }
                    let what = ["ū", "α"][fld];
                    modes.push(GaugeMode {
                        label: format!(
                            "gauge: {what} alternating along {along} on the particle line \
                             {across} = {:.6} (field transfer {t:.1e})",
                            origin[b] + line as f64 * h[b]
                        ),
                        terms,
                        kind: [RowKind::Displacement, RowKind::Rotation][fld],
                        transfer: t,
                    });
                }
            }
        }
    }
    modes
}
