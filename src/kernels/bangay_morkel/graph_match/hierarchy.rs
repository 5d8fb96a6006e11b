//! Graph matching coarse to fine over a mesh hierarchy (Bangay & Morkel
//! 2006 §3.3, §4): the coarsest level starts from its colours if it has
//! any, otherwise uncoloured, and its first pass may visit vertices in
//! sweep order (§3.1.2) so the pattern grows as one front; every other pass
//! visits them in a seeded random order. A finer level starts from the
//! colours of the level above carried through the √2 parents.

use super::{
    BatchRule, Candidates, GraphMatchSettings, LevelMesh, MatchImages, PassStats, SynthesisState,
    match_pass_with_progress, mean_edge_lengths, pass_work_per_vertex,
};
use crate::kernels::bangay_morkel::sqrt2::Parents;
use crate::kernels::bangay_morkel::sweep::{sweep_field, sweep_order};
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::{PolyMesh, Topology};
use crate::progress::{Progress, level_label};
use glam::{Vec2, Vec3};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use std::time::Instant;

/// One level of the hierarchy as the matching reads it. A per-vertex
/// slice is used only when it has the level's vertex count.
#[derive(Clone, Copy, Debug)]
pub struct HierarchyLevel<'a> {
    /// The level's mesh.
    pub mesh: &'a PolyMesh,
    /// Its own tangent frames, if any ([`level_frames`]).
    pub frames: Option<&'a [TangentFrame]>,
    /// Colours it already has (values, channels per vertex): the coarsest
    /// level starts from them (e.g. `init_colours`' exemplar texels).
    pub colours: Option<(&'a [f32], usize)>,
    /// Where those colours came from (level-0 pixels).
    pub texels: Option<&'a [Vec2]>,
    /// Its sweep field (§3.1.2), for the first coarse pass.
    pub sweep: Option<&'a [f32]>,
    /// Its parents in the next coarser level (√2 ids).
    pub parents: Option<&'a Parents>,
}

/// How the hierarchy is matched.
#[derive(Clone, Copy, Debug)]
pub struct HierarchySettings<'a> {
    /// Region matching.
    pub kernel: GraphMatchSettings,
    /// Passes per level, coarsest first; the last entry repeats.
    pub passes: &'a [u32],
    /// The first pass on the coarsest level in increasing sweep value (a
    /// growing front); otherwise a seeded random order.
    pub sweep_first: bool,
    /// Similar texels per texel for coherent candidates.
    pub similar: usize,
}

impl HierarchySettings<'_> {
    /// The passes of the level `level_from_coarsest` levels below the
    /// coarsest.
    pub fn passes_for(&self, level_from_coarsest: usize) -> u32 {
        let i = level_from_coarsest.min(self.passes.len().saturating_sub(1));
        self.passes.get(i).copied().unwrap_or(1)
    }
}

/// What matching left on one level.
#[derive(Clone, Debug)]
pub struct LevelMatch {
    /// Colours, the exemplar's channels per vertex.
    pub colours: Vec<f32>,
    /// Matched exemplar texel per vertex (level-0 pixels).
    pub texels: Vec<Vec2>,
    /// Passes run.
    pub passes: u32,
    /// Their counts.
    pub stats: PassStats,
    /// Wall time of the level.
    pub seconds: f64,
}

/// Frames for a level: its own, or the finest level's restricted to the
/// level's vertices (√2 keeps ids) and re-projected onto its normals.
pub fn level_frames(
    mesh: &PolyMesh,
    own: Option<&[TangentFrame]>,
    finest: Option<&[TangentFrame]>,
) -> Option<Vec<TangentFrame>> {
    let n = mesh.vertex_count();
    if let Some(f) = own.filter(|f| f.len() == n) {
        return Some(f.to_vec());
    }
    let f = finest.filter(|f| f.len() >= n)?;
    let normals = mesh.vertex_normals();
    Some(
        normals
            .iter()
            .zip(f)
            .map(|(&nrm, fr)| TangentFrame::from_up(nrm, fr.t))
            .collect(),
    )
}

