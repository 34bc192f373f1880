//! Sparse direct solver over a [`SparsityPattern`]: symbolic analysis once, numeric
//! refactorisation for every new set of values (Newton iterations, load steps), and solves with
//! one or many right-hand sides (the DSA solves all design variables with one factorisation).

use super::supernodal::{FillOrdering, SupernodalNumeric, SupernodalSymbolic};
use super::{check_len, SolverError, SparsityPattern};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltError;
use faer::linalg::lu::partial_pivoting as dense_lu;
use faer::sparse::linalg::{cholesky, lu, LuError};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat, SymbolicSparseColMatRef};
use faer::{Conj, Mat, MatMut, MatRef, Par, Side};

/// Factorisation method.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Sparse LU with partial (row) pivoting and a COLAMD column ordering: any nonsingular
    /// matrix, in particular unsymmetric tangents (contact, plasticity, transformation method).
    #[default]
    Lu,
    /// Sparse Cholesky `LLᵀ` with an AMD ordering, for symmetric positive definite matrices.
    /// Only the lower triangle of the values is read.
    Cholesky,
    /// Dense LU with partial (row) pivoting (faer's blocked kernel) of the pattern's values
    /// scattered into an `n × n` matrix: for patterns so full that sparse elimination fills in
    /// completely. Meshfree shells with supports of 3 spacings on a 17 × 17 grid store 29.5 % of
    /// the entries; there one numeric factorisation took 47 ms dense against 56 ms sparse
    /// (serial, 1446 unknowns; 37 ms dense on 2 threads; `examples/lu_probe.rs` measured it
    /// and `benches/shell.rs` reports it). Memory: `8 n²` bytes.
    DenseLu,
    /// Multifrontal supernodal LU on the symmetric structure of the pattern (AMD ordering and
    /// supernodes of the Cholesky factor, computed once), row pivoting inside each supernode's
    /// diagonal block, subtrees and large updates on rayon tasks whose split depends on the
    /// pattern only (the factors do not depend on the number of threads). A factorisation
    /// that fails the singularity probe is redone with [`Method::Lu`]'s unrestricted pivoting.
    SupernodalLu,
}

impl Method {
    /// Stored fraction above which [`Method::auto`] picks the dense LU for small systems.
    pub const DENSE_FILL: f64 = 0.25;
    /// Largest system [`Method::auto`] factorises densely. On the hemisphere's 17 × 17 tangent
    /// (1446 unknowns, 29.5 % stored) the supernodal LU with nested dissection does
    /// 0.57 GFlop against the dense LU's 2.0 GFlop, in 0.017 against 0.043 CPU-s (0.012
    /// against 0.024 s of wall time on two cores, `examples/solver_probe.rs`); at 15 × 15
    /// (1126) 0.007 against 0.016 s, while from 9 × 9 to 13 × 13 (406 to 846 unknowns) the two
    /// take the same time. Above a thousand unknowns it is the better choice whatever the
    /// fill, and its result does not depend on the number of threads.
    pub const DENSE_MAX_N: usize = 1000;

    /// The LU for `pattern`: [`Method::DenseLu`] for small systems (`n ≤`
    /// [`Method::DENSE_MAX_N`]) that store at least [`Method::DENSE_FILL`] of the `n²`
    /// entries, else [`Method::SupernodalLu`].
    pub fn auto(pattern: &SparsityPattern) -> Method {
        let n = pattern.n_dofs();
        let fill = pattern.nnz() as f64 / (n as f64 * n as f64).max(1.0);
        if n <= Self::DENSE_MAX_N && fill >= Self::DENSE_FILL {
            Method::DenseLu
        } else {
            Method::SupernodalLu
        }
    }
}

/// Threading of faer's factorisation and solve kernels ([`Method::Lu`], [`Method::Cholesky`],
/// [`Method::DenseLu`], and the fallback of [`Method::SupernodalLu`]). The supernodal LU itself
/// runs its independent subtrees and cut updates on rayon's pool whatever this setting, with a
/// split that does not depend on the number of threads.
///
/// The default is sequential. On the elastoplastic hemisphere tangent (1446 unknowns, 616k
/// stored entries) one numeric LU took 54.5 ms serial and 41 ms on 2 threads when the second
/// core was free (best of 15), but 105 ms on 2 threads against 57 ms serial while another job
/// held a core (criterion, `benches/shell.rs`): on a shared 2-core machine the serial kernel is
/// the robust choice (docs/shell-formulation.md §8 item 7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Parallelism {
    /// Single-threaded (the default).
    #[default]
    Sequential,
    /// faer's rayon parallelism with this many threads (`0`: all threads of the global pool).
    Rayon(usize),
}

