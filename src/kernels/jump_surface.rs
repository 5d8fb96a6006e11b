//! Jump-map texture synthesis directly on surfaces (Zelinka & Garland 2004 §6).
//!
//! One pass over the vertices in a chosen order (§6.2) assigns each vertex a
//! floating-point exemplar address (pixels). Each already-synthesized
//! neighbour suggests "copy": its address plus the texture-space offset of the
//! edge (§6.3), and "jump": the destinations of the floating-point jump-map
//! look-up (§6.4) at that copy address (the paper looks up at the
//! neighbour's address and adds the offset; both agree for one-pixel steps,
//! and ours keeps jumps matched across long edges of coarse meshes). Suggestions that keep
//! the vertex's flattened one-ring inside the exemplar are valid (§6.5,
//! Fig. 18); one random number picks among all valid suggestions of all
//! neighbours (the selection table of §6.6). Only when none is valid is the
//! vertex placed at random. Per-corner texture coordinates then come from each
//! face's base vertex plus edge offsets, for every choice of base vertex, so a
//! renderer can blend the three (§6.5).
//!
//! Extensions, each an option whose default in [`SurfaceSynthSettings`] is
//! the paper's (the `jump_surface` stage turns them on; measured in
//! ARCHITECTURE.md, "Jump maps on surfaces without blur, repeats or seams"):
//! - `pixel_aligned`: random starts at pixel centres. Copies and jumps keep
//!   a start's sub-pixel phase, so a start between centres resamples its
//!   whole patch (bilinear blur) wherever the mapping is pixel-aligned.
//! - `max_patch_area`: a patch stops suggesting copies once it covers this
//!   much of the exemplar, so no large region is copied again and again.
//! - the matched choice ([`synthesize_surface_matched`]): where the draw
//!   leaves a choice, the candidate whose exemplar neighbourhood best
//!   matches the synthesised vertices wins.
//!
//! Coordinates: pixel addresses with x right, y down, integer values at pixel
//! centres (`(x + 0.5) / width` is the texture coordinate u).

use super::frames::TangentFrame;
use super::vertex_order::{VertexOrder, vertex_order};
use crate::image::Image;
use crate::image::sample::Wrap;
use crate::mesh::{PolyMesh, Topology};
use glam::{Vec2, Vec3};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

/// Read access to a jump map for the surface synthesizer.
pub trait JumpLookup: Sync {
    /// Width and height of the analysed exemplar, pixels.
    fn dims(&self) -> (u32, u32);
    /// Calls `f(dest_x, dest_y, weight)` for each jump stored at pixel `(x, y)`.
    fn for_each_jump<F: FnMut(u32, u32, f32)>(&self, x: u32, y: u32, f: F);
}

/// Settings of surface synthesis.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceSynthSettings {
    /// Desired patch size as a fraction of the exemplar's side `L`: patches
    /// of about `(f·L)²` pixels are wanted, so random numbers are drawn over
    /// twice that many pixels (§5.1). Each vertex counts for the texture area
    /// it covers (its mean squared edge offset), so the patch size in texels
    /// does not depend on the mesh resolution. 0.05..=16.
    pub patch_fraction: f32,
    /// Width of the boundary-avoidance band as a fraction of the exemplar
    /// size (§5.2; 0 turns it off). Ignored for tileable exemplars.
    pub boundary_fraction: f32,
    /// The exemplar tiles: addresses wrap and every suggestion is valid.
    pub tileable: bool,
    /// Vertex ordering.
    pub order: VertexOrder,
    /// Seed of the order and of every random choice.
    pub seed: u64,
    /// Largest area one patch may copy, as a fraction of the exemplar's
    /// area (an extension; 0 = unbounded, the paper). A patch is the set of
    /// vertices grown by copies from one jump or random start; once its
    /// texel area reaches this, its vertices no longer suggest copies, so
    /// the next vertex jumps. Bounds the tail of the patch sizes, which
    /// otherwise copies large parts of the exemplar verbatim again and
    /// again. 0..=1.
    pub max_patch_area: f32,
    /// Random starts at pixel centres (an extension; false = anywhere, the
    /// paper). Copies and jumps keep a start's sub-pixel phase, so a start
    /// between pixel centres resamples the whole patch it grows (bilinear
    /// blur) wherever the mapping is pixel-aligned (a flat mesh at one pixel
    /// per vertex spacing); elsewhere it changes nothing.
    pub pixel_aligned: bool,
}

impl Default for SurfaceSynthSettings {
    fn default() -> Self {
        Self {
            patch_fraction: 0.5,
            boundary_fraction: 0.2,
            tileable: false,
            order: VertexOrder::EmergingFront,
            seed: 0,
            max_patch_area: 0.0,
            pixel_aligned: false,
        }
    }
}

/// The result of surface synthesis.
#[derive(Clone, Debug, Default)]
pub struct SurfaceSynthOutput {
    /// Exemplar address per vertex, pixels.
    pub texel: Vec<Vec2>,
    /// Vertices that took a jump suggestion.
    pub jumps: usize,
    /// Vertices placed at random (component starts and vertices with no valid suggestion).
    pub random_assignments: usize,
    /// Vertices whose flattened one-ring is larger than the exemplar, so no
    /// address is valid (their texture is clamped).
    pub unfit: usize,
    /// Vertices without a valid suggestion (the paper places them at
    /// random) that the matched choice placed by matching their
    /// neighbourhood; counted in `jumps`, not in `random_assignments`.
    pub matched_starts: usize,
    /// Per vertex, its patch: the jump or random start whose copies reached
    /// it (numbered in synthesis order).
    pub patch: Vec<u32>,
}

