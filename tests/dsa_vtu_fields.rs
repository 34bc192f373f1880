//! The sensitivity fields in the VTU files of `shelldsa dsa`, read back by an independent reader
//! (meshio, through `tests/read_vtu.py --dump`), on both paper examples in their CI sizes: the
//! reduced elastoplastic hemisphere (`verification/hemisphere-plastic-dsa/ci.toml`, Table 1's
//! design variables R, φ1, t, σ0) and the quarter sheet of the cylindrical bending
//! (`verification/cylindrical-bending-dsa/ci.toml`, Table 2's die positions), each with
//! `[output] vtu = true` and `--methods continuum,dual`.
//!
//! Checked for every written step, design variable and method: the point data `d_u/d_<var>
//! (<method>)` at the node of each monitored point equals the derivative `sensitivity.json`
//! records there; the two methods' fields agree everywhere (nodes and cells); the initial state
//! carries zero sensitivities; a cell without plastic strain has no plastic-strain sensitivity;
//! the files and the `.pvd` are those `sensitivity.json` lists. On the hemisphere the cell data
//! `d_eps_p_<layer>/d_t` are also checked against central differences of the `eps_p_<layer>`
//! cell data of two complete `shelldsa run`s at `t ± h`.
//!
//! meshio must be installed (`pip install meshio`); the tests fail, rather than skip, without it.

use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

