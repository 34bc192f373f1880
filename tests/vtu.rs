//! VTU/PVD output: files written by `shelldsa::io::vtu` are checked twice, by a small pure-Rust
//! scan of the XML (counts and bit-exact numbers) and by an independent reader,
//! `tests/read_vtu.py`, which uses the `meshio` Python package. meshio must be installed
//! (`pip install meshio`); the test fails, rather than skips, without it.

use serde_json::{json, Value};
use shelldsa::io::vtu::{Cell, PvdCollection, VtuError, VtuMesh, VtuWriter};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicUsize, Ordering};

/// A fresh directory under the system temp dir, unique per process, test and call.
fn unique_dir(tag: &str) -> PathBuf {
    static COUNTER: AtomicUsize = AtomicUsize::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    let dir = std::env::temp_dir().join(format!(
        "shelldsa-vtu-{tag}-{}-{nanos}-{}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Values that stress round-tripping, mixed into the test arrays.
const AWKWARD: [f64; 8] = [
    0.1,
    1.0 / 3.0,
    -0.0,
    5e-324,
    1.797_693_134_862_315_7e308,
    -2.225_073_858_507_201e-308,
    123_456_789.012_345_68,
    -7.0,
];

fn value(seed: usize, k: usize) -> f64 {
    let base = (seed as f64 + 1.0) * 0.37 + k as f64 / 7.0 - 3.0;
    if (seed + k) % 5 == 0 {
        AWKWARD[(seed * 3 + k) % AWKWARD.len()]
    } else {
        base
    }
}

fn values(seed: usize, n: usize) -> Vec<f64> {
    (0..n).map(|k| value(seed, k)).collect()
}

/// One array: name, components, flat values.
struct Arr {
    name: &'static str,
    n_components: usize,
    values: Vec<f64>,
}

/// A test file: mesh, arrays and the expected meshio view of its cells.
struct Case {
    file: String,
    mesh: VtuMesh,
    point: Vec<Arr>,
    cell: Vec<Arr>,
}

impl Case {
    fn writer(&self) -> VtuWriter {
        let mut w = VtuWriter::new(self.mesh.clone());
        for a in &self.point {
            w = match a.n_components {
                1 => w.point_scalar(a.name, &a.values),
                3 => {
                    let v: Vec<[f64; 3]> = a.values.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
                    w.point_vector(a.name, &v)
                }
                k => w.point_array(a.name, k, &a.values),
            };
        }
        for a in &self.cell {
            w = match a.n_components {
                1 => w.cell_scalar(a.name, &a.values),
                3 => {
                    let v: Vec<[f64; 3]> = a.values.chunks(3).map(|c| [c[0], c[1], c[2]]).collect();
                    w.cell_vector(a.name, &v)
                }
                k => w.cell_array(a.name, k, &a.values),
            };
        }
        w
    }

    /// Expected content for read_vtu.py. meshio groups consecutive cells of one type into a
    /// block, so the blocks are the runs of equal type.
    fn expected(&self) -> Value {
        let mut blocks: Vec<(&str, Vec<Vec<usize>>)> = Vec::new();
        for c in &self.mesh.cells {
            let t = match c {
                Cell::Vertex(_) => "vertex",
                Cell::Triangle(_) => "triangle",
                Cell::Quad(_) => "quad",
            };
            match blocks.last_mut() {
                Some((bt, conn)) if *bt == t => conn.push(c.points().to_vec()),
                _ => blocks.push((t, vec![c.points().to_vec()])),
            }
        }
        let arrays = |v: &[Arr]| -> Value {
            v.iter()
                .map(|a| {
                    (
                        a.name.to_string(),
                        json!({"n_components": a.n_components, "values": a.values}),
                    )
                })
                .collect::<serde_json::Map<_, _>>()
                .into()
        };
        json!({
            "file": self.file,
            "points": self.mesh.points,
            "cells": blocks.iter().map(|(t, c)| json!({"type": t, "connectivity": c})).collect::<Vec<_>>(),
            "point_data": arrays(&self.point),
            "cell_data": arrays(&self.cell),
        })
    }
}

/// 4 × 3 grid on a cylindrical patch with scalar, vector, 5-, 6- and 9-component point arrays
/// and scalar and vector cell arrays. `step` perturbs values.
fn grid_case(step: usize) -> Case {
    let (n_u, n_v) = (4, 3);
    let mut pts = Vec::new();
    for i in 0..n_u {
        for j in 0..n_v {
            let th = 0.4 * i as f64 + 0.01 * step as f64;
            pts.push([2.0 * th.cos(), 2.0 * th.sin(), 0.5 * j as f64 + 0.1]);
        }
    }
    let mesh = VtuMesh::structured_grid(n_u, n_v, pts).unwrap();
    let (np, nc) = (mesh.points.len(), mesh.cells.len());
    assert_eq!((np, nc), (12, 6));
    Case {
        file: format!("step_{step:04}.vtu"),
        mesh,
        point: vec![
            Arr {
                name: "thickness",
                n_components: 1,
                values: values(step * 10 + 1, np),
            },
            Arr {
                name: "displacement",
                n_components: 3,
                values: values(step * 10 + 2, 3 * np),
            },
            Arr {
                name: "stress σ (shell, 5)",
                n_components: 5,
                values: values(step * 10 + 3, 5 * np),
            },
            Arr {
                name: "strain_sym6",
                n_components: 6,
                values: values(step * 10 + 4, 6 * np),
            },
            Arr {
                name: "F <deformation & \"gradient\">",
                n_components: 9,
                values: values(step * 10 + 5, 9 * np),
            },
        ],
        cell: vec![
            Arr {
                name: "plastic",
                n_components: 1,
                values: values(step * 10 + 6, nc),
            },
            Arr {
                name: "normal",
                n_components: 3,
                values: values(step * 10 + 7, 3 * nc),
            },
        ],
    }
}

/// A particle cloud (VTK_VERTEX cells).
fn cloud_case() -> Case {
    let pts: Vec<[f64; 3]> = (0..7)
        .map(|k| [k as f64 * 0.25, (k as f64).sqrt(), -1.0 / (k as f64 + 3.0)])
        .collect();
    let mesh = VtuMesh::point_cloud(pts);
    Case {
        file: "particles.vtu".into(),
        mesh,
        point: vec![
            Arr {
                name: "support radius",
                n_components: 1,
                values: values(91, 7),
            },
            Arr {
                name: "dU/dtau",
                n_components: 3,
                values: values(92, 21),
            },
        ],
        cell: vec![Arr {
            name: "id",
            n_components: 1,
            values: (0..7).map(|k| k as f64).collect(),
        }],
    }
}

/// Triangles then quads (two meshio blocks).
fn mixed_case() -> Case {
    let pts = vec![
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [2.0, 0.0, 0.1],
        [2.0, 1.0, 0.1],
    ];
    let mesh = VtuMesh {
        points: pts,
        cells: vec![
            Cell::Triangle([0, 1, 2]),
            Cell::Triangle([0, 2, 3]),
            Cell::Quad([1, 4, 5, 2]),
        ],
    };
    Case {
        file: "mixed.vtu".into(),
        mesh,
        point: vec![Arr {
            name: "T",
            n_components: 1,
            values: values(81, 6),
        }],
        cell: vec![Arr {
            name: "area",
            n_components: 1,
            values: vec![0.5, 0.5, 1.005],
        }],
    }
}

/// Pure-Rust scan of a written VTU: tags balance, counts are right, and every DataArray's numbers
/// parse back bit for bit.
fn scan_vtu(path: &Path, case: &Case) -> usize {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.starts_with("<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\""));
    for tag in [
        "VTKFile",
        "UnstructuredGrid",
        "Piece",
        "PointData",
        "CellData",
        "Points",
        "Cells",
        "DataArray",
    ] {
        let open =
            text.matches(&format!("<{tag} ")).count() + text.matches(&format!("<{tag}>")).count();
        let close = text.matches(&format!("</{tag}>")).count();
        assert_eq!(open, close, "<{tag}> not balanced in {}", path.display());
    }
    let (np, nc) = (case.mesh.points.len(), case.mesh.cells.len());
    assert!(text.contains(&format!(
        "<Piece NumberOfPoints=\"{np}\" NumberOfCells=\"{nc}\">"
    )));
    // 3 cell arrays + the points + the named arrays.
    let n_arrays = text.matches("<DataArray ").count();
    assert_eq!(n_arrays, 4 + case.point.len() + case.cell.len());

    let mut checked = 0;
    let mut rest = text.as_str();
    let mut float_arrays: Vec<(String, usize, Vec<f64>)> = Vec::new();
    let mut int_arrays: Vec<(String, Vec<i64>)> = Vec::new();
    while let Some(start) = rest.find("<DataArray ") {
        let head_end = start + rest[start..].find('>').unwrap();
        let head = &rest[start..head_end];
        let body_end = head_end + rest[head_end..].find("</DataArray>").unwrap();
        let body = &rest[head_end + 1..body_end];
        let attr = |a: &str| -> Option<String> {
            let k = head.find(&format!(" {a}=\""))? + a.len() + 3;
            Some(head[k..k + head[k..].find('"').unwrap()].to_string())
        };
        assert_eq!(attr("format").as_deref(), Some("ascii"));
        let name = attr("Name").unwrap_or_else(|| "points".into());
        if attr("type").as_deref() == Some("Float64") {
            let k: usize = attr("NumberOfComponents").unwrap().parse().unwrap();
            let v = body
                .split_whitespace()
                .map(|t| t.parse::<f64>().unwrap())
                .collect();
            float_arrays.push((name, k, v));
        } else {
            let v = body
                .split_whitespace()
                .map(|t| t.parse::<i64>().unwrap())
                .collect();
            int_arrays.push((name, v));
        }
        rest = &rest[body_end..];
    }
    let unescape = |s: &str| {
        s.replace("&lt;", "<")
            .replace("&gt;", ">")
            .replace("&quot;", "\"")
            .replace("&apos;", "'")
            .replace("&amp;", "&")
    };
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let expected_float: Vec<(String, usize, &[f64])> = case
        .point
        .iter()
        .chain(&case.cell)
        .map(|a| (a.name.to_string(), a.n_components, a.values.as_slice()))
        .chain([("points".to_string(), 3, case.mesh.points.as_flattened())])
        .collect();
    assert_eq!(float_arrays.len(), expected_float.len());
    for ((name, k, v), (ename, ek, ev)) in float_arrays.iter().zip(&expected_float) {
        assert_eq!(&unescape(name), ename);
        assert_eq!(k, ek, "{name}");
        assert_eq!(bits(v), bits(ev), "{name}: numbers do not round-trip");
        checked += v.len();
    }
    let conn: Vec<i64> = case
        .mesh
        .cells
        .iter()
        .flat_map(|c| c.points().iter().map(|&p| p as i64))
        .collect();
    let mut offsets = Vec::new();
    let mut o = 0;
    for c in &case.mesh.cells {
        o += c.points().len() as i64;
        offsets.push(o);
    }
    let types: Vec<i64> = case
        .mesh
        .cells
        .iter()
        .map(|c| c.vtk_type() as i64)
        .collect();
    assert_eq!(
        int_arrays,
        vec![
            ("connectivity".to_string(), conn),
            ("offsets".to_string(), offsets),
            ("types".to_string(), types)
        ]
    );
    checked
}

/// The `(timestep, file)` entries of a written PVD.
fn scan_pvd(path: &Path) -> Vec<(f64, String)> {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains("<VTKFile type=\"Collection\""));
    assert!(text.trim_end().ends_with("</VTKFile>"), "truncated PVD");
    text.lines()
        .filter(|l| l.trim_start().starts_with("<DataSet "))
        .map(|l| {
            let get = |a: &str| {
                let k = l.find(&format!(" {a}=\"")).unwrap() + a.len() + 3;
                l[k..k + l[k..].find('"').unwrap()].to_string()
            };
            (get("timestep").parse().unwrap(), get("file"))
        })
        .collect()
}

fn require_meshio() {
    let ok = Command::new("python3")
        .args(["-c", "import meshio"])
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    assert!(
        ok,
        "the independent VTU check needs Python 3 with meshio: `python3 -c \"import meshio\"` \
         failed. Run `pip install meshio` (it brings numpy) and re-run the tests."
    );
}

#[test]
fn vtu_and_pvd_read_back_by_rust_scan_and_meshio() {
    require_meshio();
    let dir = unique_dir("roundtrip");
    let mut expected_vtu = Vec::new();

    // A 3-step series, written as a solver would: each step's VTU, then the PVD rewritten.
    let pvd_path = dir.join("series.pvd");
    let mut pvd = PvdCollection::new(&pvd_path);
    let times = [0.25, 0.5, 1.0 / 3.0 + 1.0];
    let mut floats = 0;
    for (s, &t) in times.iter().enumerate() {
        let case = grid_case(s + 1);
        case.writer().write(&dir.join(&case.file)).unwrap();
        floats += scan_vtu(&dir.join(&case.file), &case);
        pvd.add_and_write(t, &case.file).unwrap();
        // After every step the collection on disk is complete for the steps so far.
        let entries = scan_pvd(&pvd_path);
        assert_eq!(entries.len(), s + 1);
        for (k, (et, ef)) in entries.iter().enumerate() {
            assert_eq!(et.to_bits(), times[k].to_bits());
            assert_eq!(ef, &format!("step_{:04}.vtu", k + 1));
        }
        assert!(!dir.join("series.pvd.tmp").exists());
        expected_vtu.push(case.expected());
    }
    for case in [cloud_case(), mixed_case()] {
        case.writer().write(&dir.join(&case.file)).unwrap();
        floats += scan_vtu(&dir.join(&case.file), &case);
        expected_vtu.push(case.expected());
    }
    assert!(floats > 1000, "{floats}");

    let expected = json!({
        "vtu": expected_vtu,
        "pvd": [{
            "file": "series.pvd",
            "entries": times.iter().enumerate().map(|(k, t)| json!({"time": t, "file": format!("step_{:04}.vtu", k + 1)})).collect::<Vec<_>>(),
        }],
    });
    std::fs::write(
        dir.join("expected.json"),
        serde_json::to_string_pretty(&expected).unwrap(),
    )
    .unwrap();

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/read_vtu.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg(&dir)
        .output()
        .expect("cannot run python3");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    println!("{stdout}{stderr}");
    assert!(
        out.status.success(),
        "independent reader tests/read_vtu.py rejected the files in {}:\n{stdout}\n{stderr}",
        dir.display()
    );
    assert!(
        stdout.contains("read_vtu.py: OK (5 vtu, 1 pvd)"),
        "{stdout}"
    );
    // SHELLDSA_KEEP_TEST_OUTPUT=1 keeps the files (to open them in ParaView).
    if std::env::var_os("SHELLDSA_KEEP_TEST_OUTPUT").is_some() {
        println!("kept {}", dir.display());
    } else {
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

fn err_of(w: VtuWriter, dir: &Path) -> String {
    let path = dir.join("bad.vtu");
    let e = w.write(&path).unwrap_err().to_string();
    assert!(!path.exists(), "nothing may be written on error ({e})");
    e
}

#[test]
fn errors_name_the_array_and_lengths() {
    let dir = unique_dir("errors");
    let case = grid_case(0);
    let np = case.mesh.points.len();
    let nc = case.mesh.cells.len();

    // Wrong length: names array, expected and actual counts.
    let e = err_of(
        case.writer()
            .point_array("stress", 5, &vec![0.0; 5 * np - 5]),
        &dir,
    );
    assert!(
        e.contains("point array `stress`") && e.contains("expected 60") && e.contains("got 55"),
        "{e}"
    );
    let e = err_of(
        case.writer().point_vector("U", &vec![[0.0; 3]; np + 1]),
        &dir,
    );
    assert!(
        e.contains("`U`") && e.contains("expected 36") && e.contains("got 39"),
        "{e}"
    );
    let e = err_of(case.writer().cell_scalar("eqps", &vec![0.0; nc + 2]), &dir);
    assert!(
        e.contains("cell array `eqps`") && e.contains("expected 6") && e.contains("got 8"),
        "{e}"
    );
    match case
        .writer()
        .point_scalar("h", &[1.0; 3])
        .validate()
        .unwrap_err()
    {
        VtuError::Length {
            location,
            array,
            expected,
            actual,
            ..
        } => assert_eq!(
            (location, array.as_str(), expected, actual),
            ("point", "h", 12, 3)
        ),
        other => panic!("{other:?}"),
    }

    // Non-finite values: array, point and component named.
    let mut v = vec![0.0; 9 * np];
    v[9 * 4 + 7] = f64::NAN;
    let e = err_of(case.writer().point_array("F", 9, &v), &dir);
    assert!(
        e.contains("`F`")
            && e.contains("point 4")
            && e.contains("component 7")
            && e.contains("NaN"),
        "{e}"
    );
    let mut pts = case.mesh.points.clone();
    pts[2][1] = f64::INFINITY;
    let e = err_of(
        VtuWriter::new(VtuMesh {
            points: pts,
            cells: vec![],
        }),
        &dir,
    );
    assert!(
        e.contains("`points`") && e.contains("point 2") && e.contains("component 1"),
        "{e}"
    );

    // Names: duplicate, empty; zero components.
    let e = err_of(
        case.writer().point_scalar("thickness", &vec![0.0; np]),
        &dir,
    );
    assert!(e.contains("`thickness`") && e.contains("twice"), "{e}");
    // The same name on points and cells is allowed.
    case.writer()
        .cell_scalar("thickness", &vec![0.0; nc])
        .validate()
        .unwrap();
    let e = err_of(case.writer().cell_scalar("", &vec![0.0; nc]), &dir);
    assert!(
        e.contains("cell array number 2") && e.contains("empty name"),
        "{e}"
    );
    let e = err_of(case.writer().point_array("z", 0, &[]), &dir);
    assert!(e.contains("`z`") && e.contains("at least 1"), "{e}");

    // Cells referring to missing points; bad grid size.
    let e = err_of(
        VtuWriter::new(VtuMesh {
            points: vec![[0.0; 3]; 3],
            cells: vec![Cell::Vertex(0), Cell::Triangle([0, 1, 3])],
        }),
        &dir,
    );
    assert!(
        e.contains("cell 1") && e.contains("point 3") && e.contains("3 points"),
        "{e}"
    );
    let e = VtuMesh::structured_grid(4, 3, vec![[0.0; 3]; 11])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("4 × 3") && e.contains("expected 12") && e.contains("got 11"),
        "{e}"
    );

    // Unwritable path.
    let e = case
        .writer()
        .write(&dir.join("no/such/dir/x.vtu"))
        .unwrap_err();
    assert!(
        matches!(e, VtuError::Io { .. }) && e.to_string().contains("x.vtu"),
        "{e}"
    );

    // PVD: times finite and increasing, files relative; a rejected entry leaves the file alone.
    let pvd_path = dir.join("s.pvd");
    let mut pvd = PvdCollection::new(&pvd_path);
    pvd.add_and_write(0.0, "a.vtu").unwrap();
    pvd.add_and_write(1.0, "sub/b.vtu").unwrap();
    let e = pvd.add(1.0, "c.vtu").unwrap_err().to_string();
    assert!(
        e.contains("entry 2") && e.contains("`c.vtu`") && e.contains("time 1"),
        "{e}"
    );
    let e = pvd.add(f64::NAN, "c.vtu").unwrap_err().to_string();
    assert!(e.contains("NaN"), "{e}");
    let e = pvd.add(2.0, "/abs/c.vtu").unwrap_err().to_string();
    assert!(e.contains("/abs/c.vtu") && e.contains("relative"), "{e}");
    assert!(pvd.add(2.0, "").is_err());
    assert_eq!(pvd.entries().len(), 2);
    assert_eq!(
        scan_pvd(&pvd_path),
        vec![(0.0, "a.vtu".to_string()), (1.0, "sub/b.vtu".to_string())]
    );

    std::fs::remove_dir_all(&dir).unwrap();
}
