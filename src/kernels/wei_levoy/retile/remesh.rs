//! Isotropic remeshing of one pyramid level: Botsch & Kobbelt, "A remeshing
//! approach to multiresolution modeling", SGP 2004, §4, with a vertex-count
//! controller on top.
//!
//! Each iteration, for the current target edge length `L`:
//! 1. split every edge longer than `4/3·L` at its midpoint (seeded random
//!    order, repeated until none is left);
//! 2. collapse every edge shorter than `4/5·L`, the shortest first (by
//!    length class, eighths of `4/5·L`, and in the mesh's spatial order
//!    within a class, see [`TriMesh::sort_spatially`]), unless the
//!    collapse would change the topology (link condition, valences, boundary
//!    rules in [`collapse_ok`]), create an edge longer than `4/3·L`, or turn a
//!    triangle over. Both ends meet at the midpoint (Botsch & Kobbelt); where
//!    that is refused, one end goes into the other, which stays where it is
//!    (a vertex in the wall of a hole into one on its rim, where the
//!    midpoint would cut the rim's crease);
//! 3. flip edges that bring the valences of their four vertices closer to 6
//!    (interior) and 4 (boundary), unless that turns a triangle over;
//! 4. tangential relaxation: a few times, move each vertex towards the
//!    centroid of its neighbours within its tangent plane (boundary vertices
//!    along their boundary); then project it onto the reference surface
//!    (boundary vertices onto their own boundary loop); a move that would turn
//!    a triangle over is not taken;
//! 5. rescale `L` by `sqrt(V / V_target)` so the count converges to the target.
//!
//! The count in step 5 is that of the pieces that can follow the target
//! ([`Pieces`]): a connected piece whose share of the target by area is
//! below [`SMALL_PIECE`] vertices (a chip, a stray triangle of a scan) keeps
//! whatever few vertices its topology needs, and the rest of the surface
//! keeps the density asked for instead of being made coarser to pay for them.
//! The level's count then aims at the large pieces' shares plus what the
//! small ones hold.
//!
//! Afterwards the count is matched exactly by splitting the longest or
//! collapsing the shortest edges, and a few more flip and relaxation rounds
//! smooth the result. "Turned over" means the triangle normal has a
//! non-positive dot product with its previous normal or with the
//! reference-surface normal at any of its corners (a corner on a crease or a
//! corner of the input agrees if any input face through its point does), or
//! — for triangles whose
//! corners see normals more than about 45° apart, i.e. that straddle a crease
//! of the input — at the closest point of the input around its centroid
//! (found by walking the input's triangles from a corner's source triangle,
//! [`SurfaceProjector::project_local`], so the test costs the same on any
//! size of input). The per-corner and centroid tests keep triangles across
//! a sharp ridge from standing edge-on to one side of it.
//!
//! After each iteration's compaction the level's vertices and faces are
//! renumbered along a Morton curve ([`TriMesh::sort_spatially`]): the
//! sequential passes then walk the mesh in space order, and their cost per
//! vertex stays flat once the mesh no longer fits in the cache.
//!
//! Everything that changes connectivity is sequential; normals and projections
//! are computed in parallel into per-vertex arrays and applied in vertex
//! order, so the result does not depend on the number of threads.

use super::project::{SurfacePoint, SurfaceProjector};
use super::trimesh::{NONE, TriMesh, next, prev};
use crate::progress::Progress;
use glam::Vec3;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

/// Tangential relaxation steps before each projection onto the surface.
const SMOOTHING_STEPS: usize = 4;
/// Relaxation rounds (each `SMOOTHING_STEPS` steps and a projection) after
/// the vertex count is matched, before a last flip sweep and round.
const FINAL_ROUNDS: usize = 2;
/// Corner reference normals with a smaller dot product than this (about 45°
/// apart) mark a triangle straddling a crease of the input, which is then also
/// checked at its centroid.
const CREASE_COS: f32 = 0.7;
/// Length classes (equal fractions of the collapse threshold) in which
/// short edges are collapsed, shortest class first.
const COLLAPSE_CLASSES: u32 = 8;
/// Upper bound on split or collapse sweeps per iteration.
const MAX_SWEEPS: usize = 16;

/// What one level should become.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LevelPlan {
    /// Vertex count to reach.
    pub target_vertices: usize,
    /// First guess of the target edge length (model units).
    pub edge_length: f32,
    /// Remeshing iterations before the count is matched.
    pub iterations: u32,
    pub seed: u64,
}

/// The work of remeshing one level, for progress, in vertex-iterations (one
/// vertex through one split–collapse–flip–relax iteration): the first
/// iteration, each later one, and the final count matching and smoothing.
///
/// Measured on the bunny (1 839 vertices) remeshed to 40 k, 82 k and 160 k
/// vertices: a later iteration costs about the same per target vertex
/// (5–7 µs), the final step about 2.5 iterations, and the first iteration,
/// which grows (or shrinks) the mesh from what it starts with, 4.4, 7.8 and
/// 11.7 iterations: about `1 + 0.13 · (ratio − 1)` for a vertex-count
/// ratio of 22, 44 and 87 between the target and the start.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LevelWork {
    pub first: u64,
    pub each: u64,
    pub last: u64,
    pub iterations: u32,
}

