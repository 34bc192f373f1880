//! Deterministic (serial = parallel, bit for bit) assembly of cell contributions.
//!
//! Cell contributions are computed in parallel with rayon, in batches of consecutive cells. The
//! matrix path then scatters a batch in parallel over disjoint column ranges of the CSC values
//! (balanced by stored entries): each range's owner adds the batch's contributions strictly in
//! cell order through the slot maps of [`SparsityPattern`], so every stored entry receives its
//! additions in the same order as in the serial loop and the result is bit-identical whatever
//! the number of threads. The vector-only path scatters each batch serially, overlapped with the
//! computation of the next batch. Memory stays bounded by the batch size.
//!
//! Parallel evaluation pays off when computing a cell costs more than scattering it (quadrature
//! with shape functions and return maps); for a trivially cheap cell function the scatter is
//! memory-bound and [`Execution::Serial`] can be as fast (see `benches/solver.rs`).

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
    (32 * rayon::current_num_threads()).max(64)
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
    let n_cells = pattern.n_cells();
    let check = |c: usize, res: Result<(DMatrix<f64>, DVector<f64>), E>| {
        let (k, f) = res.map_err(|source| AssemblyError::Cell { cell: c, source })?;
        let m = pattern.cell_dofs(c).len();
        if k.nrows() != m || k.ncols() != m || f.len() != m {
            return Err(AssemblyError::Shape {
                cell: c,
                m,
                rows: k.nrows(),
                cols: k.ncols(),
                len: f.len(),
            });
        }
        Ok((k, f))
    };
    match exec {
        Execution::Serial => {
            for c in 0..n_cells {
                let (k, f) = check(c, local(c))?;
                let (k, f) = (k.as_slice(), f.as_slice());
                scatter(pattern, c, k, f, values, rhs, 0, 0..pattern.n_dofs());
            }
        }
        Execution::Parallel => {
            let parts = partitions(pattern, rayon::current_num_threads());
            let b = batch_len();
            let mut start = 0;
            while start < n_cells {
                let end = (start + b).min(n_cells);
                let batch = (start..end)
                    .into_par_iter()
                    .map(&local)
                    .collect::<Vec<_>>()
                    .into_iter()
                    .enumerate()
                    .map(|(i, res)| check(start + i, res))
                    .collect::<Result<Vec<_>, _>>()?;
                // Every partition owns a contiguous column range (its slice of `values`, and the
                // same range of `rhs`) and adds the batch's contributions in cell order.
                split_by_columns(pattern, &parts, values, rhs)
                    .into_par_iter()
                    .for_each(|(cols, base, vals, r)| {
                        for (i, (k, f)) in batch.iter().enumerate() {
                            let (k, f) = (k.as_slice(), f.as_slice());
                            scatter(pattern, start + i, k, f, vals, r, base, cols.clone());
                        }
                    });
                start = end;
            }
        }
    }
    Ok(())
}

/// Reusable cell buffers of [`assemble_with`]: one matrix and one vector per cell of a batch,
/// kept between assemblies so that repeated assemblies (Newton iterations) allocate nothing
/// and touch no fresh pages.
#[derive(Debug, Default, Clone)]
pub struct AssemblyBuffers {
    cells: Vec<(Vec<f64>, Vec<f64>)>,
}

impl AssemblyBuffers {
    /// Empty buffers (they grow on first use).
    pub fn new() -> Self {
        Self::default()
    }

    /// Buffers for `n` cells (their contents are set by [`zeroed`] when a cell is evaluated, on
    /// the thread that evaluates it).
    fn take(&mut self, n: usize) -> &mut [(Vec<f64>, Vec<f64>)] {
        if self.cells.len() < n {
            self.cells.resize_with(n, Default::default);
        }
        &mut self.cells[..n]
    }
}

/// Size the buffer of cell `c` and zero it.
fn zeroed<'b>(
    pattern: &SparsityPattern,
    c: usize,
    (k, f): &'b mut (Vec<f64>, Vec<f64>),
) -> (&'b mut [f64], &'b mut [f64]) {
    let m = pattern.cell_dofs(c).len();
    k.clear();
    k.resize(m * m, 0.0);
    f.clear();
    f.resize(m, 0.0);
    (k, f)
}

