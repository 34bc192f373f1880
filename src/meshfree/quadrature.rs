//! Quadrature for the meshfree shell: 1-D Gauss–Legendre and Gauss–Lobatto rules, background-cell
//! quadrature on a parameter box, and through-thickness rules.
//!
//! **1-D rules** on `[−1, 1]` are computed, not tabulated: Newton's method on the Legendre
//! polynomials (three-term recurrence) from Chebyshev starting values, iterated until the update
//! is below `1e-16` and then once more, and symmetrised (`x_i = −x_{n−1−i}`, equal weights of
//! mirrored nodes). Gauss–Legendre with `n` points (supported `1..=10`) integrates polynomials of
//! degree `≤ 2n − 1` exactly; Gauss–Lobatto with `n` points (supported `2..=7`, the end points
//! included) integrates degree `≤ 2n − 3` exactly.
//!
//! **Background cells** ([`CellQuadrature`]): the box is split into `n_u × n_v` equal cells, each
//! with a tensor-product Gauss rule. The weights are *parameter-domain* weights (they sum to the
//! box area); the surface area element `|x̄_,1 × x̄_,2|` is applied later by the shell.
//!
//! **Through the thickness** ([`ThicknessRule`]): `ζ ∈ [−1, 1]` and weights summing to 2 (the
//! factor `t/2` of the thickness map is applied by the shell).

use super::particles::{ParamBox, ParticleGrid};

/// Largest supported Gauss–Legendre point count.
pub const MAX_GAUSS_POINTS: usize = 10;
/// Largest supported Gauss–Lobatto point count.
pub const MAX_LOBATTO_POINTS: usize = 7;

/// Errors of the quadrature constructors; each names the offending parameter and its value.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum QuadratureError {
    /// Point count outside the supported range of the rule.
    #[error("{rule} rule: unsupported number of points n = {n} (supported {min}..={max})")]
    UnsupportedPoints {
        /// Rule family ("Gauss–Legendre" or "Gauss–Lobatto").
        rule: &'static str,
        /// Requested points.
        n: usize,
        /// Smallest supported.
        min: usize,
        /// Largest supported.
        max: usize,
    },
    /// The parameter box is empty or not finite along one axis.
    #[error("cell quadrature: empty or non-finite parameter box along {axis}: [{lo}, {hi}]")]
    EmptyBox {
        /// "u" or "v".
        axis: &'static str,
        /// Lower bound.
        lo: f64,
        /// Upper bound.
        hi: f64,
    },
    /// A count parameter (cells) is zero.
    #[error("cell quadrature: {parameter} = {value} must be at least 1")]
    ZeroCount {
        /// Parameter name.
        parameter: &'static str,
        /// Its value.
        value: usize,
    },
}

/// A 1-D quadrature rule on `[−1, 1]`: nodes ascending, positive weights.
#[derive(Clone, Debug, PartialEq)]
pub struct Rule1d {
    /// Nodes, ascending.
    pub nodes: Vec<f64>,
    /// Weights (sum 2).
    pub weights: Vec<f64>,
}

impl Rule1d {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }
    /// No points (never the case for a constructed rule).
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }
    /// `Σ w_i f(x_i)` on `[−1, 1]`.
    pub fn integrate(&self, f: impl Fn(f64) -> f64) -> f64 {
        self.nodes
            .iter()
            .zip(&self.weights)
            .map(|(&x, &w)| w * f(x))
            .sum()
    }
    /// Nodes and weights mapped to `[a, b]` (weights scaled by `(b − a)/2`).
    pub fn mapped(&self, a: f64, b: f64) -> (Vec<f64>, Vec<f64>) {
        let (c, h) = (0.5 * (a + b), 0.5 * (b - a));
        (
            self.nodes.iter().map(|&x| c + h * x).collect(),
            self.weights.iter().map(|&w| h * w).collect(),
        )
    }
}

/// `(P_n(x), P_{n−1}(x))` by the three-term recurrence (`n ≥ 1`).
fn legendre(n: usize, x: f64) -> (f64, f64) {
    let (mut p0, mut p1) = (1.0, x);
    for k in 2..=n {
        let kf = k as f64;
        let p2 = ((2.0 * kf - 1.0) * x * p1 - (kf - 1.0) * p0) / kf;
        p0 = p1;
        p1 = p2;
    }
    (p1, p0)
}

/// Make a rule exactly symmetric: average mirrored nodes/weights; the middle node of an odd rule
/// is 0.
fn symmetrise(nodes: &mut [f64], weights: &mut [f64]) {
    let n = nodes.len();
    for i in 0..n / 2 {
        let j = n - 1 - i;
        let x = 0.5 * (nodes[j] - nodes[i]);
        let w = 0.5 * (weights[i] + weights[j]);
        nodes[i] = -x;
        nodes[j] = x;
        weights[i] = w;
        weights[j] = w;
    }
    if n % 2 == 1 {
        nodes[n / 2] = 0.0;
    }
}

