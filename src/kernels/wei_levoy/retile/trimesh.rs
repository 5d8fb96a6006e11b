//! The editable triangle mesh the remesher works on: a directed-edge structure
//! (Campagna, Kobbelt & Seidel 1998, "Directed edges — a scalable
//! representation for triangle meshes").
//!
//! Half-edge `h = 3·f + i` is the side of face `f` that starts at its corner
//! `i` and ends at corner `(i + 1) mod 3`, so `next`, `prev` and the face are
//! arithmetic and only the origin vertex (`vert`) and the opposite half-edge
//! (`twin`, [`NONE`] on the boundary) are stored. Every per-vertex quantity is
//! its own array. Split, flip and collapse are O(valence); deleted faces and
//! vertices are marked dead and removed by [`TriMesh::compact`].
//!
//! Architecture invariant: the mesh is an oriented 2-manifold with boundary
//! (every vertex has one fan of faces) whenever no operation is under way;
//! [`TriMesh::check`] verifies it in tests.

use glam::Vec3;

/// "No half-edge / no vertex": the twin of a boundary half-edge, the vertex of
/// a dead face's corner, the out-half-edge of a dead vertex.
pub(crate) const NONE: u32 = u32::MAX;

/// The half-edge after `h` in its face.
#[inline]
pub(crate) fn next(h: u32) -> u32 {
    if h % 3 == 2 { h - 2 } else { h + 1 }
}

/// The half-edge before `h` in its face.
#[inline]
pub(crate) fn prev(h: u32) -> u32 {
    if h.is_multiple_of(3) { h + 2 } else { h - 1 }
}

/// A manifold triangle mesh with boundary, editable in place.
#[derive(Clone, Debug, Default)]
pub(crate) struct TriMesh {
    /// Vertex positions.
    pub pos: Vec<Vec3>,
    /// One outgoing half-edge per vertex; [`NONE`] for a dead vertex.
    pub out: Vec<u32>,
    /// The vertex lies on a boundary loop.
    pub on_boundary: Vec<bool>,
    /// Boundary loop of the vertex ([`NONE`] inside).
    pub loop_id: Vec<u32>,
    /// Input triangle the vertex was last projected onto (a search hint for
    /// vertices not yet projected).
    pub src_face: Vec<u32>,
    /// Barycentric coordinates of the projection in `src_face`.
    pub src_bary: Vec<Vec3>,
    /// Unit normal of the input surface at the vertex's projection.
    pub ref_normal: Vec<Vec3>,
    /// Origin vertex of each half-edge (= corner vertex); [`NONE`] in dead faces.
    pub vert: Vec<u32>,
    /// Opposite half-edge; [`NONE`] on the boundary.
    pub twin: Vec<u32>,
    /// Number of live vertices.
    pub live_vertices: usize,
}

/// Outgoing half-edges of a vertex, in fan order (see [`TriMesh::fan`]).
pub(crate) struct Fan<'a> {
    twin: &'a [u32],
    start: u32,
    cur: u32,
}

impl Iterator for Fan<'_> {
    type Item = u32;
    #[inline]
    fn next(&mut self) -> Option<u32> {
        let h = self.cur;
        if h == NONE {
            return None;
        }
        let t = self.twin[h as usize];
        self.cur = if t == NONE {
            NONE
        } else {
            let n = next(t);
            if n == self.start { NONE } else { n }
        };
        Some(h)
    }
}

