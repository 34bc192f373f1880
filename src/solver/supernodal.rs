//! Multifrontal supernodal LU on the symmetric structure of the pattern.
//!
//! The meshfree tangents are structurally symmetric (every pair of DOFs of a cell is stored
//! both ways) but numerically unsymmetric (the Petrov–Galerkin VCI gradients, the follower loads,
//! the plastic update). LU with partial row pivoting over all rows must bound its fill by the
//! Cholesky factor of `AᵀA`; here instead the fill-reducing ordering ([`FillOrdering`]) and the
//! supernodes of the Cholesky factor of `A` are computed once, and the numeric LU keeps that
//! structure: `L` has the Cholesky factor's pattern and `U` its transpose. Row pivoting is
//! allowed inside each supernode's diagonal block, which does not change the structure (the
//! rows of a supernode share their column pattern). A pivot that this restriction makes tiny is
//! caught by the solver's probe solve, and the caller falls back to the unrestricted LU. The
//! multipliers of constraint rows, whose diagonal is zero, are ordered after the DOFs they
//! couple ([`SparsityPattern::with_multipliers_from`]): in a supernode of their own before
//! them they would meet that zero as their pivot, and every factorisation would fall back.
//!
//! Each supernode is eliminated from a dense frontal matrix (its columns, its rows and the rows
//! of its pattern): the entries of `A`, then the children's update matrices (extend-add), then a
//! blocked right-looking LU of its leading columns, whose Schur complement is the update matrix
//! handed to the parent. Independent subtrees run as rayon tasks and the large trailing
//! updates are cut into column blocks of a fixed width. Every floating-point operation, and its
//! order, is fixed by the pattern alone: the factors are bit-identical for any number of threads.

use super::{SolverError, SparsityPattern};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::lu::partial_pivoting::factor as dense_lu;
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve as tri;
use faer::reborrow::{IntoConst, Reborrow, ReborrowMut};
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::{Accum, Mat, MatMut, MatRef, Par, Side};
use rayon::prelude::*;
use std::sync::Mutex;

/// Panel width of the blocked LU of a front.
const PANEL: usize = 64;
/// Column-block width of the trailing updates cut into parallel tasks.
const UPDATE_BLOCK: usize = 128;
/// Trailing updates below this many flops run as one task.
const PAR_UPDATE_FLOPS: f64 = 4.0e6;
/// Subtrees below this many flops are factorised in one task.
const PAR_SUBTREE_FLOPS: f64 = 2.0e6;
/// Subtrees with fewer stored factor entries are solved in one task (a solve reads every entry
/// once: 2¹⁶ entries are about 0.1 ms of work, far above a task's cost).
const PAR_SOLVE_ENTRIES: usize = 1 << 16;

/// Fill-reducing ordering of [`super::Method::SupernodalLu`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum FillOrdering {
    /// Of the three orderings below, the one whose factorisation costs least by
    /// `SupernodalSymbolic::cost` (each one's symbolic analysis is done; the pattern alone
    /// decides, so the choice is the same for every factorisation of a run and any number of
    /// threads): nested dissection unless another costs at most [`ORDERING_MARGIN`] of it.
    /// None is best on every grid of the shell tangents:
    /// `verification/hemisphere-plastic/README.md`.
    #[default]
    Cheapest,
    /// Nested dissection by level-set separators of the graph of supervariables (DOFs with
    /// identical columns), leaves of at most [`ND_LEAF`] DOFs kept in their numbering.
    NestedDissection,
    /// faer's approximate minimum degree.
    Amd,
    /// METIS's multilevel nested dissection (`METIS_NodeND`) of the graph of supervariables,
    /// each weighted by its DOFs.
    Metis,
}

/// Largest part (in DOFs) nested dissection does not cut further.
pub const ND_LEAF: usize = 128;

/// Operations one front entry costs in `SupernodalSymbolic::cost`: every entry is zeroed,
/// assembled and extend-added, memory-bound work. Fitted to one numeric factorisation of the
/// shell tangents under the three orderings (`solver_probe`, 2026-11-27): on the 17² hemisphere
/// METIS needs 21 % fewer operations than nested dissection and 41 % more front entries, and
/// both take 11.6 ms.
pub const FRONT_ENTRY_FLOPS: f64 = 100.0;

/// [`FillOrdering::Cheapest`] leaves nested dissection only for an ordering whose cost is at most
/// this fraction of its cost: below that margin the estimate does not tell them apart (the 17²
/// hemisphere's runs were 5 % slower with METIS's ordering at a 1 % lower estimate).
pub const ORDERING_MARGIN: f64 = 0.9;

/// The symbolic analysis: ordering, supernodes, assembly and extend-add maps.
#[derive(Debug)]
pub(crate) struct SupernodalSymbolic {
    n: usize,
    /// `perm[new] = old`.
    perm: Vec<usize>,
    /// First column of every supernode, and `n` at the end.
    begin: Vec<usize>,
    /// Rows below the diagonal block of every supernode (new numbering, ascending).
    rows_ptr: Vec<usize>,
    rows: Vec<usize>,
    /// Position of each of those rows in the parent's front.
    rel: Vec<u32>,
    /// Children of every supernode, ascending.
    children_ptr: Vec<usize>,
    children: Vec<usize>,
    roots: Vec<usize>,
    /// Entries of `A` per supernode: (slot, column-major position in the front).
    asm_ptr: Vec<usize>,
    asm: Vec<(u32, u32)>,
    /// Floating-point operations of every subtree's factorisation.
    subtree_flops: Vec<f64>,
    /// Stored factor entries of every subtree (the work of its part of a solve).
    subtree_entries: Vec<usize>,
    /// First supernode of every subtree, when every subtree's supernodes (and so its
    /// columns) are consecutive, the children's ranges in ascending order followed by the
    /// supernode itself (a postorder); `None` otherwise, and the solve runs sequentially.
    first: Option<Vec<usize>>,
    /// Operations of one numeric factorisation.
    pub flops: f64,
    /// Stored entries of `L` and `U` together.
    pub factor_entries: usize,
    /// Order of the largest front.
    pub max_front: usize,
    /// Entries of all fronts together (each is zeroed, assembled and extended-added once per
    /// factorisation).
    pub front_entries: usize,
    /// The ordering used (never [`FillOrdering::Cheapest`]: the one it chose).
    pub ordering: FillOrdering,
}

/// The numeric factors of every supernode.
#[derive(Debug)]
struct SupernodeFactor {
    /// `m × k`: `L₁₁ \ U₁₁` in rows `0..k` (rows in pivot order), `L₂₁` below.
    panel: Mat<f64>,
    /// `k × r`: `U₁₂` (rows in pivot order).
    u12: Mat<f64>,
    /// Row `i` of the factored block is the block's row `piv[i]`.
    piv: Vec<usize>,
    /// `panel` and `u12` rounded to single precision, read by the preconditioner's solves
    /// ([`SupernodalSymbolic::solve_single`]), made on their first use after a
    /// factorisation (`SupernodalNumeric::single_current`).
    panel_single: Mat<f32>,
    u12_single: Mat<f32>,
}

impl Default for SupernodeFactor {
    fn default() -> Self {
        SupernodeFactor {
            panel: Mat::new(),
            u12: Mat::new(),
            piv: Vec::new(),
            panel_single: Mat::new(),
            u12_single: Mat::new(),
        }
    }
}

/// A front: `m × m`, column-major, contiguous.
struct Front {
    m: usize,
    data: Vec<f64>,
}

