//! Coherent per-vertex synthesis of exemplar **coordinates** over a mesh
//! pyramid: an extension beyond Wei & Levoy 2001 that carries the ideas of
//! parallel controllable synthesis (Lefebvre & Hoppe 2005), appearance space
//! (Lefebvre & Hoppe 2006) and k-coherence (Ashikhmin 2001, Tong et al.
//! 2002) from the image grid onto arbitrary meshes.
//!
//! # The algorithm
//!
//! Every vertex holds a continuous coordinate `u(v)` in the exemplar
//! (level-0 pixels, pixel centres at `i + 0.5`); its colour, and every other
//! exemplar channel, is the exemplar pixel under it, so the result is always
//! made of exemplar pixels (sharp) and the channels follow for free.
//!
//! The texture scale is `τ` exemplar pixels per world unit (by default one
//! pixel per vertex spacing `d₀ = √(2·A₀)` of the finest level). A world
//! displacement `d` seen from vertex `v` is the pixel offset
//! `δ = frame_v.texel_offset(d, τ)`. Mesh level `L` has spacing `d_L`, i.e.
//! `r_L = τ·d_L` exemplar pixels between neighbouring vertices; it compares
//! neighbourhoods in the appearance space of Gaussian stack level
//! `round(log₂ r_L)`, sampled with window spacing `r_L` ([`appearance`]).
//!
//! Levels run from the coarsest:
//!
//! 1. **Initialise.** The coarsest level takes random coordinates. A finer
//!    level takes, per vertex `v`, the coordinate of the nearest vertex `p` of
//!    the nearest coarser triangle, shifted by the offset of `v` from `p` in
//!    `p`'s frame (`u(p) + frame_p.texel_offset(x_v − x_p, τ)`): coherent
//!    patches upsample to coherent patches, whatever the level ratio (2 for
//!    `retile` and `builtin_pyramid` levels, √2 for `subdivide_sqrt2`).
//! 2. **Jitter.** Each coordinate moves by up to `jitter · r_L` pixels per
//!    axis (seeded per level), which breaks up the copied patches.
//! 3. **Correction passes.** Each vertex `v` compares, over its mesh
//!    neighbours `w` (the `ring`-ring, at most [`MAX_NEIGHBOURS`] nearest),
//!    `E(c) = Σ_w ‖A(c + δ_w) − A(u(w))‖²` for candidates `c`: its current
//!    coordinate, each neighbour's coordinate shifted back by the
//!    neighbour's offset (`u(w) − δ_w`, coherent), and the same for the `k`
//!    exemplar pixels most similar to `u(w)` (k-coherent). It keeps the
//!    cheapest, so its own term never grows. A pass visits the vertices in a
//!    seeded random order, run as batches of non-conflicting vertices
//!    ([`crate::kernels::wei_levoy::wl_match::schedule`]): exactly the sequential
//!    result, for any thread count.
//!
//! Coordinates of a clamped (non-tileable) exemplar stay inside it:
//! candidates outside are skipped. Of a tileable one they wrap.

pub mod appearance;

use std::time::Instant;

use glam::{Vec2, Vec3};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

use self::appearance::{APPEARANCE_DIMS, AppearanceLevel, AppearanceSpec, appearance_level_cached};
use crate::cache_format::AnalysisStore;
use crate::image::{Image, pyramid::gaussian_stack, sample::Wrap};
use crate::kernels::surface::flatten::{
    TriangleAdjacency, mean_fan_triangle_area, template_spacing,
};
use crate::kernels::surface::frames::TangentFrame;
use crate::kernels::surface::occupancy::Occupancy;
use crate::kernels::wei_levoy::wl_match::parents::TriangleBvh;
use crate::kernels::wei_levoy::wl_match::schedule::{dependency_batches_of, random_order};
use crate::kernels::wei_levoy::wl_match::{SynthesisLevel, WlError, validate_levels};
use crate::mesh::Topology;
use crate::progress::{Progress, level_label};

/// Neighbours compared per vertex at most (the nearest of its rings).
pub const MAX_NEIGHBOURS: usize = 24;

/// Vertices per parallel chunk of the neighbourhood search.
const NEIGHBOURHOOD_CHUNK: usize = 512;

/// The nearest neighbours whose shifted coordinates (and similar pixels) are
/// candidates; farther ones only take part in the comparison.
pub const CANDIDATE_SOURCES: usize = 8;

