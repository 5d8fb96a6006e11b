//! Stage `coherent`: coherent per-vertex synthesis of exemplar coordinates
//! over the mesh pyramid (an extension; [`crate::kernels::coherent`]):
//! upsampled through the tangent frames, jittered, and corrected by
//! k-coherent candidates compared in appearance space. Colours are the
//! exemplar pixels at the coordinates, so every exemplar channel follows.
//!
//! Works on whatever mesh levels exist, as `match` does: the non-source
//! `MeshLevel` entities (`retile`, `builtin_pyramid` or `subdivide_sqrt2`),
//! or the source mesh alone as a one-level pyramid. Level 0 becomes the
//! active mesh.
//!
//! Reads: the pyramid's levels (`Geometry`, `Frames`; the finest level's
//! `SourceTexels` with `start = "sources"`), the exemplar, `TextureScale`
//! (or `TexelSpacing` when refining), the analysis cache. Writes: on every
//! level `VertexColours` and `SourceTexels` (removing `CornerUvs`), `Frames`
//! where it had none; `ActiveMesh`, `TexelSpacing`.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::image::sample::Wrap;
use crate::kernels::coherent::{
    CoherentLevel, CoherentSettings, coherent_synthesis, pixel_centres, pixel_colours,
};
use crate::kernels::wei_levoy::wl_match::SynthesisLevel;
use crate::progress::Progress;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::Vec2;
use serde::{Deserialize, Serialize};

/// Where the coordinates start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Start {
    /// Random coordinates on the coarsest level, grown coarse to fine.
    #[default]
    Random,
    /// The finest level's `SourceTexels` from an earlier stage (`jump_surface`,
    /// `match`, `graph_match`, `coherent`): only correction passes on the
    /// finest level, refining that result.
    Sources,
}

/// Settings of `coherent`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CoherentStageSettings {
    /// Where the coordinates start.
    pub start: Start,
    /// Correction passes per level.
    pub passes: u32,
    /// Similar exemplar pixels per pixel (k-coherence).
    pub k: u32,
    /// Appearance-space components.
    pub appearance_dims: u32,
    /// Appearance window points per side.
    pub window: u32,
    /// Mesh rings compared.
    pub ring: u32,
    /// Jitter after upsampling, in vertex spacings.
    pub jitter: f32,
    /// Weight of the occurrence penalty.
    pub spread: f32,
    /// Extra cost of a jump over a coherent shift.
    pub coherence: f32,
    /// Exemplar pixels per world unit; 0 = `[input] texture_scale` (or, when
    /// refining, the scale of the result refined).
    pub scale: f32,
    /// Read and write the appearance analyses in the on-disk cache.
    pub cache: bool,
}

impl Default for CoherentStageSettings {
    fn default() -> Self {
        let k = CoherentSettings::default();
        Self {
            start: Start::Random,
            passes: k.passes,
            k: k.k as u32,
            appearance_dims: k.dims as u32,
            window: k.window,
            ring: k.ring,
            jitter: k.jitter,
            spread: k.spread,
            coherence: k.coherence,
            scale: k.scale,
            cache: true,
        }
    }
}

