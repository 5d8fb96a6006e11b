//! Mesh loaders: OBJ, PLY (ASCII and binary), OFF and STL (ASCII and binary).
//!
//! [`load_mesh`] picks the format from the file extension, parses the file into
//! a raw polygon soup, validates it (finite coordinates, face indices in range)
//! and runs the load-time repairs of [`crate::mesh::repair`]. Every error names
//! the file and the place in it (`line 12`, `face 7`, `vertex 3`, ...), so the
//! user knows what to fix.
//!
//! Architecture invariant: the parsers never panic, whatever the bytes; counts
//! read from a file are never trusted for allocation beyond what the file
//! length can hold.

mod obj;
mod off;
mod ply;
mod stl;

use super::PolyMesh;
use super::error::MeshError;
use super::repair::{LoadReport, repair_mesh};
use glam::Vec3;
use std::path::Path;

/// How to load a mesh.
///
/// Deserialises from a config table such as
/// `[mesh] merge_duplicates = true, merge_tolerance = 1e-6`; unknown keys are
/// rejected.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LoadOptions {
    /// Merge vertices whose positions coincide (within `merge_tolerance`).
    /// Default `false`: vertices the file keeps apart stay apart, since a seam
    /// may be intentional. STL files are always welded exactly, since the
    /// format shares no vertices at all.
    pub merge_duplicates: bool,
    /// Merge distance as a fraction of the bounding-box diagonal (unitless).
    /// Default `0.0`, meaning only bit-identical positions merge. Range
    /// `0.0..=0.1`. Only used when `merge_duplicates` is set.
    pub merge_tolerance: f32,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            merge_duplicates: false,
            merge_tolerance: 0.0,
        }
    }
}

impl LoadOptions {
    /// Largest accepted `merge_tolerance`.
    pub const MAX_MERGE_TOLERANCE: f32 = 0.1;

    /// Checks the option ranges.
    ///
    /// # Errors
    /// [`MeshError::InvalidOption`] naming the option and its allowed range.
    pub fn validate(&self) -> Result<(), MeshError> {
        let t = self.merge_tolerance;
        if !(0.0..=Self::MAX_MERGE_TOLERANCE).contains(&t) {
            return Err(MeshError::InvalidOption {
                option: "merge_tolerance".into(),
                value: format!("{t}"),
                allowed: format!(
                    "0.0..={} (a fraction of the bounding-box diagonal)",
                    Self::MAX_MERGE_TOLERANCE
                ),
            });
        }
        Ok(())
    }
}

/// The mesh file formats we read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MeshFormat {
    /// Wavefront OBJ (positions and polygon faces; everything else ignored).
    Obj,
    /// Stanford PLY, ASCII or binary little/big endian.
    Ply,
    /// Object File Format (Geomview), ASCII.
    Off,
    /// Stereolithography, ASCII or binary.
    Stl,
}

impl MeshFormat {
    /// The format named by `path`'s extension (case-insensitive).
    ///
    /// # Errors
    /// [`MeshError::UnknownFormat`] for any other extension, or none.
    pub fn from_path(path: &Path) -> Result<Self, MeshError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase())
            .unwrap_or_default();
        match ext.as_str() {
            "obj" => Ok(Self::Obj),
            "ply" => Ok(Self::Ply),
            "off" => Ok(Self::Off),
            "stl" => Ok(Self::Stl),
            _ => Err(MeshError::UnknownFormat {
                path: path.to_path_buf(),
                extension: ext,
            }),
        }
    }
}

/// Prefix of the mesh names [`load_mesh`] builds procedurally.
pub const BUILTIN_PREFIX: &str = "builtin:";

