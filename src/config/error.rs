use std::path::PathBuf;

/// Everything that can be wrong with a pipeline configuration.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The config file could not be read.
    #[error("cannot read config {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// TOML syntax or a top-level key/type error (toml's message carries line and column).
    #[error("{file}: {message}")]
    Syntax { file: String, message: String },
    /// A `--set PATH=VALUE` override is malformed or names no place in the config.
    #[error("--set {assignment}: {message}")]
    Override { assignment: String, message: String },
    /// A `[[stage]]` names no registered stage.
    #[error(
        "{file}:{line}: stage {index} has kind {kind:?}, which is not a stage; allowed: {allowed}"
    )]
    UnknownStage {
        file: String,
        line: usize,
        index: usize,
        kind: String,
        allowed: String,
    },
    /// A stage parameter is unknown, of the wrong type, or out of range.
    #[error("{file}:{line}: stage {index} ({kind}), parameter `{param}`: {message}")]
    Param {
        file: String,
        line: usize,
        index: usize,
        kind: String,
        param: String,
        message: String,
    },
    /// A value in `[input]` or `[output]` is wrong.
    #[error("{file}: `{key}`: {message}")]
    Value {
        file: String,
        key: String,
        message: String,
    },
    /// An input file named in the config does not exist.
    #[error("{origin}: `{key}` names {written:?}, which does not exist in {dir} ({rule})")]
    MissingFile {
        /// `FILE:LINE` of the value, or `--set KEY`.
        origin: String,
        /// The dotted key (`input.mesh`).
        key: String,
        /// The path as written.
        written: String,
        /// The folder it was resolved against, absolute.
        dir: String,
        /// Which rule chose that folder.
        rule: &'static str,
    },
    /// A stage needs data that no earlier stage produces.
    #[error(
        "{file}:{line}: stage {index} ({kind}) needs {needs}, which no earlier stage produces: {hint}"
    )]
    MissingInput {
        file: String,
        line: usize,
        index: usize,
        kind: String,
        needs: String,
        hint: String,
    },
}
