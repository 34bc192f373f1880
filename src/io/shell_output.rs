//! Shell results: a VTU of the mid-surface per converged step with a PVD collection,
//! `results.json` rewritten after every converged step, and a load–displacement plot of the
//! monitors at the end.
//!
//! # The VTU of a step
//!
//! The mid-surface is drawn on a structured grid of the parameter domain whose quads are the
//! integration (background) cells, each optionally split `subdivide × subdivide` times. Points
//! are the **initial** positions `x̄⁰(ξ)` (exact, from the CAD surface); the deformed shape is
//! ParaView's "Warp by vector" with the point array `displacement` (scale 1).
//!
//! Point data (at every grid node, from [`ShellModel::sample`]):
//! - `displacement`: `ū(ξ) = Σ Ψ_I ū_I` (3);
//! - `director`: the unit current director `d/|d|`, `d = n⁰ + Σ Ψ_I (d_I − d_I⁰)` (3);
//! - `director_rotation`: the rotation vector `θ a` taking the initial normal `n⁰` to `d/|d|`
//!   by the shortest rotation: `a = n⁰ × d̂ / |n⁰ × d̂|`, `θ = atan2(|n⁰ × d̂|, n⁰ · d̂)` (3).
//!   It has no drilling component (the director carries none).
//!
//! Cell data (per visualisation quad, the values of its integration cell):
//! - `N` = `[N11, N22, N12]`, `M` = `[M11, M22, M12]`, `Q` = `[Q1, Q2]`: stress resultants per
//!   unit length in the initial lamina frame carried by the director
//!   ([`crate::shell::resultants`]);
//! - `eps_p_top`, `eps_p_mid`, `eps_p_bottom`: equivalent plastic strain `ē^p` (eq 15) of the
//!   layer nearest `ζ = +1`, the layers nearest `ζ = 0` (averaged if two are equally near, as
//!   for an even Gauss rule), and the layer nearest `ζ = −1`;
//! - `von_mises_top`, `von_mises_bottom`: the von Mises stress of the top and bottom layers
//!   (including the transverse shears, [`crate::material::von_mises`]).
//!
//! Every cell value is the area-weighted mean over the cell's quadrature points (weights
//! `w_k |x̄⁰,1 × x̄⁰,2|`, the initial area element).
//!
//! # results.json
//!
//! `{"case", "title", "wall_time_s", "status", "steps": [...]}`, one top-level entry per line
//! and one step per line. While running, `status` is `"running"` and `steps` lists the converged
//! steps; at the end it is `"complete"` or `"failed: <reason>"` and `steps` lists every step
//! attempt in order (converged or cut), each `{"step", "load_factor", "iterations",
//! "residual_norms", "converged", "monitors"}`, with `"monitors": {NAME: {"displacement": [ux,
//! uy, uz]}}` for converged steps and `null` (plus `"failure"`) for rejected ones. The file is
//! written to `results.json.tmp` and renamed ([`replace_file`]), so a reader, or a run killed
//! at any moment, never sees half a file. It and the PVD are rewritten after every converged
//! step while the run is short and then less and less often (`RewriteSchedule`: the total written
//! stays linear in the number of steps); every step is also appended to `steps.jsonl` as it
//! converges (one line of JSON each, serialised once and reused by every rewrite).
//!
//! # Output failures
//!
//! A file that cannot be written (a full disk, a removed directory) is an [`OutputError`]
//! naming it; its temporary file is removed, and [`ShellOutput::finish`] still tries to leave
//! a final `status` in results.json.

use super::shell_case::{Monitor, OutputSpec};
use super::vtu::{replace_file, PvdCollection, VtuError, VtuMesh, VtuWriter};
use crate::geometry::Surface;
use crate::meshfree::quadrature::CellQuadrature;
use crate::meshfree::ParamBox;
use crate::shell::contact::{ContactReport, ToolReport};
use crate::shell::model::ShellModel;
use crate::shell::resultants::layer_choice;
pub use crate::shell::resultants::{
    director_rotation, point_resultants, resultant_frame, CellResultants,
};
use crate::shell::ShellError;
use crate::solver::{CriticalKind, FactorisedAt, StepRecord, StepTiming};

/// `{"residual_and_tangent", "residual", "factorise", "solve"}` in seconds.
fn timing_json(t: &StepTiming) -> Value {
    json!({
        "residual_and_tangent": t.residual_and_tangent_s,
        "residual": t.residual_s,
        "factorise": t.factorise_s,
        "solve": t.solve_s,
    })
}
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Instant;
use thiserror::Error;

