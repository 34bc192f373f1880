//! Design variables in a shell case file: the `[[design]]` tables and the optional `[dsa]`
//! table (`docs/case-format.md` §"Design sensitivity").
//!
//! ```toml
//! [[design]]
//! name = "t"                      # unique, non-empty
//! kind = "thickness"              # or "material.young" | "material.poisson" | "material.sigma0"
//!                                 #    | "material.hardening" | "material.beta" | "material.shear_factor"
//!                                 #    | "shape.<surface parameter>" ("shape.radius", "shape.cp[2][3].z")
//!                                 #    | "tool.<name>.<x|y|z>" (translation of a tool's path)
//!                                 #    | "tool.<name>.<rx|ry|rz>" (rotation of the tool as built
//!                                 #      about its pivot, radians)
//! fd_steps = [1e-3, 1e-4]         # relative steps h/|τ| of the finite-difference study
//!                                 # (absolute lengths or angles for a tool variable, whose τ is 0)
//!
//! [dsa]
//! methods = ["continuum", "dual", "fd"]   # default: all three
//! monitors = ["A.ux", "B"]        # `<monitor>.<ux|uy|uz>` or `<monitor>` (all three),
//!                                 # `tool.<name>.<fx|fy|fz>` or `tool.<name>` (the force the
//!                                 # sheet exerts on a tool: the punch force);
//!                                 # default: every [[monitor]], all three components
//!
//! [[dsa.angle]]                   # a chord angle (degrees) in the plane of two global axes:
//! name = "flange"                 # atan2(Δ_j, Δ_i), Δ = x(to) − x(from) in the current state
//! from = [0.8, 0.0]               # parameter coordinates
//! to = [1.0, 0.0]
//! plane = ["x", "z"]
//!
//! [[dsa.distance]]                # mean squared distance (1/n) Σ |x_k − x*_k|² of sheet
//! name = "shape"                  # points from targets (least squares)
//! at = [[0.5, 0.0], [1.0, 0.0]]   # parameter coordinates
//! target = [[0.0, 0.0, -20.0], [30.0, 0.0, -5.0]]
//!
//! [[dsa.plastic]]                 # smooth maximum (1/ρ) ln((1/N) Σ exp(ρ ē^p_k)) of the
//! name = "peak strain"            # equivalent plastic strain over the layer points of a
//! region = [[0.0, 0.2], [0.0, 1.0]]   # parameter box [[u_min, u_max], [v_min, v_max]]
//! layers = "top"                  # "all" (default), "top" or "bottom"
//! rho = 500.0                     # > 0: below the maximum by at most ln(N)/ρ
//!
//! [[dsa.thinning]]                # smooth maximum of the thinning strain ln(da/dA) of the
//! name = "peak thinning"          # mid-surface (the negative thickness strain under plastic
//! region = [[0.0, 0.2], [0.0, 1.0]]   # incompressibility) over the quadrature points of a box
//! rho = 500.0
//! ```
//!
//! Everything is checked here, before any analysis: each wrong key is a
//! [`CaseError::Invalid`] naming the dotted key (`design[1].kind`, `dsa.monitors[0]`), the
//! value and the expectation; every `±h` of the finite-difference study must give an
//! admissible design ([`DesignVariable::perturbed`]: `t ± h > 0`, material parameters in their
//! ranges).

use super::{fmt_num, CaseError, Monitor as CaseMonitor};
use crate::contact::RigidTool;
use crate::geometry::Surface;
use crate::material::MaterialParams;
pub use crate::sensitivity::study::{DesignEntry, DsaMethod, DsaSpec};
use crate::sensitivity::{
    Design, DesignKind, DesignScope, DesignVariable, Layers, Monitor, Quantity,
};
use serde::Deserialize;
use std::path::Path;

/// Default relative finite-difference steps `h/|τ|`: 1e-3 and 1e-4 (truncation error of the
/// central difference ~1e-6 and ~1e-8 of the response's curvature scale, both far above the
/// ~1e-14 noise of converged re-runs; `docs/sensitivity.md` §4).
pub const DEFAULT_FD_STEPS: [f64; 2] = [1e-3, 1e-4];

/// The displacement components a sensitivity monitor can name.
pub const COMPONENT_NAMES: [&str; 3] = ["ux", "uy", "uz"];

/// The force components a tool-force monitor (`tool.<name>.<fx|fy|fz>`) can name.
pub const FORCE_NAMES: [&str; 3] = ["fx", "fy", "fz"];

