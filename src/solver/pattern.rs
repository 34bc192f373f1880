//! Sparsity pattern of the global matrix, built once from cell DOF lists.

use super::{check_len, SolverError};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMat, SymbolicSparseColMatRef};

/// Compressed-column (CSC) pattern with sorted row indices, the full diagonal, and for every cell
/// a precomputed map from local `(i, j)` to the slot in the values array.
///
/// A cell is the set of DOFs coupled by one integration cell or one particle support: every pair
/// of its DOFs is a structural nonzero. The diagonal is always stored (even for a DOF no cell
/// touches) so that essential conditions can put a unit diagonal without changing the pattern.
#[derive(Debug, Clone)]
pub struct SparsityPattern {
    n: usize,
    symbolic: SymbolicSparseColMat<usize>,
    cell_ptr: Vec<usize>,
    cell_dofs: Vec<usize>,
    /// The cell slots (the slot of each local `(i, j)`) as runs: per cell column (`run_ptr` over
    /// all cells' columns in order), maximal runs of consecutive local rows whose slots are
    /// consecutive too. Slots are `u32`; patterns with more than `u32::MAX` stored entries are
    /// rejected.
    run_ptr: Vec<usize>,
    runs: Vec<SlotRun>,
    /// Every column's rows as runs of consecutive rows (`column_run_ptr` over the columns): the
    /// products with the matrix read its values slice by slice, without a row index per entry.
    column_run_ptr: Vec<usize>,
    column_runs: Vec<RowRun>,
    diag: Vec<usize>,
    /// First DOF of the multipliers of a bordered (saddle-point) system, `n` when none: the
    /// DOFs from here on have a zero diagonal block ([`Self::with_multipliers_from`]).
    multipliers_from: usize,
}

/// A run of a cell column's slots ([`SparsityPattern::cell_column_runs`]): local rows
/// `row..row + len` go to the slots `slot..slot + len`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SlotRun {
    /// First local row.
    pub row: u32,
    /// Its slot.
    pub slot: u32,
    /// Number of rows.
    pub len: u32,
}

/// A run of a column's stored rows ([`SparsityPattern::column_runs`]): rows `row..row + len`,
/// stored in consecutive slots.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RowRun {
    /// First row.
    pub row: u32,
    /// Number of rows.
    pub len: u32,
}

/// What both constructors derive from a CSC structure with sorted rows and the full diagonal:
/// the diagonal's slots, and the maximal runs of consecutive rows of every column (pointers per
/// column, runs). Structures with more than `u32::MAX` entries are rejected (slots and rows are
/// kept as `u32`).
#[allow(clippy::type_complexity)]
fn column_structure(
    col_ptr: &[usize],
    row_idx: &[usize],
) -> Result<(Vec<usize>, Vec<usize>, Vec<RowRun>), SolverError> {
    if row_idx.len() > u32::MAX as usize {
        return Err(SolverError::TooManyEntries { nnz: row_idx.len() });
    }
    let diag = col_ptr
        .windows(2)
        .enumerate()
        .map(|(j, w)| {
            w[0] + row_idx[w[0]..w[1]]
                .binary_search(&j)
                .expect("diagonal inserted")
        })
        .collect();
    let mut ptr = Vec::with_capacity(col_ptr.len());
    ptr.push(0);
    let mut runs = Vec::new();
    for w in col_ptr.windows(2) {
        let rows = &row_idx[w[0]..w[1]];
        let mut a = 0;
        while a < rows.len() {
            let mut len = 1;
            while a + len < rows.len() && rows[a + len] == rows[a] + len {
                len += 1;
            }
            runs.push(RowRun {
                row: rows[a] as u32,
                len: len as u32,
            });
            a += len;
        }
        ptr.push(runs.len());
    }
    Ok((diag, ptr, runs))
}

