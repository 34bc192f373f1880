//! VTU files read back by meshio (`tests/read_vtu.py --dump`): the independent reader of the
//! output tests.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

/// meshio's view of the files (see tests/read_vtu.py `--dump`), keyed by path.
pub fn meshio_dump(paths: &[PathBuf]) -> Value {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/read_vtu.py");
    let out = Command::new("python3")
        .arg(&script)
        .arg("--dump")
        .args(paths)
        .output()
        .expect("cannot run python3");
    assert!(
        out.status.success(),
        "tests/read_vtu.py --dump failed (is meshio installed? `pip install meshio`):\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// A float written by read_vtu.py (a repr string: parsed exactly).
pub fn num(v: &Value) -> f64 {
    v.as_str()
        .unwrap_or_else(|| panic!("expected a float string, got {v}"))
        .parse()
        .unwrap()
}