/// Texture-space offset of every directed edge `v → w`, aligned with
/// `topo.neighbour_list` (§6.3, Fig. 13): the edge is projected onto the
/// average of its endpoints' bases, scaled by the mean of their scales
/// (pixels per world unit). `offset(v→w) = −offset(w→v)` exactly.
pub fn edge_offsets(
    positions: &[Vec3],
    frames: &[TangentFrame],
    scale: &[f32],
    topo: &Topology,
) -> Vec<Vec2> {
    let mut out = vec![Vec2::ZERO; topo.neighbour_list.len()];
    let starts = &topo.neighbour_start;
    out.par_chunks_mut(4096)
        .enumerate()
        .for_each(|(chunk, slots)| {
            let first = chunk * 4096;
            // The vertex owning slot `first`.
            let mut v = starts.partition_point(|&s| s as usize <= first) - 1;
            for (k, slot) in slots.iter_mut().enumerate() {
                let i = first + k;
                while starts[v + 1] as usize <= i {
                    v += 1;
                }
                let w = topo.neighbour_list[i] as usize;
                *slot = edge_offset(positions, frames, scale, v, w);
            }
        });
    out
}

#[inline]
fn edge_offset(
    positions: &[Vec3],
    frames: &[TangentFrame],
    scale: &[f32],
    a: usize,
    b: usize,
) -> Vec2 {
    // Symmetric in (a, b) so both directions share one basis; where the
    // mean degenerates (opposite frames), the lower vertex's frame, so the
    // fallback is symmetric too and the offsets stay exactly antisymmetric.
    let (fa, fb) = (&frames[a], &frames[b]);
    let low = &frames[a.min(b)];
    let up = (fa.t + fb.t).try_normalize().unwrap_or(low.t);
    let right_avg = fa.s + fb.s;
    let right = (right_avg - up * up.dot(right_avg))
        .try_normalize()
        .unwrap_or(low.s);
    let k = 0.5 * (scale[a] + scale[b]);
    let d = positions[b] - positions[a];
    Vec2::new(d.dot(right), -d.dot(up)) * k
}

/// Offset of the edge `a → b` from the CSR arrays (`None` when not adjacent).
#[inline]
pub fn offset_between(topo: &Topology, offsets: &[Vec2], a: u32, b: u32) -> Option<Vec2> {
    let nb = topo.neighbours(a);
    let i = nb.binary_search(&b).ok()?;
    Some(offsets[topo.neighbour_start[a as usize] as usize + i])
}

/// Runs the synthesis pass. `offsets` come from [`edge_offsets`].
pub fn synthesize_surface<J: JumpLookup>(
    topo: &Topology,
    offsets: &[Vec2],
    jumps: &J,
    settings: &SurfaceSynthSettings,
    progress: &crate::progress::Progress,
) -> SurfaceSynthOutput {
    synthesize_surface_matched(topo, offsets, jumps, settings, None, progress)
}

/// Random candidates of a matched start ([`synthesize_surface_matched`]).
pub const RANDOM_CANDIDATES: usize = 32;

/// Mesh rings whose synthesised vertices a matched choice compares. Two
/// (stop 29) see about a 5-pixel window at one pixel per edge: enough for
/// texture detail, not for the layout of planks and brick, so a jump could
/// land with its boards a few pixels off its neighbours'. Four (about 9
/// pixels) on the planar benchmark, seeds 1–3, five photos, exact
/// measures: the cells failing issue 13's gate 2 → 0 of 15 (planks p90 at
/// seed 1 1.10 → 0.87 × the peer, water at seed 3 1.001 → 0.95 ×); three
/// rings left planks failing at every seed (1.05–1.11 ×). The choice runs
/// only at copies that disagree, jumps and starts: the synthesis took
/// about 4 ms more on the 65 k-vertex plane (18–20 ms against 14–16).
pub const MATCH_RINGS: u32 = 4;

/// Synthesised vertices compared per matched choice at most (a regular
/// mesh has about 30 done vertices within four edges), so a vertex of
/// high valence (a fan cap's centre) costs a bounded amount.
pub const MATCH_NEIGHBOURS: usize = 96;

/// Vertices a matched choice's ring search visits at most (done or not).
const MATCH_VISITED: usize = 4 * MATCH_NEIGHBOURS;

/// The exemplar's colours for the matched choice.
#[derive(Clone, Copy)]
pub struct Matcher<'a> {
    /// The exemplar.
    pub image: &'a Image,
    /// Its addressing.
    pub wrap: Wrap,
}

