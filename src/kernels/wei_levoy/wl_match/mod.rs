//! Wei & Levoy 2001 surface texture synthesis over a mesh pyramid (Table 3):
//! multi-resolution mesh neighbourhoods built by flattening (§3.3), matched
//! against the exemplar's Gaussian pyramid, coarse to fine, two passes per
//! level in random vertex order (§3.2).
//!
//! # The algorithm
//!
//! Mesh level `L` (0 the finest) pairs with exemplar pyramid level `L`; one
//! exemplar pixel of level `L` corresponds to `d_L = √(2·A_L)` world units on
//! mesh level `L` (`A_L` its mean triangle area, [`template_spacing`]).
//! Neighbourhoods `{n×n, k}` are given from coarse to fine as in the paper,
//! e.g. `{1×1,1}, {3×3,2}, {5×5,2}, {7×7,2}`; the finest level takes the
//! last entry. A neighbourhood of level `L` reads `k` levels: an `n×n`
//! template on level `L` around the vertex, and on each coarser level
//! `L + j` a template of `2·⌈h/2^j⌉ + 1` points per side (`h = ⌊n/2⌋`, so it
//! spans at least the fine template) with spacing `d_{L+j}`, centred where
//! the vertex's normal line meets level `L + j` (the parent face; no hit
//! within `parent_reach · d_{L+j}` means default colours, footnote 2). All
//! templates lie in the vertex's tangent frame; each is filled by
//! flattening and resampling ([`crate::kernels::surface::flatten`]); uncovered points
//! take the mean colour of the exemplar level.
//!
//! Levels are synthesised from the coarsest. On each level:
//!
//! 1. Pass 1 searches with the coarser parts only (they do not change while
//!    the level is synthesised, so the vertices are independent and run in
//!    parallel). On the coarsest level, which has no coarser part, the
//!    vertices keep random exemplar pixels instead.
//! 2. Pass 2 searches with the whole neighbourhood, visiting the vertices in
//!    a random order; each vertex sees the colours its predecessors wrote.
//!    The order runs as a sequence of batches of mutually independent
//!    vertices ([`schedule`]), which gives exactly the sequential result.
//!
//! Each vertex takes the colour of the best exemplar pixel and remembers the
//! pixel. The search back-end is chosen by [`SearchKind`].

pub mod features;
pub mod parents;
pub mod schedule;
pub mod search;

use crate::kernels::mix;
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;

use self::features::{Part, exemplar_features};
use self::parents::TriangleBvh;
pub use self::search::SearchKind;
use self::search::{Match, build_search};
use crate::image::{Image, pyramid::gaussian_pyramid, sample::Wrap};
use crate::kernels::surface::flatten::{
    FlattenScratch, PatchSeed, ScratchPool, StencilPoint, Template, TriangleAdjacency,
    flatten_stencil, resample_stencil, template_spacing,
};
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::PolyMesh;
use crate::progress::{Progress, level_label};

/// A neighbourhood `{size×size, levels}` (Wei & Levoy Table 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NeighbourhoodSpec {
    /// Template points per side on the synthesised level; odd, ≥ 1.
    pub size: u32,
    /// Pyramid levels the neighbourhood reads (the synthesised one and
    /// `levels − 1` coarser ones), ≥ 1.
    pub levels: u32,
}

/// The paper's neighbourhoods, coarse to fine (§4).
pub const PAPER_NEIGHBOURHOODS: [NeighbourhoodSpec; 4] = [
    NeighbourhoodSpec { size: 1, levels: 1 },
    NeighbourhoodSpec { size: 3, levels: 2 },
    NeighbourhoodSpec { size: 5, levels: 2 },
    NeighbourhoodSpec { size: 7, levels: 2 },
];

/// Settings of [`wei_levoy_synthesis`].
#[derive(Clone, Debug, PartialEq)]
pub struct WlSettings {
    /// Neighbourhoods from the coarsest level to the finest; the finest mesh
    /// level takes the last entry, levels beyond the list's length the first.
    pub neighbourhoods: Vec<NeighbourhoodSpec>,
    /// The search back-end.
    pub search: SearchKind,
    /// 2: both passes (paper); 1: only the pass with the whole neighbourhood.
    pub passes: u32,
    /// Seed of the random pixels and orders.
    pub seed: u64,
    /// How exemplar pixels outside the image are addressed.
    pub wrap: Wrap,
    /// How far along the normal a parent face may be, in template spacings
    /// of the coarser level; > 0.
    pub parent_reach: f32,
    /// Most bytes of a level's flattened pass-2 stencils kept from its
    /// schedule for its queries ([`STORED_STENCIL_BYTES`] by default); a
    /// level whose stencils take more flattens each again for its query.
    /// The result is the same either way.
    pub stencil_budget: u64,
}