impl TriMesh {
    /// Builds the structure from consistently oriented, edge-manifold
    /// triangles. Returns the first directed edge `(a, b)` that occurs twice
    /// (an orientation conflict or a non-manifold edge) as the error.
    /// Vertices in no triangle are dead. Per-vertex attributes get neutral
    /// values (no boundary loop, source face 0, normal +Z).
    pub fn from_triangles(pos: Vec<Vec3>, tris: &[[u32; 3]]) -> Result<Self, (u32, u32)> {
        let nv = pos.len();
        let mut vert = Vec::with_capacity(tris.len() * 3);
        for t in tris {
            vert.extend_from_slice(t);
        }
        let nh = vert.len();
        let mut keys: Vec<(u64, u32)> = (0..nh as u32)
            .map(|h| {
                let a = vert[h as usize] as u64;
                let b = vert[next(h) as usize] as u64;
                ((a << 32) | b, h)
            })
            .collect();
        keys.sort_unstable();
        for w in keys.windows(2) {
            if w[0].0 == w[1].0 {
                return Err(((w[0].0 >> 32) as u32, w[0].0 as u32));
            }
        }
        let mut twin = vec![NONE; nh];
        for &(key, h) in &keys {
            let rev = key.rotate_right(32);
            if let Ok(i) = keys.binary_search_by_key(&rev, |k| k.0) {
                twin[h as usize] = keys[i].1;
            }
        }
        let mut mesh = TriMesh {
            pos,
            out: vec![NONE; nv],
            on_boundary: vec![false; nv],
            loop_id: vec![NONE; nv],
            src_face: vec![0; nv],
            src_bary: vec![Vec3::new(1.0, 0.0, 0.0); nv],
            ref_normal: vec![Vec3::Z; nv],
            vert,
            twin,
            live_vertices: 0,
        };
        mesh.rebuild_vertex_links();
        Ok(mesh)
    }

    /// Recomputes `out`, `on_boundary` and `live_vertices` from the faces.
    pub fn rebuild_vertex_links(&mut self) {
        self.out.iter_mut().for_each(|o| *o = NONE);
        self.on_boundary.iter_mut().for_each(|b| *b = false);
        for h in 0..self.vert.len() as u32 {
            let v = self.vert[h as usize];
            if v == NONE {
                continue;
            }
            if self.out[v as usize] == NONE {
                self.out[v as usize] = h;
            }
            if self.twin[h as usize] == NONE {
                self.on_boundary[v as usize] = true;
                self.on_boundary[self.vert[next(h) as usize] as usize] = true;
            }
        }
        self.live_vertices = self.out.iter().filter(|&&o| o != NONE).count();
    }

    /// Number of half-edge slots (three per face, dead ones included).
    #[inline]
    pub fn halfedge_slots(&self) -> usize {
        self.vert.len()
    }

    /// True when the face of `h` is alive.
    #[inline]
    pub fn alive_halfedge(&self, h: u32) -> bool {
        self.vert[h as usize] != NONE
    }

    /// Target vertex of `h`.
    #[inline]
    pub fn to(&self, h: u32) -> u32 {
        self.vert[next(h) as usize]
    }

    /// Length of the edge of `h`.
    #[inline]
    pub fn edge_length(&self, h: u32) -> f32 {
        (self.pos[self.to(h) as usize] - self.pos[self.vert[h as usize] as usize]).length()
    }

    /// The first outgoing half-edge of `v` in fan order: for a boundary
    /// vertex, the one whose previous half-edge lies on the boundary; for an
    /// interior vertex (closed fan), any.
    #[inline]
    pub fn fan_start(&self, v: u32) -> u32 {
        let s = self.out[v as usize];
        if !self.on_boundary[v as usize] {
            return s;
        }
        let mut h = s;
        loop {
            let t = self.twin[prev(h) as usize];
            if t == NONE {
                return h;
            }
            h = t;
            if h == s {
                return s;
            }
        }
    }

