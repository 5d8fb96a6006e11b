//! Closest-point projection onto a triangle mesh and onto its boundary
//! polylines, accelerated by a bounding-volume hierarchy.
//!
//! The BVH is binary, built top-down by splitting at the median centroid
//! along the widest axis (deterministic, O(n log n)), with up to
//! [`LEAF_SIZE`] primitives per leaf. A query walks nearer children first and
//! prunes every box farther than the best distance so far; a good first guess
//! (the face a vertex was on before it moved) makes queries during
//! remeshing nearly constant time. Closest points on triangles follow
//! Ericson, *Real-Time Collision Detection* (2005), §5.1.5.

use super::trimesh::{NONE, TriMesh, next};
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::PolyMesh;
use crate::progress::Progress;
use glam::{Vec2, Vec3};

/// Most primitives in a BVH leaf.
const LEAF_SIZE: usize = 4;

#[derive(Clone, Copy, Debug)]
struct Node {
    lo: Vec3,
    hi: Vec3,
    /// Leaf: first index into `Bvh::prims`. Inner node: index of the left
    /// child (the right one follows it).
    first: u32,
    /// Primitives in a leaf; 0 for an inner node.
    count: u32,
}

/// A bounding-volume hierarchy over primitives given by their boxes.
#[derive(Clone, Debug, Default)]
struct Bvh {
    nodes: Vec<Node>,
    prims: Vec<u32>,
}

#[inline]
fn box_dist2(lo: Vec3, hi: Vec3, p: Vec3) -> f32 {
    let d = (lo - p).max(p - hi).max(Vec3::ZERO);
    d.length_squared()
}

impl Bvh {
    fn build(boxes: &[(Vec3, Vec3)]) -> Self {
        let mut prims: Vec<u32> = (0..boxes.len() as u32).collect();
        let centre: Vec<Vec3> = boxes.iter().map(|(lo, hi)| 0.5 * (*lo + *hi)).collect();
        let mut nodes = Vec::with_capacity(2 * boxes.len() / LEAF_SIZE + 1);
        if boxes.is_empty() {
            return Self { nodes, prims };
        }
        nodes.push(Node {
            lo: Vec3::ZERO,
            hi: Vec3::ZERO,
            first: 0,
            count: 0,
        });
        // (node, start, end) ranges of `prims` still to split.
        let mut todo = vec![(0usize, 0usize, boxes.len())];
        while let Some((n, s, e)) = todo.pop() {
            let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
            let (mut clo, mut chi) = (lo, hi);
            for &p in &prims[s..e] {
                let (a, b) = boxes[p as usize];
                lo = lo.min(a);
                hi = hi.max(b);
                clo = clo.min(centre[p as usize]);
                chi = chi.max(centre[p as usize]);
            }
            nodes[n].lo = lo;
            nodes[n].hi = hi;
            let ext = chi - clo;
            if e - s <= LEAF_SIZE || ext.max_element() <= 0.0 {
                nodes[n].first = s as u32;
                nodes[n].count = (e - s) as u32;
                continue;
            }
            let axis = if ext.x >= ext.y && ext.x >= ext.z {
                0
            } else if ext.y >= ext.z {
                1
            } else {
                2
            };
            let mid = s + (e - s) / 2;
            prims[s..e].select_nth_unstable_by(mid - s, |&a, &b| {
                centre[a as usize][axis]
                    .total_cmp(&centre[b as usize][axis])
                    .then(a.cmp(&b))
            });
            let left = nodes.len();
            let blank = Node {
                lo: Vec3::ZERO,
                hi: Vec3::ZERO,
                first: 0,
                count: 0,
            };
            nodes.push(blank);
            nodes.push(blank);
            nodes[n].first = left as u32;
            todo.push((left + 1, mid, e));
            todo.push((left, s, mid));
        }
        Self { nodes, prims }
    }