/// Numeric factorisation over a [`SupernodalSymbolic`].
#[derive(Debug, Default)]
pub(crate) struct SupernodalNumeric {
    factors: Vec<Mutex<SupernodeFactor>>,
    /// Front storage kept from one factorisation to the next: the fronts of a pattern have
    /// the same sizes every time, so after the first factorisation no front is allocated
    /// (a fresh large allocation costs page faults and, when freed, a TLB shootdown on every
    /// core).
    pool: FrontPool,
    /// Whether the factors' single-precision copies are those of the current factorisation
    /// (made by the first single-precision solve after it, so that a run without one pays
    /// neither their time nor their memory).
    single_current: Mutex<bool>,
}

/// Buffers of released fronts.
#[derive(Debug, Default)]
struct FrontPool(Mutex<Vec<Vec<f64>>>);

impl FrontPool {
    /// A zeroed buffer of `len` entries: the smallest kept one that holds them, else a new one.
    fn take(&self, len: usize) -> Vec<f64> {
        let mut kept = self.0.lock().unwrap_or_else(|e| e.into_inner());
        let best = kept
            .iter()
            .enumerate()
            .filter(|(_, b)| b.capacity() >= len)
            .min_by_key(|(_, b)| b.capacity())
            .map(|(i, _)| i);
        let mut buf = match best {
            Some(i) => kept.swap_remove(i),
            None => Vec::with_capacity(len),
        };
        drop(kept);
        buf.clear();
        buf.resize(len, 0.0);
        buf
    }

    fn give(&self, buf: Vec<f64>) {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).push(buf);
    }
}

impl SupernodalSymbolic {
    /// Ordering and supernodes of `pattern` (the ordering on its structure, faer's supernodal
    /// symbolic Cholesky), with the maps the numeric phase uses.
    pub fn new(pattern: &SparsityPattern, ordering: FillOrdering) -> Result<Self, SolverError> {
        if ordering == FillOrdering::Cheapest {
            let nd = Self::new(pattern, FillOrdering::NestedDissection)?;
            let mut best: Option<Self> = None;
            for o in [FillOrdering::Metis, FillOrdering::Amd] {
                let s = Self::new(pattern, o)?;
                // Ties keep the earlier candidate.
                if best.as_ref().is_none_or(|b| s.cost() < b.cost()) {
                    best = Some(s);
                }
            }
            return Ok(match best {
                Some(b) if b.cost() <= ORDERING_MARGIN * nd.cost() => b,
                _ => nd,
            });
        }
        let n = pattern.n_dofs();
        let faer_err = |e: faer::sparse::FaerError| SolverError::Faer(format!("{e:?}"));
        let fwd = match ordering {
            FillOrdering::Cheapest => unreachable!("resolved above"),
            FillOrdering::NestedDissection => nested_dissection(pattern),
            FillOrdering::Amd => amd(pattern).map_err(faer_err)?,
            FillOrdering::Metis => metis_order(pattern)?,
        };
        let fwd = delay_multipliers(pattern, fwd);
        let mut inv = vec![0usize; n];
        for (new, &old) in fwd.iter().enumerate() {
            inv[old] = new;
        }
        let sym = factorize_symbolic_cholesky(
            pattern.symbolic(),
            Side::Lower,
            SymmetricOrdering::Custom(faer::perm::PermRef::new_checked(&fwd, &inv, n)),
            CholeskySymbolicParams {
                supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
                ..Default::default()
            },
        )
        .map_err(faer_err)?;
        let perm: Vec<usize> = match sym.perm() {
            Some(p) => p.arrays().0.to_vec(),
            None => (0..n).collect(),
        };
        let mut perm_inv = vec![0usize; n];
        for (new, &old) in perm.iter().enumerate() {
            perm_inv[old] = new;
        }
        let SymbolicCholeskyRaw::Supernodal(sn) = sym.raw() else {
            return Err(SolverError::Faer(
                "supernodal symbolic analysis expected".into(),
            ));
        };
        let ns = sn.n_supernodes();
        let mut begin: Vec<usize> = sn.supernode_begin().to_vec();
        begin.push(n);
        let mut rows_ptr = vec![0usize];
        let mut rows = Vec::new();
        for s in 0..ns {
            rows.extend_from_slice(sn.supernode(s).pattern());
            rows_ptr.push(rows.len());
        }
        let mut sn_of = vec![0usize; n];
        for s in 0..ns {
            sn_of[begin[s]..begin[s + 1]].fill(s);
        }
        // Parent: the supernode of the first row below the diagonal block.
        let parent: Vec<Option<usize>> = (0..ns)
            .map(|s| {
                rows[rows_ptr[s]..rows_ptr[s + 1]]
                    .first()
                    .map(|&r| sn_of[r])
            })
            .collect();
        let mut n_children = vec![0usize; ns + 1];
        for p in parent.iter().flatten() {
            n_children[p + 1] += 1;
        }
        for s in 0..ns {
            n_children[s + 1] += n_children[s];
        }
        let children_ptr = n_children.clone();
        let mut fill = n_children;
        let mut children = vec![0usize; children_ptr[ns]];
        let mut roots = Vec::new();
        for (s, p) in parent.iter().enumerate() {
            match p {
                Some(p) => {
                    children[fill[*p]] = s;
                    fill[*p] += 1;
                }
                None => roots.push(s),
            }
        }
        // Position of an index in the front of supernode s.
        let local = |s: usize, x: usize| -> Option<usize> {
            let (f, l) = (begin[s], begin[s + 1]);
            if (f..l).contains(&x) {
                Some(x - f)
            } else {
                rows[rows_ptr[s]..rows_ptr[s + 1]]
                    .binary_search(&x)
                    .ok()
                    .map(|p| l - f + p)
            }
        };
        let mut rel = vec![0u32; rows.len()];
        for s in 0..ns {
            if let Some(p) = parent[s] {
                for q in rows_ptr[s]..rows_ptr[s + 1] {
                    let pos = local(p, rows[q]).ok_or_else(|| {
                        SolverError::Faer(format!(
                            "supernode {s}: row {} missing from its parent's front",
                            rows[q]
                        ))
                    })?;
                    rel[q] = pos as u32;
                }
            }
        }
        // Entries of A, bucketed by supernode.
        let front = |s: usize| begin[s + 1] - begin[s] + rows_ptr[s + 1] - rows_ptr[s];
        let (cp, ri) = (pattern.col_ptr(), pattern.row_idx());
        let mut count = vec![0usize; ns + 1];
        for j in 0..n {
            for &i in &ri[cp[j]..cp[j + 1]] {
                count[sn_of[perm_inv[i].min(perm_inv[j])] + 1] += 1;
            }
        }
        for s in 0..ns {
            count[s + 1] += count[s];
        }
        let asm_ptr = count.clone();
        let mut fill = count;
        let mut asm = vec![(0u32, 0u32); asm_ptr[ns]];
        for j in 0..n {
            for (q, &i) in ri[cp[j]..cp[j + 1]].iter().enumerate() {
                let (pi, pj) = (perm_inv[i], perm_inv[j]);
                let s = sn_of[pi.min(pj)];
                let m = front(s);
                let (li, lj) = (local(s, pi), local(s, pj));
                let (Some(li), Some(lj)) = (li, lj) else {
                    return Err(SolverError::Faer(format!(
                        "entry ({i}, {j}) outside the front of supernode {s}"
                    )));
                };
                asm[fill[s]] = ((cp[j] + q) as u32, (lj * m + li) as u32);
                fill[s] += 1;
            }
        }
        // Operations: per pivot column with c entries below it in L (and c right of it in U),
        // c divisions and 2c² for the rank-one update.
        let mut flops_of = vec![0.0f64; ns];
        let mut factor_entries = 0usize;
        let mut max_front = 0usize;
        let mut front_entries = 0usize;
        for s in 0..ns {
            let k = begin[s + 1] - begin[s];
            let m = front(s);
            max_front = max_front.max(m);
            front_entries += m * m;
            factor_entries += k * (2 * m - k);
            flops_of[s] = (0..k)
                .map(|i| {
                    let c = (m - i - 1) as f64;
                    c + 2.0 * c * c
                })
                .sum();
        }
        let mut subtree_flops = flops_of.clone();
        let mut subtree_entries: Vec<usize> = (0..ns)
            .map(|s| {
                let k = begin[s + 1] - begin[s];
                k * (2 * front(s) - k)
            })
            .collect();
        for s in 0..ns {
            if let Some(p) = parent[s] {
                subtree_flops[p] += subtree_flops[s];
                subtree_entries[p] += subtree_entries[s];
            }
        }
        let first = postorder_ranges(&children_ptr, &children, &roots, ns);
        if asm.len() > u32::MAX as usize || max_front.pow(2) > u32::MAX as usize {
            return Err(SolverError::TooManyEntries { nnz: asm.len() });
        }
        Ok(Self {
            n,
            perm,
            begin,
            rows_ptr,
            rows,
            rel,
            children_ptr,
            children,
            roots,
            asm_ptr,
            asm,
            subtree_flops,
            subtree_entries,
            first,
            flops: flops_of.iter().sum(),
            factor_entries,
            max_front,
            front_entries,
            ordering,
        })
    }

