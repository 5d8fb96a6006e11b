//! Up-front memory estimates (issue 43): every stage estimates its large
//! allocations from its typed settings and the input's sizes
//! ([`crate::stage::Stage::memory_estimate`]); a run whose estimate is
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
use crate::config::{ConfigError, RawInput, RawOutput};
use crate::stage::StagePlan;
use crate::stage::memory::{BYTES_PER_MESH_VERTEX, InputSizes, MemoryEstimate, show_bytes};

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
/// all when they fit. A stage whose analysis is `cached` (one flag per
/// stage; missing: not cached) is not checked.
///
/// # Errors
/// The first estimate over the limit (less the input's resident bytes).
pub fn check_stages(
    stages: &[Box<dyn StagePlan>],
    sizes: &InputSizes,
    limit: &MemoryLimit,
    cached: &[bool],
) -> Result<Vec<StageEstimate>, Refusal> {
    let resident = sizes.resident_bytes();
    let mut all = Vec::new();
    for (i, (stage, sizes)) in stages.iter().zip(stage_sizes(stages, sizes)).enumerate() {
        if cached.get(i).copied().unwrap_or(false) {
            continue;
        }
        for e in stage.memory_estimate(&sizes) {
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

/// Bytes the result metrics hold per vertex of the mesh they measure (the
/// edges and vertex faces they build, the per-vertex signal), measured.
pub const METRICS_BYTES_PER_VERTEX: u64 = 96;

/// The result metrics' working memory (they follow every pipeline, on the
/// mesh the last stage leaves): per sampled location its windows (query,
/// template, index entry) and its dense sharpness template, the exact index
/// of the exemplar's windows (one band at most,
/// [`crate::kernels::metrics::window_index::BAND_WINDOWS`]) and a few
/// arrays per vertex. Grows with `output.metric_samples` (locations are
/// vertices, each sampled at most once, once the mesh is known); the
/// channels are taken as 4 until the exemplar is loaded. Checked once the
/// input is loaded ([`check_metrics`]).
pub fn metrics_estimate(output: &RawOutput, sizes: &InputSizes) -> MemoryEstimate {
    use crate::kernels::metrics::surface_quality::SHARPNESS_OVERSAMPLING;
    use crate::kernels::metrics::window_index::{BAND_WINDOWS, BYTES_PER_WINDOW};
    let n = u64::from(output.metric_neighbourhood.max(1));
    let ch = if sizes.loaded {
        u64::from(sizes.exemplar_channels.max(1))
    } else {
        4
    };
    let side = (n - 1) * u64::from(SHARPNESS_OVERSAMPLING) + 1;
    // The templates twice (one per location, then side by side), the query.
    let per_sample = 4 * ch * (2 * (n * n + side * side) + n * n) + BYTES_PER_WINDOW as u64 + 64;
    // Locations are vertices (each at most once) when the mesh is known.
    let vertices = sizes.vertices;
    let locations = move |samples: u64| {
        if vertices > 0 {
            samples.min(vertices)
        } else {
            samples
        }
    };
    let windows = (u64::from(sizes.exemplar_width) * u64::from(sizes.exemplar_height))
        .min(BAND_WINDOWS as u64);
    let fixed =
        windows * (BYTES_PER_WINDOW as u64 + 4 * ch) + sizes.vertices * METRICS_BYTES_PER_VERTEX;
    MemoryEstimate::growing(
        "output.metric_samples",
        "the result metrics' sampled windows, the exemplar's window index and per-vertex arrays",
        output.metric_samples as u64,
        (10, 100_000),
        move |samples| fixed + locations(samples) * per_sample,
        |samples| samples.to_string(),
    )
}

/// Checks [`metrics_estimate`] on the mesh the last of `stages` leaves
/// against `limit`; returns the estimate's bytes.
///
/// # Errors
/// [`ConfigError::Value`] for `output.metric_samples`, naming the estimate,
/// the limit and the largest value that fits.
pub fn check_metrics(
    output: &RawOutput,
    stages: &[Box<dyn StagePlan>],
    sizes: &InputSizes,
    limit: &MemoryLimit,
    file: &str,
) -> Result<u64, ConfigError> {
    let last = stages.iter().fold(*sizes, |s, stage| stage.sizes_after(&s));
    let e = metrics_estimate(output, &last);
    let resident = sizes.resident_bytes();
    if e.bytes.saturating_add(resident) > limit.bytes {
        return Err(ConfigError::Value {
            file: file.into(),
            key: "output.metric_samples".into(),
            message: over_limit_message(&e, limit, resident),
        });
    }
    Ok(e.bytes)
}

/// [`check_stages`] for the loaded `input` of a run of `seed`: its `sizes`
/// (`InputSizes::of(input, raw)`, under `raw`'s texture scale), a stage
/// whose analysis of the exemplar is cached already not checked. What a run
/// checks before its first stage.
///
/// # Errors
/// As [`check_stages`].
pub fn check_loaded(
    stages: &[Box<dyn StagePlan>],
    input: &super::LoadedInput,
    sizes: &InputSizes,
    raw: &RawInput,
    seed: u64,
    limit: &MemoryLimit,
) -> Result<Vec<StageEstimate>, Refusal> {
    let cached: Vec<bool> = stages
        .iter()
        .enumerate()
        .map(|(i, s)| {
            s.analysis_cached(
                &input.exemplar,
                raw.exemplar_wrap,
                seed,
                crate::stage::StageCtx { index: i },
            )
        })
        .collect();
    check_stages(stages, sizes, limit, &cached)
}

/// The sizes each stage sees: the input's, then what each stage before it
/// leaves ([`StagePlan::sizes_after`]: a retiled or subdivided mesh).
pub fn stage_sizes(stages: &[Box<dyn StagePlan>], input: &InputSizes) -> Vec<InputSizes> {
    let mut current = *input;
    stages
        .iter()
        .map(|s| {
            let seen = current;
            current = s.sizes_after(&seen);
            seen
        })
        .collect()
}

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
