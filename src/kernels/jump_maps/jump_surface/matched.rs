//! The matched choice of jump-map surface synthesis (an extension: where
//! the draw leaves a choice, the candidate whose exemplar neighbourhood best
//! matches the synthesised vertices wins) and the seam band.

use super::*;
use crate::image::Image;
use crate::image::sample::Wrap;
use crate::kernels::jump_maps::vertex_order::vertex_order;
use crate::mesh::Topology;
use glam::Vec2;
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

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