impl SparsityPattern {
    /// Pattern of `n_dofs` unknowns coupled by `cells` (each a list of global DOF indices; a DOF
    /// may repeat within a cell, its contributions are then summed).
    pub fn from_cells(n_dofs: usize, cells: &[Vec<usize>]) -> Result<Self, SolverError> {
        for (cell, dofs) in cells.iter().enumerate() {
            if let Some((local, &dof)) = dofs.iter().enumerate().find(|(_, &d)| d >= n_dofs) {
                return Err(SolverError::DofOutOfRange {
                    cell,
                    local,
                    dof,
                    n_dofs,
                });
            }
        }
        // DOF -> cells containing it (CSR-like).
        let mut count = vec![0usize; n_dofs + 1];
        for dofs in cells {
            for &d in dofs {
                count[d + 1] += 1;
            }
        }
        for i in 0..n_dofs {
            count[i + 1] += count[i];
        }
        let mut fill = count.clone();
        let mut dof_cells = vec![0usize; count[n_dofs]];
        for (c, dofs) in cells.iter().enumerate() {
            for &d in dofs {
                dof_cells[fill[d]] = c;
                fill[d] += 1;
            }
        }
        // Column j: union of the DOFs of every cell containing j, plus j itself.
        let mut col_ptr = Vec::with_capacity(n_dofs + 1);
        col_ptr.push(0usize);
        let mut row_idx = Vec::new();
        let mut mark = vec![usize::MAX; n_dofs];
        let mut col = Vec::new();
        for j in 0..n_dofs {
            col.clear();
            mark[j] = j;
            col.push(j);
            for &c in &dof_cells[count[j]..count[j + 1]] {
                for &i in &cells[c] {
                    if mark[i] != j {
                        mark[i] = j;
                        col.push(i);
                    }
                }
            }
            col.sort_unstable();
            row_idx.extend_from_slice(&col);
            col_ptr.push(row_idx.len());
        }
        let (diag, column_run_ptr, column_runs) = column_structure(&col_ptr, &row_idx)?;
        let mut cell_ptr = Vec::with_capacity(cells.len() + 1);
        cell_ptr.push(0);
        let mut cell_dofs = Vec::new();
        // A cell's DOFs list the particles' DOFs in order, so its columns' slots come in long
        // runs (a row of neighbouring particles): only the runs are kept (a few per column
        // against one `u32` per entry), and the scatter adds them slice by slice.
        let mut run_ptr = vec![0usize];
        let mut runs = Vec::new();
        let mut order: Vec<usize> = Vec::new();
        let mut column: Vec<u32> = Vec::new();
        for dofs in cells {
            // Column-major local order (slot of local (i, j) at j * m + i), matching nalgebra.
            // The cell's rows in ascending order are found in each (sorted) column by one merge
            // walk instead of a binary search per entry.
            let m = dofs.len();
            order.clear();
            order.extend(0..m);
            order.sort_unstable_by_key(|&a| dofs[a]);
            column.resize(m, 0);
            for &cj in dofs {
                let rows = &row_idx[col_ptr[cj]..col_ptr[cj + 1]];
                let mut k = 0;
                for &a in &order {
                    let ri = dofs[a];
                    while rows[k] < ri {
                        k += 1;
                    }
                    debug_assert_eq!(rows[k], ri, "cell pair in pattern");
                    column[a] = (col_ptr[cj] + k) as u32;
                }
                let mut a = 0;
                while a < m {
                    let mut len = 1;
                    while a + len < m && column[a + len] == column[a] + len as u32 {
                        len += 1;
                    }
                    runs.push(SlotRun {
                        row: a as u32,
                        slot: column[a],
                        len: len as u32,
                    });
                    a += len;
                }
                run_ptr.push(runs.len());
            }
            cell_dofs.extend_from_slice(dofs);
            cell_ptr.push(cell_dofs.len());
        }
        let symbolic = SymbolicSparseColMat::new_checked(n_dofs, n_dofs, col_ptr, None, row_idx);
        Ok(Self {
            n: n_dofs,
            symbolic,
            cell_ptr,
            cell_dofs,
            run_ptr,
            runs,
            column_run_ptr,
            column_runs,
            diag,
            multipliers_from: n_dofs,
        })
    }