impl Parallelism {
    /// The faer setting.
    pub fn par(self) -> Par {
        match self {
            Parallelism::Sequential => Par::Seq,
            Parallelism::Rayon(n) => Par::rayon(n),
        }
    }
}

/// The precision of the triangular solves that apply a held factorisation as GMRES's
/// preconditioner ([`LinearSolver::precondition_columns_in_place`]; [`Method::SupernodalLu`]
/// only, every other method solves in double precision).
///
/// The default is [`PreconditionerPrecision::Single`]: a preconditioner solve reads every
/// stored entry of the factors once, and GMRES on a tangent held over several Newton iterates
/// is bound by that traffic. A factorisation held over iterates differs from the current
/// tangent by far more than single precision's rounding, so the Arnoldi steps hardly change,
/// and every solution is still accepted on its true residual in double precision. Measured on
/// the plastic hemisphere (`verification/hemisphere-plastic`, whole runs, 2 cores, the two
/// settings alternated in one sitting): 65 × 65, the solves 28.8–29.0 → 17.1–17.9 s for
/// 566 → 616 Arnoldi steps, the run 104.1–104.7 → 91.4–93.2 s; 33 × 33, the solves
/// 3.3–3.5 → 2.5–2.6 s for 439 → 510 steps, the run 14.6–15.2 → 13.9–14.7 s; 17 × 17,
/// 219 → 228 steps, 2.48–2.64 → 2.42–2.49 s; the same Newton iterations, the monitors equal to
/// 1e-13. The continuum DSA's solves ([`super::krylov::gmres_columns_to`]) stay in double
/// precision.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PreconditionerPrecision {
    /// Factors rounded to single precision at the first preconditioner solve after each
    /// factorisation (none in a run without one), solves in single
    /// precision (half the memory traffic).
    #[default]
    Single,
    /// The double-precision factors and solve.
    Double,
}

/// Options of [`LinearSolver`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverOptions {
    /// faer's threading for factorisation and solves.
    pub parallelism: Parallelism,
    /// The precision of the preconditioner's solves.
    pub preconditioner: PreconditionerPrecision,
    /// Singularity probe (LU only): after each factorisation solve `A x = A p` for a fixed
    /// vector `p` with entries in [0.5, 1.5] and reject the factorisation if `max|x − p|`
    /// exceeds this bound or is not finite. faer's LU does not report exactly-zero numerical
    /// pivots (it divides by them), so this is how a singular tangent is caught before it
    /// pollutes a Newton update. The forward error of a healthy solve is about `cond(A)·ε`;
    /// the default `1e-2` accepts condition numbers far beyond those of shell tangents while
    /// catching zero and round-off-sized pivots. `None` disables the probe (one solve saved).
    pub singularity_probe: Option<f64>,
}

impl Default for SolverOptions {
    fn default() -> Self {
        SolverOptions {
            parallelism: Parallelism::Sequential,
            preconditioner: PreconditionerPrecision::Single,
            singularity_probe: Some(1e-2),
        }
    }
}

/// Ratio of the flop rate of a numeric factorisation to that of a triangular solve, for
/// [`LinearSolver::refactorisation_cost`]. One supernodal factorisation of the hemisphere's
/// tangent took the CPU time of 31 products and solves at 33 × 33 (8.5e9 flops against
/// 2 · 2.8e6 + 2 · 8.9e6 per step: a rate ratio of 12), and it runs on both cores where the
/// solves run on one (`examples/solver_probe.rs`).
pub const FACTOR_RATE_RATIO: f64 = 15.0;

/// [`LinearSolver::refactorisation_cost`] of the methods that do not count their flops.
pub const DEFAULT_REFACTORISATION_COST: f64 = 20.0;

/// faer's sparse LU (symbolic and numeric), the supernodal LU's fallback.
type FallbackLu = (lu::SymbolicLu<usize>, lu::NumericLu<usize, f64>);

