use std::path::PathBuf;

/// Failures while writing results.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// A file or folder could not be written.
    #[error("cannot write {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// An encoder failed.
    #[error("cannot encode {what}: {message}")]
    Encode { what: String, message: String },
}
