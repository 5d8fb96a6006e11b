//! Run-wide resources: the seed every random stream derives from, the one
//! texture scale, per-stage metrics and timings, and the first stage failure.

use crate::stage::StageError;
use bevy_ecs::prelude::*;
use rand::SeedableRng;

/// The run's seed; every random stream derives from it, the stage index and a
/// stream id, so results never depend on thread count or scheduling.
#[derive(Resource, Clone, Copy, Debug)]
pub struct RunSeed(pub u64);

impl RunSeed {
    /// A seeded generator for one stage and one purpose (or one element).
    pub fn rng(&self, stage: usize, stream: u64) -> rand_pcg::Pcg64Mcg {
        rand_pcg::Pcg64Mcg::seed_from_u64(mix(self.0, stage as u64, stream))
    }

    /// A 64-bit seed for one stage and stream, for kernels that seed their own.
    pub fn derive(&self, stage: usize, stream: u64) -> u64 {
        mix(self.0, stage as u64, stream)
    }
}

pub use crate::kernels::mix;

/// World units per exemplar texel on the active mesh: the spacing at which
/// quality metrics resample the surface. Stages that set a texture scale update it.
#[derive(Resource, Clone, Copy, Debug)]
pub struct TexelSpacing(pub f32);

/// Exemplar texels per world unit of the run: the texture scale's, else
/// the active mesh's texel spacing inverted.
pub fn run_texels_per_unit(scale: Option<&TextureScale>, spacing: &TexelSpacing) -> f32 {
    scale.map_or(1.0 / spacing.0.max(f32::MIN_POSITIVE), |t| {
        t.texels_per_unit
    })
}

/// The run's one texture scale: `[input] texture_scale` resolved against the
/// input mesh's bounding-box diagonal and the exemplar's width. Every stage
/// whose own scale parameter is left at its default takes its scale from
/// here (jump maps' pixels per unit, Bangay–Morkel's `r_scale`, coherent's
/// scale, lapped patch size, retiling density, √2 depth, bake density).
#[derive(Resource, Clone, Copy, Debug)]
pub struct TextureScale {
    /// Exemplar pixels per world unit.
    pub texels_per_unit: f32,
    /// Bounding-box diagonal of the input mesh, world units.
    pub diagonal: f32,
    /// `[input] texture_scale` as written, for messages.
    pub value: f64,
    /// `[input] texture_scale_unit`.
    pub unit: crate::config::TextureScaleUnit,
}

impl TextureScale {
    /// Resolves `value` in `unit` for an input mesh of bounding-box diagonal
    /// `diagonal` and an exemplar `exemplar_width` pixels wide.
    pub fn resolve(
        value: f64,
        unit: crate::config::TextureScaleUnit,
        exemplar_width: u32,
        diagonal: f64,
    ) -> Self {
        Self {
            texels_per_unit: unit.texels_per_unit(value, exemplar_width, diagonal) as f32,
            diagonal: diagonal as f32,
            value,
            unit,
        }
    }

    /// Exemplar pixels per bounding-box diagonal of the input mesh.
    pub fn texels_per_diagonal(&self) -> f32 {
        self.texels_per_unit * self.diagonal
    }

    /// Vertices a surface of `area` square world units needs for one vertex
    /// per exemplar pixel² (a vertex spacing √(2 · mean triangle area) of one
    /// exemplar pixel: the resolution of the per-vertex methods).
    pub fn vertices_for_area(&self, area: f64) -> f64 {
        area * f64::from(self.texels_per_unit).powi(2)
    }

    /// [`Self::vertices_for_area`], checked before any remeshing: at least
    /// `MIN_DERIVED_VERTICES` and at most `max` (the stage's own range; its
    /// memory estimate refused a count over the memory limit before the
    /// run), else a message naming the scale, the count it asks for, and the
    /// two ways out (`[input] texture_scale` or the stage's own `key`).
    pub fn derived_vertices(&self, area: f64, key: &str, max: usize) -> Result<usize, String> {
        let n = self.vertices_for_area(area);
        if n.is_finite() && (MIN_DERIVED_VERTICES as f64..=max as f64).contains(&n) {
            return Ok(n.round() as usize);
        }
        Err(format!(
            "[input] texture_scale = {} ({:?}) is {} exemplar pixels per world unit, which asks for {n:.0} vertices on this surface of area {area:.4e} (one per exemplar pixel²); allowed {MIN_DERIVED_VERTICES}..={max}: {} texture_scale, or set `{key}`",
            self.value,
            self.unit,
            self.texels_per_unit,
            match (n < MIN_DERIVED_VERTICES as f64, self.unit) {
                (true, crate::config::TextureScaleUnit::PixelsPerUnit) => "raise",
                (true, _) => "lower",
                (false, crate::config::TextureScaleUnit::PixelsPerUnit) => "lower",
                (false, _) => "raise",
            }
        ))
    }

    /// A human-readable line for logs: the scale and where it comes from.
    pub fn describe(&self) -> String {
        format!(
            "texture scale {} exemplar pixels per world unit ({} per bounding-box diagonal)",
            self.texels_per_unit,
            self.texels_per_diagonal()
        )
    }
}

/// Fewest vertices a texture scale may ask of a remeshing or subdivision
/// stage (below it there is no texture to speak of).
pub const MIN_DERIVED_VERTICES: usize = 12;

/// Checks an explicit vertex count of a remeshing or subdivision stage:
/// 0 (derive it from the texture scale) or [`MIN_DERIVED_VERTICES`]..=`max`
/// (the upper bound is the parameter's range); the message for a count in
/// between.
pub fn check_vertex_count(value: u64, max: u64) -> Result<(), String> {
    if (1..MIN_DERIVED_VERTICES as u64).contains(&value) {
        return Err(format!(
            "{value} is too few; allowed: 0 (derived from [input] texture_scale) or {MIN_DERIVED_VERTICES}..={max}"
        ));
    }
    Ok(())
}

/// Per-stage metrics, written to `metrics.json` under `stages[i].metrics`.
#[derive(Resource, Debug, Default)]
pub struct Metrics {
    /// One JSON object per stage, in stage order.
    pub stages: Vec<serde_json::Map<String, serde_json::Value>>,
    /// Metrics of the whole result (texture energy, histogram distance).
    pub result: serde_json::Map<String, serde_json::Value>,
}

impl Metrics {
    /// Records `key = value` for stage `index` (0-based); floats are kept
    /// shortest ([`crate::config::params::to_json`]).
    pub fn record(&mut self, index: usize, key: &str, value: impl serde::Serialize) {
        if self.stages.len() <= index {
            self.stages.resize_with(index + 1, Default::default);
        }
        let v = crate::config::params::to_json(&value);
        self.stages[index].insert(key.to_string(), v);
    }
}

/// Wall time of one stage.
#[derive(Clone, Debug, serde::Serialize)]
pub struct StageTiming {
    /// 1-based stage number.
    pub index: usize,
    /// Stage kind.
    pub kind: String,
    /// Wall time in seconds.
    pub seconds: f64,
}

/// Stage timings, in order.
#[derive(Resource, Debug, Default)]
pub struct StageTimings(pub Vec<StageTiming>);

/// The first failure of a stage; later stages do not run.
#[derive(Resource, Debug, Default)]
pub struct StageFailure(pub Option<StageError>);

/// Records a stage failure (the first one wins); later stages do not run.
pub fn fail(failure: &mut StageFailure, index: usize, kind: &str, message: impl Into<String>) {
    if failure.0.is_none() {
        failure.0 = Some(StageError::new(index, kind, message));
    }
}