    /// A model pattern of meshfree-shell-like structure: `nx × nx` particles on a grid, numbered
    /// row by row with `dofs` consecutive DOFs each, every particle's cell coupling the
    /// particles within `reach` spacings in both directions (a square support). For benchmarks
    /// and tests of the solvers on patterns of the tangent's kind without building a model.
    pub fn particle_grid(nx: usize, dofs: usize, reach: usize) -> Result<Self, SolverError> {
        let mut cells = Vec::with_capacity(nx * nx);
        for i in 0..nx {
            for j in 0..nx {
                let mut cell = Vec::new();
                for a in i.saturating_sub(reach)..(i + reach + 1).min(nx) {
                    for b in j.saturating_sub(reach)..(j + reach + 1).min(nx) {
                        cell.extend((0..dofs).map(|d| (a * nx + b) * dofs + d));
                    }
                }
                cells.push(cell);
            }
        }
        Self::from_cells(nx * nx * dofs, &cells)
    }

    /// The values array with the stored entry `(i, j)` set to `f(i, j)`.
    pub fn values_from(&self, f: impl Fn(usize, usize) -> f64) -> Vec<f64> {
        let (cp, ri) = (self.col_ptr(), self.row_idx());
        let mut values = vec![0.0; self.nnz()];
        for j in 0..self.n {
            for q in cp[j]..cp[j + 1] {
                values[q] = f(ri[q], j);
            }
        }
        values
    }

    /// Pattern of the given structural nonzeros `(row, col)` (duplicates allowed) plus the full
    /// diagonal, with no cells: for matrices formed by products rather than cell assembly (the
    /// transformed tangent `Λ⁻ᵀ K Λ⁻¹` of the meshfree transformation method). Fill values
    /// through [`Self::slot`].
    pub fn from_entries(n_dofs: usize, entries: &[(usize, usize)]) -> Result<Self, SolverError> {
        if let Some((local, &(r, c))) = entries
            .iter()
            .enumerate()
            .find(|(_, &(r, c))| r >= n_dofs || c >= n_dofs)
        {
            return Err(SolverError::DofOutOfRange {
                cell: 0,
                local,
                dof: r.max(c),
                n_dofs,
            });
        }
        let mut cols: Vec<Vec<usize>> = (0..n_dofs).map(|j| vec![j]).collect();
        for &(r, c) in entries {
            cols[c].push(r);
        }
        let mut col_ptr = Vec::with_capacity(n_dofs + 1);
        col_ptr.push(0usize);
        let mut row_idx = Vec::new();
        for col in &mut cols {
            col.sort_unstable();
            col.dedup();
            row_idx.extend_from_slice(col);
            col_ptr.push(row_idx.len());
        }
        let (diag, column_run_ptr, column_runs) = column_structure(&col_ptr, &row_idx)?;
        let symbolic = SymbolicSparseColMat::new_checked(n_dofs, n_dofs, col_ptr, None, row_idx);
        Ok(Self {
            n: n_dofs,
            symbolic,
            cell_ptr: vec![0],
            cell_dofs: Vec::new(),
            run_ptr: vec![0],
            runs: Vec::new(),
            column_run_ptr,
            column_runs,
            diag,
            multipliers_from: n_dofs,
        })
    }

    /// Number of DOFs (rows = columns).
    pub fn n_dofs(&self) -> usize {
        self.n
    }

    /// Mark the DOFs from `first` on as the multipliers of constraint rows: the matrix is
    /// bordered, `[K Cᵀ; C 0]`, with a zero block on their diagonal. A factorisation that
    /// pivots only within blocks fixed by the pattern ([`super::Method::SupernodalLu`]) then
    /// orders every multiplier after the DOFs it couples, where its pivot is the Schur
    /// complement `−C K⁻¹ Cᵀ` rather than a structural zero. `first` is clamped to the DOF
    /// count (no multipliers).
    pub fn with_multipliers_from(mut self, first: usize) -> Self {
        self.multipliers_from = first.min(self.n);
        self
    }

    /// First multiplier DOF ([`Self::with_multipliers_from`]; the DOF count when none).
    pub fn multipliers_from(&self) -> usize {
        self.multipliers_from
    }

    /// Number of cells.
    pub fn n_cells(&self) -> usize {
        self.cell_ptr.len() - 1
    }

