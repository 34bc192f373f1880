//! The gather map of a model's shape-function particles: the transpose of the model's scatter
//! ([`ShellModel::scatter_particle`]), which maps a load stiffness computed on point-local
//! degrees of freedom back to the global ones (loads and contact).

use super::model::ShellModel;
use super::point::DOFS_PER_PARTICLE;
use crate::scalar::Real;
use nalgebra::DMatrix;
use std::collections::HashMap;

/// The gather map of shape-function particles: for each of a particle's 5 local components,
/// the global `(dof, coefficient)` pairs it is gathered from. It is built as the transpose of
/// [`ShellModel::scatter_particle`] (scatter a unit local vector, read the global entries), so
/// whatever linear map the seam applies (identity for a real particle, a reflection for a
/// symmetry image) the load stiffness `Gᵀ K_loc G` follows it.
#[derive(Debug)]
pub struct GatherMap {
    rows: HashMap<usize, [Vec<(usize, f64)>; DOFS_PER_PARTICLE]>,
    scratch: Vec<f64>,
}

impl GatherMap {
    /// An empty map for `model`.
    pub fn new(model: &ShellModel) -> Self {
        GatherMap {
            rows: HashMap::new(),
            scratch: vec![0.0; model.n_dofs()],
        }
    }

    /// The rows of shape-function particle `j` (computed on first use: one scatter and one scan
    /// of the global vector per component).
    pub fn rows(
        &mut self,
        model: &ShellModel,
        j: usize,
    ) -> &[Vec<(usize, f64)>; DOFS_PER_PARTICLE] {
        let scratch = &mut self.scratch;
        self.rows.entry(j).or_insert_with(|| {
            std::array::from_fn(|c| {
                let mut e = [0.0; DOFS_PER_PARTICLE];
                e[c] = 1.0;
                model.scatter_particle(j, &e, scratch);
                let mut row = Vec::new();
                for (i, v) in scratch.iter_mut().enumerate() {
                    if *v != 0.0 {
                        row.push((i, *v));
                        *v = 0.0;
                    }
                }
                row
            })
        })
    }

    /// Component `c` of particle `j` gathered from the global vector `q`.
    pub fn gather<T: Real>(&mut self, model: &ShellModel, j: usize, c: usize, q: &[T]) -> T {
        self.rows(model, j)[c]
            .iter()
            .fold(T::zero(), |s, &(i, g)| s + q[i] * g)
    }

    /// Add `Gᵀ K_loc G` as triplets: `k_loc` is indexed by `(particle, component)` pairs
    /// `local[a]` on both sides.
    pub fn add_triplets(
        &mut self,
        model: &ShellModel,
        local: &[(usize, usize)],
        k_loc: &DMatrix<f64>,
        out: &mut Vec<(usize, usize, f64)>,
    ) {
        let rows: Vec<Vec<(usize, f64)>> = local
            .iter()
            .map(|&(j, c)| self.rows(model, j)[c].clone())
            .collect();
        for (a, ra) in rows.iter().enumerate() {
            for (b, rb) in rows.iter().enumerate() {
                let v = k_loc[(a, b)];
                if v == 0.0 {
                    continue;
                }
                for &(i, gi) in ra {
                    for &(jj, gj) in rb {
                        out.push((i, jj, gi * v * gj));
                    }
                }
            }
        }
    }
}