/// [`assemble`] with the cell contributions written into reused buffers:
/// `local(c, k, f)` receives the zeroed column-major `m × m` matrix `k` and vector `f` of cell
/// `c` (`m = pattern.cell_dofs(c).len()`) and adds the cell's contribution to them. The
/// buffers live in `buffers` between calls. Same order of additions, hence the same
/// bit-identical results for any number of threads, as [`assemble`].
pub fn assemble_with<F, E>(
    pattern: &SparsityPattern,
    values: &mut [f64],
    rhs: &mut [f64],
    exec: Execution,
    buffers: &mut AssemblyBuffers,
    local: F,
) -> Result<(), AssemblyError<E>>
where
    F: Fn(usize, &mut [f64], &mut [f64]) -> Result<(), E> + Sync,
    E: Send,
{
    check_len("assemble: values", values.len(), pattern.nnz())?;
    check_len("assemble: rhs", rhs.len(), pattern.n_dofs())?;
    values.fill(0.0);
    rhs.fill(0.0);
    let n_cells = pattern.n_cells();
    match exec {
        Execution::Serial => {
            for c in 0..n_cells {
                let (k, f) = zeroed(pattern, c, &mut buffers.take(1)[0]);
                local(c, k, f).map_err(|source| AssemblyError::Cell { cell: c, source })?;
                scatter(pattern, c, k, f, values, rhs, 0, 0..pattern.n_dofs());
            }
        }
        Execution::Parallel => {
            let parts = partitions(pattern, rayon::current_num_threads());
            let b = batch_len();
            let mut start = 0;
            while start < n_cells {
                let end = (start + b).min(n_cells);
                let bufs = buffers.take(end - start);
                let results: Vec<Result<(), E>> = bufs
                    .par_iter_mut()
                    .enumerate()
                    .map(|(i, buf)| {
                        let (k, f) = zeroed(pattern, start + i, buf);
                        local(start + i, k, f)
                    })
                    .collect();
                // The lowest failing cell is reported, as in the serial loop.
                for (i, res) in results.into_iter().enumerate() {
                    res.map_err(|source| AssemblyError::Cell {
                        cell: start + i,
                        source,
                    })?;
                }
                let bufs = &*bufs;
                split_by_columns(pattern, &parts, values, rhs)
                    .into_par_iter()
                    .for_each(|(cols, base, vals, r)| {
                        for (i, (k, f)) in bufs.iter().enumerate() {
                            scatter(pattern, start + i, k, f, vals, r, base, cols.clone());
                        }
                    });
                start = end;
            }
        }
    }
    Ok(())
}

/// Add cell `c`'s contribution to the columns `cols` held in `vals` (slots offset by `base`)
/// and to the matching part of the vector held in `r` (offset by `cols.start`).
#[allow(clippy::too_many_arguments)]
#[inline]
fn scatter(
    pattern: &SparsityPattern,
    c: usize,
    kk: &[f64],
    f: &[f64],
    vals: &mut [f64],
    r: &mut [f64],
    base: usize,
    cols: std::ops::Range<usize>,
) {
    let dofs = pattern.cell_dofs(c);
    let m = dofs.len();
    for (jj, &col) in dofs.iter().enumerate() {
        if cols.contains(&col) {
            let kcol = &kk[jj * m..(jj + 1) * m];
            // Runs of consecutive rows and slots: slice additions the compiler vectorises.
            for run in pattern.cell_column_runs(c, jj) {
                let (a, s, len) = (run.row as usize, run.slot as usize - base, run.len as usize);
                for (v, x) in vals[s..s + len].iter_mut().zip(&kcol[a..a + len]) {
                    *v += x;
                }
            }
            r[col - cols.start] += f[jj];
        }
    }
}

/// Column boundaries splitting the stored entries into about `n` equal parts.
fn partitions(pattern: &SparsityPattern, n: usize) -> Vec<usize> {
    let cp = pattern.col_ptr();
    let nnz = pattern.nnz();
    let n = n.max(1);
    let mut bounds = vec![0];
    for t in 1..n {
        let target = nnz * t / n;
        let j = cp.partition_point(|&p| p < target).min(pattern.n_dofs());
        if j > *bounds.last().expect("non-empty") {
            bounds.push(j);
        }
    }
    if *bounds.last().expect("non-empty") < pattern.n_dofs() || bounds.len() == 1 {
        bounds.push(pattern.n_dofs());
    }
    bounds
}

type Part<'a> = (std::ops::Range<usize>, usize, &'a mut [f64], &'a mut [f64]);

/// Disjoint mutable pieces of `values` and `rhs` for the column ranges given by `bounds`.
fn split_by_columns<'a>(
    pattern: &SparsityPattern,
    bounds: &[usize],
    mut values: &'a mut [f64],
    mut rhs: &'a mut [f64],
) -> Vec<Part<'a>> {
    let cp = pattern.col_ptr();
    let mut out = Vec::with_capacity(bounds.len());
    for w in bounds.windows(2) {
        let (c0, c1) = (w[0], w[1]);
        let (v, vrest) = std::mem::take(&mut values).split_at_mut(cp[c1] - cp[c0]);
        let (r, rrest) = std::mem::take(&mut rhs).split_at_mut(c1 - c0);
        values = vrest;
        rhs = rrest;
        out.push((c0..c1, cp[c0], v, r));
    }
    out
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