impl Matcher<'_> {
    /// The exemplar's colour at address `p` (integers at pixel centres).
    #[inline]
    fn colour(&self, p: Vec2) -> [f32; 4] {
        let mut c = [0.0f32; 4];
        let k = (self.image.channels as usize).min(4);
        self.image
            .sample_bilinear(p.x + 0.5, p.y + 0.5, self.wrap, &mut c[..k]);
        c
    }

    /// The synthesised vertices within [`MATCH_RINGS`] edges of `v`
    /// (breadth first, each vertex once, its offset from `v` summed along
    /// the first path that reaches it; a vertex whose offset lies within
    /// half a pixel of one already taken is left out) with their colours,
    /// into `out`: at most [`MATCH_NEIGHBOURS`], after visiting at most
    /// [`MATCH_VISITED`] vertices. `seen` is scratch; `mark` holds one
    /// entry per vertex, `v + 1` where the search for `v` has been (each
    /// vertex is searched from once, so it is never cleared).
    #[allow(clippy::too_many_arguments)]
    fn gather(
        &self,
        topo: &Topology,
        offsets: &[Vec2],
        texel: &[Vec2],
        done: &[bool],
        v: u32,
        seen: &mut Vec<(u32, Vec2)>,
        mark: &mut [u32],
        out: &mut Vec<(Vec2, [f32; 4])>,
    ) {
        let tag = v + 1;
        mark[v as usize] = tag;
        out.clear();
        seen.clear();
        seen.push((v, Vec2::ZERO));
        let mut from = 0;
        for _ in 0..MATCH_RINGS {
            let end = seen.len();
            for i in from..end {
                let (u, ou) = seen[i];
                let su = topo.neighbour_start[u as usize] as usize;
                for (j, &w) in topo.neighbours(u).iter().enumerate() {
                    if seen.len() >= MATCH_VISITED {
                        return;
                    }
                    if mark[w as usize] == tag {
                        continue;
                    }
                    mark[w as usize] = tag;
                    let o = ou + offsets[su + j];
                    seen.push((w, o));
                    if done[w as usize]
                        && out.len() < MATCH_NEIGHBOURS
                        && !out.iter().any(|e| (e.0 - o).length_squared() < 0.25)
                    {
                        out.push((o, self.colour(texel[w as usize])));
                    }
                }
            }
            from = end;
        }
    }

    /// Sum of squared colour differences between the exemplar around `p`
    /// and the gathered neighbourhood, summed in order; once the sum
    /// exceeds `bound` the sum so far is returned (a candidate that cannot
    /// win need not be finished).
    #[inline]
    fn error(&self, p: Vec2, nb: &[(Vec2, [f32; 4])], bound: f32) -> f32 {
        let mut e = 0.0f32;
        for (o, t) in nb {
            let c = self.colour(p + *o);
            e += (0..4).map(|i| (c[i] - t[i]) * (c[i] - t[i])).sum::<f32>();
            if e > bound {
                break;
            }
        }
        e
    }
}