impl Default for WlSettings {
    fn default() -> Self {
        Self {
            neighbourhoods: PAPER_NEIGHBOURHOODS.to_vec(),
            search: SearchKind::Exhaustive,
            passes: 2,
            seed: 0,
            wrap: Wrap::Repeat,
            parent_reach: 4.0,
            stencil_budget: STORED_STENCIL_BYTES,
        }
    }
}

/// One mesh level to synthesise on.
#[derive(Clone, Copy, Debug)]
pub struct SynthesisLevel<'a> {
    /// The level's mesh (any polygons; they are fan-triangulated).
    pub mesh: &'a PolyMesh,
    /// One tangent frame per vertex.
    pub frames: &'a [TangentFrame],
}

/// Colours and exemplar pixels to start the coarsest level from.
#[derive(Clone, Copy, Debug)]
pub struct InitialColours<'a> {
    /// `channels` values per vertex.
    pub values: &'a [f32],
    /// The exemplar pixel `(x, y)` of the coarsest exemplar level each came from.
    pub texels: &'a [[u32; 2]],
}

/// What happened on one level.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct LevelReport {
    /// Pyramid level (0 finest).
    pub level: usize,
    /// Vertices synthesised.
    pub vertices: usize,
    /// Template spacing `d = √(2A)` in world units.
    pub spacing: f32,
    /// Neighbourhood `[size, levels]` used (levels clamped to the pyramid).
    pub neighbourhood: [u32; 2],
    /// Values compared per neighbourhood in pass 1 and pass 2.
    pub dims: [usize; 2],
    /// Mean over vertices of the squared match distance per value, pass 1
    /// and pass 2 (`None` for a pass not run).
    pub mean_distance: [Option<f32>; 2],
    /// Batches pass 2 ran in.
    pub batches: usize,
    /// Fraction of level-`L` template points no flattened triangle covered.
    pub uncovered: f32,
    /// Coarser-level parent lookups whose normal met nothing.
    pub parent_misses: usize,
    /// Query × exemplar vector × value products an exhaustive search does
    /// (the same count for any back-end, for comparison).
    pub exhaustive_values: u64,
    /// Wall time of the searches, seconds.
    pub search_seconds: f64,
    /// Wall time of flattening and resampling, seconds.
    pub flatten_seconds: f64,
}

/// The result on one level.
#[derive(Clone, Debug, Default)]
pub struct LevelResult {
    /// `channels` values per vertex.
    pub colours: Vec<f32>,
    /// The exemplar pixel `(x, y)` of the same pyramid level each vertex took.
    pub texels: Vec<[u32; 2]>,
    /// Statistics.
    pub report: LevelReport,
}

/// Bad input to [`wei_levoy_synthesis`].
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum WlError {
    /// No mesh level was given.
    #[error("no mesh levels to synthesise on")]
    NoLevels,
    /// A level has no triangles.
    #[error("mesh level {level} has no faces")]
    NoFaces {
        /// The level.
        level: usize,
    },
    /// Frames and vertices differ in number.
    #[error("mesh level {level} has {frames} frames for {vertices} vertices")]
    FrameCount {
        /// The level.
        level: usize,
        /// Frames given.
        frames: usize,
        /// Vertices of the level.
        vertices: usize,
    },
    /// Starting coordinates and finest-level vertices differ in number.
    #[error("{given} starting coordinates for {vertices} vertices of the finest level")]
    StartCount {
        /// Coordinates given.
        given: usize,
        /// Vertices of the finest level.
        vertices: usize,
    },
    /// A neighbourhood entry is out of range.
    #[error(
        "neighbourhood {index} = [{size}, {levels}] is not allowed: size must be odd in 1..=31 and levels in 1..=8"
    )]
    Neighbourhood {
        /// Entry index (0 = coarsest).
        index: usize,
        /// Its size.
        size: u32,
        /// Its level count.
        levels: u32,
    },
    /// The neighbourhood list is empty.
    #[error("the neighbourhood list is empty")]
    NoNeighbourhoods,
    /// The exemplar has no pixels.
    #[error("the exemplar has no pixels")]
    EmptyExemplar,
}