    /// The primitive nearest to `p` by `dist2` (squared distance, or
    /// infinity to skip a primitive), starting from the guess `(best,
    /// best_d2)`. Returns `(NONE, ∞)` when every primitive is skipped.
    #[inline]
    fn nearest(
        &self,
        p: Vec3,
        mut best: u32,
        mut best_d2: f32,
        mut dist2: impl FnMut(u32) -> f32,
    ) -> (u32, f32) {
        if self.nodes.is_empty() {
            return (best, best_d2);
        }
        let mut stack = [0u32; 64];
        let mut top = 1;
        while top > 0 {
            top -= 1;
            let node = self.nodes[stack[top] as usize];
            if box_dist2(node.lo, node.hi, p) >= best_d2 {
                continue;
            }
            if node.count > 0 {
                let r = node.first as usize..(node.first + node.count) as usize;
                for &prim in &self.prims[r] {
                    let d2 = dist2(prim);
                    if d2 < best_d2 || (d2 == best_d2 && d2.is_finite() && prim < best) {
                        best_d2 = d2;
                        best = prim;
                    }
                }
            } else {
                let l = node.first;
                let dl = box_dist2(self.nodes[l as usize].lo, self.nodes[l as usize].hi, p);
                let dr = box_dist2(
                    self.nodes[l as usize + 1].lo,
                    self.nodes[l as usize + 1].hi,
                    p,
                );
                // Push the farther child first so the nearer one is searched first.
                let (near, far) = if dl <= dr { (l, l + 1) } else { (l + 1, l) };
                if top + 2 > stack.len() {
                    // Deeper than any median-split tree over < 2^60 primitives.
                    continue;
                }
                stack[top] = far;
                stack[top + 1] = near;
                top += 2;
            }
        }
        (best, best_d2)
    }
}

/// Closest point to `p` on triangle `(a, b, c)` and its barycentric
/// coordinates (Ericson 2005, §5.1.5). Degenerate triangles are handled.
#[inline]
pub fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> (Vec3, Vec3) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, Vec3::X);
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (b, Vec3::Y);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + v * ab, Vec3::new(1.0 - v, v, 0.0));
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (c, Vec3::Z);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + w * ac, Vec3::new(1.0 - w, 0.0, w));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + w * (c - b), Vec3::new(0.0, 1.0 - w, w));
    }
    let denom = va + vb + vc;
    if denom.abs() <= f32::MIN_POSITIVE {
        // Degenerate (collinear) triangle whose edge tests all failed: take a.
        return (a, Vec3::X);
    }
    let v = vb / denom;
    let w = vc / denom;
    (a + ab * v + ac * w, Vec3::new(1.0 - v - w, v, w))
}

/// A point on the reference surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// The point (model units).
    pub point: Vec3,
    /// The triangle it lies on.
    pub face: u32,
    /// Its barycentric coordinates in that triangle (they sum to 1).
    pub bary: Vec3,
}

/// A boundary edge of the reference surface.
#[derive(Clone, Copy, Debug)]
struct Segment {
    /// The triangle that owns the edge.
    face: u32,
    /// Which corner of that triangle the edge starts at.
    corner: u8,
    loop_id: u32,
}

/// Projects points onto a fixed triangle mesh (the reference surface).
///
/// Build it once with [`SurfaceProjector::new`] (any polygon mesh; faces are
/// fan-triangulated like [`PolyMesh::triangulated`], and face ids in results
/// index those triangles), then query from any number of threads.
#[derive(Clone, Debug, Default)]
pub struct SurfaceProjector {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    normals: Vec<Vec3>,
    tri_bvh: Bvh,
    segments: Vec<Segment>,
    seg_bvh: Bvh,
    /// Per triangle, the triangle across each edge (corner `i` to `i + 1`;
    /// [`NONE`] on the boundary). Empty unless built from a [`TriMesh`].
    neighbours: Vec<[u32; 3]>,
}