/// [`synthesize_surface`] with the matched choice (an extension) when
/// `matcher` is given: the paper's draw still decides whether a vertex
/// copies or jumps; where that leaves a choice, the candidate whose exemplar
/// neighbourhood best matches the synthesised vertices within [`MATCH_RINGS`] edges
/// wins: among disagreeing copies (where patches meet), among all valid
/// jumps of all neighbours (excluding jumps that continue a neighbour's
/// copy), and among [`RANDOM_CANDIDATES`] random starts and those jumps
/// where the paper starts at random.
pub fn synthesize_surface_matched<J: JumpLookup>(
    topo: &Topology,
    offsets: &[Vec2],
    jumps: &J,
    settings: &SurfaceSynthSettings,
    matcher: Option<Matcher>,
    progress: &crate::progress::Progress,
) -> SurfaceSynthOutput {
    let n = topo.vertex_count();
    let (w, h) = jumps.dims();
    let size = Vec2::new(w as f32, h as f32);
    let max = size - Vec2::ONE;
    let order = vertex_order(topo, settings.order, settings.seed);
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(settings.seed ^ 0x005E_ED0F_5EED);
    let mut texel = vec![Vec2::ZERO; n];
    let mut done = vec![false; n];
    let side = ((w as f32) * (h as f32)).sqrt();
    let range = (2.0 * (settings.patch_fraction * side).powi(2)).max(1.0);
    let band = settings.boundary_fraction * w.min(h) as f32;
    let mut out = SurfaceSynthOutput::default();
    let wrap = |p: Vec2| Vec2::new(p.x.rem_euclid(size.x), p.y.rem_euclid(size.y));
    let stored_of = |tap: Vec2| {
        if settings.tileable {
            wrap(tap)
        } else {
            tap.clamp(Vec2::ZERO, max)
        }
    };
    // Bilinear taps around a floating-point address (§6.4).
    let taps = |at: Vec2| {
        let base = at.floor();
        let f = at - base;
        [
            (base, (1.0 - f.x) * (1.0 - f.y)),
            (base + Vec2::X, f.x * (1.0 - f.y)),
            (base + Vec2::Y, (1.0 - f.x) * f.y),
            (base + Vec2::ONE, f.x * f.y),
        ]
    };
    let weight_sum = |at: Vec2| -> f32 {
        taps(at)
            .iter()
            .filter(|t| t.1 > 0.0)
            .map(|&(tap, bw)| {
                let st = stored_of(tap);
                let mut s = 0.0;
                jumps.for_each_jump(st.x as u32, st.y as u32, |_, _, jw| s += jw);
                s * bw
            })
            .sum()
    };
    /// One already-synthesized neighbour's suggestions, before validity of
    /// the jumps is known.
    #[derive(Clone, Copy)]
    struct Suggestion {
        /// The neighbour's patch.
        patch: u32,
        copy: Vec2,
        copy_mass: f32,
        jump_at: Vec2,
        jump_shift: Vec2,
        jump_scale: f32,
        jump_mass: f32,
    }
    // Every jump of a neighbour's suggestion, with its mass in the
    // selection table: its destination shifted by the look-up's sub-pixel
    // position and the suggestion's shift.
    let each_jump = |sg: &Suggestion, f: &mut dyn FnMut(Vec2, f32)| {
        for (tap, bw) in taps(sg.jump_at) {
            if bw <= 0.0 {
                continue;
            }
            let st = stored_of(tap);
            let sub = sg.jump_at - tap + sg.jump_shift;
            jumps.for_each_jump(st.x as u32, st.y as u32, |dx, dy, jw| {
                f(
                    Vec2::new(dx as f32, dy as f32) + sub,
                    jw * bw * sg.jump_scale,
                );
            });
        }
    };
    let mut suggestions: Vec<Suggestion> = Vec::with_capacity(32);
    // The matched choice's buffers (no allocation per vertex).
    let mut nb_buf: Vec<(Vec2, [f32; 4])> = Vec::with_capacity(64);
    let mut seen_buf: Vec<(u32, Vec2)> = Vec::with_capacity(128);
    let mut mark = if matcher.is_some() {
        vec![0u32; n]
    } else {
        Vec::new()
    };
    let mut cands: Vec<(Vec2, Option<u32>)> = Vec::with_capacity(64);
    // Whether address `p` keeps a one-ring spanning `bmin..=bmax` (§6.5,
    // Fig. 18) inside the exemplar.
    let fits = |p: Vec2, bmin: Vec2, bmax: Vec2| {
        settings.tileable || ((p + bmin).cmpge(Vec2::ZERO).all() && (p + bmax).cmple(max).all())
    };
    // A random start: uniform over the addresses that keep the one-ring
    // inside the exemplar, at a pixel centre when aligned.
    let random_start = |rng: &mut rand_pcg::Pcg64Mcg, bmin: Vec2, bmax: Vec2| {
        let free = if settings.tileable {
            Vec2::new(rng.random::<f32>() * size.x, rng.random::<f32>() * size.y)
        } else {
            let lo = -bmin;
            let hi = max - bmax;
            if hi.cmpge(lo).all() {
                lo + (hi - lo) * Vec2::new(rng.random::<f32>(), rng.random::<f32>())
            } else {
                (lo + hi) * 0.5
            }
        };
        let snapped = free.round();
        if settings.pixel_aligned && fits(snapped, bmin, bmax) {
            snapped
        } else {
            free
        }
    };
    // Per vertex its patch, per patch its texel area (max_patch_area).
    let cap = settings.max_patch_area * w as f32 * h as f32;
    let capped = cap > 0.0;
    let mut patch_of: Vec<u32> = vec![0; n];
    let mut patch_area: Vec<f32> = Vec::new();
    for (step, &v) in order.iter().enumerate() {
        if step % 65536 == 0 {
            progress.inc(step.min(65536) as u64);
        }
        let vi = v as usize;
        let lo_i = topo.neighbour_start[vi] as usize;
        let hi_i = topo.neighbour_start[vi + 1] as usize;
        // Bounding box of the flattened one-ring (§6.5, Fig. 18).
        let (mut bmin, mut bmax) = (Vec2::ZERO, Vec2::ZERO);
        for o in &offsets[lo_i..hi_i] {
            bmin = bmin.min(*o);
            bmax = bmax.max(*o);
        }
        let valid = |p: Vec2| fits(p, bmin, bmax);
        suggestions.clear();
        for (k, &u) in topo.neighbours(v).iter().enumerate() {
            let ui = u as usize;
            if !done[ui] {
                continue;
            }
            let d = -offsets[lo_i + k]; // u → v
            let pu = texel[ui];
            // The address copying would give v. The jump map is looked up
            // there rather than at u's own address: with one pixel between
            // neighbours (images) the two agree, but across a long edge a
            // destination found at u would be `d` away from the region it
            // matches, while one found at the copy address matches v's own
            // neighbourhood. (Our refinement of §6.4 for coarse meshes.)
            let copy = pu + d;
            let look = stored_of(copy);
            let (mut jump_at, mut jump_shift) = (look, Vec2::ZERO);
            let mut sum = weight_sum(look);
            if sum == 0.0 {
                // No jump list at the copy address (outside an inset map's
                // source region): fall back to u's own, as the paper does.
                (jump_at, jump_shift) = (pu, d);
                sum = weight_sum(pu);
            }
            // Jump probability per pixel of area (§5.1), raised near the
            // exemplar boundary (§5.2).
            let step_area = d.length_squared().max(1e-6);
            let mut r = range;
            if !settings.tileable && band > 0.0 {
                let dist = look.min(max - look).min_element().max(0.0);
                if dist < band {
                    r = sum + (range - sum) * dist / band;
                }
            }
            let mut k_scale = step_area / r.max(1e-6);
            if sum * k_scale > 1.0 {
                k_scale = 1.0 / sum;
            }
            let copy_mass = (1.0 - sum * k_scale).max(0.0);
            let patch = patch_of[ui];
            let open = !capped || patch_area[patch as usize] < cap;
            suggestions.push(Suggestion {
                patch,
                copy,
                copy_mass: if valid(copy) && open { copy_mass } else { 0.0 },
                jump_at,
                jump_shift,
                jump_scale: k_scale,
                jump_mass: sum * k_scale,
            });
        }
        // The selection table of §6.6 over all neighbours' valid
        // suggestions, sampled without building it: draw over the valid
        // copies plus ALL jump mass, enumerate a neighbour's jumps only when
        // the draw falls in its jump mass, and redraw when it lands on an
        // invalid jump. Accepted draws follow the table's distribution exactly.
        let total: f32 = suggestions.iter().map(|s| s.copy_mass + s.jump_mass).sum();
        let mut chosen = None;
        if total > 0.0 {
            'draw: for _ in 0..64 {
                let mut x = rng.random::<f32>() * total;
                for sg in &suggestions {
                    if x < sg.copy_mass {
                        chosen = Some((sg.copy, Some(sg.patch)));
                        break 'draw;
                    }
                    x -= sg.copy_mass;
                    if x < sg.jump_mass {
                        // Enumerate this neighbour's coalesced jumps.
                        let mut hit = None;
                        let mut y = x;
                        for (tap, bw) in taps(sg.jump_at) {
                            if bw <= 0.0 || hit.is_some() {
                                continue;
                            }
                            let st = stored_of(tap);
                            let sub = sg.jump_at - tap + sg.jump_shift;
                            jumps.for_each_jump(st.x as u32, st.y as u32, |dx, dy, jw| {
                                if hit.is_some() {
                                    return;
                                }
                                let m = jw * bw * sg.jump_scale;
                                if y < m {
                                    hit = Some(Vec2::new(dx as f32, dy as f32) + sub);
                                } else {
                                    y -= m;
                                }
                            });
                        }
                        match hit {
                            Some(p) if valid(p) => {
                                chosen = Some((p, None));
                                break 'draw;
                            }
                            _ => continue 'draw,
                        }
                    }
                    x -= sg.jump_mass;
                }
            }
            if chosen.is_none() {
                // 64 rejections in a row: draw from the exact table.
                let mut table: Vec<(Vec2, f32, Option<u32>)> = Vec::new();
                for sg in &suggestions {
                    if sg.copy_mass > 0.0 {
                        table.push((sg.copy, sg.copy_mass, Some(sg.patch)));
                    }
                    each_jump(sg, &mut |p, mass| {
                        if valid(p) {
                            table.push((p, mass, None));
                        }
                    });
                }
                let t: f32 = table.iter().map(|e| e.1).sum();
                if t > 0.0 {
                    let mut x = rng.random::<f32>() * t;
                    let mut pick = table[table.len() - 1];
                    for e in &table {
                        if x < e.1 {
                            pick = *e;
                            break;
                        }
                        x -= e.1;
                    }
                    chosen = Some((pick.0, pick.2));
                }
            }
        }
        // The matched choice: where the paper's draw leaves a choice (copies
        // that disagree, which jump, where a random start goes), the
        // candidate whose exemplar neighbourhood best matches the
        // synthesised neighbours wins.
        if let Some(m) = matcher
            && !suggestions.is_empty()
        {
            let copies_disagree = || {
                let mut first = None;
                suggestions
                    .iter()
                    .filter(|sg| sg.copy_mass > 0.0)
                    .any(|sg| {
                        let f = *first.get_or_insert(sg.copy);
                        (sg.copy - f).abs().max_element() > 0.5
                    })
            };
            let decide = match chosen {
                Some((_, Some(_))) => copies_disagree(),
                _ => true,
            };
            if decide {
                m.gather(
                    topo,
                    offsets,
                    &texel,
                    &done,
                    v,
                    &mut seen_buf,
                    &mut mark,
                    &mut nb_buf,
                );
                if !nb_buf.is_empty() {
                    cands.clear();
                    match chosen {
                        Some((_, Some(_))) => {
                            for sg in suggestions.iter().filter(|sg| sg.copy_mass > 0.0) {
                                cands.push((sg.copy, Some(sg.patch)));
                            }
                        }
                        _ => {
                            // Every valid jump of every neighbour, except
                            // those that continue a neighbour's copy.
                            for sg in suggestions.iter().filter(|sg| sg.jump_mass > 0.0) {
                                each_jump(sg, &mut |p, _| {
                                    let continues = suggestions
                                        .iter()
                                        .any(|c| (c.copy - p).abs().max_element() <= 0.5);
                                    if valid(p) && !continues {
                                        cands.push((p, None));
                                    }
                                });
                            }
                            if chosen.is_none() {
                                for _ in 0..RANDOM_CANDIDATES {
                                    cands.push((random_start(&mut rng, bmin, bmax), None));
                                }
                            }
                        }
                    }
                    // The first least error (a candidate that cannot beat
                    // the best so far stops early and is not taken).
                    let mut best = None;
                    for &(p, patch) in &cands {
                        let bound = best.map_or(f32::INFINITY, |b: (f32, Vec2, _)| b.0);
                        let e = m.error(p, &nb_buf, bound);
                        if e < bound {
                            best = Some((e, p, patch));
                        }
                    }
                    if let Some((_, p, patch)) = best {
                        if chosen.is_none() {
                            // Counted as a jump below, not as random.
                            out.matched_starts += 1;
                        }
                        chosen = Some((p, patch));
                    }
                }
            }
        }
        // The texel area of v: its mean squared edge offset.
        let step = if hi_i > lo_i {
            offsets[lo_i..hi_i]
                .iter()
                .map(|o| o.length_squared())
                .sum::<f32>()
                / (hi_i - lo_i) as f32
        } else {
            0.0
        };
        let mut from_patch = None;
        let chosen = match chosen {
            Some((p, copied)) => {
                if copied.is_none() {
                    out.jumps += 1;
                }
                from_patch = copied;
                p
            }
            None => {
                out.random_assignments += 1;
                let lo = -bmin;
                let hi = max - bmax;
                if !settings.tileable && !hi.cmpge(lo).all() {
                    out.unfit += 1;
                }
                random_start(&mut rng, bmin, bmax)
            }
        };
        let patch = from_patch.unwrap_or_else(|| {
            patch_area.push(0.0);
            (patch_area.len() - 1) as u32
        });
        patch_of[vi] = patch;
        patch_area[patch as usize] += step;
        texel[vi] = if settings.tileable {
            wrap(chosen)
        } else {
            chosen
        };
        done[vi] = true;
    }
    out.texel = texel;
    out.patch = patch_of;
    out
}