    /// The estimated cost of one numeric factorisation, in operations: its flops plus
    /// [`FRONT_ENTRY_FLOPS`] per front entry.
    pub fn cost(&self) -> f64 {
        self.flops + FRONT_ENTRY_FLOPS * self.front_entries as f64
    }

    /// Number of supernodes.
    pub fn n_supernodes(&self) -> usize {
        self.begin.len() - 1
    }

    fn k(&self, s: usize) -> usize {
        self.begin[s + 1] - self.begin[s]
    }

    fn r(&self, s: usize) -> usize {
        self.rows_ptr[s + 1] - self.rows_ptr[s]
    }

    fn kids(&self, s: usize) -> &[usize] {
        &self.children[self.children_ptr[s]..self.children_ptr[s + 1]]
    }

    /// Numeric factorisation of the matrix with `values` over the pattern analysed.
    pub fn factorize(&self, values: &[f64], numeric: &mut SupernodalNumeric) {
        let ns = self.n_supernodes();
        if numeric.factors.len() != ns {
            numeric.factors = (0..ns).map(|_| Mutex::default()).collect();
        }
        *numeric
            .single_current
            .get_mut()
            .unwrap_or_else(|e| e.into_inner()) = false;
        let (factors, pool) = (&numeric.factors, &numeric.pool);
        self.roots
            .par_iter()
            .with_max_len(1)
            .for_each(|&s| pool.give(self.factor_subtree(s, values, factors, pool).data));
    }

    /// Factorise the subtree rooted at `s`; returns its front (update matrix in rows and
    /// columns `k..`).
    fn factor_subtree(
        &self,
        s: usize,
        values: &[f64],
        factors: &[Mutex<SupernodeFactor>],
        pool: &FrontPool,
    ) -> Front {
        let kids = self.kids(s);
        let updates: Vec<Front> = if kids.len() > 1 && self.subtree_flops[s] > PAR_SUBTREE_FLOPS {
            kids.par_iter()
                .with_max_len(1)
                .map(|&c| self.factor_subtree(c, values, factors, pool))
                .collect()
        } else {
            kids.iter()
                .map(|&c| self.factor_subtree(c, values, factors, pool))
                .collect()
        };
        let (k, r) = (self.k(s), self.r(s));
        let m = k + r;
        let mut data = pool.take(m * m);
        for &(slot, pos) in &self.asm[self.asm_ptr[s]..self.asm_ptr[s + 1]] {
            data[pos as usize] += values[slot as usize];
        }
        for (&c, upd) in kids.iter().zip(&updates) {
            let (kc, mc) = (self.k(c), upd.m);
            let rel = &self.rel[self.rows_ptr[c]..self.rows_ptr[c + 1]];
            for (b, &pb) in rel.iter().enumerate() {
                let src = &upd.data[(kc + b) * mc + kc..(kc + b + 1) * mc];
                let dst = &mut data[pb as usize * m..(pb as usize + 1) * m];
                for (&pa, &v) in rel.iter().zip(src) {
                    dst[pa as usize] += v;
                }
            }
        }
        for upd in updates {
            pool.give(upd.data);
        }
        let mut piv: Vec<usize> = (0..k).collect();
        {
            let f = MatMut::from_column_major_slice_mut(&mut data, m, m);
            partial_lu(f, k, &mut piv);
        }
        let f = MatRef::from_column_major_slice(&data, m, m);
        let mut fac = factors[s].lock().unwrap_or_else(|e| e.into_inner());
        fac.panel.resize_with(m, k, |_, _| 0.0);
        fac.panel.copy_from(f.subcols(0, k));
        fac.u12.resize_with(k, r, |_, _| 0.0);
        fac.u12.copy_from(f.submatrix(0, k, k, r));
        fac.piv = piv;
        drop(fac);
        Front { m, data }
    }

    /// Sign of the determinant of the matrix factorised in `numeric` (`+1`, `−1`, or `0` for an
    /// exactly zero pivot). The symmetric fill-reducing permutation leaves the determinant
    /// unchanged; the row pivoting inside every supernode's diagonal block is a block-diagonal
    /// row permutation `Π` with `Π P A Pᵀ = L U`, `L` unit lower triangular, so
    /// `sign det A = sign det Π · Π_i sign U_ii` (the parity of every supernode's pivot order
    /// times the signs of its `U₁₁` diagonal).
    pub fn determinant_sign(&self, numeric: &SupernodalNumeric) -> f64 {
        let mut negative = false;
        for s in 0..numeric.factors.len() {
            let fac = factors_ref(numeric, s);
            if permutation_is_odd(&fac.piv) {
                negative = !negative;
            }
            for i in 0..fac.piv.len() {
                let d = fac.panel[(i, i)];
                if d == 0.0 {
                    return 0.0;
                }
                if d < 0.0 {
                    negative = !negative;
                }
            }
        }
        if negative {
            -1.0
        } else {
            1.0
        }
    }

    /// Solve in place for every column of `rhs` with the factors in `numeric`.
    ///
    /// Both substitutions run over the supernodal tree as the factorisation does, front by
    /// front: the forward one hands each parent the sum of its subtree's updates to the rows
    /// of the subtree root's pattern (an update vector, extend-added by the same maps as the
    /// update matrices), the backward one hands each child the solved values of its parent's
    /// front. Subtrees then write disjoint rows only, so independent subtrees run as rayon
    /// tasks; every operation and its order is fixed by the pattern alone, and the result is
    /// bit-identical for any number of threads.
    pub fn solve(&self, numeric: &SupernodalNumeric, rhs: MatMut<'_, f64>) {
        self.solve_with::<f64>(numeric, rhs);
    }

    /// [`Self::solve`] with the factors rounded to single precision, in single precision:
    /// half the memory traffic of the double-precision solve, for a preconditioner (the
    /// rounding perturbs the factors by a relative 6e-8, far less than the staleness of a
    /// factorisation held over Newton iterates).
    pub fn solve_single(&self, numeric: &SupernodalNumeric, rhs: MatMut<'_, f32>) {
        {
            let mut current = numeric
                .single_current
                .lock()
                .unwrap_or_else(|e| e.into_inner());
            if !*current {
                numeric.factors.par_iter().for_each(|f| {
                    let mut fac = f.lock().unwrap_or_else(|e| e.into_inner());
                    let SupernodeFactor {
                        panel,
                        u12,
                        panel_single,
                        u12_single,
                        ..
                    } = &mut *fac;
                    round_into(panel.as_ref(), panel_single);
                    round_into(u12.as_ref(), u12_single);
                });
                *current = true;
            }
        }
        self.solve_with::<f32>(numeric, rhs);
    }

