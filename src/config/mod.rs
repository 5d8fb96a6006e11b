//! Pipeline configuration: raw TOML types (serde, unknown keys rejected),
//! `--set` overrides, and the source text kept for line numbers in errors.
//!
//! The typed, validated form of each stage lives with the stage
//! (`crate::stages`); [`crate::pipeline::Pipeline::from_config`] turns a
//! [`RawConfig`] into it.

mod error;
pub mod params;

pub use error::ConfigError;
pub use params::{ParamDoc, ParamRange, StageSettings};

use crate::image::sample::Wrap;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// The config file's text and where it came from.
///
/// The path rule: a relative path written in a config **file** (`[input]`
/// paths, a stage's `mask_image`) resolves against the folder of that file,
/// as in most config-driven tools, so a config and its data move together
/// and run from any directory. A path given on the command line with
/// `--set KEY=PATH` resolves against the current directory, as every other
/// command-line path does; so does every path of a config given as text
/// ([`ConfigSource::from_text`], no file). `[output] dir` (and `--out`) are
/// not inputs: they resolve against the current directory, so results land
/// where the user runs the command (`out/...` under the repository root),
/// whichever folder holds the config, and a config in a read-only folder
/// still runs.
#[derive(Clone, Debug)]
pub struct ConfigSource {
    /// Name shown in messages (the path as given).
    pub file: String,
    /// The TOML text (after `--set` overrides, if any).
    pub text: String,
    /// Folder against which relative input paths written in the config
    /// resolve: the config file's folder, or the current directory (`.`) for
    /// a config given as text.
    pub base_dir: PathBuf,
    /// Dotted keys set with `--set` (`input.mesh`, `stage.3.mask_image`):
    /// their relative paths resolve against the current directory.
    pub command_line_keys: Vec<String>,
    /// The name and text before `--set` rewrote them, so that messages about
    /// keys from the file give the line the user wrote.
    pub before_overrides: Option<(String, String)>,
}

impl ConfigSource {
    /// Reads a config file; relative input paths in it resolve against its
    /// folder.
    pub fn from_file(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let base_dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let text = without_bom(text);
        Ok(Self {
            file: path.display().to_string(),
            text,
            base_dir,
            command_line_keys: Vec::new(),
            before_overrides: None,
        })
    }

    /// A config given as text (tests, embedded configs): relative paths
    /// resolve against the current directory.
    pub fn from_text(name: &str, text: &str) -> Self {
        Self {
            file: name.to_string(),
            text: without_bom(text.to_string()),
            base_dir: PathBuf::from("."),
            command_line_keys: Vec::new(),
            before_overrides: None,
        }
    }

    /// Whether the dotted `key` was set with `--set`.
    pub fn is_command_line_key(&self, key: &str) -> bool {
        self.command_line_keys.iter().any(|k| k == key)
    }

    /// The folder a relative path under the dotted `key` resolves against:
    /// the current directory (`.`) for a `--set` key, else [`Self::base_dir`].
    pub fn base_dir_for(&self, key: &str) -> &Path {
        if self.is_command_line_key(key) {
            Path::new(".")
        } else {
            &self.base_dir
        }
    }

    /// Resolves `spec`, the path written under the dotted `key`: absolute
    /// paths stay, relative ones join [`Self::base_dir_for`] the key.
    pub fn resolve_path(&self, key: &str, spec: &str) -> PathBuf {
        let path = Path::new(spec);
        if path.is_absolute() {
            path.to_path_buf()
        } else {
            self.base_dir_for(key).join(path)
        }
    }

    /// Where the value of the dotted `key` is written, for messages:
    /// `FILE:LINE` (the line of the value in [`Self::text`]), `--set KEY` for
    /// a command-line key, or `FILE` when the key is not found.
    pub fn origin_of(&self, key: &str) -> String {
        if self.is_command_line_key(key) {
            return format!("--set {key}");
        }
        let file = self.before_overrides.as_ref().map_or(&self.file, |b| &b.0);
        match self.line_of_key(key) {
            Some(line) => format!("{file}:{line}"),
            None => file.clone(),
        }
    }

