//! Stage `graph_match`: texture synthesis by k-region graph matching over
//! the √2 hierarchy (Bangay & Morkel 2006 §3.3), optionally transferring
//! each matched neighbourhood with a graph cut (§3.4).
//!
//! Coarse to fine over the levels of `Sqrt2Pyramid` (or just the active
//! mesh): the coarsest level starts from its colours if it has any,
//! otherwise uncoloured, and its first pass visits vertices in sweep order
//! (§3.1.2) so the pattern grows as one front; every other pass visits them
//! in a seeded random order. A finer level starts from the colours of the
//! level above carried through the √2 parents. Every vertex keeps the
//! matched colour (`VertexColours`) and the matched exemplar texel
//! (`SourceTexels`, level-0 pixels) so other exemplar channels can follow.
//! Per level the metrics hold the counts of Table 1 (comparisons with and
//! without oversampling averaging) and of the cuts (vertices coloured per
//! cut, seam cost).
//!
//! Defaults, all in texture terms so they hold on any mesh at any scale:
//! `r_scale` one texel per mean edge of the finest level; `region` an
//! eighth of the exemplar's smaller side ([`default_region`]), so a region
//! spans a texture element whatever the mesh; `k` from 2 (so coarse levels,
//! where the region is smaller than an edge, still compare 13 vertices, and
//! a cut has an interior) up to what the region needs on the finest level
//! ([`default_k_max`], at most 16); passes `[3, 2, 1]`. Measured on the
//! planar benchmark (256² from the 128² shared textures), against the old
//! defaults (region 5 texels, k 1..=10, passes [2, 1]): structure distance
//! 0.30 → 0.08 on brick (the mortar net no longer breaks into fragments on
//! grey), lower on every shared texture, at 5–15× the time.
//!
//! `density_invariant` (default on; off = the paper) makes the result
//! follow the texture rather than the tessellation on meshes denser than
//! the texture: vertices within half a texel of a matched vertex take the
//! texel under them instead of being matched again, and cut edges are
//! weighted by their length in texels (`kernels::bangay_morkel::graph_match::FOOTPRINT`).
//! On meshes with edges of about a texel (the planar benchmark, the √2
//! hierarchies `subdivide_sqrt2` builds) neither changes much.
//!
//! `candidates = "coherent"` (an extension; the paper's exhaustive search
//! is the default and the reference reproduction) scores k-coherent
//! candidates instead of every texel (`kernels::bangay_morkel::graph_match`,
//! `Candidates::Coherent`): 2–4× faster, and with `graph_cut` it gives the
//! cut its point — larger copied pieces, fewer seams
//! (`configs/plane/bangay_morkel_coherent.toml`; measured in README,
//! "Bangay–Morkel with coherent candidates").
//!
//! Reads: the `Sqrt2Pyramid` levels (or the active mesh alone): their
//! `Geometry`, `Frames` (or the active mesh's), `VertexColours`,
//! `SourceTexels`, `SweepField`, `LevelParents`; the exemplar,
//! `TextureScale`. Writes: on every level `VertexColours`, `SourceTexels`,
//! `VertexScale`; `TexelSpacing`.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::image::Image;
use crate::kernels::bangay_morkel::graph_match::hierarchy::{
    HierarchyLevel, HierarchySettings, LevelMatch, match_hierarchy,
};
use crate::kernels::bangay_morkel::graph_match::{
    Candidates, GraphMatchSettings, ImageLevels, MatchImages, PassStats,
};
use crate::progress::Progress;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::query::ROQueryItem;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};

/// Order of the first pass on the coarsest level.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CoarseOrder {
    /// Increasing sweep value: a growing front (§3.1.2).
    #[default]
    Sweep,
    /// A seeded random permutation.
    Random,
}