/// The vertices within `rings` edges of a seam: an edge whose endpoints
/// belong to different patches ([`SurfaceSynthOutput::patch`]).
pub fn seam_band(topo: &Topology, patch: &[u32], rings: u32) -> Vec<bool> {
    let n = topo.vertex_count();
    let mut band: Vec<bool> = (0..n as u32)
        .into_par_iter()
        .map(|v| {
            let p = patch[v as usize];
            topo.neighbours(v).iter().any(|&w| patch[w as usize] != p)
        })
        .collect();
    let mut frontier: Vec<u32> = (0..n as u32).filter(|&v| band[v as usize]).collect();
    for _ in 0..rings {
        let mut next = Vec::new();
        for &v in &frontier {
            for &w in topo.neighbours(v) {
                if !band[w as usize] {
                    band[w as usize] = true;
                    next.push(w);
                }
            }
        }
        frontier = next;
    }
    band
}

/// The texture-space offset of every face side: entry `c` is the offset of
/// the edge from corner `c`'s vertex to the next corner's (§6.3), taken from
/// `offsets` ([`edge_offsets`]); zero for a side joining a vertex to itself.
/// With these, [`corner_uvs`] needs neither the topology nor the per-edge
/// offsets, which can be dropped first (together some 180 bytes per vertex).
pub fn corner_side_offsets(mesh: &PolyMesh, topo: &Topology, offsets: &[Vec2]) -> Vec<Vec2> {
    let mut out = vec![Vec2::ZERO; mesh.corner_count()];
    fill_by_face(mesh, &mut out, |f, slots| {
        let face = mesh.face(f);
        let k = face.len();
        for (i, slot) in slots.iter_mut().enumerate() {
            *slot = offset_between(topo, offsets, face[i], face[(i + 1) % k]).unwrap_or(Vec2::ZERO);
        }
    });
    out
}

