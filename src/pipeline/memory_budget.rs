//! Up-front memory estimates (issue 43): every stage estimates its large
//! allocations from its typed settings and the input's sizes
//! ([`crate::pipeline::Stage::memory_estimate`]); a run whose estimate is
//! over the memory it may use ([`MemoryLimit`]: cgroup, `RLIMIT_AS`,
//! physical memory or `$SURFSYNTH_MEMORY_LIMIT`) is refused with exit 2
//! before any work, naming the stage, the parameter, the estimate, the
//! limit and the largest value of the parameter that fits, instead of
//! aborting when an allocation fails mid-run.
//!
//! Checked twice: at validation with the sizes known before loading
//! ([`InputSizes::default`]: no mesh, no exemplar, so only what the
//! settings alone decide is refused: `jump_image`'s size, `bake.size`,
//! `lapped_paste.atlas_size`, `export`'s `bake_size` and `plane_size`,
//! explicit vertex counts, a builtin mesh's `resolution`), then once the
//! input is loaded, before the first stage, with its real sizes (the
//! jump-map analysis of the exemplar, sizes derived from the texture
//! scale, per-face terms).
//!
//! An estimate is a stage's peak beyond what was live when it started (its
//! working buffers and its results), checked against the limit less the
//! loaded input's own bytes. The constants are measured with a counting
//! allocator (`tests/memory_estimates.rs` checks each estimate within 2× of
//! the measured peak at three sizes).

use super::memory_limit::{LIMIT_VAR, MemoryLimit};
use crate::config::{ConfigError, RawInput};
use crate::pipeline::registry::StagePlan;

/// Sizes of the run's input that estimates scale with. Before the input is
/// loaded (validation) every size is 0 and `loaded` false: estimates are
/// then lower bounds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct InputSizes {
    /// Whether the sizes are the loaded input's.
    pub loaded: bool,
    /// Vertices of the input mesh.
    pub vertices: u64,
    /// Faces (polygons) of the input mesh.
    pub faces: u64,
    /// Triangles of its fan triangulation.
    pub triangles: u64,
    /// Its surface area, world units².
    pub area: f64,
    /// Exemplar width, pixels.
    pub exemplar_width: u32,
    /// Exemplar height, pixels.
    pub exemplar_height: u32,
    /// Exemplar channels.
    pub exemplar_channels: u32,
    /// Channels of the exemplar's material maps (normal 3, roughness 1,
    /// height 1), summed.
    pub map_channels: u32,
    /// `[input] texture_scale` resolved: exemplar pixels per world unit.
    pub texels_per_unit: f64,
    /// Bounding-box diagonal of the input mesh, world units.
    pub diagonal: f64,
    /// Whether the exemplar tiles (`[input] exemplar_wrap = "repeat"`).
    pub exemplar_repeats: bool,
}

impl InputSizes {
    /// The sizes of a loaded input under `input`'s texture scale.
    pub fn of(loaded: &super::LoadedInput, input: &RawInput) -> Self {
        let mesh = &loaded.mesh;
        let ex = &loaded.exemplar;
        let ch = &loaded.channels;
        let map_channels = [&ch.normal, &ch.roughness, &ch.height]
            .iter()
            .filter_map(|m| m.as_ref().map(|i| i.channels))
            .sum();
        let diagonal = crate::mesh::repair::bounding_box_diagonal(&mesh.positions);
        Self {
            loaded: true,
            vertices: mesh.vertex_count() as u64,
            faces: mesh.face_count() as u64,
            triangles: (mesh.corner_count() as u64).saturating_sub(2 * mesh.face_count() as u64),
            area: f64::from(mesh.area()),
            exemplar_width: ex.width,
            exemplar_height: ex.height,
            exemplar_channels: ex.channels,
            map_channels,
            texels_per_unit: input.texture_scale_unit.texels_per_unit(
                input.texture_scale,
                ex.width,
                diagonal,
            ),
            diagonal,
            exemplar_repeats: input.exemplar_wrap == crate::image::sample::Wrap::Repeat,
        }
    }

    /// Exemplar pixels.
    pub fn exemplar_pixels(&self) -> u64 {
        u64::from(self.exemplar_width) * u64::from(self.exemplar_height)
    }