/// Settings of `graph_match`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GraphMatchStageSettings {
    /// Texels of the exemplar per world unit; 0 = `[input] texture_scale`.
    pub r_scale: f32,
    /// Edge of the square neighbourhood in texels (`n` of §3.3.2); 0 =
    /// derived from the exemplar ([`default_region`]).
    pub region: f32,
    /// Smallest k (at least 2 when `graph_cut` is on; see the kernel).
    pub k_min: u32,
    /// Largest k; 0 = the k the region needs on the finest level
    /// ([`default_k_max`]).
    pub k_max: u32,
    /// Gaussian stack or pyramid.
    pub image_levels: ImageLevels,
    /// Number of stack/pyramid levels; 0 = until the blur spans the exemplar.
    pub image_level_count: u32,
    /// Passes per mesh level, coarsest first; the last entry repeats.
    pub passes: Vec<u32>,
    /// Order of the first pass on the coarsest level.
    pub coarse_order: CoarseOrder,
    /// Oversampling averaging (§3.3.3).
    pub averaging: bool,
    /// Graph-cut transfer of the matched neighbourhood (§3.4).
    pub graph_cut: bool,
    /// σ of eq. 1.
    pub cut_sigma: f32,
    /// Exhaustive search (the paper) or k-coherent candidates (extension).
    pub candidates: Candidates,
    /// Similar texels per texel for coherent candidates (k of k-coherence).
    pub similar: u32,
    /// Extra relative cost of a jump over a shift (coherent candidates).
    pub jump_cost: f32,
    /// Occurrence penalty of coherent candidates.
    pub spread: f32,
    /// Footprint sharing and length-weighted cuts (results follow the
    /// texture, not the tessellation).
    pub density_invariant: bool,
}

impl Default for GraphMatchStageSettings {
    fn default() -> Self {
        Self {
            r_scale: 0.0,
            region: 0.0,
            k_min: 2,
            k_max: 0,
            image_levels: ImageLevels::Stack,
            image_level_count: 0,
            passes: vec![3, 2, 1],
            coarse_order: CoarseOrder::Sweep,
            averaging: true,
            graph_cut: true,
            cut_sigma: 1.0,
            candidates: Candidates::Exhaustive,
            similar: 4,
            jump_cost: JUMP_COST,
            spread: SPREAD,
            density_invariant: true,
        }
    }
}