impl LevelWork {
    pub(crate) fn of(target: usize, start: usize, iterations: u32) -> Self {
        let target = target.max(1) as f64;
        let start = start.max(1) as f64;
        let ratio = target.max(start) / target.min(start);
        Self {
            first: (target * (1.0 + 0.13 * (ratio - 1.0))).round() as u64,
            each: target as u64,
            last: (2.5 * target).round() as u64,
            iterations,
        }
    }

    /// The level's work in all.
    pub(crate) fn total(&self) -> u64 {
        match self.iterations {
            0 => self.last,
            n => self.first + self.each * u64::from(n - 1) + self.last,
        }
    }
}

/// The shares of a level's first iteration (see [`LevelWork`]) spent
/// splitting and collapsing: growing the bunny to 160 k vertices took 1.4 s
/// to split and 11.6 s to collapse (on the split mesh, not yet sorted) of
/// 13.8 s.
const FIRST_SPLIT_SHARE: f64 = 0.10;
const FIRST_COLLAPSE_SHARE: f64 = 0.84;

/// Reusable buffers of the sequential passes.
#[derive(Default)]
pub(crate) struct Scratch {
    stamp: Vec<u32>,
    epoch: u32,
    ring_a: Vec<u32>,
    ring_b: Vec<u32>,
}

impl Scratch {
    fn next_epoch(&mut self, vertices: usize) -> u32 {
        if self.stamp.len() < vertices {
            self.stamp.resize(vertices, 0);
        }
        self.epoch = self.epoch.wrapping_add(1);
        if self.epoch == 0 {
            self.stamp.fill(0);
            self.epoch = 1;
        }
        self.epoch
    }
}

/// A connected piece with a smaller share of a level's target than this
/// (vertices, by area) does not steer the edge length: it keeps the few
/// vertices its topology needs (a closed chip at least 4, a lone triangle 3).
pub(crate) const SMALL_PIECE: f64 = 16.0;

/// The input's connected pieces: which piece each input triangle belongs
/// to and each piece's share of the total area.
#[derive(Clone, Debug, Default)]
pub(crate) struct Pieces {
    /// Piece of each input triangle (the faces of the projector).
    pub tri_piece: Vec<u32>,
    /// Area of each piece over the total area.
    pub area_share: Vec<f64>,
}

impl Pieces {
    /// The pieces of a prepared input mesh (triangle `f` = half-edges `3f..3f+3`).
    pub(crate) fn of(mesh: &TriMesh) -> Self {
        let (piece, count) = super::prepare::component_labels(mesh);
        let faces = mesh.halfedge_slots() / 3;
        let mut tri_piece = vec![0u32; faces];
        let mut area = vec![0.0f64; count as usize];
        for (f, tp) in tri_piece.iter_mut().enumerate() {
            let h = 3 * f as u32;
            if !mesh.alive_halfedge(h) {
                continue;
            }
            let c = piece[mesh.vert[h as usize] as usize];
            *tp = c;
            area[c as usize] += 0.5 * f64::from(mesh.face_normal_scaled(h).length());
        }
        let total: f64 = area.iter().sum();
        let area_share = area
            .iter()
            .map(|a| if total > 0.0 { a / total } else { 0.0 })
            .collect();
        Self {
            tri_piece,
            area_share,
        }
    }

    /// Per piece, the live vertices of `mesh` lying on it (by their source face).
    pub(crate) fn counts(&self, mesh: &TriMesh, out: &mut Vec<usize>) {
        out.clear();
        out.resize(self.area_share.len(), 0);
        for v in 0..mesh.pos.len() {
            if mesh.out[v] != NONE
                && let Some(&c) = self.tri_piece.get(mesh.src_face[v] as usize)
            {
                out[c as usize] += 1;
            }
        }
    }

    /// The share of a level aiming at `target` vertices that falls on the
    /// pieces that follow the target (0 when every piece is small).
    pub(crate) fn large_share(&self, target: usize) -> f64 {
        self.area_share
            .iter()
            .map(|a| a * target as f64)
            .filter(|&s| s >= SMALL_PIECE)
            .sum()
    }

    /// For a level aiming at `target` vertices: `(vertices on the pieces
    /// that follow the target, their share of it, vertices held by small
    /// pieces)`, given per-piece `counts`.
    pub(crate) fn split(&self, target: usize, counts: &[usize]) -> (usize, f64, usize) {
        let (mut free, mut share, mut held) = (0, 0.0, 0);
        for (&a, &n) in self.area_share.iter().zip(counts) {
            let s = a * target as f64;
            if s < SMALL_PIECE {
                held += n;
            } else {
                free += n;
                share += s;
            }
        }
        (free, share, held)
    }
}

