//! Results for ParaView: VTK XML UnstructuredGrid (`.vtu`) files and the `.pvd` collection that
//! indexes them as a time (load-step) series.
//!
//! Nothing numerical happens here: the caller hands over points, cells and named arrays of `f64`,
//! this module checks them and writes them.
//!
//! # Format
//!
//! Data are written **inline ASCII** (`format="ascii"`), one tuple per line, every number with
//! Rust's `{:e}` formatting of the `f64`, which is the shortest decimal that parses back to the
//! same bits. ASCII was chosen over base64 "binary" because shell results are small (thousands of
//! particles or grid points), the files stay readable and diffable, and there is no header-size
//! convention (`UInt32` vs `UInt64` byte-count prefixes) for a reader to disagree about. The file
//! declares `version="0.1"`, which every VTK/ParaView release and meshio read.
//!
//! # Checks (all done by [`VtuWriter::write`] before anything touches the disk)
//!
//! - every array has exactly `count × n_components` numbers (count = points or cells);
//! - array names are non-empty and unique among the point arrays, and among the cell arrays
//!   (a point array and a cell array may share a name, as in VTK);
//! - **no NaN or infinity is written**: a non-finite value is an error naming the array, the
//!   tuple index and the component. A converged step has finite results; a NaN in one is a bug
//!   to surface, and VTK's ASCII parser does not read `NaN`/`inf` back reliably;
//! - cell vertex indices are below the number of points.
//!
//! Names are XML-escaped, so any text is allowed.
//!
//! Files are written to `NAME.tmp` beside the target and then renamed over it, so a reader (or a
//! run killed mid-write) never sees a half-written file.

use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// VTK cell type number of a vertex.
pub const VTK_VERTEX: u8 = 1;
/// VTK cell type number of a triangle.
pub const VTK_TRIANGLE: u8 = 5;
/// VTK cell type number of a quadrilateral.
pub const VTK_QUAD: u8 = 9;

/// Errors of the VTU and PVD writers. Each names the array (or file) concerned.
#[derive(Debug, Error)]
pub enum VtuError {
    /// An array does not have one tuple per point (or per cell).
    #[error(
        "{location} array `{array}`: expected {expected} values ({count} {location}s × \
         {n_components} components), got {actual}"
    )]
    Length {
        /// `"point"` or `"cell"`.
        location: &'static str,
        /// Array name (`"points"` for the coordinates).
        array: String,
        /// Components per tuple.
        n_components: usize,
        /// Number of points or cells.
        count: usize,
        /// Expected number of values, `count × n_components`.
        expected: usize,
        /// Number of values given.
        actual: usize,
    },
    /// A NaN or infinite value.
    #[error(
        "{location} array `{array}`: value {value} at {location} {index}, component {component} \
         is not finite (NaN and infinity are not written)"
    )]
    NonFinite {
        /// `"point"` or `"cell"`.
        location: &'static str,
        /// Array name (`"points"` for the coordinates).
        array: String,
        /// Tuple (point or cell) index.
        index: usize,
        /// Component within the tuple.
        component: usize,
        /// The offending value.
        value: f64,
    },
    /// Two arrays of the same location with one name.
    #[error("{location} array name `{array}` is used twice")]
    DuplicateName {
        /// `"point"` or `"cell"`.
        location: &'static str,
        /// The repeated name.
        array: String,
    },
    /// An empty array name.
    #[error("{location} array number {position} has an empty name")]
    EmptyName {
        /// `"point"` or `"cell"`.
        location: &'static str,
        /// Position of the array among that location's arrays (0-based).
        position: usize,
    },
    /// An array declared with zero components.
    #[error("{location} array `{array}`: the number of components must be at least 1")]
    ZeroComponents {
        /// `"point"` or `"cell"`.
        location: &'static str,
        /// Array name.
        array: String,
    },
    /// A cell refers to a point that does not exist.
    #[error(
        "cell {cell}: vertex {vertex} refers to point {point}, but the mesh has {n_points} points"
    )]
    CellIndex {
        /// Cell index.
        cell: usize,
        /// Vertex position within the cell.
        vertex: usize,
        /// The point index given.
        point: usize,
        /// Number of points.
        n_points: usize,
    },
    /// [`VtuMesh::structured_grid`] got a wrong size.
    #[error(
        "structured grid {n_u} × {n_v}: expected {expected} points, got {actual} \
         (and n_u, n_v must both be at least 2)"
    )]
    GridSize {
        /// Points along u.
        n_u: usize,
        /// Points along v.
        n_v: usize,
        /// `n_u × n_v`.
        expected: usize,
        /// Points given.
        actual: usize,
    },
    /// A PVD entry with a non-finite or non-increasing time.
    #[error(
        "collection {path}: entry {index} (`{file}`) has time {time}, which must be finite and \
         greater than the previous entry's {previous}"
    )]
    PvdTime {
        /// The `.pvd` file.
        path: PathBuf,
        /// Entry index (0-based).
        index: usize,
        /// Its data file.
        file: String,
        /// The time given.
        time: f64,
        /// The previous entry's time (`-inf` for the first entry).
        previous: f64,
    },
    /// A PVD entry whose data-file path is absolute or empty.
    #[error(
        "collection {path}: data file `{file}` must be a non-empty path relative to the .pvd \
         file's folder"
    )]
    PvdFile {
        /// The `.pvd` file.
        path: PathBuf,
        /// The path given.
        file: String,
    },
    /// Writing the file failed.
    #[error("cannot write {path}: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
}