/// Everything about one mesh level that does not change during synthesis.
struct LevelGeometry {
    adjacency: TriangleAdjacency,
    spacing: f32,
    bvh: Option<TriangleBvh>,
    /// Default colour of uncovered template points: the exemplar level's mean.
    default: Vec<f32>,
}

/// Queries per parallel task in pass 1, fixed so results do not depend on
/// the thread count.
const PASS1_CHUNK: usize = 64;
/// Vertices per parallel flattening task (each task makes one scratch).
const FLATTEN_CHUNK: usize = 256;
/// Queries per parallel task within a pass-2 batch.
const PASS2_CHUNK: usize = 64;
/// Per chunk of [`FLATTEN_CHUNK`] vertices: the vertices each reads (one
/// flat list and each vertex's start in it) and its uncovered stencil
/// points.
type ReadLists = (Vec<u32>, Vec<u32>, usize);

/// Most bytes of flattened pass-2 stencils kept from the schedule for the
/// queries ([`stored_stencil_bytes`]); a level whose stencils take more
/// flattens each again when its query is built (the same stencil: the
/// flattening is deterministic).
pub const STORED_STENCIL_BYTES: u64 = 256 << 20;

/// Bytes of the pass-2 stencils of `vertices` vertices with `points`
/// template points each that a level keeps, 0 when they exceed `budget`
/// (then none is kept; the default budget is [`STORED_STENCIL_BYTES`]).
pub fn stored_stencil_bytes(vertices: u64, points: u64, budget: u64) -> u64 {
    let bytes = vertices
        .saturating_mul(points)
        .saturating_mul(std::mem::size_of::<StencilPoint>() as u64);
    if bytes <= budget { bytes } else { 0 }
}

/// The parts of a level's neighbourhood: the level itself, then each coarser level.
pub fn neighbourhood_parts(spec: NeighbourhoodSpec, available_levels: usize) -> Vec<Part> {
    let k = (spec.levels as usize).min(available_levels).max(1);
    let h = spec.size / 2;
    (0..k as u32)
        .map(|j| Part {
            level_offset: j,
            size: if j == 0 {
                spec.size
            } else {
                2 * h.div_ceil(1 << j) + 1
            },
        })
        .collect()
}

/// Bytes the exemplar side of the finest level's search holds for an
/// exemplar of `pixels` pixels of `channels` channels: the neighbourhood
/// vectors of every pixel (`4·dim` bytes, `dim` from the finest
/// neighbourhood `spec`) and the search structure: the augmented copy
/// (exhaustive, `4·(dim + 1)` a pixel), the tree's codewords (tsvq, about
/// one more copy) or the PCA fit on at most 4096 rows with the projected
/// points of the kd-tree (pca_kdtree). The coarser levels' are smaller
/// and freed before it.
pub fn search_bytes(
    pixels: u64,
    channels: u32,
    spec: NeighbourhoodSpec,
    search: &SearchKind,
) -> u64 {
    let dim: u64 = neighbourhood_parts(spec, spec.levels as usize)
        .iter()
        .map(|p| p.values(channels as usize) as u64)
        .sum();
    let vectors = pixels * dim * 4;
    let structure = match search {
        SearchKind::Exhaustive => pixels * (dim + 1) * 4,
        SearchKind::Tsvq { .. } => pixels * dim * 4,
        SearchKind::PcaKdTree { .. } => {
            let sample = pixels.min(search::pca_kdtree::SAMPLE as u64);
            crate::kernels::jump_maps::jump_map::pca::fit_bytes(sample as usize, dim as usize)
                + pixels * (search::pca_kdtree::TREE_DIMS as u64 * 4 + 8)
        }
    };
    vectors + structure
}

/// The neighbourhood of level `level` out of `levels`.
fn spec_for(settings: &WlSettings, level: usize) -> NeighbourhoodSpec {
    let n = settings.neighbourhoods.len();
    if level < n {
        settings.neighbourhoods[n - 1 - level]
    } else {
        settings.neighbourhoods[0]
    }
}

