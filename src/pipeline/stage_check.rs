//! Each stage's settings checked against the loaded input before any stage
//! runs ([`crate::stage::Stage::check_input`]): what only the input decides
//! (the exemplar's size against a stage's neighbourhoods or patches, a key
//! vertex against the mesh's vertices) is refused with exit 2 then, not
//! once the stages before it have run (issue 43).

use super::memory_budget::stage_sizes;
use super::{LoadedInput, Pipeline, PipelineError};
use crate::stage::memory::InputSizes;
use crate::stage::{InputView, StageError};

/// Checks every stage of `pipeline` against `input`, each with the sizes
/// it will see and, while every stage before it keeps the input mesh's
/// vertices, the input's vertex count for the ids its settings name.
///
/// # Errors
/// [`StageError`] of the first stage that refuses, with its message.
pub fn check_stage_inputs(
    pipeline: &Pipeline,
    input: &LoadedInput,
    sizes: &InputSizes,
) -> Result<(), PipelineError> {
    let mut key_vertices = Some(sizes.vertices);
    for (i, (stage, sizes)) in pipeline
        .stages
        .iter()
        .zip(stage_sizes(&pipeline.stages, sizes))
        .enumerate()
    {
        let view = InputView {
            sizes: &sizes,
            exemplar: &input.exemplar_name,
            key_vertices,
        };
        stage
            .check_input(&view)
            .map_err(|message| StageError::new(i, stage.kind(), message))?;
        if !stage.keeps_vertex_ids(&sizes) {
            key_vertices = None;
        }
    }
    Ok(())
}
