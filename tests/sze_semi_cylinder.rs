//! Reduced `verification/semi-cylinder` (Sze, Liu & Lo 2004 §3.7, the pinched semi-cylinder):
//! the shipped case on 13 × 25 particles over the whole path to P_max, every one of Sze's 25
//! levels. Full path, refinement, the edge condition and the stabilisation's role:
//! `verification/semi-cylinder/README.md`.

use shelldsa::io::shell_build;
use shelldsa::io::shell_case::parse_shell_case;
use std::path::Path;

/// Sze's table (P/P_max, deflection of the load point in hundredths of the SI unit):
/// `../shared/reference-values.md` §2, §3.7.
const SZE: [(f64, f64); 25] = [
    (0.05, 5.421),
    (0.10, 16.100),
    (0.125, 22.195),
    (0.15, 27.657),
    (0.175, 32.700),
    (0.20, 37.582),
    (0.225, 42.633),
    (0.25, 48.537),
    (0.275, 56.355),
    (0.30, 66.410),
    (0.325, 79.810),
    (0.35, 94.669),
    (0.40, 113.704),
    (0.45, 124.751),
    (0.50, 132.653),
    (0.55, 138.920),
    (0.60, 144.185),
    (0.65, 148.770),
    (0.70, 152.863),
    (0.75, 156.584),
    (0.80, 160.015),
    (0.85, 163.211),
    (0.90, 166.200),
    (0.95, 168.973),
    (1.00, 171.505),
];

fn case_text(grid: &str) -> String {
    let mut text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("verification/semi-cylinder/case.toml"),
    )
    .unwrap();
    assert!(text.contains("grid = [17, 33]"));
    text = text.replace("grid = [17, 33]", grid);
    text
}

/// `100 w` at each of Sze's levels (the run stops on every one; the half model carries P/2).
fn deflections(text: &str) -> Vec<(f64, f64)> {
    let case = parse_shell_case(text, Path::new("semi-cylinder.toml")).unwrap();
    let mut built = shell_build::build(&case).unwrap();
    // One directory per run: the tests of this file run in parallel in one process.
    static RUNS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let run = RUNS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let out = std::env::temp_dir().join(format!("shelldsa-semi-{}-{run}", std::process::id()));
    let s = shell_build::run(&case, &mut built, &out, std::time::Instant::now(), |_| {}).unwrap();
    let _ = std::fs::remove_dir_all(&out);
    SZE.iter()
        .filter_map(|&(p, _)| {
            s.steps
                .iter()
                .find(|st| (st.load_factor - 1000.0 * p).abs() < 1e-9)
                .map(|st| (p, -100.0 * st.monitors[0][2]))
        })
        .collect()
}

/// The largest relative error of `got` against Sze's levels, each level printed; every level
/// must have been reached.
fn largest_error(title: &str, got: &[(f64, f64)]) -> f64 {
    assert_eq!(
        got.len(),
        SZE.len(),
        "{title}: every level reached: {got:?}"
    );
    let mut worst = 0.0f64;
    for ((p, w), (_, sze)) in got.iter().zip(SZE) {
        let e = w / sze - 1.0;
        println!(
            "{title}, P/P_max {p:5.3}: 100 w {w:8.3} (Sze {sze:8.3}) {:+.2} %",
            100.0 * e
        );
        worst = worst.max(e.abs());
    }
    worst
}

#[test]
fn pinched_semi_cylinder_follows_sze_at_all_25_levels() {
    let worst = largest_error("stabilised", &deflections(&case_text("grid = [13, 25]")));
    // Measured on 13 × 25: largest error 2.17 % (at the first level, −0.4 … −1.3 % from 0.30 on),
    // 0.78 % on 17 × 33 (README). 2.5 % keeps a margin for round-off of the path while a
    // lost level, a false limit point, the checkerboard mode (without the stabilisation the
    // path turns at P/P_max ≈ 0.1) or the other edge reading (u_x held: −21 % at 0.30) fails.
    assert!(worst < 0.025, "largest error {worst:e}");
}

/// The same case with the normalised director field and no stabilisation
/// (`integration.director = "normalised"`, docs/stability.md §9), against the interpolated
/// field without it.
#[test]
fn normalised_director_follows_sze_without_stabilisation() {
    let base = case_text("grid = [13, 25]");
    let line = base
        .lines()
        .find(|l| l.starts_with("director_stabilisation = "))
        .unwrap()
        .to_string();
    // The shipped case names the interpolated field beside its stabilisation.
    let named = base
        .lines()
        .find(|l| l.starts_with("director = \"interpolated\""))
        .unwrap()
        .to_string();
    let base = base.replace(&format!("{named}\n"), "");
    let got = deflections(&base.replace(&line, "director = \"normalised\""));
    let worst = largest_error("normalised", &got);
    // Measured on 13 × 25: largest error 2.57 % (−2.52 % at P_max; 1.28 % on 17 × 33, 0.80 %
    // on 21 × 41, converging from below). 3 % keeps a margin for round-off of the path while a
    // false limit point or a lost level fails.
    assert!(worst < 0.03, "largest error {worst:e}");
    // The interpolated field without the stabilisation: the checkerboard mode's false limit
    // point before P/P_max = 0.1 (docs/stability.md §2), so at most the first level.
    let interpolated = deflections(&base.replace(&line, "director = \"interpolated\""));
    println!("interpolated, no stabilisation: {interpolated:?}");
    assert!(interpolated.len() <= 1, "{interpolated:?}");
}