/// Loads a mesh file, choosing the format by extension (`.obj`, `.ply`,
/// `.off`, `.stl`, any case), and repairs it (see [`crate::mesh::repair`]).
///
/// A path of the form `builtin:NAME` builds the procedural mesh `NAME` with
/// default options instead (see [`crate::mesh::builtin`]); its report is empty.
///
/// Convex faces keep their degree up to
/// [`MAX_FACE_CORNERS`](crate::mesh::repair::MAX_FACE_CORNERS) corners; larger
/// ones, and every non-convex face, are cut into triangles (the report
/// counts them; see [`crate::mesh::repair::triangulate_faces`]). All OBJ
/// objects and groups merge into one mesh. A UTF-8 byte-order mark at the
/// start of a text file (OBJ, OFF, PLY header, ASCII STL) is skipped. Non-manifold edges, boundaries and several components are
/// legal and kept.
///
/// # Errors
/// - [`MeshError::Io`] when the file cannot be read;
/// - [`MeshError::UnknownFormat`] for an unsupported extension;
/// - [`MeshError::Parse`] for a truncated file or a bad token, with the line
///   (text) or the element (binary) where it happened;
/// - [`MeshError::NonFinite`] for a NaN or infinite coordinate;
/// - [`MeshError::IndexOutOfRange`] for a face index outside the vertex list
///   ([`MeshError::ReferenceOutOfRange`] for OBJ, with the line and the
///   reference as written);
/// - [`MeshError::BadFace`] for a face that cannot be cut into triangles
///   (it crosses itself), with its line;
/// - [`MeshError::NoFaces`] when no usable face is left;
/// - [`MeshError::InvalidOption`] for out-of-range `options`.
pub fn load_mesh(path: &Path, options: &LoadOptions) -> Result<(PolyMesh, LoadReport), MeshError> {
    options.validate()?;
    if let Some(name) = path.to_str().and_then(|s| s.strip_prefix(BUILTIN_PREFIX)) {
        let mesh = super::builtin::builtin_mesh(name, &super::builtin::BuiltinOptions::default())?;
        let report = LoadReport {
            input_vertices: mesh.vertex_count(),
            input_faces: mesh.face_count(),
            ..LoadReport::default()
        };
        return Ok((mesh, report));
    }
    let format = MeshFormat::from_path(path)?;
    // Three coarse steps (read, parse, repair): a file of a million
    // vertices takes a second or two, too long for silence on a terminal.
    let progress = crate::progress::Progress::new(3, "load_mesh");
    let _finish = progress.finish_on_drop();
    progress.set_part("reading");
    let bytes = std::fs::read(path).map_err(|source| MeshError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    progress.inc(1);
    let loaded = load_mesh_from_bytes_with_progress(&bytes, format, path, options, &progress);
    progress.finish();
    loaded
}

/// Parses, validates and repairs a mesh held in memory. `path` is only used in
/// error messages. See [`load_mesh`] for the errors.
pub fn load_mesh_from_bytes(
    bytes: &[u8],
    format: MeshFormat,
    path: &Path,
    options: &LoadOptions,
) -> Result<(PolyMesh, LoadReport), MeshError> {
    load_mesh_from_bytes_with_progress(
        bytes,
        format,
        path,
        options,
        &crate::progress::Progress::hidden(),
    )
}

/// [`load_mesh_from_bytes`], advancing `progress` by one step after parsing
/// and one after the repairs.
fn load_mesh_from_bytes_with_progress(
    bytes: &[u8],
    format: MeshFormat,
    path: &Path,
    options: &LoadOptions,
    progress: &crate::progress::Progress,
) -> Result<(PolyMesh, LoadReport), MeshError> {
    options.validate()?;
    progress.set_part("parsing");
    let (mut mesh, face_lines) = parse_mesh_located(bytes, format, path)?;
    progress.inc(1);
    progress.set_part("repairs");
    let file_faces = mesh.face_count();
    if file_faces == 0 {
        return Err(MeshError::NoFaces {
            path: path.to_path_buf(),
            detail: format!(" ({} vertices, no face elements)", mesh.vertex_count()),
        });
    }
    let report = repair_mesh(&mut mesh, options).map_err(|bad| MeshError::BadFace {
        path: path.to_path_buf(),
        location: match face_lines.get(bad.face) {
            Some(&line) if line > 0 => format!("line {line}"),
            _ => format!("face {}", bad.face),
        },
        message: bad.message(),
    })?;
    drop(face_lines);
    progress.inc(1);
    if mesh.face_count() == 0 {
        let detail = match report.far_vertex {
            Some(far) => {
                let [x, y, z] = far.position.to_array().map(show_coordinate);
                format!(
                    " left after repairs: vertex {} at ({x}, {y}, {z}) lies far from the others, making the bounding-box diagonal {:.3e} where the other vertices span {:.3e}, so all {file_faces} faces count as zero-area (at most {:e} × the diagonal squared); allowed: coordinates of one object, within a million face sizes of each other (fix or remove vertex {})",
                    far.index,
                    far.diagonal,
                    far.others_diagonal,
                    crate::mesh::repair::ZERO_AREA_FACTOR,
                    far.index
                )
            }
            None => format!(
                " left after repairs (all {file_faces} faces were degenerate or had zero area)"
            ),
        };
        return Err(MeshError::NoFaces {
            path: path.to_path_buf(),
            detail,
        });
    }
    Ok((mesh, report))
}

/// A coordinate for a message: as written for everyday magnitudes, in
/// exponent form (`1e30`) for huge and tiny ones.
fn show_coordinate(v: f32) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e6).contains(&a) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// Parses and validates a mesh without repairing it: indices are in range and
/// coordinates finite, but faces may have fewer than three corners, repeated
/// vertices or zero area, and vertices may be unused.
pub fn parse_mesh(bytes: &[u8], format: MeshFormat, path: &Path) -> Result<PolyMesh, MeshError> {
    parse_mesh_located(bytes, format, path).map(|(mesh, _)| mesh)
}

