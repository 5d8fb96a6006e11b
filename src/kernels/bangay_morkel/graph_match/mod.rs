//! Texture synthesis by k-region graph matching (Bangay & Morkel 2006 §3.3,
//! with the graph-cut transfer of §3.4).
//!
//! For a vertex `P` to colour:
//! 1. its *k-region* (the vertices at most `k` edges away, Fig. 7) is
//!    unfolded into texture space: every region vertex gets an offset
//!    `(uᵢ, vᵢ)` from `P`, accumulated along shortest edge paths and
//!    averaged over all of them (§3.3.1, [`k_region`]); `k` follows from a
//!    region size given in texels (§3.3.2, [`region_k`]);
//! 2. every coloured region vertex reads the Gaussian stack level of its own
//!    vertex density, `log2(r_scale · ē)` (§3.3.4,
//!    [`MatchImages::level_for`]), at `Q + (uᵢ, vᵢ)`;
//! 3. the texel `Q` of the exemplar with the smallest sum of squared colour
//!    differences wins, searched exhaustively (Algorithm 1,
//!    [`best_match`]); region vertices that land on the same texel are
//!    first replaced by their mean colour with their count as weight
//!    (oversampling, §3.3.3, [`MatchGroups`]);
//! 4. `P` takes the colour of `Q` on its own level and remembers `Q`
//!    (`SourceTexels`); with graph cut on, the region around `P` takes the
//!    exemplar imprint where a minimum cut says so (§3.4,
//!    [`crate::kernels::bangay_morkel::graph_cut_transfer`]).
//!
//! With [`Candidates::Coherent`] (an extension beyond the paper) step 3
//! scores only k-coherent candidates instead of every texel: the sources of
//! the coloured region vertices within two edges, shifted back by their
//! offsets, and the texels most similar to each in appearance space
//! ([`MatchImages::prepare_similar`]), a jump costing `jump_cost` more than a
//! shift. Matches then continue their neighbours' patches, so the graph cut
//! of step 4 finds imprints that agree with the surface and takes larger
//! pieces (fewer seams).
//!
//! [`match_pass`] runs this over a vertex order; [`hierarchy`] runs the
//! passes coarse to fine over a √2 hierarchy. Vertices whose k-regions
//! are disjoint do not see each other's results, so batches of vertices
//! with pairwise disjoint regions are matched in parallel (consecutive ones
//! for a sweep order, [`BatchRule::Exact`]; any for a random order,
//! [`BatchRule::Relaxed`]): the result is exactly that of a sequential
//! order, whatever the thread count. A batch of one vertex is searched in
//! parallel over candidate tiles.

pub mod hierarchy;
mod region;
mod search;
mod spectral;
mod stack;

pub use region::{KRegion, RegionScratch, k_for_side, k_region, mean_edge_lengths, region_k};
pub use search::{
    BestMatch, MatchGroups, Sample, Search, best_candidate, best_candidate_with, best_match,
    best_match_by,
};
pub use stack::{ImageLevels, MatchImages};

use crate::image::sample::Wrap;
use crate::kernels::bangay_morkel::graph_cut_transfer::{TransferRegion, graph_cut_transfer};
use crate::kernels::bangay_morkel::sqrt2::Parents;
use crate::kernels::mix;
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::Topology;
use crate::progress::Progress;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Smallest region radius with graph cut on: a k-region of radius 1 has no
/// vertex between the target and the border ring, so its cut is trivial.
pub const MIN_CUT_K: u32 = 2;

/// At most this many vertices are matched as one parallel batch.
const MAX_BATCH: usize = 64;

/// Settings of region matching.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GraphMatchSettings {
    /// `r_scale`: texels of the exemplar per world unit (§3.3.2); > 0.
    pub r_scale: f32,
    /// `n`: edge of the square neighbourhood in texels of the matched level
    /// (§3.3.2); > 0.
    pub region_texels: f32,
    /// Smallest `k` used (at least 1, so a region has neighbours).
    pub k_min: u32,
    /// Largest `k` used (bounds the cost where vertices are dense).
    pub k_max: u32,
    /// Oversampling averaging of §3.3.3 (same result, fewer comparisons).
    pub averaging: bool,
    /// Graph-cut transfer of the matched neighbourhood onto the region
    /// (§3.4); when off only the matched vertex is coloured. When on,
    /// regions have radius at least [`MIN_CUT_K`] whatever `k_min`.
    pub graph_cut: bool,
    /// `σ` of eq. 1; > 0.
    pub cut_sigma: f32,
    /// Where the matched texel `Q` is looked for.
    pub candidates: Candidates,
    /// With coherent candidates: a jump to a similar texel must beat the
    /// shifts by this fraction of its sum (its sum is scaled by
    /// `1 + jump_cost`); ≥ 0.
    pub jump_cost: f32,
    /// With coherent candidates: weight of the occurrence penalty (counts
    /// per exemplar cell, `kernels::surface::occupancy`); a candidate in a part of the exemplar used `x > 1`
    /// times an even share costs `spread · (x − 1)` times the mean of the
    /// candidates' sums more. 0 = off (the default). ≥ 0.
    pub spread: f32,
    /// Results that follow the texture, not the tessellation: region
    /// vertices less than half a texel from a matched vertex take the texel
    /// under them and are not matched on their own in the same pass
    /// ([`FOOTPRINT`]), and a cut's edge weights are scaled by the edges'
    /// lengths in texels. Off, every vertex is matched and eq. 1 is used as
    /// printed (the paper).
    pub density_invariant: bool,
}

