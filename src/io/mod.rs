//! Case files in, results out. Nothing numerical here.
//!
//! A case file is TOML; its `[problem] kind` selects the problem type:
//! - `kind = "material-path"`: the three-way design-sensitivity check of a material point driven
//!   along a strain path (see `verification/material-point-path/case.toml` for an annotated
//!   example);
//! - `kind = "shell"`: a whole shell problem ([`shell_case`]; format in `docs/case-format.md`),
//!   assembled by [`shell_build`] and written by [`shell_output`].

pub mod dsa_case;
pub mod dsa_output;
pub mod dsa_plots;
pub mod dsa_study;
pub mod plot;
pub mod shell_build;
pub mod shell_case;
pub mod shell_output;
pub mod vtu;

use crate::material::{MaterialError, MaterialParams, Vec5};
use crate::verification::material_path::MaterialPath;
use serde::{Deserialize, Deserializer};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Errors reading a case file. Each names the file, the key and what was expected.
#[derive(Debug, Error)]
pub enum CaseError {
    /// The file could not be read.
    #[error("cannot read case file {path}: {source}")]
    Read {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// TOML syntax error, unknown key or wrong type (the message names key, line and column).
    #[error("case file {path}: {message}")]
    Parse {
        /// File.
        path: PathBuf,
        /// Parser message.
        message: String,
    },
    /// The `[surface]` table describes no valid surface (the geometry error names the field,
    /// its value and what was expected).
    #[error("case file {path}: `surface`: {source}")]
    Surface {
        /// File.
        path: PathBuf,
        /// Cause.
        source: crate::geometry::GeometryError,
    },
    /// `shelldsa dsa` on a case without design variables.
    #[error(
        "case file {path}: no [[design]] table: `shelldsa dsa` needs at least one design variable"
    )]
    NoDesign {
        /// File.
        path: PathBuf,
    },
    /// A value outside its admissible range.
    #[error("case file {path}: `{key}` = {value} is invalid: expected {expected}")]
    Invalid {
        /// File.
        path: PathBuf,
        /// Dotted key.
        key: String,
        /// Value as written.
        value: String,
        /// What was expected.
        expected: String,
    },
}

/// A named point whose displacement is recorded at every converged step.
#[derive(Clone, Debug, PartialEq)]
pub struct Monitor {
    /// Name (unique).
    pub name: String,
    /// Parameter point.
    pub at: [f64; 2],
}

/// A number as a message shows it: plain between 1e-4 and 1e15, else in exponent form (`{}`
/// writes 1e308 with 309 digits).
pub(crate) fn fmt_num(v: f64) -> String {
    if v == 0.0 || !v.is_finite() || (1e-4..1e15).contains(&v.abs()) {
        v.to_string()
    } else {
        format!("{v:e}")
    }
}

/// A fixed-length array of a case file, of exactly `N` entries. serde's own array support reads
/// the first `N` entries of a longer TOML array and drops the rest without a word, so every
/// fixed-length array of a case file is read through this (the TOML layer then names the key,
/// line and column of a wrong length).
pub(crate) fn exact<'de, D, T, const N: usize>(d: D) -> Result<[T; N], D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    let v: Vec<T> = Vec::deserialize(d)?;
    let n = v.len();
    let expected = format!("an array of exactly {N} entries");
    v.try_into()
        .map_err(|_| <D::Error as serde::de::Error>::invalid_length(n, &expected.as_str()))
}

/// [`exact`] for an optional key (use with `#[serde(default)]`).
pub(crate) fn exact_opt<'de, D, T, const N: usize>(d: D) -> Result<Option<[T; N]>, D::Error>
where
    D: Deserializer<'de>,
    T: Deserialize<'de>,
{
    exact(d).map(Some)
}

/// What a name or title in a case file must be (names are printed on terminals and written
/// into CSV headers, JSON and XML).
pub const NAME_EXPECTED: &str = "a non-empty name without control characters";

/// A name or title of a case file: not blank, no control character (a terminal escape, a
/// line break, a tab).
pub fn is_name(text: &str) -> bool {
    !text.trim().is_empty() && !text.chars().any(char::is_control)
}

/// `[problem]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ProblemSpec {
    #[allow(dead_code)] // dispatched on before this struct is parsed
    kind: String,
    #[serde(default)]
    title: Option<String>,
}

/// `[material]` (all keys required except `shear_factor`, default 5/6).
#[derive(Debug, Deserialize, Clone, Copy)]
#[serde(deny_unknown_fields)]
pub struct MaterialSpec {
    young: f64,
    poisson: f64,
    #[serde(default = "default_shear_factor")]
    shear_factor: f64,
    sigma0: f64,
    hardening: f64,
    beta: f64,
}