/// Settings of [`coherent_synthesis`].
#[derive(Clone, Debug, PartialEq)]
pub struct CoherentSettings {
    /// Correction passes per level, ≥ 0.
    pub passes: u32,
    /// Similar exemplar pixels per pixel (k-coherence); 0 = pure coherence.
    pub k: usize,
    /// Appearance-space components, `1..=8`.
    pub dims: usize,
    /// Appearance window points per side (odd, ≥ 1).
    pub window: u32,
    /// Mesh rings compared, `1..=3`.
    pub ring: u32,
    /// Jitter after upsampling, in level spacings (pixels `r_L`), ≥ 0.
    pub jitter: f32,
    /// Weight of the occurrence penalty that spreads the synthesis over the
    /// whole exemplar, ≥ 0 (0 = plain nearest neighbourhood).
    pub spread: f32,
    /// Extra cost of a jump to a similar pixel over a coherent shift, in mean
    /// neighbourhood errors, ≥ 0 (larger: larger coherent patches).
    pub coherence: f32,
    /// Exemplar pixels per world unit; 0 = one per finest vertex spacing.
    pub scale: f32,
    /// Seed of the random coordinates, jitter and orders.
    pub seed: u64,
    /// Exemplar addressing.
    pub wrap: Wrap,
}

impl CoherentSettings {
    /// The defaults, usable in constants.
    pub const DEFAULT: Self = Self {
        passes: 3,
        k: 4,
        dims: 8,
        window: 5,
        ring: 3,
        jitter: 0.0,
        spread: 0.5,
        coherence: 2.0,
        scale: 0.0,
        seed: 0,
        wrap: Wrap::Repeat,
    };
}

impl Default for CoherentSettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// What happened on one level.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct CoherentLevelReport {
    /// Pyramid level (0 finest).
    pub level: usize,
    /// Vertices synthesised.
    pub vertices: usize,
    /// Vertex spacing `d_L = √(2A)` in world units.
    pub spacing: f32,
    /// Exemplar pixels between neighbouring vertices (`r_L = τ·d_L`).
    pub texels_per_spacing: f32,
    /// Gaussian stack level compared.
    pub stack_level: usize,
    /// Mean neighbours compared per vertex.
    pub mean_neighbours: f32,
    /// Mean per-neighbour appearance error `E(u(v)) / |N(v)|` over the
    /// vertices: after initialisation and jitter, then after every pass.
    pub energy: Vec<f32>,
    /// Of the last pass's choices, the fractions that kept the coordinate,
    /// took a neighbour's shifted coordinate, or a similar pixel's.
    pub picks: [f32; 3],
    /// Batches per pass.
    pub batches: Vec<usize>,
    /// Vertices visited per pass (the others could not change).
    pub visited: Vec<usize>,
    /// Wall time of the level (appearance space included), seconds.
    pub seconds: f64,
    /// Of `seconds`, the exemplar's appearance space (analysis: the same
    /// for every mesh), seconds.
    pub analysis_seconds: f64,
    /// Whether the appearance analysis came from the on-disk cache.
    pub analysis_cached: bool,
}

/// Coordinates of one level.
#[derive(Clone, Debug, Default)]
pub struct CoherentLevel {
    /// Per vertex, its exemplar coordinate (level-0 pixels, continuous).
    pub coords: Vec<Vec2>,
    /// Statistics.
    pub report: CoherentLevelReport,
}

/// Neighbours of some vertices of a level with their pixel offsets, CSR.
struct Neighbourhoods {
    /// Per vertex of the level, its entry in `start` (`u32::MAX`: none).
    slot: Vec<u32>,
    start: Vec<u32>,
    vertex: Vec<u32>,
    offset: Vec<Vec2>,
}

impl Neighbourhoods {
    /// `v`'s neighbours and offsets (none when `v` was not listed).
    #[inline]
    fn of(&self, v: u32) -> (&[u32], &[Vec2]) {
        let s = self.slot[v as usize];
        if s == u32::MAX {
            return (&[], &[]);
        }
        let (a, b) = (
            self.start[s as usize] as usize,
            self.start[s as usize + 1] as usize,
        );
        (&self.vertex[a..b], &self.offset[a..b])
    }

    /// The slot array back, all `u32::MAX` again (`list`: the vertices it
    /// was found for), to find the next chunk's without a new one.
    fn release(mut self, list: &[u32]) -> Vec<u32> {
        for &v in list {
            self.slot[v as usize] = u32::MAX;
        }
        self.slot
    }
}

/// Vertices per chunk of a masked refinement: a larger mask's
/// neighbourhoods are found a chunk at a time (for every pass), so its
/// memory does not grow with the mask; a smaller one's once.
const REFINE_CHUNK: usize = 1 << 15;