/// Synthesises colours on every level of a mesh pyramid (`levels[0]` the
/// finest) from `exemplar` (Wei & Levoy 2001 Table 3; see the module docs).
/// `initial` seeds the coarsest level (random pixels of the coarsest
/// exemplar level, e.g. from `init_colours`); without it, the coarsest level
/// draws its own random pixels.
///
/// Results are identical for any thread count. Returns one [`LevelResult`]
/// per level, finest first.
///
/// # Errors
/// [`WlError`] for missing levels, faces or frames, bad neighbourhoods or an
/// empty exemplar.
pub fn wei_levoy_synthesis(
    levels: &[SynthesisLevel],
    exemplar: &Image,
    settings: &WlSettings,
    initial: Option<InitialColours>,
) -> Result<Vec<LevelResult>, WlError> {
    wei_levoy_synthesis_with_progress(levels, exemplar, settings, initial, &Progress::hidden())
}

/// [`wei_levoy_synthesis`], reporting to `progress`: two steps per vertex
/// and level (pass 1, then pass 2 batch by batch), each level a part
/// (`"level 1/3"`, coarsest first).
///
/// # Errors
/// As [`wei_levoy_synthesis`].
pub fn wei_levoy_synthesis_with_progress(
    levels: &[SynthesisLevel],
    exemplar: &Image,
    settings: &WlSettings,
    initial: Option<InitialColours>,
    progress: &Progress,
) -> Result<Vec<LevelResult>, WlError> {
    validate(levels, exemplar, settings)?;
    let count = levels.len();
    progress.set_length(
        levels
            .iter()
            .map(|l| 2 * l.mesh.vertex_count() as u64)
            .sum(),
    );
    let ch = exemplar.channels as usize;
    let pyramid = gaussian_pyramid(exemplar, count, settings.wrap);
    // Every colour a query holds is a convex combination of pyramid pixels
    // (or a level's mean), so it lies in the pyramid's range of values.
    let range = pyramid
        .iter()
        .flat_map(|img| img.data.iter().copied())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        });
    let geometry: Vec<LevelGeometry> = levels
        .iter()
        .enumerate()
        .map(|(l, lv)| {
            let adjacency = TriangleAdjacency::new(lv.mesh);
            let spacing = template_spacing(adjacency.mean_triangle_area(&lv.mesh.positions))
                .max(f32::MIN_POSITIVE);
            let bvh = (l > 0).then(|| TriangleBvh::new(&adjacency, &lv.mesh.positions));
            LevelGeometry {
                adjacency,
                spacing,
                bvh,
                default: pyramid[l].mean(),
            }
        })
        .collect();

    let mut results: Vec<LevelResult> = vec![LevelResult::default(); count];
    for l in (0..count).rev() {
        let _span = tracing::info_span!("wl_level", level = l).entered();
        progress.set_part(&level_label(l, count));
        let level = &levels[l];
        let geo = &geometry[l];
        let nv = level.mesh.vertex_count();
        let spec = spec_for(settings, l);
        let parts = neighbourhood_parts(spec, count - l);
        let mut report = LevelReport {
            level: l,
            vertices: nv,
            spacing: geo.spacing,
            neighbourhood: [spec.size, parts.len() as u32],
            ..Default::default()
        };
        let img = &pyramid[l];

        // Start from random exemplar pixels of this level.
        let (mut colours, mut texels) = match initial {
            Some(init)
                if l == count - 1 && init.values.len() == nv * ch && init.texels.len() == nv =>
            {
                (init.values.to_vec(), init.texels.to_vec())
            }
            _ => random_pixels(img, nv, settings.seed, l as u64),
        };

        // The coarser parts of every vertex's neighbourhood.
        let started = Instant::now();
        let coarse_parts = &parts[1..];
        let coarse_dim: usize = coarse_parts.iter().map(|p| p.values(ch)).sum();
        let coarse_span = tracing::info_span!("wl_coarse_parts", level = l).entered();
        let (coarse, misses) = coarse_queries(
            levels,
            &geometry,
            &results,
            l,
            coarse_parts,
            ch,
            settings.parent_reach,
            range,
        );
        drop(coarse_span);
        report.parent_misses = misses;
        report.flatten_seconds += started.elapsed().as_secs_f64();

        // Pass 1: coarser levels only.
        if coarse_dim > 0 && settings.passes >= 2 {
            let _span = tracing::info_span!("wl_pass1", level = l).entered();
            let db = exemplar_features(&pyramid, l, coarse_parts, settings.wrap);
            let search = build_search(settings.search, db, mix(settings.seed, l as u64, 11));
            let started = Instant::now();
            let mut matches = vec![NO_MATCH; nv];
            matches
                .par_chunks_mut(PASS1_CHUNK)
                .enumerate()
                .for_each_init(Vec::new, |q, (c, out)| {
                    // This chunk's rows, back as values, in a buffer each
                    // worker reuses.
                    q.clear();
                    q.resize(out.len() * coarse_dim, 0.0f32);
                    for (i, row) in q.chunks_exact_mut(coarse_dim).enumerate() {
                        coarse.row_into(c * PASS1_CHUNK + i, row);
                    }
                    search.search(q, out);
                    progress.inc(out.len() as u64);
                });
            report.search_seconds += started.elapsed().as_secs_f64();
            report.exhaustive_values += (nv * search.len() * coarse_dim) as u64;
            report.dims[0] = coarse_dim;
            report.mean_distance[0] = Some(mean_distance(&matches, coarse_dim));
            for (v, m) in matches.iter().enumerate() {
                assign(img, *m, &mut colours[v * ch..(v + 1) * ch], &mut texels[v]);
            }
        } else {
            progress.inc(nv as u64);
        }

        // Pass 2: the whole neighbourhood, in random order.
        {
            let _span = tracing::info_span!("wl_pass2", level = l).entered();
            let started = Instant::now();
            let size = parts[0].size;
            let template = Template {
                size,
                spacing: geo.spacing,
            };
            let tp = template.points();
            let stencil_span = tracing::info_span!("wl_stencils", level = l).entered();
            // The stencils are flattened here to find which vertices each
            // vertex reads, and kept for the queries when they fit the
            // settings' `stencil_budget` (STORED_STENCIL_BYTES by default;
            // `points × 24` bytes per vertex, 1.2 KB for 7 × 7); otherwise
            // flattened again when a query is built.
            let store = stored_stencil_bytes(nv as u64, tp as u64, settings.stencil_budget) > 0;
            let pool = ScratchPool::new();
            let stencil_of = |v: usize, st: &mut [StencilPoint], scratch: &mut FlattenScratch| {
                flatten_stencil(
                    &geo.adjacency,
                    &level.mesh.positions,
                    PatchSeed::Vertex(v as u32),
                    &level.frames[v],
                    template,
                    st,
                    scratch,
                )
            };
            // Which vertices each vertex reads (covered stencil vertices):
            // per fixed chunk of vertices, one flat list and each vertex's
            // offsets into it, read in place. (Copied into one list they
            // were held twice at the level's peak: ~230 bytes per vertex.)
            let (chunks, stored): (Vec<ReadLists>, Vec<Vec<StencilPoint>>) = (0..nv
                .div_ceil(FLATTEN_CHUNK))
                .into_par_iter()
                .map(|c| {
                    let vs = c * FLATTEN_CHUNK..((c + 1) * FLATTEN_CHUNK).min(nv);
                    pool.with(|scratch| {
                        let mut st = vec![StencilPoint::UNCOVERED; tp];
                        let mut kept = Vec::with_capacity(if store { vs.len() * tp } else { 0 });
                        let mut flat = Vec::with_capacity(vs.len() * tp);
                        let mut starts = Vec::with_capacity(vs.len() + 1);
                        starts.push(0u32);
                        let mut one: Vec<u32> = Vec::with_capacity(3 * tp);
                        let mut uncovered = 0;
                        for v in vs {
                            uncovered += tp - stencil_of(v, &mut st, scratch).covered;
                            if store {
                                kept.extend_from_slice(&st);
                            }
                            one.clear();
                            for s in st.iter().filter(|s| s.is_covered()) {
                                for k in 0..3 {
                                    if s.weights[k] != 0.0 {
                                        one.push(s.vertices[k]);
                                    }
                                }
                            }
                            one.sort_unstable();
                            one.dedup();
                            flat.extend_from_slice(&one);
                            starts.push(flat.len() as u32);
                        }
                        flat.shrink_to_fit();
                        ((flat, starts, uncovered), kept)
                    })
                })
                .unzip();
            drop(stencil_span);
            let schedule_span = tracing::info_span!("wl_schedule", level = l).entered();
            let uncovered: usize = chunks.iter().map(|c| c.2).sum();
            report.uncovered = uncovered as f32 / (nv * tp).max(1) as f32;
            let order = schedule::random_order(nv, mix(settings.seed, l as u64, 2));
            let batches = schedule::dependency_batches(&order, |v| {
                let (flat, starts, _) = &chunks[v as usize / FLATTEN_CHUNK];
                let i = v as usize % FLATTEN_CHUNK;
                &flat[starts[i] as usize..starts[i + 1] as usize]
            });
            drop(chunks);
            report.batches = batches.len();
            report.flatten_seconds += started.elapsed().as_secs_f64();
            drop(schedule_span);

            let db = exemplar_features(&pyramid, l, &parts, settings.wrap);
            let search = build_search(settings.search, db, mix(settings.seed, l as u64, 12));
            let dim = search.dim();
            let fine_dim = parts[0].values(ch);
            let mut all = vec![NO_MATCH; nv];
            let mut search_seconds = 0.0;
            for batch in &batches {
                let t0 = Instant::now();
                let found: Vec<(u32, Match)> = batch
                    .par_chunks(PASS2_CHUNK)
                    .flat_map_iter(|vs| {
                        let mut q = vec![0.0f32; vs.len() * dim];
                        let mut st = vec![StencilPoint::UNCOVERED; tp];
                        pool.with(|scratch| {
                            for (&v, row) in vs.iter().zip(q.chunks_exact_mut(dim)) {
                                let v = v as usize;
                                let points = if store {
                                    let c = &stored[v / FLATTEN_CHUNK];
                                    &c[v % FLATTEN_CHUNK * tp..][..tp]
                                } else {
                                    stencil_of(v, &mut st, scratch);
                                    &st[..]
                                };
                                resample_stencil(
                                    points,
                                    &colours,
                                    ch,
                                    &geo.default,
                                    &mut row[..fine_dim],
                                );
                                coarse.row_into(v, &mut row[fine_dim..]);
                            }
                        });
                        let mut out = vec![NO_MATCH; vs.len()];
                        search.search(&q, &mut out);
                        vs.iter().copied().zip(out).collect::<Vec<_>>()
                    })
                    .collect();
                search_seconds += t0.elapsed().as_secs_f64();
                progress.inc(batch.len() as u64);
                for (v, m) in found {
                    let v = v as usize;
                    all[v] = m;
                    assign(img, m, &mut colours[v * ch..(v + 1) * ch], &mut texels[v]);
                }
            }
            report.search_seconds += search_seconds;
            report.exhaustive_values += (nv * search.len() * dim) as u64;
            report.dims[1] = dim;
            report.mean_distance[1] = Some(mean_distance(&all, dim));
        }
        tracing::debug!(?report, "wei-levoy level done");
        results[l] = LevelResult {
            colours,
            texels,
            report,
        };
    }
    Ok(results)
}