enum Factor {
    Lu {
        symbolic: lu::SymbolicLu<usize>,
        numeric: lu::NumericLu<usize, f64>,
    },
    Llt {
        symbolic: cholesky::SymbolicCholesky<usize>,
        l_values: Vec<f64>,
    },
    Dense {
        /// `L` (strictly lower, unit diagonal implied) and `U` in one matrix.
        lu: Mat<f64>,
        perm_fwd: Vec<usize>,
        perm_bwd: Vec<usize>,
    },
    Supernodal {
        symbolic: Box<SupernodalSymbolic>,
        numeric: SupernodalNumeric,
        /// The unrestricted sparse LU, built when a restricted-pivoting factorisation fails
        /// the probe; `active` while it holds the current factorisation.
        fallback: Option<Box<FallbackLu>>,
        active: bool,
    },
}

/// A sparse direct solver bound to one sparsity pattern.
pub struct LinearSolver {
    n: usize,
    pattern: SymbolicSparseColMat<usize>,
    factor: Factor,
    options: SolverOptions,
    factorized: bool,
    n_factorizations: usize,
    n_fallbacks: usize,
}

impl std::fmt::Debug for LinearSolver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LinearSolver")
            .field("n", &self.n)
            .field("method", &self.method())
            .field("options", &self.options)
            .field("factorized", &self.factorized)
            .field("n_factorizations", &self.n_factorizations)
            .field("n_fallbacks", &self.n_fallbacks)
            .finish()
    }
}

fn faer_err(e: impl std::fmt::Debug) -> SolverError {
    SolverError::Faer(format!("{e:?}"))
}

/// faer's dense LU blocking with a recursion threshold of 32 columns (faer's default 16): on the
/// 1446-unknown hemisphere tangent one factorisation took 31.7 ms against 37.4 ms on 2 threads,
/// and the same (≈ 49 ms) serially (`LU_TUNE=1 cargo run --release --example lu_probe`).
fn dense_lu_params() -> dense_lu::factor::PartialPivLuParams {
    let mut p: dense_lu::factor::PartialPivLuParams = faer::Auto::<f64>::auto();
    p.recursion_threshold = 32;
    p.block_size = 64;
    p
}

/// Scatter the pattern's `values` into the dense `a` (zero elsewhere) and screen them as
/// [`LinearSolver::factorize`] does for the sparse methods (non-finite entries, identically zero
/// rows and columns), in one pass over the columns, in parallel with rayon.
fn dense_scatter_screen(
    pattern: SymbolicSparseColMatRef<'_, usize>,
    values: &[f64],
    a: &mut Mat<f64>,
) -> Result<(), SolverError> {
    use rayon::prelude::*;
    let n = pattern.ncols();
    let (cp, ri) = (pattern.col_ptr(), pattern.row_idx());
    let cols: Vec<_> = a.as_mut().col_iter_mut().collect();
    // Per task: the first bad column (in column order) and the row maxima of its columns.
    let (first_bad, row_max) = cols
        .into_par_iter()
        .enumerate()
        .with_min_len(32)
        .fold(
            || (None::<SolverError>, vec![0.0f64; n]),
            |(mut bad, mut row_max), (j, mut col)| {
                col.fill(0.0);
                let mut col_max = 0.0f64;
                for p in cp[j]..cp[j + 1] {
                    let v = values[p];
                    if bad.is_none() && !v.is_finite() {
                        bad = Some(SolverError::NonFiniteMatrix {
                            row: ri[p],
                            col: j,
                            value: v,
                        });
                    }
                    col[ri[p]] = v;
                    col_max = col_max.max(v.abs());
                    row_max[ri[p]] = row_max[ri[p]].max(v.abs());
                }
                if bad.is_none() && col_max == 0.0 {
                    bad = Some(SolverError::Singular {
                        dof: Some(j),
                        detail: format!("column {j} is identically zero"),
                    });
                }
                (bad, row_max)
            },
        )
        .reduce(
            || (None, vec![0.0f64; n]),
            |(b1, mut r1), (b2, r2)| {
                for (x, y) in r1.iter_mut().zip(&r2) {
                    *x = x.max(*y);
                }
                // Folds cover increasing column ranges and `reduce` keeps their order, so the
                // left error is the lowest column's.
                (b1.or(b2), r1)
            },
        );
    if let Some(e) = first_bad {
        return Err(e);
    }
    if let Some(i) = row_max.iter().position(|&m| m == 0.0) {
        return Err(SolverError::Singular {
            dof: Some(i),
            detail: format!("row {i} is identically zero"),
        });
    }
    Ok(())
}

/// Fixed probe vector with entries in [0.5, 1.5] (a Weyl sequence, no special structure).
fn probe(i: usize) -> f64 {
    0.5 + ((i as f64 + 1.0) * 0.618_033_988_749_895).fract()
}