    fn solve_with<T: Precision>(&self, numeric: &SupernodalNumeric, mut rhs: MatMut<'_, T>) {
        let n = self.n;
        let nrhs = rhs.ncols();
        let mut x = Mat::<T>::zeros(n, nrhs);
        for j in 0..nrhs {
            for (new, &old) in self.perm.iter().enumerate() {
                x[(new, j)] = rhs[(old, j)];
            }
        }
        match &self.first {
            Some(first) => {
                let mut parts = Vec::with_capacity(self.roots.len());
                let mut rest = x.as_mut();
                for &s in &self.roots {
                    let len = self.begin[s + 1] - self.begin[first[s]];
                    let (a, b) = rest.split_at_row_mut(len);
                    parts.push((s, a));
                    rest = b;
                }
                let no_rows = Mat::<T>::zeros(0, nrhs);
                parts
                    .into_par_iter()
                    .with_max_len(1)
                    .for_each(|(s, mut xs)| {
                        self.forward(numeric, first, s, xs.rb_mut());
                        self.backward(numeric, first, s, xs, no_rows.as_ref());
                    });
            }
            None => self.solve_sequential(numeric, x.as_mut()),
        }
        for j in 0..nrhs {
            for (new, &old) in self.perm.iter().enumerate() {
                rhs[(old, j)] = x[(new, j)];
            }
        }
    }

    /// The children of `s` with their rows of `x` (the subtree's rows, children first).
    #[allow(clippy::type_complexity)]
    fn split_children<'a, T: Precision>(
        &self,
        first: &[usize],
        s: usize,
        x: MatMut<'a, T>,
    ) -> (Vec<(usize, MatMut<'a, T>)>, MatMut<'a, T>) {
        let (mut rest, own) = x.split_at_row_mut(self.begin[s] - self.begin[first[s]]);
        let kids = self.kids(s);
        let mut parts = Vec::with_capacity(kids.len());
        for &c in kids {
            let (a, b) = rest.split_at_row_mut(self.begin[c + 1] - self.begin[first[c]]);
            parts.push((c, a));
            rest = b;
        }
        (parts, own)
    }

    /// Whether the children of `s` are solved as parallel tasks.
    fn solve_in_parallel(&self, s: usize) -> bool {
        self.kids(s).len() > 1 && self.subtree_entries[s] >= PAR_SOLVE_ENTRIES
    }

    /// Forward substitution `L y = P b` over the subtree of `s`, whose rows of `x` (children's
    /// subtrees, then `s`'s own columns) hold `P b` and receive `y`; returns the subtree's
    /// update to the rows of `s`'s pattern (to be added to the parent's front).
    fn forward<T: Precision>(
        &self,
        numeric: &SupernodalNumeric,
        first: &[usize],
        s: usize,
        x: MatMut<'_, T>,
    ) -> Mat<T> {
        let (parts, mut own) = self.split_children(first, s, x);
        let updates: Vec<Mat<T>> = if self.solve_in_parallel(s) {
            parts
                .into_par_iter()
                .with_max_len(1)
                .map(|(c, xc)| self.forward(numeric, first, c, xc))
                .collect()
        } else {
            parts
                .into_iter()
                .map(|(c, xc)| self.forward(numeric, first, c, xc))
                .collect()
        };
        let nrhs = own.ncols();
        let (k, r) = (self.k(s), self.r(s));
        let mut front = Mat::<T>::zeros(k + r, nrhs);
        front.as_mut().subrows_mut(0, k).copy_from(own.rb());
        for (&c, upd) in self.kids(s).iter().zip(&updates) {
            let rel = &self.rel[self.rows_ptr[c]..self.rows_ptr[c + 1]];
            for j in 0..nrhs {
                for (a, &p) in rel.iter().enumerate() {
                    front[(p as usize, j)] += upd[(a, j)];
                }
            }
        }
        let fac = factors_ref(numeric, s);
        for j in 0..nrhs {
            for (i, &p) in fac.piv.iter().enumerate() {
                own[(i, j)] = front[(p, j)];
            }
        }
        let panel = T::panel(&fac);
        tri::solve_unit_lower_triangular_in_place(
            panel.submatrix(0, 0, k, k),
            own.rb_mut(),
            Par::Seq,
        );
        let mut update = front.as_mut().subrows_mut(k, r);
        if r > 0 {
            matmul(
                update.rb_mut(),
                Accum::Add,
                panel.submatrix(k, 0, r, k),
                own.rb(),
                T::MINUS_ONE,
                Par::Seq,
            );
        }
        update.to_owned()
    }

    /// Backward substitution `U x = y` over the subtree of `s`: its rows of `x` hold `y` and
    /// receive `x`; `above` holds the solution at the rows of `s`'s pattern.
    fn backward<T: Precision>(
        &self,
        numeric: &SupernodalNumeric,
        first: &[usize],
        s: usize,
        x: MatMut<'_, T>,
        above: MatRef<'_, T>,
    ) {
        let (parts, mut own) = self.split_children(first, s, x);
        let (k, r) = (self.k(s), self.r(s));
        {
            let fac = factors_ref(numeric, s);
            if r > 0 {
                matmul(
                    own.rb_mut(),
                    Accum::Add,
                    T::u12(&fac),
                    above,
                    T::MINUS_ONE,
                    Par::Seq,
                );
            }
            tri::solve_upper_triangular_in_place(
                T::panel(&fac).submatrix(0, 0, k, k),
                own.rb_mut(),
                Par::Seq,
            );
        }
        if parts.is_empty() {
            return;
        }
        let nrhs = own.ncols();
        let mut front = Mat::<T>::zeros(k + r, nrhs);
        front.as_mut().subrows_mut(0, k).copy_from(own.rb());
        front.as_mut().subrows_mut(k, r).copy_from(above);
        let child = |(c, xc): (usize, MatMut<'_, T>)| {
            let rel = &self.rel[self.rows_ptr[c]..self.rows_ptr[c + 1]];
            let mut a = Mat::<T>::zeros(rel.len(), nrhs);
            for j in 0..nrhs {
                for (q, &p) in rel.iter().enumerate() {
                    a[(q, j)] = front[(p as usize, j)];
                }
            }
            self.backward(numeric, first, c, xc, a.as_ref());
        };
        if self.solve_in_parallel(s) {
            parts.into_par_iter().with_max_len(1).for_each(child);
        } else {
            parts.into_iter().for_each(child);
        }
    }

    /// The solve supernode by supernode in their order, for trees whose subtrees are not
    /// consecutive.
    fn solve_sequential<T: Precision>(&self, numeric: &SupernodalNumeric, mut x: MatMut<'_, T>) {
        let nrhs = x.ncols();
        let mut tmp = Mat::<T>::zeros(0, 0);
        let ns = self.n_supernodes();
        // Forward: L y = P b.
        for s in 0..ns {
            let fac = factors_ref(numeric, s);
            let (f0, k, r) = (self.begin[s], self.k(s), self.r(s));
            tmp.resize_with(k.max(r), nrhs, |_, _| T::ZERO);
            for j in 0..nrhs {
                for (i, &p) in fac.piv.iter().enumerate() {
                    tmp[(i, j)] = x[(f0 + p, j)];
                }
                for i in 0..k {
                    x[(f0 + i, j)] = tmp[(i, j)];
                }
            }
            let panel = T::panel(&fac);
            tri::solve_unit_lower_triangular_in_place(
                panel.submatrix(0, 0, k, k),
                x.rb_mut().subrows_mut(f0, k),
                Par::Seq,
            );
            if r > 0 {
                let mut t = tmp.as_mut().submatrix_mut(0, 0, r, nrhs);
                matmul(
                    t.rb_mut(),
                    Accum::Replace,
                    panel.submatrix(k, 0, r, k),
                    x.rb().subrows(f0, k),
                    T::ONE,
                    Par::Seq,
                );
                let rows = &self.rows[self.rows_ptr[s]..self.rows_ptr[s + 1]];
                for j in 0..nrhs {
                    for (a, &ra) in rows.iter().enumerate() {
                        x[(ra, j)] -= t[(a, j)];
                    }
                }
            }
        }
        // Backward: U x = y.
        for s in (0..ns).rev() {
            let fac = factors_ref(numeric, s);
            let (f0, k, r) = (self.begin[s], self.k(s), self.r(s));
            if r > 0 {
                tmp.resize_with(r, nrhs, |_, _| T::ZERO);
                let rows = &self.rows[self.rows_ptr[s]..self.rows_ptr[s + 1]];
                for j in 0..nrhs {
                    for (a, &ra) in rows.iter().enumerate() {
                        tmp[(a, j)] = x[(ra, j)];
                    }
                }
                matmul(
                    x.rb_mut().subrows_mut(f0, k),
                    Accum::Add,
                    T::u12(&fac),
                    tmp.as_ref(),
                    T::MINUS_ONE,
                    Par::Seq,
                );
            }
            tri::solve_upper_triangular_in_place(
                T::panel(&fac).submatrix(0, 0, k, k),
                x.rb_mut().subrows_mut(f0, k),
                Par::Seq,
            );
        }
    }
}