/// Errors writing shell results.
#[derive(Debug, Error)]
pub enum OutputError {
    /// A VTU or PVD file.
    #[error(transparent)]
    Vtu(#[from] VtuError),
    /// Another file.
    #[error("cannot write {path}: {source}")]
    Io {
        /// File or directory.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// JSON serialisation.
    #[error("results.json: {0}")]
    Json(#[from] serde_json::Error),
    /// The plot.
    #[error(transparent)]
    Plot(#[from] super::plot::PlotError),
    /// A JSON document other than results.json (`sensitivity.json`, `terms.json`).
    #[error("{}: {source}", path.display())]
    Document {
        /// The file.
        path: PathBuf,
        /// Cause.
        source: serde_json::Error,
    },
    /// Sampling the model.
    #[error("sampling the shell: {0}")]
    Model(#[from] ShellError),
    /// The output grid does not match the model's quadrature.
    #[error("output grid: {0}")]
    Grid(String),
}

/// A CSV field (RFC 4180): quoted, with its quotes doubled, when it holds a comma, a quote, a
/// line break or leading or trailing white space; as it is otherwise.
pub fn csv_field(text: &str) -> String {
    let plain = !text.contains([',', '"', '\n', '\r']) && text.trim() == text;
    if plain {
        text.to_string()
    } else {
        format!("\"{}\"", text.replace('"', "\"\""))
    }
}

/// Create `dir` (the step files' folder of an output directory) and remove the step files
/// (`step_NNNN.vtu`, four or more digits) an earlier run left there, so that the folder holds
/// this run's steps only. Other files are left alone.
pub(crate) fn fresh_steps_dir(dir: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name();
        let Some(name) = name.to_str() else { continue };
        let digits = name
            .strip_prefix("step_")
            .and_then(|n| n.strip_suffix(".vtu"));
        let ours = digits.is_some_and(|d| d.len() >= 4 && d.bytes().all(|b| b.is_ascii_digit()));
        if ours && entry.file_type()?.is_file() {
            std::fs::remove_file(entry.path())?;
        }
    }
    Ok(())
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> OutputError + '_ {
    move |source| OutputError::Io {
        path: path.to_owned(),
        source,
    }
}

/// The visualisation grid: the integration cells of a [`CellQuadrature`], each split
/// `subdivide × subdivide` times, and which cell every quadrature point of the model lies in.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputGrid {
    param_box: ParamBox,
    n_cells: [usize; 2],
    subdivide: usize,
    point_cell: Vec<usize>,
}

impl OutputGrid {
    /// The grid of `cq`'s cells, split `subdivide ≥ 1` times per direction. The model using it
    /// must have been built on `cq`'s points, in `cq`'s order ([`OutputGrid::check_model`]).
    pub fn new(cq: &CellQuadrature, subdivide: usize) -> Result<Self, OutputError> {
        if subdivide == 0 {
            return Err(OutputError::Grid("subdivide = 0: expected >= 1".into()));
        }
        Ok(OutputGrid {
            param_box: cq.param_box(),
            n_cells: cq.n_cells(),
            subdivide,
            point_cell: cq.cells().to_vec(),
        })
    }

    /// Check that the model's in-plane quadrature points are this grid's (same count; each
    /// point inside the box of the cell it is assigned to, within round-off).
    pub fn check_model(&self, model: &ShellModel) -> Result<(), OutputError> {
        if model.points.len() != self.point_cell.len() {
            return Err(OutputError::Grid(format!(
                "the model has {} quadrature points, the cell quadrature {}",
                model.points.len(),
                self.point_cell.len()
            )));
        }
        let b = &self.param_box;
        let h = [
            (b.hi[0] - b.lo[0]) / self.n_cells[0] as f64,
            (b.hi[1] - b.lo[1]) / self.n_cells[1] as f64,
        ];
        for (k, (p, &c)) in model.points.iter().zip(&self.point_cell).enumerate() {
            let ij = [c % self.n_cells[0], c / self.n_cells[0]];
            for a in 0..2 {
                let lo = b.lo[a] + h[a] * ij[a] as f64;
                // Round-off of the cell edges: 1e-12 of a cell.
                let tol = 1e-12 * h[a];
                if p.uv[a] < lo - tol || p.uv[a] > lo + h[a] + tol {
                    return Err(OutputError::Grid(format!(
                        "quadrature point {k} at {:?} is not in cell {c}",
                        p.uv
                    )));
                }
            }
        }
        Ok(())
    }

    /// Grid nodes per direction: `n_cells · subdivide + 1`.
    pub fn n_nodes(&self) -> [usize; 2] {
        [
            self.n_cells[0] * self.subdivide + 1,
            self.n_cells[1] * self.subdivide + 1,
        ]
    }

    /// Parameter coordinates of node `(i, j)` (`i` along u).
    pub fn node_uv(&self, i: usize, j: usize) -> [f64; 2] {
        let n = self.n_nodes();
        let c = |k: usize, m: usize| {
            let b = &self.param_box;
            if m + 1 == n[k] {
                b.hi[k]
            } else {
                b.lo[k] + (b.hi[k] - b.lo[k]) * m as f64 / (n[k] - 1) as f64
            }
        };
        [c(0, i), c(1, j)]
    }

    /// Node parameter coordinates in VTU order (`i * n_v + j`, v fastest; see
    /// [`VtuMesh::structured_grid`]).
    pub fn nodes(&self) -> Vec<[f64; 2]> {
        let n = self.n_nodes();
        (0..n[0])
            .flat_map(|i| (0..n[1]).map(move |j| (i, j)))
            .map(|(i, j)| self.node_uv(i, j))
            .collect()
    }

    /// Number of integration cells.
    pub fn n_cells(&self) -> usize {
        self.n_cells[0] * self.n_cells[1]
    }

    /// Integration cell (`i + n_u j`, as [`CellQuadrature::cells`]) of each visualisation quad,
    /// in VTU order (quad `a * (n_v − 1) + b` at node `(a, b)`).
    pub fn quad_cells(&self) -> Vec<usize> {
        let n = self.n_nodes();
        let s = self.subdivide;
        (0..n[0] - 1)
            .flat_map(|a| (0..n[1] - 1).map(move |b| (a / s) + self.n_cells[0] * (b / s)))
            .collect()
    }
}

/// Per integration cell, the area-weighted mean of [`point_resultants`] over its quadrature
/// points (weights `w_k |x̄⁰,1 × x̄⁰,2|`). A cell without points (impossible for a
/// [`CellQuadrature`]) is an error.
pub fn cell_resultants(
    model: &ShellModel,
    grid: &OutputGrid,
) -> Result<Vec<CellResultants>, OutputError> {
    grid.check_model(model)?;
    let nc = grid.n_cells();
    let mut sum = vec![CellResultants::default(); nc];
    let mut area = vec![0.0; nc];
    for (k, &c) in grid.point_cell.iter().enumerate() {
        let p = &model.points[k];
        let w = p.weight * p.surface.x_a[0].cross(&p.surface.x_a[1]).norm();
        let r = point_resultants(model, k);
        let s = &mut sum[c];
        for i in 0..3 {
            s.n[i] += w * r.n[i];
            s.m[i] += w * r.m[i];
            s.eps_p[i] += w * r.eps_p[i];
        }
        for i in 0..2 {
            s.q[i] += w * r.q[i];
            s.von_mises[i] += w * r.von_mises[i];
        }
        area[c] += w;
    }
    sum.into_iter()
        .zip(area)
        .enumerate()
        .map(|(c, (s, a))| {
            if a <= 0.0 {
                return Err(OutputError::Grid(format!(
                    "integration cell {c} has no quadrature point of positive weight"
                )));
            }
            let d = |v: f64| v / a;
            Ok(CellResultants {
                n: s.n.map(d),
                m: s.m.map(d),
                q: s.q.map(d),
                eps_p: s.eps_p.map(d),
                von_mises: s.von_mises.map(d),
            })
        })
        .collect()
}

/// Contact pressure `[top, bottom]` per integration cell: the area-weighted mean (weights
/// `w_k |x̄⁰,1 × x̄⁰,2|`, as the other cell data) of the per-quadrature-point pressures of a
/// [`ContactReport`] (`−ω g` at a penetrating slave point, zero elsewhere).
pub fn cell_contact_pressure(
    model: &ShellModel,
    grid: &OutputGrid,
    pressure: &[[f64; 2]],
) -> Result<Vec<[f64; 2]>, OutputError> {
    grid.check_model(model)?;
    if pressure.len() != model.points.len() {
        return Err(OutputError::Grid(format!(
            "{} contact pressures for {} quadrature points",
            pressure.len(),
            model.points.len()
        )));
    }
    let nc = grid.n_cells();
    let mut sum = vec![[0.0; 2]; nc];
    let mut area = vec![0.0; nc];
    for (k, &c) in grid.point_cell.iter().enumerate() {
        let p = &model.points[k];
        let w = p.weight * p.surface.x_a[0].cross(&p.surface.x_a[1]).norm();
        for f in 0..2 {
            sum[c][f] += w * pressure[k][f];
        }
        area[c] += w;
    }
    Ok(sum
        .into_iter()
        .zip(area)
        .map(|(s, a)| if a > 0.0 { s.map(|v| v / a) } else { [0.0; 2] })
        .collect())
}

/// The VTU of the committed state of `model` on `grid` (see the module documentation).
pub fn shell_vtu(
    model: &ShellModel,
    surface: &Surface<f64>,
    grid: &OutputGrid,
) -> Result<VtuWriter, OutputError> {
    shell_vtu_with_contact(model, surface, grid, None)
}

/// As [`shell_vtu`], plus, with the per-quadrature-point contact pressures of a
/// [`ContactReport`], the cell data `contact_pressure_top` / `contact_pressure_bottom`
/// ([`cell_contact_pressure`]) and the same as point data (each grid node the mean of the
/// visualisation quads around it).
pub fn shell_vtu_with_contact(
    model: &ShellModel,
    surface: &Surface<f64>,
    grid: &OutputGrid,
    pressure: Option<&[[f64; 2]]>,
) -> Result<VtuWriter, OutputError> {
    let cells = cell_resultants(model, grid)?;
    let nodes = grid.nodes();
    let mut points = Vec::with_capacity(nodes.len());
    let mut disp = Vec::with_capacity(nodes.len());
    let mut dir = Vec::with_capacity(nodes.len());
    let mut rot = Vec::with_capacity(nodes.len());
    for &uv in &nodes {
        let s = model.sample(surface, uv)?;
        points.push(s.x0.into());
        disp.push(s.displacement.into());
        dir.push(s.director.normalize().into());
        rot.push(director_rotation(&s.n0, &s.director).into());
    }
    let n = grid.n_nodes();
    let mesh = VtuMesh::structured_grid(n[0], n[1], points)?;
    let qc = grid.quad_cells();
    let per = |f: &dyn Fn(&CellResultants) -> Vec<f64>| -> Vec<f64> {
        qc.iter().flat_map(|&c| f(&cells[c])).collect()
    };
    let mut w = VtuWriter::new(mesh)
        .point_vector("displacement", &disp)
        .point_vector("director", &dir)
        .point_vector("director_rotation", &rot)
        .cell_array("N", 3, &per(&|r| r.n.to_vec()))
        .cell_array("M", 3, &per(&|r| r.m.to_vec()))
        .cell_array("Q", 2, &per(&|r| r.q.to_vec()))
        .cell_scalar("eps_p_top", &per(&|r| vec![r.eps_p[0]]))
        .cell_scalar("eps_p_mid", &per(&|r| vec![r.eps_p[1]]))
        .cell_scalar("eps_p_bottom", &per(&|r| vec![r.eps_p[2]]))
        .cell_scalar("von_mises_top", &per(&|r| vec![r.von_mises[0]]))
        .cell_scalar("von_mises_bottom", &per(&|r| vec![r.von_mises[1]]));
    if let Some(pr) = pressure {
        let cp = cell_contact_pressure(model, grid, pr)?;
        // Point values: mean of the (up to four) visualisation quads around each node.
        let mut node = vec![[0.0; 2]; n[0] * n[1]];
        let mut count = vec![0.0; n[0] * n[1]];
        for a in 0..n[0] - 1 {
            for b in 0..n[1] - 1 {
                let c = qc[a * (n[1] - 1) + b];
                for (i, j) in [(a, b), (a + 1, b), (a, b + 1), (a + 1, b + 1)] {
                    let k = i * n[1] + j;
                    node[k][0] += cp[c][0];
                    node[k][1] += cp[c][1];
                    count[k] += 1.0;
                }
            }
        }
        let face = |f: usize| -> Vec<f64> {
            node.iter()
                .zip(&count)
                .map(|(v, &m)| if m > 0.0 { v[f] / m } else { 0.0 })
                .collect()
        };
        w = w
            .point_scalar("contact_pressure_top", &face(0))
            .point_scalar("contact_pressure_bottom", &face(1))
            .cell_scalar(
                "contact_pressure_top",
                &qc.iter().map(|&c| cp[c][0]).collect::<Vec<_>>(),
            )
            .cell_scalar(
                "contact_pressure_bottom",
                &qc.iter().map(|&c| cp[c][1]).collect::<Vec<_>>(),
            );
    }
    Ok(w)
}

/// One design variable's sensitivity fields from one method at a committed step
/// ([`add_sensitivity_fields`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SensitivityField {
    /// The array names' suffix, `<variable> (<method>)`: the arrays are `d_u/d_<label>`,
    /// `d_eps_p_top/d_<label>`, `d_eps_p_mid/d_<label>`, `d_eps_p_bottom/d_<label>`.
    pub label: String,
    /// `ⁿū̇_I` of the particles as a generalised vector of the model (translations set).
    pub translations: Vec<f64>,
    /// `ⁿė^p` of every layer point, point-major as `ShellModel::history`.
    pub plastic_strain: Vec<f64>,
}

/// Per integration cell, the area-weighted mean (the weights of [`cell_resultants`]) of
/// per-layer-point `values` (point-major as `ShellModel::history`) at the layers nearest
/// `ζ = +1`, `ζ = 0` (averaged when two are equally near) and `ζ = −1`: the layout of the
/// `eps_p_top`, `eps_p_mid`, `eps_p_bottom` cell data.
pub fn cell_layer_means(
    model: &ShellModel,
    grid: &OutputGrid,
    values: &[f64],
    name: &str,
) -> Result<Vec<[f64; 3]>, OutputError> {
    grid.check_model(model)?;
    let nl = model.thickness_rule.len();
    if values.len() != model.points.len() * nl {
        return Err(OutputError::Grid(format!(
            "`{name}`: {} layer-point values, expected {} ({} points × {nl} layers)",
            values.len(),
            model.points.len() * nl,
            model.points.len()
        )));
    }
    let (top, mid, bottom) = layer_choice(&model.thickness_rule);
    let nc = grid.n_cells();
    let mut sum = vec![[0.0; 3]; nc];
    let mut area = vec![0.0; nc];
    for (k, &c) in grid.point_cell.iter().enumerate() {
        let p = &model.points[k];
        let w = p.weight * p.surface.x_a[0].cross(&p.surface.x_a[1]).norm();
        let at = |l: usize| values[k * nl + l];
        let m = mid.iter().map(|&l| at(l)).sum::<f64>() / mid.len().max(1) as f64;
        for (f, v) in [at(top), m, at(bottom)].into_iter().enumerate() {
            sum[c][f] += w * v;
        }
        area[c] += w;
    }
    sum.into_iter()
        .zip(area)
        .enumerate()
        .map(|(c, (s, a))| {
            if a <= 0.0 {
                return Err(OutputError::Grid(format!(
                    "integration cell {c} has no quadrature point of positive weight"
                )));
            }
            Ok(s.map(|v| v / a))
        })
        .collect()
}

/// `w` (the VTU of `model` on `grid`, [`shell_vtu_with_contact`]) with the design
/// sensitivities: the point data `uv` (the node's parameter coordinates, 2 components) and per
/// field `d_u/d_<label>` (3: `Σ Ψ_J ū̇_J` at the node, by
/// [`ShellModel::interpolate_translation`], the derivative a displacement monitor at that
/// point records), and the cell data `d_eps_p_top/d_<label>`, `d_eps_p_mid/d_<label>`,
/// `d_eps_p_bottom/d_<label>` ([`cell_layer_means`] of `ė^p`).
pub fn add_sensitivity_fields(
    mut w: VtuWriter,
    model: &ShellModel,
    grid: &OutputGrid,
    fields: &[SensitivityField],
) -> Result<VtuWriter, OutputError> {
    let nodes = grid.nodes();
    let uv: Vec<f64> = nodes.iter().flatten().copied().collect();
    w = w.point_array("uv", 2, &uv);
    let qc = grid.quad_cells();
    for f in fields {
        let du = nodes
            .iter()
            .map(|&uv| Ok(model.interpolate_translation(uv, &f.translations)?.into()))
            .collect::<Result<Vec<[f64; 3]>, ShellError>>()?;
        w = w.point_vector(&format!("d_u/d_{}", f.label), &du);
        let name = format!("d_eps_p/d_{}", f.label);
        let cells = cell_layer_means(model, grid, &f.plastic_strain, &name)?;
        for (i, layer) in ["top", "mid", "bottom"].iter().enumerate() {
            let per: Vec<f64> = qc.iter().map(|&c| cells[c][i]).collect();
            w = w.cell_scalar(&format!("d_eps_p_{layer}/d_{}", f.label), &per);
        }
    }
    Ok(w)
}

fn dot3(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Displacement `ū(ξ)` of the committed state at each monitor.
pub fn monitor_displacements(
    model: &ShellModel,
    surface: &Surface<f64>,
    monitors: &[Monitor],
) -> Result<Vec<[f64; 3]>, OutputError> {
    monitors
        .iter()
        .map(|m| Ok(model.sample(surface, m.at)?.displacement.into()))
        .collect()
}

/// The line search's tries (written only when there were some): `{iteration, length,
/// reason}` each, the reason why the iterate at the previous length was not usable.
fn backtracks_json(b: &[crate::solver::Backtrack]) -> Value {
    Value::Array(
        b.iter()
            .map(|t| {
                json!({
                    "iteration": t.iteration,
                    "length": t.length,
                    "reason": t.reason.to_string(),
                })
            })
            .collect(),
    )
}

/// What was recorded for one converged step.
#[derive(Clone, Debug, PartialEq)]
pub struct StepSummary {
    /// Converged step number (1-based).
    pub step: usize,
    /// Load factor reached.
    pub load_factor: f64,
    /// Newton iterations.
    pub iterations: usize,
    /// Of them, those whose iterate changed the contact active set
    /// ([`crate::solver::StepRecord::active_set_iterations`]).
    pub active_set_iterations: usize,
    /// Residual norms of every evaluation.
    pub residual_norms: Vec<f64>,
    /// Residual-only evaluations `(k, ‖r_k‖)` of the residual-first acceptance
    /// ([`crate::solver::StepRecord::residual_only`]).
    pub residual_only: Vec<(usize, f64)>,
    /// Whether the converged iterate was accepted from its residual alone (no tangent assembled
    /// or factorised there).
    pub accepted_residual_only: bool,
    /// Wall time of the step's solver parts (the converged attempt).
    pub timing: StepTiming,
    /// Updates solved by preconditioned GMRES: `(k, Arnoldi steps)`.
    pub krylov: Vec<(usize, usize)>,
    /// Iterations whose GMRES update gave up ([`crate::solver::StepRecord::krylov_gave_up`]).
    pub krylov_gave_up: Vec<usize>,
    /// Iterations factorised without trying GMRES
    /// ([`crate::solver::StepRecord::krylov_skipped`]).
    pub krylov_skipped: Vec<usize>,
    /// Backtracking tries of the Newton line search
    /// ([`crate::solver::StepRecord::backtracks`]).
    pub backtracks: Vec<crate::solver::Backtrack>,
    /// Intermediate levels solved to start the step ([`crate::solver::StepRecord::continuation`]).
    pub continuation: Vec<f64>,
    /// Monitor displacements, in the case's monitor order.
    pub monitors: Vec<[f64; 3]>,
    /// The VTU written for this step (relative to the output directory), if any.
    pub vtu: Option<String>,
    /// Contact with rigid tools at this step (cases with `[[tool]]`).
    pub contact: Option<StepContact>,
    /// Set on the step at which the `[contact] release` tool separated from the sheet.
    pub separation: Option<Separation>,
    /// Reactions of the `prescribed` entries (displacement control): `(boundary[k], the force
    /// or moment the support exerts on the shell along the prescribed component)`.
    pub reactions: Vec<(String, f64)>,
    /// The share of the particles' director changes that the RK approximation leaves out
    /// ([`crate::shell::stabilisation::DirectorResolution`]): near 1 for the checkerboard mode.
    pub director_unresolved: Option<f64>,
    /// The same share of the step's own director changes (`None` where they are negligible,
    /// [`crate::shell::stabilisation::NEGLIGIBLE_STEP_CHANGE`]).
    pub director_unresolved_step: Option<f64>,
}

/// The tools at one converged step.
#[derive(Clone, Debug, PartialEq)]
pub struct StepContact {
    /// Per tool: position, rotation, the force the sheet exerts on it, active slave points.
    pub tools: Vec<ToolReport>,
    /// Active (penetrating) slave points over all tools.
    pub active_points: usize,
}

/// The separation of the `[contact] release` tool: the first converged step at which it
/// carries no force (no active slave point) after it had carried some.
#[derive(Clone, Debug, PartialEq)]
pub struct Separation {
    /// Tool name.
    pub tool: String,
    /// Load factor (tool time) of that step.
    pub t: f64,
    /// Converged step number.
    pub step: usize,
    /// Load factor of the last converged step with the tool in contact (the separation lies in
    /// `(t_before, t]`).
    pub t_before: f64,
}

/// Writes the results of a shell run into one directory: `shell.pvd` with `steps/step_NNNN.vtu`
/// (step 0 is the initial state), `results.json`, and `load_displacement.png`.
#[derive(Debug)]
pub struct ShellOutput {
    dir: PathBuf,
    case: String,
    title: String,
    monitors: Vec<Monitor>,
    spec: OutputSpec,
    grid: OutputGrid,
    final_load: f64,
    pvd: PvdCollection,
    steps: Vec<StepSummary>,
    /// Each converged step's record as one line of compact JSON (serialised once).
    step_lines: Vec<String>,
    /// `steps.jsonl`, open for appending, and its length after the last whole line.
    step_log: Option<(std::fs::File, u64)>,
    rewrites: crate::solver::observe::RewriteSchedule,
    start: Instant,
    info: serde_json::Map<String, Value>,
    contact: Option<ContactTracking>,
    /// Per monitor: the unit direction of its `along` value, if any.
    directions: Vec<Option<[f64; 3]>>,
    /// Displacement control: the load–displacement plot shows the reaction of the first
    /// `prescribed` entry times this sign (that of its prescribed value: the load along the
    /// prescribed motion).
    displacement_control: Option<f64>,
    /// Reactions of the step being recorded (set before [`Self::converged_with_contact`]).
    pending_reactions: Vec<(String, f64)>,
    pending_director_unresolved: Option<(Option<f64>, Option<f64>)>,
    pvd_time: PvdTime,
    /// Critical points passed, as (kind, converged step after it, 1-based), marked on the
    /// load–displacement plot.
    critical: Vec<(CriticalKind, usize)>,
}

/// What `shell.pvd` gives ParaView as a written step's time (a collection's times must rise).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PvdTime {
    /// The load factor: it rises at every step under load and displacement control (a tool's
    /// path parameter `t` too, through loading and unloading).
    #[default]
    LoadFactor,
    /// The converged step's number: under arc-length control the load factor falls after a
    /// load maximum.
    Step,
}

/// What [`ShellOutput`] tracks of the contact over the run.
#[derive(Clone, Debug, Default)]
struct ContactTracking {
    /// The tool whose separation is detected.
    release: Option<String>,
    /// Load factor of the last step at which the release tool was in contact.
    release_in_contact: Option<f64>,
    separation: Option<Separation>,
    /// Per tool (case order): name, whether it had an active point at a converged step.
    touched: Vec<(String, bool)>,
    /// Per-quadrature-point pressure of the last converged step (for a VTU written at the end).
    last_pressure: Option<Vec<[f64; 2]>>,
    warnings: Vec<String>,
}

/// File of the PVD collection inside the output directory.
pub const PVD_FILE: &str = "shell.pvd";
/// Results file inside the output directory.
pub const RESULTS_FILE: &str = "results.json";
/// Append-only record of the converged steps inside the output directory: one line of JSON per
/// step (the same object as in results.json's `steps`), appended as each step converges.
pub const STEPS_LOG_FILE: &str = "steps.jsonl";
/// Plot file inside the output directory.
pub const PLOT_FILE: &str = "load_displacement.png";
/// Tool force table inside the output directory (cases with tools).
pub const TOOL_FORCES_FILE: &str = "tool_forces.csv";
/// Force–stroke plot inside the output directory (cases with tools).
pub const TOOL_PLOT_FILE: &str = "force_stroke.png";

/// The legend entries of the critical points on the load–displacement plot and the kinds each
/// marks.
const CRITICAL_GROUPS: [(&str, &[CriticalKind]); 3] = [
    (
        "step after a limit point",
        &[CriticalKind::LoadMaximum, CriticalKind::LoadMinimum],
    ),
    ("step after a snap-back", &[CriticalKind::SnapBack]),
    ("step after a bifurcation", &[CriticalKind::Bifurcation]),
];

impl ShellOutput {
    /// Output into `dir` (created if missing). `case` names the case (e.g. its file),
    /// `final_load` is the load factor of the last step (always written to VTU), `start` the
    /// start of the run (for `wall_time_s`).
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        dir: &Path,
        case: &str,
        title: &str,
        monitors: &[Monitor],
        spec: OutputSpec,
        grid: OutputGrid,
        final_load: f64,
        start: Instant,
    ) -> Result<Self, OutputError> {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        if spec.vtu {
            let steps = dir.join("steps");
            fresh_steps_dir(&steps).map_err(io_err(&steps))?;
        }
        Ok(ShellOutput {
            dir: dir.to_owned(),
            case: case.to_owned(),
            title: title.to_owned(),
            monitors: monitors.to_vec(),
            spec,
            grid,
            final_load,
            pvd: PvdCollection::new(dir.join(PVD_FILE)),
            steps: Vec::new(),
            step_lines: Vec::new(),
            step_log: None,
            rewrites: crate::solver::observe::RewriteSchedule::starting(start),
            start,
            info: serde_json::Map::new(),
            contact: None,
            directions: Vec::new(),
            displacement_control: None,
            pending_reactions: Vec::new(),
            pvd_time: PvdTime::default(),
            pending_director_unresolved: None,
            critical: Vec::new(),
        })
    }

    /// Per monitor (case order), the unit direction whose displacement component is recorded as
    /// `"along"` in results.json and plotted instead of the three components.
    pub fn set_monitor_directions(&mut self, directions: Vec<Option<[f64; 3]>>) {
        self.directions = directions;
    }

    /// Displacement control, with the sign of the first `prescribed` entry's value: the
    /// load–displacement plot then shows that entry's reaction times the sign (the load along
    /// the prescribed motion) on its load axis.
    pub fn set_displacement_control(&mut self, sign: Option<f64>) {
        self.displacement_control = sign;
    }

    /// What `shell.pvd` gives as a step's time ([`PvdTime::Step`] for arc-length runs), also
    /// written to results.json as `pvd_time`.
    pub fn set_pvd_time(&mut self, time: PvdTime) {
        self.pvd_time = time;
        let name = match time {
            PvdTime::LoadFactor => "load factor",
            PvdTime::Step => "step",
        };
        self.set_info("pvd_time", Value::from(name));
    }

    /// The reactions of the `prescribed` entries at the step recorded next.
    pub fn set_step_reactions(&mut self, reactions: Vec<(String, f64)>) {
        self.pending_reactions = reactions;
    }

    /// The unresolved shares of the director changes, since the reference state and in the
    /// step (`None`: the changes are negligible), at the step recorded next.
    pub fn set_step_director_unresolved(&mut self, total: Option<f64>, step: Option<f64>) {
        self.pending_director_unresolved = Some((total, step));
    }

    /// Record contact with the named tools (in case order): per-step tool positions, forces
    /// and active points in results.json, the contact pressure in the VTUs, `tool_forces.csv`
    /// and `force_stroke.png` at the end, and the separation of the tool `release`.
    pub fn set_contact(&mut self, tools: &[String], release: Option<String>) {
        self.contact = Some(ContactTracking {
            release,
            touched: tools.iter().map(|t| (t.clone(), false)).collect(),
            ..ContactTracking::default()
        });
    }

    /// The separation of the release tool, once detected.
    pub fn separation(&self) -> Option<&Separation> {
        self.contact.as_ref().and_then(|c| c.separation.as_ref())
    }

    /// Warnings of the run (tools that never touched the sheet; set by [`Self::finish`]).
    pub fn warnings(&self) -> &[String] {
        self.contact.as_ref().map_or(&[], |c| &c.warnings)
    }

    /// The critical points the run passed, each as its kind and the converged step (1-based)
    /// after it: the load–displacement plot marks that step (limit points, snap-backs and
    /// bifurcations in three series) on the panels of monitors with a direction.
    pub fn set_critical_points(&mut self, points: Vec<(CriticalKind, usize)>) {
        self.critical = points;
    }

    /// Extra top-level entries of results.json (model size, settings).
    pub fn set_info(&mut self, key: &str, value: Value) {
        self.info.insert(key.to_owned(), value);
    }

    /// The converged steps recorded so far.
    pub fn steps(&self) -> &[StepSummary] {
        &self.steps
    }

    /// The output directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    fn write_vtu(
        &mut self,
        model: &ShellModel,
        surface: &Surface<f64>,
        step: usize,
        time: f64,
    ) -> Result<String, OutputError> {
        let rel = format!("steps/step_{step:04}.vtu");
        let pressure = self.contact.as_ref().map(|c| {
            c.last_pressure
                .clone()
                .unwrap_or_else(|| vec![[0.0; 2]; model.points.len()])
        });
        shell_vtu_with_contact(model, surface, &self.grid, pressure.as_deref())?
            .write(&self.dir.join(&rel))?;
        let time = match self.pvd_time {
            PvdTime::LoadFactor => time,
            PvdTime::Step => step as f64,
        };
        self.pvd.add(time, &rel)?;
        Ok(rel)
    }