/// Radius, in texels of the matched level, of a matched vertex's footprint:
/// region vertices closer than this read the matched texel itself (their
/// offset rounds to zero), so matching them on their own would compare
/// almost the same samples again. Sharing it makes the number of matches
/// per pass follow the texture's area in texels rather than the vertex
/// count on meshes denser than the texture (linear time on dense scans);
/// on meshes with edges of a texel or more it never applies.
pub const FOOTPRINT: f32 = 0.5;

/// Where [`match_pass`] looks for a vertex's texel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Candidates {
    /// Every texel of the level (Algorithm 1; the paper); with a clamped
    /// exemplar, every texel whose region lies inside it.
    #[default]
    Exhaustive,
    /// k-coherent candidates (an extension; Ashikhmin 2001, Tong et al.
    /// 2002): the source of each coloured region vertex within two edges,
    /// shifted back by its offset, and the pixels most similar to that
    /// source in appearance space ([`MatchImages::prepare_similar`]), each
    /// shifted the same way. The region's full colour sum picks among them.
    /// Falls back to the exhaustive search where no region vertex within
    /// two edges is coloured or the level has no similarity sets.
    Coherent,
}

/// The vertices' uses of the exemplar's cells (`kernels::surface::occupancy`), for
/// the occurrence penalty of coherent candidates
/// ([`GraphMatchSettings::spread`]): without it, continued patches keep
/// copying the part of the exemplar they started in, and a result can
/// settle on a quarter of it. Counts are taken at the start of a pass and
/// updated after each parallel batch, so a batch reads one state whatever
/// the thread count. Coordinates are level-0 texels; the penalty counts
/// only use beyond an even share.
struct Occupancy(crate::kernels::surface::occupancy::Occupancy);

impl Occupancy {
    /// Cells of side `cell` level-0 texels. `texels_per_vertex`: about the
    /// level's area per vertex in level-0 texels² (its mean edge squared).
    /// A cell counts as evenly used at
    /// the larger of the mean count and one copy of it (a result smaller
    /// than the exemplar need not use all of it, and a patch copied once is
    /// not over-used).
    fn new(
        state: &SynthesisState,
        images: &MatchImages,
        cell: f32,
        texels_per_vertex: f32,
    ) -> Self {
        let img = images.image(0);
        let mut occ = crate::kernels::surface::occupancy::Occupancy::new(
            img.width as f32,
            img.height as f32,
            cell,
        );
        let mut n = 0usize;
        for (t, &c) in state.texels.iter().zip(&state.coloured) {
            if c {
                occ.add(*t);
                n += 1;
            }
        }
        let cell = cell.max(1.0);
        let once = cell * cell / texels_per_vertex.max(f32::MIN_POSITIVE);
        occ.expected = (n as f32 / occ.cells() as f32).max(once).max(1.0);
        Self(occ)
    }

    /// How far the uses of `t`'s cell by other vertices than the one at
    /// `here` exceed an even share, in even shares (0 up to one share).
    #[inline]
    fn load(&self, t: Vec2, here: Option<Vec2>) -> f32 {
        (self.0.share(t, here) - 1.0).max(0.0)
    }

    fn moved(&mut self, from: Option<Vec2>, to: Vec2) {
        self.0.moved(from, to);
    }
}

/// Region vertices at most this many edges from the centre give coherent
/// candidates.
const COHERENT_DEPTH: u32 = 2;

impl Default for GraphMatchSettings {
    fn default() -> Self {
        Self {
            r_scale: 64.0,
            region_texels: 5.0,
            k_min: 1,
            k_max: 12,
            averaging: true,
            graph_cut: false,
            cut_sigma: 1.0,
            candidates: Candidates::Exhaustive,
            jump_cost: 0.0,
            spread: 0.0,
            density_invariant: false,
        }
    }
}

/// A mesh level as the matcher reads it.
#[derive(Clone, Copy, Debug)]
pub struct LevelMesh<'a> {
    /// Vertex positions.
    pub positions: &'a [Vec3],
    /// Its topology.
    pub topo: &'a Topology,
    /// Tangent frames (s right, t up), one per vertex.
    pub frames: &'a [TangentFrame],
    /// Mean edge length per vertex ([`mean_edge_lengths`]).
    pub mean_edge: &'a [f32],
}

/// What synthesis has written so far on one level.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SynthesisState {
    /// Values per colour.
    pub channels: usize,
    /// Colours, `channels` per vertex.
    pub colours: Vec<f32>,
    /// Matched exemplar coordinate per vertex, in level-0 pixels (pixel
    /// centres at `i + 0.5`).
    pub texels: Vec<Vec2>,
    /// Whether each vertex has a colour yet.
    pub coloured: Vec<bool>,
    /// The image level each colour stands for: the level it was copied
    /// from. A vertex's colour is compared with the exemplar on this level
    /// (§3.3.4), so colours carried down from a coarser mesh level, which
    /// stand for larger areas, are matched against blurrier levels than
    /// colours matched on the current one ("simultaneous matching against
    /// multiple levels", abstract).
    pub levels: Vec<u8>,
}