/// One cell of a [`VtuMesh`]: indices into its points.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cell {
    /// `VTK_VERTEX` (1): one particle.
    Vertex(usize),
    /// `VTK_TRIANGLE` (5), counter-clockwise seen from the side the normal points to.
    Triangle([usize; 3]),
    /// `VTK_QUAD` (9), counter-clockwise seen from the side the normal points to.
    Quad([usize; 4]),
}

impl Cell {
    /// The point indices.
    pub fn points(&self) -> &[usize] {
        match self {
            Cell::Vertex(p) => std::slice::from_ref(p),
            Cell::Triangle(p) => p,
            Cell::Quad(p) => p,
        }
    }

    /// The VTK cell type number.
    pub fn vtk_type(&self) -> u8 {
        match self {
            Cell::Vertex(_) => VTK_VERTEX,
            Cell::Triangle(_) => VTK_TRIANGLE,
            Cell::Quad(_) => VTK_QUAD,
        }
    }
}

/// Points in 3-D and the cells over them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct VtuMesh {
    /// Coordinates.
    pub points: Vec<[f64; 3]>,
    /// Cells.
    pub cells: Vec<Cell>,
}

impl VtuMesh {
    /// A particle cloud: one `VTK_VERTEX` cell per point, cell `i` = point `i`.
    pub fn point_cloud(points: Vec<[f64; 3]>) -> Self {
        let cells = (0..points.len()).map(Cell::Vertex).collect();
        VtuMesh { points, cells }
    }