    /// The initial (unloaded) state as step 0 at load factor 0, and a first results.json.
    /// If a file cannot be written, results.json gets the status `"failed: writing results:
    /// ..."` (if the disk still takes that) and the error is returned.
    pub fn initial(
        &mut self,
        model: &ShellModel,
        surface: &Surface<f64>,
    ) -> Result<(), OutputError> {
        let written = self.initial_files(model, surface);
        if let Err(e) = &written {
            let _ = self.write_final(&format!("failed: writing results: {e}"), &[]);
        }
        written
    }

    fn initial_files(
        &mut self,
        model: &ShellModel,
        surface: &Surface<f64>,
    ) -> Result<(), OutputError> {
        self.grid.check_model(model)?;
        let log = self.dir.join(STEPS_LOG_FILE);
        let file = std::fs::File::create(&log).map_err(io_err(&log))?;
        self.step_log = Some((file, 0));
        if self.spec.vtu {
            self.write_vtu(model, surface, 0, 0.0)?;
        }
        self.rewrite("running")
    }

    /// Record a converged (and committed) step: monitors, the VTU if due (every `every`-th
    /// step and the last one), the PVD and results.json.
    pub fn converged(
        &mut self,
        model: &ShellModel,
        surface: &Surface<f64>,
        record: &StepRecord,
    ) -> Result<&StepSummary, OutputError> {
        self.converged_with_contact(model, surface, record, None)
    }