/// One `[[design]]` table as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct DesignFile {
    name: String,
    kind: String,
    #[serde(default)]
    fd_steps: Option<Vec<f64>>,
}

/// The `[dsa]` table as written.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct DsaFile {
    #[serde(default)]
    methods: Option<Vec<String>>,
    #[serde(default)]
    monitors: Option<Vec<String>>,
    #[serde(default)]
    angle: Vec<AngleFile>,
    #[serde(default)]
    distance: Vec<DistanceFile>,
    #[serde(default)]
    plastic: Vec<PlasticFile>,
    #[serde(default)]
    thinning: Vec<ThinningFile>,
}

/// One `[[dsa.thinning]]` table as written: a smooth maximum of the thinning strain over a
/// region.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct ThinningFile {
    name: String,
    region: [[f64; 2]; 2],
    rho: f64,
}

/// One `[[dsa.plastic]]` table as written: a smooth maximum of `ē^p` over a region.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct PlasticFile {
    name: String,
    region: [[f64; 2]; 2],
    #[serde(default)]
    layers: Option<String>,
    rho: f64,
}

/// One `[[dsa.angle]]` table as written: a chord angle response.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct AngleFile {
    name: String,
    from: [f64; 2],
    to: [f64; 2],
    plane: [String; 2],
}

/// One `[[dsa.distance]]` table as written: the mean squared distance of points from targets.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct DistanceFile {
    name: String,
    at: Vec<[f64; 2]>,
    target: Vec<[f64; 3]>,
}

/// A [`CaseError::Invalid`] of the case file `path`.
pub(super) fn invalid(
    path: &Path,
    key: impl Into<String>,
    value: impl Into<String>,
    expected: impl Into<String>,
) -> CaseError {
    CaseError::Invalid {
        path: path.into(),
        key: key.into(),
        value: value.into(),
        expected: expected.into(),
    }
}

fn fmt_list(a: &[f64]) -> String {
    let parts: Vec<String> = a.iter().map(|v| format!("{v}")).collect();
    format!("[{}]", parts.join(", "))
}

/// Parse a list of method names (`--methods dual,fd` or `[dsa] methods`): at least one, no
/// repeats.
pub fn parse_methods(
    names: &[String],
    key: &str,
    path: &Path,
) -> Result<Vec<DsaMethod>, CaseError> {
    if names.is_empty() {
        return Err(invalid(path, key, "[]", "at least one of \"dual\", \"fd\""));
    }
    let mut out = Vec::with_capacity(names.len());
    for (i, n) in names.iter().enumerate() {
        let m = DsaMethod::from_name(n.trim()).ok_or_else(|| {
            invalid(
                path,
                format!("{key}[{i}]"),
                format!("{:?}", n.trim()),
                "\"continuum\", \"dual\" or \"fd\"",
            )
        })?;
        if out.contains(&m) {
            return Err(invalid(
                path,
                format!("{key}[{i}]"),
                format!("{n:?}"),
                "a method not listed before",
            ));
        }
        out.push(m);
    }
    Ok(out)
}

/// The case's geometry the design variables refer to: the sheet's surface (`shape.<…>`) and
/// the tools (`tool.<name>.<…>`), both already checked.
pub(crate) struct CaseGeometry<'a> {
    /// The sheet's mid-surface.
    pub surface: &'a Surface<f64>,
    /// The rigid tools.
    pub tools: &'a [RigidTool],
}