/// [`parse_mesh`], with the 1-based line of each face in a text file (0
/// where there is none: binary PLY, STL).
fn parse_mesh_located(
    bytes: &[u8],
    format: MeshFormat,
    path: &Path,
) -> Result<(PolyMesh, Vec<u32>), MeshError> {
    // STL decides between binary and ASCII itself: the 80-byte header of a
    // binary file may begin with the BOM's bytes.
    let bytes = if format == MeshFormat::Stl {
        bytes
    } else {
        strip_bom(bytes)
    };
    let raw = match format {
        MeshFormat::Obj => obj::parse_obj(bytes, path)?,
        MeshFormat::Ply => ply::parse_ply(bytes, path)?,
        MeshFormat::Off => off::parse_off(bytes, path)?,
        MeshFormat::Stl => stl::parse_stl(bytes, path)?,
    };
    match raw.finish(path) {
        Err(MeshError::IndexOutOfRange { face, .. }) if format == MeshFormat::Obj => {
            Err(obj::reference_error(bytes, path, face).unwrap_or_else(|| {
                parse_error(
                    path,
                    format!("face {face}"),
                    "a face refers to a missing vertex",
                )
            }))
        }
        other => other,
    }
}

/// A polygon soup as read from a file, before validation. Corner indices are
/// 0-based but still signed and unchecked.
#[derive(Debug)]
struct RawMesh {
    positions: Vec<Vec3>,
    face_start: Vec<u32>,
    corners: Vec<i64>,
    /// The 1-based line of each face in a text file, 0 where there is none.
    face_line: Vec<u32>,
    /// Set when the corner count overflowed `u32`.
    too_many_corners: bool,
}

impl RawMesh {
    /// Reserves room for the given counts, capped so that a lying header in a
    /// short file cannot make us allocate much.
    fn with_capacity(vertices: usize, faces: usize, file_len: usize) -> Self {
        let cap = file_len / 4 + 16;
        let mut face_start = Vec::with_capacity(faces.min(cap) + 1);
        face_start.push(0);
        Self {
            positions: Vec::with_capacity(vertices.min(cap)),
            face_start,
            corners: Vec::with_capacity((faces.saturating_mul(3)).min(cap)),
            face_line: Vec::with_capacity(faces.min(cap)),
            too_many_corners: false,
        }
    }

    #[inline]
    fn push_vertex(&mut self, p: [f32; 3]) {
        self.positions.push(Vec3::from_array(p));
    }

    #[inline]
    fn push_corner(&mut self, index: i64) {
        self.corners.push(index);
    }

