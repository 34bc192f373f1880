//! The three-way check of a `shelldsa dsa` run's sensitivity.json, shared by the whole-run
//! tests.

use serde_json::Value;

/// Every variable of `a` (sensitivity.json): continuum = dual within 1e-8 relative on the
/// components with |ψ'| ≥ 1e-6 max|ψ'| of the variable; the dual against central differences
/// at the second step (h/τ = 1e-4: truncation ~1e-8, re-run noise up to 1e-10 of the response
/// over h/τ) within 1e-6 where the active set holds; Taylor rates within 2 ± 0.1. Returns the
/// number of variables.
pub fn assert_three_ways(a: &Value) -> usize {
    let vars = a["variables"].as_array().unwrap();
    for v in vars {
        let name = v["name"].as_str().unwrap();
        let big = v["steps"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|s| s["monitors"].as_object().unwrap().values())
            .map(|c| c["dual"].as_f64().unwrap().abs())
            .fold(0.0, f64::max);
        assert!(big > 0.0, "{name}");
        let (mut worst_cd, mut worst_fd, mut compared) = (0.0f64, 0.0f64, 0);
        for s in v["steps"].as_array().unwrap() {
            for (label, c) in s["monitors"].as_object().unwrap() {
                let dual = c["dual"].as_f64().unwrap();
                let cont = c["continuum"].as_f64().unwrap();
                if dual.abs() < 1e-6 * big {
                    continue;
                }
                let e = (cont / dual - 1.0).abs();
                worst_cd = worst_cd.max(e);
                assert!(
                    e < 1e-8,
                    "{name} step {} {label}: {cont} vs {dual}",
                    s["step"]
                );
                if s["fd_flagged"][1].as_bool().unwrap() {
                    continue;
                }
                let fd = c["fd_central"][1].as_f64().unwrap();
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