fn default_shear_factor() -> f64 {
    5.0 / 6.0
}

/// `[design.material_rate]`: d(parameter)/dτ, all default 0.
#[derive(Debug, Deserialize, Default, Clone, Copy)]
#[serde(deny_unknown_fields)]
struct MaterialRateSpec {
    #[serde(default)]
    young: f64,
    #[serde(default)]
    poisson: f64,
    #[serde(default)]
    shear_factor: f64,
    #[serde(default)]
    sigma0: f64,
    #[serde(default)]
    hardening: f64,
    #[serde(default)]
    beta: f64,
}

/// `[design]`.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DesignSpec {
    #[serde(default = "default_tau_name")]
    name: String,
    #[serde(default)]
    tau: f64,
    #[serde(default = "default_fd_step")]
    fd_step: f64,
    #[serde(default)]
    material_rate: MaterialRateSpec,
}

fn default_tau_name() -> String {
    "tau".into()
}
fn default_fd_step() -> f64 {
    1e-6
}

/// One `[[path.segment]]`: `steps` equal increments.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SegmentSpec {
    steps: i64,
    #[serde(deserialize_with = "exact")]
    increment: [f64; 5],
    #[serde(default, deserialize_with = "exact")]
    rate: [f64; 5],
}

/// `[path]`: either a named generator or explicit segments.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PathSpec {
    #[serde(default)]
    generator: Option<String>,
    #[serde(default)]
    segment: Vec<SegmentSpec>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialPathFile {
    problem: ProblemSpec,
    material: MaterialSpec,
    design: DesignSpec,
    path: PathSpec,
    #[serde(default)]
    check: Option<CheckSpec>,
    #[serde(default)]
    limits: Option<PathLimitsFile>,
}

/// `[limits]` of a material-path case.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PathLimitsFile {
    max_steps: i64,
}

/// Default largest number of steps of a material path (`[limits] max_steps` raises it): about
/// 0.6 kB per step over the analysis, the dual and finite-difference runs and the tables,
/// 60 MB at the limit.
pub const MAX_PATH_STEPS: usize = 100_000;

/// `[check]`: tolerances of the three-way comparison.
#[derive(Debug, Deserialize, Clone, Copy)]
#[serde(deny_unknown_fields)]
pub struct CheckSpec {
    /// Continuum (hand-derived) against dual numbers, relative.
    pub dual_rel: f64,
    /// Continuum against central differences, relative.
    pub fd_rel: f64,
    /// Absolute floor of the FD comparison as a fraction of the largest sensitivity.
    pub fd_floor: f64,
}

impl Default for CheckSpec {
    fn default() -> Self {
        CheckSpec {
            dual_rel: 1e-9,
            fd_rel: 1e-5,
            fd_floor: 1e-4,
        }
    }
}

/// A material-point path case.
#[derive(Debug, Clone)]
pub struct MaterialPathCase {
    /// Title for reports.
    pub title: String,
    /// Design-variable name.
    pub design_name: String,
    /// The path, material and design dependence.
    pub path: MaterialPath,
    /// Finite-difference step on τ.
    pub fd_step: f64,
    /// Tolerances.
    pub check: CheckSpec,
    /// Largest number of path steps accepted (`[limits] max_steps`).
    pub max_steps: usize,
}

/// A parsed case.
#[derive(Debug, Clone)]
pub enum Case {
    /// `kind = "material-path"`.
    MaterialPath(Box<MaterialPathCase>),
    /// `kind = "shell"`.
    Shell(Box<shell_case::ShellCase>),
}

/// Problem kinds this build understands.
pub const KINDS: &[&str] = &["material-path", "shell"];

/// What a checked case will need and any warnings, as lines for `check`, `run` and `dsa` to
/// print before the work (the estimate of [`shell_case::ShellCase::estimate`], or the steps of
/// a material path; warnings start with `warning:`).
pub fn case_report(case: &Case) -> Vec<String> {
    match case {
        Case::MaterialPath(m) => vec![format!(
            "estimate: {} path steps (limit {}), 4 runs of the path (analysis, dual numbers, τ ± h)",
            m.path.n_steps(),
            m.max_steps
        )],
        Case::Shell(s) => shell_report(s),
    }
}