impl LinearSolver {
    /// Symbolic analysis (ordering, elimination structure) of `pattern`, done once.
    pub fn new(
        pattern: &SparsityPattern,
        method: Method,
        options: SolverOptions,
    ) -> Result<Self, SolverError> {
        let symbolic = pattern.symbolic();
        let factor = match method {
            Method::Lu => Factor::Lu {
                symbolic: lu::factorize_symbolic_lu(symbolic, Default::default())
                    .map_err(faer_err)?,
                numeric: lu::NumericLu::new(),
            },
            Method::Cholesky => {
                let symbolic = cholesky::factorize_symbolic_cholesky(
                    symbolic,
                    Side::Lower,
                    cholesky::SymmetricOrdering::Amd,
                    Default::default(),
                )
                .map_err(faer_err)?;
                let l_values = vec![0.0; symbolic.len_val()];
                Factor::Llt { symbolic, l_values }
            }
            Method::SupernodalLu => Factor::Supernodal {
                symbolic: Box::new(SupernodalSymbolic::new(pattern, FillOrdering::default())?),
                numeric: SupernodalNumeric::default(),
                fallback: None,
                active: false,
            },
            Method::DenseLu => {
                let n = pattern.n_dofs();
                Factor::Dense {
                    lu: Mat::zeros(n, n),
                    perm_fwd: vec![0; n],
                    perm_bwd: vec![0; n],
                }
            }
        };
        Ok(Self {
            n: pattern.n_dofs(),
            pattern: pattern.symbolic().to_owned().map_err(faer_err)?,
            factor,
            options,
            factorized: false,
            n_factorizations: 0,
            n_fallbacks: 0,
        })
    }

    /// [`Method::SupernodalLu`] with the given fill-reducing ordering (the default is
    /// [`FillOrdering::Cheapest`]).
    pub fn supernodal(
        pattern: &SparsityPattern,
        ordering: FillOrdering,
        options: SolverOptions,
    ) -> Result<Self, SolverError> {
        Ok(Self {
            n: pattern.n_dofs(),
            pattern: pattern.symbolic().to_owned().map_err(faer_err)?,
            factor: Factor::Supernodal {
                symbolic: Box::new(SupernodalSymbolic::new(pattern, ordering)?),
                numeric: SupernodalNumeric::default(),
                fallback: None,
                active: false,
            },
            options,
            factorized: false,
            n_factorizations: 0,
            n_fallbacks: 0,
        })
    }

    /// The method chosen at construction.
    pub fn method(&self) -> Method {
        match self.factor {
            Factor::Lu { .. } => Method::Lu,
            Factor::Llt { .. } => Method::Cholesky,
            Factor::Dense { .. } => Method::DenseLu,
            Factor::Supernodal { .. } => Method::SupernodalLu,
        }
    }

    /// The fill-reducing ordering used and the estimated cost of one numeric factorisation
    /// (operations plus front entries, [`super::FRONT_ENTRY_FLOPS`] each), for
    /// [`Method::SupernodalLu`] (`None` for the other methods).
    pub fn ordering_and_cost(&self) -> Option<(FillOrdering, f64)> {
        match &self.factor {
            Factor::Supernodal { symbolic, .. } => Some((symbolic.ordering, symbolic.cost())),
            _ => None,
        }
    }

    /// Size of the factorisation for [`Method::SupernodalLu`]: supernodes, stored entries of
    /// `L` and `U`, operations of one numeric factorisation and the largest front.
    pub fn structure(&self) -> Option<String> {
        match &self.factor {
            Factor::Supernodal { symbolic, .. } => Some(format!(
                "{:?} ordering, {} supernodes, {} entries in L+U ({:.1} per row), {:.3e} flops, \
                 largest front {}, {} front entries",
                symbolic.ordering,
                symbolic.n_supernodes(),
                symbolic.factor_entries,
                symbolic.factor_entries as f64 / self.n.max(1) as f64,
                symbolic.flops,
                symbolic.max_front,
                symbolic.front_entries
            )),
            _ => None,
        }
    }

