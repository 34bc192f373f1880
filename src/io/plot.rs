//! PNG line charts (plotters, with the DejaVu font embedded so no system fonts are needed).

use plotters::prelude::*;
use std::path::Path;
use std::sync::Once;

static FONT: Once = Once::new();

fn register_font() {
    FONT.call_once(|| {
        // The embedded font is valid OpenType, so registration cannot fail in practice. If it
        // did, plotters would fail at text drawing and `line_chart` would return that error.
        let _ = plotters::style::register_font(
            "sans-serif",
            FontStyle::Normal,
            dejavu::sans::regular(),
        );
    });
}

/// One series of a chart.
pub struct Series<'a> {
    /// Legend label.
    pub label: &'a str,
    /// Points (x, y).
    pub points: Vec<(f64, f64)>,
    /// How the points are drawn.
    pub style: Style,
}

/// How a series' points are drawn.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// A line through the points.
    Line,
    /// A filled dot per point; later dot series smaller, so that coinciding points of several
    /// series stay visible as concentric dots.
    Dots,
    /// A ring per point, larger than the dots: marks a few points of another series.
    Rings,
}

/// Axis scaling.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    /// Linear axis.
    Linear,
    /// Base-10 logarithmic axis (non-positive values are left out).
    Log,
}

/// One panel of a figure.
pub struct Panel<'a> {
    /// Panel title.
    pub title: &'a str,
    /// x-axis label.
    pub x_label: &'a str,
    /// y-axis label.
    pub y_label: &'a str,
    /// x-axis scale.
    pub x_scale: Scale,
    /// y-axis scale.
    pub y_scale: Scale,
    /// Series drawn in the panel.
    pub series: Vec<Series<'a>>,
}

const COLORS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// Largest magnitude an axis spans: values beyond it (and, on a log axis, positive values
/// below its inverse) are drawn at the axis' end. Keeps every range, its padding and the tick
/// arithmetic finite.
const AXIS_MAX: f64 = 1e300;

/// Largest ratio of the ends of a log axis. plotters counts the decades of a log axis as
/// `ln(hi/lo)`: where the ratio overflows to ∞ the count becomes `usize::MAX` and its loop that
/// thins the ticks runs ~10^19 times (errors of 3e307 next to 1e-17 did that). Values more than
/// 300 decades below the largest are drawn at the axis' lower end.
const MAX_LOG_RATIO: f64 = 1e300;

/// Smallest width of a linear axis relative to its largest magnitude. plotters' tick search
/// refines the tick spacing until enough ticks fit; on a range only a few ulps wide the spacing
/// underflows and the search never ends, so a narrower range is widened to ±1e-3 of its
/// centre (±1 around 0).
const MIN_REL_WIDTH: f64 = 1e-9;

/// The value drawn for `v` on an axis (`None`: not drawn: not finite, or not positive on a log
/// axis).
fn axis_value(v: f64, log: bool) -> Option<f64> {
    if !v.is_finite() {
        None
    } else if log {
        (v > 0.0).then(|| v.clamp(1.0 / AXIS_MAX, AXIS_MAX))
    } else {
        Some(v.clamp(-AXIS_MAX, AXIS_MAX))
    }
}

/// Axis range of `vals`: finite, non-empty, at least one decade on a log axis, at least
/// [`MIN_REL_WIDTH`] of the magnitude on a linear one.
fn range(vals: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in vals.filter_map(|v| axis_value(v, log)) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return if log { (1e-16, 1.0) } else { (0.0, 1.0) };
    }
    if log {
        // A factor 2 of margin on both sides; at least one decade, at most MAX_LOG_RATIO.
        let (lo, hi) = (lo / 2.0, hi * 2.0);
        if hi / lo < 10.0 {
            let c = lo.sqrt() * hi.sqrt();
            (c / 10f64.sqrt(), c * 10f64.sqrt())
        } else {
            (lo.max(hi / MAX_LOG_RATIO), hi)
        }
    } else if hi - lo <= MIN_REL_WIDTH * lo.abs().max(hi.abs()) {
        let c = 0.5 * (lo + hi);
        let half = if c == 0.0 { 1.0 } else { 1e-3 * c.abs() };
        (c - half, c + half)
    } else {
        let pad = 0.05 * (hi - lo);
        (lo - pad, hi + pad)
    }
}