/// [`case_report`] of a shell case.
pub fn shell_report(s: &shell_case::ShellCase) -> Vec<String> {
    std::iter::once(format!(
        "{} (limits: {} unknowns, {} layer points, memory {}, support {} spacings)",
        s.estimate(),
        s.limits.max_unknowns,
        s.limits.max_layer_points,
        shell_case::fmt_bytes(s.limits.max_memory_bytes),
        s.limits.max_support
    ))
    .chain(s.warnings.iter().map(|w| format!("warning: {w}")))
    .collect()
}

/// Read and validate a case file.
pub fn read_case(path: &Path) -> Result<Case, CaseError> {
    let text = std::fs::read_to_string(path).map_err(|source| CaseError::Read {
        path: path.into(),
        source,
    })?;
    parse_case(&text, path)
}

/// Parse and validate case-file text (`path` names the file in messages).
pub fn parse_case(text: &str, path: &Path) -> Result<Case, CaseError> {
    let parse_err = |e: toml::de::Error| CaseError::Parse {
        path: path.into(),
        message: e.to_string(),
    };
    #[derive(Deserialize)]
    struct Head {
        problem: Option<toml::Value>,
    }
    let head: Head = toml::from_str(text).map_err(parse_err)?;
    let kind = head
        .problem
        .as_ref()
        .and_then(|p| p.get("kind"))
        .and_then(|k| k.as_str())
        .map(str::to_owned);
    let invalid = |key: &str, value: String, expected: String| CaseError::Invalid {
        path: path.into(),
        key: key.into(),
        value,
        expected,
    };
    match kind.as_deref() {
        Some("material-path") => {
            let f: MaterialPathFile = toml::from_str(text).map_err(parse_err)?;
            material_path_case(f, path)
        }
        Some("shell") => shell_case::parse_shell_case(text, path).map(|c| Case::Shell(Box::new(c))),
        Some(other) => Err(invalid(
            "problem.kind",
            format!("{other:?}"),
            format!("one of {KINDS:?}"),
        )),
        None => Err(invalid(
            "problem.kind",
            "(missing)".into(),
            format!("a [problem] table with kind = one of {KINDS:?}"),
        )),
    }
}

/// Validated material parameters of a `[material]` table (shared by every problem kind); an
/// error names `material.<parameter>`, its value and the admissible range.
fn material_from_spec(m: &MaterialSpec, path: &Path) -> Result<MaterialParams<f64>, CaseError> {
    let material = MaterialParams {
        young: m.young,
        poisson: m.poisson,
        shear_factor: m.shear_factor,
        sigma0: m.sigma0,
        hardening: m.hardening,
        beta: m.beta,
    };
    let invalid = |key: String, value: String, expected: String| CaseError::Invalid {
        path: path.into(),
        key,
        value,
        expected,
    };
    material.validate().map_err(|e| match e {
        MaterialError::InvalidParameter {
            name,
            value,
            expected,
        } => invalid(
            format!("material.{name}"),
            value.to_string(),
            expected.to_string(),
        ),
        other => invalid("material".into(), String::new(), other.to_string()),
    })?;
    Ok(material)
}