    /// Estimated cost of one numeric factorisation (with its singularity probe) in units of
    /// one step of GMRES preconditioned by it: one product with the matrix and one pair of
    /// triangular solves (`2 nnz(A) + 2 nnz(L+U)` flops, memory-bound). The factorisation's
    /// flops run [`FACTOR_RATE_RATIO`] times faster than those of a solve (dense blocked
    /// kernels against one pass over the factors). [`Method::SupernodalLu`] and
    /// [`Method::DenseLu`] count their flops; the other methods give
    /// [`DEFAULT_REFACTORISATION_COST`].
    pub fn refactorisation_cost(&self) -> f64 {
        let nnz = self.pattern.row_idx().len() as f64;
        let n = self.n as f64;
        let (flops, factor_entries) = match &self.factor {
            Factor::Supernodal { symbolic, .. } => (symbolic.flops, symbolic.factor_entries as f64),
            Factor::Dense { .. } => (2.0 / 3.0 * n * n * n, n * n),
            _ => return DEFAULT_REFACTORISATION_COST,
        };
        // In the units of double-precision solves whatever the preconditioner's precision:
        // counting a single-precision solve as half (more Arnoldi steps allowed per
        // factorisation) took the plastic hemisphere's 65² run from 616 to 738 Arnoldi steps
        // for 37 and 36 factorisations, 91 s to 95 s.
        let step = 2.0 * nnz + 2.0 * factor_entries;
        // The probe is one more solve and product.
        flops / (FACTOR_RATE_RATIO * step.max(1.0)) + 1.0
    }

    /// Number of DOFs.
    pub fn n_dofs(&self) -> usize {
        self.n
    }

    /// Options in use.
    pub fn options(&self) -> SolverOptions {
        self.options
    }

    /// Change faer's threading (takes effect at the next factorisation or solve).
    pub fn set_parallelism(&mut self, parallelism: Parallelism) {
        self.options.parallelism = parallelism;
    }

    /// Whether a valid numeric factorisation is held.
    pub fn is_factorized(&self) -> bool {
        self.factorized
    }

    /// Number of successful numeric factorisations so far (the symbolic one is done once).
    pub fn n_factorizations(&self) -> usize {
        self.n_factorizations
    }

    /// How many of those [`Method::SupernodalLu`] redid with the unrestricted sparse LU after
    /// its probe solve failed (a pivot too small for pivoting within the supernodes): each
    /// costs both factorisations.
    pub fn n_fallbacks(&self) -> usize {
        self.n_fallbacks
    }

    /// Sign of the determinant of the matrix held factorised: `Some(±1)` (or `Some(0)` for an
    /// exactly zero pivot), `None` without a factorisation or where the method cannot give it.
    ///
    /// With `P A Q = L U` (`L` unit lower triangular, `P`, `Q` permutations),
    /// `sign det A = sign det P · sign det Q · Π_i sign U_ii`: [`Method::DenseLu`] reads the
    /// parity of its row permutation and `U`'s diagonal, [`Method::SupernodalLu`] those of every
    /// supernode (its symmetric ordering `Q = Pᵀ` cancels), and a Cholesky factorisation that
    /// succeeded is of a positive definite matrix (`+1`). faer's sparse LU ([`Method::Lu`],
    /// and the supernodal LU's fallback while it holds the factorisation) does not expose its
    /// `U`: `None`. Reading the sign costs `O(n)` and changes nothing in the factors.
    pub fn determinant_sign(&self) -> Option<f64> {
        if !self.factorized {
            return None;
        }
        match &self.factor {
            Factor::Lu { .. } => None,
            Factor::Llt { .. } => Some(1.0),
            Factor::Dense { lu, perm_fwd, .. } => {
                let mut negative = super::supernodal::permutation_is_odd(perm_fwd);
                for i in 0..self.n {
                    let d = lu[(i, i)];
                    if d == 0.0 {
                        return Some(0.0);
                    }
                    if d < 0.0 {
                        negative = !negative;
                    }
                }
                Some(if negative { -1.0 } else { 1.0 })
            }
            Factor::Supernodal {
                symbolic,
                numeric,
                active,
                ..
            } => (!*active).then(|| symbolic.determinant_sign(numeric)),
        }
    }

