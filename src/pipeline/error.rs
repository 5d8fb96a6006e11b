use crate::config::ConfigError;
use crate::image::ImageError;
use crate::mesh::MeshError;
use crate::output::OutputError;
use crate::stage::StageError;

/// Any failure of a run, with the exit code the CLI maps it to.
#[derive(Debug, thiserror::Error)]
pub enum PipelineError {
    /// The config is wrong (exit 2).
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The mesh is wrong (exit 2).
    #[error(transparent)]
    Mesh(#[from] MeshError),
    /// The exemplar is wrong (exit 2).
    #[error(transparent)]
    Image(#[from] ImageError),
    /// Results could not be written (exit 1).
    #[error(transparent)]
    Output(#[from] OutputError),
    /// A stage refused its input: what and where (exit 2).
    #[error(transparent)]
    Stage(#[from] StageError),
    /// A bug or an environment failure (exit 1).
    #[error("internal error: {0}")]
    Internal(String),
}

impl PipelineError {
    /// 2 for anything the user can fix in their input, 1 otherwise.
    pub fn exit_code(&self) -> i32 {
        match self {
            PipelineError::Config(_)
            | PipelineError::Mesh(_)
            | PipelineError::Image(_)
            | PipelineError::Stage(_) => 2,
            PipelineError::Output(_) | PipelineError::Internal(_) => 1,
        }
    }
}