impl StageSettings for CoherentStageSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "start",
            unit: "",
            range: ParamRange::OneOf(&["random", "sources"]),
            doc: "random: grow coordinates coarse to fine from random ones; sources: refine an earlier stage's result (its source texels on the finest level) with correction passes there only",
        },
        ParamDoc {
            name: "passes",
            unit: "passes per level",
            range: ParamRange::Int(0, 16),
            doc: "correction passes per mesh level, each in a seeded random vertex order",
        },
        ParamDoc {
            name: "k",
            unit: "exemplar pixels",
            range: ParamRange::Int(0, 16),
            doc: "similar exemplar pixels per pixel offered as candidates (k-coherence); 0 = shifted neighbour coordinates only",
        },
        ParamDoc {
            name: "appearance_dims",
            unit: "components",
            range: ParamRange::Int(1, 8),
            doc: "principal components of the exemplar neighbourhoods compared (appearance space)",
        },
        ParamDoc {
            name: "window",
            unit: "points per side",
            range: ParamRange::Int(1, 15),
            doc: "odd window of the appearance vectors, its points one vertex spacing apart",
        },
        ParamDoc {
            name: "ring",
            unit: "mesh rings",
            range: ParamRange::Int(1, 3),
            doc: "mesh neighbours compared per vertex: its 1-, 2- or 3-ring (the nearest 24 at most)",
        },
        ParamDoc {
            name: "jitter",
            unit: "vertex spacings",
            range: ParamRange::Float(0.0, 4.0),
            doc: "random shift of each upsampled coordinate per axis, breaking up copied patches",
        },
        ParamDoc {
            name: "spread",
            unit: "× mean neighbourhood error",
            range: ParamRange::Float(0.0, 100.0),
            doc: "occurrence penalty: a candidate in an exemplar cell (4 vertex spacings wide) used n times more than average costs spread·n mean errors more, so all of the exemplar is used; 0 = off",
        },
        ParamDoc {
            name: "coherence",
            unit: "× mean neighbourhood error",
            range: ParamRange::Float(0.0, 100.0),
            doc: "extra cost of jumping to a similar exemplar pixel rather than shifting a neighbour's coordinate: larger gives larger coherent patches (Ashikhmin's coherence bias)",
        },
        ParamDoc {
            name: "scale",
            unit: "exemplar pixels per world unit",
            range: ParamRange::Float(0.0, 1e9),
            doc: "texture scale; 0 = the run's `[input] texture_scale` (start = random; `retile` / `subdivide_sqrt2` derive their density from the same scale, one exemplar pixel per finest vertex spacing √(2·mean triangle area)), or the scale of the result being refined (start = sources); a value here overrides it for this stage",
        },
        ParamDoc {
            name: "cache",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "read and write each level's appearance analysis (exemplar only) in the analysis cache, as jump_map's ($SURFSYNTH_CACHE, else $XDG_CACHE_HOME/surfsynth, else ~/.cache/surfsynth); results are the same either way",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if self.window.is_multiple_of(2) {
            return Err((
                "window".into(),
                format!(
                    "{} is even; the window needs a centre point (1, 3, 5, …)",
                    self.window
                ),
            ));
        }
        Ok(())
    }
}

impl CoherentStageSettings {
    /// The kernel's settings: the scale is `scale`, or when refining the
    /// scale of the result refined (the texel spacing `spacing` the earlier
    /// stage set), else the run's `texture_scale`.
    fn kernel_settings(
        &self,
        spacing: f32,
        texture_scale: f32,
        seed: u64,
        wrap: Wrap,
    ) -> CoherentSettings {
        CoherentSettings {
            passes: self.passes,
            k: self.k as usize,
            dims: self.appearance_dims as usize,
            window: self.window,
            ring: self.ring,
            jitter: self.jitter,
            spread: self.spread,
            coherence: self.coherence,
            scale: match (self.scale, self.start) {
                (s, _) if s > 0.0 => s,
                (_, Start::Sources) => 1.0 / spacing.max(f32::MIN_POSITIVE),
                (_, Start::Random) => texture_scale,
            },
            seed,
            wrap,
        }
    }
}

/// The finest level's source texels to refine (`start = "sources"`), or
/// none (`start = "random"`).
fn start_texels<'a>(
    start: Start,
    data: &'a LevelData,
    input: &PyramidInput,
) -> Result<Option<&'a [Vec2]>, String> {
    if start == Start::Random {
        return Ok(None);
    }
    let texels = data
        .get(input.entities[0])
        .ok()
        .and_then(|d| d.3)
        .map(|t| &t.0[..])
        .filter(|t| t.len() == input.meshes[0].vertex_count());
    if texels.is_none() {
        return Err(
            "start = \"sources\" needs source texels on the finest mesh level: put a stage that records them (jump_surface, match, graph_match, coherent) before it".into(),
        );
    }
    Ok(texels)
}