    /// Numeric factorisation of the matrix with `values` over the pattern, reusing the symbolic
    /// analysis. On error the previous factorisation is invalidated.
    pub fn factorize(&mut self, values: &[f64]) -> Result<(), SolverError> {
        self.factorized = false;
        check_len(
            "factorize: values",
            values.len(),
            self.pattern.row_idx().len(),
        )?;
        if !matches!(self.factor, Factor::Dense { .. }) {
            self.screen(values)?;
        }
        let par = self.options.parallelism.par();
        let a = SparseColMatRef::new(self.pattern.as_ref(), values);
        match &mut self.factor {
            Factor::Lu { symbolic, numeric } => {
                let req = symbolic.factorize_numeric_lu_scratch::<f64>(par, Default::default());
                let mut buf = MemBuffer::try_new(req).map_err(faer_err)?;
                let res = symbolic.factorize_numeric_lu(
                    numeric,
                    a,
                    par,
                    MemStack::new(&mut buf),
                    Default::default(),
                );
                match res {
                    Ok(_) => {}
                    Err(LuError::SymbolicSingular { index }) => {
                        let col = symbolic.col_perm().arrays().0[index];
                        return Err(SolverError::Singular {
                            dof: Some(col),
                            detail: format!(
                                "no nonzero pivot candidate at elimination step {index} \
                                 (column {col}): structurally rank deficient"
                            ),
                        });
                    }
                    Err(e) => return Err(faer_err(e)),
                }
            }
            Factor::Llt { symbolic, l_values } => {
                let req = symbolic.factorize_numeric_llt_scratch::<f64>(par, Default::default());
                let mut buf = MemBuffer::try_new(req).map_err(faer_err)?;
                let res = symbolic.factorize_numeric_llt(
                    l_values,
                    a,
                    Side::Lower,
                    Default::default(),
                    par,
                    MemStack::new(&mut buf),
                    Default::default(),
                );
                if let Err(LltError::NonPositivePivot { index }) = res {
                    // faer 0.24 reports this index 1-based from the simplicial kernel and
                    // 0-based from the (dense, per supernode) supernodal kernel.
                    let index = match symbolic.raw() {
                        cholesky::SymbolicCholeskyRaw::Simplicial(_) => index.saturating_sub(1),
                        cholesky::SymbolicCholeskyRaw::Supernodal(_) => index,
                    };
                    let dof = symbolic.perm().map_or(index, |p| p.arrays().0[index]);
                    return Err(SolverError::NotPositiveDefinite { dof, step: index });
                }
            }
            Factor::Supernodal {
                symbolic,
                numeric,
                active,
                ..
            } => {
                *active = false;
                symbolic.factorize(values, numeric);
            }
            Factor::Dense {
                lu,
                perm_fwd,
                perm_bwd,
            } => {
                dense_scatter_screen(self.pattern.as_ref(), values, lu)?;
                let params = dense_lu_params();
                let req = dense_lu::factor::lu_in_place_scratch::<usize, f64>(
                    self.n,
                    self.n,
                    par,
                    params.into(),
                );
                let mut buf = MemBuffer::try_new(req).map_err(faer_err)?;
                dense_lu::factor::lu_in_place(
                    lu.as_mut(),
                    perm_fwd,
                    perm_bwd,
                    par,
                    MemStack::new(&mut buf),
                    params.into(),
                );
            }
        }
        self.factorized = true;
        let pivoted = !matches!(self.factor, Factor::Llt { .. });
        if let (true, Some(tol)) = (pivoted, self.options.singularity_probe) {
            if let Err(e) = self.probe(values, tol) {
                self.factorized = false;
                if !matches!(self.factor, Factor::Supernodal { .. }) {
                    return Err(e);
                }
                // Pivots restricted to the supernodes' diagonal blocks may be poor where
                // unrestricted ones are fine: redo with the sparse LU, whose verdict stands.
                self.factorize_fallback(values)?;
                self.factorized = true;
                if let Err(e) = self.probe(values, tol) {
                    self.factorized = false;
                    return Err(e);
                }
                // Counted with the factorisations: only where the redone one is used.
                self.n_fallbacks += 1;
            }
        }
        self.n_factorizations += 1;
        Ok(())
    }

    /// [`Method::SupernodalLu`] only: factorise with the unrestricted sparse LU (symbolic
    /// analysis on first use) and solve with it until the next factorisation.
    fn factorize_fallback(&mut self, values: &[f64]) -> Result<(), SolverError> {
        let par = self.options.parallelism.par();
        let a = SparseColMatRef::new(self.pattern.as_ref(), values);
        let Factor::Supernodal {
            fallback, active, ..
        } = &mut self.factor
        else {
            return Ok(());
        };
        if fallback.is_none() {
            let symbolic = lu::factorize_symbolic_lu(self.pattern.as_ref(), Default::default())
                .map_err(faer_err)?;
            *fallback = Some(Box::new((symbolic, lu::NumericLu::new())));
        }
        let (symbolic, numeric) = &mut **fallback.as_mut().expect("built above");
        let req = symbolic.factorize_numeric_lu_scratch::<f64>(par, Default::default());
        let mut buf = MemBuffer::try_new(req).map_err(faer_err)?;
        symbolic
            .factorize_numeric_lu(numeric, a, par, MemStack::new(&mut buf), Default::default())
            .map_err(|e| SolverError::Singular {
                dof: None,
                detail: format!("sparse LU: {e:?}"),
            })?;
        *active = true;
        Ok(())
    }