/// Check the `[[design]]` and `[dsa]` tables of a case (`None` when there are no `[[design]]`
/// tables; a `[dsa]` table without them is an error). `thickness`, `material`, `monitors` and
/// `geometry` are the case's, already checked.
pub(crate) fn check(
    path: &Path,
    design: Vec<DesignFile>,
    dsa: Option<DsaFile>,
    thickness: f64,
    material: &MaterialParams<f64>,
    monitors: &[CaseMonitor],
    geometry: &CaseGeometry<'_>,
) -> Result<Option<DsaSpec>, CaseError> {
    let (surface, tools) = (geometry.surface, geometry.tools);
    if design.is_empty() {
        return match dsa {
            Some(_) => Err(invalid(
                path,
                "dsa",
                "(table)",
                "at least one [[design]] table alongside [dsa]",
            )),
            None => Ok(None),
        };
    }
    let base = Design {
        thickness,
        material: *material,
        surface: Some(surface.clone()),
        tool_offsets: Default::default(),
    };
    // Size of the sheet's coordinates (largest |x_i| at the corners and the middle of the
    // parameter box), against which a tool's absolute step must not vanish.
    let coordinate_scale = {
        let d = surface.domain();
        let mut m: f64 = 0.0;
        for u in [d[0][0], 0.5 * (d[0][0] + d[0][1]), d[0][1]] {
            for v in [d[1][0], 0.5 * (d[1][0] + d[1][1]), d[1][1]] {
                m = m.max(surface.eval(u, v).x.amax());
            }
        }
        m
    };
    let mut entries: Vec<DesignEntry> = Vec::with_capacity(design.len());
    for (k, d) in design.iter().enumerate() {
        let key = format!("design[{k}]");
        if !super::is_name(&d.name) {
            return Err(invalid(
                path,
                format!("{key}.name"),
                format!("{:?}", d.name),
                super::NAME_EXPECTED,
            ));
        }
        if let Some(j) = entries.iter().position(|e| e.variable.name == d.name) {
            return Err(invalid(
                path,
                format!("{key}.name"),
                format!("{:?}", d.name),
                format!("a name not used by an earlier design variable (design[{j}])"),
            ));
        }
        let kind = design_kind(path, &format!("{key}.kind"), &d.kind, surface, tools)?;
        if let Some(j) = entries.iter().position(|e| e.variable.kind == kind) {
            return Err(invalid(
                path,
                format!("{key}.kind"),
                format!("{:?}", d.kind),
                format!(
                    "a kind not used by an earlier design variable (design[{j}] `{}`)",
                    entries[j].variable.name
                ),
            ));
        }
        let is_tool = kind.is_offset();
        let variable = DesignVariable::new(d.name.clone(), kind);
        check_tool_name(path, k, &variable, tools)?;
        let fd_steps = d
            .fd_steps
            .clone()
            .unwrap_or_else(|| DEFAULT_FD_STEPS.to_vec());
        let steps_key = format!("{key}.fd_steps");
        if fd_steps.is_empty() {
            return Err(invalid(
                path,
                &steps_key,
                "[]",
                "at least one relative step h/|τ| > 0",
            ));
        }
        for (i, &r) in fd_steps.iter().enumerate() {
            if !(r > 0.0 && r.is_finite()) {
                return Err(invalid(
                    path,
                    format!("{steps_key}[{i}]"),
                    fmt_num(r),
                    "a finite relative step h/|τ| > 0",
                ));
            }
            if fd_steps[..i].contains(&r) {
                return Err(invalid(
                    path,
                    format!("{steps_key}[{i}]"),
                    fmt_num(r),
                    "a step not listed before",
                ));
            }
        }
        let tau = variable.value(&base);
        if tau == 0.0 && !is_tool {
            return Err(invalid(
                path,
                &steps_key,
                fmt_list(&fd_steps),
                format!(
                    "a variable with a non-zero value: `{}` = 0, so relative steps h/|τ| give \
                     h = 0",
                    d.kind
                ),
            ));
        }
        for (i, &r) in fd_steps.iter().enumerate() {
            let h = if is_tool { r } else { r * tau.abs() };
            // The perturbed value must differ from the nominal one in floating point: a step
            // that vanishes against τ (or, for a tool offset, against the coordinates it
            // moves) gives a difference of 0 and a meaningless central difference.
            let tool_parameter = match &variable.kind {
                DesignKind::ToolShape {
                    tool, parameter, ..
                } => tools
                    .iter()
                    .find(|t| &t.name == tool)
                    .and_then(|t| t.surface.parameter_values().get(*parameter).copied()),
                _ => None,
            };
            let (value, what) = if let Some(p) = tool_parameter {
                (p, "the tool's surface parameter")
            } else if is_tool {
                (coordinate_scale, "the sheet's coordinates")
            } else {
                (tau, "the variable's value")
            };
            if !(h >= f64::MIN_POSITIVE && value + h != value && value - h != value) {
                return Err(invalid(
                    path,
                    format!("{steps_key}[{i}]"),
                    fmt_num(r),
                    format!(
                        "a step h = {h:e} that changes {what} ({value:e}) in floating point \
                         (τ ± h ≠ τ; relative steps above ~1e-12 keep the difference above \
                         round-off)"
                    ),
                ));
            }
            let scope = DesignScope {
                base: Some(&base),
                model: None,
                tools: Some(tools),
            };
            variable.check(&[h, -h], &scope).map_err(|e| {
                invalid(
                    path,
                    format!("{steps_key}[{i}]"),
                    fmt_num(r),
                    format!("a step that keeps the design admissible: {e}"),
                )
            })?;
        }
        entries.push(DesignEntry { variable, fd_steps });
    }

    let dsa = dsa.unwrap_or_default();
    let methods = match &dsa.methods {
        Some(m) => parse_methods(m, "dsa.methods", path)?,
        None => vec![DsaMethod::Continuum, DsaMethod::Dual, DsaMethod::Fd],
    };
    let sel = match &dsa.monitors {
        Some(m) => {
            if m.is_empty() {
                return Err(invalid(
                    path,
                    "dsa.monitors",
                    "[]",
                    "at least one `<monitor>` or `<monitor>.<ux|uy|uz>`",
                ));
            }
            let mut out: Vec<Monitor> = Vec::new();
            for (i, s) in m.iter().enumerate() {
                let key = format!("dsa.monitors[{i}]");
                for mon in monitor_selection(path, &key, s, monitors)? {
                    if out.iter().any(|o| o.label == mon.label) {
                        return Err(invalid(
                            path,
                            &key,
                            format!("{s:?}"),
                            format!("a component not selected before (`{}` is)", mon.label),
                        ));
                    }
                    out.push(mon);
                }
            }
            out
        }
        None => {
            if monitors.is_empty() {
                return Err(invalid(
                    path,
                    "monitor",
                    "(none)",
                    "at least one [[monitor]]: the design sensitivities are those of the \
                     monitored displacements",
                ));
            }
            let mut out = Vec::new();
            for m in monitors {
                for (c, n) in COMPONENT_NAMES.iter().enumerate() {
                    out.push(sens_monitor(path, "monitor", m, c, n)?);
                }
            }
            out
        }
    };
    let mut sel = sel;
    let functionals = position_functionals(path, &dsa, surface)?;
    if functionals
        .iter()
        .any(|m| m.quantity.reads_initial_geometry())
    {
        if let Some((k, e)) = entries
            .iter()
            .enumerate()
            .find(|(_, e)| matches!(e.variable.kind, DesignKind::Shape { .. }))
        {
            return Err(invalid(
                path,
                format!("design[{k}].kind"),
                format!("{:?}", e.variable.kind.key()),
                "a thickness, material or tool variable with [[dsa.angle]], [[dsa.distance]] or \
                 [[dsa.thinning]] responses (the initial geometry they read would move with a \
                 shape variable, whose design velocity these responses do not carry)",
            ));
        }
    }
    for m in functionals {
        if sel.iter().any(|o| o.label == m.label) {
            return Err(invalid(
                path,
                "dsa",
                format!("{:?}", m.label),
                "response names not used by another monitored component",
            ));
        }
        sel.push(m);
    }
    Ok(Some(DsaSpec {
        design: entries,
        methods,
        monitors: sel,
    }))
}