impl SynthesisState {
    /// `vertices` vertices without colours.
    pub fn uncoloured(vertices: usize, channels: usize) -> Self {
        Self {
            channels,
            colours: vec![0.0; vertices * channels],
            texels: vec![Vec2::ZERO; vertices],
            coloured: vec![false; vertices],
            levels: vec![0; vertices],
        }
    }

    /// Every vertex coloured with `colours` (`channels` per vertex), taken
    /// to stand for image level `level`.
    pub fn from_colours(colours: Vec<f32>, channels: usize, level: u8) -> Self {
        let n = colours.len() / channels.max(1);
        Self {
            channels,
            colours,
            texels: vec![Vec2::ZERO; n],
            coloured: vec![true; n],
            levels: vec![level; n],
        }
    }

    /// The state carried to a refined mesh level through its √2 `parents`:
    /// an old vertex keeps everything bit for bit; a new one gets the
    /// weighted mean colour and texel of its parents, is coloured when all
    /// of them are, and stands for one level above the coarsest among them
    /// (a mean of neighbouring samples is blurrier than each of them). Until
    /// it is matched again, its colour is thus compared with a blurrier
    /// level than the freshly matched colours around it, which keeps the
    /// interpolated guidance from pulling matches toward flat exemplar
    /// areas (measured: sharper results and a lower energy relative to a
    /// shuffle on the planar test).
    pub fn carried(&self, parents: &Parents) -> Self {
        let ch = self.channels;
        let n = parents.len();
        let mut out = Self::uncoloured(n, ch);
        for v in 0..n {
            let (pv, pw) = parents.of(v);
            if let ([s], [w]) = (pv, pw)
                && *w == 1.0
            {
                let s = *s as usize;
                out.colours[v * ch..(v + 1) * ch]
                    .copy_from_slice(&self.colours[s * ch..(s + 1) * ch]);
                out.texels[v] = self.texels[s];
                out.coloured[v] = self.coloured[s];
                out.levels[v] = self.levels[s];
                continue;
            }
            let mut texel = Vec2::ZERO;
            let (mut coloured, mut level) = (true, 0u8);
            for (&s, &w) in pv.iter().zip(pw) {
                let s = s as usize;
                for c in 0..ch {
                    out.colours[v * ch + c] += self.colours[s * ch + c] * w;
                }
                texel += self.texels[s] * w;
                coloured &= self.coloured[s];
                level = level.max(self.levels[s]);
            }
            out.texels[v] = texel;
            out.coloured[v] = coloured;
            out.levels[v] = level.saturating_add(1);
        }
        out
    }
}

/// Counts of one or more passes (the figures of Table 1 and §3.4).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct PassStats {
    /// Vertices matched.
    pub matched: u64,
    /// Vertices skipped because a graph cut or a matched vertex's footprint
    /// ([`FOOTPRINT`]) coloured them earlier in the same pass.
    pub covered_by_cuts: u64,
    /// Vertices coloured as part of a matched vertex's footprint (not taken
    /// by its cut).
    pub footprint_vertices: u64,
    /// Vertices that had no coloured region vertex and took a random texel.
    pub random_starts: u64,
    /// Region vertices compared per candidate, summed over matched vertices,
    /// counting every coloured region vertex ("without averaging").
    pub comparisons_plain: u64,
    /// The same counting one term per distinct texel ("with averaging").
    pub comparisons_averaged: u64,
    /// Graph cuts solved.
    pub cuts: u64,
    /// Vertices that took exemplar colours in cuts (the matched vertices
    /// included).
    pub cut_vertices: u64,
    /// Largest number of vertices one cut coloured.
    pub cut_vertices_max: u64,
    /// Sum of the cut costs (seams), colour-distance units.
    pub cut_cost: f64,
    /// Largest gap between a cut's cost and its max-flow value.
    pub cut_flow_gap: f64,
    /// Parallel batches the pass was split into.
    pub batches: u64,
}

impl std::ops::AddAssign for PassStats {
    fn add_assign(&mut self, o: Self) {
        self.matched += o.matched;
        self.covered_by_cuts += o.covered_by_cuts;
        self.footprint_vertices += o.footprint_vertices;
        self.random_starts += o.random_starts;
        self.comparisons_plain += o.comparisons_plain;
        self.comparisons_averaged += o.comparisons_averaged;
        self.cuts += o.cuts;
        self.cut_vertices += o.cut_vertices;
        self.cut_vertices_max = self.cut_vertices_max.max(o.cut_vertices_max);
        self.cut_cost += o.cut_cost;
        self.cut_flow_gap = self.cut_flow_gap.max(o.cut_flow_gap);
        self.batches += o.batches;
    }
}

/// A vertex ready to match: its region and levels.
struct Planned {
    region: KRegion,
    /// Image level of the centre (stack level or pyramid level).
    level: usize,
}

/// What matching one vertex decided; applied after its batch.
struct Outcome {
    /// Vertex, exemplar texel (level-0 pixels) and the level its colour
    /// came from.
    writes: Vec<(u32, Vec2, u8)>,
    colours: Vec<f32>,
    stats: PassStats,
}