    /// Reject non-finite entries and identically zero rows or columns, naming them.
    fn screen(&self, values: &[f64]) -> Result<(), SolverError> {
        let (cp, ri) = (self.pattern.col_ptr(), self.pattern.row_idx());
        let mut row_max = vec![0.0f64; self.n];
        for j in 0..self.n {
            let mut col_max = 0.0f64;
            for p in cp[j]..cp[j + 1] {
                let v = values[p];
                if !v.is_finite() {
                    return Err(SolverError::NonFiniteMatrix {
                        row: ri[p],
                        col: j,
                        value: v,
                    });
                }
                col_max = col_max.max(v.abs());
                row_max[ri[p]] = row_max[ri[p]].max(v.abs());
            }
            if col_max == 0.0 {
                return Err(SolverError::Singular {
                    dof: Some(j),
                    detail: format!("column {j} is identically zero"),
                });
            }
        }
        if let Some(i) = row_max.iter().position(|&m| m == 0.0) {
            return Err(SolverError::Singular {
                dof: Some(i),
                detail: format!("row {i} is identically zero"),
            });
        }
        Ok(())
    }

    fn probe(&self, values: &[f64], tol: f64) -> Result<(), SolverError> {
        let (cp, ri) = (self.pattern.col_ptr(), self.pattern.row_idx());
        let mut b = vec![0.0; self.n];
        for j in 0..self.n {
            let pj = probe(j);
            for p in cp[j]..cp[j + 1] {
                b[ri[p]] += values[p] * pj;
            }
        }
        self.solve_unchecked(MatMut::from_column_major_slice_mut(&mut b, self.n, 1));
        let mut worst = (0usize, 0.0f64);
        for (i, x) in b.iter().enumerate() {
            let e = (x - probe(i)).abs();
            if !e.is_finite() {
                return Err(SolverError::Singular {
                    dof: Some(i),
                    detail: format!(
                        "zero pivot: probe solve gave a non-finite value at DOF {i} \
                         (the matrix is numerically singular)"
                    ),
                });
            }
            if e > worst.1 {
                worst = (i, e);
            }
        }
        if worst.1 > tol {
            return Err(SolverError::Singular {
                dof: Some(worst.0),
                detail: format!(
                    "probe solve has forward error {:.3e} > {tol:.1e}, largest at DOF {} \
                     (numerically singular or condition number ≳ {:.1e})",
                    worst.1,
                    worst.0,
                    worst.1 / f64::EPSILON
                ),
            });
        }
        Ok(())
    }

