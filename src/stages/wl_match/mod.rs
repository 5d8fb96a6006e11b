//! Stage `match`: Wei & Levoy 2001 surface texture synthesis over the mesh
//! pyramid (Table 3): per-vertex multi-resolution neighbourhoods by
//! flattening (§3.3), two passes per level in random order (§3.2), with an
//! exhaustive or accelerated search. Writes colours and matched exemplar
//! texels on every level; level 0 becomes the active mesh.
//!
//! Works on whatever mesh levels exist: the non-source `MeshLevel` entities
//! (from `retile` or `builtin_pyramid`), or the source mesh alone as a
//! one-level pyramid.
//!
//! Reads: the pyramid's levels (`Geometry`, `Frames`; the coarsest level's
//! `VertexColours` and `SourceTexels` from `init_colours`), the exemplar.
//! Writes: on every level `VertexColours` and `SourceTexels`, `Frames`
//! where it had none; `ActiveMesh`, `TexelSpacing`.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::wei_levoy::wl_match::{
    InitialColours, LevelReport, NeighbourhoodSpec, SearchKind, SynthesisLevel, WlSettings,
    wei_levoy_synthesis_with_progress,
};
use crate::progress::Progress;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::Vec2;
use serde::{Deserialize, Serialize};

/// The search back-end, as named in configs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SearchBackend {
    /// Exact exhaustive L2 search.
    #[default]
    Exhaustive,
    /// PCA + kd-tree, candidates re-ranked exactly (approximate).
    PcaKdtree,
    /// Tree-structured vector quantisation (approximate, the paper's).
    Tsvq,
}

/// Settings of `match`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MatchSettings {
    /// `[size, levels]` per pyramid level, coarsest first.
    pub neighbourhoods: Vec<[u32; 2]>,
    /// Search back-end.
    pub search: SearchBackend,
    /// 2: extrapolation pass then full pass (paper); 1: full pass only.
    pub passes: u32,
    /// pca_kdtree: principal components indexed.
    pub pca_dims: u32,
    /// pca_kdtree: candidates re-ranked per query.
    pub candidates: u32,
    /// tsvq: largest leaf.
    pub leaf_size: u32,
    /// tsvq: leaves searched per query.
    pub leaves: u32,
    /// How far along the normal a parent face may lie, in coarser-level
    /// template spacings.
    pub parent_reach: f32,
}

impl Default for MatchSettings {
    fn default() -> Self {
        Self {
            neighbourhoods: vec![[1, 1], [3, 2], [5, 2], [7, 2]],
            search: SearchBackend::Exhaustive,
            passes: 2,
            pca_dims: 8,
            candidates: 16,
            leaf_size: 8,
            leaves: 1,
            parent_reach: 4.0,
        }
    }
}

impl StageSettings for MatchSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "neighbourhoods",
            unit: "[points per side, levels]",
            range: ParamRange::Int(1, 31),
            doc: "neighbourhood {n×n, k} per pyramid level, coarsest first (the finest level takes the last entry); n odd, k in 1..=8",
        },
        ParamDoc {
            name: "search",
            unit: "",
            range: ParamRange::OneOf(&["exhaustive", "pca_kdtree", "tsvq"]),
            doc: "exhaustive: exact L2 over every exemplar neighbourhood; pca_kdtree: kd-tree on principal components, candidates re-ranked exactly; tsvq: tree-structured VQ (the paper's acceleration)",
        },
        ParamDoc {
            name: "passes",
            unit: "",
            range: ParamRange::Int(1, 2),
            doc: "2: a pass with coarser levels only, then one with the whole neighbourhood (§3.2); 1: only the second",
        },
        ParamDoc {
            name: "pca_dims",
            unit: "components",
            range: ParamRange::Int(1, 8),
            doc: "pca_kdtree: principal components the kd-tree indexes",
        },
        ParamDoc {
            name: "candidates",
            unit: "",
            range: ParamRange::Int(1, 1024),
            doc: "pca_kdtree: nearest candidates in PCA space re-ranked by the exact distance",
        },
        ParamDoc {
            name: "leaf_size",
            unit: "vectors",
            range: ParamRange::Int(1, 4096),
            doc: "tsvq: largest cluster left unsplit",
        },
        ParamDoc {
            name: "leaves",
            unit: "",
            range: ParamRange::Int(1, 4096),
            doc: "tsvq: leaves searched best-first per query (1: greedy descent, as the paper)",
        },
        ParamDoc {
            name: "parent_reach",
            unit: "template spacings",
            range: ParamRange::Float(0.01, 1000.0),
            doc: "farthest a coarser level may lie along a vertex normal to count as its parent face; beyond, default colours (footnote 2)",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if self.neighbourhoods.is_empty() {
            return Err((
                "neighbourhoods".into(),
                "needs at least one [size, levels] entry".into(),
            ));
        }
        for (i, [size, levels]) in self.neighbourhoods.iter().enumerate() {
            if size % 2 == 0 || *levels == 0 || *levels > 8 {
                return Err((
                    "neighbourhoods".into(),
                    format!(
                        "entry {} = [{size}, {levels}] is not allowed; size must be odd (1..=31) and levels in 1..=8",
                        i + 1
                    ),
                ));
            }
        }
        Ok(())
    }
}