impl SurfaceProjector {
    /// Builds the projector for the triangles of `mesh.triangulated()`,
    /// without boundary queries. O(n log n).
    pub fn new(mesh: &PolyMesh) -> Self {
        let tri = mesh.triangulated();
        let triangles: Vec<[u32; 3]> = tri.faces().map(|f| [f[0], f[1], f[2]]).collect();
        Self::build(tri.positions, triangles, Vec::new())
    }

    /// [`Self::new`] with edge adjacency, so [`Self::project_local`] and
    /// [`Self::project_facing_local`] walk instead of searching the tree.
    /// Triangles meet across an edge only where exactly two share it with
    /// opposite orientations; elsewhere (a boundary, a non-manifold edge, a
    /// flipped neighbour) a walk stops. O(n log n).
    pub fn with_adjacency(mesh: &PolyMesh) -> Self {
        let mut out = Self::new(mesh);
        // (smaller vertex, larger vertex, triangle, edge) sorted: the
        // triangles of one edge are consecutive.
        let mut edges: Vec<(u32, u32, u32, u8)> = out
            .triangles
            .iter()
            .enumerate()
            .flat_map(|(t, tri)| {
                (0..3u8).map(move |k| {
                    let (a, b) = (tri[k as usize], tri[(k as usize + 1) % 3]);
                    (a.min(b), a.max(b), t as u32, k)
                })
            })
            .collect();
        edges.sort_unstable();
        let mut neighbours = vec![[NONE; 3]; out.triangles.len()];
        let mut i = 0;
        while i < edges.len() {
            let mut j = i + 1;
            while j < edges.len() && edges[j].0 == edges[i].0 && edges[j].1 == edges[i].1 {
                j += 1;
            }
            if j - i == 2 {
                let ((_, _, t0, k0), (_, _, t1, k1)) = (edges[i], edges[i + 1]);
                let start = |t: u32, k: u8| out.triangles[t as usize][k as usize];
                // Consistently oriented neighbours run the edge both ways.
                if start(t0, k0) != start(t1, k1) {
                    neighbours[t0 as usize][k0 as usize] = t1;
                    neighbours[t1 as usize][k1 as usize] = t0;
                }
            }
            i = j;
        }
        out.neighbours = neighbours;
        out
    }

