//! Reproducing-kernel (RK) meshfree shape functions on the 2-D parameter domain `(u, v)` of a CAD
//! surface.
//!
//! With a particle set `{x_I}` and per-particle rectangular supports of half-widths `a_I = (a_u, a_v)`,
//! the RK shape functions are
//!
//! ```text
//! Ψ_I(x) = Hᵀ(0) M⁻¹(x) H(x − x_I) φ_a(x − x_I),      M(x) = Σ_I H(x − x_I) Hᵀ(x − x_I) φ_a(x − x_I)
//! ```
//!
//! with a tensor-product kernel `φ_a(d) = φ(|d_u|/a_u) φ(|d_v|/a_v)`, the cubic B-spline
//! ([`kernel::cubic_bspline`]) or the quartic spline ([`kernel::quartic_spline`]; the choice:
//! [`KernelFunction`]), and a complete linear `H = (1, Δu, Δv)` or quadratic
//! `H = (1, Δu, Δv, Δu², ΔuΔv, Δv²)` basis ([`Basis`]). They reproduce every polynomial of the
//! basis exactly: `Σ_I Ψ_I p(x_I) = p(x)` and `Σ_I ∂_jΨ_I p(x_I) = ∂_j p(x)`.
//!
//! **Basis scaling.** The basis is evaluated at `Δ/s` with, per axis, `s` = the largest support
//! half-width among the particles covering `x`. Scaling the monomials by any invertible diagonal
//! matrix `D` that is the same for every particle at a given `x` leaves `Ψ_I` unchanged in exact
//! arithmetic (`M → DMD`, `H → DH`, `H(0) = e₁` unchanged), so the scale is treated as a constant even
//! though it is piecewise constant in `x`; it only keeps `M` well conditioned (entries of order one
//! instead of `h⁴` for the quadratic basis on a fine grid). The moment matrix is further equilibrated
//! (`D M D` with `D = diag(M_ii)^(-1/2)`) before its Cholesky factorisation, whose pivots give the
//! condition estimate that rejects degenerate neighbourhoods.
//!
//! **Derivatives** are derived by hand: with `b = M⁻¹ H(0)`,
//! `∂_j b = −M⁻¹ (∂_j M) b` and
//! `∂_jΨ_I = (∂_j b)ᵀ H_I φ_I + bᵀ (∂_j H_I) φ_I + bᵀ H_I ∂_jφ_I`.
//!
//! Entry points:
//! - [`ShapeFunctions`]: the f64 hot path; builds a [`SupportGrid`] once, then
//!   [`ShapeFunctions::evaluate`] fills a reusable [`ShapeValues`] without allocating (after the
//!   buffers have grown to the largest neighbourhood).
//! - [`rk_shape_functions`] / [`rk_shape_functions_sparse`]: the generic point kernel (cubic
//!   B-spline) over
//!   [`Real`](crate::scalar::Real), so evaluation point, particle coordinates and support sizes can
//!   be dual numbers (design sensitivities, verification).
//! - [`SupportGrid`]: which particles' supports cover a point (uniform cell grid, build once,
//!   query many), with the brute-force reference [`covering_brute_force`].
//! - [`particles`]: regular and jittered particle grids on a parameter box, a seeded xorshift RNG,
//!   support sizes from the particle spacing.

pub mod kernel;
pub mod particles;
pub mod quadrature;
pub mod search;
pub mod shape;
pub mod vci;

pub use kernel::{
    covers, cubic_bspline, kernel_1d, kernel_1d_with, quartic_spline, tensor_kernel,
    tensor_kernel_with, KernelFunction,
};
pub use particles::{
    jittered_grid, local_spacing, regular_grid, supports_from_spacing, Edge, ParamBox,
    ParticleGrid, XorShift64,
};
pub use search::{covering_brute_force, SupportGrid};
pub use shape::{
    rk_shape_functions, rk_shape_functions_sparse, ShapeFunctions, ShapeValues,
    DEFAULT_MAX_CONDITION,
};

use std::fmt;

/// The polynomial basis `H` of the reproducing conditions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Basis {
    /// `(1, Δu, Δv)`: reproduces linear fields (3 terms).
    Linear,
    /// `(1, Δu, Δv, Δu², ΔuΔv, Δv²)`: reproduces quadratic fields (6 terms).
    Quadratic,
    /// The quadratic terms and `(Δu³, Δu²Δv, ΔuΔv², Δv³)`: reproduces cubic fields (10 terms).
    Cubic,
}

impl Basis {
    /// Number of basis terms (3, 6 or 10): the minimum number of particles in support.
    pub fn size(self) -> usize {
        match self {
            Basis::Linear => 3,
            Basis::Quadratic => 6,
            Basis::Cubic => 10,
        }
    }
    /// Polynomial order (1, 2 or 3).
    pub fn order(self) -> usize {
        match self {
            Basis::Linear => 1,
            Basis::Quadratic => 2,
            Basis::Cubic => 3,
        }
    }
}

impl fmt::Display for Basis {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Basis::Linear => "linear",
            Basis::Quadratic => "quadratic",
            Basis::Cubic => "cubic",
        })
    }
}

/// Errors of the meshfree module. Evaluation errors name the evaluation point and the number of
/// particles whose supports cover it.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MeshfreeError {
    /// Fewer particles cover the point than the basis has terms.
    #[error(
        "RK shape functions at point (u, v) = ({u}, {v}): only {neighbours} particle(s) in support, \
         the {basis} basis needs at least {required}; enlarge the supports or add particles",
        u = .point[0], v = .point[1]
    )]
    TooFewNeighbours {
        /// Evaluation point.
        point: [f64; 2],
        /// Particles covering it.
        neighbours: usize,
        /// Basis size.
        required: usize,
        /// Basis.
        basis: Basis,
    },
    /// The moment matrix is singular or too ill-conditioned (particles degenerate, e.g. collinear).
    #[error(
        "RK moment matrix at point (u, v) = ({u}, {v}) is singular or ill-conditioned \
         (condition estimate {condition:.3e}, limit {limit:.1e}) with {neighbours} particle(s) in \
         support for the {basis} basis: too few or degenerate (collinear) particles",
        u = .point[0], v = .point[1]
    )]
    IllConditioned {
        /// Evaluation point.
        point: [f64; 2],
        /// Particles covering it.
        neighbours: usize,
        /// Condition estimate of the equilibrated moment matrix (infinite when a pivot vanished).
        condition: f64,
        /// Rejection threshold.
        limit: f64,
        /// Basis.
        basis: Basis,
    },
    /// Inconsistent or invalid input (lengths differ, non-positive or non-finite supports, …).
    #[error("invalid meshfree input: {0}")]
    InvalidInput(String),
}
