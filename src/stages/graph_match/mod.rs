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

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::bangay_morkel::graph_match::{
    BatchRule, Candidates, GraphMatchSettings, ImageLevels, LevelMesh, MatchImages, PassStats,
    SynthesisState, match_pass_with_progress, mean_edge_lengths, pass_work_per_vertex,
};
use crate::kernels::bangay_morkel::sweep::{sweep_field, sweep_order};
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::Topology;
use crate::progress::{Progress, level_label};
use crate::stage::{Datum, Stage, StageCtx, StageError};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use rand::seq::SliceRandom;
use serde::{Deserialize, Serialize};
use std::time::Instant;

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
    fn passes_for(&self, level_from_coarsest: usize) -> u32 {
        let i = level_from_coarsest.min(self.passes.len().saturating_sub(1));
        self.passes.get(i).copied().unwrap_or(1)
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

type LevelQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static Geometry,
        Option<&'static Frames>,
        Option<&'static VertexColours>,
        Option<&'static SweepField>,
        Option<&'static LevelParents>,
        Option<&'static SourceTexels>,
    ),
>;

/// Frames for a level: its own, or the active mesh's restricted to the
/// level's vertices (√2 keeps ids) and re-projected onto its normals.
fn level_frames(
    mesh: &crate::mesh::PolyMesh,
    own: Option<&Frames>,
    finest: Option<&Frames>,
) -> Option<Vec<TangentFrame>> {
    let n = mesh.vertex_count();
    if let Some(f) = own.filter(|f| f.0.len() == n) {
        return Some(f.0.clone());
    }
    let f = finest.filter(|f| f.0.len() >= n)?;
    let normals = mesh.vertex_normals();
    Some(
        normals
            .iter()
            .zip(&f.0)
            .map(|(&nrm, fr)| TangentFrame::from_up(nrm, fr.t))
            .collect(),
    )
}