/// Gauss–Legendre rule with `n` points, `1 ≤ n ≤ 10`: exact for polynomials of degree `≤ 2n − 1`.
pub fn gauss_legendre(n: usize) -> Result<Rule1d, QuadratureError> {
    if !(1..=MAX_GAUSS_POINTS).contains(&n) {
        return Err(QuadratureError::UnsupportedPoints {
            rule: "Gauss–Legendre",
            n,
            min: 1,
            max: MAX_GAUSS_POINTS,
        });
    }
    let nf = n as f64;
    let mut nodes = vec![0.0; n];
    let mut weights = vec![0.0; n];
    for i in 0..n {
        // Root i (descending) of P_n; Tricomi-type starting value.
        let mut x = (std::f64::consts::PI * (i as f64 + 0.75) / (nf + 0.5)).cos();
        let mut dp = 1.0;
        for it in 0..100 {
            let (p, pm1) = legendre(n, x);
            // P_n'(x) = n (x P_n − P_{n−1}) / (x² − 1)
            dp = nf * (x * p - pm1) / (x * x - 1.0);
            let dx = p / dp;
            x -= dx;
            if dx.abs() < 1e-16 || it == 99 {
                let (p, pm1) = legendre(n, x);
                dp = nf * (x * p - pm1) / (x * x - 1.0);
                break;
            }
        }
        nodes[n - 1 - i] = x;
        weights[n - 1 - i] = 2.0 / ((1.0 - x * x) * dp * dp);
    }
    symmetrise(&mut nodes, &mut weights);
    Ok(Rule1d { nodes, weights })
}

/// Gauss–Lobatto rule with `n` points, `2 ≤ n ≤ 7`, end points `±1` included: exact for
/// polynomials of degree `≤ 2n − 3`. The interior nodes are the roots of `P'_{n−1}`, the weights
/// `2 / (n (n − 1) P_{n−1}(x_i)²)`.
pub fn gauss_lobatto(n: usize) -> Result<Rule1d, QuadratureError> {
    if !(2..=MAX_LOBATTO_POINTS).contains(&n) {
        return Err(QuadratureError::UnsupportedPoints {
            rule: "Gauss–Lobatto",
            n,
            min: 2,
            max: MAX_LOBATTO_POINTS,
        });
    }
    let m = n - 1; // degree of the Legendre polynomial
    let mf = m as f64;
    let mut nodes = vec![0.0; n];
    let mut weights = vec![0.0; n];
    nodes[0] = -1.0;
    nodes[m] = 1.0;
    for i in 1..m {
        // Chebyshev–Gauss–Lobatto starting value, descending in i.
        let mut x = (std::f64::consts::PI * i as f64 / mf).cos();
        for it in 0..100 {
            // f = P'_m, f' = P''_m from (1 − x²) P''_m = 2x P'_m − m(m+1) P_m.
            let (p, pm1) = legendre(m, x);
            let dp = mf * (x * p - pm1) / (x * x - 1.0);
            let ddp = (2.0 * x * dp - mf * (mf + 1.0) * p) / (1.0 - x * x);
            let dx = dp / ddp;
            x -= dx;
            if dx.abs() < 1e-16 || it == 99 {
                break;
            }
        }
        nodes[m - i] = x;
    }
    for (x, w) in nodes.iter().zip(weights.iter_mut()) {
        let (p, _) = legendre(m, *x);
        *w = 2.0 / (mf * (mf + 1.0) * p * p);
    }
    symmetrise(&mut nodes, &mut weights);
    Ok(Rule1d { nodes, weights })
}

/// Through-thickness rule for `ζ ∈ [−1, 1]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ThicknessRule {
    /// Gauss–Legendre with `n` points (`1..=10`); 2–3 for elastic runs.
    Gauss(usize),
    /// Gauss–Lobatto with `n` points (`2..=7`), surfaces included; 5 for plastic runs.
    Lobatto(usize),
}

impl ThicknessRule {
    /// The 1-D rule (`ζ_i`, `w_i`), weights summing to 2.
    pub fn rule(self) -> Result<Rule1d, QuadratureError> {
        match self {
            ThicknessRule::Gauss(n) => gauss_legendre(n),
            ThicknessRule::Lobatto(n) => gauss_lobatto(n),
        }
    }
    /// Number of points.
    pub fn points(self) -> usize {
        match self {
            ThicknessRule::Gauss(n) | ThicknessRule::Lobatto(n) => n,
        }
    }
}

/// Tensor-product Gauss quadrature on `n_u × n_v` equal background cells of a parameter box.
///
/// Points are ordered cell by cell (cell `c = i + n_u j`, `i` along u), and within a cell u
/// fastest; `weights` are parameter-domain weights `w_a w_b · |cell| / 4`.
#[derive(Clone, Debug, PartialEq)]
pub struct CellQuadrature {
    param_box: ParamBox,
    n_cells: [usize; 2],
    points_per_axis: usize,
    points: Vec<[f64; 2]>,
    weights: Vec<f64>,
    cells: Vec<usize>,
}

