//! Loading `[input]`: the mesh (builtin or file) and the exemplar.

use super::PipelineError;
use crate::config::{ConfigError, ConfigSource, RawInput};
use crate::image::Image;
use crate::mesh::PolyMesh;
use std::path::{Path, PathBuf};

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
    /// Extra exemplar maps (height, normal, roughness), the exemplar's size.
    pub channels: crate::world::ExemplarChannels,
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
/// against `base_dir`. `file` names the config in messages (without line
/// numbers; [`load_input_from`] gives them).
pub fn load_input(
    input: &RawInput,
    base_dir: &Path,
    file: &str,
) -> Result<LoadedInput, PipelineError> {
    let mut source = ConfigSource::from_text(file, "");
    source.base_dir = base_dir.to_path_buf();
    load_input_from(input, &source)
}

/// The file a path-valued key names, resolved by the path rule of
/// [`ConfigSource`] (the config file's folder; `--set` keys and text configs
/// against the current directory).
///
/// # Errors
/// [`ConfigError::MissingFile`] when it does not exist, naming the key, the
/// path as written, the line of the config and the folder it was resolved
/// against.
pub fn input_file(source: &ConfigSource, key: &str, spec: &str) -> Result<PathBuf, ConfigError> {
    let full = source.resolve_path(key, spec);
    if full.exists() {
        return Ok(full);
    }
    let base = source.base_dir_for(key);
    let dir = std::path::absolute(base).unwrap_or_else(|_| base.to_path_buf());
    Err(ConfigError::MissingFile {
        origin: source.origin_of(key),
        key: key.to_string(),
        written: spec.to_string(),
        dir: dir.display().to_string(),
        rule: if source.is_command_line_key(key) {
            "a path given with --set resolves against the current directory"
        } else {
            "a relative path in a config file resolves against the file's folder; in a config given as text, against the current directory"
        },
    })
}

/// The keys of `[input]` that may name a file.
pub const INPUT_FILE_KEYS: [&str; 5] = [
    "input.mesh",
    "input.exemplar",
    "input.height_map",
    "input.normal_map",
    "input.roughness_map",
];

/// Checks that every file `[input]` names exists (builtins and derivations
/// need none); returns the resolved paths. [`load_input_from`] does the same
/// checks before loading.
pub fn check_input_files(
    input: &RawInput,
    source: &ConfigSource,
) -> Result<Vec<PathBuf>, ConfigError> {
    let mut files = Vec::new();
    let entries = [
        (input.mesh.as_deref(), "builtin:"),
        (Some(input.exemplar.as_str()), "builtin:"),
        (input.height_map.as_deref(), "derive:"),
        (input.normal_map.as_deref(), "derive:"),
        (input.roughness_map.as_deref(), "derive:"),
    ];
    for (key, (spec, special)) in INPUT_FILE_KEYS.into_iter().zip(entries) {
        if let Some(spec) = spec.map(str::trim).filter(|s| !s.starts_with(special)) {
            files.push(input_file(source, key, spec)?);
        }
    }
    Ok(files)
}

/// Loads the mesh and exemplar named in `[input]`, relative paths resolved
/// by the path rule of [`ConfigSource`].
pub fn load_input_from(
    input: &RawInput,
    source: &ConfigSource,
) -> Result<LoadedInput, PipelineError> {
    let _span = tracing::info_span!("load_input").entered();
    check_input_files(input, source)?;
    let file = source.file.as_str();
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
        // `--set input.mesh=FILE` replacing a config's builtin mesh: the
        // config's options were for that builtin, so they are dropped (and
        // said so); options given on the command line are still refused.
        let replaced_builtin = source.is_command_line_key("input.mesh")
            && !source
                .command_line_keys
                .iter()
                .any(|k| k.starts_with("input.mesh_options"));
        if !input.mesh_options.is_empty() && replaced_builtin {
            tracing::warn!(
                "input.mesh_options ({}) ignored: they apply to the builtin mesh that --set input.mesh replaced",
                input
                    .mesh_options
                    .keys()
                    .cloned()
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        } else if !input.mesh_options.is_empty() {
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
                ..load_exemplar(input, source)?
            });
        };
        let path = source.resolve_path("input.mesh", mesh_path.trim());
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
        ..load_exemplar(input, source)?
    })
}

fn load_exemplar(input: &RawInput, source: &ConfigSource) -> Result<LoadedInput, PipelineError> {
    let file = source.file.as_str();
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
    let (exemplar, exemplar_name) = crate::image::exemplar_from_spec(
        &input.exemplar,
        source.base_dir_for("input.exemplar"),
        &opts,
    )?;
    let channels = load_channels(input, source, &exemplar, &exemplar_name, &opts)?;
    Ok(LoadedInput {
        mesh: PolyMesh::new(),
        load_report: String::new(),
        exemplar,
        exemplar_name,
        channels,
    })
}