/// Remeshes `mesh` in place onto `proj`; returns the final target edge
/// length and the vertex count the level aimed at in the end: the plan's
/// target, with each small piece's share replaced by what it holds (see
/// [`Pieces`]). `progress` advances by each iteration's [`LevelWork`] and
/// once more for the final count matching and smoothing; the current part
/// has `LevelWork::of(target, live vertices at the start, iterations)
/// .total()` steps.
pub(crate) fn remesh_level(
    mesh: &mut TriMesh,
    proj: &SurfaceProjector,
    pieces: &Pieces,
    plan: &LevelPlan,
    progress: &Progress,
) -> (f32, usize) {
    let work = LevelWork::of(plan.target_vertices, mesh.live_vertices, plan.iterations);
    let mut rng = Pcg64Mcg::seed_from_u64(plan.seed);
    let mut scratch = Scratch::default();
    let mut len = plan.edge_length;
    let mut counts = Vec::new();
    let mut target = plan.target_vertices.max(1);
    for iteration in 0..plan.iterations {
        let _span = tracing::debug_span!("remesh_iteration", iteration).entered();
        // The first iteration can be most of the level (see `LevelWork`):
        // it reports its split and, step by step, its collapse.
        let (split_steps, collapse_steps) = if iteration == 0 {
            let split = (FIRST_SPLIT_SHARE * work.first as f64) as u64;
            (split, (FIRST_COLLAPSE_SHARE * work.first as f64) as u64)
        } else {
            (0, 0)
        };
        {
            let _span = tracing::debug_span!("split").entered();
            split_long_edges(mesh, 4.0 / 3.0 * len, &mut rng);
            progress.inc(split_steps);
        }
        {
            let _span = tracing::debug_span!("collapse").entered();
            let collapse_progress = (collapse_steps > 0).then_some((progress, collapse_steps));
            collapse_short_edges(
                mesh,
                proj,
                0.8 * len,
                4.0 / 3.0 * len,
                &mut scratch,
                collapse_progress,
            );
            mesh.compact();
            mesh.sort_spatially();
        }
        {
            let _span = tracing::debug_span!("equalize").entered();
            equalize_valences(mesh, proj);
        }
        {
            let _span = tracing::debug_span!("relax").entered();
            relax(mesh, proj, SMOOTHING_STEPS);
        }
        pieces.counts(mesh, &mut counts);
        let (free, share, held) = pieces.split(plan.target_vertices, &counts);
        let ratio = if share > 0.0 {
            (free as f64 / share).sqrt() as f32
        } else {
            (mesh.live_vertices as f32 / plan.target_vertices.max(1) as f32).sqrt()
        };
        if share > 0.0 {
            target = (share.round() as usize + held).max(1);
        }
        len *= ratio.clamp(0.5, 2.0);
        progress.inc(if iteration == 0 {
            work.first - split_steps - collapse_steps
        } else {
            work.each
        });
    }
    match_vertex_count(mesh, proj, target, len, &mut rng, &mut scratch);
    mesh.compact();
    mesh.sort_spatially();
    equalize_valences(mesh, proj);
    for _ in 0..FINAL_ROUNDS {
        relax(mesh, proj, SMOOTHING_STEPS);
    }
    equalize_valences(mesh, proj);
    relax(mesh, proj, SMOOTHING_STEPS);
    progress.inc(work.last);
    (len, target)
}

/// Ties every vertex of a freshly prepared `mesh` (whose faces are those of
/// `proj`) to the input: its source face is one of its faces, at the corner
/// it is, and its reference normal is that face's normal.
pub(crate) fn attach_to_input(mesh: &mut TriMesh, proj: &SurfaceProjector) {
    for v in 0..mesh.pos.len() {
        let h = mesh.out[v];
        if h != NONE {
            mesh.src_face[v] = h / 3;
            let mut bary = [0.0; 3];
            bary[(h % 3) as usize] = 1.0;
            mesh.src_bary[v] = Vec3::from_array(bary);
            mesh.ref_normal[v] = proj.face_normal(h / 3);
        }
    }
}

/// Unique edges as `(a, b, squared length)`, one half-edge each.
fn edges_where(mesh: &TriMesh, keep: impl Fn(f32) -> bool) -> Vec<(u32, u32, f32)> {
    let mut out = Vec::new();
    for h in 0..mesh.halfedge_slots() as u32 {
        let t = mesh.twin[h as usize];
        if !mesh.alive_halfedge(h) || (t != NONE && t < h) {
            continue;
        }
        let (a, b) = (mesh.vert[h as usize], mesh.to(h));
        let l2 = (mesh.pos[a as usize] - mesh.pos[b as usize]).length_squared();
        if keep(l2) {
            out.push((a, b, l2));
        }
    }
    out
}

fn split_long_edges(mesh: &mut TriMesh, hi: f32, rng: &mut Pcg64Mcg) {
    let hi2 = hi * hi;
    for _ in 0..MAX_SWEEPS {
        let mut cands = edges_where(mesh, |l2| l2 > hi2);
        if cands.is_empty() {
            break;
        }
        cands.shuffle(rng);
        for (a, b, _) in cands {
            // A split only removes the edge it splits, so the rest stay valid.
            if let Some(h) = mesh.find_edge(a, b) {
                mesh.split(h);
            }
        }
    }
}