impl CellQuadrature {
    /// `n_cells_u × n_cells_v` cells on `param_box`, each with a `points_per_cell ×
    /// points_per_cell` Gauss–Legendre rule (`points_per_cell` is the count per direction,
    /// `1..=10`; 4 for the quadratic basis).
    pub fn new(
        param_box: ParamBox,
        n_cells_u: usize,
        n_cells_v: usize,
        points_per_cell: usize,
    ) -> Result<Self, QuadratureError> {
        for (axis, k) in [("u", 0), ("v", 1)] {
            let (lo, hi) = (param_box.lo[k], param_box.hi[k]);
            if !(lo.is_finite() && hi.is_finite() && hi > lo) {
                return Err(QuadratureError::EmptyBox { axis, lo, hi });
            }
        }
        for (parameter, value) in [("n_cells_u", n_cells_u), ("n_cells_v", n_cells_v)] {
            if value == 0 {
                return Err(QuadratureError::ZeroCount { parameter, value });
            }
        }
        let rule = gauss_legendre(points_per_cell)?;
        let ng = rule.len();
        let n_cells = [n_cells_u, n_cells_v];
        let total = n_cells_u * n_cells_v * ng * ng;
        let mut points = Vec::with_capacity(total);
        let mut weights = Vec::with_capacity(total);
        let mut cells = Vec::with_capacity(total);
        let edge = |k: usize, i: usize| -> f64 {
            if i == n_cells[k] {
                param_box.hi[k] // exact last edge, no accumulated round-off
            } else {
                param_box.lo[k] + (param_box.hi[k] - param_box.lo[k]) * i as f64 / n_cells[k] as f64
            }
        };
        for j in 0..n_cells_v {
            let (yv, wv) = rule.mapped(edge(1, j), edge(1, j + 1));
            for i in 0..n_cells_u {
                let (yu, wu) = rule.mapped(edge(0, i), edge(0, i + 1));
                let c = i + n_cells_u * j;
                for b in 0..ng {
                    for a in 0..ng {
                        points.push([yu[a], yv[b]]);
                        weights.push(wu[a] * wv[b]);
                        cells.push(c);
                    }
                }
            }
        }
        Ok(CellQuadrature {
            param_box,
            n_cells,
            points_per_axis: ng,
            points,
            weights,
            cells,
        })
    }

    /// Cells aligned with a particle grid: one cell between neighbouring nominal grid lines
    /// (`(n_u − 1) × (n_v − 1)` cells), each subdivided `subdivide × subdivide` times, on the box
    /// spanned by the grid's particles.
    pub fn for_particle_grid(
        grid: &ParticleGrid,
        subdivide: usize,
        points_per_cell: usize,
    ) -> Result<Self, QuadratureError> {
        if subdivide == 0 {
            return Err(QuadratureError::ZeroCount {
                parameter: "subdivide",
                value: subdivide,
            });
        }
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for p in &grid.positions {
            for k in 0..2 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        let b = ParamBox { lo, hi };
        let nc = |k: usize| grid.counts[k].saturating_sub(1) * subdivide;
        Self::new(b, nc(0), nc(1), points_per_cell)
    }

    /// The box.
    pub fn param_box(&self) -> ParamBox {
        self.param_box
    }
    /// `(n_cells_u, n_cells_v)`.
    pub fn n_cells(&self) -> [usize; 2] {
        self.n_cells
    }
    /// Gauss points per cell and direction.
    pub fn points_per_axis(&self) -> usize {
        self.points_per_axis
    }
    /// Quadrature points `(ξ1, ξ2)`.
    pub fn points(&self) -> &[[f64; 2]] {
        &self.points
    }
    /// Parameter-domain weights (sum = box area).
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }
    /// Cell index `i + n_u j` of each point.
    pub fn cells(&self) -> &[usize] {
        &self.cells
    }
    /// Number of points.
    pub fn len(&self) -> usize {
        self.points.len()
    }
    /// No points (never the case for a constructed rule).
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }
    /// The sub-box of cell `c = i + n_u j`.
    pub fn cell_box(&self, c: usize) -> ParamBox {
        let (i, j) = (c % self.n_cells[0], c / self.n_cells[0]);
        let b = &self.param_box;
        let e = |k: usize, m: usize| {
            if m == self.n_cells[k] {
                b.hi[k]
            } else {
                b.lo[k] + (b.hi[k] - b.lo[k]) * m as f64 / self.n_cells[k] as f64
            }
        };
        ParamBox::new([e(0, i), e(0, i + 1)], [e(1, j), e(1, j + 1)])
    }
    /// `(point, weight, cell)` for every point.
    pub fn iter(&self) -> impl Iterator<Item = ([f64; 2], f64, usize)> + '_ {
        self.points
            .iter()
            .zip(&self.weights)
            .zip(&self.cells)
            .map(|((&p, &w), &c)| (p, w, c))
    }
    /// `Σ_q w_q f(ξ_q)`.
    pub fn integrate(&self, f: impl Fn([f64; 2]) -> f64) -> f64 {
        self.iter().map(|(p, w, _)| w * f(p)).sum()
    }
}
