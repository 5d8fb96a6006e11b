//! Writes what the `export` stage prepared.

use super::OutputError;
use crate::stages::world::ExportJob;
use std::path::{Path, PathBuf};

/// Writes the job's files into `dir`; returns their paths.
pub fn write_export(dir: &Path, job: &ExportJob) -> Result<Vec<PathBuf>, OutputError> {
    let mut files = Vec::new();
    for (name, image) in &job.images {
        let path = dir.join(name);
        super::write_png(&path, image)?;
        files.push(path);
    }
    for format in &job.formats {
        match format.as_str() {
            "ply" => {
                let path = dir.join(format!("{}.ply", job.stem));
                let colours = job
                    .colours
                    .as_ref()
                    .map(|c| (c.values.as_slice(), c.channels));
                super::ply::write_ply(&path, &job.mesh, colours, &[])?;
                files.push(path);
            }
            "obj" => {
                let (uvs, texture) = match &job.uvs {
                    Some((uv, tex)) => (Some(uv.as_slice()), Some(tex)),
                    None => (None, None),
                };
                let colours = job
                    .colours
                    .as_ref()
                    .map(|c| (c.values.as_slice(), c.channels));
                files.extend(super::obj::write_obj(
                    dir, &job.stem, &job.mesh, uvs, texture, colours,
                )?);
            }
            "baked" => {
                if let Some((mesh, uvs, image)) = &job.baked {
                    let stem = format!("{}_baked", job.stem);
                    files.extend(super::obj::write_obj(
                        dir,
                        &stem,
                        mesh,
                        Some(uvs.as_slice()),
                        Some(image),
                        None,
                    )?);
                }
            }
            "preview" => {
                files.extend(super::render::write_previews(
                    dir,
                    "preview",
                    &job.previews,
                )?);
            }
            _ => {}
        }
    }
    Ok(files)
}