/// Collapses the edges shorter than `lo` (not making any longer than `hi`),
/// in sweeps; `progress`, when given, advances by its steps as candidates
/// are tried. The sweeps after the first try about as many candidates again
/// in all (measured: 1.13 M, then 0.29 M, 0.15 M and nine sweeps of
/// 0.11 M that collapse next to nothing), about 1.5 µs each, so the steps
/// are spread over twice the first sweep's candidates.
fn collapse_short_edges(
    mesh: &mut TriMesh,
    proj: &SurfaceProjector,
    lo: f32,
    hi: f32,
    scratch: &mut Scratch,
    progress: Option<(&Progress, u64)>,
) {
    let lo2 = lo * lo;
    let hidden = Progress::hidden();
    let (report, steps) = progress.unwrap_or((&hidden, 0));
    // Candidates tried, expected in all, and steps reported.
    let (mut tried, mut expected, mut reported) = (0usize, 0usize, 0u64);
    for _ in 0..MAX_SWEEPS {
        // Shortest length class first, and within a class in the mesh's
        // spatial order (edges_where follows the face order, which
        // `sort_spatially` made spatial): a strict shortest-first order
        // visits the mesh at random, and on a mesh bigger than the cache
        // every collapse test then misses it.
        let mut cands: Vec<(u32, u32, u32)> = edges_where(mesh, |l2| l2 < lo2)
            .into_iter()
            .map(|(a, b, l2)| {
                let class = (COLLAPSE_CLASSES as f32 * (l2 / lo2).sqrt()) as u32;
                (class.min(COLLAPSE_CLASSES - 1), a, b)
            })
            .collect();
        cands.sort_by_key(|c| c.0);
        if expected == 0 {
            expected = 2 * cands.len().max(1);
        }
        let mut done = 0;
        for &(_, a, b) in &cands {
            tried += 1;
            if steps > 0 && tried % 4096 == 0 {
                let now = (steps as f64 * (tried as f64 / expected as f64).min(1.0)) as u64;
                report.inc(now - reported);
                reported = now;
            }
            let Some(h) = mesh.find_edge(a, b) else {
                continue;
            };
            if mesh.edge_length(h) < lo && try_collapse(mesh, proj, h, hi, scratch) {
                done += 1;
            }
        }
        if done == 0 {
            break;
        }
    }
    report.inc(steps - reported);
}

/// How to collapse the edge of `h`: the half-edge to collapse (its origin
/// goes) and where the kept vertex lands. An interior vertex goes into a
/// boundary one, which stays put; otherwise both meet at the midpoint.
/// `None` for an interior edge between two boundary vertices, whose collapse
/// would pinch the surface.
pub(crate) fn collapse_plan(mesh: &TriMesh, h: u32) -> Option<(u32, Vec3)> {
    let a = mesh.vert[h as usize];
    let b = mesh.to(h);
    let t = mesh.twin[h as usize];
    let (pa, pb) = (mesh.pos[a as usize], mesh.pos[b as usize]);
    let (ba, bb) = (mesh.on_boundary[a as usize], mesh.on_boundary[b as usize]);
    if t == NONE {
        Some((h, 0.5 * (pa + pb)))
    } else if ba && bb {
        None
    } else if ba {
        Some((t, pa))
    } else if bb {
        Some((h, pb))
    } else {
        Some((h, 0.5 * (pa + pb)))
    }
}

/// Collapses the edge of `h` as [`collapse_plan`] says, if [`collapse_ok`].
fn try_collapse(
    mesh: &mut TriMesh,
    proj: &SurfaceProjector,
    h: u32,
    hi: f32,
    scratch: &mut Scratch,
) -> bool {
    let a = mesh.vert[h as usize];
    let b = mesh.to(h);
    let (pa, pb) = (mesh.pos[a as usize], mesh.pos[b as usize]);
    let Some((mut g, mut p)) = collapse_plan(mesh, h) else {
        return false;
    };
    let check = collapse_check(mesh, proj, g, p, hi, scratch);
    if check != Check::Ok {
        // Between two interior vertices, the midpoint may cut a crease or
        // corner of the input that one end lies on (a vertex in a wall next
        // to a rim): the other end then goes into that one, which stays.
        // (The topology does not depend on where they meet.)
        if check == Check::Topology || p == pa || p == pb {
            return false;
        }
        let t = mesh.twin[h as usize];
        if collapse_ok(mesh, proj, h, pb, hi, scratch) {
            (g, p) = (h, pb);
        } else if t != NONE && collapse_ok(mesh, proj, t, pa, hi, scratch) {
            (g, p) = (t, pa);
        } else {
            return false;
        }
    }
    let (ra, rb) = (mesh.ref_normal[a as usize], mesh.ref_normal[b as usize]);
    let keep = mesh.to(g);
    mesh.collapse(g, p);
    if p != pa && p != pb {
        let n = (ra + rb).normalize_or_zero();
        if n != Vec3::ZERO {
            mesh.ref_normal[keep as usize] = n;
        }
    }
    true
}

/// Whether collapsing `h` = a → b with b moved to `p` keeps the mesh a
/// manifold of the same topology with no edge longer than `hi` and no
/// triangle turned over.
///
/// Topology (Dey et al. 1999, "Topology preserving edge contraction"; Hoppe
/// et al. 1993): the common neighbours of `a` and `b` must be exactly the
/// vertices opposite the edge (link condition); the opposite vertices keep
/// valence ≥ 3 (≥ 2 on the boundary), which also rules out collapsing a
/// tetrahedron; a lone triangle is never collapsed; an interior edge may only
/// remove an interior vertex (checked by the caller together with the rule
/// that an interior edge between two boundary vertices stays).
pub(crate) fn collapse_ok(
    mesh: &TriMesh,
    proj: &SurfaceProjector,
    h: u32,
    p: Vec3,
    hi: f32,
    scratch: &mut Scratch,
) -> bool {
    collapse_check(mesh, proj, h, p, hi, scratch) == Check::Ok
}