    /// Closes the face made of the corners pushed since the previous call.
    #[inline]
    fn end_face(&mut self) {
        self.end_face_at(0);
    }

    /// [`end_face`](Self::end_face) for a face on text line `line` (1-based).
    #[inline]
    fn end_face_at(&mut self, line: usize) {
        match u32::try_from(self.corners.len()) {
            Ok(n) => {
                self.face_start.push(n);
                self.face_line.push(u32::try_from(line).unwrap_or(0));
            }
            Err(_) => self.too_many_corners = true,
        }
    }

    fn face_count(&self) -> usize {
        self.face_start.len() - 1
    }

    /// Validates coordinates and indices and converts to a [`PolyMesh`],
    /// with the line of each face.
    fn finish(self, path: &Path) -> Result<(PolyMesh, Vec<u32>), MeshError> {
        if self.too_many_corners {
            return Err(MeshError::Parse {
                path: path.to_path_buf(),
                location: format!("face {}", self.face_count()),
                message: "more than 4294967295 face corners; the mesh is too large".into(),
            });
        }
        if let Some((v, p)) = self
            .positions
            .iter()
            .enumerate()
            .find(|(_, p)| !p.is_finite())
        {
            return Err(MeshError::NonFinite {
                path: path.to_path_buf(),
                vertex: v,
                value: p.to_array(),
            });
        }
        let nv = self.positions.len();
        let mut corner_vertex = Vec::with_capacity(self.corners.len());
        for (f, w) in self.face_start.windows(2).enumerate() {
            for &i in &self.corners[w[0] as usize..w[1] as usize] {
                match u32::try_from(i) {
                    Ok(u) if (u as usize) < nv => corner_vertex.push(u),
                    _ => {
                        return Err(MeshError::IndexOutOfRange {
                            path: path.to_path_buf(),
                            face: f,
                            index: i,
                            vertex_count: nv,
                        });
                    }
                }
            }
        }
        Ok((
            PolyMesh {
                positions: self.positions,
                face_start: self.face_start,
                corner_vertex,
            },
            self.face_line,
        ))
    }
}

/// UTF-8 byte-order mark, written by some Windows editors at the start of a
/// text file.
const UTF8_BOM: &[u8] = b"\xEF\xBB\xBF";

/// `bytes` without a leading UTF-8 byte-order mark.
pub(crate) fn strip_bom(bytes: &[u8]) -> &[u8] {
    bytes.strip_prefix(UTF8_BOM).unwrap_or(bytes)
}

/// Lines of a text file as `(1-based line number, bytes)`, without the line
/// terminator (`\n` or `\r\n`).
fn lines(bytes: &[u8]) -> impl Iterator<Item = (usize, &[u8])> {
    bytes.split(|&b| b == b'\n').enumerate().map(|(i, l)| {
        let l = l.strip_suffix(b"\r").unwrap_or(l);
        (i + 1, l)
    })
}

/// The part of a line before a `#` comment.
fn strip_comment(line: &[u8]) -> &[u8] {
    match line.iter().position(|&b| b == b'#') {
        Some(i) => &line[..i],
        None => line,
    }
}

/// Whitespace-separated tokens of a line.
fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|t| !t.is_empty())
}

/// Parses a token as a number (`f32`, `i64`, `usize`, ...).
fn parse_token<T: std::str::FromStr>(token: &[u8]) -> Option<T> {
    std::str::from_utf8(token).ok()?.parse().ok()
}

/// A token for an error message: lossy, and cut to a readable length.
fn show_token(token: &[u8]) -> String {
    let s = String::from_utf8_lossy(token);
    if s.chars().count() > 40 {
        let cut: String = s.chars().take(40).collect();
        format!("{cut}...")
    } else {
        s.into_owned()
    }
}

