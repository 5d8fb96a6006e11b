use std::path::PathBuf;

/// Everything that can be wrong with a mesh a user gives us.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    /// The file could not be opened or read.
    #[error("cannot read mesh file {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The extension names no supported format.
    #[error("mesh file {path}: unknown format {extension:?}; allowed: .obj, .ply, .off, .stl")]
    UnknownFormat { path: PathBuf, extension: String },
    /// The file is not valid in its format (truncated, bad token, ...).
    #[error("mesh file {path}, {location}: {message}")]
    Parse {
        path: PathBuf,
        /// Where in the file: `line 12`, `face 7`, `byte 1024`, ...
        location: String,
        message: String,
    },
    /// A vertex coordinate is NaN or infinite.
    #[error(
        "mesh {path}: vertex {vertex} has a non-finite coordinate {value:?}; coordinates must be finite numbers"
    )]
    NonFinite {
        path: PathBuf,
        vertex: usize,
        value: [f32; 3],
    },
    /// A face refers to a vertex that does not exist.
    #[error(
        "mesh {path}: face {face} refers to vertex {index}, but the mesh has {vertex_count} vertices (valid: 0..{vertex_count})"
    )]
    IndexOutOfRange {
        path: PathBuf,
        face: usize,
        index: i64,
        vertex_count: usize,
    },
    /// An OBJ face reference names no vertex, reported as the user wrote it
    /// (1-based, or negative relative to the vertices above its line).
    #[error("mesh file {path}, line {line}: face {face} refers to vertex {written}, but {detail}")]
    ReferenceOutOfRange {
        path: PathBuf,
        /// 1-based line of the face.
        line: usize,
        /// 0-based face number (faces counted in file order).
        face: usize,
        /// The reference as written.
        written: i64,
        /// What exists and what is allowed.
        detail: String,
    },
    /// A face that cannot be cut into triangles: it crosses itself, or it
    /// is non-convex with more corners than the loader cuts (see
    /// [`crate::mesh::repair::triangulate_faces`]).
    #[error("mesh file {path}, {location}: {message}")]
    BadFace {
        path: PathBuf,
        /// Where in the file: `line 12` (text formats) or `face 7`.
        location: String,
        /// What is wrong and what is allowed.
        message: String,
    },
    /// Nothing to texture.
    #[error("mesh {path}: no faces{detail}; a mesh needs at least one triangle or polygon")]
    NoFaces { path: PathBuf, detail: String },
    /// A builtin mesh name or option is wrong.
    #[error("builtin mesh {name:?}: {message}")]
    Builtin { name: String, message: String },
    /// A stage cannot process this mesh (with what and where).
    #[error("{stage}: {message}")]
    Unsupported { stage: String, message: String },
    /// A loader option is out of range.
    #[error("mesh load option {option} = {value} is out of range; allowed: {allowed}")]
    InvalidOption {
        option: String,
        value: String,
        allowed: String,
    },
}