/// Why a collapse is refused, if it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Check {
    Ok,
    /// The topology would change: refused wherever the vertices meet.
    Topology,
    /// An edge would grow too long or a triangle turn over: another
    /// meeting point may do.
    Shape,
}

/// [`collapse_ok`], saying why not.
fn collapse_check(
    mesh: &TriMesh,
    proj: &SurfaceProjector,
    h: u32,
    p: Vec3,
    hi: f32,
    scratch: &mut Scratch,
) -> Check {
    let a = mesh.vert[h as usize];
    let b = mesh.to(h);
    let t = mesh.twin[h as usize];
    let c = mesh.vert[prev(h) as usize];
    let d = if t == NONE {
        NONE
    } else {
        mesh.vert[prev(t) as usize]
    };
    if t == NONE {
        if mesh.twin[next(h) as usize] == NONE && mesh.twin[prev(h) as usize] == NONE {
            return Check::Topology;
        }
    } else if mesh.on_boundary[a as usize] {
        return Check::Topology;
    }
    for v in [c, d] {
        if v != NONE {
            let min = if mesh.on_boundary[v as usize] { 3 } else { 4 };
            if mesh.valence(v) < min {
                return Check::Topology;
            }
        }
    }
    let mut ring_a = std::mem::take(&mut scratch.ring_a);
    let mut ring_b = std::mem::take(&mut scratch.ring_b);
    mesh.ring(a, &mut ring_a);
    mesh.ring(b, &mut ring_b);
    let skip = [h / 3, if t == NONE { NONE } else { t / 3 }];
    // Until it is projected, the merged vertex must suit the surface at both ends.
    // Collapsed into `b` where it is, the merged vertex is `b`.
    let rb = mesh.ref_normal[b as usize];
    let refs = if p == mesh.pos[b as usize] {
        [rb, rb]
    } else {
        [mesh.ref_normal[a as usize], rb]
    };
    let p_at =
        (p == mesh.pos[b as usize]).then(|| (mesh.src_face[b as usize], mesh.src_bary[b as usize]));
    let check = match link_and_lengths_ok(mesh, (a, b, c, d), &ring_a, &ring_b, p, hi, scratch) {
        Check::Ok
            if fan_keeps_orientation(mesh, proj, a, skip, p, refs, p_at)
                && (p_at.is_some()
                    || fan_keeps_orientation(mesh, proj, b, skip, p, refs, None)) =>
        {
            Check::Ok
        }
        Check::Ok => Check::Shape,
        other => other,
    };
    scratch.ring_a = ring_a;
    scratch.ring_b = ring_b;
    check
}

fn link_and_lengths_ok(
    mesh: &TriMesh,
    (a, b, c, d): (u32, u32, u32, u32),
    ring_a: &[u32],
    ring_b: &[u32],
    p: Vec3,
    hi: f32,
    scratch: &mut Scratch,
) -> Check {
    let epoch = scratch.next_epoch(mesh.pos.len());
    for &x in ring_a {
        scratch.stamp[x as usize] = epoch;
    }
    for &x in ring_b {
        if scratch.stamp[x as usize] == epoch && x != c && x != d {
            return Check::Topology;
        }
    }
    let shared = if d == NONE { 3 } else { 4 };
    if ring_a.len() + ring_b.len() < 3 + shared {
        return Check::Topology;
    }
    let hi2 = hi * hi;
    let moved_b = p != mesh.pos[b as usize];
    let short = ring_a
        .iter()
        .filter(|&&x| x != b)
        .chain(ring_b.iter().filter(|&&x| moved_b && x != a))
        .all(|&x| (mesh.pos[x as usize] - p).length_squared() < hi2);
    if short { Check::Ok } else { Check::Shape }
}

/// Whether a triangle with (unnormalised) normal `n` agrees with the
/// reference normal `r` (a zero `r`, from a degenerate input face, says nothing).
#[inline]
fn agrees(n: Vec3, r: Vec3) -> bool {
    n.dot(r) > 0.0 || r == Vec3::ZERO
}

/// Where a corner of a new triangle lies on the input, if known: input
/// face and barycentric coordinates.
type CornerAt = Option<(u32, Vec3)>;