    /// As [`Self::converged`], with the contact state of the committed step (cases with tools,
    /// after [`Self::set_contact`]): tools, active points, pressure, separation.
    pub fn converged_with_contact(
        &mut self,
        model: &ShellModel,
        surface: &Surface<f64>,
        record: &StepRecord,
        report: Option<&ContactReport>,
    ) -> Result<&StepSummary, OutputError> {
        let step = self.steps.len() + 1;
        let mut contact = None;
        let mut separation = None;
        if let (Some(track), Some(rep)) = (self.contact.as_mut(), report) {
            for (k, t) in rep.tools.iter().enumerate() {
                if t.active_points > 0 {
                    if let Some(e) = track.touched.get_mut(k) {
                        e.1 = true;
                    }
                }
            }
            if let Some(name) = &track.release {
                if let Some(t) = rep.tools.iter().find(|t| &t.name == name) {
                    if t.active_points > 0 {
                        track.release_in_contact = Some(record.load);
                    } else if let (None, Some(before)) =
                        (&track.separation, track.release_in_contact)
                    {
                        let s = Separation {
                            tool: name.clone(),
                            t: record.load,
                            step,
                            t_before: before,
                        };
                        track.separation = Some(s.clone());
                        separation = Some(s);
                    }
                }
            }
            track.last_pressure = Some(rep.pressure.clone());
            contact = Some(StepContact {
                tools: rep.tools.clone(),
                active_points: rep.tools.iter().map(|t| t.active_points).sum(),
            });
        }
        let monitors = monitor_displacements(model, surface, &self.monitors)?;
        let last = (self.final_load - record.load).abs() <= 1e-12 * self.final_load.abs().max(1.0);
        let vtu = if self.spec.vtu && (step % self.spec.every == 0 || last) {
            Some(self.write_vtu(model, surface, step, record.load)?)
        } else {
            None
        };
        self.steps.push(StepSummary {
            step,
            load_factor: record.load,
            iterations: record.iterations,
            active_set_iterations: record.active_set_iterations,
            residual_norms: record.residual_norms.clone(),
            residual_only: record.residual_only.clone(),
            accepted_residual_only: record.factorised_at == Some(FactorisedAt::PreviousIterate),
            timing: record.timing,
            krylov: record.krylov.clone(),
            krylov_gave_up: record.krylov_gave_up.clone(),
            krylov_skipped: record.krylov_skipped.clone(),
            backtracks: record.backtracks.clone(),
            continuation: record.continuation.clone(),
            monitors,
            vtu,
            contact,
            separation,
            reactions: std::mem::take(&mut self.pending_reactions),
            director_unresolved: self.pending_director_unresolved.and_then(|s| s.0),
            director_unresolved_step: self.pending_director_unresolved.take().and_then(|s| s.1),
        });
        let summary = self.steps.last().expect("just pushed");
        let line = serde_json::to_string(&self.step_json(summary))?;
        self.append_step(&line)?;
        self.step_lines.push(line);
        if self.rewrites.due(self.steps.len()) {
            self.rewrite("running")?;
        }
        Ok(self.steps.last().expect("just pushed"))
    }