    /// Outgoing half-edges of the live vertex `v`, rotating from face to face
    /// across shared edges (for a boundary vertex, from one boundary edge to
    /// the other).
    #[inline]
    pub fn fan(&self, v: u32) -> Fan<'_> {
        let start = self.fan_start(v);
        Fan {
            twin: &self.twin,
            start,
            cur: start,
        }
    }

    /// Number of edges at `v`.
    #[inline]
    pub fn valence(&self, v: u32) -> usize {
        self.fan(v).count() + self.on_boundary[v as usize] as usize
    }

    /// Fills `buf` with the neighbours of `v` (fan order; for a boundary
    /// vertex the last entry is its other boundary neighbour).
    pub fn ring(&self, v: u32, buf: &mut Vec<u32>) {
        buf.clear();
        let s = self.fan_start(v);
        buf.extend(
            Fan {
                twin: &self.twin,
                start: s,
                cur: s,
            }
            .map(|h| self.to(h)),
        );
        let p = prev(s);
        if self.twin[p as usize] == NONE {
            buf.push(self.vert[p as usize]);
        }
    }

    /// The two boundary neighbours `(incoming, outgoing)` of a boundary vertex.
    pub fn boundary_neighbours(&self, v: u32) -> (u32, u32) {
        let s = self.fan_start(v);
        let last = self.fan(v).last().unwrap_or(s);
        (self.vert[prev(s) as usize], self.to(last))
    }

    /// A half-edge of the edge `{a, b}`: `a → b` when it exists, otherwise
    /// the boundary half-edge `b → a`.
    pub fn find_edge(&self, a: u32, b: u32) -> Option<u32> {
        if self.out[a as usize] == NONE || self.out[b as usize] == NONE {
            return None;
        }
        let s = self.fan_start(a);
        let fan = Fan {
            twin: &self.twin,
            start: s,
            cur: s,
        };
        for h in fan {
            if self.to(h) == b {
                return Some(h);
            }
        }
        let p = prev(s);
        (self.twin[p as usize] == NONE && self.vert[p as usize] == b).then_some(p)
    }

    /// Unscaled normal (twice the area) of the face of `h`.
    #[inline]
    pub fn face_normal_scaled(&self, h: u32) -> Vec3 {
        let f = h - h % 3;
        let a = self.pos[self.vert[f as usize] as usize];
        let b = self.pos[self.vert[f as usize + 1] as usize];
        let c = self.pos[self.vert[f as usize + 2] as usize];
        (b - a).cross(c - a)
    }

    /// Appends a vertex copying the per-vertex attributes of `like`.
    fn push_vertex(&mut self, p: Vec3, like: u32, on_boundary: bool) -> u32 {
        let l = like as usize;
        self.pos.push(p);
        self.out.push(NONE);
        self.on_boundary.push(on_boundary);
        self.loop_id
            .push(if on_boundary { self.loop_id[l] } else { NONE });
        self.src_face.push(self.src_face[l]);
        self.src_bary.push(self.src_bary[l]);
        self.ref_normal.push(self.ref_normal[l]);
        self.live_vertices += 1;
        (self.pos.len() - 1) as u32
    }

    #[inline]
    fn set_twin(&mut self, a: u32, b: u32) {
        if a != NONE {
            self.twin[a as usize] = b;
        }
        if b != NONE {
            self.twin[b as usize] = a;
        }
    }

    /// Splits the edge of `h` at its midpoint; returns the new vertex. The one
    /// or two faces at the edge become two or four.
    pub fn split(&mut self, h: u32) -> u32 {
        let t = self.twin[h as usize];
        let (h1, h2) = (next(h), prev(h));
        let a = self.vert[h as usize];
        let b = self.vert[h1 as usize];
        let c = self.vert[h2 as usize];
        let mid = 0.5 * (self.pos[a as usize] + self.pos[b as usize]);
        let m = self.push_vertex(mid, a, t == NONE);
        let nr = (self.ref_normal[a as usize] + self.ref_normal[b as usize]).normalize_or_zero();
        if nr != Vec3::ZERO {
            self.ref_normal[m as usize] = nr;
        }

        // Face (a, b, c) becomes (a, m, c) plus the new face (m, b, c).
        let x1 = self.twin[h1 as usize];
        let g = self.vert.len() as u32;
        self.vert.extend_from_slice(&[m, b, c]);
        self.twin.extend_from_slice(&[NONE, NONE, NONE]);
        self.vert[h1 as usize] = m;
        self.set_twin(g + 1, x1);
        self.set_twin(h1, g + 2);
        self.out[m as usize] = h1;
        self.out[b as usize] = g + 1;
        self.out[a as usize] = h;

        if t == NONE {
            self.twin[h as usize] = NONE;
            self.twin[g as usize] = NONE;
        } else {
            // Face (b, a, d) becomes (b, m, d) plus the new face (m, a, d).
            let (t1, t2) = (next(t), prev(t));
            let d = self.vert[t2 as usize];
            let y1 = self.twin[t1 as usize];
            let k = self.vert.len() as u32;
            self.vert.extend_from_slice(&[m, a, d]);
            self.twin.extend_from_slice(&[NONE, NONE, NONE]);
            self.vert[t1 as usize] = m;
            self.set_twin(k + 1, y1);
            self.set_twin(t1, k + 2);
            self.set_twin(h, k);
            self.set_twin(t, g);
        }
        m
    }

    /// Flips the interior edge of `h` = a → b in faces (a, b, c) and (b, a, d)
    /// to the edge c — d. The caller checks that c — d is not an edge yet.
    pub fn flip(&mut self, h: u32) {
        let t = self.twin[h as usize];
        debug_assert!(t != NONE, "flip of a boundary edge");
        let (h1, h2, t1, t2) = (next(h), prev(h), next(t), prev(t));
        let a = self.vert[h as usize];
        let b = self.vert[h1 as usize];
        let c = self.vert[h2 as usize];
        let d = self.vert[t2 as usize];
        let (x1, x2, y1, y2) = (
            self.twin[h1 as usize],
            self.twin[h2 as usize],
            self.twin[t1 as usize],
            self.twin[t2 as usize],
        );
        // New faces (d, c, a) in the slots of h and (c, d, b) in those of t.
        self.vert[h as usize] = d;
        self.vert[h1 as usize] = c;
        self.vert[h2 as usize] = a;
        self.vert[t as usize] = c;
        self.vert[t1 as usize] = d;
        self.vert[t2 as usize] = b;
        self.set_twin(h, t);
        self.set_twin(h1, x2);
        self.set_twin(h2, y1);
        self.set_twin(t1, y2);
        self.set_twin(t2, x1);
        self.out[a as usize] = h2;
        self.out[b as usize] = t2;
        self.out[c as usize] = h1;
        self.out[d as usize] = t1;
    }

    /// Collapses `h` = a → b: removes `a` and its one or two faces at the
    /// edge, and moves `b` to `p`. The caller checks that the collapse keeps
    /// the mesh manifold (see `remesh::collapse_ok`).
    pub fn collapse(&mut self, h: u32, p: Vec3) {
        let t = self.twin[h as usize];
        let a = self.vert[h as usize];
        let b = self.to(h);
        let s = self.fan_start(a);
        let mut g = s;
        loop {
            // Relabel every corner of `a` (including the faces about to die).
            let tw = self.twin[g as usize];
            self.vert[g as usize] = b;
            if tw == NONE {
                break;
            }
            g = next(tw);
            if g == s {
                break;
            }
        }
        let (h1, h2) = (next(h), prev(h));
        let c = self.vert[h2 as usize];
        let x1 = self.twin[h1 as usize];
        let x2 = self.twin[h2 as usize];
        self.set_twin(x1, x2);
        let (mut y1, mut y2, mut d) = (NONE, NONE, NONE);
        if t != NONE {
            let (t1, t2) = (next(t), prev(t));
            d = self.vert[t2 as usize];
            y1 = self.twin[t1 as usize];
            y2 = self.twin[t2 as usize];
            self.set_twin(y1, y2);
        }
        for f in [h - h % 3, if t == NONE { NONE } else { t - t % 3 }] {
            if f != NONE {
                for i in 0..3 {
                    self.vert[(f + i) as usize] = NONE;
                    self.twin[(f + i) as usize] = NONE;
                }
            }
        }
        // New out-half-edges for b, c, d from the surviving neighbours.
        let pick = |cands: [u32; 4]| cands.into_iter().find(|&x| x != NONE).unwrap_or(NONE);
        self.out[b as usize] = pick([
            x2,
            y2,
            if x1 == NONE { NONE } else { next(x1) },
            if y1 == NONE { NONE } else { next(y1) },
        ]);
        self.out[c as usize] = pick([x1, if x2 == NONE { NONE } else { next(x2) }, NONE, NONE]);
        if d != NONE {
            self.out[d as usize] = pick([y1, if y2 == NONE { NONE } else { next(y2) }, NONE, NONE]);
        }
        self.out[a as usize] = NONE;
        self.pos[b as usize] = p;
        self.live_vertices -= 1;
    }

    /// Removes dead faces and vertices, renumbering the rest in order.
    pub fn compact(&mut self) {
        let nv = self.pos.len();
        let mut n = 0u32;
        let vmap: Vec<u32> = self
            .out
            .iter()
            .map(|&o| {
                if o == NONE {
                    NONE
                } else {
                    n += 1;
                    n - 1
                }
            })
            .collect();
        let nf = self.vert.len() / 3;
        let mut hmap = vec![NONE; self.vert.len()];
        let mut nh = 0u32;
        for f in 0..nf {
            if self.vert[3 * f] != NONE {
                for i in 0..3 {
                    hmap[3 * f + i] = nh + i as u32;
                }
                nh += 3;
            }
        }
        let mut w = 0;
        for h in 0..self.vert.len() {
            if hmap[h] != NONE {
                let tw = self.twin[h];
                self.vert[w] = vmap[self.vert[h] as usize];
                self.twin[w] = if tw == NONE { NONE } else { hmap[tw as usize] };
                w += 1;
            }
        }
        self.vert.truncate(w);
        self.twin.truncate(w);
        let mut w = 0;
        for v in 0..nv {
            if vmap[v] != NONE {
                self.pos[w] = self.pos[v];
                self.out[w] = hmap[self.out[v] as usize];
                self.on_boundary[w] = self.on_boundary[v];
                self.loop_id[w] = self.loop_id[v];
                self.src_face[w] = self.src_face[v];
                self.src_bary[w] = self.src_bary[v];
                self.ref_normal[w] = self.ref_normal[v];
                w += 1;
            }
        }
        self.pos.truncate(w);
        self.out.truncate(w);
        self.on_boundary.truncate(w);
        self.loop_id.truncate(w);
        self.src_face.truncate(w);
        self.src_bary.truncate(w);
        self.ref_normal.truncate(w);
        self.live_vertices = w;
    }

    /// Renumbers the vertices of a compacted mesh along a Morton (Z-order)
    /// curve through its bounding box, and its faces by their first vertex
    /// in that order, so that vertices and faces near in space are near in
    /// memory. Splits append their vertices in a shuffled order, so without
    /// this a remeshed level's vertices lie in random spatial order and
    /// every sweep over them misses the cache on a big mesh. Ties keep the
    /// old order, so the result is deterministic.
    pub fn sort_spatially(&mut self) {
        let nv = self.pos.len();
        debug_assert_eq!(
            nv, self.live_vertices,
            "sort_spatially needs a compacted mesh"
        );
        let mut keys: Vec<(u64, u32)> = morton_codes(&self.pos).zip(0..).collect();
        keys.sort_unstable();
        let mut vmap = vec![0u32; nv];
        for (new, &(_, old)) in keys.iter().enumerate() {
            vmap[old as usize] = new as u32;
        }
        let nf = self.vert.len() / 3;
        let mut faces: Vec<(u32, u32)> = (0..nf as u32)
            .map(|f| {
                let c = &self.vert[3 * f as usize..3 * f as usize + 3];
                (c.iter().map(|&v| vmap[v as usize]).min().unwrap_or(0), f)
            })
            .collect();
        faces.sort_unstable();
        let mut fmap = vec![0u32; nf];
        for (new, &(_, old)) in faces.iter().enumerate() {
            fmap[old as usize] = new as u32;
        }
        let hmap = |h: u32| {
            if h == NONE {
                NONE
            } else {
                3 * fmap[(h / 3) as usize] + h % 3
            }
        };
        let mut vert = vec![NONE; self.vert.len()];
        let mut twin = vec![NONE; self.twin.len()];
        for h in 0..self.vert.len() as u32 {
            let g = hmap(h) as usize;
            vert[g] = vmap[self.vert[h as usize] as usize];
            twin[g] = hmap(self.twin[h as usize]);
        }
        self.vert = vert;
        self.twin = twin;
        fn permute<T: Copy>(v: &mut Vec<T>, keys: &[(u64, u32)]) {
            *v = keys.iter().map(|&(_, old)| v[old as usize]).collect();
        }
        permute(&mut self.pos, &keys);
        permute(&mut self.on_boundary, &keys);
        permute(&mut self.loop_id, &keys);
        permute(&mut self.src_face, &keys);
        permute(&mut self.src_bary, &keys);
        permute(&mut self.ref_normal, &keys);
        self.out = keys
            .iter()
            .map(|&(_, old)| hmap(self.out[old as usize]))
            .collect();
    }

    /// Live faces as vertex triples (after [`TriMesh::compact`], all faces).
    pub fn triangles(&self) -> Vec<[u32; 3]> {
        self.vert
            .chunks_exact(3)
            .filter(|c| c[0] != NONE)
            .map(|c| [c[0], c[1], c[2]])
            .collect()
    }

    /// Verifies the structural invariants; returns a description of the
    /// first violation. O(n); used by tests.
    #[cfg(test)]
    pub fn check(&self) -> Result<(), String> {
        for h in 0..self.vert.len() as u32 {
            let v = self.vert[h as usize];
            if v == NONE {
                continue;
            }
            if self.out[v as usize] == NONE {
                return Err(format!("half-edge {h} starts at dead vertex {v}"));
            }
            let t = self.twin[h as usize];
            if t != NONE {
                if self.twin[t as usize] != h {
                    return Err(format!("twin of {h} is {t}, whose twin is not {h}"));
                }
                if self.vert[t as usize] != self.to(h) || self.to(t) != v {
                    return Err(format!("half-edges {h} and {t} are not opposite"));
                }
            }
            if self.to(h) == v {
                return Err(format!("half-edge {h} is a loop at vertex {v}"));
            }
        }
        let mut seen = vec![0u32; self.pos.len()];
        let mut boundary = vec![false; self.pos.len()];
        for h in 0..self.vert.len() {
            if self.vert[h] != NONE {
                seen[self.vert[h] as usize] += 1;
                if self.twin[h] == NONE {
                    boundary[self.vert[h] as usize] = true;
                    boundary[self.to(h as u32) as usize] = true;
                }
            }
        }
        let mut live = 0;
        for v in 0..self.pos.len() as u32 {
            let o = self.out[v as usize];
            if o == NONE {
                continue;
            }
            live += 1;
            if self.vert[o as usize] != v {
                return Err(format!("out-half-edge of vertex {v} starts elsewhere"));
            }
            let fan = self.fan(v).count() as u32;
            if fan != seen[v as usize] {
                return Err(format!(
                    "vertex {v} has {} corners but a fan of {fan} (non-manifold vertex)",
                    seen[v as usize]
                ));
            }
            if boundary[v as usize] != self.on_boundary[v as usize] {
                return Err(format!("boundary flag of vertex {v} is stale"));
            }
        }
        if live != self.live_vertices {
            return Err(format!(
                "live vertex count {} but {live} vertices have faces",
                self.live_vertices
            ));
        }
        Ok(())
    }
}