/// Fills `out` (one entry per corner, or per fan triangle when its length is
/// `corners − 2·faces`) in parallel, handing `fill(f, slots)` face `f`'s
/// entries. Exact-size output: no intermediate lists.
fn fill_by_face<T: Send>(mesh: &PolyMesh, out: &mut [T], fill: impl Fn(usize, &mut [T]) + Sync) {
    let per_triangle = out.len() != mesh.corner_count();
    // First entry of face f: its first corner, or its first fan triangle
    // (face_start[f] − 2f: each face of k corners has k − 2 triangles).
    let first = |f: usize| {
        let c = mesh.face_start[f] as usize;
        if per_triangle { c - 2 * f } else { c }
    };
    let nf = mesh.face_count();
    // Faces in chunks of about 4096 entries, cut at face boundaries.
    let mut rest = &mut out[..];
    let mut chunks = Vec::new();
    let mut f = 0;
    while f < nf {
        let mut g = f + 1;
        while g < nf && first(g) - first(f) < 4096 {
            g += 1;
        }
        let len = if g < nf { first(g) } else { first(nf) } - first(f);
        let (head, tail) = rest.split_at_mut(len);
        chunks.push((f..g, head));
        rest = tail;
        f = g;
    }
    chunks.into_par_iter().for_each(|(faces, mut slots)| {
        for f in faces {
            let n = mesh.face_corners(f).len() - if per_triangle { 2 } else { 0 };
            let (mine, more) = std::mem::take(&mut slots).split_at_mut(n);
            fill(f, mine);
            slots = more;
        }
    });
}

/// Address (exemplar pixels, before the half-pixel shift) of face corner `j`
/// seen from base corner `b` of face `f`: the base address plus the edge
/// offsets along the shorter way round the face (for a triangle always the
/// direct edge, which the validity test of §6.5 covers); halfway round a
/// polygon, the mean of both ways. A step backwards subtracts the side's
/// offset: offsets are antisymmetric exactly.
fn walk(mesh: &PolyMesh, sides: &[Vec2], texel: &[Vec2], f: usize, b: usize, j: usize) -> Vec2 {
    let face = mesh.face(f);
    let side = &sides[mesh.face_corners(f)];
    let k = face.len();
    let base = texel[face[b] as usize];
    let fwd = (j + k - b) % k;
    let forward = |count: usize| {
        let mut p = base;
        let mut i = b;
        for _ in 0..count {
            p += side[i];
            i = (i + 1) % k;
        }
        p
    };
    let backward = |count: usize| {
        let mut p = base;
        let mut i = b;
        for _ in 0..count {
            i = (i + k - 1) % k;
            p += -side[i];
        }
        p
    };
    let back = k - fwd;
    if fwd == 0 {
        base
    } else if fwd < back {
        forward(fwd)
    } else if back < fwd {
        backward(back)
    } else {
        (forward(fwd) + backward(back)) * 0.5
    }
}

/// Exemplar pixel address to `[0, 1]` texture coordinates (pixel centres).
#[inline]
fn to_uv(p: Vec2, dims: (u32, u32)) -> Vec2 {
    let inv = Vec2::new(1.0 / dims.0 as f32, 1.0 / dims.1 as f32);
    (p + Vec2::splat(0.5)) * inv
}

/// The three base-vertex layers of the §6.5 blend, compactly: the per-vertex
/// texel addresses and per-corner side offsets they are walked from (8 bytes
/// per vertex + 8 per corner, ~56 bytes per vertex on a triangle mesh,
/// instead of 72 per fan triangle, ~144 per vertex). [`Self::triangle`]
/// makes a fan triangle's layers on request, bit for bit what a full array
/// ([`Self::to_vec`]) holds.
#[derive(Clone, Debug, Default)]
pub struct BlendLayers {
    /// Per vertex, the synthesised exemplar address (pixels).
    pub texel: Vec<Vec2>,
    /// Per corner, the offset to the next corner of its face
    /// ([`corner_side_offsets`]).
    pub sides: Vec<Vec2>,
    /// Exemplar width and height in pixels.
    pub dims: (u32, u32),
}

impl BlendLayers {
    /// Fan triangles of `mesh` (`corners − 2·faces`).
    pub fn triangle_count(mesh: &PolyMesh) -> usize {
        mesh.corner_count().saturating_sub(2 * mesh.face_count())
    }

    /// Whether the layers were made for `mesh`.
    pub fn fits(&self, mesh: &PolyMesh) -> bool {
        self.texel.len() == mesh.vertex_count() && self.sides.len() == mesh.corner_count()
    }

    /// Layers of fan triangle `t` (local corners `0, t + 1, t + 2`) of face
    /// `f`: per base corner, the UVs of the three corners.
    pub fn face_triangle(&self, mesh: &PolyMesh, f: usize, t: usize) -> [[Vec2; 3]; 3] {
        let local = [0, t + 1, t + 2];
        local
            .map(|b| local.map(|j| to_uv(walk(mesh, &self.sides, &self.texel, f, b, j), self.dims)))
    }