    fn solve_unchecked(&self, rhs: MatMut<'_, f64>) {
        let par = self.options.parallelism.par();
        let k = rhs.ncols();
        match &self.factor {
            Factor::Lu { symbolic, numeric } => {
                let mut buf = MemBuffer::new(symbolic.solve_in_place_scratch::<f64>(k, par));
                lu::LuRef::new_unchecked(symbolic, numeric).solve_in_place_with_conj(
                    Conj::No,
                    rhs,
                    par,
                    MemStack::new(&mut buf),
                );
            }
            Factor::Llt { symbolic, l_values } => {
                let mut buf = MemBuffer::new(symbolic.solve_in_place_scratch::<f64>(k, par));
                cholesky::LltRef::new(symbolic, l_values).solve_in_place_with_conj(
                    Conj::No,
                    rhs,
                    par,
                    MemStack::new(&mut buf),
                );
            }
            Factor::Supernodal {
                symbolic,
                numeric,
                fallback,
                active,
            } => match (active, fallback) {
                (true, Some(fb)) => {
                    let (symbolic, numeric) = &**fb;
                    let mut buf = MemBuffer::new(symbolic.solve_in_place_scratch::<f64>(k, par));
                    lu::LuRef::new_unchecked(symbolic, numeric).solve_in_place_with_conj(
                        Conj::No,
                        rhs,
                        par,
                        MemStack::new(&mut buf),
                    );
                }
                _ => symbolic.solve(numeric, rhs),
            },
            Factor::Dense {
                lu,
                perm_fwd,
                perm_bwd,
            } => {
                // `lu_in_place` wrote `perm_fwd` and its inverse `perm_bwd` in the
                // factorisation this solve follows (checked again here).
                let perm = faer::perm::PermRef::new_checked(perm_fwd, perm_bwd, self.n);
                let solve = |rhs: MatMut<'_, f64>| {
                    let k = rhs.ncols();
                    let mut buf = MemBuffer::new(dense_lu::solve::solve_in_place_scratch::<
                        usize,
                        f64,
                    >(self.n, k, par));
                    dense_lu::solve::solve_in_place_with_conj(
                        lu.as_ref(),
                        lu.as_ref(),
                        perm,
                        Conj::No,
                        rhs,
                        par,
                        MemStack::new(&mut buf),
                    );
                };
                if k >= 2 && matches!(self.options.parallelism, Parallelism::Sequential) {
                    // Several right-hand sides (the continuum DSA's design variables): the
                    // two halves of the columns on two rayon tasks, each a sequential solve.
                    // The split depends on `k` only, so the result does not depend on the
                    // number of threads.
                    let (a, b) = rhs.split_at_col_mut(k / 2);
                    rayon::join(|| solve(a), || solve(b));
                } else {
                    solve(rhs);
                }
            }
        }
    }

    /// Apply the factorisation's inverse as a preconditioner to the `k` columns of `b`
    /// (column-major, length `n·k`), in place: for the supernodal LU with
    /// [`PreconditionerPrecision::Single`] (the default), in single precision from the
    /// factors rounded to it, half the memory traffic of [`Self::solve_columns_in_place`]
    /// (the result differs from that solve's by single precision's rounding, amplified by
    /// the matrix's conditioning); otherwise that solve itself. Errors as that solve's.
    pub fn precondition_columns_in_place(
        &self,
        b: &mut [f64],
        k: usize,
    ) -> Result<(), SolverError> {
        match &self.factor {
            Factor::Supernodal {
                symbolic,
                numeric,
                active: false,
                ..
            } if self.factorized
                && self.options.preconditioner == PreconditionerPrecision::Single =>
            {
                check_len("precondition: rhs", b.len(), self.n * k)?;
                check_finite(MatRef::from_column_major_slice(b, self.n, k))?;
                let mut single = Mat::<f32>::from_fn(self.n, k, |i, j| b[j * self.n + i] as f32);
                symbolic.solve_single(numeric, single.as_mut());
                for j in 0..k {
                    for (i, x) in b[j * self.n..(j + 1) * self.n].iter_mut().enumerate() {
                        *x = single[(i, j)] as f64;
                    }
                }
                Ok(())
            }
            _ => self.solve_columns_in_place(b, k),
        }
    }

    /// Solve `A x = b` in place (`b` becomes `x`).
    pub fn solve_in_place(&self, b: &mut [f64]) -> Result<(), SolverError> {
        self.solve_columns_in_place(b, 1)
    }

    /// Solve for `k` right-hand sides stored column-major in `b` (length `n·k`), in place.
    pub fn solve_columns_in_place(&self, b: &mut [f64], k: usize) -> Result<(), SolverError> {
        check_len("solve: rhs", b.len(), self.n * k)?;
        self.solve_multi_in_place(MatMut::from_column_major_slice_mut(b, self.n, k))
    }

    /// Solve for every column of `b` (an `n × k` faer matrix view) with the one factorisation.
    pub fn solve_multi_in_place(&self, b: MatMut<'_, f64>) -> Result<(), SolverError> {
        if !self.factorized {
            return Err(SolverError::NotFactorized);
        }
        check_len("solve: rhs rows", b.nrows(), self.n)?;
        check_finite(b.as_ref())?;
        self.solve_unchecked(b);
        Ok(())
    }
}

/// The first non-finite entry of the right-hand sides `b`, as an error naming its column and
/// row.
fn check_finite(b: MatRef<'_, f64>) -> Result<(), SolverError> {
    for c in 0..b.ncols() {
        for r in 0..b.nrows() {
            let v = b[(r, c)];
            if !v.is_finite() {
                return Err(SolverError::NonFiniteRhs {
                    rhs: c,
                    row: r,
                    value: v,
                });
            }
        }
    }
    Ok(())
}