/// The `[[dsa.angle]]`, `[[dsa.plastic]]`, `[[dsa.thinning]]` and `[[dsa.distance]]`
/// responses, checked (angles and distances with their points' initial positions on
/// `surface`).
fn position_functionals(
    path: &Path,
    dsa: &DsaFile,
    surface: &Surface<f64>,
) -> Result<Vec<Monitor>, CaseError> {
    let dom = surface.domain();
    let named = |key: &str, name: &str| -> Result<(), CaseError> {
        if super::is_name(name) {
            Ok(())
        } else {
            Err(invalid(
                path,
                format!("{key}.name"),
                format!("{name:?}"),
                super::NAME_EXPECTED,
            ))
        }
    };
    let at = |key: &str, uv: [f64; 2]| -> Result<[f64; 3], CaseError> {
        let inside = (0..2).all(|k| uv[k] >= dom[k][0] && uv[k] <= dom[k][1]);
        if !inside {
            return Err(invalid(
                path,
                key,
                fmt_list(&uv),
                format!("parameter coordinates in the surface's domain {dom:?}"),
            ));
        }
        Ok(surface.eval(uv[0], uv[1]).x.into())
    };
    let axis = |key: &str, a: &str| -> Result<usize, CaseError> {
        ["x", "y", "z"]
            .iter()
            .position(|n| *n == a)
            .ok_or_else(|| invalid(path, key, format!("{a:?}"), "\"x\", \"y\" or \"z\""))
    };
    let aggregate = |key: &str, region: [[f64; 2]; 2], rho: f64| -> Result<(), CaseError> {
        for (a, r) in region.iter().enumerate() {
            let inside = r[0] <= r[1] && r[0] <= dom[a][1] && r[1] >= dom[a][0];
            if !inside || !r.iter().all(|v| v.is_finite()) {
                return Err(invalid(
                    path,
                    format!("{key}.region[{a}]"),
                    fmt_list(r),
                    format!(
                        "a range [min, max] overlapping the surface's domain {:?}",
                        dom[a]
                    ),
                ));
            }
        }
        if !(rho.is_finite() && rho > 0.0) {
            return Err(invalid(
                path,
                format!("{key}.rho"),
                format!("{rho}"),
                "a finite aggregation parameter > 0 (1/strain; the smooth maximum lies below \
                 the maximum by at most ln(N)/rho)",
            ));
        }
        Ok(())
    };
    let mut out = Vec::new();
    for (k, a) in dsa.angle.iter().enumerate() {
        let key = format!("dsa.angle[{k}]");
        named(&key, &a.name)?;
        let initial = [
            at(&format!("{key}.from"), a.from)?,
            at(&format!("{key}.to"), a.to)?,
        ];
        let plane = [
            axis(&format!("{key}.plane[0]"), &a.plane[0])?,
            axis(&format!("{key}.plane[1]"), &a.plane[1])?,
        ];
        out.push(
            Monitor::chord_angle(a.name.clone(), [a.from, a.to], initial, plane)
                .map_err(|e| invalid(path, &key, format!("{:?}", a.name), e.to_string()))?,
        );
    }
    for (k, pl) in dsa.plastic.iter().enumerate() {
        let key = format!("dsa.plastic[{k}]");
        named(&key, &pl.name)?;
        let layers = match pl.layers.as_deref() {
            None | Some("all") => Layers::All,
            Some("top") => Layers::Top,
            Some("bottom") => Layers::Bottom,
            Some(other) => {
                return Err(invalid(
                    path,
                    format!("{key}.layers"),
                    format!("{other:?}"),
                    "\"all\", \"top\" or \"bottom\"",
                ))
            }
        };
        aggregate(&key, pl.region, pl.rho)?;
        out.push(
            Monitor::plastic_strain(pl.name.clone(), pl.region, layers, pl.rho)
                .map_err(|e| invalid(path, &key, format!("{:?}", pl.name), e.to_string()))?,
        );
    }
    for (k, th) in dsa.thinning.iter().enumerate() {
        let key = format!("dsa.thinning[{k}]");
        named(&key, &th.name)?;
        aggregate(&key, th.region, th.rho)?;
        out.push(
            Monitor::thinning(th.name.clone(), th.region, th.rho)
                .map_err(|e| invalid(path, &key, format!("{:?}", th.name), e.to_string()))?,
        );
    }
    for (k, d) in dsa.distance.iter().enumerate() {
        let key = format!("dsa.distance[{k}]");
        named(&key, &d.name)?;
        let initial =
            d.at.iter()
                .enumerate()
                .map(|(i, uv)| at(&format!("{key}.at[{i}]"), *uv))
                .collect::<Result<Vec<_>, _>>()?;
        out.push(
            Monitor::target_distance(d.name.clone(), d.at.clone(), initial, d.target.clone())
                .map_err(|e| invalid(path, &key, format!("{:?}", d.name), e.to_string()))?,
        );
    }
    Ok(out)
}