    /// Builds the projector over the live faces of a prepared mesh (face ids
    /// are its face slots divided by three, which are all live right after
    /// preparation), including its boundary loops.
    pub(crate) fn from_trimesh(mesh: &TriMesh) -> Self {
        let triangles: Vec<[u32; 3]> = mesh
            .vert
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        let mut segments = Vec::new();
        for h in 0..mesh.halfedge_slots() as u32 {
            if mesh.alive_halfedge(h) && mesh.twin[h as usize] == NONE {
                segments.push(Segment {
                    face: h / 3,
                    corner: (h % 3) as u8,
                    loop_id: mesh.loop_id[mesh.vert[h as usize] as usize],
                });
            }
        }
        let mut out = Self::build(mesh.pos.clone(), triangles, segments);
        out.neighbours = mesh
            .twin
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]].map(|h| if h == NONE { NONE } else { h / 3 }))
            .collect();
        out
    }

    fn build(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>, segments: Vec<Segment>) -> Self {
        let boxes: Vec<(Vec3, Vec3)> = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| positions[v as usize]);
                (a.min(b).min(c), a.max(b).max(c))
            })
            .collect();
        let normals = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| positions[v as usize]);
                (b - a).cross(c - a).normalize_or_zero()
            })
            .collect();
        let tri_bvh = Bvh::build(&boxes);
        let mut out = Self {
            positions,
            triangles,
            normals,
            tri_bvh,
            segments,
            seg_bvh: Bvh::default(),
            neighbours: Vec::new(),
        };
        let seg_boxes: Vec<(Vec3, Vec3)> = out
            .segments
            .iter()
            .map(|s| {
                let (a, b) = out.segment_ends(s);
                (a.min(b), a.max(b))
            })
            .collect();
        out.seg_bvh = Bvh::build(&seg_boxes);
        out
    }

    /// The vertex ids of triangle `face` (vertices of the mesh it was built from).
    pub fn triangle(&self, face: u32) -> [u32; 3] {
        self.triangles[face as usize]
    }

    /// Number of triangles of the reference surface.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Unit normal of triangle `face` (zero when it has no area).
    pub fn face_normal(&self, face: u32) -> Vec3 {
        self.normals[face as usize]
    }

    /// The point with barycentric coordinates `bary` in triangle `face`.
    pub fn point_at(&self, face: u32, bary: Vec3) -> Vec3 {
        let [a, b, c] = self.triangles[face as usize].map(|v| self.positions[v as usize]);
        a * bary.x + b * bary.y + c * bary.z
    }

    #[inline]
    fn tri_closest(&self, t: u32, p: Vec3) -> (Vec3, Vec3) {
        let [a, b, c] = self.triangles[t as usize].map(|v| self.positions[v as usize]);
        closest_point_on_triangle(p, a, b, c)
    }

    #[inline]
    fn segment_ends(&self, s: &Segment) -> (Vec3, Vec3) {
        let tri = self.triangles[s.face as usize];
        let i = s.corner as usize;
        (
            self.positions[tri[i] as usize],
            self.positions[tri[next(i as u32) as usize] as usize],
        )
    }

    /// The closest point of the surface to `p`. Ties go to the lower face id.
    /// Returns `None` only for a surface without triangles.
    pub fn project(&self, p: Vec3) -> Option<SurfacePoint> {
        let (face, _) = self.tri_bvh.nearest(p, NONE, f32::INFINITY, |t| {
            (self.tri_closest(t, p).0 - p).length_squared()
        });
        (face != NONE).then(|| {
            let (point, bary) = self.tri_closest(face, p);
            SurfacePoint { point, face, bary }
        })
    }

    /// Like [`Self::project`], with `hint` a triangle likely to be near
    /// (speeds up the search; the result is the same).
    pub fn project_near(&self, p: Vec3, hint: u32) -> Option<SurfacePoint> {
        let (mut best, mut best_d2) = (NONE, f32::INFINITY);
        if (hint as usize) < self.triangles.len() {
            best = hint;
            best_d2 = (self.tri_closest(hint, p).0 - p).length_squared();
        }
        let (face, _) = self.tri_bvh.nearest(p, best, best_d2, |t| {
            (self.tri_closest(t, p).0 - p).length_squared()
        });
        (face != NONE).then(|| {
            let (point, bary) = self.tri_closest(face, p);
            SurfacePoint { point, face, bary }
        })
    }

    /// The closest point to `p` on the surface around triangle `hint`:
    /// starting there, steps to whichever neighbouring triangle (across an
    /// edge) is closer to `p`, until none is. For a point near `hint`, as
    /// the centroid of a small triangle whose corner projects onto `hint`,
    /// this costs a few triangle tests however big the surface is, where a
    /// search from the root of the tree pays its depth and cache misses. It
    /// can stop at a local minimum of the distance, i.e. it answers "the
    /// surface here" rather than the globally closest sheet, which is what a
    /// local orientation test wants. Without adjacency (a projector not
    /// built from a [`TriMesh`]) or a valid hint, it is [`Self::project_near`].
    pub fn project_local(&self, p: Vec3, hint: u32) -> Option<SurfacePoint> {
        if self.neighbours.is_empty() || hint as usize >= self.triangles.len() {
            return self.project_near(p, hint);
        }
        self.walk(p, hint, |_| true)
            .unwrap_or_else(|face| self.project_near(p, face))
    }

    /// [`Self::project_local`] among the triangles facing the same way as
    /// `normal` ([`Self::project_facing`]): from `hint`, steps to whichever
    /// facing neighbour is closer to `p`, until none is — "the surface
    /// here", facing that way. A hint that does not face that way, a walk
    /// longer than [`Self::MAX_WALK`] steps, or a projector without adjacency
    /// search the tree ([`Self::project_facing`]).
    pub fn project_facing_local(&self, p: Vec3, normal: Vec3, hint: u32) -> Option<SurfacePoint> {
        let facing = |t: u32| self.normals[t as usize].dot(normal) > 0.0;
        if self.neighbours.is_empty() || hint as usize >= self.triangles.len() || !facing(hint) {
            return self.project_facing(p, normal, hint);
        }
        self.walk(p, hint, facing)
            .unwrap_or_else(|face| self.project_facing(p, normal, face))
    }

    /// A walk longer than this is far from its hint: search the tree.
    const MAX_WALK: usize = 64;

    /// From triangle `hint` (which needs adjacency), steps to whichever
    /// neighbour that `allowed` admits is closer to `p`, until none is: the
    /// closest point there, or `Err(face)` with the face reached after
    /// [`Self::MAX_WALK`] steps.
    fn walk(
        &self,
        p: Vec3,
        hint: u32,
        allowed: impl Fn(u32) -> bool,
    ) -> Result<Option<SurfacePoint>, u32> {
        let mut face = hint;
        let (mut point, mut bary) = self.tri_closest(face, p);
        let mut d2 = (point - p).length_squared();
        // The face the walk came from is farther than `face` (each step is
        // a strict improvement), so it is not tested again.
        let mut came_from = NONE;
        for _ in 0..Self::MAX_WALK {
            let mut step = None;
            for &g in &self.neighbours[face as usize] {
                if g == NONE || g == came_from || !allowed(g) {
                    continue;
                }
                let (q, b) = self.tri_closest(g, p);
                let e = (q - p).length_squared();
                if e < d2 {
                    (d2, step) = (e, Some((g, q, b)));
                }
            }
            match step {
                Some((g, q, b)) => {
                    came_from = face;
                    (face, point, bary) = (g, q, b);
                }
                None => return Ok(Some(SurfacePoint { point, face, bary })),
            }
        }
        Err(face)
    }

    /// Whether `pred` holds for the normal of any input triangle through the
    /// surface point at `bary` in `face`: `face` itself, the triangle across
    /// the edge the point lies on, or the triangles around the vertex it lies
    /// at (a coordinate of at most [`Self::ON_FEATURE`] counts as zero). On a
    /// crease or a corner of the input this is every normal the surface has
    /// there. Without adjacency (a projector not built from a [`TriMesh`]),
    /// only `face`. At most [`Self::MAX_FAN`] triangles around a vertex are
    /// asked.
    pub(crate) fn any_normal_at(
        &self,
        face: u32,
        bary: Vec3,
        mut pred: impl FnMut(Vec3) -> bool,
    ) -> bool {
        let Some(normal) = self.normals.get(face as usize) else {
            return false;
        };
        if pred(*normal) {
            return true;
        }
        if self.neighbours.is_empty() {
            return false;
        }
        let b = bary.to_array();
        let zero = b.map(|x| x <= Self::ON_FEATURE);
        match zero.iter().filter(|&&z| z).count() {
            1 => {
                // On the edge opposite the zero corner k: corner k+1 to k+2.
                let k = zero.iter().position(|&z| z).unwrap_or(0);
                let g = self.neighbours[face as usize][(k + 1) % 3];
                g != NONE && pred(self.normals[g as usize])
            }
            2 => {
                let j = zero.iter().position(|&z| !z).unwrap_or(0);
                let v = self.triangles[face as usize][j];
                // Walk the fan of v both ways across its two edges in each
                // triangle (corner i to i+1 and corner i-1 to i).
                for side in [0usize, 2] {
                    let mut g = face;
                    for _ in 0..Self::MAX_FAN {
                        let Some(i) = self.triangles[g as usize].iter().position(|&x| x == v)
                        else {
                            break;
                        };
                        let n = self.neighbours[g as usize][(i + side) % 3];
                        if n == NONE || n == face {
                            break;
                        }
                        if pred(self.normals[n as usize]) {
                            return true;
                        }
                        g = n;
                    }
                }
                false
            }
            _ => false,
        }
    }

    /// Barycentric coordinates at most this are on an edge or a vertex of
    /// the input ([`Self::any_normal_at`]); closest points in an edge or
    /// vertex region come out exactly zero there.
    pub(crate) const ON_FEATURE: f32 = 1e-6;
    /// Most triangles [`Self::any_normal_at`] asks around one vertex.
    pub(crate) const MAX_FAN: usize = 64;

    /// The closest point to `p` among the triangles facing the same way as
    /// `normal` (positive dot product), so that a point is not snapped onto
    /// the far side of a thin part; `hint` is a triangle likely to be near
    /// (speeds up the search). Falls back to [`Self::project`] when no
    /// triangle faces that way.
    pub fn project_facing(&self, p: Vec3, normal: Vec3, hint: u32) -> Option<SurfacePoint> {
        let facing = |t: u32| self.normals[t as usize].dot(normal) > 0.0;
        let (mut best, mut best_d2) = (NONE, f32::INFINITY);
        if (hint as usize) < self.triangles.len() && facing(hint) {
            best = hint;
            best_d2 = (self.tri_closest(hint, p).0 - p).length_squared();
        }
        let (face, _) = self.tri_bvh.nearest(p, best, best_d2, |t| {
            if facing(t) {
                (self.tri_closest(t, p).0 - p).length_squared()
            } else {
                f32::INFINITY
            }
        });
        if face == NONE {
            return self.project(p);
        }
        let (point, bary) = self.tri_closest(face, p);
        Some(SurfacePoint { point, face, bary })
    }

    /// The closest point to `p` on boundary loop `loop_id` (see
    /// `prepare::number_boundary_loops`); `None` without such a loop.
    pub(crate) fn project_to_boundary(&self, p: Vec3, loop_id: u32) -> Option<SurfacePoint> {
        let seg_closest = |s: &Segment| {
            let (a, b) = self.segment_ends(s);
            let ab = b - a;
            let len2 = ab.length_squared();
            let u = if len2 > 0.0 {
                ((p - a).dot(ab) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (a + u * ab, u)
        };
        let (si, _) = self.seg_bvh.nearest(p, NONE, f32::INFINITY, |i| {
            let s = &self.segments[i as usize];
            if s.loop_id == loop_id {
                (seg_closest(s).0 - p).length_squared()
            } else {
                f32::INFINITY
            }
        });
        if si == NONE {
            return None;
        }
        let s = &self.segments[si as usize];
        let (point, u) = seg_closest(s);
        let mut bary = [0.0f32; 3];
        bary[s.corner as usize] = 1.0 - u;
        bary[next(s.corner as u32) as usize] = u;
        Some(SurfacePoint {
            point,
            face: s.face,
            bary: Vec3::from_array(bary),
        })
    }
}

/// Per-vertex attributes of a result surface, to be resampled elsewhere by
/// [`map_back`].
#[derive(Clone, Copy, Debug)]
pub struct ResultAttributes<'a> {
    /// `channels` values per result vertex.
    pub colours: &'a [f32],
    /// Values per vertex.
    pub channels: usize,
    /// Matched exemplar texel per result vertex, if known.
    pub texels: Option<&'a [Vec2]>,
    /// Tangent frame per result vertex, if known.
    pub frames: Option<&'a [TangentFrame]>,
}