    /// Bytes the loaded input holds for the whole run: the exemplar and its
    /// maps (`f32` per channel), the mesh (positions, corners, face starts).
    pub fn resident_bytes(&self) -> u64 {
        let image =
            self.exemplar_pixels() * u64::from(self.exemplar_channels + self.map_channels) * 4;
        let mesh = self.vertices * 12 + (self.triangles + 2 * self.faces) * 4 + self.faces * 4;
        image + mesh
    }

    /// Vertices a surface of `area` needs for one vertex per exemplar pixel²
    /// at the run's texture scale
    /// ([`crate::stages::world::TextureScale::vertices_for_area`]).
    pub fn vertices_for_area(&self, area: f64) -> f64 {
        area * self.texels_per_unit * self.texels_per_unit
    }
}

/// The largest value of a parameter within a number of bytes, as the user
/// would write it (`None`: not even the smallest).
type Largest = Box<dyn Fn(u64) -> Option<String>>;

/// One way out of an estimate over the limit: a parameter and the largest
/// value of it that fits.
pub struct Fit {
    /// The parameter, as a config names it (`width x height`, `size`).
    pub param: String,
    /// Between the parameter and its value in a message: ` = `.
    pub separator: &'static str,
    largest: Largest,
}

impl Fit {
    /// The largest value of an integer parameter in `range` whose
    /// `bytes_at` is within a budget (`bytes_at` non-decreasing), shown by
    /// `show`.
    pub fn growing(
        param: impl Into<String>,
        range: (u64, u64),
        bytes_at: impl Fn(u64) -> u64 + 'static,
        show: impl Fn(u64) -> String + 'static,
    ) -> Self {
        Self {
            param: param.into(),
            separator: " = ",
            largest: Box::new(move |budget| {
                let (mut lo, mut hi) = range;
                if bytes_at(lo) > budget {
                    return None;
                }
                while lo < hi {
                    let mid = lo + (hi - lo).div_ceil(2);
                    if bytes_at(mid) <= budget {
                        lo = mid;
                    } else {
                        hi = mid - 1;
                    }
                }
                Some(show(lo))
            }),
        }
    }

    /// The largest of `values` (in increasing order) whose `bytes_at` is
    /// within a budget, for a parameter whose estimate need not grow with
    /// it (a scan rather than a bisection), shown by `show`.
    pub fn scan(
        param: impl Into<String>,
        values: Vec<u64>,
        bytes_at: impl Fn(u64) -> u64 + 'static,
        show: impl Fn(u64) -> String + 'static,
    ) -> Self {
        Self {
            param: param.into(),
            separator: " = ",
            largest: Box::new(move |budget| {
                values
                    .iter()
                    .rev()
                    .find(|&&v| bytes_at(v) <= budget)
                    .map(|&v| show(v))
            }),
        }
    }

    /// A fit computed by `largest` (the value within a budget, as written).
    pub fn with(
        param: impl Into<String>,
        largest: impl Fn(u64) -> Option<String> + 'static,
    ) -> Self {
        Self {
            param: param.into(),
            separator: " = ",
            largest: Box::new(largest),
        }
    }

    /// Written `PARAM SEPARATOR VALUE` in messages (` = ` by default).
    pub fn separated(mut self, separator: &'static str) -> Self {
        self.separator = separator;
        self
    }

    /// The largest value within `budget` bytes, as written in a config.
    pub fn largest_within(&self, budget: u64) -> Option<String> {
        (self.largest)(budget)
    }
}

/// A stage's estimate of one large allocation (or of its peak while a
/// parameter's work runs).
pub struct MemoryEstimate {
    /// The parameter it grows with, as a config names it.
    pub param: &'static str,
    /// Its value, as written (`8192x8192`, `[31, 31, 31]`).
    pub value: String,
    /// What is allocated, for messages.
    pub what: String,
    /// Estimated bytes.
    pub bytes: u64,
    /// Ways out when over the limit, the parameter's own first.
    pub fits: Vec<Fit>,
}

impl MemoryEstimate {
    /// An estimate of `bytes_at(value)` growing with the integer parameter
    /// `param` in `range`, shown by `show`.
    pub fn growing(
        param: &'static str,
        what: impl Into<String>,
        value: u64,
        range: (u64, u64),
        bytes_at: impl Fn(u64) -> u64 + Clone + 'static,
        show: impl Fn(u64) -> String + Clone + 'static,
    ) -> Self {
        Self {
            param,
            value: show(value),
            what: what.into(),
            bytes: bytes_at(value),
            fits: vec![Fit::growing(param, range, bytes_at, show)],
        }
    }