    /// 1-based line of the value of a dotted `key` (`input.mesh`,
    /// `output.dir`, `stage.N.PARAM` with `N` from 1) in the text as written
    /// in the file (before `--set` overrides).
    pub fn line_of_key(&self, key: &str) -> Option<usize> {
        type Table = BTreeMap<String, Spanned<toml::Value>>;
        #[derive(Deserialize)]
        struct Spans {
            #[serde(default)]
            input: Table,
            #[serde(default)]
            output: Table,
            #[serde(default)]
            stage: Vec<Table>,
        }
        let text = self.before_overrides.as_ref().map_or(&self.text, |b| &b.1);
        let spans: Spans = toml::from_str(text).ok()?;
        let segments: Vec<&str> = key.split('.').collect();
        let value = match segments.as_slice() {
            ["input", name] => spans.input.get(*name),
            ["output", name] => spans.output.get(*name),
            ["stage", n, name] => n
                .parse::<usize>()
                .ok()
                .and_then(|n| n.checked_sub(1))
                .and_then(|i| spans.stage.get(i))
                .and_then(|t| t.get(*name)),
            _ => None,
        }?;
        Some(
            1 + text
                .bytes()
                .take(value.span().start)
                .filter(|&b| b == b'\n')
                .count(),
        )
    }

    /// 1-based line of a byte offset into the text.
    pub fn line_of(&self, offset: usize) -> usize {
        1 + self
            .text
            .as_bytes()
            .iter()
            .take(offset)
            .filter(|&&b| b == b'\n')
            .count()
    }

    /// Applies `--set PATH=VALUE` overrides. PATH is the dotted TOML path;
    /// `stage.N` addresses the N-th `[[stage]]` (1-based, as messages count
    /// them). VALUE is parsed as a TOML value, or taken as a string when it is
    /// not one (`--set input.mesh=../x.obj`). Line numbers in later messages
    /// then refer to the config as rewritten with the overrides. Relative
    /// paths set here resolve against the current directory (see
    /// [`ConfigSource`]).
    pub fn apply_overrides(&mut self, overrides: &[String]) -> Result<(), ConfigError> {
        if overrides.is_empty() {
            return Ok(());
        }
        let mut table: toml::Table =
            toml::from_str(&self.text).map_err(|e| ConfigError::Syntax {
                file: self.file.clone(),
                message: e.to_string(),
            })?;
        if self.before_overrides.is_none() {
            self.before_overrides = Some((self.file.clone(), self.text.clone()));
        }
        for assignment in overrides {
            apply_override(&mut table, assignment)?;
            if let Some((path, _)) = assignment.split_once('=') {
                let key = path.trim().to_string();
                if !self.command_line_keys.contains(&key) {
                    self.command_line_keys.push(key);
                }
            }
        }
        self.text = toml::to_string(&table).map_err(|e| ConfigError::Override {
            assignment: overrides.join(" "),
            message: e.to_string(),
        })?;
        self.file = format!("{} (with --set overrides)", self.file);
        Ok(())
    }

    /// Parses the text into the raw config.
    pub fn parse(&self) -> Result<RawConfig, ConfigError> {
        toml::from_str(&self.text).map_err(|e| ConfigError::Syntax {
            file: self.file.clone(),
            message: e.to_string().trim_end().to_string(),
        })
    }
}

/// `text` without a leading UTF-8 byte-order mark (which some Windows editors
/// write and the TOML parser rejects as a stray character).
fn without_bom(text: String) -> String {
    match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    }
}

fn apply_override(table: &mut toml::Table, assignment: &str) -> Result<(), ConfigError> {
    let err = |message: String| ConfigError::Override {
        assignment: assignment.to_string(),
        message,
    };
    let (path, value_text) = assignment
        .split_once('=')
        .ok_or_else(|| err("expected PATH=VALUE, e.g. stage.2.iterations=50".into()))?;
    let path = path.trim();
    let value: toml::Value = toml::from_str::<toml::Table>(&format!("v = {value_text}"))
        .ok()
        .and_then(|mut t| t.remove("v"))
        .unwrap_or_else(|| toml::Value::String(value_text.to_string()));
    let segments: Vec<&str> = path.split('.').collect();
    if segments.iter().any(|s| s.is_empty()) {
        return Err(err(format!("PATH {path:?} has an empty segment")));
    }
    let mut cur = table;
    let (last, parents) = segments
        .split_last()
        .ok_or_else(|| err("empty PATH".into()))?;
    let mut i = 0;
    while i < parents.len() {
        let seg = parents[i];
        if seg == "stage" {
            let idx_text = segments
                .get(i + 1)
                .ok_or_else(|| err("`stage` must be followed by a stage number".into()))?;
            let n: usize = idx_text
                .parse()
                .map_err(|_| err(format!("stage number {idx_text:?} is not a number")))?;
            let stages = cur
                .get_mut("stage")
                .and_then(|v| v.as_array_mut())
                .ok_or_else(|| err("the config has no [[stage]] entries".into()))?;
            let count = stages.len();
            let entry = n
                .checked_sub(1)
                .and_then(|k| stages.get_mut(k))
                .ok_or_else(|| err(format!("stage {n} does not exist; stages are 1..={count}")))?;
            if i + 1 == parents.len() {
                let t = entry
                    .as_table_mut()
                    .ok_or_else(|| err(format!("stage {n} is not a table")))?;
                t.insert(last.to_string(), value);
                return Ok(());
            }
            cur = entry
                .as_table_mut()
                .ok_or_else(|| err(format!("stage {n} is not a table")))?;
            i += 2;
            continue;
        }
        let next = cur
            .entry(seg.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        cur = next
            .as_table_mut()
            .ok_or_else(|| err(format!("`{seg}` is a value, not a table")))?;
        i += 1;
    }
    cur.insert(last.to_string(), value);
    Ok(())
}

/// The config file as written, before validation.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RawConfig {
    /// Seed of every random choice in the run. Default 0.
    #[serde(default)]
    pub seed: u64,
    /// What to texture with what.
    pub input: RawInput,
    /// The stages, in order.
    #[serde(default)]
    pub stage: Vec<Spanned<BTreeMap<Spanned<String>, toml::Value>>>,
    /// Where results go.
    #[serde(default)]
    pub output: RawOutput,
}