/// A result resampled at the vertices of another mesh (see [`map_back`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MappedBack {
    /// `channels` values per target vertex: the barycentric interpolation of
    /// the closest result triangle's vertex colours.
    pub colours: Vec<f32>,
    /// Per target vertex, the texel of the closest triangle's corner with the
    /// largest barycentric weight (texel coordinates do not interpolate
    /// across the exemplar's wrap).
    pub texels: Option<Vec<Vec2>>,
    /// Per target vertex, that corner's frame turned into the target's
    /// tangent plane (n-way symmetric frames do not interpolate either).
    pub frames: Option<Vec<TangentFrame>>,
    /// Per target vertex, its distance to the result surface (model units).
    pub distance: Vec<f32>,
}

/// Bad input to [`map_back`].
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum MapBackError {
    /// The result surface has no triangles.
    #[error("the result mesh has no faces to map back from")]
    NoFaces,
    /// An attribute array does not have one entry per result vertex.
    #[error("the result's {what} has {got} entries for {vertices} vertices")]
    Length {
        /// Which attribute.
        what: &'static str,
        /// Entries given.
        got: usize,
        /// Vertices of the result mesh.
        vertices: usize,
    },
}

/// Maps a result synthesised on a retiled surface back onto the original
/// mesh (Wei & Levoy 2001 §5: "mapped back onto the original model in a
/// post-process by resampling"): each target vertex (`positions`, with
/// `normals`, which may be zero) takes the closest point of the result
/// surface among the triangles facing its way (so a thin part is not read
/// from its far side; any triangle when none faces that way) and
/// interpolates the colours there barycentrically. Works on any number of
/// components, with boundaries, and with polygon faces (fan-triangulated).
/// Each target vertex is independent: the result does not depend on the
/// thread count.
///
/// # Errors
/// [`MapBackError`] when the result has no faces or an attribute's length is
/// not one entry per result vertex.
pub fn map_back(
    result: &PolyMesh,
    attributes: &ResultAttributes,
    positions: &[Vec3],
    normals: &[Vec3],
) -> Result<MappedBack, MapBackError> {
    map_back_with_progress(result, attributes, positions, normals, &Progress::hidden())
}