    /// [`Self::growing`] for an image of `width × height` pixels (`param`
    /// names both, e.g. `width x height`): the largest size that fits keeps
    /// the aspect ratio, its longer side in `1..=max_side`.
    pub fn image(
        param: &'static str,
        what: impl Into<String>,
        (width, height): (u32, u32),
        max_side: u32,
        bytes_at: impl Fn(u64, u64) -> u64 + Clone + 'static,
    ) -> Self {
        let (w, h) = (u64::from(width.max(1)), u64::from(height.max(1)));
        let long = w.max(h);
        let dims = move |side: u64| {
            let scale = |d: u64| ((d as f64 * side as f64 / long as f64).round() as u64).max(1);
            (scale(w), scale(h))
        };
        let show = move |side: u64| {
            let (a, b) = dims(side);
            format!("{a}x{b}")
        };
        let now = bytes_at(w, h);
        let bytes = move |side: u64| {
            let (a, b) = dims(side);
            bytes_at(a, b)
        };
        Self {
            param,
            value: format!("{width}x{height}"),
            what: what.into(),
            bytes: now,
            fits: vec![Fit::growing(param, (1, u64::from(max_side)), bytes, show)],
        }
    }

    /// Another way out, tried after the parameter's own.
    pub fn or(mut self, fit: Fit) -> Self {
        self.fits.push(fit);
        self
    }
}

/// Shows a byte count in GiB (two decimals), else MiB, else KiB.
pub fn show_bytes(bytes: u64) -> String {
    let b = bytes as f64;
    if bytes >= 1 << 40 {
        format!("{:.2} TiB", b / (1u64 << 40) as f64)
    } else if bytes >= 1 << 30 {
        format!("{:.2} GiB", b / (1u64 << 30) as f64)
    } else if bytes >= 1 << 20 {
        format!("{:.1} MiB", b / (1u64 << 20) as f64)
    } else {
        format!("{:.0} KiB", b / 1024.0)
    }
}

/// The message of an estimate over `limit` with `resident` bytes of input
/// held for the whole run: the parameter, its value, the estimate, the
/// limit and where it comes from, and the largest values that fit.
pub fn over_limit_message(e: &MemoryEstimate, limit: &MemoryLimit, resident: u64) -> String {
    let budget = limit.bytes.saturating_sub(resident);
    let fits: Vec<String> = e
        .fits
        .iter()
        .filter_map(|f| {
            f.largest_within(budget)
                .map(|v| format!("{}{}{v}", f.param, f.separator))
        })
        .collect();
    let input = if resident > 0 {
        format!(", {} of which the loaded input holds", show_bytes(resident))
    } else {
        String::new()
    };
    let way_out = if fits.is_empty() {
        format!(
            "no value of `{}` fits; allowed: an estimate within the limit (free memory, or raise {LIMIT_VAR})",
            e.param
        )
    } else {
        format!("the largest that fits: {}", fits.join(", or "))
    };
    format!(
        "`{}` = {} needs an estimated {} of memory ({}), over the memory limit of {} ({}){input}; {way_out}",
        e.param,
        e.value,
        show_bytes(e.bytes),
        e.what,
        show_bytes(limit.bytes),
        limit.source,
    )
}

/// One stage's estimate, for `metrics.json`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct StageEstimate {
    /// 1-based stage number.
    pub index: usize,
    /// Stage kind.
    pub kind: &'static str,
    /// The parameter the estimate grows with.
    pub param: &'static str,
    /// Estimated bytes.
    pub bytes: u64,
}

/// A stage whose estimate is over the limit.
#[derive(Clone, Debug, PartialEq)]
pub struct Refusal {
    /// 1-based stage number.
    pub index: usize,
    /// Stage kind.
    pub kind: &'static str,
    /// The parameter.
    pub param: &'static str,
    /// [`over_limit_message`].
    pub message: String,
}

/// Checks every stage's estimates for `sizes` against `limit`; returns them
/// all when they fit.
///
/// # Errors
/// The first estimate over the limit (less the input's resident bytes).
pub fn check_stages(
    stages: &[Box<dyn StagePlan>],
    sizes: &InputSizes,
    limit: &MemoryLimit,
) -> Result<Vec<StageEstimate>, Refusal> {
    let resident = sizes.resident_bytes();
    let mut all = Vec::new();
    for (i, stage) in stages.iter().enumerate() {
        for e in stage.memory_estimate(sizes) {
            if e.bytes.saturating_add(resident) > limit.bytes {
                return Err(Refusal {
                    index: i + 1,
                    kind: stage.kind(),
                    param: e.param,
                    message: over_limit_message(&e, limit, resident),
                });
            }
            all.push(StageEstimate {
                index: i + 1,
                kind: stage.kind(),
                param: e.param,
                bytes: e.bytes,
            });
        }
    }
    Ok(all)
}