/// The `ring`-ring (at most [`MAX_NEIGHBOURS`], nearest first, ties by
/// id) with offsets in the vertex's frame at `scale` of each vertex in
/// `list` (`None`: every vertex). `slot` is a released slot array to reuse
/// (all `u32::MAX`, one per vertex), or empty.
fn neighbourhoods(
    topology: &Topology,
    positions: &[Vec3],
    frames: &[TangentFrame],
    ring: u32,
    scale: f32,
    list: Option<&[u32]>,
    slot: Vec<u32>,
) -> Neighbourhoods {
    let _s = tracing::info_span!("vertex_neighbourhoods").entered();
    let n = list.map_or(positions.len(), <[u32]>::len);
    let vertex_of = |i: usize| list.map_or(i as u32, |l| l[i]);
    // Per fixed chunk of vertices, flat lists with reused buffers (no
    // allocation per vertex); concatenated in vertex order.
    // `seen[w] == v + 1`: w is already in v's rings (a stamp per searched
    // vertex, so the per-thread array is never cleared).
    // The stamps are kept in a pool, not made per rayon split: a mesh-sized
    // array per split is zeroed again and again (`Pool`).
    let pool = crate::kernels::surface::flatten::Pool::<Vec<u32>>::new();
    let chunks: Vec<(Vec<u32>, Vec<Vec2>, Vec<u32>)> = (0..n.div_ceil(NEIGHBOURHOOD_CHUNK))
        .into_par_iter()
        .map(|c| {
            pool.with(|seen| {
                if seen.len() != positions.len() {
                    seen.clear();
                    seen.resize(positions.len(), 0);
                }
                let vs = (c * NEIGHBOURHOOD_CHUNK..((c + 1) * NEIGHBOURHOOD_CHUNK).min(n))
                    .map(vertex_of);
                let mut found: Vec<u32> = Vec::new();
                let mut near: Vec<(f32, u32)> = Vec::new();
                let mut vertex = Vec::new();
                let mut offset = Vec::new();
                let mut counts = Vec::with_capacity(vs.len());
                for v in vs {
                    let stamp = v + 1;
                    found.clear();
                    found.push(v);
                    seen[v as usize] = stamp;
                    let mut frontier = 0;
                    for _ in 0..ring {
                        let end = found.len();
                        for i in frontier..end {
                            for &w in topology.neighbours(found[i]) {
                                if seen[w as usize] != stamp {
                                    seen[w as usize] = stamp;
                                    found.push(w);
                                }
                            }
                        }
                        frontier = end;
                    }
                    let x = positions[v as usize];
                    near.clear();
                    near.extend(
                        found[1..]
                            .iter()
                            .map(|&w| ((positions[w as usize] - x).length_squared(), w)),
                    );
                    near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                    near.truncate(MAX_NEIGHBOURS);
                    let f = frames[v as usize];
                    for &(_, w) in &near {
                        vertex.push(w);
                        offset.push(f.texel_offset(positions[w as usize] - x, scale));
                    }
                    counts.push(near.len() as u32);
                }
                (vertex, offset, counts)
            })
        })
        .collect();
    let total: usize = chunks.iter().map(|c| c.0.len()).sum();
    let mut start = Vec::with_capacity(n + 1);
    start.push(0u32);
    let mut vertex = Vec::with_capacity(total);
    let mut offset = Vec::with_capacity(total);
    for (vs, os, counts) in chunks {
        vertex.extend_from_slice(&vs);
        offset.extend_from_slice(&os);
        for c in counts {
            start.push(start[start.len() - 1] + c);
        }
    }
    let slot = match list {
        None => (0..n as u32).collect(),
        Some(l) => {
            let mut slot = if slot.len() == positions.len() {
                slot
            } else {
                vec![u32::MAX; positions.len()]
            };
            for (i, &v) in l.iter().enumerate() {
                slot[v as usize] = i as u32;
            }
            slot
        }
    };
    Neighbourhoods {
        slot,
        start,
        vertex,
        offset,
    }
}

/// Exemplar addressing of coordinates: wrap a tileable exemplar, reject a
/// coordinate outside a clamped one.
#[derive(Clone, Copy)]
struct Domain {
    width: f32,
    height: f32,
    w: u32,
    h: u32,
    wrap: Wrap,
}

impl Domain {
    /// The coordinate inside the exemplar, or `None` (clamped exemplar).
    #[inline]
    fn admit(&self, c: Vec2) -> Option<Vec2> {
        match self.wrap {
            Wrap::Repeat => Some(Vec2::new(
                c.x.rem_euclid(self.width).min(self.width - 1e-3),
                c.y.rem_euclid(self.height).min(self.height - 1e-3),
            )),
            Wrap::Clamp => {
                (c.x >= 0.0 && c.y >= 0.0 && c.x < self.width && c.y < self.height).then_some(c)
            }
        }
    }

