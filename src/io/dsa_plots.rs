//! The figures `shelldsa dsa` writes beside `sensitivity.json`: per design variable, each
//! monitored response's derivative along the load path with the methods overlaid
//! (`dsa_<variable>.png`), and, with finite differences, the step-size study and the Taylor
//! remainders on log–log axes with the reference slope 2 (`dsa_<variable>_fd.png`); with
//! `--terms STEP`, the term groups of the continuum right-hand side against the dual reference
//! as bars (`terms_step<STEP>.png`).

use super::plot::{bar_figure, figure, BarPanel, Panel, PlotError, Scale, Series, Style};
use crate::sensitivity::study::{max_rel_diff, DsaResult, VariableResult};
use crate::sensitivity::terms::TermBreakdown;
use std::path::{Path, PathBuf};

/// Height of one panel (pixels).
const PANEL_HEIGHT: u32 = 240;
/// Width of a figure (pixels).
const WIDTH: u32 = 960;

/// A file-name stem for a variable name: letters, digits, `.`, `-` and `_` kept, anything
/// else replaced by `_`.
fn stem(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_') {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Write the figures of every design variable into `dir`; returns the files written.
pub fn write(dir: &Path, r: &DsaResult) -> Result<Vec<PathBuf>, PlotError> {
    let mut written = Vec::new();
    for v in &r.variables {
        let name = stem(&v.entry.variable.name);
        let path = dir.join(format!("dsa_{name}.png"));
        derivatives_figure(&path, r, v)?;
        written.push(path);
        if !v.fd.is_empty() {
            let path = dir.join(format!("dsa_{name}_fd.png"));
            fd_figure(&path, r, v)?;
            written.push(path);
        }
    }
    Ok(written)
}

/// One panel per monitored component: `dψ/dτ` against the load factor, continuum (line), dual
/// (markers) and central differences per step size at the steps whose active set did not
/// change within `±h` (markers).
fn derivatives_figure(path: &Path, r: &DsaResult, v: &VariableResult) -> Result<(), PlotError> {
    let loads = &r.nominal.loads;
    let column = |d: &Vec<Vec<f64>>, m: usize| -> Vec<(f64, f64)> {
        d.iter().zip(loads).map(|(row, &l)| (l, row[m])).collect()
    };
    let fd_labels: Vec<String> =
        v.fd.iter()
            .map(|c| format!("central difference, h/|τ| = {:e}", c.relative))
            .collect();
    let titles: Vec<String> = r
        .spec
        .monitors
        .iter()
        .map(|m| format!("d({})/d({})", m.label, v.entry.variable.name))
        .collect();
    let panels: Vec<Panel> = r
        .spec
        .monitors
        .iter()
        .enumerate()
        .map(|(m, _)| {
            let mut series = Vec::new();
            if let Some(d) = &v.continuum {
                series.push(Series {
                    label: "continuum",
                    points: column(d, m),
                    style: Style::Line,
                });
            }
            if let Some(d) = &v.dual {
                series.push(Series {
                    label: "dual",
                    points: column(d, m),
                    style: Style::Dots,
                });
            }
            for (c, label) in v.fd.iter().zip(&fd_labels) {
                series.push(Series {
                    label,
                    points: c
                        .derivatives
                        .iter()
                        .zip(loads)
                        .zip(&c.flagged)
                        .filter(|(_, f)| !**f)
                        .map(|((row, &l), _)| (l, row[m]))
                        .collect(),
                    style: Style::Dots,
                });
            }
            Panel {
                title: &titles[m],
                x_label: "load factor",
                y_label: "derivative",
                x_scale: Scale::Linear,
                y_scale: Scale::Linear,
                series,
            }
        })
        .collect();
    let height = PANEL_HEIGHT * panels.len().max(1) as u32;
    figure(path, WIDTH, height, &panels)
}

/// The steps whose Taylor remainders are drawn: the first and the last step with a fitted
/// rate, and the final step (at most three, in order, without repeats).
fn taylor_steps(v: &VariableResult, steps: usize) -> Vec<usize> {
    let fitted: Vec<usize> = v
        .taylor
        .iter()
        .filter(|f| f.rate.is_some())
        .map(|f| f.step)
        .collect();
    let mut out: Vec<usize> = fitted
        .first()
        .into_iter()
        .chain(fitted.last())
        .copied()
        .collect();
    if steps > 0 {
        out.push(steps - 1);
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// A line of slope 2 on log–log axes over the `h` range of `points`, half a decade below
/// their first point (parallel to data of rate 2, not on top of them).
fn slope_two(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let Some(&(h0, r0)) = points.first() else {
        return Vec::new();
    };
    let (lo, hi) = points.iter().fold((f64::INFINITY, 0.0f64), |(a, b), p| {
        (a.min(p.0), b.max(p.0))
    });
    let below = 10f64.powf(-0.5);
    [lo, hi]
        .iter()
        .map(|&h| (h, below * r0 * (h / h0).powi(2)))
        .collect()
}

/// Two log–log panels: the Taylor remainder `max_m |ψ(τ+h) − ψ(τ) − h ψ'|` against `h` at a few
/// steps with the slope-2 reference, and the step-size study `max |Δψ/(ψ'Δτ) − 1|` over the
/// unflagged components against `h`.
fn fd_figure(path: &Path, r: &DsaResult, v: &VariableResult) -> Result<(), PlotError> {
    let steps = taylor_steps(v, r.nominal.loads.len());
    let labels: Vec<String> = steps
        .iter()
        .map(|&s| {
            let flagged = v.fd.iter().any(|c| c.flagged.get(s) == Some(&true));
            format!(
                "step {} (load factor {}){}",
                s + 1,
                super::plot::plain_tick(r.nominal.loads[s]),
                if flagged {
                    ", active set changed within ±h"
                } else {
                    ""
                }
            )
        })
        .collect();
    let mut taylor = Vec::new();
    let mut first_points: Option<Vec<(f64, f64)>> = None;
    for (&s, label) in steps.iter().zip(&labels) {
        let mut points: Vec<(f64, f64)> =
            v.fd.iter()
                .filter_map(|c| Some((c.h.abs(), *c.taylor.as_ref()?.remainder.get(s)?)))
                .collect();
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        if first_points.is_none() && points.iter().any(|p| p.1 > 0.0) {
            first_points = Some(points.clone());
        }
        taylor.push(Series {
            label,
            points,
            style: Style::Line,
        });
    }
    if let Some(p) = first_points {
        taylor.push(Series {
            label: "slope 2 (reference)",
            points: slope_two(&p),
            style: Style::Line,
        });
    }
    let mut study: Vec<(f64, f64)> =
        v.fd.iter()
            .filter_map(|c| Some((c.h.abs(), max_rel_diff(v, c)?)))
            .collect();
    study.sort_by(|a, b| a.0.total_cmp(&b.0));
    let reference = slope_two(&study);
    let name = &v.entry.variable.name;
    let (t1, t2) = (
        format!("Taylor remainder of {name}: max over the monitors"),
        format!("central differences of {name} against the derivative"),
    );
    let panels = [
        Panel {
            title: &t1,
            x_label: "h",
            y_label: "|ψ(τ+h) − ψ(τ) − hψ'|",
            x_scale: Scale::Log,
            y_scale: Scale::Log,
            series: taylor,
        },
        Panel {
            title: &t2,
            x_label: "h",
            y_label: "max |Δψ/(ψ'h) − 1|",
            x_scale: Scale::Log,
            y_scale: Scale::Log,
            series: vec![
                Series {
                    label: "unflagged steps, |ψ'| ≥ 1e-6 max|ψ'|",
                    points: study,
                    style: Style::Dots,
                },
                Series {
                    label: "slope 2 (reference)",
                    points: reference,
                    style: Style::Line,
                },
            ],
        },
    ];
    figure(path, WIDTH, 2 * PANEL_HEIGHT + 80, &panels)
}

/// `--terms STEP`: one bar panel per design variable, per term group (and the whole right-hand
/// side) the largest entry of the continuum fictitious load, of the dual reference seeded with
/// that group, and of their difference. Returns the file written.
pub fn write_terms(dir: &Path, breakdowns: &[TermBreakdown]) -> Result<PathBuf, PlotError> {
    let step = breakdowns.first().map_or(0, |b| b.step);
    let path = dir.join(format!("terms_step{step}.png"));
    let titles: Vec<String> = breakdowns
        .iter()
        .map(|b| {
            format!(
                "{}: term groups at step {} (load factor {})",
                b.variable.name,
                b.step,
                super::plot::plain_tick(b.load)
            )
        })
        .collect();
    let categories: Vec<Vec<String>> = breakdowns
        .iter()
        .map(|b| {
            b.groups
                .iter()
                .map(|g| g.group.map_or("all".to_string(), |g| g.name().to_string()))
                .collect()
        })
        .collect();
    let panels: Vec<BarPanel> = breakdowns
        .iter()
        .zip(&titles)
        .zip(&categories)
        .map(|((b, title), categories)| BarPanel {
            title,
            y_label: "largest entry",
            categories,
            series: vec![
                (
                    "continuum",
                    b.groups.iter().map(|g| g.continuum_max).collect(),
                ),
                ("dual", b.groups.iter().map(|g| g.dual_max).collect()),
                (
                    "|continuum − dual|",
                    b.groups.iter().map(|g| g.max_difference).collect(),
                ),
            ],
        })
        .collect();
    let height = PANEL_HEIGHT * panels.len().max(1) as u32;
    bar_figure(&path, WIDTH, height, &panels)?;
    Ok(path)
}