    /// End of the run: the VTU of the last converged step if it was skipped by `every`, the
    /// PVD, the plot and tool forces, then the final results.json (`status` is `"complete"` or
    /// `"failed: ..."`; `attempts` every step attempt of the driver, in order). If a file cannot
    /// be written, results.json gets the status `"failed: writing results: ..."` naming it
    /// (if the disk still takes that) and the first such error is returned.
    pub fn finish(
        &mut self,
        model: &ShellModel,
        surface: &Surface<f64>,
        status: &str,
        attempts: &[StepRecord],
    ) -> Result<(), OutputError> {
        if let Some(track) = self.contact.as_mut() {
            let never: Vec<&str> = track
                .touched
                .iter()
                .filter(|t| !t.1)
                .map(|t| t.0.as_str())
                .collect();
            if !never.is_empty() && !self.steps.is_empty() {
                track.warnings.push(format!(
                    "tool(s) {never:?} never touched the sheet at a converged step \
                     (no active slave point): check the tool position, path and side"
                ));
            }
        }
        let written = self.finish_files(model, surface);
        let status = match &written {
            Ok(()) => status.to_string(),
            Err(e) if !status.starts_with("failed: writing results") => {
                format!("failed: writing results: {e}")
            }
            Err(_) => status.to_string(),
        };
        self.write_final(&status, attempts)?;
        written
    }