const NO_MATCH: Match = Match {
    index: 0,
    distance: 0.0,
};

fn validate(
    levels: &[SynthesisLevel],
    exemplar: &Image,
    settings: &WlSettings,
) -> Result<(), WlError> {
    if levels.is_empty() {
        return Err(WlError::NoLevels);
    }
    if exemplar.pixel_count() == 0 || exemplar.channels == 0 {
        return Err(WlError::EmptyExemplar);
    }
    if settings.neighbourhoods.is_empty() {
        return Err(WlError::NoNeighbourhoods);
    }
    for (index, s) in settings.neighbourhoods.iter().enumerate() {
        if s.size % 2 == 0 || !(1..=31).contains(&s.size) || !(1..=8).contains(&s.levels) {
            return Err(WlError::Neighbourhood {
                index,
                size: s.size,
                levels: s.levels,
            });
        }
    }
    validate_levels(levels)
}

/// Every level has faces and one frame per vertex.
pub(crate) fn validate_levels(levels: &[SynthesisLevel]) -> Result<(), WlError> {
    for (level, lv) in levels.iter().enumerate() {
        if lv.mesh.face_count() == 0 {
            return Err(WlError::NoFaces { level });
        }
        if lv.frames.len() != lv.mesh.vertex_count() {
            return Err(WlError::FrameCount {
                level,
                frames: lv.frames.len(),
                vertices: lv.mesh.vertex_count(),
            });
        }
    }
    Ok(())
}