/// Bytes per vertex of a builtin mesh over a whole pipeline: positions,
/// faces (two triangles per grid vertex), topology (edges, one-rings,
/// vertex→faces), tangent frames, scales, colours, source texels, the
/// neighbourhood vectors of the matching stages, and the copies later stages
/// and the exporter make (≈ 60 `f32`/`u32` arrays of 1–3 values). A coarse
/// upper bound: what a stage adds is its own estimate.
pub const BYTES_PER_MESH_VERTEX: u64 = 1024;

/// An integer setting as a count: at least 1 (absent or not an integer: 1).
fn count(value: Option<&toml::Value>) -> u64 {
    value.and_then(|v| v.as_integer()).unwrap_or(1).max(1) as u64
}

/// Checks a builtin mesh's `resolution` in `[input]` (a grid of that many
/// vertices, built when the input loads) against `limit`.
///
/// # Errors
/// [`ConfigError::Value`] naming the key, the estimate, the limit and the
/// largest resolution that fits.
pub fn check_input(input: &RawInput, limit: &MemoryLimit, file: &str) -> Result<(), ConfigError> {
    let is_builtin = input
        .mesh
        .as_deref()
        .is_some_and(|m| m.trim().starts_with("builtin:"));
    let Some(resolution) = input
        .mesh_options
        .get("resolution")
        .and_then(|r| r.as_array())
        .filter(|r| is_builtin && !r.is_empty())
    else {
        return Ok(());
    };
    let sides: Vec<u64> = resolution.iter().map(|v| count(Some(v))).collect();
    let (u, v) = (sides[0], sides.get(1).copied().unwrap_or(1));
    let e = MemoryEstimate::image(
        "resolution",
        "the builtin mesh's vertices over the whole pipeline",
        (u as u32, v as u32),
        1 << 16,
        |a, b| (a * b).saturating_mul(BYTES_PER_MESH_VERTEX),
    );
    if e.bytes > limit.bytes {
        return Err(ConfigError::Value {
            file: file.to_string(),
            key: "input.mesh_options.resolution".into(),
            message: over_limit_message(&e, limit, 0),
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::memory_limit::LimitSource;

    fn limit(bytes: u64) -> MemoryLimit {
        MemoryLimit {
            bytes,
            source: LimitSource::Environment,
        }
    }

    #[test]
    fn the_largest_value_that_fits_fits_and_the_next_does_not() {
        let per = |side: u64| side * side * 64;
        let e = MemoryEstimate::growing("size", "an atlas", 8192, (256, 8192), per, |v| {
            v.to_string()
        });
        for budget in [1u64 << 22, 5 << 20, 1 << 30, 3 << 30] {
            let v: u64 = e.fits[0].largest_within(budget).unwrap().parse().unwrap();
            assert!(
                per(v) <= budget && (v == 8192 || per(v + 1) > budget),
                "{budget} {v}"
            );
        }
        assert_eq!(e.fits[0].largest_within(1000), None);
        let m = over_limit_message(&e, &limit(1 << 30), 0);
        assert!(
            m.contains("`size` = 8192")
                && m.contains("4.00 GiB")
                && m.contains("1.00 GiB")
                && m.contains(LIMIT_VAR)
                && m.contains("size = 4096"),
            "{m}"
        );
    }

    #[test]
    fn an_image_that_fits_keeps_its_aspect_ratio() {
        let e = MemoryEstimate::image("width x height", "an image", (8000, 2000), 32768, |w, h| {
            w * h * 64
        });
        let v = e.fits[0].largest_within(256 << 20).unwrap();
        let (w, h) = v.split_once('x').unwrap();
        let (w, h): (u64, u64) = (w.parse().unwrap(), h.parse().unwrap());
        assert!(
            w * h * 64 <= 256 << 20 && (w as f64 / h as f64 - 4.0).abs() < 0.01,
            "{v}"
        );
        assert!((w + 4) * (h + 1) * 64 > 256 << 20, "{v}");
    }
}