/// First supernode of every subtree when the tree is in postorder (every subtree's supernodes
/// consecutive, its children's ranges ascending and adjacent, then itself, and the roots'
/// ranges tiling all supernodes in ascending order); `None` otherwise.
fn postorder_ranges(
    children_ptr: &[usize],
    children: &[usize],
    roots: &[usize],
    ns: usize,
) -> Option<Vec<usize>> {
    let mut first: Vec<usize> = (0..ns).collect();
    for s in 0..ns {
        let kids = &children[children_ptr[s]..children_ptr[s + 1]];
        let mut next = None;
        for &c in kids {
            // Children come before their parent, so `first[c]` is final here.
            if c >= s || next.is_some_and(|n| first[c] != n) {
                return None;
            }
            if next.is_none() {
                first[s] = first[c];
            }
            next = Some(c + 1);
        }
        if next.is_some_and(|n| n != s) {
            return None;
        }
    }
    let mut next = 0;
    for &s in roots {
        if first[s] != next {
            return None;
        }
        next = s + 1;
    }
    (next == ns).then_some(first)
}

/// The precision of a solve: which copy of the factors it reads.
trait Precision: faer::traits::RealField + Copy + std::ops::AddAssign + std::ops::SubAssign {
    const ZERO: Self;
    const ONE: Self;
    const MINUS_ONE: Self;
    fn panel(f: &SupernodeFactor) -> MatRef<'_, Self>;
    fn u12(f: &SupernodeFactor) -> MatRef<'_, Self>;
}

/// The two precisions, each reading its own copy of the factors.
macro_rules! precision {
    ($t:ty, $panel:ident, $u12:ident) => {
        impl Precision for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const MINUS_ONE: Self = -1.0;
            fn panel(f: &SupernodeFactor) -> MatRef<'_, Self> {
                f.$panel.as_ref()
            }
            fn u12(f: &SupernodeFactor) -> MatRef<'_, Self> {
                f.$u12.as_ref()
            }
        }
    };
}
precision!(f64, panel, u12);
precision!(f32, panel_single, u12_single);

/// `to = from` rounded to single precision (resized to its shape).
fn round_into(from: MatRef<'_, f64>, to: &mut Mat<f32>) {
    to.resize_with(from.nrows(), from.ncols(), |_, _| 0.0);
    for j in 0..from.ncols() {
        let (src, dst) = (from.col(j), to.as_mut().col_mut(j));
        for (d, s) in dst.iter_mut().zip(src.iter()) {
            *d = *s as f32;
        }
    }
}

fn factors_ref(
    numeric: &SupernodalNumeric,
    s: usize,
) -> std::sync::MutexGuard<'_, SupernodeFactor> {
    numeric.factors[s].lock().unwrap_or_else(|e| e.into_inner())
}

/// Whether the permutation `p` (`p[i]` the old index of new position `i`) is odd: a cycle of
/// length `c` is `c − 1` transpositions, so the parity is that of `n − (number of cycles)`.
pub(crate) fn permutation_is_odd(p: &[usize]) -> bool {
    let mut seen = vec![false; p.len()];
    let mut transpositions = 0usize;
    for start in 0..p.len() {
        let mut len = 0usize;
        let mut i = start;
        while !seen[i] {
            seen[i] = true;
            i = p[i];
            len += 1;
        }
        transpositions += len.saturating_sub(1);
    }
    transpositions % 2 == 1
}

/// Reorder rows `0..p.len()` of `a` so that new row `i` is old row `p[i]`. Only the rows the
/// permutation moves are touched (they are a permutation of themselves): a panel's pivoting
/// swaps a few rows of a block of hundreds.
fn permute_rows(mut a: MatMut<'_, f64>, p: &[usize], tmp: &mut Vec<f64>) {
    let moved: Vec<(usize, usize)> = p
        .iter()
        .enumerate()
        .filter(|&(i, &pi)| i != pi)
        .map(|(i, &pi)| (i, pi))
        .collect();
    tmp.resize(moved.len(), 0.0);
    for j in 0..a.ncols() {
        let mut col = a.rb_mut().col_mut(j);
        for (t, &(_, pi)) in tmp.iter_mut().zip(&moved) {
            *t = col[pi];
        }
        for (&(i, _), t) in moved.iter().zip(tmp.iter()) {
            col[i] = *t;
        }
    }
}

/// `c −= a b`, cut into column blocks of [`UPDATE_BLOCK`] run as rayon tasks when large. The
/// blocks depend on the shapes only.
fn update(c: MatMut<'_, f64>, a: MatRef<'_, f64>, b: MatRef<'_, f64>) {
    let flops = 2.0 * c.nrows() as f64 * c.ncols() as f64 * a.ncols() as f64;
    if flops < PAR_UPDATE_FLOPS || c.ncols() <= UPDATE_BLOCK {
        matmul(c, Accum::Add, a, b, -1.0, Par::Seq);
        return;
    }
    let mut blocks = Vec::new();
    let mut rest = c;
    let mut j0 = 0;
    while rest.ncols() > 0 {
        let w = UPDATE_BLOCK.min(rest.ncols());
        let (head, tail) = rest.split_at_col_mut(w);
        blocks.push((j0, head));
        rest = tail;
        j0 += w;
    }
    blocks
        .into_par_iter()
        .with_max_len(1)
        .for_each(|(j0, blk)| {
            let w = blk.ncols();
            matmul(blk, Accum::Add, a, b.subcols(j0, w), -1.0, Par::Seq);
        });
}