    /// Layers of fan triangle `t` of [`PolyMesh::triangulate_corners`]
    /// (its face found by binary search).
    pub fn triangle(&self, mesh: &PolyMesh, t: usize) -> [[Vec2; 3]; 3] {
        // First fan triangle of face f: face_start[f] − 2f. Faces without
        // triangles share their successor's first, so the last face whose
        // first is ≤ t is the one holding t.
        let first = |f: usize| mesh.face_start[f] as usize - 2 * f;
        let (mut lo, mut hi) = (0usize, mesh.face_count());
        while hi - lo > 1 {
            let mid = (lo + hi) / 2;
            if first(mid) <= t {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        self.face_triangle(mesh, lo, t - first(lo))
    }

    /// Every fan triangle's layers (72 bytes each), for tests and small meshes.
    pub fn to_vec(&self, mesh: &PolyMesh) -> Vec<[[Vec2; 3]; 3]> {
        let mut out = vec![[[Vec2::ZERO; 3]; 3]; Self::triangle_count(mesh)];
        fill_by_face(mesh, &mut out, |f, slots| {
            for (t, layers) in slots.iter_mut().enumerate() {
                *layers = self.face_triangle(mesh, f, t);
            }
        });
        out
    }
}

/// Blend layers per fan triangle as the consumers read them: a full array
/// (tests, single-base UVs repeated three times) or [`BlendLayers`] of a mesh.
#[derive(Clone, Copy, Debug)]
pub enum Blend<'a> {
    /// One entry per fan triangle.
    Full(&'a [[[Vec2; 3]; 3]]),
    /// Made on request from the compact form.
    Compact {
        layers: &'a BlendLayers,
        mesh: &'a PolyMesh,
    },
}

impl<'a> From<&'a [[[Vec2; 3]; 3]]> for Blend<'a> {
    fn from(layers: &'a [[[Vec2; 3]; 3]]) -> Self {
        Blend::Full(layers)
    }
}

impl<'a> From<&'a Vec<[[Vec2; 3]; 3]>> for Blend<'a> {
    fn from(layers: &'a Vec<[[Vec2; 3]; 3]>) -> Self {
        Blend::Full(layers)
    }
}

impl Blend<'_> {
    /// Number of fan triangles.
    pub fn len(&self) -> usize {
        match self {
            Blend::Full(l) => l.len(),
            Blend::Compact { mesh, .. } => BlendLayers::triangle_count(mesh),
        }
    }

    /// Whether there are no triangles.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Layers of fan triangle `t`.
    #[inline]
    pub fn get(&self, t: usize) -> [[Vec2; 3]; 3] {
        match self {
            Blend::Full(l) => l[t],
            Blend::Compact { layers, mesh } => layers.triangle(mesh, t),
        }
    }

    /// [`Self::get`] when the caller knows the triangle's face `f` (no search).
    #[inline]
    pub fn get_in_face(&self, t: usize, f: usize) -> [[Vec2; 3]; 3] {
        match self {
            Blend::Full(l) => l[t],
            Blend::Compact { layers, mesh } => {
                layers.face_triangle(mesh, f, t - (mesh.face_start[f] as usize - 2 * f))
            }
        }
    }
}

/// Per-corner texture coordinates (§6.5), in `[0, 1]` units of the exemplar
/// (v down). Returns the single-base UVs (each face's first corner as base),
/// and the blend layers: for every fan triangle of
/// [`PolyMesh::triangulate_corners`] the UVs of its three corners for each
/// of the three base choices (compactly: `sides` and a copy of `texel`).
/// `sides` come from [`corner_side_offsets`].
pub fn corner_uvs(
    mesh: &PolyMesh,
    sides: Vec<Vec2>,
    texel: &[Vec2],
    dims: (u32, u32),
) -> (Vec<Vec2>, BlendLayers) {
    let mut single = vec![Vec2::ZERO; mesh.corner_count()];
    fill_by_face(mesh, &mut single, |f, slots| {
        for (j, uv) in slots.iter_mut().enumerate() {
            *uv = to_uv(walk(mesh, &sides, texel, f, 0, j), dims);
        }
    });
    let blend = BlendLayers {
        texel: texel.to_vec(),
        sides,
        dims,
    };
    (single, blend)
}

impl JumpLookup for super::jump_map::JumpMap {
    fn dims(&self) -> (u32, u32) {
        (self.width(), self.height())
    }
    #[inline]
    fn for_each_jump<F: FnMut(u32, u32, f32)>(&self, x: u32, y: u32, mut f: F) {
        for j in self.jumps_at(x, y) {
            f(j.to.x, j.to.y, j.weight);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A jump map with no jumps: synthesis must then copy everywhere.
    struct NoJumps(u32, u32);
    impl JumpLookup for NoJumps {
        fn dims(&self) -> (u32, u32) {
            (self.0, self.1)
        }
        fn for_each_jump<F: FnMut(u32, u32, f32)>(&self, _: u32, _: u32, _: F) {}
    }

    fn plane(n: usize) -> PolyMesh {
        let p = (0..n * n)
            .map(|i| Vec3::new((i % n) as f32, -((i / n) as f32), 0.0))
            .collect();
        let mut faces = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = (y * n + x) as u32;
                let n = n as u32;
                faces.push([i, i + n, i + n + 1]);
                faces.push([i, i + n + 1, i + 1]);
            }
        }
        PolyMesh::from_triangles(p, &faces)
    }