    /// The files of [`Self::finish`] other than results.json.
    fn finish_files(
        &mut self,
        model: &ShellModel,
        surface: &Surface<f64>,
    ) -> Result<(), OutputError> {
        if self.spec.vtu {
            if let Some(k) = self.steps.len().checked_sub(1) {
                if self.steps[k].vtu.is_none() {
                    let (step, load) = (self.steps[k].step, self.steps[k].load_factor);
                    let rel = self.write_vtu(model, surface, step, load)?;
                    self.steps[k].vtu = Some(rel);
                    self.step_lines[k] = serde_json::to_string(&self.step_json(&self.steps[k]))?;
                }
            }
            self.pvd.write()?;
        }
        if self.spec.plot && !self.monitors.is_empty() {
            self.plot(&self.dir.join(PLOT_FILE))?;
        }
        if self.contact.is_some() {
            self.write_tool_forces(&self.dir.join(TOOL_FORCES_FILE))?;
            if self.spec.plot {
                self.plot_tool_forces(&self.dir.join(TOOL_PLOT_FILE))?;
            }
        }
        Ok(())
    }

    /// The tool whose translation defines the stroke: the release tool, else the first.
    fn stroke_tool(&self) -> usize {
        let Some(track) = &self.contact else { return 0 };
        track
            .release
            .as_ref()
            .and_then(|r| track.touched.iter().position(|t| &t.0 == r))
            .unwrap_or(0)
    }

    /// `tool_forces.csv`: one row per converged step (and the unloaded start), `step, t,
    /// stroke` (the length `|a(t)|` of the stroke tool's translation) and per tool its
    /// translation, the force the sheet exerts on it and its active slave points.
    fn write_tool_forces(&self, path: &Path) -> Result<(), OutputError> {
        let Some(track) = &self.contact else {
            return Ok(());
        };
        let st = self.stroke_tool();
        let mut text = String::from("step,t,stroke");
        for (name, _) in &track.touched {
            for c in ["x", "y", "z", "fx", "fy", "fz", "active_points"] {
                text.push(',');
                text.push_str(&csv_field(&format!("{name}_{c}")));
            }
        }
        text.push('\n');
        for s in &self.steps {
            let Some(c) = &s.contact else { continue };
            let stroke = c.tools.get(st).map_or(0.0, |t| {
                (t.position[0].powi(2) + t.position[1].powi(2) + t.position[2].powi(2)).sqrt()
            });
            text.push_str(&format!("{},{:e},{:e}", s.step, s.load_factor, stroke));
            for t in &c.tools {
                for v in t.position.iter().chain(&t.force) {
                    text.push_str(&format!(",{v:e}"));
                }
                text.push_str(&format!(",{}", t.active_points));
            }
            text.push('\n');
        }
        replace_file(path, text.as_bytes()).map_err(io_err(path))
    }

