//! Global level (f64 only): sparsity pattern, deterministic parallel assembly, essential
//! conditions by elimination, sparse factorisation with a reusable symbolic analysis, and a
//! Newton–Raphson driver with load stepping and automatic step cutting.
//!
//! The pieces fit the paper's solution strategy: the linearised equilibrium equation (its eq. 36)
//! is solved by Newton iterations on a consistent tangent; at a converged step the *same*
//! factorised tangent solves the design sensitivity equation (eq. 65) for every design variable
//! at once, without iteration. [`newton::NewtonSolver`] therefore factorises the tangent at the
//! converged configuration (the factorisation doubles as its energy-norm convergence test) and
//! hands it to [`newton::NonlinearProblem::on_converged`] before the step is committed.
//!
//! Data flow of one Newton iteration:
//! 1. the problem fills `values` (aligned with [`SparsityPattern`]) and the residual, usually with
//!    [`assemble`] from cell contributions;
//! 2. [`EssentialBc::apply`] eliminates the prescribed DOFs without changing the pattern;
//! 3. [`LinearSolver::factorize`] refactorises numerically, reusing the symbolic analysis;
//! 4. [`LinearSolver::solve_in_place`] (or the multi-RHS variants) solves.

pub mod assembly;
pub mod dirichlet;
pub mod krylov;
pub mod linear;
pub mod newton;
pub mod observe;
pub mod pattern;
pub mod spectrum;
pub mod supernodal;

pub use assembly::{
    assemble, assemble_vector, assemble_with, AssemblyBuffers, AssemblyError, Execution,
};
pub use dirichlet::EssentialBc;
pub use linear::{LinearSolver, Method, Parallelism, PreconditionerPrecision, SolverOptions};
pub use newton::{
    Acceptance, ArcLength, ArcLengthReport, Backtrack, ConvergedStep, ConvergedTangent,
    CriticalKind, CriticalPoint, FactorisedAt, Failure, FailureReason, LineSearch, LinearUpdates,
    LoadStepping, NewtonFailure, NewtonOptions, NewtonReport, NewtonSolver, NonlinearProblem,
    Predictor, ProblemError, StepRecord, StepTiming, StopFailure, BACKTRACK_BUDGET,
    BACKTRACK_LENGTHS,
};
pub use pattern::{RowRun, SlotRun, SparsityPattern};
pub use supernodal::{FillOrdering, FRONT_ENTRY_FLOPS, ORDERING_MARGIN};

/// Errors of the linear-algebra layer. Every variant names where the problem was found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SolverError {
    /// A pattern with more stored entries than the `u32` cell slots address.
    #[error("the pattern stores {nnz} entries: at most u32::MAX = 4294967295 are supported")]
    TooManyEntries {
        /// Stored entries.
        nnz: usize,
    },
    /// A cell lists a DOF index outside `0..n_dofs`.
    #[error(
        "cell {cell}: local DOF {local} has global index {dof}, but there are only {n_dofs} DOFs"
    )]
    DofOutOfRange {
        /// Cell index.
        cell: usize,
        /// Position in the cell's DOF list.
        local: usize,
        /// Offending global index.
        dof: usize,
        /// Number of DOFs of the pattern.
        n_dofs: usize,
    },
    /// A slice has the wrong length.
    #[error("{what}: expected length {expected}, got {got}")]
    Length {
        /// Which argument.
        what: &'static str,
        /// Expected length.
        expected: usize,
        /// Actual length.
        got: usize,
    },
    /// A matrix entry is NaN or infinite.
    #[error("matrix entry ({row}, {col}) is not finite: {value}")]
    NonFiniteMatrix {
        /// Row of the entry.
        row: usize,
        /// Column of the entry.
        col: usize,
        /// The value.
        value: f64,
    },
    /// A right-hand side entry is NaN or infinite.
    #[error("right-hand side {rhs}, entry {row} is not finite: {value}")]
    NonFiniteRhs {
        /// Column of the right-hand-side block.
        rhs: usize,
        /// Row (DOF).
        row: usize,
        /// The value.
        value: f64,
    },
    /// The matrix is singular (or numerically so); `detail` says how this was detected.
    #[error("singular matrix: {detail}")]
    Singular {
        /// A DOF (row or column index) involved, when known.
        dof: Option<usize>,
        /// Human-readable diagnosis.
        detail: String,
    },
    /// Cholesky met a non-positive pivot: the matrix is not symmetric positive definite.
    #[error(
        "matrix not positive definite: non-positive pivot at DOF {dof} (elimination step {step})"
    )]
    NotPositiveDefinite {
        /// Original DOF index of the pivot.
        dof: usize,
        /// Step of the (permuted) elimination.
        step: usize,
    },
    /// `solve` was called before a successful `factorize`.
    #[error("solve called without a valid factorisation")]
    NotFactorized,
    /// Essential-condition input error.
    #[error("essential condition: {0}")]
    Constraint(String),
    /// An error reported by faer (allocation, index overflow).
    #[error("faer: {0}")]
    Faer(String),
}

pub(crate) fn check_len(
    what: &'static str,
    got: usize,
    expected: usize,
) -> Result<(), SolverError> {
    if got == expected {
        Ok(())
    } else {
        Err(SolverError::Length {
            what,
            expected,
            got,
        })
    }
}