    /// Number of stored entries (length of the values array).
    pub fn nnz(&self) -> usize {
        self.symbolic.row_idx().len()
    }

    /// Column pointers (length `n_dofs + 1`).
    pub fn col_ptr(&self) -> &[usize] {
        self.symbolic.col_ptr()
    }

    /// Row indices, sorted within each column.
    pub fn row_idx(&self) -> &[usize] {
        self.symbolic.row_idx()
    }

    /// The rows of column `j` as runs of consecutive rows, in order: the `k`-th stored entry of
    /// the column is in the run holding the `k`-th row, so the runs' lengths add up to the
    /// column's entries, from slot `col_ptr()[j]` on.
    pub fn column_runs(&self, j: usize) -> &[RowRun] {
        &self.column_runs[self.column_run_ptr[j]..self.column_run_ptr[j + 1]]
    }

    /// Global DOFs of cell `c`.
    pub fn cell_dofs(&self, c: usize) -> &[usize] {
        &self.cell_dofs[self.cell_ptr[c]..self.cell_ptr[c + 1]]
    }

    /// Slots of cell `c`, expanded from its runs: local `(i, j)` of an `m × m` cell matrix is
    /// stored at `slots[j * m + i]`.
    pub fn cell_slots(&self, c: usize) -> Vec<u32> {
        let m = self.cell_dofs(c).len();
        let mut slots = Vec::with_capacity(m * m);
        for jj in 0..m {
            for run in self.cell_column_runs(c, jj) {
                slots.extend((0..run.len).map(|t| run.slot + t));
            }
        }
        slots
    }

    /// The slots of column `jj` of cell `c` as runs ([`SlotRun`]): local rows
    /// `row..row + len` of that column are stored at `slot..slot + len`.
    pub fn cell_column_runs(&self, c: usize, jj: usize) -> &[SlotRun] {
        let k = self.cell_ptr[c] + jj;
        &self.runs[self.run_ptr[k]..self.run_ptr[k + 1]]
    }

    /// Slot of the diagonal entry of DOF `i`.
    pub fn diag_slot(&self, i: usize) -> usize {
        self.diag[i]
    }

    /// Slot of entry `(row, col)`, if it is in the pattern.
    pub fn slot(&self, row: usize, col: usize) -> Option<usize> {
        if row >= self.n || col >= self.n {
            return None;
        }
        let (p0, p1) = (self.col_ptr()[col], self.col_ptr()[col + 1]);
        self.row_idx()[p0..p1]
            .binary_search(&row)
            .ok()
            .map(|k| p0 + k)
    }

    /// The faer symbolic structure.
    pub fn symbolic(&self) -> SymbolicSparseColMatRef<'_, usize> {
        self.symbolic.as_ref()
    }

    /// A faer matrix view of `values` over this pattern.
    ///
    /// # Panics
    /// If `values.len() != self.nnz()`.
    pub fn matrix<'a>(&'a self, values: &'a [f64]) -> SparseColMatRef<'a, usize, f64> {
        SparseColMatRef::new(self.symbolic(), values)
    }

    /// `y = A x` for the matrix with `values` over this pattern.
    pub fn mat_vec(&self, values: &[f64], x: &[f64], y: &mut [f64]) -> Result<(), SolverError> {
        check_len("values", values.len(), self.nnz())?;
        check_len("x", x.len(), self.n)?;
        check_len("y", y.len(), self.n)?;
        y.fill(0.0);
        let (cp, ri) = (self.col_ptr(), self.row_idx());
        for j in 0..self.n {
            let xj = x[j];
            for p in cp[j]..cp[j + 1] {
                y[ri[p]] += values[p] * xj;
            }
        }
        Ok(())
    }

    /// Dense copy (for tests and small diagnostics).
    pub fn to_dense(&self, values: &[f64]) -> nalgebra::DMatrix<f64> {
        let mut a = nalgebra::DMatrix::zeros(self.n, self.n);
        let (cp, ri) = (self.col_ptr(), self.row_idx());
        for j in 0..self.n {
            for p in cp[j]..cp[j + 1] {
                a[(ri[p], j)] = values[p];
            }
        }
        a
    }
}