    /// The coordinate moved inside the exemplar (clamped or wrapped).
    #[inline]
    fn confine(&self, c: Vec2) -> Vec2 {
        self.admit(c).unwrap_or_else(|| {
            Vec2::new(
                c.x.clamp(0.0, self.width - 1e-3),
                c.y.clamp(0.0, self.height - 1e-3),
            )
        })
    }

    /// The pixel index under a coordinate anywhere (addressed by `wrap`).
    #[inline]
    fn pixel(&self, c: Vec2) -> u32 {
        let ix = super::floor_i64(c.x);
        let iy = super::floor_i64(c.y);
        let (x, y) = match self.wrap {
            Wrap::Repeat => (
                ix.rem_euclid(self.w as i64) as u32,
                iy.rem_euclid(self.h as i64) as u32,
            ),
            Wrap::Clamp => (
                ix.clamp(0, self.w as i64 - 1) as u32,
                iy.clamp(0, self.h as i64 - 1) as u32,
            ),
        };
        y * self.w + x
    }

    /// The centre of pixel index `p`.
    #[inline]
    fn centre(&self, p: u32) -> Vec2 {
        Vec2::new((p % self.w) as f32 + 0.5, (p / self.w) as f32 + 0.5)
    }
}

#[inline]
fn dist2(a: &[f32; APPEARANCE_DIMS], b: &[f32; APPEARANCE_DIMS]) -> f32 {
    a.iter().zip(b).map(|(x, y)| (x - y) * (x - y)).sum()
}

/// The neighbourhood cost of coordinate `c` against `targets`, stopping once
/// it exceeds `bound`.
#[inline]
fn cost(
    app: &AppearanceLevel,
    domain: &Domain,
    c: Vec2,
    offsets: &[Vec2],
    targets: &[[f32; APPEARANCE_DIMS]],
    bound: f32,
) -> f32 {
    let mut e = 0.0;
    for (d, t) in offsets.iter().zip(targets) {
        e += dist2(&app.vectors[domain.pixel(c + *d) as usize], t);
        if e > bound {
            break;
        }
    }
    e
}

/// The level's uses of the exemplar's cells (`kernels::surface::occupancy`): every
/// coordinate once; an even share is the mean count per cell.
fn occupancy(coords: &[Vec2], domain: &Domain, cell: f32) -> Occupancy {
    let mut occ = Occupancy::new(domain.width, domain.height, cell);
    occ.expected = (coords.len() as f32 / occ.cells() as f32).max(1e-6);
    for &c in coords {
        occ.add(c);
    }
    occ
}

/// What one batch of corrections reads besides the coordinates.
struct Corrector<'a> {
    nbs: &'a Neighbourhoods,
    app: &'a AppearanceLevel,
    domain: &'a Domain,
    occ: &'a Occupancy,
    /// Occurrence penalty per compared neighbour.
    weight: f32,
    /// Extra cost of a jump to a similar pixel per compared neighbour.
    jump: f32,
}

/// The best coordinate for `v` given the current coordinates, and how it was
/// found (0 kept, 1 coherent, 2 similar).
fn correct(v: u32, coords: &[Vec2], k: &Corrector) -> (Vec2, u8) {
    let Corrector {
        nbs,
        app,
        domain,
        occ,
        weight,
        jump,
    } = *k;
    let (ws, offsets) = nbs.of(v);
    let here = coords[v as usize];
    if ws.is_empty() {
        return (here, 0);
    }
    let weight = weight * ws.len() as f32;
    let jump = jump * ws.len() as f32;
    let mut targets = [[0.0f32; APPEARANCE_DIMS]; MAX_NEIGHBOURS];
    let mut sources = [0u32; MAX_NEIGHBOURS];
    for (i, &w) in ws.iter().enumerate() {
        let p = domain.pixel(coords[w as usize]);
        sources[i] = p;
        targets[i] = app.vectors[p as usize];
    }
    let targets = &targets[..ws.len()];
    let penalty = |c: Vec2| weight * occ.share(c, Some(here));
    let mut best = (
        cost(app, domain, here, offsets, targets, f32::INFINITY) + penalty(here),
        here,
        0u8,
    );
    let mut tried = [u32::MAX; CANDIDATE_SOURCES * 17 + 1];
    let mut tried_len = 0;
    tried[0] = domain.pixel(here);
    tried_len += 1;
    for (i, &w) in ws.iter().enumerate().take(CANDIDATE_SOURCES) {
        let uw = coords[w as usize];
        let frac = uw - domain.centre(sources[i]);
        let similar = app.similar_of(sources[i]);
        for (j, &s) in std::iter::once(&sources[i]).chain(similar).enumerate() {
            let Some(c) = domain.admit(domain.centre(s) + frac - offsets[i]) else {
                continue;
            };
            let p = domain.pixel(c);
            if tried[..tried_len].contains(&p) {
                continue;
            }
            if tried_len < tried.len() {
                tried[tried_len] = p;
                tried_len += 1;
            }
            let pen = penalty(c) + if j == 0 { 0.0 } else { jump };
            if pen >= best.0 {
                continue;
            }
            let e = cost(app, domain, c, offsets, targets, best.0 - pen) + pen;
            if e < best.0 {
                best = (e, c, if j == 0 { 1 } else { 2 });
            }
        }
    }
    (best.1, best.2)
}