#[path = "common/meshio.rs"]
mod meshio;
use meshio::{meshio_dump, num};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn unique_dir(tag: &str) -> PathBuf {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    let dir = std::env::temp_dir().join(format!(
        "shelldsa-dsa-vtu-{tag}-{}-{nanos}",
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn cleanup(dir: &Path) {
    // SHELLDSA_KEEP_TEST_OUTPUT=1 keeps the files (to open them in ParaView).
    if std::env::var_os("SHELLDSA_KEEP_TEST_OUTPUT").is_some() {
        println!("kept {}", dir.display());
    } else {
        let _ = std::fs::remove_dir_all(dir);
    }
}

/// A CI case's text with its VTU output switched on.
fn case_text(rel: &str) -> String {
    let t = std::fs::read_to_string(root().join(rel)).unwrap();
    assert!(t.contains("\nvtu = false"), "{rel}: expected `vtu = false`");
    t.replace("\nvtu = false", "\nvtu = true")
}

fn shelldsa(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_shelldsa"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "shelldsa {args:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// One VTU as read by meshio: named point and cell arrays, one row per point or cell.
struct Vtu {
    point: BTreeMap<String, Vec<Vec<f64>>>,
    cell: BTreeMap<String, Vec<Vec<f64>>>,
}

fn arrays(v: &Value) -> BTreeMap<String, Vec<Vec<f64>>> {
    v.as_object()
        .unwrap()
        .iter()
        .map(|(k, rows)| {
            let t = rows
                .as_array()
                .unwrap()
                .iter()
                .map(|r| r.as_array().unwrap().iter().map(num).collect())
                .collect();
            (k.clone(), t)
        })
        .collect()
}

impl Vtu {
    fn of(v: &Value) -> Self {
        Vtu {
            point: arrays(&v["point_data"]),
            cell: arrays(&v["cell_data"]),
        }
    }
    fn point(&self, name: &str) -> &Vec<Vec<f64>> {
        self.point
            .get(name)
            .unwrap_or_else(|| panic!("no point array `{name}`: {:?}", self.point.keys()))
    }
    fn cell(&self, name: &str) -> &Vec<Vec<f64>> {
        self.cell
            .get(name)
            .unwrap_or_else(|| panic!("no cell array `{name}`: {:?}", self.cell.keys()))
    }
}

fn max_abs<'a>(rows: impl IntoIterator<Item = &'a Vec<f64>>) -> f64 {
    rows.into_iter()
        .flatten()
        .fold(0.0f64, |a, x| a.max(x.abs()))
}

const METHODS: [&str; 2] = ["continuum", "dual"];
const LAYERS: [&str; 3] = ["top", "mid", "bottom"];

/// `shelldsa dsa` on the case at `rel` (VTU on) in a fresh directory, every check of the module
/// documentation; returns the directory, sensitivity.json and the VTUs by step.
fn run_and_check(rel: &str, tag: &str) -> (PathBuf, Value, Vec<Vtu>) {
    let dir = unique_dir(tag);
    let case = dir.join("case.toml");
    std::fs::write(&case, case_text(rel)).unwrap();
    let out = dir.join("dsa");
    shelldsa(&[
        "dsa",
        case.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--methods",
        "continuum,dual",
    ]);
    let json: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("sensitivity.json")).unwrap())
            .unwrap();
    assert_eq!(json["status"], "complete");
    let loads: Vec<f64> = json["loads"]
        .as_array()
        .unwrap()
        .iter()
        .map(|l| l.as_f64().unwrap())
        .collect();

    // The files: step 0 and every converged step (`every` = 1), as listed and in the .pvd.
    let listed = json["vtu"]["steps"].as_array().unwrap();
    assert_eq!(json["vtu"]["collection"], "shell.pvd");
    assert!(json["vtu"]["error"].is_null());
    assert_eq!(listed.len(), loads.len() + 1);
    for (s, e) in listed.iter().enumerate() {
        assert_eq!(e["step"].as_u64().unwrap() as usize, s);
        assert_eq!(e["file"], format!("steps/step_{s:04}.vtu"));
        let want = if s == 0 { 0.0 } else { loads[s - 1] };
        assert_eq!(e["load"].as_f64().unwrap(), want);
    }
    let mut paths = vec![out.join("shell.pvd")];
    paths.extend(listed.iter().map(|e| out.join(e["file"].as_str().unwrap())));
    let dump = meshio_dump(&paths);
    let pvd = &dump[paths[0].to_str().unwrap()]["entries"];
    let pvd = pvd.as_array().unwrap();
    assert_eq!(pvd.len(), listed.len());
    for (p, e) in pvd.iter().zip(listed) {
        assert_eq!(p["file"], e["file"]);
        // meshio/Python read the time exactly, serde_json's default parser may be an ulp off.
        let (a, b) = (num(&p["time"]), e["load"].as_f64().unwrap());
        assert!(
            (a - b).abs() <= 1e-15 * b.abs(),
            "pvd time {a} for load {b}"
        );
    }
    let vtus: Vec<Vtu> = paths[1..]
        .iter()
        .map(|p| Vtu::of(&dump[p.to_str().unwrap()]))
        .collect();

    let names: Vec<String> = json["variables"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["name"].as_str().unwrap().to_string())
        .collect();
    let uv = vtus[0].point("uv").clone();

    // The initial state: zero sensitivities.
    for name in &names {
        for m in METHODS {
            assert_eq!(max_abs(vtus[0].point(&format!("d_u/d_{name} ({m})"))), 0.0);
            for l in LAYERS {
                assert_eq!(
                    max_abs(vtus[0].cell(&format!("d_eps_p_{l}/d_{name} ({m})"))),
                    0.0
                );
            }
        }
    }

    // At each monitored point: the field at its node equals sensitivity.json's derivative.
    // Both are the same f64 (`ShellModel::interpolate_translation` of the same sensitivity
    // vector at the same (u, v)), written with round-trip formatting; meshio reads the VTU
    // exactly, serde_json's default float parser may be an ulp off (measured ≤ 1.3e-16 of the
    // largest derivative). 1e-12 of the variable's largest derivative allows for that and a
    // reordered sum, nothing more.
    let monitors = json["monitors"].as_array().unwrap();
    let mut checked = 0;
    for (v, var) in json["variables"].as_array().unwrap().iter().enumerate() {
        for m in METHODS {
            let array = format!("d_u/d_{} ({m})", names[v]);
            let steps = var["steps"].as_array().unwrap();
            let scale = steps
                .iter()
                .flat_map(|s| s["monitors"].as_object().unwrap().values())
                .map(|c| c[m].as_f64().unwrap().abs())
                .fold(0.0f64, f64::max);
            assert!(scale > 0.0, "{array}: all monitored derivatives zero");
            let mut worst = 0.0f64;
            for (s, step) in steps.iter().enumerate() {
                let field = vtus[s + 1].point(&array);
                for mon in monitors {
                    let at = [
                        mon["uv"][0].as_f64().unwrap(),
                        mon["uv"][1].as_f64().unwrap(),
                    ];
                    let node = uv
                        .iter()
                        .position(|p| p[0] == at[0] && p[1] == at[1])
                        .unwrap_or_else(|| panic!("monitor {mon} is not at an output node"));
                    let c = mon["component"].as_u64().unwrap() as usize;
                    let want = step["monitors"][mon["label"].as_str().unwrap()][m]
                        .as_f64()
                        .unwrap();
                    worst = worst.max((field[node][c] - want).abs() / scale);
                    checked += 1;
                }
            }
            println!("{rel}: {array} at the monitors: max |field − json| / max |ψ'| = {worst:.2e}");
            assert!(worst <= 1e-12, "{array}: {worst:e}");
        }
    }
    assert_eq!(
        checked,
        names.len() * METHODS.len() * loads.len() * monitors.len()
    );

    // The two methods' fields everywhere: the continuum = dual criterion (1e-8 of the
    // largest |dual| value of the field over all steps); a cell with no plastic strain in a
    // layer has none of its sensitivity either (its layer points never yielded).
    for name in &names {
        let mut pairs = vec![format!("d_u/d_{name}")];
        pairs.extend(LAYERS.iter().map(|l| format!("d_eps_p_{l}/d_{name}")));
        for (k, base) in pairs.iter().enumerate() {
            let get = |t: &Vtu, m: &str| {
                let a = format!("{base} ({m})");
                if k == 0 {
                    t.point(&a).clone()
                } else {
                    t.cell(&a).clone()
                }
            };
            let scale = vtus
                .iter()
                .map(|t| max_abs(&get(t, "dual")))
                .fold(0.0f64, f64::max);
            let diff = vtus
                .iter()
                .map(|t| {
                    get(t, "continuum")
                        .iter()
                        .flatten()
                        .zip(get(t, "dual").iter().flatten())
                        .fold(0.0f64, |a, (x, y)| a.max((x - y).abs()))
                })
                .fold(0.0f64, f64::max);
            let rel_diff = if scale > 0.0 { diff / scale } else { diff };
            println!("{rel}: {base}: continuum vs dual {rel_diff:.2e} of max {scale:.3e}");
            assert!(rel_diff <= 1e-8, "{base}: {rel_diff:e}");
            if k > 0 {
                for t in &vtus {
                    let ep = t.cell(&format!("eps_p_{}", LAYERS[k - 1]));
                    for m in METHODS {
                        for (c, d) in ep.iter().zip(&get(t, m)) {
                            if c[0] == 0.0 {
                                assert_eq!(d[0], 0.0, "{base} ({m}) where eps_p = 0");
                            }
                        }
                    }
                }
            }
        }
    }
    (dir, json, vtus)
}

/// The reduced hemisphere (Table 1's variables): the checks above, and the plastic-strain
/// sensitivity fields of the thickness against central differences of complete re-runs.
#[test]
fn hemisphere_sensitivity_fields() {
    let rel = "verification/hemisphere-plastic-dsa/ci.toml";
    let (dir, json, vtus) = run_and_check(rel, "hemisphere");
    let last = vtus.last().unwrap();
    // The case yields: the plastic-strain sensitivities are not all zero at the last step.
    assert!(max_abs(last.cell("eps_p_top")) > 0.0);
    for name in ["R", "phi1", "t", "sigma0"] {
        assert!(max_abs(last.cell(&format!("d_eps_p_top/d_{name} (continuum)"))) > 0.0);
    }

    // `eps_p_<layer>` of the plain runs at t ± h; the thickness does not move the geometry, so
    // the cell means' weights are the same in the three runs and the central difference of the
    // cell data is the derivative of the cell mean.
    let t: f64 = json["variables"][2]["value"].as_f64().unwrap();
    assert_eq!(json["variables"][2]["kind"], "thickness");
    let h = 1e-4 * t;
    let text = case_text(rel);
    let line = text.lines().find(|l| l.starts_with("thickness =")).unwrap();
    let mut runs = Vec::new();
    for (tag, tau) in [("plus", t + h), ("minus", t - h)] {
        let case = dir.join(format!("{tag}.toml"));
        std::fs::write(
            &case,
            text.replacen(line, &format!("thickness = {tau:e}"), 1),
        )
        .unwrap();
        let out = dir.join(tag);
        shelldsa(&[
            "run",
            case.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let files: Vec<PathBuf> = (1..vtus.len())
            .map(|s| out.join(format!("steps/step_{s:04}.vtu")))
            .collect();
        let dump = meshio_dump(&files);
        runs.push(
            files
                .iter()
                .map(|f| Vtu::of(&dump[f.to_str().unwrap()]))
                .collect::<Vec<_>>(),
        );
    }
    for l in LAYERS {
        let d = format!("d_eps_p_{l}/d_t (continuum)");
        let scale = vtus.iter().map(|v| max_abs(v.cell(&d))).fold(0.0, f64::max);
        let mut worst = (0.0f64, 0, 0);
        for s in 1..vtus.len() {
            let plus = runs[0][s - 1].cell(&format!("eps_p_{l}"));
            let minus = runs[1][s - 1].cell(&format!("eps_p_{l}"));
            for (c, g) in vtus[s].cell(&d).iter().enumerate() {
                let fd = (plus[c][0] - minus[c][0]) / (2.0 * h);
                let e = (fd - g[0]).abs() / scale;
                if e > worst.0 {
                    worst = (e, s, c);
                }
            }
        }
        println!(
            "{rel}: {d} against central differences (h/t = 1e-4): max |fd − field| / max |field| \
             = {:.2e} (step {}, cell {}), max |field| = {scale:.3e}",
            worst.0, worst.1, worst.2
        );
        // As the monitors' central differences at h/τ = 1e-4 (tests/dsa_dual.rs, dsa_cli.rs):
        // h² truncation ~1e-8 relative plus the re-runs' convergence noise over h; no layer
        // point changes its yield status within ±h on this case (measured 1.9e-8).
        assert!(worst.0 <= 1e-5, "{d}: {:e}", worst.0);
    }
    cleanup(&dir);
}

/// The quarter sheet of the cylindrical bending (Table 2's die positions, contact and
/// springback): the checks above.
#[test]
fn cylindrical_bending_sensitivity_fields() {
    let rel = "verification/cylindrical-bending-dsa/ci.toml";
    let (dir, _json, vtus) = run_and_check(rel, "bending");
    let last = vtus.last().unwrap();
    assert!(max_abs(last.cell("eps_p_top")) > 0.0);
    assert!(last.cell.contains_key("contact_pressure_top"));
    for name in ["die.x", "die.z"] {
        assert!(max_abs(last.point(&format!("d_u/d_{name} (continuum)"))) > 0.0);
        assert!(max_abs(last.cell(&format!("d_eps_p_top/d_{name} (continuum)"))) > 0.0);
    }
    cleanup(&dir);
}