/// Largest `normal_strength`.
const MAX_NORMAL_STRENGTH: f32 = 100.0;

/// Loads or derives the extra exemplar maps of `[input]` (`height_map`,
/// `normal_map`, `roughness_map`): files must be the exemplar's size; grey
/// maps keep their first channel or the luminance of RGB files; normal maps
/// need three channels.
fn load_channels(
    input: &RawInput,
    source: &ConfigSource,
    exemplar: &Image,
    exemplar_name: &str,
    opts: &crate::image::ExemplarOptions,
) -> Result<crate::world::ExemplarChannels, PipelineError> {
    use crate::kernels::atlas::channels as ch;
    let file = source.file.as_str();
    let value_err = |key: &str, message: String| -> PipelineError {
        ConfigError::Value {
            file: file.to_string(),
            key: key.to_string(),
            message,
        }
        .into()
    };
    let load_file = |key: &str, spec: &str| -> Result<Image, PipelineError> {
        let img = crate::image::load_image(&source.resolve_path(key, spec))?;
        if (img.width, img.height) != (exemplar.width, exemplar.height) {
            return Err(crate::image::ImageError::ChannelSize {
                key: key.to_string(),
                path: spec.to_string(),
                width: img.width,
                height: img.height,
                exemplar: exemplar_name.to_string(),
                exemplar_width: exemplar.width,
                exemplar_height: exemplar.height,
            }
            .into());
        }
        Ok(img)
    };
    let grey = |img: Image| {
        if img.channels >= 3 {
            ch::luminance_image(&img)
        } else {
            let c = img.channels.max(1) as usize;
            Image {
                width: img.width,
                height: img.height,
                channels: 1,
                data: img.data.chunks_exact(c).map(|p| p[0]).collect(),
            }
        }
    };
    let unknown_derive = |key: &str, spec: &str, allowed: &str| {
        value_err(
            key,
            format!(
                "{spec:?} is not a known derivation; allowed: {allowed}, or a path to an image file"
            ),
        )
    };

    let height = match input.height_map.as_deref().map(str::trim) {
        None => None,
        Some("derive:luminance") => Some(ch::luminance_image(exemplar)),
        Some("derive:builtin") => {
            let Some(name) = input.exemplar.trim().strip_prefix("builtin:") else {
                return Err(value_err(
                    "input.height_map",
                    format!(
                        "\"derive:builtin\" needs a builtin exemplar (exemplar = \"builtin:NAME\"), not {exemplar_name:?}; use \"derive:luminance\" or a file"
                    ),
                ));
            };
            Some(crate::image::builtin_height(name.trim(), opts)?)
        }
        Some(spec) if spec.starts_with("derive:") => {
            return Err(unknown_derive(
                "input.height_map",
                spec,
                "derive:luminance, derive:builtin",
            ));
        }
        Some(spec) => Some(grey(load_file("input.height_map", spec)?)),
    };

    let strength = input.normal_strength;
    if !(strength.is_finite() && (0.0..=MAX_NORMAL_STRENGTH).contains(&strength)) {
        return Err(value_err(
            "input.normal_strength",
            format!("{strength} is out of range; allowed: 0..={MAX_NORMAL_STRENGTH}"),
        ));
    }
    let normal = match input.normal_map.as_deref().map(str::trim) {
        None => None,
        Some("derive:height") => {
            let Some(h) = height.as_ref() else {
                return Err(value_err(
                    "input.normal_map",
                    "\"derive:height\" needs a height map; set input.height_map (e.g. \"derive:luminance\")".into(),
                ));
            };
            Some(ch::normal_from_height(h, strength, input.exemplar_wrap))
        }
        Some(spec) if spec.starts_with("derive:") => {
            return Err(unknown_derive("input.normal_map", spec, "derive:height"));
        }
        Some(spec) => {
            let img = load_file("input.normal_map", spec)?;
            if img.channels < 3 {
                return Err(value_err(
                    "input.normal_map",
                    format!(
                        "{spec} has {} channel(s); a normal map needs 3 (RGB) or 4 (RGBA)",
                        img.channels
                    ),
                ));
            }
            let c = img.channels as usize;
            let data = img
                .data
                .chunks_exact(c)
                .flat_map(|p| [p[0], p[1], p[2]])
                .collect();
            Some(Image {
                width: img.width,
                height: img.height,
                channels: 3,
                data,
            })
        }
    };

    let roughness = match input.roughness_map.as_deref().map(str::trim) {
        None => None,
        Some("derive:luminance") => Some(ch::inverted_luminance_image(exemplar)),
        Some(spec) if spec.starts_with("derive:") => {
            return Err(unknown_derive(
                "input.roughness_map",
                spec,
                "derive:luminance",
            ));
        }
        Some(spec) => Some(grey(load_file("input.roughness_map", spec)?)),
    };

    Ok(crate::world::ExemplarChannels {
        normal,
        roughness,
        height,
        wrap: input.exemplar_wrap,
    })
}