    /// A structured `n_u × n_v` visualisation grid of quads.
    ///
    /// `points[i * n_v + j]` is the point at parameter node `(u_i, v_j)` (row-major, `v` varies
    /// fastest). The `(n_u - 1)(n_v - 1)` quads are numbered the same way: quad `i * (n_v - 1) + j`
    /// has corners `(i, j), (i+1, j), (i+1, j+1), (i, j+1)`, counter-clockwise in the `(u, v)`
    /// plane, so the quad normal points along `a_u × a_v`.
    pub fn structured_grid(
        n_u: usize,
        n_v: usize,
        points: Vec<[f64; 3]>,
    ) -> Result<Self, VtuError> {
        let expected = n_u * n_v;
        if n_u < 2 || n_v < 2 || points.len() != expected {
            return Err(VtuError::GridSize {
                n_u,
                n_v,
                expected,
                actual: points.len(),
            });
        }
        let id = |i: usize, j: usize| i * n_v + j;
        let mut cells = Vec::with_capacity((n_u - 1) * (n_v - 1));
        for i in 0..n_u - 1 {
            for j in 0..n_v - 1 {
                cells.push(Cell::Quad([
                    id(i, j),
                    id(i + 1, j),
                    id(i + 1, j + 1),
                    id(i, j + 1),
                ]));
            }
        }
        Ok(VtuMesh { points, cells })
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Location {
    Point,
    Cell,
}

impl Location {
    fn name(self) -> &'static str {
        match self {
            Location::Point => "point",
            Location::Cell => "cell",
        }
    }
}

#[derive(Clone, Debug)]
struct Array {
    name: String,
    n_components: usize,
    values: Vec<f64>,
}

/// Builds one `.vtu` file: a mesh and named point and cell arrays.
///
/// The builder methods only record; [`write`](Self::write) checks everything (see the module
/// documentation) and writes. Arrays appear in the file in the order they were added; the first
/// 1-component point array is marked as ParaView's active scalar and the first 3-component one as
/// its active vector (likewise for cell arrays).
///
/// ```no_run
/// use shelldsa::io::vtu::{VtuMesh, VtuWriter};
/// let mesh = VtuMesh::structured_grid(2, 2, vec![[0.0; 3], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [1.0; 3]])?;
/// VtuWriter::new(mesh)
///     .point_scalar("thickness", &[0.1; 4])
///     .point_vector("displacement", &[[0.0; 3]; 4])
///     .point_array("stress", 5, &[0.0; 20])
///     .cell_scalar("plastic", &[1.0])
///     .write("out/step_0001.vtu".as_ref())?;
/// # Ok::<(), shelldsa::io::vtu::VtuError>(())
/// ```
#[derive(Clone, Debug)]
pub struct VtuWriter {
    mesh: VtuMesh,
    point_data: Vec<Array>,
    cell_data: Vec<Array>,
}

impl VtuWriter {
    /// A writer for `mesh` with no arrays yet.
    pub fn new(mesh: VtuMesh) -> Self {
        VtuWriter {
            mesh,
            point_data: Vec::new(),
            cell_data: Vec::new(),
        }
    }

    /// The mesh.
    pub fn mesh(&self) -> &VtuMesh {
        &self.mesh
    }

    /// A 1-component point array (one value per point).
    pub fn point_scalar(self, name: &str, values: &[f64]) -> Self {
        self.point_array(name, 1, values)
    }

    /// A 3-component point array (one vector per point).
    pub fn point_vector(self, name: &str, values: &[[f64; 3]]) -> Self {
        self.point_array(name, 3, values.as_flattened())
    }

    /// A point array of `n_components` per point, stored point after point
    /// (`values[p * n_components + c]`). ParaView reads 9 components as a full tensor
    /// (row-major `XX XY XZ YX …`) and 6 as a symmetric one in the order `XX YY ZZ XY YZ XZ`;
    /// any other count (e.g. the 5-component shell stress `σ11 σ22 σ12 σ23 σ31`) is shown as
    /// numbered components.
    pub fn point_array(mut self, name: &str, n_components: usize, values: &[f64]) -> Self {
        self.point_data.push(Array {
            name: name.to_owned(),
            n_components,
            values: values.to_vec(),
        });
        self
    }

    /// A 1-component cell array (one value per cell).
    pub fn cell_scalar(self, name: &str, values: &[f64]) -> Self {
        self.cell_array(name, 1, values)
    }

    /// A 3-component cell array (one vector per cell).
    pub fn cell_vector(self, name: &str, values: &[[f64; 3]]) -> Self {
        self.cell_array(name, 3, values.as_flattened())
    }