/// Whether the new triangle `corners` with normal `n` faces the way the
/// reference surface does: at each corner (reference normals `refs`), and,
/// when the corners' normals differ by more than a crease angle, also at the
/// closest point of the input around its centroid (walked to from input
/// face `hint`).
///
/// A corner on a crease or a corner of the input (`at`, where it lies on
/// the input) carries the normal of one of the faces meeting there, and the
/// triangle may lie on another: a wall triangle at the rim of a hole whose
/// corner took the top face's normal. Such a corner agrees when any input
/// face through its point does ([`SurfaceProjector::any_normal_at`]).
fn triangle_faces_surface(
    proj: &SurfaceProjector,
    n: Vec3,
    corners: [Vec3; 3],
    refs: [Vec3; 3],
    at: [CornerAt; 3],
    hint: u32,
) -> bool {
    let own = refs.map(|r| agrees(n, r));
    if !(0..3).all(|i| own[i] || corner_agrees(proj, n, refs[i], at[i])) {
        return false;
    }
    let centroid = (corners[0] + corners[1] + corners[2]) / 3.0;
    // A corner that agrees only through another face at its point is on a
    // crease: the triangle must then also face the way of the input's
    // closest point to its centroid (searched over the whole input, as the
    // final check of a level does, since a local walk may stop on the wrong
    // side of the crease).
    if own.contains(&false) {
        return proj
            .project_near(centroid, hint)
            .is_some_and(|sp| agrees(n, proj.face_normal(sp.face)));
    }
    let creased = refs[0].dot(refs[1]) < CREASE_COS
        || refs[1].dot(refs[2]) < CREASE_COS
        || refs[0].dot(refs[2]) < CREASE_COS;
    !creased
        || proj
            .project_local(centroid, hint)
            .is_none_or(|sp| agrees(n, proj.face_normal(sp.face)))
}

/// Whether normal `n` agrees with a corner's reference normal `r` or, on a
/// crease or corner of the input, with any input face through the point
/// `at` where the corner lies.
fn corner_agrees(proj: &SurfaceProjector, n: Vec3, r: Vec3, at: CornerAt) -> bool {
    agrees(n, r) || at.is_some_and(|(f, b)| proj.any_normal_at(f, b, |m| agrees(n, m)))
}

/// Whether moving vertex `v` to `p` keeps every face of its fan (except the
/// faces `skip`) facing the way it did and the way the reference surface
/// does ([`triangle_faces_surface`]); `refs` stand for the moved vertex's
/// reference normal (both must agree), and `p_at` is where `p` lies on the
/// input, if known.
fn fan_keeps_orientation(
    mesh: &TriMesh,
    proj: &SurfaceProjector,
    v: u32,
    skip: [u32; 2],
    p: Vec3,
    refs: [Vec3; 2],
    p_at: CornerAt,
) -> bool {
    let pv = mesh.pos[v as usize];
    let at = |x: u32| Some((mesh.src_face[x as usize], mesh.src_bary[x as usize]));
    mesh.fan(v).all(|g| {
        let f = g / 3;
        if f == skip[0] || f == skip[1] {
            return true;
        }
        let x = mesh.to(g);
        let y = mesh.vert[prev(g) as usize];
        let (px, py) = (mesh.pos[x as usize], mesh.pos[y as usize]);
        let old = (px - pv).cross(py - pv);
        let new = (px - p).cross(py - p);
        let (rx, ry) = (mesh.ref_normal[x as usize], mesh.ref_normal[y as usize]);
        new.dot(old) > 0.0
            && corner_agrees(proj, new, refs[1], p_at)
            && triangle_faces_surface(
                proj,
                new,
                [p, px, py],
                [refs[0], rx, ry],
                [p_at, at(x), at(y)],
                mesh.src_face[x as usize],
            )
    })
}

fn valences(mesh: &TriMesh) -> Vec<i32> {
    (0..mesh.pos.len() as u32)
        .into_par_iter()
        .map(|v| {
            if mesh.out[v as usize] == NONE {
                0
            } else {
                mesh.valence(v) as i32
            }
        })
        .collect()
}

/// One sweep of valence-improving edge flips.
fn equalize_valences(mesh: &mut TriMesh, proj: &SurfaceProjector) {
    let mut val = valences(mesh);
    let ideal = |mesh: &TriMesh, v: u32| if mesh.on_boundary[v as usize] { 4 } else { 6 };
    for h in 0..mesh.halfedge_slots() as u32 {
        let t = mesh.twin[h as usize];
        if !mesh.alive_halfedge(h) || t == NONE || t < h {
            continue;
        }
        let a = mesh.vert[h as usize];
        let b = mesh.to(h);
        let c = mesh.vert[prev(h) as usize];
        let d = mesh.vert[prev(t) as usize];
        let dev = |v: u32, delta: i32| {
            let e = val[v as usize] + delta - ideal(mesh, v);
            e * e
        };
        let before = dev(a, 0) + dev(b, 0) + dev(c, 0) + dev(d, 0);
        let after = dev(a, -1) + dev(b, -1) + dev(c, 1) + dev(d, 1);
        if after >= before {
            continue;
        }
        let min_after = |v: u32| if mesh.on_boundary[v as usize] { 2 } else { 3 };
        if val[a as usize] - 1 < min_after(a) || val[b as usize] - 1 < min_after(b) {
            continue;
        }
        if !flip_keeps_orientation(mesh, proj, h, [a, b, c, d]) || mesh.find_edge(c, d).is_some() {
            continue;
        }
        mesh.flip(h);
        val[a as usize] -= 1;
        val[b as usize] -= 1;
        val[c as usize] += 1;
        val[d as usize] += 1;
    }
}