impl Stage for GraphMatch {
    const KIND: &'static str = "graph_match";
    const SUMMARY: &'static str = "k-region graph matching against a Gaussian stack, coarse to fine over the √2 hierarchy, with optional graph-cut transfer";
    const PAPER: &'static str = "Bangay & Morkel 2006 §3.3, §3.4";
    type Settings = GraphMatchStageSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh, Datum::Frames]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Colours]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        (move |mut commands: Commands,
               active: Res<ActiveMesh>,
               pyramid: Option<Res<Sqrt2Pyramid>>,
               exemplar: Res<Exemplar>,
               seed: Res<RunSeed>,
               texture_scale: Res<TextureScale>,
               mut spacing: ResMut<TexelSpacing>,
               mut metrics: ResMut<Metrics>,
               mut failure: ResMut<StageFailure>,
               meshes: LevelQuery| {
            let fail = |failure: &mut StageFailure, message: String| {
                failure.0 = Some(StageError {
                    index: ctx.index + 1,
                    kind: Self::KIND.into(),
                    message,
                });
            };
            let idx = ctx.index;
            let levels: Vec<Entity> = match pyramid.as_deref() {
                Some(p) if !p.0.is_empty() => p.0.iter().rev().copied().collect(),
                _ => vec![active.0],
            };
            let Ok((finest_geometry, finest_frames, ..)) = meshes.get(active.0) else {
                return;
            };
            let r_scale = if settings.r_scale > 0.0 {
                settings.r_scale
            } else {
                texture_scale.texels_per_unit
            };
            let img = &exemplar.image;
            let level_count = if settings.image_level_count > 0 {
                settings.image_level_count as usize
            } else {
                MatchImages::default_levels(img)
            };
            let mut images = {
                let _span = tracing::info_span!("exemplar_levels", levels = level_count).entered();
                MatchImages::new(img, settings.image_levels, level_count, exemplar.wrap)
            };
            let region = if settings.region > 0.0 {
                settings.region
            } else {
                default_region(img.width, img.height)
            };
            let k_max = if settings.k_max > 0 {
                settings.k_max
            } else {
                default_k_max(
                    region,
                    r_scale,
                    finest_geometry.0.average_edge_length(),
                    settings.k_min,
                )
            };
            let kernel = GraphMatchSettings {
                r_scale,
                region_texels: region,
                k_min: settings.k_min,
                k_max,
                averaging: settings.averaging,
                graph_cut: settings.graph_cut,
                cut_sigma: settings.cut_sigma,
                candidates: settings.candidates,
                jump_cost: settings.jump_cost,
                spread: settings.spread,
                density_invariant: settings.density_invariant,
            };
            metrics.record(idx, "r_scale", r_scale);
            metrics.record(idx, "region", region);
            metrics.record(idx, "k_min", settings.k_min);
            metrics.record(idx, "k_max", k_max);
            metrics.record(idx, "image_levels", images.levels());
            let ch = img.channels as usize;
            // One bar for the stage: each level's passes weighed by the
            // level's vertices times a vertex's work at the level's mean
            // edge (without graph cut its region's size), so the finest
            // levels, with the most vertices and the largest regions, take
            // their share of the ETA.
            let part = |li: usize, pass: u32, passes: u32| {
                format!(
                    "{} pass {}/{passes}",
                    level_label(levels.len() - 1 - li, levels.len()),
                    pass + 1
                )
            };
            let progress = Progress::new(0, Self::KIND);
            let _finish = progress.finish_on_drop();
            progress.plan(levels.iter().enumerate().flat_map(|(li, &e)| {
                let passes = settings.passes_for(li);
                let work = meshes.get(e).map_or(0.0, |m| {
                    let mesh = &m.0.0;
                    let per_vertex = pass_work_per_vertex(&images, &kernel, mesh.average_edge_length());
                    mesh.vertex_count() as f64 * per_vertex
                });
                (0..passes).map(move |pass| (part(li, pass, passes), work))
            }));
            let mut state: Option<SynthesisState> = None;
            let mut per_level = Vec::new();
            let mut total = PassStats::default();
            for (li, &e) in levels.iter().enumerate() {
                let Ok((geometry, frames, colours, sweep, parents, texels)) = meshes.get(e) else {
                    return;
                };
                let mesh = &geometry.0;
                let nv = mesh.vertex_count();
                let started = Instant::now();
                let _span = tracing::info_span!("match_level", level = levels.len() - 1 - li, vertices = nv).entered();
                let Some(frames) = level_frames(mesh, frames, finest_frames) else {
                    return fail(&mut failure, "a level has no tangent frames".into());
                };
                let topo = Topology::build(mesh);
                let mean_edge = mean_edge_lengths(&mesh.positions, &topo);
                if settings.candidates == Candidates::Coherent {
                    // Similarity sets of the image levels this mesh level is
                    // matched on (each level's depend only on the level and
                    // the seed, so preparing them level by level changes
                    // nothing).
                    let _span = tracing::info_span!("similarity_sets", k = settings.similar).entered();
                    let mut used = vec![false; images.levels()];
                    for &m in &mean_edge {
                        used[images.level_for(r_scale * m)] = true;
                    }
                    let used: Vec<usize> = (0..used.len()).filter(|&l| used[l]).collect();
                    images.prepare_similar(&used, settings.similar as usize, seed.derive(idx, 0xC0DE));
                }
                let mut st = match (state.take(), parents) {
                    // Colours already there (e.g. `init_colours`: exemplar
                    // texels) stand for level 0.
                    (None, _) => match colours {
                        Some(c) if c.channels == ch && c.values.len() == nv * ch => {
                            let mut s = SynthesisState::from_colours(c.values.clone(), ch, 0);
                            // Keep where those colours came from, so vertices
                            // no pass rematches still name their texel.
                            if let Some(t) = texels.filter(|t| t.0.len() == nv) {
                                s.texels.clone_from(&t.0);
                            }
                            s
                        }
                        _ => SynthesisState::uncoloured(nv, ch),
                    },
                    (Some(prev), Some(p)) if p.0.len() == nv => prev.carried(&p.0),
                    _ => {
                        return fail(
                            &mut failure,
                            "a hierarchy level has no parents in the level above".into(),
                        );
                    }
                };
                let level = LevelMesh {
                    positions: &mesh.positions,
                    topo: &topo,
                    frames: &frames,
                    mean_edge: &mean_edge,
                };
                let passes = settings.passes_for(li);
                let mut level_stats = PassStats::default();
                for pass in 0..passes {
                    progress.start_part(&part(li, pass, passes), nv as u64);
                    let (order, rule) = if li == 0 && pass == 0 && settings.coarse_order == CoarseOrder::Sweep {
                        let values = match sweep {
                            Some(s) if s.0.len() == nv => s.0.clone(),
                            _ => {
                                let dirs: Vec<glam::Vec3> = frames.iter().map(|f| f.t).collect();
                                sweep_field(&mesh.positions, &topo, &dirs, &[0], 30)
                            }
                        };
                        (sweep_order(&values), BatchRule::Exact)
                    } else {
                        let mut o: Vec<u32> = (0..nv as u32).collect();
                        o.shuffle(&mut seed.rng(idx, ((li as u64) << 16) | pass as u64));
                        (o, BatchRule::Relaxed)
                    };
                    // The first coarse pass lays the pattern out by
                    // exhaustive matching; coherent candidates would copy
                    // the exemplar verbatim from the first vertex on.
                    let pass_kernel = if li == 0 && pass == 0 {
                        GraphMatchSettings {
                            candidates: Candidates::Exhaustive,
                            ..kernel
                        }
                    } else {
                        kernel
                    };
                    let s = match_pass_with_progress(
                        &level,
                        &images,
                        &pass_kernel,
                        &order,
                        rule,
                        seed.derive(idx, (1 << 40) | ((li as u64) << 16) | pass as u64),
                        &mut st,
                        &progress,
                    );
                    level_stats += s;
                }
                let seconds = started.elapsed().as_secs_f64();
                tracing::info!(
                    "level {} ({nv} vertices): {passes} passes, {} matched, {} comparisons ({} without averaging), {seconds:.2} s",
                    levels.len() - 1 - li,
                    level_stats.matched,
                    level_stats.comparisons_averaged,
                    level_stats.comparisons_plain
                );
                per_level.push(serde_json::json!({
                    "level": levels.len() - 1 - li,
                    "vertices": nv,
                    "passes": passes,
                    "seconds": seconds,
                    "stats": level_stats,
                    "cut_vertices_per_cut": per_cut(&level_stats),
                }));
                total += level_stats;
                commands.entity(e).insert((
                    VertexColours {
                        channels: ch,
                        values: st.colours.clone(),
                    },
                    SourceTexels(st.texels.clone()),
                    // The scale the sources were matched at, so a renderer
                    // can continue each source across its vertex's
                    // neighbourhood (`export`'s `plane_colours = "sources"`).
                    VertexScale(vec![r_scale; st.texels.len()]),
                ));
                state = Some(st);
            }
            progress.finish();
            metrics.record(idx, "levels", per_level);
            metrics.record(idx, "total", total);
            metrics.record(idx, "cut_vertices_per_cut", per_cut(&total));
            spacing.0 = 1.0 / r_scale;
        })
        .into_configs()
    }
}