/// How closely a pass must follow its vertex order.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BatchRule {
    /// Exactly the given order (a sweep front): only runs of *consecutive*
    /// vertices with pairwise disjoint regions are matched together.
    #[default]
    Exact,
    /// The order may be permuted for parallelism (a random order): a vertex
    /// whose region overlaps the batch being formed waits for the next one.
    /// The pass then equals processing, one vertex at a time, the order
    /// "batch 1, batch 2, …", which depends only on the order and the mesh.
    Relaxed,
}

/// Vertices planned ahead of the batches, per planning round.
const PLAN_AHEAD: usize = 4 * MAX_BATCH;

thread_local! {
    /// Per-thread region buffers (sized by the mesh, so kept between calls).
    static SCRATCH: std::cell::RefCell<RegionScratch> = std::cell::RefCell::new(RegionScratch::new());
}

/// One matching pass over `order` (Bangay & Morkel §3.3, §3.4): each vertex
/// in turn is matched against `images` and coloured (with its region, when
/// graph cut is on), reading and writing `state`. Vertices a cut of this
/// pass already coloured are skipped (that is where the transfer saves
/// matching work). `seed` only picks the texel of a vertex that has no
/// coloured region vertex at all (the start of growth).
///
/// Vertices whose k-regions are disjoint neither read nor write each
/// other's colours, so they are matched in parallel batches of pairwise
/// disjoint regions, formed as `rule` allows; regions are planned ahead in
/// parallel. The result equals processing the (possibly permuted, see
/// [`BatchRule`]) order one vertex at a time — except the occurrence counts
/// of `spread`, which advance once per batch — and does not depend on the
/// thread count.
///
/// Preconditions: `state` and `level` describe the same vertices; `images`
/// has `state.channels` channels; settings in their documented ranges.
pub fn match_pass(
    level: &LevelMesh,
    images: &MatchImages,
    settings: &GraphMatchSettings,
    order: &[u32],
    rule: BatchRule,
    seed: u64,
    state: &mut SynthesisState,
) -> PassStats {
    match_pass_with_progress(
        level,
        images,
        settings,
        order,
        rule,
        seed,
        state,
        &Progress::hidden(),
    )
}

/// The work of one pass per vertex, for progress, in region vertices.
/// Without graph cut each vertex is matched over its region, the
/// `(k + 1)² + k²` vertices `k_region` builds at a vertex whose edges
/// average `mean_edge` (Bangay & Morkel §3.3.2). Measured on the bunny
/// (`configs/41_…`, `k` from 2 to 14): 15–22, 43–47, 100–177, 165–265 and
/// 553–735 µs per vertex (two runs) for 18, 42, 163, 198 and 471
/// comparisons per vertex, a comparison costing more in a larger region
/// (the finest level 2.8–3.4 times the next for 2.4 times the
/// comparisons): the work is `R^1.2` for a region of `R` vertices (`R`
/// gave ETAs 0.6× the real time left, `R^1.4` 1.3–1.7×). With
/// graph cut a match colours its region and the vertices it covers are
/// skipped, so larger regions mean fewer, larger matches, but the finer
/// levels still cost more per vertex (`configs/23_…` at texture scale 0.15:
/// 6.7, 8.6 and 13.8 µs per vertex on levels 3, 1 and 0, whose matches
/// compare 209 and 358 region vertices on levels 1 and 0): the work is
/// `R^0.5` per vertex (1 per vertex gave ETAs 0.5× the time left there;
/// `R^0.5` 0.77–1.13×, and 0.69–1.37× on the eight and the fandisk; how it is
/// spread over a pass: [`pass_fraction`]).
pub fn pass_work_per_vertex(
    images: &MatchImages,
    settings: &GraphMatchSettings,
    mean_edge: f32,
) -> f64 {
    let l = images.level_for(settings.r_scale * mean_edge);
    let k = region_k(
        settings.region_texels,
        images.level_factor(l),
        settings.r_scale,
        mean_edge,
        settings.k_min,
        settings.k_max,
    );
    let k = if settings.graph_cut {
        k.max(MIN_CUT_K)
    } else {
        k
    };
    let r = f64::from((k + 1) * (k + 1) + k * k);
    if settings.graph_cut {
        r.sqrt()
    } else {
        r.powf(1.2)
    }
}

/// The share of a pass's work done after `planned` of its `total` vertices
/// (in its order) were planned while `covered` of all vertices were
/// coloured by another vertex's cut.
///
/// With cuts, a vertex is matched only if no cut covered it first, and a
/// match covers about `a` more vertices times the share still uncovered: in
/// a random order the uncovered share after a share `x` of the order is
/// `1 / (1 + a·x)` and the matches so far (the work) are `ln(1 + a·x) / a`,
/// so the share of the pass's work done is `ln(1 + a·x) / ln(1 + a)`. `a`
/// is read off the coverage so far (`c = a·x / (1 + a·x)`). On the bunny's
/// finest level (176 k vertices, `a` ≈ 1000) half the pass's time goes to
/// the first 4 % of its order. Without cuts nothing is covered and the
/// share is `x`.
pub fn pass_fraction(planned: usize, total: usize, covered: usize) -> f64 {
    if total == 0 {
        return 1.0;
    }
    let x = (planned as f64 / total as f64).clamp(0.0, 1.0);
    let c = (covered as f64 / total as f64).clamp(0.0, 0.999_999);
    if x <= 0.0 || c <= 0.0 {
        return x;
    }
    let a = c / ((1.0 - c) * x);
    ((a * x).ln_1p() / a.ln_1p()).clamp(0.0, 1.0)
}