/// `[input]`: the mesh and the exemplar.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RawInput {
    /// `builtin:NAME` or a path to .obj, .ply, .off or .stl. Optional for
    /// image-only pipelines (`jump_image`). A relative path (here and in
    /// every path of `[input]`) resolves against the config file's folder;
    /// given with `--set`, against the current directory. Faces of more than
    /// 255 corners are triangulated on load; a UTF-8 byte-order mark is
    /// skipped.
    #[serde(default)]
    pub mesh: Option<String>,
    /// `builtin:NAME` or a path to .png, .jpg, .bmp or .tga. Files (and the
    /// material maps below) may have at most
    /// [`MAX_IMAGE_SIDE`](crate::image::io::MAX_IMAGE_SIDE) = 8192 pixels a
    /// side and [`MAX_IMAGE_PIXELS`](crate::image::io::MAX_IMAGE_PIXELS) =
    /// 4096² pixels in all, checked from the file header before decoding.
    pub exemplar: String,
    /// Options of a builtin mesh (`surfsynth stages` lists them).
    #[serde(default)]
    pub mesh_options: toml::Table,
    /// Options of a builtin exemplar.
    #[serde(default)]
    pub exemplar_options: toml::Table,
    /// Merge vertices at identical positions on load (scans exported with split vertices).
    #[serde(default)]
    pub merge_duplicates: bool,
    /// Whether the exemplar tiles: `repeat` (toroidal neighbourhoods) or `clamp`.
    #[serde(default)]
    pub exemplar_wrap: Wrap,
    /// Height (displacement) map that follows the synthesis: a path to an
    /// image the exemplar's size (an RGB file is reduced to its luminance),
    /// `derive:luminance` (the exemplar's luminance) or `derive:builtin` (a
    /// builtin exemplar's own height). Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_map: Option<String>,
    /// Tangent-space normal map (+X right, +Y up as displayed): a path to an
    /// RGB image the exemplar's size or `derive:height` (Sobel of the height
    /// map, `normal_strength`). Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub normal_map: Option<String>,
    /// Roughness map: a path to an image the exemplar's size (reduced to
    /// luminance) or `derive:luminance` (1 − the exemplar's luminance). Optional.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub roughness_map: Option<String>,
    /// Relief of `normal_map = "derive:height"`: pixels of height that a
    /// height difference of 1 spans; 0..=100, default 4.
    #[serde(default = "default_normal_strength")]
    pub normal_strength: f32,
    /// The one texture scale every method uses (see [`TextureScaleUnit`]):
    /// how large the exemplar appears on the surface. Default 0.5 with
    /// `texture_scale_unit = "diagonal"`: the exemplar's width spans half
    /// the input mesh's bounding-box diagonal, whatever the mesh's units.
    /// Stage parameters that set a scale (`jump_surface.scale`,
    /// `graph_match.r_scale`, `coherent.scale`, `tangent_field.patch_size`,
    /// `retile.vertices`, `subdivide_sqrt2.target_vertices`, `bake.size`)
    /// override it for their stage when given.
    #[serde(default = "default_texture_scale")]
    pub texture_scale: f64,
    /// Unit of `texture_scale`.
    #[serde(default)]
    pub texture_scale_unit: TextureScaleUnit,
}

fn default_normal_strength() -> f32 {
    4.0
}

fn default_texture_scale() -> f64 {
    DEFAULT_TEXTURE_SCALE
}