fn material_path_case(f: MaterialPathFile, path: &Path) -> Result<Case, CaseError> {
    let invalid = |key: &str, value: String, expected: &str| CaseError::Invalid {
        path: path.into(),
        key: key.into(),
        value,
        expected: expected.into(),
    };
    let material = material_from_spec(&f.material, path)?;
    if let Some(t) = f.problem.title.as_ref().filter(|t| !is_name(t)) {
        return Err(invalid("problem.title", format!("{t:?}"), NAME_EXPECTED));
    }
    if !is_name(&f.design.name) {
        return Err(invalid(
            "design.name",
            format!("{:?}", f.design.name),
            NAME_EXPECTED,
        ));
    }
    let r = f.design.material_rate;
    let material_rate = MaterialParams {
        young: r.young,
        poisson: r.poisson,
        shear_factor: r.shear_factor,
        sigma0: r.sigma0,
        hardening: r.hardening,
        beta: r.beta,
    };
    for (name, v) in crate::material::PARAM_NAMES
        .iter()
        .zip(material_rate.to_array())
    {
        if !v.is_finite() {
            return Err(invalid(
                &format!("design.material_rate.{name}"),
                v.to_string(),
                "a finite number",
            ));
        }
    }
    let h = f.design.fd_step;
    if !(h > 0.0 && h.is_finite()) {
        return Err(invalid("design.fd_step", fmt_num(h), "a finite step > 0"));
    }
    if !f.design.tau.is_finite() {
        return Err(invalid(
            "design.tau",
            f.design.tau.to_string(),
            "a finite number",
        ));
    }
    let max_steps = match &f.limits {
        None => MAX_PATH_STEPS,
        Some(l) if l.max_steps >= 1 => l.max_steps as usize,
        Some(l) => {
            return Err(invalid(
                "limits.max_steps",
                l.max_steps.to_string(),
                "an integer >= 1",
            ))
        }
    };
    let check = f.check.unwrap_or_default();
    for (key, v) in [
        ("check.dual_rel", check.dual_rel),
        ("check.fd_rel", check.fd_rel),
        ("check.fd_floor", check.fd_floor),
    ] {
        if !(v > 0.0 && v < 1.0) {
            return Err(invalid(key, fmt_num(v), "a relative tolerance in (0, 1)"));
        }
    }
    let mut mp = match (&f.path.generator, f.path.segment.is_empty()) {
        (Some(g), true) if g == "non-proportional-60" => {
            MaterialPath::non_proportional_60(material.beta)
                .map_err(|e| invalid("path.generator", g.clone(), &e.to_string()))?
        }
        (Some(g), true) => {
            return Err(invalid(
                "path.generator",
                format!("{g:?}"),
                "\"non-proportional-60\" or [[path.segment]] tables",
            ))
        }
        (Some(_), false) => {
            return Err(invalid(
                "path",
                "generator and segments".into(),
                "either `generator` or [[path.segment]], not both",
            ))
        }
        (None, true) => {
            return Err(invalid(
                "path",
                "(empty)".into(),
                "`generator` or at least one [[path.segment]]",
            ))
        }
        (None, false) => {
            let mut inc = Vec::new();
            let mut rates = Vec::new();
            let mut total: usize = 0;
            for (i, s) in f.path.segment.iter().enumerate() {
                if s.steps < 1 {
                    return Err(invalid(
                        &format!("path.segment[{i}].steps"),
                        s.steps.to_string(),
                        "an integer >= 1",
                    ));
                }
                total = total.saturating_add(s.steps as usize);
                if total > max_steps {
                    return Err(invalid(
                        &format!("path.segment[{i}].steps"),
                        s.steps.to_string(),
                        &format!(
                            "at most limits.max_steps = {max_steps} steps over all segments \
                             (these reach {total}); raise `max_steps` in a [limits] table for a \
                             longer path"
                        ),
                    ));
                }
                for (c, v) in s.increment.iter().chain(&s.rate).enumerate() {
                    if !v.is_finite() {
                        let key = if c < 5 { "increment" } else { "rate" };
                        return Err(invalid(
                            &format!("path.segment[{i}].{key}[{}]", c % 5),
                            v.to_string(),
                            "a finite number",
                        ));
                    }
                }
                for _ in 0..s.steps {
                    inc.push(Vec5::from(s.increment));
                    rates.push(Vec5::from(s.rate));
                }
            }
            MaterialPath {
                material,
                material_rate: MaterialParams::zero(),
                increments: inc,
                increment_rates: rates,
                tau: 0.0,
            }
        }
    };
    mp.material = material;
    mp.material_rate = material_rate;
    mp.tau = f.design.tau;
    if let Some(what) = mp.lost_in_step(h) {
        return Err(invalid(
            "design.fd_step",
            fmt_num(h),
            &format!(
                "a step that changes every τ-dependent value in floating point: with τ ± h, \
                 {what} is unchanged, so its central difference is 0"
            ),
        ));
    }
    Ok(Case::MaterialPath(Box::new(MaterialPathCase {
        title: f
            .problem
            .title
            .unwrap_or_else(|| "material-point path".into()),
        design_name: f.design.name,
        path: mp,
        fd_step: h,
        check,
        max_steps,
    })))
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[problem]
kind = "material-path"
[material]
young = 210000.0
poisson = 0.3
sigma0 = 250.0
hardening = 1000.0
beta = 0.5
[design]
material_rate = { young = 21000.0 }
[[path.segment]]
steps = 3
increment = [1e-3, 0.0, 0.0, 0.0, 0.0]
rate = [1e-4, 0.0, 0.0, 0.0, 0.0]
"#;

    fn err(text: &str) -> String {
        parse_case(text, Path::new("case.toml"))
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn good_case_parses() {
        let Case::MaterialPath(c) = parse_case(GOOD, Path::new("case.toml")).unwrap() else {
            panic!("a material-path case")
        };
        assert_eq!(c.path.n_steps(), 3);
        assert_eq!(c.path.material_rate.young, 21000.0);
        assert_eq!(c.path.material.shear_factor, 5.0 / 6.0);
    }

    #[test]
    fn errors_name_key_value_and_expectation() {
        let e = err(&GOOD.replace("poisson = 0.3", "poisson = 0.7"));
        assert!(
            e.contains("material.poisson") && e.contains("0.7") && e.contains("(-1, 0.5)"),
            "{e}"
        );
        let e = err(&GOOD.replace("beta = 0.5", "beta = 2.0"));
        assert!(e.contains("material.beta") && e.contains('2'), "{e}");
        let e = err(&GOOD.replace("sigma0 = 250.0", "sigma0 = -1.0"));
        assert!(e.contains("material.sigma0") && e.contains("-1"), "{e}");
        let e = err(&GOOD.replace("steps = 3", "steps = 0"));
        assert!(e.contains("path.segment[0].steps"), "{e}");
        let e = err(&GOOD.replace("kind = \"material-path\"", "kind = \"plate\""));
        assert!(
            e.contains("problem.kind") && e.contains("plate") && e.contains("material-path"),
            "{e}"
        );
        // Unknown key (a typo) is named by the TOML layer.
        let e = err(&GOOD.replace("hardening = 1000.0", "hardenning = 1000.0"));
        assert!(e.contains("hardenning"), "{e}");
        // Wrong type.
        let e = err(&GOOD.replace("young = 210000.0", "young = \"steel\""));
        assert!(e.contains("young") || e.contains("steel"), "{e}");
        let e = err(&GOOD.replace(
            "increment = [1e-3, 0.0, 0.0, 0.0, 0.0]",
            "increment = [1e-3, 0.0]",
        ));
        assert!(e.contains("increment") || e.contains("5"), "{e}");
    }

    #[test]
    fn too_long_arrays_are_errors() {
        let e = err(&GOOD.replace(
            "increment = [1e-3, 0.0, 0.0, 0.0, 0.0]",
            "increment = [1e-3, 0.0, 0.0, 0.0, 0.0, 7.0]",
        ));
        assert!(e.contains("increment") && e.contains("exactly 5"), "{e}");
        let e = err(&GOOD.replace(
            "rate = [1e-4, 0.0, 0.0, 0.0, 0.0]",
            "rate = [1e-4, 0.0, 0.0, 0.0, 0.0, 0.0]",
        ));
        assert!(e.contains("rate") && e.contains("exactly 5"), "{e}");
    }

    /// NaN compared with a tolerance is false, so a NaN tolerance used to pass every check.
    #[test]
    fn tolerances_are_finite_and_in_range() {
        let base = format!("{GOOD}[check]\ndual_rel = 1e-9\nfd_rel = 1e-5\nfd_floor = 1e-4\n");
        assert!(parse_case(&base, Path::new("c.toml")).is_ok());
        for (key, bad) in [
            ("dual_rel", "nan"),
            ("dual_rel", "-1e-9"),
            ("fd_rel", "inf"),
            ("fd_rel", "0.0"),
            ("fd_floor", "-1e-4"),
            ("fd_floor", "2.0"),
        ] {
            let text = base.replacen(&format!("{key} = "), &format!("{key} = {bad} # "), 1);
            let e = err(&text);
            assert!(e.contains(&format!("check.{key}")), "{key} = {bad}: {e}");
        }
    }

    /// A step that leaves a τ-dependent value unchanged (its difference is 0) is an error naming
    /// `design.fd_step`; NaN, 0 and negative steps too.
    #[test]
    fn fd_steps_that_underflow_are_errors() {
        for bad in ["1e-20", "5e-324", "0.0", "-1e-6", "nan"] {
            let e = err(&GOOD.replace("[design]", &format!("[design]\nfd_step = {bad}")));
            assert!(e.contains("design.fd_step"), "{bad}: {e}");
        }
        let e = err(&GOOD.replace("[design]", "[design]\nfd_step = 1e-20"));
        assert!(e.contains("material.young"), "{e}");
    }

    #[test]
    fn path_length_is_limited_unless_raised() {
        let e = err(&GOOD.replace("steps = 3", "steps = 1000000000000"));
        assert!(
            e.contains("path.segment[0].steps") && e.contains("max_steps"),
            "{e}"
        );
        let e = err(&GOOD.replace("steps = 3", "steps = -3"));
        assert!(e.contains("path.segment[0].steps"), "{e}");
        let raised = format!(
            "{}[limits]\nmax_steps = 200000\n",
            GOOD.replace("steps = 3", "steps = 150000")
        );
        let Case::MaterialPath(c) = parse_case(&raised, Path::new("c.toml")).unwrap() else {
            panic!("a material-path case")
        };
        assert_eq!(c.path.n_steps(), 150_000);
    }
}