/// [`match_pass`], reporting to `progress` as the pass's vertices are
/// planned (at most a planning chunk ahead of the colouring): the current
/// part's length is set to the order's length and its position to the share
/// of the pass's work done ([`pass_fraction`]), so a pass whose cuts leave
/// most of its order covered does not look stalled at its start and done
/// at its end.
#[allow(clippy::too_many_arguments)]
pub fn match_pass_with_progress(
    level: &LevelMesh,
    images: &MatchImages,
    settings: &GraphMatchSettings,
    order: &[u32],
    rule: BatchRule,
    seed: u64,
    state: &mut SynthesisState,
    progress: &Progress,
) -> PassStats {
    let _span = tracing::debug_span!("match_pass", vertices = order.len()).entered();
    let n = level.positions.len();
    let mut stats = PassStats::default();
    let mut covered = vec![false; n];
    let mut batch_mark = vec![0u32; n];
    let mut batch_id = 0u32;
    let mut batch: Vec<Planned> = Vec::with_capacity(MAX_BATCH);
    let mut pending: std::collections::VecDeque<Planned> = std::collections::VecDeque::new();
    let mut kept: std::collections::VecDeque<Planned> = std::collections::VecDeque::new();
    let mut next = 0usize;
    // Vertices coloured by another vertex's cut, and the position reported.
    let mut covered_count = 0usize;
    let mut reported = 0u64;
    progress.set_length(order.len() as u64);
    let mut occupancy = (settings.spread > 0.0 && settings.candidates == Candidates::Coherent)
        .then(|| {
            // The level's mean edge and mean squared edge in texels, one pass.
            let (edge, squared) = level.mean_edge.iter().fold((0.0f64, 0.0f64), |(a, b), &e| {
                let t = (settings.r_scale * e) as f64;
                (a + e as f64, b + t * t)
            });
            let texels_per_vertex = squared / n.max(1) as f64;
            let edge = edge / n.max(1) as f64;
            // Half the region's side, in level-0 texels: the region is in
            // texels of the level the level's typical vertex matches on.
            let factor = images.level_factor(images.level_for(settings.r_scale * edge as f32));
            Occupancy::new(
                state,
                images,
                settings.region_texels / 2.0 * factor,
                texels_per_vertex as f32,
            )
        });
    loop {
        if pending.len() < MAX_BATCH && next < order.len() {
            let end = (next + PLAN_AHEAD).min(order.len());
            let chunk = &order[next..end];
            next = end;
            let planned: Vec<Planned> = chunk
                .par_iter()
                .with_min_len(16)
                .filter(|&&v| !covered[v as usize])
                .map(|&v| {
                    SCRATCH.with(|s| plan_vertex(level, images, settings, v, &mut s.borrow_mut()))
                })
                .collect();
            stats.covered_by_cuts += (chunk.len() - planned.len()) as u64;
            tracing::trace!(planned = next, covered = covered_count, "pass progress");
            let done = pass_fraction(next, order.len(), covered_count);
            reported = reported.max((done * order.len() as f64).round() as u64);
            progress.set_position(reported);
            pending.extend(planned);
        }
        if pending.is_empty() {
            if next >= order.len() {
                break;
            }
            continue;
        }
        batch_id += 1;
        while let Some(p) = pending.pop_front() {
            let centre = p.region.vertices[0] as usize;
            if covered[centre] {
                stats.covered_by_cuts += 1;
                continue;
            }
            let clash = p
                .region
                .vertices
                .iter()
                .any(|&w| batch_mark[w as usize] == batch_id);
            if clash || batch.len() == MAX_BATCH {
                match rule {
                    BatchRule::Exact => {
                        pending.push_front(p);
                        break;
                    }
                    BatchRule::Relaxed => {
                        kept.push_back(p);
                        if batch.len() == MAX_BATCH {
                            break;
                        }
                        continue;
                    }
                }
            }
            for &w in &p.region.vertices {
                batch_mark[w as usize] = batch_id;
            }
            batch.push(p);
        }
        // Deferred vertices go back to the front, in their order.
        while let Some(p) = kept.pop_back() {
            pending.push_front(p);
        }
        run_batch(
            level,
            images,
            settings,
            seed,
            state,
            &mut covered,
            &mut covered_count,
            &mut batch,
            &mut stats,
            occupancy.as_mut(),
        );
    }
    progress.set_position(order.len() as u64);
    stats
}