fn sens_monitor(
    path: &Path,
    key: &str,
    m: &CaseMonitor,
    component: usize,
    cname: &str,
) -> Result<Monitor, CaseError> {
    Monitor::new(format!("{}.{cname}", m.name), m.at, component)
        .map_err(|e| invalid(path, key, format!("{:?}", m.name), e.to_string()))
}

fn monitor_selection(
    path: &Path,
    key: &str,
    s: &str,
    monitors: &[CaseMonitor],
) -> Result<Vec<Monitor>, CaseError> {
    let names: Vec<&str> = monitors.iter().map(|m| m.name.as_str()).collect();
    let find = |n: &str| {
        monitors.iter().find(|m| m.name == n).ok_or_else(|| {
            invalid(
                path,
                key,
                format!("{s:?}"),
                format!(
                    "`<monitor>` or `<monitor>.<ux|uy|uz>` with <monitor> one of the \
                     [[monitor]] names {names:?}"
                ),
            )
        })
    };
    // A monitor's own name may contain a dot: the whole string is tried first.
    if let Ok(m) = find(s) {
        return COMPONENT_NAMES
            .iter()
            .enumerate()
            .map(|(c, n)| sens_monitor(path, key, m, c, n))
            .collect();
    }
    // The force on a tool: `tool.<name>.<fx|fy|fz>` or `tool.<name>` (all three).
    if let Some(rest) = s.strip_prefix("tool.") {
        let (name, comps) = match rest.rsplit_once('.') {
            Some((name, comp)) if FORCE_NAMES.contains(&comp) => (name, vec![comp]),
            _ => (rest, FORCE_NAMES.to_vec()),
        };
        if name.is_empty() {
            return Err(invalid(
                path,
                key,
                format!("{s:?}"),
                "`tool.<name>` or `tool.<name>.<fx|fy|fz>` with a tool of the case",
            ));
        }
        return comps
            .into_iter()
            .map(|comp| {
                let c = FORCE_NAMES.iter().position(|n| *n == comp).unwrap_or(0);
                Monitor::tool_force(format!("tool.{name}.{comp}"), name, c)
                    .map_err(|e| invalid(path, key, format!("{s:?}"), e.to_string()))
            })
            .collect();
    }
    let Some((name, comp)) = s.rsplit_once('.') else {
        return find(s).map(|_| Vec::new());
    };
    let m = find(name)?;
    let c = COMPONENT_NAMES
        .iter()
        .position(|n| *n == comp)
        .ok_or_else(|| {
            invalid(
                path,
                key,
                format!("{s:?}"),
                format!("a component of {COMPONENT_NAMES:?} after `{name}.`"),
            )
        })?;
    Ok(vec![sens_monitor(path, key, m, c, comp)?])
}