/// Random pixels of `img` for `count` vertices; vertex `v` of level `level`
/// draws from its own stream.
fn random_pixels(img: &Image, count: usize, seed: u64, level: u64) -> (Vec<f32>, Vec<[u32; 2]>) {
    let ch = img.channels as usize;
    let (w, h) = (img.width as u64, img.height as u64);
    let mut colours = vec![0.0f32; count * ch];
    let mut texels = vec![[0u32; 2]; count];
    for v in 0..count {
        let r = mix(seed, level, (v as u64) << 8 | 1);
        let x = (((r >> 32) * w) >> 32) as u32;
        let y = (((r & 0xFFFF_FFFF) * h) >> 32) as u32;
        colours[v * ch..(v + 1) * ch].copy_from_slice(img.pixel(x, y));
        texels[v] = [x, y];
    }
    (colours, texels)
}

#[inline]
fn assign(img: &Image, m: Match, colour: &mut [f32], texel: &mut [u32; 2]) {
    let (x, y) = (m.index % img.width, m.index / img.width);
    colour.copy_from_slice(img.pixel(x, y));
    *texel = [x, y];
}

fn mean_distance(matches: &[Match], dim: usize) -> f32 {
    if matches.is_empty() || dim == 0 {
        return 0.0;
    }
    let sum: f64 = matches.iter().map(|m| m.distance as f64).sum();
    (sum / (matches.len() * dim) as f64) as f32
}