    /// `force_stroke.png`: the magnitude of each tool's force against the stroke (the
    /// translation length of the release tool, else the first tool), in the order of the steps
    /// (loading and unloading branches both drawn).
    fn plot_tool_forces(&self, path: &Path) -> Result<(), OutputError> {
        use super::plot::{figure, Panel, Scale, Series, Style};
        let Some(track) = &self.contact else {
            return Ok(());
        };
        let st = self.stroke_tool();
        let labels: Vec<String> = track
            .touched
            .iter()
            .map(|t| format!("|force| on {}", t.0))
            .collect();
        let series: Vec<Series> = (0..track.touched.len())
            .map(|k| Series {
                label: &labels[k],
                points: std::iter::once((0.0, 0.0))
                    .chain(self.steps.iter().filter_map(|s| {
                        let c = s.contact.as_ref()?;
                        let p = c.tools.get(st)?.position;
                        let f = c.tools.get(k)?.force;
                        Some((
                            (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt(),
                            (f[0] * f[0] + f[1] * f[1] + f[2] * f[2]).sqrt(),
                        ))
                    }))
                    .collect(),
                style: Style::Line,
            })
            .collect();
        let title = format!("{}: tool forces", self.title);
        let x_label = format!(
            "stroke of {} (length of its translation)",
            track.touched.get(st).map_or("", |t| t.0.as_str())
        );
        let panel = Panel {
            title: &title,
            x_label: &x_label,
            y_label: "force",
            x_scale: Scale::Linear,
            y_scale: Scale::Linear,
            series,
        };
        figure(path, 900, 480, &[panel]).map_err(OutputError::Plot)
    }

    fn monitors_json(&self, values: &[[f64; 3]]) -> Value {
        let mut m = serde_json::Map::new();
        for (k, (mon, v)) in self.monitors.iter().zip(values).enumerate() {
            let mut e = json!({ "displacement": v });
            if let (Some(Some(d)), Value::Object(o)) = (self.directions.get(k), &mut e) {
                o.insert("along".into(), json!(dot3(v, d)));
                o.insert("direction".into(), json!(d));
            }
            m.insert(mon.name.clone(), e);
        }
        Value::Object(m)
    }

    fn step_json(&self, s: &StepSummary) -> Value {
        let mut v = json!({
            "step": s.step,
            "load_factor": s.load_factor,
            "iterations": s.iterations,
            "active_set_iterations": s.active_set_iterations,
            "residual_norms": s.residual_norms,
            "residual_only": s.residual_only,
            "accepted_residual_only": s.accepted_residual_only,
            "timing_s": timing_json(&s.timing),
            "krylov_updates": s.krylov,
            "krylov_gave_up": s.krylov_gave_up,
            "krylov_skipped": s.krylov_skipped,
            "converged": true,
            "monitors": self.monitors_json(&s.monitors),
            "vtu": s.vtu,
        });
        if let (false, Value::Object(o)) = (s.backtracks.is_empty(), &mut v) {
            o.insert("line_search".into(), backtracks_json(&s.backtracks));
        }
        if let (false, Value::Object(o)) = (s.continuation.is_empty(), &mut v) {
            o.insert("continuation".into(), json!(s.continuation));
        }
        if let (Some(share), Value::Object(o)) = (s.director_unresolved, &mut v) {
            o.insert("director_unresolved".into(), json!(share));
        }
        if let (Some(share), Value::Object(o)) = (s.director_unresolved_step, &mut v) {
            o.insert("director_unresolved_step".into(), json!(share));
        }
        if let (false, Value::Object(o)) = (s.reactions.is_empty(), &mut v) {
            let r: serde_json::Map<String, Value> = s
                .reactions
                .iter()
                .map(|(k, f)| (k.clone(), json!(f)))
                .collect();
            o.insert("reactions".into(), Value::Object(r));
        }
        if let (Some(c), Value::Object(o)) = (&s.contact, &mut v) {
            let mut m = serde_json::Map::new();
            for t in &c.tools {
                m.insert(
                    t.name.clone(),
                    json!({
                        "position": t.position,
                        "rotation": t.rotation,
                        "force": t.force,
                        "active_points": t.active_points,
                    }),
                );
            }
            o.insert("tools".into(), Value::Object(m));
            o.insert("active_contact_points".into(), json!(c.active_points));
            if let Some(sep) = &s.separation {
                o.insert("separation".into(), json!(sep.tool));
            }
        }
        v
    }

    /// The results.json document.
    pub fn results_json(&self, status: &str, attempts: Option<&[StepRecord]>) -> Value {
        let mut doc = self.header_json(status);
        let steps = match attempts {
            None => self.steps.iter().map(|s| self.step_json(s)).collect(),
            Some(att) => self
                .attempt_entries(att)
                .into_iter()
                .map(|e| match e {
                    Ok(k) => self.step_json(&self.steps[k]),
                    Err(v) => v,
                })
                .collect(),
        };
        doc.insert("steps".into(), Value::Array(steps));
        Value::Object(doc)
    }

    /// Every step attempt in order: `Ok(k)` for the `k`-th converged step, `Err(entry)` for a
    /// rejected attempt (`"converged": false`, its failure, no monitors).
    fn attempt_entries(&self, attempts: &[StepRecord]) -> Vec<Result<usize, Value>> {
        let mut next = 0;
        let mut n = 0;
        attempts
            .iter()
            .map(|a| {
                if a.converged && next < self.steps.len() {
                    n = self.steps[next].step;
                    next += 1;
                    return Ok(next - 1);
                }
                let mut e = json!({
                    "step": n + 1,
                    "load_factor": a.load,
                    "step_size": a.step_size,
                    "iterations": a.iterations,
                    "active_set_iterations": a.active_set_iterations,
                    "residual_norms": a.residual_norms,
                    "converged": false,
                    "failure": a.failure.as_ref().map(|f| f.to_string()),
                    "monitors": Value::Null,
                });
                if let (false, Value::Object(o)) = (a.backtracks.is_empty(), &mut e) {
                    o.insert("line_search".into(), backtracks_json(&a.backtracks));
                }
                Err(e)
            })
            .collect()
    }

    /// Every top-level entry of results.json but `steps`.
    fn header_json(&self, status: &str) -> serde_json::Map<String, Value> {
        let mut doc = serde_json::Map::new();
        doc.insert("case".into(), json!(self.case));
        doc.insert("title".into(), json!(self.title));
        doc.insert(
            "wall_time_s".into(),
            json!(self.start.elapsed().as_secs_f64()),
        );
        doc.insert("status".into(), json!(status));
        // Solver parts summed over the converged steps (failed attempts not included).
        let total = self
            .steps
            .iter()
            .fold(StepTiming::default(), |a, s| StepTiming {
                residual_and_tangent_s: a.residual_and_tangent_s + s.timing.residual_and_tangent_s,
                residual_s: a.residual_s + s.timing.residual_s,
                factorise_s: a.factorise_s + s.timing.factorise_s,
                solve_s: a.solve_s + s.timing.solve_s,
            });
        doc.insert("solver_timing_s".into(), timing_json(&total));
        doc.insert(
            "monitors".into(),
            Value::Array(
                self.monitors
                    .iter()
                    .map(|m| json!({"name": m.name, "at": m.at}))
                    .collect(),
            ),
        );
        for (k, v) in &self.info {
            doc.insert(k.clone(), v.clone());
        }
        if let Some(track) = &self.contact {
            doc.insert(
                "separation".into(),
                match &track.separation {
                    Some(s) => {
                        json!({"tool": s.tool, "t": s.t, "step": s.step, "t_before": s.t_before})
                    }
                    None => Value::Null,
                },
            );
            doc.insert("warnings".into(), json!(track.warnings));
        }
        doc
    }

    /// results.json as text: one top-level entry per line and one step per line, the step
    /// lines those serialised when each step converged (so a rewrite costs a copy, not a
    /// serialisation, of the steps).
    fn results_text(
        &self,
        status: &str,
        attempts: Option<&[StepRecord]>,
    ) -> Result<String, OutputError> {
        let mut text = String::from("{\n");
        for (k, v) in self.header_json(status) {
            text.push_str(&format!(
                "  {}: {},\n",
                serde_json::to_string(&k)?,
                serde_json::to_string(&v)?
            ));
        }
        text.push_str("  \"steps\": [");
        let mut first = true;
        let mut push = |line: &str| {
            text.push_str(if first { "\n    " } else { ",\n    " });
            text.push_str(line);
            first = false;
        };
        match attempts {
            None => self.step_lines.iter().for_each(|l| push(l)),
            Some(att) => {
                for e in self.attempt_entries(att) {
                    match e {
                        Ok(k) => push(&self.step_lines[k]),
                        Err(v) => push(&serde_json::to_string(&v)?),
                    }
                }
            }
        }
        text.push_str(if first { "]\n}\n" } else { "\n  ]\n}\n" });
        Ok(text)
    }

    /// Append one step's line to `steps.jsonl` (one `write` call). On failure the file is cut
    /// back to its last whole line.
    fn append_step(&mut self, line: &str) -> Result<(), OutputError> {
        use std::io::Write;
        let path = self.dir.join(STEPS_LOG_FILE);
        let Some((file, len)) = self.step_log.as_mut() else {
            return Ok(());
        };
        let mut bytes = Vec::with_capacity(line.len() + 1);
        bytes.extend_from_slice(line.as_bytes());
        bytes.push(b'\n');
        match file.write_all(&bytes) {
            Ok(()) => {
                *len += bytes.len() as u64;
                Ok(())
            }
            Err(e) => {
                let _ = file.set_len(*len);
                Err(io_err(&path)(e))
            }
        }
    }

    /// Rewrite the PVD and results.json (with the converged steps so far).
    fn rewrite(&mut self, status: &str) -> Result<(), OutputError> {
        let t = Instant::now();
        if self.spec.vtu {
            self.pvd.write()?;
        }
        let text = self.results_text(status, None)?;
        let path = self.dir.join(RESULTS_FILE);
        replace_file(&path, text.as_bytes()).map_err(io_err(&path))?;
        self.rewrites.wrote(self.steps.len(), t.elapsed());
        Ok(())
    }

    /// The final results.json. If it cannot be written (a full disk), a short one with the
    /// status and without the step list (every converged step is in `steps.jsonl`) is tried
    /// before giving up, so that the status does not stay `"running"`; the error is returned
    /// either way.
    fn write_final(&mut self, status: &str, attempts: &[StepRecord]) -> Result<(), OutputError> {
        let path = self.dir.join(RESULTS_FILE);
        let text = self.results_text(status, Some(attempts))?;
        let Err(e) = replace_file(&path, text.as_bytes()) else {
            return Ok(());
        };
        let mut short = self.header_json(&format!("{status}; results.json: {e}"));
        short.insert("steps_file".into(), json!(STEPS_LOG_FILE));
        short.insert("steps".into(), json!([]));
        let _ = serde_json::to_string_pretty(&Value::Object(short))
            .map(|t| replace_file(&path, t.as_bytes()));
        Err(io_err(&path)(e))
    }

    /// One panel per monitor, from the unloaded state, a marker per converged step: the load
    /// (under displacement control, the reaction of the first `prescribed` entry; otherwise the
    /// load factor) against the monitor's displacement along its `direction`, or against its
    /// three components. With a direction, the steps after critical points
    /// ([`Self::set_critical_points`]) are marked again, one series per group of kinds.
    fn plot(&self, path: &Path) -> Result<(), OutputError> {
        use super::plot::{figure, Panel, Scale, Series, Style};
        let sign = self
            .displacement_control
            .filter(|_| self.steps.first().is_some_and(|s| !s.reactions.is_empty()));
        let load = |s: &StepSummary| match sign {
            Some(g) => g * s.reactions[0].1,
            None => s.load_factor,
        };
        let y_label = match sign {
            Some(_) => format!(
                "load at {} (reaction along the prescribed motion)",
                self.steps[0].reactions[0].0
            ),
            None => "load factor".to_string(),
        };
        let titles: Vec<String> = self
            .monitors
            .iter()
            .map(|m| format!("monitor {} at (u, v) = ({}, {})", m.name, m.at[0], m.at[1]))
            .collect();
        let labels: Vec<String> = self
            .directions
            .iter()
            .map(|d| match d {
                Some(d) => format!("u · ({:.3}, {:.3}, {:.3})", d[0], d[1], d[2]),
                None => String::new(),
            })
            .collect();
        let panels: Vec<Panel> = (0..self.monitors.len())
            .map(|k| {
                let direction = self.directions.get(k).copied().flatten();
                let series = match direction {
                    Some(d) => {
                        let at = |s: &StepSummary| (dot3(&s.monitors[k], &d), load(s));
                        let mut series = vec![Series {
                            label: &labels[k],
                            points: std::iter::once((0.0, 0.0))
                                .chain(self.steps.iter().map(at))
                                .collect(),
                            style: Style::Dots,
                        }];
                        for (label, kinds) in CRITICAL_GROUPS {
                            let points: Vec<(f64, f64)> = self
                                .critical
                                .iter()
                                .filter(|(kind, _)| kinds.contains(kind))
                                .filter_map(|(_, step)| self.steps.iter().find(|s| s.step == *step))
                                .map(at)
                                .collect();
                            if !points.is_empty() {
                                series.push(Series {
                                    label,
                                    points,
                                    style: Style::Rings,
                                });
                            }
                        }
                        series
                    }
                    None => ["ux", "uy", "uz"]
                        .iter()
                        .enumerate()
                        .map(|(c, label)| Series {
                            label,
                            points: std::iter::once((0.0, 0.0))
                                .chain(self.steps.iter().map(|s| (s.monitors[k][c], load(s))))
                                .collect(),
                            style: Style::Dots,
                        })
                        .collect(),
                };
                Panel {
                    title: &titles[k],
                    x_label: "displacement",
                    y_label: &y_label,
                    x_scale: Scale::Linear,
                    y_scale: Scale::Linear,
                    series,
                }
            })
            .collect();
        let height = 420 * panels.len() as u32;
        figure(path, 900, height, &panels).map_err(OutputError::Plot)
    }
}