    /// A cell array of `n_components` per cell, stored cell after cell (see
    /// [`point_array`](Self::point_array)).
    pub fn cell_array(mut self, name: &str, n_components: usize, values: &[f64]) -> Self {
        self.cell_data.push(Array {
            name: name.to_owned(),
            n_components,
            values: values.to_vec(),
        });
        self
    }

    /// Check the mesh and every array (see the module documentation); the first problem found is
    /// returned.
    pub fn validate(&self) -> Result<(), VtuError> {
        let n_points = self.mesh.points.len();
        let n_cells = self.mesh.cells.len();
        check_values(
            Location::Point,
            "points",
            3,
            n_points,
            self.mesh.points.as_flattened(),
        )?;
        for (c, cell) in self.mesh.cells.iter().enumerate() {
            for (vertex, &point) in cell.points().iter().enumerate() {
                if point >= n_points {
                    return Err(VtuError::CellIndex {
                        cell: c,
                        vertex,
                        point,
                        n_points,
                    });
                }
            }
        }
        for (location, arrays, count) in [
            (Location::Point, &self.point_data, n_points),
            (Location::Cell, &self.cell_data, n_cells),
        ] {
            let mut seen = HashSet::new();
            for (position, a) in arrays.iter().enumerate() {
                if a.name.is_empty() {
                    return Err(VtuError::EmptyName {
                        location: location.name(),
                        position,
                    });
                }
                if !seen.insert(a.name.as_str()) {
                    return Err(VtuError::DuplicateName {
                        location: location.name(),
                        array: a.name.clone(),
                    });
                }
                if a.n_components == 0 {
                    return Err(VtuError::ZeroComponents {
                        location: location.name(),
                        array: a.name.clone(),
                    });
                }
                check_values(location, &a.name, a.n_components, count, &a.values)?;
            }
        }
        Ok(())
    }