/// Records the levels' figures as metrics of stage `index`; returns the
/// finest level's texels per world unit, if any.
fn record_metrics(metrics: &mut Metrics, index: usize, results: &[CoherentLevel]) -> Option<f32> {
    let reports: Vec<_> = results.iter().map(|r| r.report.clone()).collect();
    metrics.record(index, "levels", &reports);
    let r = reports.first()?;
    let texels_per_unit = r.texels_per_spacing / r.spacing;
    metrics.record(index, "texels_per_world_unit", texels_per_unit);
    metrics.record(
        index,
        "energy_finest",
        r.energy.last().copied().unwrap_or(0.0),
    );
    Some(texels_per_unit)
}

/// The `coherent` stage.
pub struct Coherent;

impl Stage for Coherent {
    const KIND: &'static str = "coherent";
    const SUMMARY: &'static str = "coherent synthesis of exemplar coordinates: upsampled through the frames, corrected by k-coherent candidates in appearance space (or refining an earlier result)";
    const PAPER: &'static str =
        "extension: Lefebvre & Hoppe 2005/2006, Tong et al. 2002 on the Wei & Levoy mesh pyramid";
    type Settings = CoherentStageSettings;

    /// The appearance analysis of a level
    /// ([`crate::kernels::coherent::appearance::appearance_bytes`]), the
    /// Gaussian stack, about 16 bytes an exemplar pixel, and, per vertex of
    /// the finest level, the coordinates, rings and candidates of every
    /// level, about 800 bytes (measured: `tests/memory_estimates.rs`).
    fn memory_estimate(settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        const PER_VERTEX: u64 = 800;
        let pixels = sizes.exemplar_pixels();
        let exemplar = if pixels == 0 {
            0
        } else {
            crate::kernels::coherent::appearance::appearance_bytes(
                pixels,
                sizes.exemplar_channels,
                settings.window,
                settings.k,
            ) + pixels * 16
        };
        MemoryEstimate::per_vertex(
            "the appearance analysis and the coordinates of every vertex",
            sizes,
            exemplar,
            PER_VERTEX,
        )
    }
    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh, Datum::Frames]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Colours]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let synthesize = move |mut commands: Commands,
                               seed: Res<RunSeed>,
                               exemplar: Res<Exemplar>,
                               texture_scale: Res<TextureScale>,
                               mut spacing_res: ResMut<TexelSpacing>,
                               mut metrics: ResMut<Metrics>,
                               pyramid: Pyramid|
              -> SystemResult {
            let input = pyramid.input()?;
            let inputs: Vec<SynthesisLevel> = input
                .meshes
                .iter()
                .zip(&input.frames)
                .map(|(m, f)| SynthesisLevel { mesh: m, frames: f })
                .collect();
            let kernel = settings.kernel_settings(
                spacing_res.0,
                texture_scale.texels_per_unit,
                seed.derive(ctx.index, 0),
                exemplar.wrap,
            );
            let store = crate::cache::DiskCache::if_enabled(settings.cache);
            // The kernel sets the length: vertices times passes.
            let progress = Progress::new(0, Self::KIND);
            let _finish = progress.finish_on_drop();
            let start = start_texels(settings.start, &pyramid.data, &input)?;
            let store = store.as_ref().map(|s| s as _);
            let results =
                coherent_synthesis(&inputs, &exemplar.image, &kernel, start, store, &progress)
                    .map_err(|e| e.to_string())?;
            progress.finish();
            if let Some(texels_per_unit) = record_metrics(&mut metrics, ctx.index, &results) {
                spacing_res.0 = 1.0 / texels_per_unit;
            }
            let img = &exemplar.image;
            for (l, r) in results.into_iter().enumerate() {
                let texels = pixel_centres(&r.coords, img.width, img.height, exemplar.wrap);
                let colours = VertexColours {
                    channels: img.channels as usize,
                    values: pixel_colours(img, &texels),
                };
                // The vertex colours replace an earlier per-corner result.
                commands.entity(input.entities[l]).remove::<CornerUvs>();
                input.write_level(&mut commands, l, colours, texels);
            }
            commands.insert_resource(ActiveMesh(input.entities[0]));
            Ok(())
        };
        ctx.fallible(Self::KIND, synthesize)
    }
}