/// `v`'s neighbourhood cost `E(u(v))` at the current coordinates.
#[inline]
fn own_cost(
    v: u32,
    coords: &[Vec2],
    nbs: &Neighbourhoods,
    app: &AppearanceLevel,
    domain: &Domain,
) -> f64 {
    let (ws, offsets) = nbs.of(v);
    let c = coords[v as usize];
    ws.iter()
        .zip(offsets)
        .map(|(&w, d)| {
            let t = &app.vectors[domain.pixel(coords[w as usize]) as usize];
            dist2(&app.vectors[domain.pixel(c + *d) as usize], t) as f64
        })
        .sum()
}

/// Mean per-neighbour cost of the current coordinates.
fn energy(coords: &[Vec2], nbs: &Neighbourhoods, app: &AppearanceLevel, domain: &Domain) -> f32 {
    let (sum, count) = energy_sum(coords, nbs, None, app, domain);
    (sum / count.max(1) as f64) as f32
}

/// Sum of the listed vertices' costs, and of their neighbourhoods' sizes.
/// (`list`: the vertices `nbs` was found for; `None`: every vertex.)
fn energy_sum(
    coords: &[Vec2],
    nbs: &Neighbourhoods,
    list: Option<&[u32]>,
    app: &AppearanceLevel,
    domain: &Domain,
) -> (f64, usize) {
    let cost = |v: u32| own_cost(v, coords, nbs, app, domain);
    let sum: f64 = match list {
        None => (0..coords.len() as u32).into_par_iter().map(cost).sum(),
        Some(l) => l.par_iter().map(|&v| cost(v)).sum(),
    };
    (sum, nbs.vertex.len())
}

/// Synthesises exemplar coordinates on every level of `levels` (finest
/// first), coarse to fine. Returns one [`CoherentLevel`] per level.
///
/// With `start` (one coordinate per vertex of the finest level: another
/// method's result, e.g. `SourceTexels` of `jump_surface` or `match`), only
/// the finest level is synthesised, from those coordinates: correction
/// passes that refine a result instead of growing one; one level returned.
///
/// # Errors
/// [`WlError`] for no levels, an empty exemplar, a level without faces
/// or with the wrong number of frames.
pub fn coherent_synthesis(
    levels: &[SynthesisLevel],
    exemplar: &Image,
    settings: &CoherentSettings,
    start: Option<&[Vec2]>,
    store: Option<&dyn AnalysisStore>,
    progress: &Progress,
) -> Result<Vec<CoherentLevel>, WlError> {
    synthesis(
        levels, exemplar, settings, start, None, None, store, progress,
    )
}

/// Refines another method's coordinates `start` on one level (as
/// [`coherent_synthesis`] with a start) where `mask` allows: only vertices
/// in `mask` are corrected; the others keep their coordinates and serve as
/// context. Neighbourhoods are found for the masked vertices alone, so a
/// thin mask (the band around another method's seams) costs in proportion
/// to its size. `topology` is the level mesh's, when the caller has it.
///
/// # Errors
/// As [`coherent_synthesis`]; a mask of the wrong length is
/// [`WlError::StartCount`].
#[allow(clippy::too_many_arguments)] // the refinement's inputs and its two services (store, progress)
pub fn coherent_refine(
    level: &SynthesisLevel,
    topology: Option<&Topology>,
    exemplar: &Image,
    settings: &CoherentSettings,
    start: &[Vec2],
    mask: &[bool],
    store: Option<&dyn AnalysisStore>,
    progress: &Progress,
) -> Result<CoherentLevel, WlError> {
    if mask.len() != level.mesh.vertex_count() {
        return Err(WlError::StartCount {
            given: mask.len(),
            vertices: level.mesh.vertex_count(),
        });
    }
    let levels = [SynthesisLevel {
        mesh: level.mesh,
        frames: level.frames,
    }];
    let mut out = synthesis(
        &levels,
        exemplar,
        settings,
        Some(start),
        Some(mask),
        topology,
        store,
        progress,
    )?;
    Ok(out.swap_remove(0))
}