/// The coarser parts of every vertex's query, stored as 16-bit steps of
/// the exemplar pyramid's value range: half the bytes of `f32` rows (the
/// largest array of the match stage on dense meshes, ~150 instead of ~300
/// bytes per vertex with the paper's neighbourhoods), read back within half
/// a step (`(hi − lo) / 131 070`, below 1e-5 for 8-bit images, 1/500 of an
/// 8-bit grey level).
struct CoarseRows {
    values: Vec<u16>,
    dim: usize,
    lo: f32,
    step: f32,
}

impl CoarseRows {
    fn new(nv: usize, dim: usize, (lo, hi): (f32, f32)) -> Self {
        // A flat (or unknown) range still gets a step around its value.
        let (lo, hi) = match (lo.is_finite(), hi.is_finite()) {
            (true, true) if (hi - lo) / u16::MAX as f32 > 0.0 => (lo, hi),
            (true, _) => (lo - 0.5, lo + 0.5),
            _ => (0.0, 1.0),
        };
        Self {
            values: vec![0; nv * dim],
            dim,
            lo,
            step: (hi - lo) / u16::MAX as f32,
        }
    }

    fn quantise(&self, x: f32) -> u16 {
        ((x - self.lo) / self.step)
            .round()
            .clamp(0.0, u16::MAX as f32) as u16
    }

    /// Vertex `v`'s row, as values.
    fn row_into(&self, v: usize, out: &mut [f32]) {
        debug_assert_eq!(out.len(), self.dim);
        let row = &self.values[v * self.dim..(v + 1) * self.dim];
        for (o, &q) in out.iter_mut().zip(row) {
            *o = self.lo + q as f32 * self.step;
        }
    }
}

/// The coarser parts of every vertex of level `l`: where its normal meets
/// each coarser level, a flattened, resampled template of that level's
/// (already synthesised) colours. Returns the rows (the parts' total size
/// each; values in `range`) and the number of parent lookups that met
/// nothing.
#[allow(clippy::too_many_arguments)]
fn coarse_queries(
    levels: &[SynthesisLevel],
    geometry: &[LevelGeometry],
    results: &[LevelResult],
    l: usize,
    parts: &[Part],
    ch: usize,
    reach: f32,
    range: (f32, f32),
) -> (CoarseRows, usize) {
    let dim: usize = parts.iter().map(|p| p.values(ch)).sum();
    let nv = levels[l].mesh.vertex_count();
    let mut out = CoarseRows::new(nv, dim, range);
    if dim == 0 {
        return (out, 0);
    }
    // Scratches shared by the chunks (see `ScratchPool`).
    let pool = ScratchPool::new();
    let mut values = std::mem::take(&mut out.values);
    let misses: usize = values
        .par_chunks_mut(dim * FLATTEN_CHUNK)
        .enumerate()
        .map(|(c, rows)| {
            pool.with(|scratch| {
                let mut stencil = Vec::<StencilPoint>::new();
                let mut row = vec![0.0f32; dim];
                let mut misses = 0;
                for (i, dst) in rows.chunks_exact_mut(dim).enumerate() {
                    misses += coarse_row(
                        levels,
                        geometry,
                        results,
                        l,
                        parts,
                        ch,
                        reach,
                        c * FLATTEN_CHUNK + i,
                        &mut row,
                        scratch,
                        &mut stencil,
                    );
                    for (d, &x) in dst.iter_mut().zip(&row) {
                        *d = out.quantise(x);
                    }
                }
                misses
            })
        })
        .sum();
    out.values = values;
    (out, misses)
}