impl StageSettings for GraphMatchStageSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "r_scale",
            unit: "texels per world unit",
            range: ParamRange::Float(0.0, 1e9),
            doc: "texture scale r_scale (§3.3.2); 0 = the run's `[input] texture_scale` (with `subdivide_sqrt2` deriving its depth from the same scale, about one texel per finest vertex spacing); a value here overrides it for this stage",
        },
        ParamDoc {
            name: "region",
            unit: "texels",
            range: ParamRange::Float(0.0, 64.0),
            doc: "edge n of the square texture neighbourhood a k-region stands for; k solves (k+1)² + k² = (aᵐ n / (r_scale ē))²; 0 = an eighth of the exemplar's smaller side, clamped to 5..=32 texels (16 for a 128² exemplar: a few texture elements across)",
        },
        ParamDoc {
            name: "k_min",
            unit: "edges",
            range: ParamRange::Int(1, 64),
            doc: "smallest k-region radius; 2 (default) gives coarse levels 13-vertex regions and the graph cut an interior (with graph_cut on, regions are grown to k ≥ 2 regardless: at k = 1 every vertex but the centre is on the border)",
        },
        ParamDoc {
            name: "k_max",
            unit: "edges",
            range: ParamRange::Int(0, 64),
            doc: "largest k-region radius (bounds the work where vertices are dense); 0 = the k the region needs at the finest level's mean edge, at most 16",
        },
        ParamDoc {
            name: "image_levels",
            unit: "",
            range: ParamRange::OneOf(&["stack", "pyramid"]),
            doc: "Gaussian stack (a = 1; each region vertex reads the level of its own density) or pyramid (a = 2; the centre's level)",
        },
        ParamDoc {
            name: "image_level_count",
            unit: "levels",
            range: ParamRange::Int(0, 16),
            doc: "stack/pyramid levels; 0 = until the blur spans the exemplar",
        },
        ParamDoc {
            name: "passes",
            unit: "passes",
            range: ParamRange::Int(0, 64),
            doc: "matching passes per mesh level, coarsest first; the last entry repeats for finer levels (§4); default [3, 2, 1]: extra passes where levels are cheap settle the layout before it is refined",
        },
        ParamDoc {
            name: "coarse_order",
            unit: "",
            range: ParamRange::OneOf(&["sweep", "random"]),
            doc: "order of the first pass on the coarsest level (sweep: a growing front, §3.1.2); later passes are random",
        },
        ParamDoc {
            name: "averaging",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "replace region vertices that map to one texel by their mean with multiplicity (§3.3.3); same result, fewer comparisons",
        },
        ParamDoc {
            name: "graph_cut",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "after each match, transfer the matched neighbourhood onto the k-region through a minimum cut (§3.4; the paper's method, so the default); false = only the matched vertex takes its texel (§3.3 alone). On the planar benchmark the cut lowers coherence mean and p90 on all five shared photos and is faster (covered vertices are not matched again)",
        },
        ParamDoc {
            name: "cut_sigma",
            unit: "",
            range: ParamRange::Float(1e-3, 1e3),
            doc: "σ of eq. 1: edge weights fall as exp(−(x_A² + x_B²)/(σ r²)) away from the matched vertex",
        },
        ParamDoc {
            name: "candidates",
            unit: "",
            range: ParamRange::OneOf(&["exhaustive", "coherent"]),
            doc: "where a vertex's texel is looked for: exhaustive = every texel of the level (Algorithm 1, the paper; with exemplar_wrap = \"clamp\" only texels whose whole region lies inside the exemplar, since a sample past the edge would read the edge texel repeated); coherent = an extension: the sources of the coloured region vertices within two edges shifted back by their offsets, and the `similar` texels most like each (k-coherence, Tong et al. 2002), so matches continue their neighbours' patches and graph cuts take larger pieces; the coarsest level's first pass stays exhaustive (it lays out the pattern)",
        },
        ParamDoc {
            name: "jump_cost",
            unit: "fraction of the region's colour sum",
            range: ParamRange::Float(0.0, 10.0),
            doc: "with candidates = coherent: a jump to a similar texel is taken only when its sum of squared differences, times 1 + jump_cost, is below every shift's (Ashikhmin-style bias toward continuing patches; 0 = plain minimum)",
        },
        ParamDoc {
            name: "spread",
            unit: "fraction of the candidates' mean colour sum per even share",
            range: ParamRange::Float(0.0, 10.0),
            doc: "with candidates = coherent: occurrence penalty — a candidate in a cell of the exemplar (square, half the region's side) used x times an even share (the larger of the mean count per cell and one copy of the cell), x > 1, costs spread · (x − 1) times the mean of the candidates' sums more, so continued patches do not all copy the part of the exemplar they started in (without it a result can settle on a quarter of the exemplar: diagonal streaks on water); lowers completeness and structure error, raises coherence error; 0 (default) = off; no effect with candidates = exhaustive",
        },
        ParamDoc {
            name: "density_invariant",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "true (default): results follow the texture, not the tessellation — region vertices less than half a texel from a matched vertex take the texel under them and are not matched again in that pass (the same samples, §3.3.3's oversampling), and graph-cut edge weights are scaled by the edge's length in texels (the cut's cost is seam length × mismatch, as on a continuous surface); so on meshes denser than the texture the matches per pass follow its area in texels, not the vertex count (linear time on dense scans); on meshes with edges of about a texel both change little; false = every vertex matched and eq. 1 as printed (the paper)",
        },
        ParamDoc {
            name: "similar",
            unit: "texels",
            range: ParamRange::Int(0, 32),
            doc: "with candidates = coherent: texels of similar appearance kept per exemplar texel (k of k-coherence; appearance = 8 principal components of 5 × 5 neighbourhoods at the level's texel spacing); 0 = shifts only",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if self.k_max != 0 && self.k_max < self.k_min {
            return Err((
                "k_max".into(),
                format!("{} is below k_min = {}", self.k_max, self.k_min),
            ));
        }
        if self.passes.is_empty() {
            return Err(("passes".into(), "give at least one entry".into()));
        }
        Ok(())
    }
}

