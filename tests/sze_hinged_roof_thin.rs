//! `verification/hinged-roof-thin` (Sze, Liu & Lo 2004 §3.8, isotropic roof, h = 6.35) on
//! 13 × 13 particles: arc length through a load maximum, two turns of the deflection
//! (snap-back) and a load minimum below zero, each reported as what it is, and the whole path
//! on Sze's. Refinement and figures: the case's README.

use shelldsa::io::shell_build;
use shelldsa::io::shell_case::parse_shell_case;
use std::path::Path;

#[path = "common/case_run.rs"]
mod case_run;
use case_run::shipped_case;

#[path = "common/load_path.rs"]
mod load_path;
use load_path::vertex;

/// (P/P_max, −W) at the load point: Sze, Liu & Lo (2004) §3.8, isotropic roof, h = 6.35, as
/// transcribed in the MBDyn test suite (`tests/plates/sze2004/sze38/sze38_ref_d.dat`).
const SZE: [(f64, f64); 37] = [
    (0.0, 0.0),
    (0.0517, 1.846),
    (0.1182, 5.271),
    (0.1583, 8.257),
    (0.1837, 10.799),
    (0.1914, 11.904),
    (0.1953, 12.892),
    (0.1950, 13.752),
    (0.1901, 14.472),
    (0.1806, 15.050),
    (0.1671, 15.501),
    (0.1323, 16.145),
    (0.0923, 16.602),
    (0.0504, 16.915),
    (0.0083, 17.008),
    (-0.0312, 16.697),
    (-0.0622, 15.780),
    (-0.0739, 15.206),
    (-0.0861, 14.767),
    (-0.1001, 14.520),
    (-0.1142, 14.451),
    (-0.1247, 14.862),
    (-0.1288, 15.778),
    (-0.1271, 16.961),
    (-0.1196, 18.320),
    (-0.1055, 19.817),
    (-0.0825, 21.420),
    (-0.0484, 23.100),
    (-0.0006, 24.824),
    (0.0626, 26.565),
    (0.1427, 28.302),
    (0.2403, 30.023),
    (0.3559, 31.720),
    (0.4898, 33.388),
    (0.6417, 35.024),
    (0.8114, 36.626),
    (1.0313, 38.450),
];

/// Deflection scale of the distance to the path: Sze's last tabulated deflection.
const W_END: f64 = 38.45;

/// The path's turns in order, as (is a load extremum, W, P): a load extremum is the vertex of
/// the parabola P(W) through the turning point and its neighbours, a turn of the deflection
/// that of W(P). `path` holds (W, P).
fn turns(path: &[(f64, f64)]) -> Vec<(bool, f64, f64)> {
    let swapped: Vec<(f64, f64)> = path.iter().map(|&(w, p)| (p, w)).collect();
    let mut out = Vec::new();
    for i in 1..path.len() - 1 {
        let ((w0, p0), (w1, p1), (w2, p2)) = (path[i - 1], path[i], path[i + 1]);
        if (p1 - p0) * (p2 - p1) < 0.0 {
            let (w, p) = vertex(path, i);
            out.push((true, w, p));
        }
        if (w1 - w0) * (w2 - w1) < 0.0 {
            let (p, w) = vertex(&swapped, i);
            out.push((false, w, p));
        }
    }
    out
}

/// Distance from `pt` (W, P) to the polyline `path` in the plane (W / W_END, P).
fn distance(pt: (f64, f64), path: &[(f64, f64)]) -> f64 {
    let (x, y) = (pt.0 / W_END, pt.1);
    path.windows(2)
        .map(|s| {
            let (ax, ay, bx, by) = (s[0].0 / W_END, s[0].1, s[1].0 / W_END, s[1].1);
            let (dx, dy) = (bx - ax, by - ay);
            let n2 = dx * dx + dy * dy;
            let t = if n2 == 0.0 {
                0.0
            } else {
                (((x - ax) * dx + (y - ay) * dy) / n2).clamp(0.0, 1.0)
            };
            (ax + t * dx - x).hypot(ay + t * dy - y)
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn thin_hinged_roof_snaps_through_and_back_on_sze_path_by_arc_length() {
    let text = shipped_case("hinged-roof-thin")
        .replace("grid = [17, 17]", "grid = [13, 13]")
        .replace("plot = true", "plot = false");
    assert_eq!(text.matches("[13, 13]").count(), 1, "test set-up");
    let case = parse_shell_case(&text, Path::new("hinged-roof-thin.toml")).unwrap();
    let mut built = shell_build::build(&case).unwrap();
    let out = std::env::temp_dir().join(format!("shelldsa-roof-thin-{}", std::process::id()));
    let s = shell_build::run(&case, &mut built, &out, std::time::Instant::now(), |_| {}).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&out);
    assert_eq!(s.status, shell_build::RunStatus::Complete);
    assert!(s.steps.last().unwrap().load_factor >= 1.05);

    // Reported in the order the path meets them: the load's maximum, the deflection's two
    // turns (the tangent stays regular there), the load's minimum.
    let kinds: Vec<&str> = json["critical_points"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c["kind"].as_str().unwrap())
        .collect();
    let snap_back = "snap-back (turning point of the displacement)";
    assert_eq!(
        kinds,
        [
            "limit point (load maximum)",
            snap_back,
            snap_back,
            "limit point (load minimum)"
        ]
    );

    let mut ours = vec![(0.0, 0.0)];
    ours.extend(
        s.steps
            .iter()
            .map(|st| (-st.monitors[0][2], st.load_factor)),
    );
    let sze: Vec<(f64, f64)> = SZE.iter().map(|&(p, w)| (w, p)).collect();
    // The same four turns on both paths, each read by the same parabola.
    let (t_sze, t_ours) = (turns(&sze), turns(&ours));
    let order: Vec<bool> = t_ours.iter().map(|t| t.0).collect();
    assert_eq!(order, [true, false, false, true], "{t_ours:?}");
    assert_eq!(t_sze.len(), 4);
    for (&(load_turn, ws, ps), &(_, w, p)) in t_sze.iter().zip(&t_ours) {
        println!("turn: Sze ({ws:.3}, {ps:.4}), ours ({w:.3}, {p:.4})");
        if load_turn {
            // The load's extremes: measured 0.07 and 0.05 % of P_max off on 13², 0.06 / 0.05
            // on 17² and 25²; 0.5 % of P_max holds them with the margin of Sze's own table
            // (his levels are 0.4 to 1 % of P_max apart around each extreme).
            assert!((p - ps).abs() <= 0.005, "load extreme {p} against {ps}");
        } else {
            // The deflection's turns: measured +0.06 / +0.27 % on 13², +0.03 / +0.31 % on 25²;
            // 1 % is the spacing of Sze's deflections there (0.1 to 0.3 of 17).
            assert!(
                (w / ws - 1.0).abs() <= 0.01,
                "deflection turn {w} against {ws}"
            );
        }
    }
    // Every tabulated point of Sze's lies within 1 % of the load scale P_max and of the
    // deflection scale W_END at once from the computed path: measured at most 0.78 % on 13²
    // (at the last point), 0.59 % on 17², 0.42 % on 25².
    for &pt in &sze[1..] {
        let d = distance(pt, &ours);
        assert!(
            d <= 0.01,
            "Sze's ({:.3}, {:.4}) is {d:.4} from the path",
            pt.0,
            pt.1
        );
    }
}
