//! Deterministic (serial = parallel, bit for bit) assembly of cell contributions.
//!
//! Cell contributions are computed in parallel with rayon, in batches of consecutive cells, and
//! scatter-added into the global arrays strictly in cell order through the slot maps of
//! [`SparsityPattern`]. The scatter of one batch overlaps the computation of the next. Floating
//! point addition is performed in exactly the same order as in the serial loop, so the result is
//! bit-identical whatever the number of threads. Memory stays bounded by the batch size.

use super::{check_len, SolverError, SparsityPattern};
use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

/// Serial or rayon-parallel evaluation of cell contributions (the scatter is always in cell order).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Execution {
    /// One cell after the other on the calling thread.
    Serial,
    /// Cells of a batch computed on rayon's global pool.
    #[default]
    Parallel,
}

/// An assembly failure, reported for the lowest-numbered failing cell.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum AssemblyError<E> {
    /// The cell function returned an error.
    #[error("cell {cell}: {source}")]
    Cell {
        /// Cell index.
        cell: usize,
        /// The cell function's error.
        source: E,
    },
    /// The cell function returned a matrix or vector of the wrong size.
    #[error("cell {cell}: local contribution is {rows}×{cols} / {len}, expected {m}×{m} / {m}")]
    Shape {
        /// Cell index.
        cell: usize,
        /// Number of the cell's DOFs.
        m: usize,
        /// Rows of the returned matrix.
        rows: usize,
        /// Columns of the returned matrix.
        cols: usize,
        /// Length of the returned vector.
        len: usize,
    },
    /// A global array has the wrong length.
    #[error(transparent)]
    Global(#[from] SolverError),
}

/// Cells per batch in the parallel path: enough work per thread, bounded memory.
fn batch_len() -> usize {
    (16 * rayon::current_num_threads()).max(64)
}

/// Compute `compute(c)` for every cell and feed the results to `consume` in cell order.
fn run<T, E, F, C>(n: usize, exec: Execution, compute: F, mut consume: C) -> Result<(), E>
where
    T: Send,
    E: Send,
    F: Fn(usize) -> T + Sync,
    C: FnMut(usize, T) -> Result<(), E> + Send,
{
    match exec {
        Execution::Serial => {
            for c in 0..n {
                consume(c, compute(c))?;
            }
            Ok(())
        }
        Execution::Parallel => {
            let b = batch_len();
            let mut pending: Option<(usize, Vec<T>)> = None;
            let mut start = 0;
            loop {
                let end = (start + b).min(n);
                let prev = pending.take();
                let (computed, scattered) = rayon::join(
                    || {
                        (start < end).then(|| {
                            (start..end)
                                .into_par_iter()
                                .map(&compute)
                                .collect::<Vec<T>>()
                        })
                    },
                    || -> Result<(), E> {
                        if let Some((s, items)) = prev {
                            for (k, item) in items.into_iter().enumerate() {
                                consume(s + k, item)?;
                            }
                        }
                        Ok(())
                    },
                );
                scattered?;
                match computed {
                    Some(items) => pending = Some((start, items)),
                    None => return Ok(()),
                }
                start = end;
            }
        }
    }
}

/// Assemble the global matrix `values` (aligned with `pattern`) and vector `rhs` from cell
/// contributions `local(c) = (k_c, f_c)`, where `k_c[(i, j)]` couples the cell's DOFs
/// `pattern.cell_dofs(c)[i]` (row) and `[j]` (column). Both global arrays are overwritten.
pub fn assemble<F, E>(
    pattern: &SparsityPattern,
    values: &mut [f64],
    rhs: &mut [f64],
    exec: Execution,
    local: F,
) -> Result<(), AssemblyError<E>>
where
    F: Fn(usize) -> Result<(DMatrix<f64>, DVector<f64>), E> + Sync,
    E: Send,
{
    check_len("assemble: values", values.len(), pattern.nnz())?;
    check_len("assemble: rhs", rhs.len(), pattern.n_dofs())?;
    values.fill(0.0);
    rhs.fill(0.0);
    run(pattern.n_cells(), exec, local, |c, res| {
        let (k, f) = res.map_err(|source| AssemblyError::Cell { cell: c, source })?;
        let dofs = pattern.cell_dofs(c);
        let m = dofs.len();
        if k.nrows() != m || k.ncols() != m || f.len() != m {
            return Err(AssemblyError::Shape {
                cell: c,
                m,
                rows: k.nrows(),
                cols: k.ncols(),
                len: f.len(),
            });
        }
        for (v, &s) in k.as_slice().iter().zip(pattern.cell_slots(c)) {
            values[s] += v;
        }
        for (v, &d) in f.iter().zip(dofs) {
            rhs[d] += v;
        }
        Ok(())
    })
}

/// Assemble only a global vector (a residual) from cell vectors `local(c)`; `rhs` is overwritten.
pub fn assemble_vector<F, E>(
    pattern: &SparsityPattern,
    rhs: &mut [f64],
    exec: Execution,
    local: F,
) -> Result<(), AssemblyError<E>>
where
    F: Fn(usize) -> Result<DVector<f64>, E> + Sync,
    E: Send,
{
    check_len("assemble_vector: rhs", rhs.len(), pattern.n_dofs())?;
    rhs.fill(0.0);
    run(pattern.n_cells(), exec, local, |c, res| {
        let f = res.map_err(|source| AssemblyError::Cell { cell: c, source })?;
        let dofs = pattern.cell_dofs(c);
        if f.len() != dofs.len() {
            return Err(AssemblyError::Shape {
                cell: c,
                m: dofs.len(),
                rows: 0,
                cols: 0,
                len: f.len(),
            });
        }
        for (v, &d) in f.iter().zip(dofs) {
            rhs[d] += v;
        }
        Ok(())
    })
}