/// Default `jump_cost` (see the parameter).
pub const JUMP_COST: f32 = 0.2;

/// Default `spread` (see the parameter): off. Measured on the planar
/// benchmark with coherent candidates and the cut
/// (`configs/plane/bangay_morkel_coherent.toml`, the config's seed), 0.3
/// keeps a result from settling on part of the exemplar (water: structure
/// 0.111 → 0.022, completeness 0.00148 → 0.00043; completeness lower and
/// the exemplar's rows used evenly on every photo) but raises coherence
/// p90 on four of five (brick 0.00066 → 0.00090, planks 0.00168 → 0.00220)
/// and shrinks the copied pieces on small results, so it is an option, not
/// the default.
pub const SPREAD: f32 = 0.0;

/// Largest derived `k_max`: a k-region of radius 16 holds 545 vertices on a
/// quad mesh, which bounds the work per vertex.
pub const DERIVED_K_MAX_CAP: u32 = 16;

/// The default region edge in texels for an exemplar of `width × height`:
/// an eighth of its smaller side, clamped to 5..=32 texels. An exemplar
/// holds a handful of texture elements across, so this is a scale the
/// texture has (16 texels for the 128² exemplars: about one brick's height,
/// a stone, a plank's width), in texels, and so independent of the mesh
/// and of `r_scale`.
pub fn default_region(width: u32, height: u32) -> f32 {
    (width.min(height) as f32 / 8.0).clamp(5.0, 32.0)
}

/// The default `k_max`: the `k` a region of `region` texels needs on a mesh
/// of mean edge `finest_edge` at `r_scale` texels per unit (§3.3.2, stack
/// levels), so the finest level gets its whole region, at least `k_min`
/// and at most [`DERIVED_K_MAX_CAP`] (or `k_min` when that is larger).
pub fn default_k_max(region: f32, r_scale: f32, finest_edge: f32, k_min: u32) -> u32 {
    let cap = DERIVED_K_MAX_CAP.max(k_min);
    crate::kernels::bangay_morkel::graph_match::region_k(
        region,
        1.0,
        r_scale,
        finest_edge,
        k_min,
        cap,
    )
}

impl GraphMatchStageSettings {
    /// The kernel's settings for `exemplar`, with the run's texture scale
    /// `texels_per_unit` and the finest level's mean edge `finest_edge`
    /// standing in for the parameters left at 0.
    fn kernel_settings(
        &self,
        exemplar: &Image,
        texels_per_unit: f32,
        finest_edge: f32,
    ) -> GraphMatchSettings {
        let r_scale = if self.r_scale > 0.0 {
            self.r_scale
        } else {
            texels_per_unit
        };
        let region = if self.region > 0.0 {
            self.region
        } else {
            default_region(exemplar.width, exemplar.height)
        };
        let k_max = if self.k_max > 0 {
            self.k_max
        } else {
            default_k_max(region, r_scale, finest_edge, self.k_min)
        };
        GraphMatchSettings {
            r_scale,
            region_texels: region,
            k_min: self.k_min,
            k_max,
            averaging: self.averaging,
            graph_cut: self.graph_cut,
            cut_sigma: self.cut_sigma,
            candidates: self.candidates,
            jump_cost: self.jump_cost,
            spread: self.spread,
            density_invariant: self.density_invariant,
        }
    }