fn plan_vertex(
    level: &LevelMesh,
    images: &MatchImages,
    settings: &GraphMatchSettings,
    v: u32,
    scratch: &mut RegionScratch,
) -> Planned {
    let e = level.mean_edge[v as usize];
    let l = images.level_for(settings.r_scale * e);
    let factor = images.level_factor(l);
    let k = region_k(
        settings.region_texels,
        factor,
        settings.r_scale,
        e,
        settings.k_min,
        settings.k_max,
    );
    // A cut needs vertices between the target and the border ring: at k = 1
    // every region vertex but the target is on the border, tied to the
    // surface, and the transfer could never colour more than the target.
    let k = if settings.graph_cut {
        k.max(MIN_CUT_K)
    } else {
        k
    };
    let mut region = KRegion::default();
    k_region(
        level.positions,
        level.topo,
        level.frames,
        v,
        k,
        settings.r_scale / factor,
        settings.graph_cut,
        scratch,
        &mut region,
    );
    Planned { region, level: l }
}

#[allow(clippy::too_many_arguments)]
fn run_batch(
    level: &LevelMesh,
    images: &MatchImages,
    settings: &GraphMatchSettings,
    seed: u64,
    state: &mut SynthesisState,
    covered: &mut [bool],
    covered_count: &mut usize,
    batch: &mut Vec<Planned>,
    stats: &mut PassStats,
    mut occupancy: Option<&mut Occupancy>,
) {
    if batch.is_empty() {
        return;
    }
    let st: &SynthesisState = state;
    let occ: Option<&Occupancy> = occupancy.as_deref();
    let outcomes: Vec<Outcome> = if batch.len() == 1 {
        vec![match_vertex(
            level, images, settings, seed, st, &batch[0], true, occ,
        )]
    } else {
        batch
            .par_iter()
            .map(|p| match_vertex(level, images, settings, seed, st, p, false, occ))
            .collect()
    };
    let ch = state.channels;
    for (p, o) in batch.iter().zip(&outcomes) {
        let centre = p.region.vertices[0];
        for (i, &(w, texel, l)) in o.writes.iter().enumerate() {
            let wi = w as usize;
            if let Some(occ) = occupancy.as_deref_mut() {
                occ.moved(state.coloured[wi].then_some(state.texels[wi]), texel);
            }
            state.colours[wi * ch..(wi + 1) * ch].copy_from_slice(&o.colours[i * ch..(i + 1) * ch]);
            state.texels[wi] = texel;
            state.coloured[wi] = true;
            state.levels[wi] = l;
            if w != centre && !covered[wi] {
                covered[wi] = true;
                *covered_count += 1;
            }
        }
        *stats += o.stats;
    }
    stats.batches += 1;
    batch.clear();
}

/// Wraps (or clamps) a level-0 pixel coordinate into the exemplar.
fn wrap_texel(images: &MatchImages, t: Vec2) -> Vec2 {
    let img = images.image(0);
    let (w, h) = (img.width as f32, img.height as f32);
    match images.wrap() {
        Wrap::Repeat => Vec2::new(t.x.rem_euclid(w), t.y.rem_euclid(h)),
        Wrap::Clamp => Vec2::new(t.x.clamp(0.0, w), t.y.clamp(0.0, h)),
    }
}