/// Blocked right-looking LU of the leading `k` columns of the `m × m` front `f`, pivoting among
/// its first `k` rows only; the trailing `(m − k) × (m − k)` block becomes the Schur complement.
/// `piv` (initially `0..k`) receives the pivot order of the first `k` rows.
fn partial_lu(mut f: MatMut<'_, f64>, k: usize, piv: &mut [usize]) {
    let m = f.nrows();
    let params: dense_lu::PartialPivLuParams = faer::Auto::<f64>::auto();
    let mut fwd = vec![0usize; k];
    let mut bwd = vec![0usize; k];
    let mut tmp = Vec::new();
    let mut buf = MemBuffer::new(dense_lu::lu_in_place_scratch::<usize, f64>(
        k,
        PANEL.min(k),
        Par::Seq,
        params.into(),
    ));
    let mut j = 0;
    while j < k {
        let w = PANEL.min(k - j);
        let h = k - j;
        // Panel LU with pivoting among the block's remaining rows j..k.
        let (fwd, bwd) = (&mut fwd[..h], &mut bwd[..h]);
        dense_lu::lu_in_place(
            f.rb_mut().submatrix_mut(j, j, h, w),
            fwd,
            bwd,
            Par::Seq,
            MemStack::new(&mut buf),
            params.into(),
        );
        // Most panels of the (nearly symmetric, diagonally strong) tangents keep their row
        // order: nothing to move then.
        if fwd.iter().enumerate().any(|(i, &p)| i != p) {
            permute_rows(f.rb_mut().submatrix_mut(j, 0, h, j), fwd, &mut tmp);
            permute_rows(
                f.rb_mut().submatrix_mut(j, j + w, h, m - j - w),
                fwd,
                &mut tmp,
            );
            let old: Vec<usize> = piv[j..k].to_vec();
            for (i, &p) in fwd.iter().enumerate() {
                piv[j + i] = old[p];
            }
        }
        // Rows below the block: X U = B with the panel's upper triangle U (Uᵀ Xᵀ = Bᵀ).
        if m > k {
            let (block, below) = f.rb_mut().submatrix_mut(j, j, m - j, w).split_at_row_mut(h);
            tri::solve_lower_triangular_in_place(
                block.rb().submatrix(0, 0, w, w).transpose(),
                below.transpose_mut(),
                Par::Seq,
            );
        }
        let (left, right) = f.rb_mut().split_at_col_mut(j + w);
        let left = left.into_const();
        let diag = left.submatrix(j, j, w, w);
        // U row block: L₁₁ X = B over the trailing columns.
        let (top, bottom) = right.split_at_row_mut(j + w);
        let mut u_rows = top.submatrix_mut(j, 0, w, m - j - w);
        tri::solve_unit_lower_triangular_in_place(diag, u_rows.rb_mut(), Par::Seq);
        // Trailing update of rows j+w..m.
        update(
            bottom,
            left.submatrix(j + w, j, m - j - w, w),
            u_rows.into_const(),
        );
        j += w;
    }
}

/// faer's approximate minimum degree ordering (`perm[new] = old`) of the pattern.
fn amd(pattern: &SparsityPattern) -> Result<Vec<usize>, faer::sparse::FaerError> {
    use faer::sparse::linalg::amd;
    let n = pattern.n_dofs();
    let mut fwd = vec![0usize; n];
    let mut inv = vec![0usize; n];
    let mut buf = MemBuffer::try_new(amd::order_scratch::<usize>(n, pattern.nnz()))?;
    amd::order(
        &mut fwd,
        &mut inv,
        pattern.symbolic(),
        amd::Control::default(),
        MemStack::new(&mut buf),
    )?;
    Ok(fwd)
}

/// `order` (`order[new] = old`) with every multiplier DOF
/// ([`SparsityPattern::with_multipliers_from`]) moved to just after the last of the other DOFs
/// it couples. Its pivot is then formed once those are eliminated: the Schur complement
/// `−c K⁻¹ cᵀ` of its row, not the structural zero on its diagonal, which pivoting within a
/// supernode cannot avoid when the multiplier sits in a supernode of its own. In the
/// elimination tree a multiplier is then an ancestor of every DOF it couples, so the
/// supernodes (a postorder of that tree) keep it after them.
fn delay_multipliers(pattern: &SparsityPattern, order: Vec<usize>) -> Vec<usize> {
    let first = pattern.multipliers_from();
    let n = pattern.n_dofs();
    if first >= n {
        return order;
    }
    let mut pos = vec![0usize; n];
    for (p, &d) in order.iter().enumerate() {
        pos[d] = p;
    }
    let (cp, ri) = (pattern.col_ptr(), pattern.row_idx());
    // (position it follows, 0 for a DOF of K and 1 for a multiplier, own position, DOF).
    let mut keyed: Vec<(usize, u8, usize, usize)> = order
        .iter()
        .map(|&d| {
            if d < first {
                (pos[d], 0, pos[d], d)
            } else {
                let last = ri[cp[d]..cp[d + 1]]
                    .iter()
                    .filter(|&&r| r < first)
                    .map(|&r| pos[r])
                    .max()
                    .unwrap_or(pos[d]);
                (last, 1, pos[d], d)
            }
        })
        .collect();
    keyed.sort_unstable();
    keyed.into_iter().map(|k| k.3).collect()
}

/// Nested-dissection ordering (`perm[new] = old`) of the pattern's graph.
///
/// DOFs whose columns have identical patterns (the five DOFs of a particle) form one
/// supervariable. A part is cut by a level set of a breadth-first search from a
/// pseudo-peripheral node: every edge joins equal or adjacent levels, so one level separates
/// the levels before it from those after; the lightest level that leaves between a quarter and
/// three quarters of the weight on each side is taken, and its nodes without a neighbour after
/// it move to the first side. Parts are ordered first, separators last, recursively down to
/// parts of at most [`ND_LEAF`] DOFs. Everything depends on the pattern only.
pub fn nested_dissection(pattern: &SparsityPattern) -> Vec<usize> {
    let g = SupervariableGraph::new(pattern);
    let ns = g.cols.len();
    let mut nd = Dissection {
        adj_ptr: &g.adj_ptr,
        adj: &g.adj,
        weight: &g.weight,
        stamp: vec![0usize; ns],
        level: vec![0usize; ns],
        next_stamp: 0,
        order: Vec::with_capacity(ns),
    };
    nd.dissect((0..ns).collect());
    g.expand(&nd.order)
}

/// METIS's nested dissection of the graph of supervariables (`perm[new] = old` on the DOFs).
fn metis_order(pattern: &SparsityPattern) -> Result<Vec<usize>, SolverError> {
    let g = SupervariableGraph::new(pattern);
    let ns = g.cols.len();
    let too_large = |what: &str, v: usize| {
        SolverError::Faer(format!(
            "METIS ordering: {what} {v} exceeds its 32-bit index range"
        ))
    };
    let idx = |v: usize, what: &str| i32::try_from(v).map_err(|_| too_large(what, v));
    let mut nvtxs = idx(ns, "vertex count")?;
    let mut xadj = g
        .adj_ptr
        .iter()
        .map(|&v| idx(v, "adjacency length"))
        .collect::<Result<Vec<i32>, _>>()?;
    let mut adjncy: Vec<i32> = g.adj.iter().map(|&v| v as i32).collect();
    let mut vwgt = g
        .weight
        .iter()
        .map(|&v| idx(v, "vertex weight"))
        .collect::<Result<Vec<i32>, _>>()?;
    let mut options = [0i32; metis_sys::METIS_NOPTIONS as usize];
    let mut perm = vec![0i32; ns];
    let mut iperm = vec![0i32; ns];
    if ns == 0 {
        return Ok(Vec::new());
    }
    // SAFETY: every array has the length METIS reads (nvtxs + 1 offsets, xadj[nvtxs] neighbours
    // without self-loops in 0..nvtxs, nvtxs weights and outputs, METIS_NOPTIONS options), and
    // all outlive the call, which keeps no pointer to them.
    let status = unsafe {
        metis_sys::METIS_SetDefaultOptions(options.as_mut_ptr());
        metis_sys::METIS_NodeND(
            &mut nvtxs,
            xadj.as_mut_ptr(),
            adjncy.as_mut_ptr(),
            vwgt.as_mut_ptr(),
            options.as_mut_ptr(),
            perm.as_mut_ptr(),
            iperm.as_mut_ptr(),
        )
    };
    if status != metis_sys::rstatus_et_METIS_OK {
        return Err(SolverError::Faer(format!(
            "METIS_NodeND returned status {status} on {ns} supervariables"
        )));
    }
    let order: Vec<usize> = perm.iter().map(|&p| p as usize).collect();
    Ok(g.expand(&order))
}