/// Whether the interior edge of `h` may be flipped: its ends keep valence
/// ≥ 3 (≥ 2 on the boundary), the new edge does not exist yet, and no
/// triangle turns over.
pub(crate) fn flip_allowed(mesh: &TriMesh, proj: &SurfaceProjector, h: u32) -> bool {
    let t = mesh.twin[h as usize];
    if t == NONE {
        return false;
    }
    let a = mesh.vert[h as usize];
    let b = mesh.to(h);
    let c = mesh.vert[prev(h) as usize];
    let d = mesh.vert[prev(t) as usize];
    let keeps_valence = |v: u32| {
        let min = if mesh.on_boundary[v as usize] { 2 } else { 3 };
        mesh.valence(v) > min
    };
    keeps_valence(a)
        && keeps_valence(b)
        && flip_keeps_orientation(mesh, proj, h, [a, b, c, d])
        && mesh.find_edge(c, d).is_none()
}

/// Whether the triangles (d, c, a) and (c, d, b) replacing the two faces at
/// `h` face the way the old ones and the reference surface do.
fn flip_keeps_orientation(
    mesh: &TriMesh,
    proj: &SurfaceProjector,
    h: u32,
    [a, b, c, d]: [u32; 4],
) -> bool {
    let p = |v: u32| mesh.pos[v as usize];
    let r = |v: u32| mesh.ref_normal[v as usize];
    let old = mesh.face_normal_scaled(h).normalize_or_zero()
        + mesh
            .face_normal_scaled(mesh.twin[h as usize])
            .normalize_or_zero();
    let n1 = (p(c) - p(d)).cross(p(a) - p(d));
    let n2 = (p(d) - p(c)).cross(p(b) - p(c));
    let hint = mesh.src_face[c as usize];
    // Triangle (x, y, z) with normal n faces the surface.
    let faces = |n: Vec3, [x, y, z]: [u32; 3]| {
        let at = |v: u32| Some((mesh.src_face[v as usize], mesh.src_bary[v as usize]));
        triangle_faces_surface(
            proj,
            n,
            [p(x), p(y), p(z)],
            [r(x), r(y), r(z)],
            [at(x), at(y), at(z)],
            hint,
        )
    };
    n1.dot(n2) > 0.0
        && n1.dot(old) > 0.0
        && n2.dot(old) > 0.0
        && faces(n1, [d, c, a])
        && faces(n2, [c, d, b])
}

/// Area-weighted unit vertex normals of the current mesh (zero when dead).
fn vertex_normals(mesh: &TriMesh) -> Vec<Vec3> {
    (0..mesh.pos.len() as u32)
        .into_par_iter()
        .map(|v| {
            if mesh.out[v as usize] == NONE {
                return Vec3::ZERO;
            }
            mesh.fan(v)
                .map(|g| mesh.face_normal_scaled(g))
                .sum::<Vec3>()
                .normalize_or_zero()
        })
        .collect()
}

/// Where tangential relaxation would move vertex `v`: towards the centroid of
/// its neighbours within its tangent plane, or for a boundary vertex towards
/// the midpoint of its boundary neighbours along the boundary.
fn relaxed_position(mesh: &TriMesh, normals: &[Vec3], v: u32) -> Option<Vec3> {
    if mesh.out[v as usize] == NONE {
        return None;
    }
    let p = mesh.pos[v as usize];
    if mesh.on_boundary[v as usize] {
        let (i, o) = mesh.boundary_neighbours(v);
        let (pi, po) = (mesh.pos[i as usize], mesh.pos[o as usize]);
        let dir = (po - pi).normalize_or_zero();
        Some(p + dir * dir.dot(0.5 * (pi + po) - p))
    } else {
        let (sum, n) = mesh.fan(v).fold((Vec3::ZERO, 0u32), |(s, n), g| {
            (s + mesh.pos[mesh.to(g) as usize], n + 1)
        });
        let u = sum / n.max(1) as f32 - p;
        let nv = normals[v as usize];
        Some(p + u - nv * nv.dot(u))
    }
}

/// The closest point of the reference surface to vertex `v` (of its
/// boundary loop, for a boundary vertex).
fn projection(
    mesh: &TriMesh,
    proj: &SurfaceProjector,
    normals: &[Vec3],
    v: u32,
) -> Option<SurfacePoint> {
    let p = mesh.pos[v as usize];
    if mesh.out[v as usize] == NONE {
        None
    } else if mesh.on_boundary[v as usize] {
        proj.project_to_boundary(p, mesh.loop_id[v as usize])
    } else {
        proj.project_facing(p, normals[v as usize], mesh.src_face[v as usize])
    }
}

/// `steps` rounds of tangential relaxation, then a projection onto the
/// reference surface. Moves are computed in parallel and taken in vertex
/// order, each only if it turns no triangle over.
fn relax(mesh: &mut TriMesh, proj: &SurfaceProjector, steps: usize) {
    for _ in 0..steps {
        let normals = vertex_normals(mesh);
        let moves: Vec<Option<Vec3>> = {
            let m = &*mesh;
            (0..m.pos.len() as u32)
                .into_par_iter()
                .map(|v| relaxed_position(m, &normals, v))
                .collect()
        };
        for (v, mv) in moves.into_iter().enumerate() {
            let Some(p) = mv else { continue };
            let r = mesh.ref_normal[v];
            if fan_keeps_orientation(mesh, proj, v as u32, [NONE, NONE], p, [r, r], None) {
                mesh.pos[v] = p;
            }
        }
    }
    let normals = vertex_normals(mesh);
    let snapped: Vec<Option<SurfacePoint>> = {
        let m = &*mesh;
        (0..m.pos.len() as u32)
            .into_par_iter()
            .map(|v| projection(m, proj, &normals, v))
            .collect()
    };
    for (v, sp) in snapped.into_iter().enumerate() {
        let Some(sp) = sp else { continue };
        let r = proj.face_normal(sp.face);
        let at = Some((sp.face, sp.bary));
        if fan_keeps_orientation(mesh, proj, v as u32, [NONE, NONE], sp.point, [r, r], at) {
            mesh.pos[v] = sp.point;
            mesh.src_face[v] = sp.face;
            mesh.src_bary[v] = sp.bary;
            mesh.ref_normal[v] = r;
        }
    }
}

