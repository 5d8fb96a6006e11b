//! Checks made before a run for the `export` format `plane`, so that a
//! request the pipeline cannot satisfy fails at once (exit 2) rather than
//! after the synthesis: the mesh the export will see must be flat in xy, and
//! a `jump_image` result must have the requested size.

use super::{Pipeline, PipelineError};
use crate::kernels::atlas::plane_raster::check_planar_xy;
use crate::mesh::PolyMesh;
use crate::stage::{Datum, PlaneRole, StageError};
use crate::stages::export::plane::{planar_message, size_message};

/// The data that count as a result a plane image can be drawn from.
pub const PLANE_RESULTS: [Datum; 4] = [
    Datum::Colours,
    Datum::CornerUvs,
    Datum::Patches,
    Datum::Image,
];

/// Follows the stages' [`PlaneRole`]s from the loaded input mesh and refuses
/// the first `plane` request on a mesh that is not flat in xy (naming the
/// mesh, why, and what is allowed) or on a `jump_image` result of another
/// size than `plane_size`.
///
/// # Errors
/// [`StageError`] of the requesting `export` stage.
pub fn check_plane_requests(
    pipeline: &Pipeline,
    input_mesh: &PolyMesh,
) -> Result<(), PipelineError> {
    let mut what = match &pipeline.input.mesh {
        Some(name) => format!("the input mesh `{name}`"),
        None => "the input (no mesh)".to_string(),
    };
    let mut planar = check_planar_xy(&input_mesh.positions);
    let mut image: Option<(u32, u32)> = None;
    let mut surface_result = false;
    for (i, stage) in pipeline.stages.iter().enumerate() {
        let refuse =
            |message: String| PipelineError::from(StageError::new(i, stage.kind(), message));
        match stage.plane_role() {
            PlaneRole::Keeps => {}
            PlaneRole::ReplacesMesh { planar: p, what: w } => {
                planar = if p {
                    Ok(())
                } else {
                    Err("it is not a plane".into())
                };
                what = w;
            }
            PlaneRole::DeformsMesh => {
                what = format!("the mesh after stage {} ({})", i + 1, stage.kind());
                planar = Err("that stage moves vertices out of their plane".into());
            }
            PlaneRole::Image { width, height } => image = Some((width, height)),
            PlaneRole::Request { width, height } => {
                if surface_result {
                    if let Err(reason) = &planar {
                        return Err(refuse(planar_message(&what, reason)));
                    }
                } else if let Some((w, h)) = image
                    && (w, h) != (width, height)
                {
                    return Err(refuse(size_message(w, h, [width, height])));
                }
            }
        }
        surface_result |= stage
            .produces()
            .iter()
            .any(|d| PLANE_RESULTS[..3].contains(d));
    }
    Ok(())
}