#[allow(clippy::too_many_arguments)]
fn match_vertex(
    level: &LevelMesh,
    images: &MatchImages,
    settings: &GraphMatchSettings,
    seed: u64,
    state: &SynthesisState,
    planned: &Planned,
    parallel: bool,
    occupancy: Option<&Occupancy>,
) -> Outcome {
    let ch = state.channels;
    let region = &planned.region;
    let centre = region.vertices[0];
    let lp = planned.level;
    let factor = images.level_factor(lp);
    let pyramid = images.kind() == ImageLevels::Pyramid;
    // Per region vertex: the level of its own density (§3.3.4), which a
    // transferred colour is taken from.
    let levels: Vec<usize> = region
        .vertices
        .iter()
        .map(|&w| {
            if pyramid {
                lp
            } else {
                images.level_for(settings.r_scale * level.mean_edge[w as usize])
            }
        })
        .collect();
    let mut samples = Vec::with_capacity(region.len());
    let mut colours = Vec::with_capacity(region.len() * ch);
    for (i, &w) in region.vertices.iter().enumerate() {
        let wi = w as usize;
        if !state.coloured[wi] {
            continue;
        }
        // A colour is compared on the level it stands for.
        let l = if pyramid {
            lp
        } else {
            (state.levels[wi] as usize).min(images.levels() - 1)
        };
        let o = region.offset[i].round();
        samples.push(Sample {
            level: l as u32,
            offset: images.reduce_offset(l, [o.x as i32, o.y as i32]),
        });
        colours.extend_from_slice(&state.colours[w as usize * ch..(w as usize + 1) * ch]);
    }
    let mut stats = PassStats {
        matched: 1,
        comparisons_plain: samples.len() as u64,
        ..Default::default()
    };
    let mut groups = MatchGroups::new();
    groups.build(&samples, &colours, ch, settings.averaging);
    // Either way, count the terms averaging would leave (Table 1 reports both).
    stats.comparisons_averaged = if settings.averaging {
        groups.len() as u64
    } else {
        let mut distinct = samples.clone();
        distinct.sort_unstable();
        distinct.dedup();
        distinct.len() as u64
    };
    // Seeds for the pruning bound: where the centre and its coloured
    // neighbours came from, shifted by their offsets (Ashikhmin-style
    // coherent candidates). They only tighten the bound.
    let mut seeds: Vec<[i32; 2]> = Vec::new();
    for (i, &w) in region.vertices.iter().enumerate() {
        if region.depth[i] > 1 || !state.coloured[w as usize] {
            continue;
        }
        let t = state.texels[w as usize] / factor - region.offset[i];
        seeds.push([t.x.floor() as i32, t.y.floor() as i32]);
    }
    let coherent = if settings.candidates == Candidates::Coherent {
        coherent_candidates(images, lp, factor, region, state)
    } else {
        Vec::new()
    };
    let found = if coherent.is_empty() {
        best_match(images, lp, &groups, &seeds, parallel)
    } else {
        let here = state.coloured[centre as usize].then_some(state.texels[centre as usize]);
        best_candidate_with(
            images,
            lp,
            &groups,
            &coherent,
            1.0 + settings.jump_cost,
            occupancy.map_or(0.0, |_| settings.spread),
            |c| {
                occupancy.map_or(0.0, |o| {
                    o.load(
                        Vec2::new(c[0] as f32 + 0.5, c[1] as f32 + 0.5) * factor,
                        here,
                    )
                })
            },
        )
    };
    let q = match found {
        Some(b) => [b.x, b.y],
        None => {
            stats.random_starts = 1;
            let img = images.image(lp);
            let r = mix(seed, centre as u64, 0x5EED);
            [
                (((r >> 32) * img.width as u64) >> 32) as u32,
                (((r & 0xFFFF_FFFF) * img.height as u64) >> 32) as u32,
            ]
        }
    };
    let qc = Vec2::new(q[0] as f32 + 0.5, q[1] as f32 + 0.5);
    let mut writes = vec![(centre, wrap_texel(images, qc * factor), lp as u8)];
    let mut out_colours = images.image(lp).pixel(q[0], q[1]).to_vec();
    // Region vertices written so far (local ids).
    let mut written = vec![false; region.len()];
    written[0] = true;
    if settings.graph_cut && region.len() > 1 {
        let n = region.len();
        let mut texture = vec![0.0f32; n * ch];
        let mut surface = vec![0.0f32; n * ch];
        let mut coloured = vec![false; n];
        let mut border = vec![false; n];
        let mut distance = vec![0.0f32; n];
        let wrap = images.wrap();
        // Each region vertex reads the texel under it (nearest, as in
        // matching; bilinear samples would blur the copy) on the level of
        // its own density.
        let texel_of = |i: usize| {
            let o = region.offset[i].round();
            [q[0] as i64 + o.x as i64, q[1] as i64 + o.y as i64]
        };
        for (i, &w) in region.vertices.iter().enumerate() {
            let wi = w as usize;
            if i == 0 {
                texture[..ch].copy_from_slice(&out_colours);
            } else {
                let [x, y] = texel_of(i);
                texture[i * ch..(i + 1) * ch]
                    .copy_from_slice(images.image(levels[i]).texel(x, y, wrap));
            }
            surface[i * ch..(i + 1) * ch].copy_from_slice(&state.colours[wi * ch..(wi + 1) * ch]);
            coloured[i] = state.coloured[wi];
            border[i] = region.depth[i] == region.k;
            distance[i] = region.offset[i].length();
        }
        let edge_factor: Vec<f32> = if settings.density_invariant {
            region
                .edges
                .iter()
                .map(|&[a, b]| (region.offset[a as usize] - region.offset[b as usize]).length())
                .collect()
        } else {
            Vec::new()
        };
        let cut = graph_cut_transfer(
            &TransferRegion {
                channels: ch,
                edges: &region.edges,
                surface: &surface,
                texture: &texture,
                coloured: &coloured,
                border: &border,
                distance: &distance,
                target: 0,
                diameter: settings.region_texels,
                edge_factor: &edge_factor,
            },
            settings.cut_sigma,
        );
        let taken = cut.taken() as u64;
        stats.cuts = 1;
        stats.cut_vertices = taken;
        stats.cut_vertices_max = taken;
        stats.cut_cost = cut.cost;
        stats.cut_flow_gap = (cut.cost - cut.flow).abs();
        for i in 1..n {
            if cut.take_texture[i] {
                written[i] = true;
                let [x, y] = texel_of(i);
                let at = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                writes.push((
                    region.vertices[i],
                    wrap_texel(images, at * factor),
                    levels[i] as u8,
                ));
                out_colours.extend_from_slice(&texture[i * ch..(i + 1) * ch]);
            }
        }
    }
    if settings.density_invariant {
        for i in 1..region.len() {
            let o = region.offset[i];
            if written[i] || o.length() >= FOOTPRINT {
                continue;
            }
            // Within half a texel the texel under it is `q` itself (on its
            // own level); its coordinate is kept exactly.
            writes.push((
                region.vertices[i],
                wrap_texel(images, (qc + o) * factor),
                levels[i] as u8,
            ));
            out_colours.extend_from_slice(images.image(levels[i]).pixel(q[0], q[1]));
            stats.footprint_vertices += 1;
        }
    }
    Outcome {
        writes,
        colours: out_colours,
        stats,
    }
}