/// A figure that could not be drawn or written: its file and the plotting backend's message
/// (the backend's error types are generic over the drawing surface, so its text is kept).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("plotting {}: {detail}", path.display())]
pub struct PlotError {
    /// The figure's file.
    pub path: std::path::PathBuf,
    /// What the backend reported.
    pub detail: String,
}

/// Draw panels stacked vertically into a PNG of `width × height` pixels.
pub fn figure(path: &Path, width: u32, height: u32, panels: &[Panel]) -> Result<(), PlotError> {
    let e = |e: &dyn std::fmt::Display| PlotError {
        path: path.to_path_buf(),
        detail: e.to_string(),
    };
    register_font();
    let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let areas = root.split_evenly((panels.len().max(1), 1));
    for (area, p) in areas.iter().zip(panels) {
        let (log_x, log_y) = (p.x_scale == Scale::Log, p.y_scale == Scale::Log);
        let xs = range(
            p.series.iter().flat_map(|s| s.points.iter().map(|q| q.0)),
            log_x,
        );
        let ys = range(
            p.series.iter().flat_map(|s| s.points.iter().map(|q| q.1)),
            log_y,
        );
        let mut b = ChartBuilder::on(area);
        b.caption(p.title, ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(80);
        let exp = |v: &f64| format!("{v:.0e}");
        // A tick within round-off of zero on a linear axis is written 0.
        let near_zero = |v: f64, r: (f64, f64)| v.abs() <= 1e-9 * r.0.abs().max(r.1.abs());
        let plain_x = |v: &f64| plain_tick(if near_zero(*v, xs) { 0.0 } else { *v });
        let plain = |v: &f64| plain_tick(if near_zero(*v, ys) { 0.0 } else { *v });
        // One arm per combination of axis kinds (plotters' coordinate types differ).
        macro_rules! draw {
            ($x:expr, $y:expr, $fx:expr, $fy:expr) => {{
                let mut chart = b.build_cartesian_2d($x, $y).map_err(|x| e(&x))?;
                chart
                    .configure_mesh()
                    .x_desc(p.x_label)
                    .y_desc(p.y_label)
                    .x_label_formatter(&$fx)
                    .y_label_formatter(&$fy)
                    .draw()
                    .map_err(|x| e(&x))?;
                draw_series(&mut chart, &p.series, (log_x, log_y), xs, ys).map_err(|x| e(&x))?;
            }};
        }
        match (log_x, log_y) {
            (false, false) => draw!(xs.0..xs.1, ys.0..ys.1, plain_x, plain),
            (false, true) => draw!(xs.0..xs.1, (ys.0..ys.1).log_scale(), plain_x, exp),
            (true, false) => draw!((xs.0..xs.1).log_scale(), ys.0..ys.1, exp, plain),
            (true, true) => draw!((xs.0..xs.1).log_scale(), (ys.0..ys.1).log_scale(), exp, exp),
        }
    }
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

/// One panel of a bar chart: per category, one bar per series (the series' values in
/// category order), on a log y axis (non-positive values are not drawn).
pub struct BarPanel<'a> {
    /// Panel title.
    pub title: &'a str,
    /// y-axis label.
    pub y_label: &'a str,
    /// Category names along x.
    pub categories: &'a [String],
    /// `(legend label, value per category)`.
    pub series: Vec<(&'a str, Vec<f64>)>,
}

/// Draw bar-chart panels stacked vertically into a PNG of `width × height` pixels.
pub fn bar_figure(
    path: &Path,
    width: u32,
    height: u32,
    panels: &[BarPanel],
) -> Result<(), PlotError> {
    let e = |e: &dyn std::fmt::Display| PlotError {
        path: path.to_path_buf(),
        detail: e.to_string(),
    };
    register_font();
    let root = BitMapBackend::new(path, (width, height)).into_drawing_area();
    root.fill(&WHITE).map_err(|x| e(&x))?;
    let areas = root.split_evenly((panels.len().max(1), 1));
    for (area, p) in areas.iter().zip(panels) {
        let n = p.categories.len().max(1);
        let ys = range(p.series.iter().flat_map(|s| s.1.iter().copied()), true);
        let mut chart = ChartBuilder::on(area)
            .caption(p.title, ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(40)
            .y_label_area_size(80)
            .build_cartesian_2d(0f64..n as f64, (ys.0..ys.1).log_scale())
            .map_err(|x| e(&x))?;
        let names = p.categories;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_labels(2 * n + 1)
            .x_label_formatter(&|x| {
                // Names at the category centres (k + ½), nothing at the boundaries.
                let k = x.floor();
                if (x - k - 0.5).abs() < 1e-6 && k >= 0.0 {
                    names.get(k as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .y_desc(p.y_label)
            .y_label_formatter(&|v| format!("{v:.0e}"))
            .draw()
            .map_err(|x| e(&x))?;
        let m = p.series.len().max(1) as f64;
        let width = 0.8 / m;
        for (j, (label, values)) in p.series.iter().enumerate() {
            let color = COLORS[j % COLORS.len()];
            let bars: Vec<Rectangle<(f64, f64)>> = values
                .iter()
                .enumerate()
                .filter_map(|(k, &v)| {
                    let v = axis_value(v, true)?.clamp(ys.0, ys.1);
                    let x0 = k as f64 + 0.1 + j as f64 * width;
                    Some(Rectangle::new(
                        [(x0, ys.0), (x0 + width, v)],
                        color.filled(),
                    ))
                })
                .collect();
            chart
                .draw_series(bars)
                .map_err(|x| e(&x))?
                .label(*label)
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 12, y + 5)], color.filled())
                });
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperMiddle)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(|x| e(&x))?;
    }
    root.present().map_err(|x| e(&x))?;
    Ok(())
}

/// A tick label in plain notation (`0.25`, `1500`, `-3.2`), with exponents only outside
/// `[1e-3, 1e6)`: six significant digits at most, trailing zeros removed.
pub(crate) fn plain_tick(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 || !v.is_finite() {
        return if v == 0.0 { "0".into() } else { v.to_string() };
    }
    if !(1e-3..1e6).contains(&a) {
        return format!("{v:.2e}");
    }
    let decimals = (5 - a.log10().floor() as i32).clamp(0, 8) as usize;
    let s = format!("{v:.decimals$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" {
        "0".into()
    } else {
        s
    }
}

fn draw_series<'a, DB: DrawingBackend + 'a, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    series: &[Series],
    (log_x, log_y): (bool, bool),
    xs: (f64, f64),
    ys: (f64, f64),
) -> Result<(), String>
where
    CT: plotters::coord::CoordTranslate<From = (f64, f64)>,
{
    let mut marker_series = 0;
    for (k, s) in series.iter().enumerate() {
        let color = COLORS[k % COLORS.len()];
        // Points inside the axes: a point far outside would be mapped to a pixel ~2^31 away,
        // and a line to it rasterised pixel by pixel.
        let pts: Vec<(f64, f64)> = s
            .points
            .iter()
            .filter_map(|p| {
                let x = axis_value(p.0, log_x)?.clamp(xs.0, xs.1);
                let y = axis_value(p.1, log_y)?.clamp(ys.0, ys.1);
                Some((x, y))
            })
            .collect();
        match s.style {
            Style::Dots => {
                // Later marker series are drawn smaller, so that coinciding points of several
                // series stay visible as concentric dots.
                let radius = 6u32.saturating_sub(2 * marker_series).max(2);
                marker_series += 1;
                chart
                    .draw_series(pts.iter().map(|&p| Circle::new(p, radius, color.filled())))
                    .map_err(|e| e.to_string())?
                    .label(s.label)
                    .legend(move |(x, y)| Circle::new((x + 10, y), 3, color.filled()));
            }
            Style::Rings => {
                chart
                    .draw_series(
                        pts.iter()
                            .map(|&p| Circle::new(p, 10, color.stroke_width(3))),
                    )
                    .map_err(|e| e.to_string())?
                    .label(s.label)
                    .legend(move |(x, y)| Circle::new((x + 10, y), 5, color.stroke_width(2)));
            }
            Style::Line => {
                chart
                    .draw_series(LineSeries::new(pts, color.stroke_width(2)))
                    .map_err(|e| e.to_string())?
                    .label(s.label)
                    .legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                    });
            }
        }
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(|e| e.to_string())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::mpsc;
    use std::time::Duration;

    #[test]
    fn ranges_are_finite_and_wide_enough() {
        let cases: [(&[f64], bool); 9] = [
            (&[1e-300, 1e300], true),
            (&[3e307, 1e-3], true),
            (&[f64::MAX, 5e-324], true),
            (&[1e-300, 1e-300], true),
            (&[0.0, -1.0, f64::NAN], true),
            (&[-f64::MAX, f64::MAX], false),
            (&[1e10, 1e10 + 1e-5], false),
            (&[0.0, 0.0], false),
            (&[f64::INFINITY, f64::NAN], false),
        ];
        for (vals, log) in cases {
            let (lo, hi) = range(vals.iter().copied(), log);
            assert!(
                lo.is_finite() && hi.is_finite() && lo < hi,
                "{vals:?}: {lo} {hi}"
            );
            if log {
                assert!(
                    lo > 0.0
                        && hi / lo >= 10.0 * (1.0 - 1e-12)
                        && hi / lo <= MAX_LOG_RATIO * (1.0 + 1e-12),
                    "{vals:?}: {lo} {hi}"
                );
            } else {
                assert!(
                    hi - lo >= MIN_REL_WIDTH * lo.abs().max(hi.abs()),
                    "{vals:?}: {lo} {hi}"
                );
            }
        }
    }

    /// Degenerate data (errors of 3e307 next to 1e-17, subnormals, a constant series, values
    /// a few ulps apart, ±f64::MAX, NaN, ±∞) draw within a few seconds: each figure is drawn
    /// on a thread and the test fails, rather than hangs, when one does not finish in 60 s
    /// (a figure takes ~0.1 s).
    #[test]
    fn degenerate_data_plot_in_bounded_time() {
        let dir = std::env::temp_dir().join(format!("shelldsa-plot-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let data: Vec<(Vec<(f64, f64)>, Scale)> = vec![
            (vec![(1.0, 3e307), (2.0, 1e-17), (3.0, 0.0)], Scale::Log),
            (
                vec![(1.0, 5e-324), (2.0, f64::MAX), (3.0, f64::INFINITY)],
                Scale::Log,
            ),
            (vec![(1.0, 1e-300), (2.0, 1e-300)], Scale::Log),
            (
                vec![(1.0, -f64::MAX), (2.0, f64::MAX), (3.0, f64::NAN)],
                Scale::Linear,
            ),
            (
                vec![(1.0, 1e10), (2.0, 1e10 + 2e-6), (3.0, 1e10)],
                Scale::Linear,
            ),
            (vec![(1.0, 0.0), (2.0, 0.0)], Scale::Linear),
            (vec![(1e300, 1.0), (-1e300, 2.0)], Scale::Linear),
            (vec![(f64::NAN, 1.0)], Scale::Linear),
        ];
        for (k, (points, y_scale)) in data.into_iter().enumerate() {
            let path = dir.join(format!("degenerate-{k}.png"));
            let (tx, rx) = mpsc::channel();
            let shown = format!("{points:?} on a {y_scale:?} axis");
            std::thread::spawn(move || {
                let r = figure(
                    &path,
                    400,
                    300,
                    &[Panel {
                        title: "degenerate",
                        x_label: "x",
                        y_label: "y",
                        x_scale: Scale::Linear,
                        y_scale,
                        series: vec![
                            Series {
                                label: "markers",
                                points: points.clone(),
                                style: Style::Dots,
                            },
                            Series {
                                label: "rings",
                                points: points.clone(),
                                style: Style::Rings,
                            },
                            Series {
                                label: "line",
                                points,
                                style: Style::Line,
                            },
                        ],
                    }],
                );
                let _ = tx.send(r);
            });
            match rx.recv_timeout(Duration::from_secs(60)) {
                Ok(r) => r.unwrap_or_else(|e| panic!("{shown}: {e}")),
                Err(_) => panic!("{shown}: plotting did not finish in 60 s"),
            }
        }
        let _ = std::fs::remove_dir_all(&dir);
    }
}
