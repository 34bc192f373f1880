//! Load–deflection paths as (W, P) points: where the load turns, and the extreme read as the
//! vertex of the parabola through the turning point and its neighbours.
#![allow(dead_code)] // each test file uses a subset

/// The first point after which the load falls.
pub fn load_maximum(pts: &[(f64, f64)]) -> usize {
    (1..pts.len() - 1)
        .find(|&i| pts[i + 1].1 < pts[i].1)
        .expect("a load maximum")
}

/// The first point after which the load falls, and the first after that where it rises again.
pub fn extreme_points(pts: &[(f64, f64)]) -> (usize, usize) {
    let i_max = load_maximum(pts);
    let i_min = (i_max..pts.len() - 1)
        .find(|&i| pts[i + 1].1 > pts[i].1)
        .expect("a load minimum after it");
    (i_max, i_min)
}

/// The vertex (W, P) of the parabola through the points i − 1, i, i + 1 of a path.
pub fn vertex(pts: &[(f64, f64)], i: usize) -> (f64, f64) {
    let ((x0, y0), (x1, y1), (x2, y2)) = (pts[i - 1], pts[i], pts[i + 1]);
    let d = (x0 - x1) * (x0 - x2) * (x1 - x2);
    let a = (x2 * (y1 - y0) + x1 * (y0 - y2) + x0 * (y2 - y1)) / d;
    let b = (x2 * x2 * (y0 - y1) + x1 * x1 * (y2 - y0) + x0 * x0 * (y1 - y2)) / d;
    let c = y1 - a * x1 * x1 - b * x1;
    (-b / (2.0 * a), c - b * b / (4.0 * a))
}