    /// How the hierarchy is matched with `kernel`.
    fn hierarchy(&self, kernel: GraphMatchSettings) -> HierarchySettings<'_> {
        HierarchySettings {
            kernel,
            passes: &self.passes,
            sweep_first: self.coarse_order == CoarseOrder::Sweep,
            similar: self.similar as usize,
        }
    }

    /// The exemplar's Gaussian stack or pyramid.
    fn match_images(&self, exemplar: &Exemplar) -> MatchImages {
        let img = &exemplar.image;
        let level_count = if self.image_level_count > 0 {
            self.image_level_count as usize
        } else {
            MatchImages::default_levels(img)
        };
        let _span = tracing::info_span!("exemplar_levels", levels = level_count).entered();
        MatchImages::new(img, self.image_levels, level_count, exemplar.wrap)
    }
}

/// Mean number of vertices a cut coloured (0 without cuts).
fn per_cut(s: &PassStats) -> f64 {
    if s.cuts == 0 {
        0.0
    } else {
        s.cut_vertices as f64 / s.cuts as f64
    }
}

/// The `graph_match` stage.
pub struct GraphMatch;

/// What the stage reads of a hierarchy level.
type HierarchyData = (
    &'static Geometry,
    Option<&'static Frames>,
    Option<&'static VertexColours>,
    Option<&'static SweepField>,
    Option<&'static LevelParents>,
    Option<&'static SourceTexels>,
);

type LevelQuery<'w, 's> = Query<'w, 's, HierarchyData>;

/// A level of the hierarchy as the kernel reads it.
fn hierarchy_level<'a>(
    (geometry, frames, colours, sweep, parents, texels): ROQueryItem<'a, 'a, HierarchyData>,
) -> HierarchyLevel<'a> {
    HierarchyLevel {
        mesh: &geometry.0,
        frames: frames.map(|f| &f.0[..]),
        colours: colours.map(|c| (&c.values[..], c.channels)),
        texels: texels.map(|t| &t.0[..]),
        sweep: sweep.map(|s| &s.0[..]),
        parents: parents.map(|p| &p.0),
    }
}

/// Records the derived settings of the match as metrics of stage `index`.
fn record_settings(
    metrics: &mut Metrics,
    index: usize,
    kernel: &GraphMatchSettings,
    images: &MatchImages,
) {
    metrics.record(index, "r_scale", kernel.r_scale);
    metrics.record(index, "region", kernel.region_texels);
    metrics.record(index, "k_min", kernel.k_min);
    metrics.record(index, "k_max", kernel.k_max);
    metrics.record(index, "image_levels", images.levels());
}

/// Writes each level's match (coarsest first) on its entity, its colours
/// in the exemplar's channels and its scale `r_scale`, and records the
/// per-level and total counts.
fn write_levels(
    commands: &mut Commands,
    metrics: &mut Metrics,
    index: usize,
    entities: &[Entity],
    matched: Vec<LevelMatch>,
    exemplar: &Exemplar,
    r_scale: f32,
) {
    let channels = exemplar.image.channels as usize;
    let count = matched.len();
    let mut per_level = Vec::with_capacity(count);
    let mut total = PassStats::default();
    for (li, (&e, m)) in entities.iter().zip(matched).enumerate() {
        let nv = m.texels.len();
        per_level.push(serde_json::json!({
            "level": count - 1 - li,
            "vertices": nv,
            "passes": m.passes,
            "seconds": m.seconds,
            "stats": m.stats,
            "cut_vertices_per_cut": per_cut(&m.stats),
        }));
        total += m.stats;
        commands.entity(e).insert((
            VertexColours {
                channels,
                values: m.colours,
            },
            SourceTexels(m.texels),
            // The scale the sources were matched at, so a renderer
            // can continue each source across its vertex's
            // neighbourhood (`export`'s `plane_colours = "sources"`).
            VertexScale(vec![r_scale; nv]),
        ));
    }
    metrics.record(index, "levels", per_level);
    metrics.record(index, "total", total);
    metrics.record(index, "cut_vertices_per_cut", per_cut(&total));
}