/// Default `[input] texture_scale`: the exemplar's width spans half the
/// bounding-box diagonal. With a 128-pixel exemplar a compact object (sphere,
/// bunny) then needs about 70 000 vertices for one exemplar pixel per vertex
/// spacing (the per-vertex methods' resolution), and a jump-map or lapped
/// result shows the exemplar two to three times across the object.
pub const DEFAULT_TEXTURE_SCALE: f64 = 0.5;

/// Largest `[input] texture_scale` value in any unit (and smallest: its
/// reciprocal), so derived vertex counts and atlas sizes stay finite.
pub const TEXTURE_SCALE_LIMIT: f64 = 1e9;

/// What `[input] texture_scale` measures.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TextureScaleUnit {
    /// The exemplar's width as a fraction of the input mesh's bounding-box
    /// diagonal (scale-free: the same config suits a mesh in millimetres or
    /// kilometres).
    #[default]
    Diagonal,
    /// The exemplar's width in world units.
    World,
    /// Exemplar pixels per world unit (the planar benchmark's 1 pixel per
    /// unit).
    PixelsPerUnit,
}

impl TextureScaleUnit {
    /// The allowed spellings, for messages.
    pub const ALLOWED: &'static str = "\"diagonal\", \"world\", \"pixels_per_unit\"";

    /// Exemplar pixels per world unit for `value` in this unit, an exemplar
    /// `exemplar_width` pixels wide and a mesh of bounding-box diagonal
    /// `diagonal` world units.
    pub fn texels_per_unit(self, value: f64, exemplar_width: u32, diagonal: f64) -> f64 {
        let w = f64::from(exemplar_width.max(1));
        match self {
            Self::Diagonal => w / (value * diagonal).max(f64::MIN_POSITIVE),
            Self::World => w / value.max(f64::MIN_POSITIVE),
            Self::PixelsPerUnit => value,
        }
    }
}

/// `[output]`: the output folder and run-wide output settings.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct RawOutput {
    /// Output folder (created). Default `out/run`. Relative to the current
    /// directory, not to the config file (see [`ConfigSource`]).
    pub dir: String,
    /// Neighbourhood width of the texture-energy metric, texels (odd, 3..=15).
    pub metric_neighbourhood: u32,
    /// Sampled locations of the texture-energy metric (10..=100000).
    pub metric_samples: usize,
}

impl Default for RawOutput {
    fn default() -> Self {
        Self {
            dir: "out/run".into(),
            metric_neighbourhood: 7,
            metric_samples: 1000,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TEXT: &str = r#"
seed = 1
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"

[[stage]]
kind = "orientation"
mode = "global"

[[stage]]
kind = "init_colours"
"#;

    #[test]
    fn overrides_address_stages_from_one_and_create_tables() {
        let mut src = ConfigSource::from_text("t.toml", TEXT);
        src.apply_overrides(&[
            "stage.1.mode=random".into(),
            "seed=3".into(),
            "input.mesh=data/meshes/knot.off".into(),
            "input.mesh_options.subdivisions=2".into(),
        ])
        .unwrap();
        let raw = src.parse().unwrap();
        assert_eq!(raw.seed, 3);
        assert_eq!(raw.input.mesh.as_deref(), Some("data/meshes/knot.off"));
        assert_eq!(raw.input.mesh_options["subdivisions"].as_integer(), Some(2));
        let mode = raw.stage[0]
            .get_ref()
            .iter()
            .find(|(k, _)| k.get_ref() == "mode")
            .map(|(_, v)| v.clone());
        assert_eq!(mode, Some(toml::Value::String("random".into())));
    }

    #[test]
    fn override_errors_name_the_problem() {
        let mut src = ConfigSource::from_text("t.toml", TEXT);
        let e = src.apply_overrides(&["stage.5.x=1".into()]).unwrap_err();
        assert!(e.to_string().contains("stages are 1..=2"), "{e}");
        let e = src.apply_overrides(&["seed".into()]).unwrap_err();
        assert!(e.to_string().contains("PATH=VALUE"), "{e}");
    }

    #[test]
    fn unknown_top_level_key_is_rejected_with_its_line() {
        let src = ConfigSource::from_text("t.toml", &format!("bogus = 1\n{TEXT}"));
        let e = src.parse().unwrap_err().to_string();
        assert!(e.contains("bogus") && e.contains("t.toml"), "{e}");
    }

    #[test]
    fn stage_keys_carry_spans() {
        let src = ConfigSource::from_text("t.toml", TEXT);
        let raw = src.parse().unwrap();
        let (key, _) = raw.stage[0].get_ref().iter().next().unwrap();
        assert_eq!(src.line_of(key.span().start), 8);
    }
}