/// Matches `levels` (coarsest first) against `images`, level by level
/// ([`match_pass_with_progress`] for every pass), reporting to `progress`
/// one part per pass weighed by the level's vertices times a vertex's work
/// at the level's mean edge ([`pass_work_per_vertex`]), so the finest
/// levels, with the most vertices and the largest regions, take their
/// share of the ETA. `finest_frames` stand in for a level without frames
/// of its own. `seed(stream)` gives the seed of a random stream: `0xC0DE`
/// the similarity sets, `(li << 16) | pass` a pass's random order, `1 <<
/// 40 | (li << 16) | pass` its matching.
///
/// # Errors
/// A level without frames, or a finer level without parents.
pub fn match_hierarchy(
    levels: &[HierarchyLevel],
    finest_frames: Option<&[TangentFrame]>,
    images: &mut MatchImages,
    settings: &HierarchySettings,
    seed: &dyn Fn(u64) -> u64,
    progress: &Progress,
) -> Result<Vec<LevelMatch>, String> {
    let count = levels.len();
    let part = |li: usize, pass: u32, passes: u32| {
        format!(
            "{} pass {}/{passes}",
            level_label(count - 1 - li, count),
            pass + 1
        )
    };
    progress.plan(levels.iter().enumerate().flat_map(|(li, level)| {
        let passes = settings.passes_for(li);
        let mesh = level.mesh;
        let per_vertex = pass_work_per_vertex(images, &settings.kernel, mesh.average_edge_length());
        let work = mesh.vertex_count() as f64 * per_vertex;
        (0..passes).map(move |pass| (part(li, pass, passes), work))
    }));
    let mut state: Option<SynthesisState> = None;
    let mut out = Vec::with_capacity(count);
    for (li, level) in levels.iter().enumerate() {
        let mesh = level.mesh;
        let nv = mesh.vertex_count();
        let started = Instant::now();
        let _span =
            tracing::info_span!("match_level", level = count - 1 - li, vertices = nv).entered();
        let frames = level_frames(mesh, level.frames, finest_frames)
            .ok_or("a level has no tangent frames")?;
        let topo = Topology::build(mesh);
        let mean_edge = mean_edge_lengths(&mesh.positions, &topo);
        if settings.kernel.candidates == Candidates::Coherent {
            prepare_similar_sets(images, settings, &mean_edge, seed(0xC0DE));
        }
        let mut st = start_state(state.take(), level, images.channels())?;
        let level_mesh = LevelMesh {
            positions: &mesh.positions,
            topo: &topo,
            frames: &frames,
            mean_edge: &mean_edge,
        };
        let passes = settings.passes_for(li);
        let mut stats = PassStats::default();
        for pass in 0..passes {
            progress.start_part(&part(li, pass, passes), nv as u64);
            let stream = ((li as u64) << 16) | pass as u64;
            let (order, rule) = if li == 0 && pass == 0 && settings.sweep_first {
                let values = match level.sweep {
                    Some(s) if s.len() == nv => s.to_vec(),
                    _ => {
                        let dirs: Vec<Vec3> = frames.iter().map(|f| f.t).collect();
                        sweep_field(&mesh.positions, &topo, &dirs, &[0], 30)
                    }
                };
                (sweep_order(&values), BatchRule::Exact)
            } else {
                let mut o: Vec<u32> = (0..nv as u32).collect();
                o.shuffle(&mut rand_pcg::Pcg64Mcg::seed_from_u64(seed(stream)));
                (o, BatchRule::Relaxed)
            };
            // The first coarse pass lays the pattern out by exhaustive
            // matching; coherent candidates would copy the exemplar
            // verbatim from the first vertex on.
            let pass_kernel = if li == 0 && pass == 0 {
                GraphMatchSettings {
                    candidates: Candidates::Exhaustive,
                    ..settings.kernel
                }
            } else {
                settings.kernel
            };
            stats += match_pass_with_progress(
                &level_mesh,
                images,
                &pass_kernel,
                &order,
                rule,
                seed((1 << 40) | stream),
                &mut st,
                progress,
            );
        }
        let seconds = started.elapsed().as_secs_f64();
        tracing::info!(
            "level {} ({nv} vertices): {passes} passes, {} matched, {} comparisons ({} without averaging), {seconds:.2} s",
            count - 1 - li,
            stats.matched,
            stats.comparisons_averaged,
            stats.comparisons_plain
        );
        out.push(LevelMatch {
            colours: st.colours.clone(),
            texels: st.texels.clone(),
            passes,
            stats,
            seconds,
        });
        state = Some(st);
    }
    Ok(out)
}

/// Similarity sets of the image levels a mesh level of mean edges
/// `mean_edge` is matched on (each level's depend only on the level and
/// the seed, so preparing them level by level changes nothing).
fn prepare_similar_sets(
    images: &mut MatchImages,
    settings: &HierarchySettings,
    mean_edge: &[f32],
    seed: u64,
) {
    let _span = tracing::info_span!("similarity_sets", k = settings.similar).entered();
    let mut used = vec![false; images.levels()];
    for &m in mean_edge {
        used[images.level_for(settings.kernel.r_scale * m)] = true;
    }
    let used: Vec<usize> = (0..used.len()).filter(|&l| used[l]).collect();
    images.prepare_similar(&used, settings.similar, seed);
}

/// The state a level starts from: the coarsest level its own colours of
/// `channels` values (and their texels) or none; a finer one the level
/// above's `previous` state carried through its parents.
fn start_state(
    previous: Option<SynthesisState>,
    level: &HierarchyLevel,
    channels: usize,
) -> Result<SynthesisState, String> {
    let nv = level.mesh.vertex_count();
    match (previous, level.parents) {
        // Colours already there (e.g. `init_colours`: exemplar
        // texels) stand for level 0.
        (None, _) => Ok(match level.colours {
            Some((values, c)) if c == channels && values.len() == nv * channels => {
                let mut s = SynthesisState::from_colours(values.to_vec(), channels, 0);
                // Keep where those colours came from, so vertices
                // no pass rematches still name their texel.
                if let Some(t) = level.texels.filter(|t| t.len() == nv) {
                    s.texels.copy_from_slice(t);
                }
                s
            }
            _ => SynthesisState::uncoloured(nv, channels),
        }),
        (Some(prev), Some(p)) if p.len() == nv => Ok(prev.carried(p)),
        _ => Err("a hierarchy level has no parents in the level above".into()),
    }
}