/// The coarser parts of vertex `v`'s neighbourhood into `row`; returns the
/// number of parent lookups that met nothing.
#[allow(clippy::too_many_arguments)]
fn coarse_row(
    levels: &[SynthesisLevel],
    geometry: &[LevelGeometry],
    results: &[LevelResult],
    l: usize,
    parts: &[Part],
    ch: usize,
    reach: f32,
    v: usize,
    row: &mut [f32],
    scratch: &mut FlattenScratch,
    stencil: &mut Vec<StencilPoint>,
) -> usize {
    let positions = &levels[l].mesh.positions;
    let frame = &levels[l].frames[v];
    let p: Vec3 = positions[v];
    let mut misses = 0;
    let mut o = 0;
    for part in parts {
        let c = l + part.level_offset as usize;
        let cg = &geometry[c];
        let len = part.values(ch);
        let dst = &mut row[o..o + len];
        o += len;
        let hit = cg
            .bvh
            .as_ref()
            .and_then(|b| b.cast_line(p, frame.n, reach * cg.spacing));
        let Some(hit) = hit else {
            for px in dst.chunks_exact_mut(ch) {
                px.copy_from_slice(&cg.default);
            }
            misses += 1;
            continue;
        };
        let template = Template {
            size: part.size,
            spacing: cg.spacing,
        };
        stencil.clear();
        stencil.resize(template.points(), StencilPoint::UNCOVERED);
        flatten_stencil(
            &cg.adjacency,
            &levels[c].mesh.positions,
            PatchSeed::Point {
                tri: hit.tri,
                at: hit.at,
            },
            frame,
            template,
            stencil,
            scratch,
        );
        resample_stencil(stencil, &results[c].colours, ch, &cg.default, dst);
    }
    misses
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn coarse_rows_read_back_within_half_a_step_of_the_range() {
        let (lo, hi) = (-0.25f32, 1.5f32);
        let mut rows = CoarseRows::new(3, 4, (lo, hi));
        let values = [
            lo,
            hi,
            0.0,
            1.0,
            0.123_456,
            0.999_99,
            -0.2,
            1.499,
            0.5,
            0.25,
            0.75,
            1.0 / 3.0,
        ];
        let quantised: Vec<u16> = values.iter().map(|&x| rows.quantise(x)).collect();
        rows.values = quantised;
        let half_step = (hi - lo) / u16::MAX as f32 / 2.0;
        let mut out = [0.0f32; 4];
        for v in 0..3 {
            rows.row_into(v, &mut out);
            for (o, x) in out.iter().zip(&values[v * 4..v * 4 + 4]) {
                assert!((o - x).abs() <= half_step * 1.01, "{x} read back as {o}");
            }
        }
        // The ends of the range are exact; values outside it are clamped.
        assert_eq!(rows.quantise(lo), 0);
        assert_eq!(rows.quantise(hi), u16::MAX);
        assert_eq!(rows.quantise(hi + 1.0), u16::MAX);
        // An empty or flat range still reads back what it stored.
        let flat = CoarseRows::new(1, 1, (0.5, 0.5));
        assert!(flat.step > 0.0);
    }

    #[test]
    fn coarser_parts_span_the_fine_template() {
        let p = neighbourhood_parts(NeighbourhoodSpec { size: 7, levels: 2 }, 4);
        assert_eq!(
            p,
            vec![
                Part {
                    level_offset: 0,
                    size: 7
                },
                Part {
                    level_offset: 1,
                    size: 5
                }
            ]
        );
        let p = neighbourhood_parts(NeighbourhoodSpec { size: 5, levels: 3 }, 2);
        assert_eq!(p.len(), 2);
        assert_eq!(p[1].size, 3);
        let p = neighbourhood_parts(NeighbourhoodSpec { size: 3, levels: 2 }, 2);
        assert_eq!(p[1].size, 3);
        let p = neighbourhood_parts(NeighbourhoodSpec { size: 1, levels: 1 }, 1);
        assert_eq!(p.len(), 1);
    }
}