/// [`map_back`], advancing `progress` (its length set to the target vertex
/// count) by one step per target vertex projected.
///
/// # Errors
/// As [`map_back`].
pub fn map_back_with_progress(
    result: &PolyMesh,
    attributes: &ResultAttributes,
    positions: &[Vec3],
    normals: &[Vec3],
    progress: &Progress,
) -> Result<MappedBack, MapBackError> {
    use rayon::prelude::*;
    let nv = result.vertex_count();
    let ch = attributes.channels;
    let check = |what: &'static str, got: usize, per: usize| {
        if got == nv * per {
            Ok(())
        } else {
            Err(MapBackError::Length {
                what,
                got: got / per.max(1),
                vertices: nv,
            })
        }
    };
    check("colours", attributes.colours.len(), ch.max(1))?;
    if let Some(t) = attributes.texels {
        check("texels", t.len(), 1)?;
    }
    if let Some(f) = attributes.frames {
        check("frames", f.len(), 1)?;
    }
    let projector = SurfaceProjector::new(result);
    if projector.triangle_count() == 0 {
        return Err(MapBackError::NoFaces);
    }
    let n = positions.len();
    progress.set_length(n as u64);
    let mut out = MappedBack {
        colours: vec![0.0; n * ch],
        texels: attributes.texels.map(|_| vec![Vec2::ZERO; n]),
        frames: attributes.frames.map(|_| {
            vec![
                TangentFrame {
                    s: Vec3::X,
                    t: Vec3::Y,
                    n: Vec3::Z,
                };
                n
            ]
        }),
        distance: vec![0.0; n],
    };
    // Closest points (the expensive part) in parallel, then a cheap gather.
    let hits: Vec<Option<SurfacePoint>> = positions
        .par_iter()
        .enumerate()
        .map(|(v, &p)| {
            let hit = match normals.get(v).copied() {
                Some(normal) if normal.length_squared() > 0.0 => {
                    projector.project_facing(p, normal, NONE)
                }
                _ => projector.project(p),
            };
            progress.inc(1);
            hit
        })
        .collect();
    for (v, hit) in hits.iter().enumerate() {
        let Some(hit) = hit else { continue };
        let tri = projector.triangle(hit.face);
        let w = hit.bary.to_array();
        let dst = &mut out.colours[v * ch..(v + 1) * ch];
        for (k, &corner) in tri.iter().enumerate() {
            let src = &attributes.colours[corner as usize * ch..(corner as usize + 1) * ch];
            for (d, s) in dst.iter_mut().zip(src) {
                *d += w[k] * s;
            }
        }
        out.distance[v] = (hit.point - positions[v]).length();
        let heaviest = tri[(0..3).fold(0, |b, k| if w[k] > w[b] { k } else { b })] as usize;
        if let (Some(dst), Some(src)) = (out.texels.as_mut(), attributes.texels) {
            dst[v] = src[heaviest];
        }
        if let (Some(dst), Some(src)) = (out.frames.as_mut(), attributes.frames) {
            let f = src[heaviest];
            let normal = normals.get(v).copied().unwrap_or(Vec3::ZERO);
            let normal = if normal.length_squared() > 0.0 {
                normal
            } else {
                f.n
            };
            dst[v] = TangentFrame::from_direction(normal, f.s);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::builtin::{BuiltinOptions, builtin_mesh};

    #[test]
    fn closest_point_regions() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let (q, w) = closest_point_on_triangle(Vec3::new(0.2, 0.2, 1.0), a, b, c);
        assert!((q - Vec3::new(0.2, 0.2, 0.0)).length() < 1e-6);
        assert!((w - Vec3::new(0.6, 0.2, 0.2)).length() < 1e-6);
        let (q, _) = closest_point_on_triangle(Vec3::new(-1.0, -1.0, 0.0), a, b, c);
        assert_eq!(q, a);
        let (q, w) = closest_point_on_triangle(Vec3::new(1.0, 1.0, 0.0), a, b, c);
        assert!((q - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-6);
        assert!((w - Vec3::new(0.0, 0.5, 0.5)).length() < 1e-6);
    }

    #[test]
    fn bvh_matches_brute_force() {
        let mesh = builtin_mesh("torus", &BuiltinOptions::default()).unwrap();
        let proj = SurfaceProjector::new(&mesh);
        let tri = mesh.triangulated();
        let mut state = 12345u32;
        let mut rnd = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 * 3.0 - 1.5
        };
        for _ in 0..200 {
            let p = Vec3::new(rnd(), rnd(), rnd());
            let got = proj.project(p).unwrap();
            let best = tri
                .faces()
                .map(|f| {
                    let [a, b, c] = [f[0], f[1], f[2]].map(|v| tri.positions[v as usize]);
                    (closest_point_on_triangle(p, a, b, c).0 - p).length()
                })
                .fold(f32::INFINITY, f32::min);
            assert!(((got.point - p).length() - best).abs() < 1e-5);
            assert!((proj.point_at(got.face, got.bary) - got.point).length() < 1e-5);
        }
    }

    /// Walking from a neighbouring point's triangle finds the same closest
    /// point as the tree, for points near a smooth surface.
    #[test]
    fn facing_walk_matches_the_tree_near_the_surface() {
        let mesh = builtin_mesh("torus", &BuiltinOptions::default()).unwrap();
        let tree = SurfaceProjector::new(&mesh);
        let walk = SurfaceProjector::with_adjacency(&mesh);
        assert!(
            walk.neighbours.iter().flatten().all(|&g| g != NONE),
            "a closed torus"
        );
        let mut state = 777u32;
        let mut rnd = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        let mut walked = 0;
        for t in 0..walk.triangle_count() as u32 {
            let centre = walk.point_at(t, Vec3::splat(1.0 / 3.0));
            let n = walk.normals[t as usize];
            // A point a little off the surface, a few triangles away.
            let p = centre + Vec3::new(rnd(), rnd(), rnd()) * 0.08 + n * 0.005;
            let want = tree.project_facing(p, n, NONE).unwrap();
            let got = walk.project_facing_local(p, n, t).unwrap();
            assert!(
                (got.point - want.point).length() < 1e-5,
                "from triangle {t}: walk {:?} tree {:?}",
                got.point,
                want.point
            );
            walked += usize::from(got.face != t);
        }
        println!(
            "walks that left their start: {walked} of {}",
            walk.triangle_count()
        );
        assert!(walked > 50, "the walks left their start {walked} times");
    }
}