/// Supervariables of a pattern (DOFs with identical columns), numbered by their first DOF,
/// with their adjacency (no self-loops) and weights (DOFs each).
struct SupervariableGraph {
    cols: Vec<Vec<usize>>,
    adj_ptr: Vec<usize>,
    adj: Vec<usize>,
    weight: Vec<usize>,
}

impl SupervariableGraph {
    /// The DOF order of a supervariable order.
    fn expand(&self, order: &[usize]) -> Vec<usize> {
        order
            .iter()
            .flat_map(|&s| self.cols[s].iter().copied())
            .collect()
    }

    fn new(pattern: &SparsityPattern) -> Self {
        let n = pattern.n_dofs();
        let (cp, ri) = (pattern.col_ptr(), pattern.row_idx());
        // Supervariables: columns with identical row patterns.
        let hash = |j: usize| {
            ri[cp[j]..cp[j + 1]]
                .iter()
                .fold(0xcbf2_9ce4_8422_2325u64, |h, &r| {
                    (h ^ r as u64).wrapping_mul(0x0100_0000_01b3)
                })
        };
        let mut cols: Vec<(usize, u64, usize)> =
            (0..n).map(|j| (cp[j + 1] - cp[j], hash(j), j)).collect();
        cols.sort_unstable();
        let mut sv_of = vec![0usize; n];
        let mut sv_cols: Vec<Vec<usize>> = Vec::new();
        for (idx, &(len, h, j)) in cols.iter().enumerate() {
            let same = idx > 0 && {
                let (l0, h0, j0) = cols[idx - 1];
                l0 == len && h0 == h && ri[cp[j0]..cp[j0 + 1]] == ri[cp[j]..cp[j + 1]]
            };
            if !same {
                sv_cols.push(Vec::new());
            }
            let s = sv_cols.len() - 1;
            sv_cols[s].push(j);
            sv_of[j] = s;
        }
        // Number supervariables by their first column (the DOF numbering's locality).
        let mut by_first: Vec<usize> = (0..sv_cols.len()).collect();
        by_first.sort_unstable_by_key(|&s| sv_cols[s].iter().min().copied());
        let mut renumber = vec![0usize; sv_cols.len()];
        for (new, &old) in by_first.iter().enumerate() {
            renumber[old] = new;
        }
        let sv_cols: Vec<Vec<usize>> = by_first
            .iter()
            .map(|&s| {
                let mut c = sv_cols[s].clone();
                c.sort_unstable();
                c
            })
            .collect();
        for s in sv_of.iter_mut() {
            *s = renumber[*s];
        }
        let ns = sv_cols.len();
        let weight: Vec<usize> = sv_cols.iter().map(Vec::len).collect();
        let mut adj_ptr = vec![0usize];
        let mut adj = Vec::new();
        let mut mark = vec![usize::MAX; ns];
        for (s, c) in sv_cols.iter().enumerate() {
            let j = c[0];
            mark[s] = s;
            for &r in &ri[cp[j]..cp[j + 1]] {
                let t = sv_of[r];
                if mark[t] != s {
                    mark[t] = s;
                    adj.push(t);
                }
            }
            adj_ptr.push(adj.len());
        }
        SupervariableGraph {
            cols: sv_cols,
            adj_ptr,
            adj,
            weight,
        }
    }
}

struct Dissection<'a> {
    adj_ptr: &'a [usize],
    adj: &'a [usize],
    weight: &'a [usize],
    stamp: Vec<usize>,
    level: Vec<usize>,
    next_stamp: usize,
    order: Vec<usize>,
}