impl Stage for GraphMatch {
    const KIND: &'static str = "graph_match";
    const SUMMARY: &'static str = "k-region graph matching against a Gaussian stack, coarse to fine over the √2 hierarchy, with optional graph-cut transfer";
    const PAPER: &'static str = "Bangay & Morkel 2006 §3.3, §3.4";
    type Settings = GraphMatchStageSettings;

    /// The exemplar's Gaussian stack and search planes, about 540 bytes an
    /// exemplar pixel; the FFT search's spectra of the levels it uses (at
    /// most 32 bytes an RGB pixel per level) and each thread's buffers
    /// (about 48 bytes a pixel, counted per core: `--threads` above the
    /// core count is not), for exemplars up to 512²; and the
    /// per-vertex colours, texels, regions and cut graphs, about 240 bytes
    /// a vertex (measured: `tests/memory_estimates.rs`).
    fn memory_estimate(_settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        const PER_VERTEX: u64 = 240;
        MemoryEstimate::per_vertex(
            "the exemplar stack and the per-vertex synthesis state",
            sizes,
            sizes.exemplar_pixels() * 540
                + MatchImages::spectral_bytes(
                    sizes.exemplar_width,
                    sizes.exemplar_height,
                    sizes.exemplar_channels,
                    MatchImages::default_levels_for(sizes.exemplar_width, sizes.exemplar_height),
                    // The cores, as rayon's default pool has: asking rayon
                    // would start its global pool before the command line
                    // sets `--threads` (validation comes first).
                    std::thread::available_parallelism().map_or(1, |n| n.get()),
                ),
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
                               active: Res<ActiveMesh>,
                               pyramid: Option<Res<Sqrt2Pyramid>>,
                               exemplar: Res<Exemplar>,
                               seed: Res<RunSeed>,
                               texture_scale: Res<TextureScale>,
                               mut spacing: ResMut<TexelSpacing>,
                               mut metrics: ResMut<Metrics>,
                               meshes: LevelQuery|
              -> SystemResult {
            let idx = ctx.index;
            // Coarsest first: the √2 hierarchy, or just the active mesh.
            let entities: Vec<Entity> = match pyramid.as_deref() {
                Some(p) if !p.0.is_empty() => p.0.iter().rev().copied().collect(),
                _ => vec![active.0],
            };
            let Ok((finest, finest_frames, ..)) = meshes.get(active.0) else {
                return Ok(());
            };
            let levels: Option<Vec<HierarchyLevel>> = entities
                .iter()
                .map(|&e| meshes.get(e).ok().map(hierarchy_level))
                .collect();
            let Some(levels) = levels else {
                return Ok(());
            };
            let kernel = settings.kernel_settings(
                &exemplar.image,
                texture_scale.texels_per_unit,
                finest.0.average_edge_length(),
            );
            let mut images = settings.match_images(&exemplar);
            record_settings(&mut metrics, idx, &kernel, &images);
            let hierarchy = settings.hierarchy(kernel);
            // One bar for the stage, its parts the levels' passes.
            let progress = Progress::new(0, Self::KIND);
            let _finish = progress.finish_on_drop();
            let matched = match_hierarchy(
                &levels,
                finest_frames.map(|f| &f.0[..]),
                &mut images,
                &hierarchy,
                &|stream| seed.derive(idx, stream),
                &progress,
            )?;
            progress.finish();
            write_levels(
                &mut commands,
                &mut metrics,
                idx,
                &entities,
                matched,
                &exemplar,
                kernel.r_scale,
            );
            spacing.0 = 1.0 / kernel.r_scale;
            Ok(())
        };
        ctx.fallible(Self::KIND, synthesize)
    }
}
