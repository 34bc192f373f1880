//! The three-way check of a `shelldsa dsa` run's sensitivity.json, shared by the whole-run
//! tests.

use serde_json::Value;

/// Every variable of `a` (sensitivity.json): continuum = dual within 1e-8 relative on the
/// components with |ψ'| ≥ 1e-6 max|ψ'| of the variable (the required agreement), and both zero
/// where the dual is exactly zero; the dual against central differences at the second step
/// size (h/τ = 1e-4: truncation measured at ~1e-8 relative, falling as h²; the bound 1e-6
/// leaves room for re-run noise up to 1e-10 of the response over h/τ, far below any real
/// disagreement) where the active set holds, and below 1e-5 max|ψ'| where the dual finds no
/// sensitivity; Taylor rates within 2 ± 0.1 wherever two unflagged, non-exact sizes exist.
/// Returns the number of variables.
pub fn assert_three_ways(a: &Value) -> usize {
    let vars = a["variables"].as_array().unwrap();
    for v in vars {
        let name = v["name"].as_str().unwrap();
        let big = largest_dual(v);
        assert!(big > 0.0, "{name}");
        let (mut worst_cd, mut worst_fd, mut compared) = (0.0f64, 0.0f64, 0);
        for s in v["steps"].as_array().unwrap() {
            let flagged = s["fd_flagged"][1].as_bool().unwrap();
            for (label, c) in s["monitors"].as_object().unwrap() {
                let dual = c["dual"].as_f64().unwrap();
                let cont = c["continuum"].as_f64().unwrap();
                let fd = c["fd_central"][1].as_f64().unwrap();
                if dual == 0.0 {
                    // Exactly no sensitivity (σ0 before first yield): none from either path.
                    assert_eq!(cont, 0.0, "{name} step {} {label}", s["step"]);
                }
                if dual.abs() < 1e-6 * big {
                    // No sensitivity: central differences find none either, to their noise.
                    assert!(
                        flagged || fd.abs() < 1e-5 * big,
                        "{name} step {} {label}: fd {fd}, dual {dual}",
                        s["step"]
                    );
                    continue;
                }
                let e = (cont / dual - 1.0).abs();
                worst_cd = worst_cd.max(e);
                assert!(
                    e < 1e-8,
                    "{name} step {} {label}: {cont} vs {dual}",
                    s["step"]
                );
                if flagged {
                    continue;
                }
                let rel = (fd / dual - 1.0).abs();
                worst_fd = worst_fd.max(rel);
                assert!(
                    rel < 1e-6,
                    "{name} step {} {label}: fd {fd}, dual {dual}",
                    s["step"]
                );
                compared += 1;
            }
        }
        println!(
            "{name:>6}: continuum − dual {worst_cd:.2e}, dual − central (h/τ 1e-4) {worst_fd:.2e} \
             over {compared} components"
        );
        assert!(compared > 0, "{name}");
        for f in v["taylor"]["per_step"].as_array().unwrap() {
            if let Some(r) = f["rate"].as_f64() {
                assert!((r - 2.0).abs() < 0.1, "{name} step {}: rate {r}", f["step"]);
            }
        }
    }
    vars.len()
}

/// A variable's largest |ψ'| (dual) over its steps and monitors (the scale of the 1e-6 cut-off
/// of components that carry no sensitivity, e.g. σ0 before first yield).
pub fn largest_dual(v: &Value) -> f64 {
    v["steps"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|s| s["monitors"].as_object().unwrap().values())
        .map(|c| c["dual"].as_f64().unwrap().abs())
        .fold(0.0, f64::max)
}
