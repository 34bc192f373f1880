//! A shell case as a design sensitivity study: its analysis for any design
//! ([`CaseAnalysis`], the study's [`Analysis`]), its nominal design, and the checks of a
//! `shelldsa dsa` run before any analysis (the loads the sensitivity methods carry, load
//! control, the design variables' tools).

use super::dsa_case::{check_tool_names, invalid, DsaMethod, DsaSpec};
use super::shell_build;
use super::shell_case::ShellCase;
use super::CaseError;
use crate::sensitivity::dual::SensitivityError;
use crate::sensitivity::fd::Analysis;
use crate::sensitivity::Design;
use crate::shell::problem::ShellProblem;
use crate::solver::NewtonSolver;

/// Rejects, before any analysis, a case on an arc-length path (`[steps] control =
/// "arc-length"`): the sensitivity methods differentiate at fixed load levels (and their
/// finite-difference re-runs compare equal levels), which an arc-length path does not have
/// (`docs/sensitivity.md`).
pub fn check_load_control(case: &ShellCase) -> Result<(), CaseError> {
    if case.steps.arc_length.is_some() {
        return Err(invalid(
            &case.path,
            "steps.control",
            "\"arc-length\"",
            "\"load\" for shelldsa dsa (design derivatives are computed at fixed load \
             factors; on an arc-length path the load factor is an unknown of every step)",
        ));
    }
    Ok(())
}

/// The case's analysis for any design ([`Analysis`]): the case with the design's thickness,
/// material, surface and tool placements.
pub struct CaseAnalysis<'a> {
    /// The case.
    pub case: &'a ShellCase,
}

impl Analysis for CaseAnalysis<'_> {
    fn solver(&self) -> crate::solver::SolverOptions {
        crate::solver::SolverOptions {
            preconditioner: self.case.steps.preconditioner,
            ..Default::default()
        }
    }
    /// The case with the design's thickness, material, surface and tool offsets (each tool's
    /// whole path translated, [`crate::contact::ToolPath::translated`], the tool as built
    /// rotated about its pivot, [`crate::contact::ToolPath::rotated`], and reshaped,
    /// [`crate::contact::RigidTool::reshaped`]).
    fn build(&self, design: &Design) -> Result<(ShellProblem, NewtonSolver), SensitivityError> {
        let mut c = self.case.clone();
        c.thickness = design.thickness;
        c.material = design.material;
        if let Some(surface) = &design.surface {
            // A shape design: the same case on the perturbed surface (the discretisation,
            // boundaries, loads and monitors live on the parameter domain and stay).
            c.surface = surface.clone();
        }
        for (name, offset) in &design.tool_offsets {
            let tool = c
                .tools
                .iter_mut()
                .find(|t| &t.name == name)
                .ok_or_else(|| {
                    SensitivityError::Design(crate::sensitivity::DesignError::UnknownTool {
                        variable: name.clone(),
                        tool: name.clone(),
                        expected: format!(
                            "{:?}",
                            self.case.tools.iter().map(|t| &t.name).collect::<Vec<_>>()
                        ),
                    })
                })?;
            tool.path = tool
                .path
                .translated(offset.translation)
                .and_then(|p| p.rotated(offset.rotation))
                .map_err(|e| SensitivityError::Build {
                    context: format!(
                        "tool `{name}` moved by {:?} and rotated by {:?}",
                        offset.translation, offset.rotation
                    ),
                    source: Box::new(e),
                })?;
            if !offset.shape.is_empty() {
                let shape: Vec<(usize, f64)> = offset.shape.iter().map(|(&k, &d)| (k, d)).collect();
                *tool = tool.reshaped(&shape).map_err(|e| SensitivityError::Build {
                    context: format!("tool `{name}` reshaped by {shape:?}"),
                    source: Box::new(e),
                })?;
            }
        }
        let b = shell_build::build(&c)
            .and_then(|b| shell_build::tools_clear_of_the_sheet(&b).map(|()| b))
            .map_err(|e| SensitivityError::Build {
                context: self.case.path.display().to_string(),
                source: Box::new(e),
            })?;
        Ok((b.problem, b.newton))
    }
}

/// The case's nominal design: thickness, material and surface.
pub fn base_design(case: &ShellCase) -> Design {
    Design {
        thickness: case.thickness,
        material: case.material,
        surface: Some(case.surface.clone()),
        tool_offsets: Default::default(),
    }
}

/// Check everything a `dsa` run of `case` with `methods` needs before any analysis, as far as
/// the case tells: design variables present and naming the case's tools, load control (the
/// study checks the variables and loads on the built model,
/// [`check_design`](crate::sensitivity::check_design)).
pub fn validate(case: &ShellCase, methods: &[DsaMethod]) -> Result<DsaSpec, CaseError> {
    let mut spec = case.dsa.clone().ok_or_else(|| CaseError::NoDesign {
        path: case.path.clone(),
    })?;
    spec.methods = methods.to_vec();
    check_load_control(case)?;
    check_tool_names(&case.path, &case.tools, &spec)?;
    Ok(spec)
}
