//! External loads on the shell, at load factor 1 (the driver scales them by λ).
//!
//! A load adds its generalised force `f_ext(q)` (5 components per particle: forces on `Δū_I`,
//! moments on `α_I`) for the increment `q` from the committed state. Configuration-dependent
//! loads (pressure following the surface, a moment about the current director) also add their
//! load stiffness `∂f_ext/∂q`; the problem's tangent is then `K − λ ∂f_ext/∂q`.

use super::model::ShellModel;
use super::ShellError;
use crate::meshfree::ShapeValues;
use std::fmt::Debug;

/// An external load.
pub trait ExternalLoad: Send + Sync + Debug {
    /// Add `factor · f_ext(q)` into `f` (global generalised DOFs; `q` is the generalised
    /// increment from the committed state).
    fn add_force(
        &self,
        model: &ShellModel,
        q: &[f64],
        factor: f64,
        f: &mut [f64],
    ) -> Result<(), ShellError>;
    /// Whether `f_ext` depends on the configuration (then [`ExternalLoad::add_stiffness`] is
    /// not empty).
    fn is_follower(&self) -> bool {
        false
    }
    /// Add `factor · ∂f_ext/∂q` as global `(row, column, value)` entries (default: a dead load).
    fn add_stiffness(
        &self,
        _model: &ShellModel,
        _q: &[f64],
        _factor: f64,
        _out: &mut Vec<(usize, usize, f64)>,
    ) -> Result<(), ShellError> {
        Ok(())
    }
}

/// A dead point force `P` at parameter coordinates `uv` (a point of the mid-surface),
/// distributed to the coefficients by the shape functions: `f_I = Ψ_I(ξ_P) P`.
#[derive(Clone, Debug, PartialEq)]
pub struct PointForce {
    /// Parameter coordinates of the load point.
    pub uv: [f64; 2],
    /// Force vector (global axes).
    pub force: [f64; 3],
}

impl ExternalLoad for PointForce {
    fn add_force(
        &self,
        model: &ShellModel,
        _q: &[f64],
        factor: f64,
        f: &mut [f64],
    ) -> Result<(), ShellError> {
        let mut sv = ShapeValues::new();
        model
            .shape_functions
            .evaluate(self.uv, &mut sv)
            .map_err(|e| ShellError::InvalidInput(format!("point force at {:?}: {e}", self.uv)))?;
        for (j, psi, _) in sv.iter() {
            let l = [
                psi * self.force[0] * factor,
                psi * self.force[1] * factor,
                psi * self.force[2] * factor,
                0.0,
                0.0,
            ];
            model.scatter_particle(j, &l, f);
        }
        Ok(())
    }
}