/// The k-coherent candidates of a region on level `lp` ([`Candidates::Coherent`]):
/// for every coloured region vertex within [`COHERENT_DEPTH`] edges, its
/// source texel and the texels most similar to it, each shifted back by the
/// vertex's offset; texels outside a clamped exemplar are dropped, a
/// repeating one wraps them. Distinct, in region order, each marked `true`
/// when it is a jump (a similar texel's shift, not a source's). Empty when
/// the level has no similarity sets or no such vertex is coloured.
fn coherent_candidates(
    images: &MatchImages,
    lp: usize,
    factor: f32,
    region: &KRegion,
    state: &SynthesisState,
) -> Vec<([u32; 2], bool)> {
    let Some(similar) = images.similar(lp) else {
        return Vec::new();
    };
    let img = images.image(lp);
    let (w, h) = (img.width as i64, img.height as i64);
    let repeat = images.wrap() == Wrap::Repeat;
    let admit = |x: i64, y: i64| -> Option<[u32; 2]> {
        if repeat {
            Some([x.rem_euclid(w) as u32, y.rem_euclid(h) as u32])
        } else if (0..w).contains(&x) && (0..h).contains(&y) {
            Some([x as u32, y as u32])
        } else {
            None
        }
    };
    let mut out: Vec<([u32; 2], bool)> = Vec::new();
    for (i, &v) in region.vertices.iter().enumerate() {
        if region.depth[i] > COHERENT_DEPTH || !state.coloured[v as usize] {
            continue;
        }
        let t = state.texels[v as usize] / factor;
        let Some([sx, sy]) = admit(t.x.floor() as i64, t.y.floor() as i64) else {
            continue;
        };
        let o = region.offset[i].round();
        let (ox, oy) = (o.x as i64, o.y as i64);
        let p = sy * w as u32 + sx;
        for (j, &s) in std::iter::once(&p).chain(similar.similar_of(p)).enumerate() {
            let (x, y) = ((s % w as u32) as i64, (s / w as u32) as i64);
            let Some(c) = admit(x - ox, y - oy) else {
                continue;
            };
            match out.iter_mut().find(|(o, _)| *o == c) {
                // A texel that is some vertex's shift is not a jump.
                Some(o) => o.1 &= j > 0,
                None => out.push((c, j > 0)),
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The share of a pass's work: linear without cuts; with cuts, the
    /// front-loaded `ln(1 + a·x) / ln(1 + a)`, from 0 to 1. On the bunny's
    /// finest level (`configs/23_…` at `texture_scale = 0.25`) 1.3 % of the
    /// order planned had 58 % of the vertices covered after 30 % of the
    /// pass's time: 0.19 of the work by this share, 0.013 by the order.
    #[test]
    fn pass_fraction_follows_the_coverage() {
        assert_eq!(pass_fraction(0, 100, 0), 0.0);
        assert_eq!(pass_fraction(25, 100, 0), 0.25);
        assert_eq!(pass_fraction(100, 100, 99), 1.0);
        assert_eq!(pass_fraction(0, 0, 0), 1.0);
        let n = 176_354;
        let f = pass_fraction(2_310, n, 102_530);
        assert!((0.17..0.21).contains(&f), "{f}");
        // More of the order planned at the same coverage is more of the work.
        assert!(pass_fraction(20_000, n, 102_530) > f);
        assert!(pass_fraction(4_620, n, 102_530) > pass_fraction(2_310, n, 102_530));
    }
    use crate::image::Image;

    #[test]
    fn occupancy_counts_use_beyond_an_even_share() {
        // A 32² exemplar in cells of 8: 16 cells.
        let img = Image::new(32, 32, 3);
        let images = MatchImages::new(&img, ImageLevels::Stack, 1, Wrap::Clamp);
        // 64 coloured vertices, all in the top-left cell; one uncoloured.
        let mut state = SynthesisState::uncoloured(65, 3);
        for v in 0..64 {
            state.texels[v] = Vec2::new(1.5, 2.5);
            state.coloured[v] = true;
        }
        // One texel² per vertex: a copy of a cell is 64 vertices, more than
        // the mean count (4), so that is the even share.
        let mut occ = Occupancy::new(&state, &images, 8.0, 1.0);
        assert_eq!(occ.0.expected, 64.0);
        let (tl, other) = (Vec2::new(3.0, 3.0), Vec2::new(20.0, 20.0));
        assert_eq!(occ.load(tl, None), 0.0);
        assert_eq!(occ.load(other, None), 0.0);
        // 64 more uses of the cell: one share over.
        for _ in 0..64 {
            occ.moved(None, tl);
        }
        assert_eq!(occ.load(tl, None), 1.0);
        // A vertex already there does not count itself.
        assert!(occ.load(tl, Some(tl)) < 1.0);
        // Moving uses out lowers it again.
        for _ in 0..64 {
            occ.moved(Some(tl), other);
        }
        assert_eq!(occ.load(tl, None), 0.0);
        // Sparse vertices (16 texels² each): the mean count is the share.
        let occ = Occupancy::new(&state, &images, 8.0, 16.0);
        assert_eq!(occ.0.expected, 4.0);
        assert_eq!(occ.load(tl, None), 15.0);
    }
}