/// Morton (Z-order) codes of points, 21 bits per axis over their bounding box.
fn morton_codes(pos: &[Vec3]) -> impl Iterator<Item = u64> + '_ {
    const CELLS: u32 = 1 << 21;
    let (lo, hi) = pos.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    let scale = CELLS as f32 / (hi - lo).max_element().max(f32::MIN_POSITIVE);
    pos.iter().map(move |&p| {
        let q = ((p - lo) * scale).min(Vec3::splat((CELLS - 1) as f32));
        spread3(q.x as u64) | (spread3(q.y as u64) << 1) | (spread3(q.z as u64) << 2)
    })
}

/// The low 21 bits of `x` spread out to every third bit (for Morton codes).
fn spread3(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | (x << 32)) & 0x1f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x1f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hexagon fan around vertex 0 (interior) with six boundary vertices.
    fn hexagon() -> TriMesh {
        let mut pos = vec![Vec3::ZERO];
        for i in 0..6 {
            let a = i as f32 * std::f32::consts::TAU / 6.0;
            pos.push(Vec3::new(a.cos(), a.sin(), 0.0));
        }
        let tris: Vec<[u32; 3]> = (0..6).map(|i| [0, 1 + i, 1 + (i + 1) % 6]).collect();
        TriMesh::from_triangles(pos, &tris).unwrap()
    }

    #[test]
    fn fan_ring_and_boundary() {
        let m = hexagon();
        m.check().unwrap();
        assert_eq!(m.valence(0), 6);
        assert!(!m.on_boundary[0]);
        assert!(m.on_boundary[1]);
        assert_eq!(m.valence(1), 3);
        let mut ring = Vec::new();
        m.ring(1, &mut ring);
        ring.sort_unstable();
        assert_eq!(ring, vec![0, 2, 6]);
        let (i, o) = m.boundary_neighbours(1);
        assert_eq!((i, o), (6, 2));
    }

    #[test]
    fn split_flip_collapse_keep_invariants() {
        let mut m = hexagon();
        let h = m.find_edge(0, 1).unwrap();
        let v = m.split(h);
        m.check().unwrap();
        assert_eq!(m.valence(v), 4);
        // Vertex 0 trades neighbour 1 for the new vertex.
        assert_eq!(m.valence(0), 6);
        // Split a boundary edge.
        let hb = m.find_edge(2, 3).unwrap();
        let w = m.split(hb);
        m.check().unwrap();
        assert!(m.on_boundary[w as usize]);
        assert_eq!(m.valence(w), 3);
        // Flip the interior edge 0 — w.
        let hf = m.find_edge(0, w).unwrap();
        m.flip(hf);
        m.check().unwrap();
        assert!(m.find_edge(0, w).is_none());
        // Collapse the interior new vertex v into 0.
        let hc = m.find_edge(v, 0).unwrap();
        let p = m.pos[0];
        m.collapse(hc, p);
        m.check().unwrap();
        m.compact();
        m.check().unwrap();
        assert_eq!(m.live_vertices, m.pos.len());
    }

    #[test]
    fn spatial_sort_keeps_the_surface_and_orders_vertices_along_z() {
        let mut m = hexagon();
        for (a, b) in [(0, 1), (2, 3), (0, 4)] {
            let h = m.find_edge(a, b).unwrap();
            m.split(h);
        }
        m.compact();
        let tri_positions = |m: &TriMesh| {
            let mut t: Vec<[[u32; 3]; 3]> = m
                .triangles()
                .iter()
                .map(|t| {
                    // Each triangle by its corners' positions, rotated to a
                    // canonical first corner (orientation kept).
                    let c = t.map(|v| m.pos[v as usize].to_array().map(f32::to_bits));
                    let i = (0..3).min_by_key(|&i| c[i]).unwrap();
                    [c[i], c[(i + 1) % 3], c[(i + 2) % 3]]
                })
                .collect();
            t.sort_unstable();
            t
        };
        let before = tri_positions(&m);
        let boundary: usize = m.on_boundary.iter().filter(|&&b| b).count();
        m.sort_spatially();
        m.check().unwrap();
        assert_eq!(tri_positions(&m), before);
        assert_eq!(m.on_boundary.iter().filter(|&&b| b).count(), boundary);
        let codes: Vec<u64> = morton_codes(&m.pos).collect();
        assert!(codes.is_sorted());
        assert_eq!(spread3(0b101), 0b100_0001); // bit 2 goes to bit 6
    }
}