impl MatchSettings {
    fn kernel_settings(&self, seed: u64, wrap: crate::image::sample::Wrap) -> WlSettings {
        WlSettings {
            neighbourhoods: self
                .neighbourhoods
                .iter()
                .map(|&[size, levels]| NeighbourhoodSpec { size, levels })
                .collect(),
            search: match self.search {
                SearchBackend::Exhaustive => SearchKind::Exhaustive,
                SearchBackend::PcaKdtree => SearchKind::PcaKdTree {
                    dims: self.pca_dims as usize,
                    candidates: self.candidates as usize,
                },
                SearchBackend::Tsvq => SearchKind::Tsvq {
                    leaf_size: self.leaf_size as usize,
                    leaves: self.leaves as usize,
                },
            },
            passes: self.passes,
            seed,
            wrap,
            parent_reach: self.parent_reach,
            stencil_budget: crate::kernels::wei_levoy::wl_match::STORED_STENCIL_BYTES,
        }
    }
}

/// The `match` stage.
pub struct Match;

/// The coarsest level's colours from `init_colours` (its exemplar pixels,
/// with their texels on the exemplar pyramid's top level), when they fit
/// the level and the top level of the exemplar's pyramid (one level per
/// level of `entities`, finest first).
fn initial_colours(
    data: &LevelData,
    entities: &[Entity],
    exemplar: &Exemplar,
) -> Option<(Vec<f32>, Vec<[u32; 2]>)> {
    let (count, coarsest) = (entities.len(), entities[entities.len() - 1]);
    let scale = 2f32.powi(count as i32 - 1);
    let init = data.get(coarsest).ok().and_then(|(g, _, c, t)| {
        let (c, t) = (c?, t?);
        let nv = g.0.vertex_count();
        let ch = exemplar.image.channels as usize;
        (c.channels == ch && c.values.len() == nv * ch && t.0.len() == nv).then(|| {
            let texels: Vec<[u32; 2]> =
                t.0.iter()
                    .map(|p| {
                        [
                            ((p.x - 0.5) / scale).round() as u32,
                            ((p.y - 0.5) / scale).round() as u32,
                        ]
                    })
                    .collect();
            (c.values.clone(), texels)
        })
    });
    let pyramid_top =
        crate::image::pyramid::gaussian_pyramid(&exemplar.image, count, exemplar.wrap);
    let top = &pyramid_top[count - 1];
    init.filter(|(_, t)| t.iter().all(|p| p[0] < top.width && p[1] < top.height))
}

/// Records the synthesis's figures as metrics of stage `index`; returns
/// the finest level's texel spacing, if any.
fn record_metrics(
    metrics: &mut Metrics,
    index: usize,
    search: SearchBackend,
    reports: &[LevelReport],
) -> Option<f32> {
    let search_seconds: f64 = reports.iter().map(|r| r.search_seconds).sum();
    let values: u64 = reports.iter().map(|r| r.exhaustive_values).sum();
    metrics.record(index, "levels", reports);
    metrics.record(index, "search_seconds", search_seconds);
    if search == SearchBackend::Exhaustive && search_seconds > 0.0 {
        // Two flops (multiply, add) per compared value in the matrix products.
        metrics.record(
            index,
            "exhaustive_gflops_per_second",
            2.0 * values as f64 / search_seconds / 1e9,
        );
    }
    let r = reports.first()?;
    metrics.record(index, "mean_match_distance_finest", r.mean_distance[1]);
    Some(r.spacing)
}