    #[test]
    fn without_jumps_a_plane_is_a_translated_copy() {
        let m = plane(8);
        let t = Topology::build(&m);
        let frames = vec![TangentFrame::from_up(Vec3::Z, Vec3::Y); m.vertex_count()];
        let scale = vec![1.0; m.vertex_count()];
        let off = edge_offsets(&m.positions, &frames, &scale, &t);
        // +x world is +x pixels; world -y (down the grid) is +y pixels.
        assert_eq!(offset_between(&t, &off, 0, 1), Some(Vec2::new(1.0, 0.0)));
        assert_eq!(offset_between(&t, &off, 0, 8), Some(Vec2::new(0.0, 1.0)));
        let s = SurfaceSynthSettings {
            tileable: true,
            ..Default::default()
        };
        let out = synthesize_surface(&t, &off, &NoJumps(32, 32), &s, &Default::default());
        assert_eq!(out.random_assignments, 1, "only the start is random");
        let p0 = out.texel[0];
        for (v, p) in out.texel.iter().enumerate() {
            let expect = p0 + Vec2::new((v % 8) as f32, (v / 8) as f32);
            let d = (*p - expect).abs();
            let d = Vec2::new(d.x.min(32.0 - d.x), d.y.min(32.0 - d.y));
            assert!(d.max_element() < 1e-3, "vertex {v}: {p} vs {expect}");
        }
    }

    /// A unit grid plane at one pixel per edge and its offsets.
    fn unit_plane(n: usize) -> (PolyMesh, Topology, Vec<Vec2>) {
        let m = plane(n);
        let t = Topology::build(&m);
        let frames = vec![TangentFrame::from_up(Vec3::Z, Vec3::Y); m.vertex_count()];
        let off = edge_offsets(&m.positions, &frames, &vec![1.0; m.vertex_count()], &t);
        (m, t, off)
    }

    #[test]
    fn pixel_aligned_starts_keep_every_address_on_a_pixel_centre() {
        let (_, t, off) = unit_plane(24);
        for aligned in [false, true] {
            let s = SurfaceSynthSettings {
                pixel_aligned: aligned,
                seed: 5,
                ..Default::default()
            };
            let out = synthesize_surface(&t, &off, &NoJumps(16, 16), &s, &Default::default());
            // A 24² plane in a 16² exemplar: copies run out, so starts recur.
            assert!(out.random_assignments > 1);
            let on_centres = out
                .texel
                .iter()
                .all(|p| (*p - p.round()).abs().max_element() < 1e-4);
            assert_eq!(on_centres, aligned, "pixel_aligned {aligned}");
        }
    }

    #[test]
    fn patches_stop_copying_at_the_area_cap() {
        let (_, t, off) = unit_plane(40);
        let area = |cap: f32| {
            let s = SurfaceSynthSettings {
                tileable: true,
                max_patch_area: cap,
                ..Default::default()
            };
            let out = synthesize_surface(&t, &off, &NoJumps(32, 32), &s, &Default::default());
            let mut count = vec![0usize; out.patch.iter().max().map_or(0, |&p| p as usize + 1)];
            for &p in &out.patch {
                count[p as usize] += 1;
            }
            count.into_iter().max().unwrap_or(0)
        };
        // Without a cap one start covers the whole 40² plane. With a cap of
        // a quarter of the 32² exemplar (256 pixels), each vertex counting
        // its mean squared edge offset (4/3 of a pixel on this triangulated
        // grid: four unit edges and two diagonals), a patch stops at 192
        // vertices plus the front that completes it.
        assert_eq!(area(0.0), 1600);
        let capped = area(0.25);
        assert!((192..=192 + 40).contains(&capped), "largest patch {capped}");
    }

    #[test]
    fn seam_band_holds_the_vertices_next_to_another_patch() {
        let (m, t, _) = unit_plane(10);
        // Two patches split at x = 5.
        let patch: Vec<u32> = (0..m.vertex_count())
            .map(|v| u32::from(v % 10 >= 5))
            .collect();
        let band = seam_band(&t, &patch, 0);
        for (v, &b) in band.iter().enumerate() {
            let x = v % 10;
            // The grid's diagonals reach one column across.
            assert_eq!(b, x == 4 || x == 5, "vertex {v}");
        }
        let wider = seam_band(&t, &patch, 1);
        assert!((0..m.vertex_count()).all(|v| wider[v] == (3..=6).contains(&(v % 10))));
    }

    #[test]
    fn clamped_addresses_keep_one_rings_inside() {
        let m = plane(12);
        let t = Topology::build(&m);
        let frames = vec![TangentFrame::from_up(Vec3::Z, Vec3::Y); m.vertex_count()];
        let scale = vec![1.5; m.vertex_count()];
        let off = edge_offsets(&m.positions, &frames, &scale, &t);
        let s = SurfaceSynthSettings::default();
        let out = synthesize_surface(&t, &off, &NoJumps(10, 10), &s, &Default::default());
        assert_eq!(out.unfit, 0);
        for v in 0..m.vertex_count() as u32 {
            for &w in t.neighbours(v) {
                let q = out.texel[v as usize] + offset_between(&t, &off, v, w).unwrap();
                assert!(q.cmpge(Vec2::splat(-1e-3)).all() && q.cmple(Vec2::splat(9.001)).all());
            }
        }
        let sides = corner_side_offsets(&m, &t, &off);
        let (single, compact) = corner_uvs(&m, sides, &out.texel, (10, 10));
        let blend = compact.to_vec(&m);
        for (t, layers) in blend.iter().enumerate() {
            assert_eq!(compact.triangle(&m, t), *layers, "triangle {t}");
        }
        assert!(
            single
                .iter()
                .all(|uv| uv.cmpge(Vec2::ZERO).all() && uv.cmple(Vec2::ONE).all())
        );
        assert_eq!(blend.len(), m.face_count());
        // A triangle's layers differ only by where the base vertex sits.
        for (f, layers) in blend.iter().enumerate() {
            let e01 = layers[0][1] - layers[0][0];
            let e01b = layers[1][1] - layers[1][0];
            assert!((e01 - e01b).length() < 1e-5, "face {f}: edge offsets agree");
        }
    }
}