fn design_kind(
    path: &Path,
    key: &str,
    s: &str,
    surface: &Surface<f64>,
    tools: &[RigidTool],
) -> Result<DesignKind, CaseError> {
    const EXPECTED: &str = "\"thickness\", \"material.<young|poisson|shear_factor|sigma0|\
                            hardening|beta>\", \"shape.<surface parameter>\", \
                            \"tool.<name>.<x|y|z|rx|ry|rz>\" or \
                            \"tool.<name>.shape.<tool surface parameter>\"";
    DesignKind::parse_with_tools(s, surface, tools)
        .map_err(|e| invalid(path, key, format!("{s:?}"), format!("{EXPECTED} ({e})")))
}

/// Check that the design variable `design[k]` names a tool of the case's `tools` if it is a
/// tool variable ([`DesignVariable::check`]): a [`CaseError::Invalid`] at `design[k].kind`
/// listing the tools otherwise.
fn check_tool_name(
    path: &Path,
    k: usize,
    variable: &DesignVariable,
    tools: &[RigidTool],
) -> Result<(), CaseError> {
    let scope = DesignScope {
        tools: Some(tools),
        ..DesignScope::default()
    };
    variable.check(&[], &scope).map_err(|err| {
        let names: Vec<&str> = tools.iter().map(|t| t.name.as_str()).collect();
        invalid(
            path,
            format!("design[{k}].kind"),
            format!("{:?}", variable.kind.key()),
            format!("a tool of the case's [[tool]] tables {names:?} ({err})"),
        )
    })
}

/// Check that every tool variable and every tool-force monitor of `spec` names one of the
/// case's `tools`: a [`CaseError::Invalid`] at its key listing the tools otherwise.
pub fn check_tool_names(path: &Path, tools: &[RigidTool], spec: &DsaSpec) -> Result<(), CaseError> {
    let names: Vec<&str> = tools.iter().map(|t| t.name.as_str()).collect();
    for (k, e) in spec.design.iter().enumerate() {
        check_tool_name(path, k, &e.variable, tools)?;
    }
    for m in &spec.monitors {
        if let Quantity::ToolForce { tool, .. } = &m.quantity {
            if !names.contains(&tool.as_str()) {
                return Err(invalid(
                    path,
                    "dsa.monitors",
                    format!("{:?}", m.label),
                    format!("the force on a tool of the case's [[tool]] tables {names:?}"),
                ));
            }
        }
    }
    Ok(())
}