/// Parses three coordinates from `tokens`; `Err` carries a message.
fn parse_xyz<'a>(tokens: &mut impl Iterator<Item = &'a [u8]>) -> Result<[f32; 3], String> {
    let mut p = [0.0f32; 3];
    for (k, slot) in p.iter_mut().enumerate() {
        let axis = ["x", "y", "z"][k];
        let Some(tok) = tokens.next() else {
            return Err(format!(
                "vertex needs 3 coordinates, found {k} (missing {axis}; file truncated?)"
            ));
        };
        *slot = parse_token(tok)
            .ok_or_else(|| format!("bad {axis} coordinate {:?}", show_token(tok)))?;
    }
    Ok(p)
}

fn parse_error(path: &Path, location: impl Into<String>, message: impl Into<String>) -> MeshError {
    MeshError::Parse {
        path: path.to_path_buf(),
        location: location.into(),
        message: message.into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(text: &str, format: MeshFormat) -> Result<(PolyMesh, LoadReport), MeshError> {
        load_mesh_from_bytes(
            text.as_bytes(),
            format,
            Path::new("t.x"),
            &LoadOptions::default(),
        )
    }

    #[test]
    fn format_from_extension_is_case_insensitive() {
        assert_eq!(
            MeshFormat::from_path(Path::new("a/B.OBJ")).unwrap(),
            MeshFormat::Obj
        );
        assert_eq!(
            MeshFormat::from_path(Path::new("x.Ply")).unwrap(),
            MeshFormat::Ply
        );
        assert!(matches!(
            MeshFormat::from_path(Path::new("x.fbx")),
            Err(MeshError::UnknownFormat { .. })
        ));
        assert!(matches!(
            MeshFormat::from_path(Path::new("noext")),
            Err(MeshError::UnknownFormat { .. })
        ));
    }

    #[test]
    fn repairs_run_after_parsing() {
        // (A face line with fewer than 3 references is a parse error since
        // issue 43: `obj::tests`.)
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nf 1 2 3\nf 1 1 2\nf 2 2 3\n";
        let (m, r) = load(text, MeshFormat::Obj).unwrap();
        assert_eq!(m.face_count(), 1);
        assert_eq!(m.vertex_count(), 3);
        assert_eq!(r.dropped_degenerate_faces, 2);
        assert_eq!(r.dropped_unused_vertices, 1);
    }

    #[test]
    fn all_faces_degenerate_is_no_faces() {
        let err = load("v 0 0 0\nv 1 0 0\nf 1 2 1\n", MeshFormat::Obj).unwrap_err();
        assert!(matches!(err, MeshError::NoFaces { .. }), "{err}");
        assert!(err.to_string().contains("degenerate"), "{err}");
    }

    /// Issue 43: one vertex a million million times farther out than the
    /// rest makes every face "zero-area" against the bounding box; the
    /// message names that vertex, its coordinates and what is allowed
    /// instead of only "all faces were degenerate".
    #[test]
    fn a_far_vertex_that_leaves_no_face_is_named() {
        let mut text = String::new();
        for j in 0..4 {
            for i in 0..4 {
                let (x, y) = if (i, j) == (3, 0) {
                    (1e30, 1e30)
                } else {
                    (i as f32, j as f32)
                };
                text += &format!("v {x:e} {y:e} 0\n");
            }
        }
        for j in 0..3 {
            for i in 0..3 {
                let a = j * 4 + i + 1;
                text += &format!("f {a} {} {}\nf {a} {} {}\n", a + 1, a + 5, a + 5, a + 4);
            }
        }
        let err = load(&text, MeshFormat::Obj).unwrap_err().to_string();
        for needle in ["vertex 3", "1e30", "allowed"] {
            assert!(err.contains(needle), "{needle}: {err}");
        }
    }

    #[test]
    fn bad_tolerance_is_rejected() {
        let opts = LoadOptions {
            merge_duplicates: true,
            merge_tolerance: f32::NAN,
        };
        let err = load_mesh(Path::new("x.obj"), &opts).unwrap_err();
        assert!(matches!(err, MeshError::InvalidOption { .. }), "{err}");
    }

    #[test]
    fn builtin_paths_build_procedural_meshes() {
        let (m, r) = load_mesh(Path::new("builtin:icosphere"), &LoadOptions::default()).unwrap();
        assert!(m.face_count() > 0);
        assert_eq!(r.input_faces, m.face_count());
    }
}