impl Dissection<'_> {
    fn neighbours(&self, s: usize) -> &[usize] {
        &self.adj[self.adj_ptr[s]..self.adj_ptr[s + 1]]
    }

    /// Breadth-first levels of the part stamped `id` reachable from `root`.
    fn levels(&mut self, root: usize, id: usize) -> Vec<Vec<usize>> {
        let visit = id + 1;
        let mut levels = vec![vec![root]];
        self.stamp[root] = visit;
        loop {
            let mut next = Vec::new();
            for &s in levels.last().expect("non-empty") {
                for k in self.adj_ptr[s]..self.adj_ptr[s + 1] {
                    let t = self.adj[k];
                    if self.stamp[t] == id {
                        self.stamp[t] = visit;
                        next.push(t);
                    }
                }
            }
            if next.is_empty() {
                break;
            }
            levels.push(next);
        }
        // Restore the part's stamp.
        for l in &levels {
            for &s in l {
                self.stamp[s] = id;
            }
        }
        levels
    }

    fn dissect(&mut self, nodes: Vec<usize>) {
        let total: usize = nodes.iter().map(|&s| self.weight[s]).sum();
        if total <= ND_LEAF || nodes.len() < 3 {
            let mut nodes = nodes;
            nodes.sort_unstable();
            self.order.extend(nodes);
            return;
        }
        self.next_stamp += 2;
        let id = self.next_stamp;
        for &s in &nodes {
            self.stamp[s] = id;
        }
        // Pseudo-peripheral root: restart from the last node of the deepest level while the
        // depth grows (at most a few sweeps).
        let mut root = nodes[0];
        let mut levels = self.levels(root, id);
        for _ in 0..4 {
            let cand = *levels
                .last()
                .expect("non-empty")
                .iter()
                .min()
                .expect("non-empty");
            let l2 = self.levels(cand, id);
            if l2.len() <= levels.len() {
                break;
            }
            root = cand;
            levels = l2;
        }
        let _ = root;
        let reached: usize = levels.iter().map(Vec::len).sum();
        if reached < nodes.len() {
            // Disconnected: the component reached, then the rest.
            let visit = id + 1;
            for l in &levels {
                for &s in l {
                    self.stamp[s] = visit;
                }
            }
            let (comp, rest): (Vec<usize>, Vec<usize>) =
                nodes.iter().partition(|&&s| self.stamp[s] == visit);
            self.dissect(comp);
            self.dissect(rest);
            return;
        }
        if levels.len() < 3 {
            self.order.extend(nodes);
            return;
        }
        // Lightest balanced level.
        let w: Vec<usize> = levels
            .iter()
            .map(|l| l.iter().map(|&s| self.weight[s]).sum())
            .collect();
        let mut before = 0usize;
        let mut best: Option<(usize, usize)> = None;
        for (k, &wk) in w.iter().enumerate() {
            let after = total - before - wk;
            if k > 0
                && k + 1 < levels.len()
                && 4 * before >= total
                && 4 * after >= total
                && best.is_none_or(|(_, bw)| wk < bw)
            {
                best = Some((k, wk));
            }
            before += wk;
        }
        let k = match best {
            Some((k, _)) => k,
            // No balanced level: the middle one by weight.
            None => {
                let mut acc = 0;
                let mut k = 1;
                for (i, &wi) in w.iter().enumerate() {
                    acc += wi;
                    if 2 * acc >= total {
                        k = i.clamp(1, levels.len() - 2);
                        break;
                    }
                }
                k
            }
        };
        // Second candidate: a window of consecutive numbers as wide as the longest edge of the
        // part in its numbering (the DOF numbering of a grid of particles makes it a straight
        // band); no edge jumps over it.
        let mut sorted = nodes.clone();
        sorted.sort_unstable();
        for (p, &s) in sorted.iter().enumerate() {
            self.level[s] = p;
        }
        let mut span = 0usize;
        for &s in &sorted {
            for &t in self.neighbours(s) {
                if self.stamp[t] == id {
                    span = span.max(self.level[t].abs_diff(self.level[s]));
                }
            }
        }
        let window = if span > 0 && span + 2 <= sorted.len() {
            // Start c: the parts before and after the window (c..c+span) most balanced.
            let mut prefix = vec![0usize; sorted.len() + 1];
            for (p, &s) in sorted.iter().enumerate() {
                prefix[p + 1] = prefix[p] + self.weight[s];
            }
            (1..sorted.len() - span)
                .map(|c| {
                    let (wa, wb) = (prefix[c], total - prefix[c + span]);
                    (wa.abs_diff(wb), c, prefix[c + span] - prefix[c])
                })
                .min()
                .filter(|&(_, c, _)| {
                    4 * prefix[c] >= total && 4 * (total - prefix[c + span]) >= total
                })
        } else {
            None
        };
        let (mut a, b, cand): (Vec<usize>, Vec<usize>, Vec<usize>) = match window {
            Some((_, c, ww)) if ww < w[k] => {
                for (p, &s) in sorted.iter().enumerate() {
                    self.level[s] = if p < c {
                        0
                    } else if p < c + span {
                        1
                    } else {
                        2
                    };
                }
                (
                    sorted[..c].to_vec(),
                    sorted[c + span..].to_vec(),
                    sorted[c..c + span].to_vec(),
                )
            }
            _ => {
                for (i, l) in levels.iter().enumerate() {
                    for &s in l {
                        self.level[s] = match i.cmp(&k) {
                            std::cmp::Ordering::Less => 0,
                            std::cmp::Ordering::Equal => 1,
                            std::cmp::Ordering::Greater => 2,
                        };
                    }
                }
                (
                    levels[..k].concat(),
                    levels[k + 1..].concat(),
                    levels[k].clone(),
                )
            }
        };
        // Separator nodes without a neighbour on the far side join the near side.
        let mut sep = Vec::new();
        for &s in &cand {
            if self
                .neighbours(s)
                .iter()
                .any(|&t| self.stamp[t] == id && self.level[t] == 2)
            {
                sep.push(s);
            } else {
                a.push(s);
            }
        }
        self.dissect(a);
        self.dissect(b);
        self.order.extend(sep);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `nx × nx` particles with 3 DOFs, each cell coupling the particles within one spacing,
    /// with diagonally dominant unsymmetric values.
    fn grid(nx: usize) -> (SparsityPattern, Vec<f64>) {
        let p = SparsityPattern::particle_grid(nx, 3, 1).unwrap();
        let values = p.values_from(|i, j| {
            if i == j {
                40.0
            } else {
                -1.0 / (1.0 + (i.abs_diff(j) % 5) as f64) + 0.1 * ((i + 3 * j) % 7) as f64
            }
        });
        (p, values)
    }

    #[test]
    fn the_tree_solve_equals_the_supernode_by_supernode_solve() {
        let (p, values) = grid(24);
        let n = p.n_dofs();
        for ordering in [FillOrdering::NestedDissection, FillOrdering::Amd] {
            let tree = SupernodalSymbolic::new(&p, ordering).unwrap();
            // Both orderings give a postorder, so the tree solve (with parallel subtrees:
            // the root's subtree holds all entries, far above the task threshold) is taken.
            assert!(tree.first.is_some(), "{ordering:?}");
            assert!(tree.subtree_entries.iter().any(|&e| e >= PAR_SOLVE_ENTRIES));
            let mut numeric = SupernodalNumeric::default();
            tree.factorize(&values, &mut numeric);
            let k = 2;
            let b: Vec<f64> = (0..n * k).map(|i| ((i * 37) % 101) as f64 - 50.0).collect();
            let mut x_tree = b.clone();
            tree.solve(
                &numeric,
                MatMut::from_column_major_slice_mut(&mut x_tree, n, k),
            );
            let mut seq = SupernodalSymbolic::new(&p, ordering).unwrap();
            seq.first = None;
            let mut x_seq = b.clone();
            seq.solve(
                &numeric,
                MatMut::from_column_major_slice_mut(&mut x_seq, n, k),
            );
            // The same operations but for the order in which the updates of a supernode's
            // rows are summed: round-off (diagonally dominant, cond ≈ 1e1: 1e-13 with margin).
            let scale = x_seq.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            let diff = x_tree
                .iter()
                .zip(&x_seq)
                .fold(0.0f64, |a, (u, v)| a.max((u - v).abs()));
            assert!(diff <= 1e-13 * scale, "{ordering:?}: {diff:e} of {scale:e}");
            // And it solves the system: A x = b to round-off.
            let mut ax = vec![0.0; n];
            let (cp, ri) = (p.col_ptr(), p.row_idx());
            for j in 0..n {
                for q in cp[j]..cp[j + 1] {
                    ax[ri[q]] += values[q] * x_tree[j];
                }
            }
            let res = ax
                .iter()
                .zip(&b[..n])
                .fold(0.0f64, |a, (u, v)| a.max((u - v).abs()));
            assert!(res <= 1e-12 * 50.0, "{ordering:?}: residual {res:e}");
        }
    }

    #[test]
    fn multipliers_follow_the_dofs_they_couple() {
        // A grid with three constraint rows appended (multipliers 432, 433, 434), each coupling
        // a few DOFs spread over the grid; ordered by both methods, every multiplier comes
        // after each DOF it couples in the supernodes' final order.
        let (p, _) = grid(12);
        let nq = p.n_dofs();
        let mut cells: Vec<Vec<usize>> =
            (0..p.n_cells()).map(|c| p.cell_dofs(c).to_vec()).collect();
        let rows = [vec![0, 40, 200], vec![5, 6, 7, 431], vec![300, 17]];
        for (c, r) in rows.iter().enumerate() {
            let mut cell = vec![nq + c];
            cell.extend(r);
            cells.push(cell);
        }
        let bordered = SparsityPattern::from_cells(nq + rows.len(), &cells)
            .unwrap()
            .with_multipliers_from(nq);
        for ordering in [FillOrdering::NestedDissection, FillOrdering::Amd] {
            let sym = SupernodalSymbolic::new(&bordered, ordering).unwrap();
            let mut pos = vec![0usize; bordered.n_dofs()];
            for (new, &old) in sym.perm.iter().enumerate() {
                pos[old] = new;
            }
            for (c, r) in rows.iter().enumerate() {
                for &d in r {
                    assert!(pos[nq + c] > pos[d], "{ordering:?}: row {c}, DOF {d}");
                }
            }
        }
    }

    #[test]
    fn postorder_ranges_are_found_or_refused() {
        // 0, 1 → 2; 3 → 4; 2, 4 → 5 (a postorder): subtrees [0, 2], [3, 4], [0, 5].
        let children_ptr = [0, 0, 0, 2, 2, 3, 5];
        let children = [0, 1, 3, 2, 4];
        assert_eq!(
            postorder_ranges(&children_ptr, &children, &[5], 6),
            Some(vec![0, 1, 0, 3, 3, 0])
        );
        // Two roots tiling the supernodes: 0 → 1, 2 alone.
        assert_eq!(
            postorder_ranges(&[0, 0, 1, 1], &[0], &[1, 2], 3),
            Some(vec![0, 0, 2])
        );
        // 0 → 2 and 1 a root: the subtree of 2 is {0, 2}, not consecutive.
        assert_eq!(postorder_ranges(&[0, 0, 0, 1], &[0], &[1, 2], 3), None);
        // Children 0 and 2 of 3 with 1 → 2: subtree of 2 is {1, 2}, of 3 is {0, 1, 2, 3} in
        // order 0, then [1, 2]: a postorder.
        assert_eq!(
            postorder_ranges(&[0, 0, 0, 1, 3], &[1, 0, 2], &[3], 4),
            Some(vec![0, 1, 1, 0])
        );
        // Children of 3 out of order: [2] listed before its sibling 0 is not adjacent.
        assert_eq!(
            postorder_ranges(&[0, 0, 0, 1, 3], &[1, 2, 0], &[3], 4),
            None
        );
    }
}