/// Splits the longest or collapses the shortest edges until the mesh has
/// `target` vertices (or no further collapse is allowed).
fn match_vertex_count(
    mesh: &mut TriMesh,
    proj: &SurfaceProjector,
    target: usize,
    len: f32,
    rng: &mut Pcg64Mcg,
    scratch: &mut Scratch,
) {
    if mesh.live_vertices < target {
        let mut cands: Vec<(f32, u32, u32, u32)> = edges_where(mesh, |_| true)
            .into_iter()
            .map(|(a, b, l2)| (l2, rng.random::<u32>(), a, b))
            .collect();
        cands.sort_unstable_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
        for &(_, _, a, b) in &cands {
            if mesh.live_vertices >= target {
                break;
            }
            if let Some(h) = mesh.find_edge(a, b) {
                mesh.split(h);
            }
        }
    }
    let hi = 1.5 * len;
    for _ in 0..MAX_SWEEPS {
        if mesh.live_vertices <= target {
            break;
        }
        let mut cands: Vec<(f32, u32, u32, u32)> = edges_where(mesh, |_| true)
            .into_iter()
            .map(|(a, b, l2)| (l2, rng.random::<u32>(), a, b))
            .collect();
        cands.sort_unstable_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
        let before = mesh.live_vertices;
        for &(_, _, a, b) in &cands {
            if mesh.live_vertices <= target {
                break;
            }
            if let Some(h) = mesh.find_edge(a, b) {
                try_collapse(mesh, proj, h, hi, scratch);
            }
        }
        if mesh.live_vertices == before {
            break;
        }
    }
}

/// Moves every vertex onto its closest point of the reference surface (its
/// boundary loop for boundary vertices) and records where that is.
pub(crate) fn snap_to_surface(mesh: &mut TriMesh, proj: &SurfaceProjector) {
    let normals = vertex_normals(mesh);
    let snapped: Vec<Option<SurfacePoint>> = {
        let m = &*mesh;
        (0..m.pos.len() as u32)
            .into_par_iter()
            .map(|v| projection(m, proj, &normals, v))
            .collect()
    };
    for (v, sp) in snapped.into_iter().enumerate() {
        if let Some(sp) = sp {
            mesh.pos[v] = sp.point;
            mesh.src_face[v] = sp.face;
            mesh.src_bary[v] = sp.bary;
            mesh.ref_normal[v] = proj.face_normal(sp.face);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::prepare::prepare;
    use super::*;
    use crate::mesh::builtin::{BuiltinOptions, builtin_mesh};

    /// Remeshes a builtin mesh to `target` vertices and checks the structure.
    fn remesh_builtin(name: &str, opts: &BuiltinOptions, target: usize) -> TriMesh {
        let input = builtin_mesh(name, opts).unwrap();
        let prep = prepare(&input).unwrap();
        let proj = SurfaceProjector::from_trimesh(&prep.mesh);
        let mut mesh = prep.mesh.clone();
        attach_to_input(&mut mesh, &proj);
        let plan = LevelPlan {
            target_vertices: target,
            edge_length: 0.1,
            iterations: 8,
            seed: 1,
        };
        let pieces = Pieces::of(&prep.mesh);
        remesh_level(&mut mesh, &proj, &pieces, &plan, &Progress::hidden());
        mesh.check().unwrap();
        mesh.compact();
        mesh.check().unwrap();
        mesh
    }

    #[test]
    fn closed_mesh_stays_a_valid_manifold_on_target() {
        let mesh = remesh_builtin("torus", &BuiltinOptions::default(), 700);
        assert_eq!(mesh.live_vertices, 700);
        assert!(mesh.on_boundary.iter().all(|&b| !b));
    }

    #[test]
    fn boundary_stays_on_the_boundary_loop() {
        let opts = BuiltinOptions {
            resolution: [12, 12],
            ..BuiltinOptions::default()
        };
        let mesh = remesh_builtin("jittered_plane", &opts, 400);
        assert_eq!(mesh.live_vertices, 400);
        // The plane spans [-1, 1]²: boundary vertices lie on its border.
        for v in 0..mesh.pos.len() {
            let p = mesh.pos[v];
            assert!(p.z.abs() < 1e-6);
            if mesh.on_boundary[v] {
                let border = 1.0 - p.x.abs().max(p.y.abs());
                assert!(border < 1e-5, "boundary vertex {v} at {p:?}");
            }
        }
    }
}