impl Stage for Match {
    const KIND: &'static str = "match";
    const SUMMARY: &'static str =
        "Wei-Levoy synthesis: flattened multi-resolution neighbourhoods matched coarse to fine";
    const PAPER: &'static str = "Wei & Levoy 2001 §3.2-3.3, Table 3";
    type Settings = MatchSettings;

    /// The exemplar side of the finest level's search
    /// ([`crate::kernels::wei_levoy::wl_match::search_bytes`]: its
    /// neighbourhood vectors and search structure), the finest level's
    /// kept stencils
    /// ([`crate::kernels::wei_levoy::wl_match::stored_stencil_bytes`]) and,
    /// per vertex of the
    /// finest level, the flattened templates, queries and results of every
    /// level, about 600 bytes (measured: `tests/memory_estimates.rs`).
    fn memory_estimate(settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        const PER_VERTEX: u64 = 600;
        let ks = settings.kernel_settings(0, crate::image::sample::Wrap::Repeat);
        let exemplar = ks.neighbourhoods.last().map_or(0, |&spec| {
            crate::kernels::wei_levoy::wl_match::search_bytes(
                sizes.exemplar_pixels(),
                sizes.exemplar_channels,
                spec,
                &ks.search,
            )
        });
        // The finest level's flattened stencils, kept between the schedule
        // and the queries when they fit (at its largest template).
        let points = ks
            .neighbourhoods
            .iter()
            .map(|spec| u64::from(spec.size) * u64::from(spec.size))
            .max()
            .unwrap_or(0);
        let stencils = crate::kernels::wei_levoy::wl_match::stored_stencil_bytes(
            sizes.vertices,
            points,
            ks.stencil_budget,
        );
        MemoryEstimate::per_vertex(
            "the exemplar's neighbourhood search, the kept stencils and the templates of every vertex",
            sizes,
            exemplar + stencils,
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
                               mut spacing_res: ResMut<TexelSpacing>,
                               mut metrics: ResMut<Metrics>,
                               pyramid: Pyramid|
              -> SystemResult {
            let input = pyramid.input()?;
            let entities = &input.entities;
            // The coarsest level starts from init_colours' pixels when it has them.
            let init = initial_colours(&pyramid.data, entities, &exemplar);
            let inputs: Vec<SynthesisLevel> = input
                .meshes
                .iter()
                .zip(&input.frames)
                .map(|(m, f)| SynthesisLevel { mesh: m, frames: f })
                .collect();
            let kernel = settings.kernel_settings(seed.derive(ctx.index, 0), exemplar.wrap);
            let progress = Progress::new(0, Self::KIND);
            let _finish = progress.finish_on_drop();
            let result = wei_levoy_synthesis_with_progress(
                &inputs,
                &exemplar.image,
                &kernel,
                init.as_ref()
                    .map(|(values, texels)| InitialColours { values, texels }),
                &progress,
            );
            progress.finish();
            let results = result.map_err(|e| e.to_string())?;
            let reports: Vec<_> = results.iter().map(|r| r.report.clone()).collect();
            let finest_spacing = record_metrics(&mut metrics, ctx.index, settings.search, &reports);
            if let Some(spacing) = finest_spacing {
                spacing_res.0 = spacing;
            }
            let channels = exemplar.image.channels as usize;
            for (l, r) in results.into_iter().enumerate() {
                let s = 2f32.powi(l as i32);
                let texels: Vec<Vec2> = r
                    .texels
                    .iter()
                    .map(|t| Vec2::new(t[0] as f32 * s + 0.5, t[1] as f32 * s + 0.5))
                    .collect();
                let colours = VertexColours {
                    channels,
                    values: r.colours,
                };
                input.write_level(&mut commands, l, colours, texels);
            }
            commands.insert_resource(ActiveMesh(entities[0]));
            Ok(())
        };
        ctx.fallible(Self::KIND, synthesize)
    }
}
