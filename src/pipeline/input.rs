//! Loading `[input]`: the mesh (builtin or file) and the exemplar.

use super::PipelineError;
use crate::config::{ConfigError, RawInput};
use crate::image::Image;
use crate::mesh::PolyMesh;
use std::path::Path;

/// The loaded inputs of a run.
#[derive(Clone, Debug)]
pub struct LoadedInput {
    /// The mesh, repaired.
    pub mesh: PolyMesh,
    /// What the loader repaired, for the log and metrics.
    pub load_report: String,
    /// The exemplar.
    pub exemplar: Image,
    /// Its display name.
    pub exemplar_name: String,
}

fn table_into<T: serde::de::DeserializeOwned>(
    table: &toml::Table,
    file: &str,
    key: &str,
) -> Result<T, ConfigError> {
    table
        .clone()
        .try_into()
        .map_err(|e: toml::de::Error| ConfigError::Value {
            file: file.to_string(),
            key: key.to_string(),
            message: e.message().trim_end().to_string(),
        })
}

/// Loads the mesh and exemplar named in `[input]`; relative paths resolve
/// against `base_dir`. `file` names the config in messages.
pub fn load_input(
    input: &RawInput,
    base_dir: &Path,
    file: &str,
) -> Result<LoadedInput, PipelineError> {
    let _span = tracing::info_span!("load_input").entered();
    let (mesh, load_report) = if let Some(name) = input
        .mesh
        .as_deref()
        .and_then(|m| m.strip_prefix("builtin:"))
    {
        let opts: crate::mesh::builtin::BuiltinOptions =
            table_into(&input.mesh_options, file, "input.mesh_options")?;
        let mesh = crate::mesh::builtin::builtin_mesh(name, &opts)?;
        (mesh, format!("builtin mesh {name}"))
    } else {
        if !input.mesh_options.is_empty() {
            return Err(ConfigError::Value {
                file: file.to_string(),
                key: "input.mesh_options".into(),
                message: "options apply to builtin meshes only (mesh = \"builtin:NAME\")".into(),
            }
            .into());
        }
        let Some(mesh_path) = input.mesh.as_deref() else {
            return Ok(LoadedInput {
                mesh: PolyMesh::new(),
                load_report: "no mesh (image-only pipeline)".into(),
                ..load_exemplar(input, base_dir, file)?
            });
        };
        let path = base_dir.join(mesh_path);
        let options = crate::mesh::LoadOptions {
            merge_duplicates: input.merge_duplicates,
            ..Default::default()
        };
        let (mesh, report) = crate::mesh::load_mesh(&path, &options)?;
        (mesh, report.summary())
    };
    Ok(LoadedInput {
        mesh,
        load_report,
        ..load_exemplar(input, base_dir, file)?
    })
}

fn load_exemplar(
    input: &RawInput,
    base_dir: &Path,
    file: &str,
) -> Result<LoadedInput, PipelineError> {
    if input.exemplar.starts_with("builtin:") {
        let _: crate::image::ExemplarOptions =
            table_into(&input.exemplar_options, file, "input.exemplar_options")?;
    } else if !input.exemplar_options.is_empty() {
        return Err(ConfigError::Value {
            file: file.to_string(),
            key: "input.exemplar_options".into(),
            message: "options apply to builtin exemplars only (exemplar = \"builtin:NAME\")".into(),
        }
        .into());
    }
    let opts: crate::image::ExemplarOptions =
        table_into(&input.exemplar_options, file, "input.exemplar_options")?;
    let (exemplar, exemplar_name) =
        crate::image::exemplar_from_spec(&input.exemplar, base_dir, &opts)?;
    Ok(LoadedInput {
        mesh: PolyMesh::new(),
        load_report: String::new(),
        exemplar,
        exemplar_name,
    })
}