    /// The file contents (after [`validate`](Self::validate)).
    pub fn to_xml(&self) -> Result<String, VtuError> {
        self.validate()?;
        let mesh = &self.mesh;
        let mut s = String::new();
        // `write!` into a String cannot fail; the results are ignored below for that reason.
        s.push_str("<?xml version=\"1.0\"?>\n");
        s.push_str(
            "<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n",
        );
        s.push_str("  <UnstructuredGrid>\n");
        let _ = writeln!(
            s,
            "    <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">",
            mesh.points.len(),
            mesh.cells.len()
        );
        write_attribute_block(&mut s, "PointData", &self.point_data);
        write_attribute_block(&mut s, "CellData", &self.cell_data);

        s.push_str("      <Points>\n");
        write_f64_array(&mut s, None, 3, mesh.points.as_flattened());
        s.push_str("      </Points>\n");

        s.push_str("      <Cells>\n");
        s.push_str("        <DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
        for cell in &mesh.cells {
            s.push_str("          ");
            for (k, p) in cell.points().iter().enumerate() {
                if k > 0 {
                    s.push(' ');
                }
                let _ = write!(s, "{p}");
            }
            s.push('\n');
        }
        s.push_str("        </DataArray>\n");
        s.push_str("        <DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
        let mut offset = 0;
        for cell in &mesh.cells {
            offset += cell.points().len();
            let _ = writeln!(s, "          {offset}");
        }
        s.push_str("        </DataArray>\n");
        s.push_str("        <DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
        for cell in &mesh.cells {
            let _ = writeln!(s, "          {}", cell.vtk_type());
        }
        s.push_str("        </DataArray>\n");
        s.push_str("      </Cells>\n");
        s.push_str("    </Piece>\n");
        s.push_str("  </UnstructuredGrid>\n");
        s.push_str("</VTKFile>\n");
        Ok(s)
    }

    /// Check everything, then write the `.vtu` file (via a temporary file renamed over `path`).
    pub fn write(&self, path: &Path) -> Result<(), VtuError> {
        let xml = self.to_xml()?;
        write_atomically(path, &xml)
    }
}

fn check_values(
    location: Location,
    array: &str,
    n_components: usize,
    count: usize,
    values: &[f64],
) -> Result<(), VtuError> {
    let expected = count * n_components;
    if values.len() != expected {
        return Err(VtuError::Length {
            location: location.name(),
            array: array.to_owned(),
            n_components,
            count,
            expected,
            actual: values.len(),
        });
    }
    if let Some(k) = values.iter().position(|v| !v.is_finite()) {
        return Err(VtuError::NonFinite {
            location: location.name(),
            array: array.to_owned(),
            index: k / n_components,
            component: k % n_components,
            value: values[k],
        });
    }
    Ok(())
}

fn write_attribute_block(s: &mut String, tag: &str, arrays: &[Array]) {
    let _ = write!(s, "      <{tag}");
    if let Some(a) = arrays.iter().find(|a| a.n_components == 1) {
        let _ = write!(s, " Scalars=\"{}\"", xml_escape(&a.name));
    }
    if let Some(a) = arrays.iter().find(|a| a.n_components == 3) {
        let _ = write!(s, " Vectors=\"{}\"", xml_escape(&a.name));
    }
    s.push_str(">\n");
    for a in arrays {
        write_f64_array(s, Some(&a.name), a.n_components, &a.values);
    }
    let _ = writeln!(s, "      </{tag}>");
}

fn write_f64_array(s: &mut String, name: Option<&str>, n_components: usize, values: &[f64]) {
    s.push_str("        <DataArray type=\"Float64\"");
    if let Some(name) = name {
        let _ = write!(s, " Name=\"{}\"", xml_escape(name));
    }
    let _ = writeln!(
        s,
        " NumberOfComponents=\"{n_components}\" format=\"ascii\">"
    );
    for tuple in values.chunks(n_components) {
        s.push_str("          ");
        for (k, v) in tuple.iter().enumerate() {
            if k > 0 {
                s.push(' ');
            }
            let _ = write!(s, "{v:e}");
        }
        s.push('\n');
    }
    s.push_str("        </DataArray>\n");
}

/// Escape text for an XML attribute value.
fn xml_escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for ch in text.chars() {
        match ch {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            // Other control characters are not allowed in XML 1.0 at all; tab, LF and CR would be
            // normalised to spaces by a parser, so keep them as character references.
            c if (c as u32) < 0x20 => {
                if matches!(c, '\t' | '\n' | '\r') {
                    let _ = write!(out, "&#{};", c as u32);
                } else {
                    out.push('\u{FFFD}');
                }
            }
            c => out.push(c),
        }
    }
    out
}

/// Write `text` to `path.tmp`, then rename it over `path`.
fn write_atomically(path: &Path, text: &str) -> Result<(), VtuError> {
    replace_file(path, text.as_bytes()).map_err(|source| VtuError::Io {
        path: path.to_owned(),
        source,
    })
}

/// Replace `path` by `bytes` so that a reader, or a run killed at any moment, sees either the
/// old file or the new one, never half a file: the bytes go to `path.tmp` beside it, which is
/// then renamed over `path`. If writing or renaming fails (a full disk, a removed directory),
/// the temporary file is removed again and the old `path` is left as it was.
pub fn replace_file(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = PathBuf::from(tmp);
    let written = std::fs::write(&tmp, bytes).and_then(|()| std::fs::rename(&tmp, path));
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// One entry of a [`PvdCollection`].
#[derive(Clone, Debug, PartialEq)]
pub struct PvdEntry {
    /// Time, load factor or step pseudo-time.
    pub time: f64,
    /// Data file, relative to the `.pvd` file's folder.
    pub file: String,
}

/// A `.pvd` collection: the index ParaView opens to play a series of `.vtu` files as time steps.
///
/// Intended use: when a load step converges, write its `.vtu`, then call
/// [`add`](Self::add) and [`write`](Self::write) (or [`add_and_write`](Self::add_and_write)).
/// The whole collection is rewritten each time (via a temporary file and a rename), so a run that
/// fails later still leaves a valid collection of the steps that converged.
///
/// Times must be finite and strictly increasing (ParaView sorts by time and shows one of any
/// entries that share a time). For a path that loads and then unloads, pass a monotone
/// pseudo-time (e.g. the cumulative step number) rather than the load factor.
#[derive(Clone, Debug)]
pub struct PvdCollection {
    path: PathBuf,
    entries: Vec<PvdEntry>,
}

impl PvdCollection {
    /// An empty collection to be written to `path` (nothing is written yet).
    pub fn new(path: impl Into<PathBuf>) -> Self {
        PvdCollection {
            path: path.into(),
            entries: Vec::new(),
        }
    }

    /// The `.pvd` file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The entries so far.
    pub fn entries(&self) -> &[PvdEntry] {
        &self.entries
    }

    /// Append a data file (relative to the `.pvd` file's folder) at `time`.
    pub fn add(&mut self, time: f64, file: impl AsRef<Path>) -> Result<(), VtuError> {
        let file = file.as_ref();
        let name = file.to_string_lossy().into_owned();
        if name.is_empty() || file.is_absolute() {
            return Err(VtuError::PvdFile {
                path: self.path.clone(),
                file: name,
            });
        }
        let previous = self.entries.last().map_or(f64::NEG_INFINITY, |e| e.time);
        if !(time.is_finite() && time > previous) {
            return Err(VtuError::PvdTime {
                path: self.path.clone(),
                index: self.entries.len(),
                file: name,
                time,
                previous,
            });
        }
        self.entries.push(PvdEntry { time, file: name });
        Ok(())
    }

    /// The file contents.
    pub fn to_xml(&self) -> String {
        let mut s = String::new();
        s.push_str("<?xml version=\"1.0\"?>\n");
        s.push_str("<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n");
        s.push_str("  <Collection>\n");
        for e in &self.entries {
            let _ = writeln!(
                s,
                "    <DataSet timestep=\"{:e}\" group=\"\" part=\"0\" file=\"{}\"/>",
                e.time,
                xml_escape(&e.file)
            );
        }
        s.push_str("  </Collection>\n");
        s.push_str("</VTKFile>\n");
        s
    }

    /// (Re)write the `.pvd` file with all entries so far (via a temporary file and a rename).
    pub fn write(&self) -> Result<(), VtuError> {
        write_atomically(&self.path, &self.to_xml())
    }

    /// [`add`](Self::add), then [`write`](Self::write).
    pub fn add_and_write(&mut self, time: f64, file: impl AsRef<Path>) -> Result<(), VtuError> {
        self.add(time, file)?;
        self.write()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn structured_grid_quads_are_row_major_and_counter_clockwise() {
        let pts = (0..6).map(|k| [k as f64, 0.0, 0.0]).collect();
        let m = VtuMesh::structured_grid(3, 2, pts).unwrap();
        assert_eq!(
            m.cells,
            vec![Cell::Quad([0, 2, 3, 1]), Cell::Quad([2, 4, 5, 3])]
        );
        assert!(matches!(
            VtuMesh::structured_grid(1, 6, vec![[0.0; 3]; 6]),
            Err(VtuError::GridSize { .. })
        ));
    }

    #[test]
    fn xml_escape_covers_markup() {
        assert_eq!(
            xml_escape("a<b>&\"c'\n"),
            "a&lt;b&gt;&amp;&quot;c&apos;&#10;"
        );
    }

    #[test]
    fn numbers_round_trip() {
        for v in [
            0.1,
            1.0 / 3.0,
            -0.0,
            5e-324,
            f64::MAX,
            -1.234_567_890_123_456_7e-200,
        ] {
            let s = format!("{v:e}");
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), v.to_bits(), "{s}");
        }
    }
}