#[allow(clippy::too_many_arguments)] // both entry points' inputs, each optional
fn synthesis(
    levels: &[SynthesisLevel],
    exemplar: &Image,
    settings: &CoherentSettings,
    start: Option<&[Vec2]>,
    mask: Option<&[bool]>,
    finest_topology: Option<&Topology>,
    store: Option<&dyn AnalysisStore>,
    progress: &Progress,
) -> Result<Vec<CoherentLevel>, WlError> {
    if levels.is_empty() {
        return Err(WlError::NoLevels);
    }
    if exemplar.pixel_count() == 0 || exemplar.channels == 0 {
        return Err(WlError::EmptyExemplar);
    }
    validate_levels(levels)?;
    if let Some(st) = start
        && st.len() != levels[0].mesh.vertex_count()
    {
        return Err(WlError::StartCount {
            given: st.len(),
            vertices: levels[0].mesh.vertex_count(),
        });
    }
    let levels = if start.is_some() {
        &levels[..1]
    } else {
        levels
    };
    // One step per vertex and correction pass (one pass for none).
    let passes = u64::from(settings.passes.max(1));
    progress.set_length(
        levels
            .iter()
            .map(|lv| lv.mesh.vertex_count() as u64 * passes)
            .sum(),
    );
    // Each level's template spacing; a coarse level's triangle adjacency is
    // built only when the next finer level is upsampled from it (never for
    // the finest, e.g. a refinement's only level).
    let spacings: Vec<f32> = levels
        .iter()
        .map(|lv| template_spacing(mean_fan_triangle_area(lv.mesh)).max(f32::MIN_POSITIVE))
        .collect();
    let scale = if settings.scale > 0.0 {
        settings.scale
    } else {
        1.0 / spacings[0]
    };
    let (w, h) = (exemplar.width, exemplar.height);
    let domain = Domain {
        width: w as f32,
        height: h as f32,
        w,
        h,
        wrap: settings.wrap,
    };
    // Stack levels up to where the window spans the exemplar.
    let max_stack = (w.min(h) as f32).log2().floor().max(0.0) as usize;
    let stack_of = |r: f32| (r.max(1.0).log2().round() as usize).min(max_stack);
    let ratios: Vec<f32> = spacings.iter().map(|s| s * scale).collect();
    let stack_count = ratios.iter().map(|&r| stack_of(r)).max().unwrap_or(0) + 1;
    let stack = gaussian_stack(exemplar, stack_count, settings.wrap);
    let window_cap = w.min(h) as f32 / settings.window.max(1) as f32;

    let mut out: Vec<CoherentLevel> = vec![CoherentLevel::default(); levels.len()];
    for l in (0..levels.len()).rev() {
        let _span = tracing::info_span!("coherent_level", level = l).entered();
        progress.set_part(&level_label(l, levels.len()));
        let started = Instant::now();
        let lv = &levels[l];
        let positions = &lv.mesh.positions;
        let nv = positions.len();
        let ratio = ratios[l];
        let stack_level = stack_of(ratio);
        let app_span = tracing::info_span!("appearance").entered();
        let spec = AppearanceSpec {
            window: settings.window,
            spacing: ratio.clamp(1.0, window_cap.max(1.0)),
            dims: settings.dims,
            k: settings.k,
            seed: settings.seed ^ l as u64,
            wrap: settings.wrap,
        };
        let (app, analysis_cached) = appearance_level_cached(&stack[stack_level], &spec, store);
        drop(app_span);
        let analysis_seconds = started.elapsed().as_secs_f64();
        let built;
        let topology = match finest_topology {
            Some(t) if l == 0 => t,
            _ => {
                built = Topology::build(lv.mesh);
                &built
            }
        };
        let ring = settings.ring.max(1);
        // A masked refinement finds neighbourhoods a chunk at a time; every
        // other run finds them all once.
        let band: Option<Vec<u32>> =
            mask.map(|m| (0..nv as u32).filter(|&v| m[v as usize]).collect());
        // One slot array serves every chunk in turn.
        let pool: std::cell::RefCell<Vec<u32>> = std::cell::RefCell::new(Vec::new());
        let found = |list: Option<&[u32]>| {
            let slot = std::mem::take(&mut *pool.borrow_mut());
            neighbourhoods(topology, positions, lv.frames, ring, scale, list, slot)
        };
        let recycle = |nbs: Neighbourhoods, list: &[u32]| {
            *pool.borrow_mut() = nbs.release(list);
        };
        let whole = match &band {
            None => Some(found(None)),
            Some(b) if b.len() <= REFINE_CHUNK => Some(found(Some(b))),
            Some(_) => None,
        };
        // Mean per-neighbour cost of the band (masked) or of every vertex.
        let level_energy = |coords: &[Vec2]| -> (f32, f32) {
            let _s = tracing::info_span!("energy").entered();
            match (&whole, &band) {
                (Some(nbs), _) => (
                    energy(coords, nbs, &app, &domain),
                    nbs.vertex.len() as f32 / band.as_ref().map_or(nv, Vec::len).max(1) as f32,
                ),
                (None, Some(band)) => {
                    let (mut sum, mut count) = (0.0f64, 0usize);
                    for chunk in band.chunks(REFINE_CHUNK) {
                        let nbs = found(Some(chunk));
                        let (s, c) = energy_sum(coords, &nbs, Some(chunk), &app, &domain);
                        sum += s;
                        count += c;
                        recycle(nbs, chunk);
                    }
                    (
                        (sum / count.max(1) as f64) as f32,
                        count as f32 / band.len().max(1) as f32,
                    )
                }
                (None, None) => (0.0, 0.0),
            }
        };
        let mut rng =
            rand_pcg::Pcg64Mcg::seed_from_u64(crate::kernels::mix(settings.seed, l as u64, 1));
        // 1. Initialise.
        let mut coords: Vec<Vec2> = if let Some(st) = start {
            st.iter().map(|&c| domain.confine(c)).collect()
        } else if l + 1 == levels.len() {
            (0..nv)
                .map(|_| {
                    Vec2::new(
                        rng.random::<f32>() * domain.width,
                        rng.random::<f32>() * domain.height,
                    )
                })
                .map(|c| domain.confine(c))
                .collect()
        } else {
            let coarse = &levels[l + 1];
            let adjacency = TriangleAdjacency::new(coarse.mesh);
            let parent_coords = &out[l + 1].coords;
            let bvh = TriangleBvh::new(&adjacency, &coarse.mesh.positions);
            positions
                .par_iter()
                .map(|&x| {
                    let Some(hit) = bvh.nearest_point(x) else {
                        return Vec2::splat(0.5);
                    };
                    let tri = adjacency.tris[hit.tri as usize];
                    let k = (0..3)
                        .max_by(|&a, &b| hit.weights[a].total_cmp(&hit.weights[b]).then(b.cmp(&a)))
                        .unwrap_or(0);
                    let p = tri[k] as usize;
                    let d = x - coarse.mesh.positions[p];
                    domain.confine(parent_coords[p] + coarse.frames[p].texel_offset(d, scale))
                })
                .collect()
        };
        // 2. Jitter.
        if settings.jitter > 0.0 && l + 1 < levels.len() && start.is_none() {
            let amp = settings.jitter * ratio;
            for c in coords.iter_mut() {
                let j = Vec2::new(
                    rng.random::<f32>() * 2.0 - 1.0,
                    rng.random::<f32>() * 2.0 - 1.0,
                );
                *c = domain.confine(*c + j * amp);
            }
        }
        // 3. Correction passes.
        let mut report = CoherentLevelReport {
            level: l,
            vertices: nv,
            spacing: spacings[l],
            texels_per_spacing: ratio,
            stack_level,
            ..Default::default()
        };
        let (e0, mean_neighbours) = level_energy(&coords);
        report.energy.push(e0);
        report.mean_neighbours = mean_neighbours;
        let cell = (4.0 * ratio).min(w.min(h) as f32 / 2.0);
        let mut occ = occupancy(&coords, &domain, cell);
        // Which vertices a pass visits. A synthesis: all, every pass. A
        // refinement (`start`), in its first pass: those in `mask`, or
        // without one, those whose neighbourhood does not already match
        // exactly (inside a copied patch a vertex has nothing to correct);
        // in later passes: the vertices a vertex that moved in the previous
        // pass compares against, and itself (an active set; neighbourhoods
        // are nearly symmetric, so these are nearly the vertices whose
        // neighbourhood changed: the others would see what they saw).
        let mut visit: Vec<bool> = match (mask, &whole) {
            (Some(m), _) => m.to_vec(),
            (None, Some(nbs)) if start.is_some() => (0..nv as u32)
                .into_par_iter()
                .map(|v| own_cost(v, &coords, nbs, &app, &domain) > 0.0)
                .collect(),
            _ => vec![true; nv],
        };
        for pass in 0..settings.passes {
            let mean_error = report.energy.last().copied().unwrap_or(0.0);
            let (weight, jump) = (
                settings.spread * mean_error,
                settings.coherence * mean_error,
            );
            let mut order = random_order(
                nv,
                crate::kernels::mix(settings.seed, l as u64, 2 + pass as u64),
            );
            order.retain(|&v| visit[v as usize]);
            report.visited.push(order.len());
            let mut next = vec![false; nv];
            // Unvisited vertices keep their coordinates.
            let mut picks = [nv - order.len(), 0, 0];
            let mut batch_count = 0;
            // The order in consecutive chunks (one when not masked): the
            // result is the sequential one over the whole order.
            let chunk_len = if whole.is_some() {
                order.len().max(1)
            } else {
                REFINE_CHUNK
            };
            // Each vertex's place in the order, when the neighbourhoods were
            // found once; a chunk's own neighbourhoods index it by place.
            let mut position = Vec::new();
            if whole.is_some() {
                position = vec![u32::MAX; nv];
                for (i, &v) in order.iter().enumerate() {
                    position[v as usize] = i as u32;
                }
            }
            for chunk in order.chunks(chunk_len) {
                let local = match &whole {
                    Some(_) => None,
                    None => Some(found(Some(chunk))),
                };
                let Some(nbs) = local.as_ref().or(whole.as_ref()) else {
                    continue;
                };
                let place: &[u32] = match &local {
                    Some(l) => &l.slot,
                    None => &position,
                };
                let batch_span = tracing::info_span!("dependency_batches").entered();
                let batches = dependency_batches_of(
                    chunk,
                    |u| place.get(u as usize).copied().filter(|&p| p != u32::MAX),
                    |v| nbs.of(v).0,
                );
                drop(batch_span);
                let _correct_span = tracing::info_span!("correct").entered();
                batch_count += batches.len();
                for batch in &batches {
                    let k = Corrector {
                        nbs,
                        app: &app,
                        domain: &domain,
                        occ: &occ,
                        weight,
                        jump,
                    };
                    let chosen: Vec<(Vec2, u8)> = batch
                        .par_iter()
                        .with_min_len(256)
                        .map(|&v| correct(v, &coords, &k))
                        .collect();
                    for (&v, (c, how)) in batch.iter().zip(chosen) {
                        if c != coords[v as usize] {
                            next[v as usize] = true;
                            for &w in nbs.of(v).0 {
                                if mask.is_none_or(|m| m[w as usize]) {
                                    next[w as usize] = true;
                                }
                            }
                        }
                        occ.moved(Some(coords[v as usize]), c);
                        coords[v as usize] = c;
                        picks[how as usize] += 1;
                    }
                }
                progress.inc(chunk.len() as u64);
                if let Some(l) = local {
                    recycle(l, chunk);
                }
            }
            report.batches.push(batch_count);
            // The vertices this pass did not visit.
            progress.inc((nv - order.len()) as u64);
            // A synthesis revisits every vertex: its occurrence penalty and
            // jump cost change with every pass, so a vertex whose
            // neighbourhood did not change may still move.
            if start.is_some() {
                visit = next;
            }
            report.energy.push(level_energy(&coords).0);
            let total = nv.max(1) as f32;
            report.picks = picks.map(|p| p as f32 / total);
        }
        if settings.passes == 0 {
            progress.inc(nv as u64);
        }
        report.seconds = started.elapsed().as_secs_f64();
        report.analysis_seconds = analysis_seconds;
        report.analysis_cached = analysis_cached;
        out[l] = CoherentLevel { coords, report };
    }
    Ok(out)
}

/// The colours of `image` at pixel centres `texels` (as [`pixel_centres`]
/// gives them), the image's channels per texel.
pub fn pixel_colours(image: &Image, texels: &[Vec2]) -> Vec<f32> {
    let mut values = Vec::with_capacity(texels.len() * image.channels as usize);
    for t in texels {
        values.extend_from_slice(image.pixel(t.x as u32, t.y as u32));
    }
    values
}

/// The exemplar pixel centre under each coordinate (what the colours copy).
pub fn pixel_centres(coords: &[Vec2], width: u32, height: u32, wrap: Wrap) -> Vec<Vec2> {
    let domain = Domain {
        width: width as f32,
        height: height as f32,
        w: width,
        h: height,
        wrap,
    };
    coords
        .iter()
        .map(|&c| domain.centre(domain.pixel(c)))
        .collect()
}
