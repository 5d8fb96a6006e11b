//! Derived connectivity of a [`PolyMesh`]: unique edges, one-rings, boundaries,
//! non-manifold edges and connected components. Works on any polygon soup that
//! satisfies the mesh invariant, including non-manifold and multi-component meshes.

use super::PolyMesh;
use rayon::slice::ParallelSliceMut;

/// Edge and vertex adjacency of a mesh, in CSR arrays.
#[derive(Clone, Debug, Default)]
pub struct Topology {
    /// Unique undirected edges `[a, b]` with `a < b`, sorted.
    pub edges: Vec<[u32; 2]>,
    /// CSR offsets into `edge_face_list`; `edges.len() + 1` entries.
    pub edge_face_start: Vec<u32>,
    /// Faces incident to each edge.
    pub edge_face_list: Vec<u32>,
    /// CSR offsets into `neighbour_list`; `vertex_count + 1` entries.
    pub neighbour_start: Vec<u32>,
    /// Sorted one-ring neighbours of each vertex.
    pub neighbour_list: Vec<u32>,
    /// CSR offsets into `vertex_face_list`.
    pub vertex_face_start: Vec<u32>,
    /// Faces incident to each vertex.
    pub vertex_face_list: Vec<u32>,
    /// For each corner, the edge from its vertex to the next corner's vertex.
    pub corner_edge: Vec<u32>,
}

/// The key of the undirected edge between vertices `a` and `b` (the same
/// for `(a, b)` and `(b, a)`), for sorting a mesh's sides into edges.
#[inline]
pub fn edge_key(a: u32, b: u32) -> u64 {
    ((a.min(b) as u64) << 32) | a.max(b) as u64
}

/// Calls `visit(a, b, corner, face)` for every side of every face in
/// order: the side from corner `corner` (vertex `a`) to the next corner of
/// its face (vertex `b`).
pub fn for_each_side(mesh: &PolyMesh, mut visit: impl FnMut(u32, u32, usize, usize)) {
    for f in 0..mesh.face_count() {
        let r = mesh.face_corners(f);
        let n = r.len();
        for (i, c) in r.clone().enumerate() {
            visit(
                mesh.corner_vertex[c],
                mesh.corner_vertex[r.start + (i + 1) % n],
                c,
                f,
            );
        }
    }
}

/// The root of `x` in a union–find forest stored as parent links, with
/// path halving (each visited link is pointed at its grandparent).
#[inline]
pub fn union_find_root(parent: &mut [u32], mut x: u32) -> u32 {
    while parent[x as usize] != x {
        let p = parent[parent[x as usize] as usize];
        parent[x as usize] = p;
        x = p;
    }
    x
}

/// Joins the sets of `a` and `b` in a union–find forest whose roots carry
/// `size` (areas, counts): the smaller root index becomes the root and
/// takes the other's size. Returns the root.
#[inline]
pub fn union_find_join(parent: &mut [u32], size: &mut [u32], a: u32, b: u32) -> u32 {
    let (ra, rb) = (union_find_root(parent, a), union_find_root(parent, b));
    if ra == rb {
        return ra;
    }
    let (lo, hi) = (ra.min(rb), ra.max(rb));
    parent[hi as usize] = lo;
    size[lo as usize] += size[hi as usize];
    lo
}

fn csr_from_pairs(n: usize, pairs: &[(u32, u32)]) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; n + 1];
    for &(k, _) in pairs {
        start[k as usize + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut list = vec![0u32; pairs.len()];
    for &(k, v) in pairs {
        list[fill[k as usize] as usize] = v;
        fill[k as usize] += 1;
    }
    (start, list)
}

/// Faces of each vertex as CSR (offsets, list), by counting: faces in
/// increasing order, a face listed once however often the vertex occurs in it.
fn vertex_faces_csr(mesh: &PolyMesh) -> (Vec<u32>, Vec<u32>) {
    let nv = mesh.vertex_count();
    let first_in_face = |f: usize, i: usize| {
        let face = mesh.face(f);
        !face[..i].contains(&face[i])
    };
    let mut vertex_face_start = vec![0u32; nv + 1];
    for f in 0..mesh.face_count() {
        for (i, &v) in mesh.face(f).iter().enumerate() {
            if first_in_face(f, i) {
                vertex_face_start[v as usize + 1] += 1;
            }
        }
    }
    for i in 0..nv {
        vertex_face_start[i + 1] += vertex_face_start[i];
    }
    let mut fill = vertex_face_start.clone();
    let mut vertex_face_list = vec![0u32; vertex_face_start[nv] as usize];
    for f in 0..mesh.face_count() {
        for (i, &v) in mesh.face(f).iter().enumerate() {
            if first_in_face(f, i) {
                vertex_face_list[fill[v as usize] as usize] = f as u32;
                fill[v as usize] += 1;
            }
        }
    }
    (vertex_face_start, vertex_face_list)
}

impl Topology {
    /// Builds the adjacency of `mesh`. O(corners · log corners).
    ///
    /// Memory: the result is about 140 bytes per vertex of a triangle mesh;
    /// the one sort of sides (16 bytes per corner) is dropped before the
    /// other arrays are filled, and those are filled by counting (no
    /// sorted pair lists), so the build needs little beyond its result.
    pub fn build(mesh: &PolyMesh) -> Self {
        let nv = mesh.vertex_count();
        let nc = mesh.corner_count();
        // Sides keyed by their undirected edge, remembering the corner and
        // its face, ordered by (edge, corner): a counting sort by the edge's
        // lower vertex, then each vertex's few sides sorted (linear time;
        // a comparison sort of every side took most of the build).
        let mut bucket_start = vec![0u32; nv + 1];
        for_each_side(mesh, |a, b, _, _| bucket_start[a.min(b) as usize + 1] += 1);
        for i in 0..nv {
            bucket_start[i + 1] += bucket_start[i];
        }
        let mut fill = bucket_start.clone();
        let mut sides: Vec<(u64, u32, u32)> = vec![(0, 0, 0); nc];
        for_each_side(mesh, |a, b, c, f| {
            let slot = &mut fill[a.min(b) as usize];
            sides[*slot as usize] = (edge_key(a, b), c as u32, f as u32);
            *slot += 1;
        });
        drop(fill);
        for v in 0..nv {
            sides[bucket_start[v] as usize..bucket_start[v + 1] as usize].sort_unstable();
        }
        drop(bucket_start);
        let edge_count = sides
            .iter()
            .enumerate()
            .filter(|&(i, s)| i == 0 || sides[i - 1].0 != s.0)
            .count();
        let mut edges: Vec<[u32; 2]> = Vec::with_capacity(edge_count);
        let mut edge_face_start: Vec<u32> = Vec::with_capacity(edge_count + 1);
        // Faces of each edge in side order, i.e. by corner: what a stable
        // CSR fill of (edge, face of the corner) pairs gives.
        let mut edge_face_list: Vec<u32> = Vec::with_capacity(sides.len());
        let mut corner_edge = vec![0u32; nc];
        edge_face_start.push(0);
        for (i, &(key, c, f)) in sides.iter().enumerate() {
            let e = [(key >> 32) as u32, key as u32];
            if edges.last() != Some(&e) {
                if !edges.is_empty() {
                    edge_face_start.push(i as u32);
                }
                edges.push(e);
            }
            corner_edge[c as usize] = edges.len() as u32 - 1;
            edge_face_list.push(f);
        }
        if !edges.is_empty() {
            edge_face_start.push(sides.len() as u32);
        }
        drop(sides);

        // One-rings from the sorted edges: vertex v receives its lower
        // neighbours (edges [w, v], in order of w) before its upper ones
        // (edges [v, w], in order of w), so every list comes out sorted.
        let mut neighbour_start = vec![0u32; nv + 1];
        for e in &edges {
            if e[0] != e[1] {
                neighbour_start[e[0] as usize + 1] += 1;
                neighbour_start[e[1] as usize + 1] += 1;
            }
        }
        for i in 0..nv {
            neighbour_start[i + 1] += neighbour_start[i];
        }
        let mut fill = neighbour_start.clone();
        let mut neighbour_list = vec![0u32; neighbour_start[nv] as usize];
        for e in &edges {
            if e[0] != e[1] {
                for (a, b) in [(e[0], e[1]), (e[1], e[0])] {
                    neighbour_list[fill[a as usize] as usize] = b;
                    fill[a as usize] += 1;
                }
            }
        }
        drop(fill);

        let (vertex_face_start, vertex_face_list) = vertex_faces_csr(mesh);

        Self {
            edges,
            edge_face_start,
            edge_face_list,
            neighbour_start,
            neighbour_list,
            vertex_face_start,
            vertex_face_list,
            corner_edge,
        }
    }

    /// A partial topology with only [`Self::edges`] and
    /// [`Self::vertex_faces`] (equal to [`Self::build`]'s); the edge-face
    /// lists, corner edges and one-rings are empty ([`Self::neighbours`] is
    /// empty for every vertex). For readers of those two only, such as the
    /// result metrics: about 52 bytes per vertex instead of 140, and the
    /// build sorts 8-byte edge keys instead of 16-byte sides.
    pub fn build_edges_and_vertex_faces(mesh: &PolyMesh) -> Self {
        let nv = mesh.vertex_count();
        let mut keys: Vec<u64> = Vec::with_capacity(mesh.corner_count());
        for face in mesh.faces() {
            let n = face.len();
            for i in 0..n {
                keys.push(edge_key(face[i], face[(i + 1) % n]));
            }
        }
        keys.par_sort_unstable();
        keys.dedup();
        let edges: Vec<[u32; 2]> = keys.iter().map(|&k| [(k >> 32) as u32, k as u32]).collect();
        drop(keys);
        let (vertex_face_start, vertex_face_list) = vertex_faces_csr(mesh);
        Self {
            edges,
            edge_face_start: Vec::new(),
            edge_face_list: Vec::new(),
            neighbour_start: vec![0; nv + 1],
            neighbour_list: Vec::new(),
            vertex_face_start,
            vertex_face_list,
            corner_edge: Vec::new(),
        }
    }

    /// Number of vertices the topology was built for.
    pub fn vertex_count(&self) -> usize {
        self.neighbour_start.len().saturating_sub(1)
    }

    /// Sorted one-ring neighbours of `v`.
    #[inline]
    pub fn neighbours(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.neighbour_list[self.neighbour_start[v] as usize..self.neighbour_start[v + 1] as usize]
    }

    /// Faces incident to `v`.
    #[inline]
    pub fn vertex_faces(&self, v: u32) -> &[u32] {
        let v = v as usize;
        &self.vertex_face_list
            [self.vertex_face_start[v] as usize..self.vertex_face_start[v + 1] as usize]
    }

    /// Faces incident to edge `e`.
    #[inline]
    pub fn edge_faces(&self, e: u32) -> &[u32] {
        let e = e as usize;
        &self.edge_face_list[self.edge_face_start[e] as usize..self.edge_face_start[e + 1] as usize]
    }

    /// The edge joining `a` and `b`, if any.
    pub fn find_edge(&self, a: u32, b: u32) -> Option<u32> {
        let key = if a < b { [a, b] } else { [b, a] };
        self.edges.binary_search(&key).ok().map(|e| e as u32)
    }

    /// Edges with exactly one incident face.
    pub fn boundary_edges(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.edges.len() as u32).filter(|&e| self.edge_faces(e).len() == 1)
    }

    /// Edges with more than two incident faces.
    pub fn non_manifold_edges(&self) -> impl Iterator<Item = u32> + '_ {
        (0..self.edges.len() as u32).filter(|&e| self.edge_faces(e).len() > 2)
    }

    /// True when `v` lies on a boundary edge.
    pub fn is_boundary_vertex(&self, v: u32) -> bool {
        self.neighbours(v).iter().any(|&w| {
            self.find_edge(v, w)
                .is_some_and(|e| self.edge_faces(e).len() == 1)
        })
    }

    /// Per-vertex boundary flags.
    pub fn boundary_vertex_flags(&self) -> Vec<bool> {
        let mut flags = vec![false; self.vertex_count()];
        for e in self.boundary_edges() {
            let [a, b] = self.edges[e as usize];
            flags[a as usize] = true;
            flags[b as usize] = true;
        }
        flags
    }

    /// Closed loops of boundary edges, each as a vertex sequence. Boundary
    /// vertices shared by several loops (pinch points) are walked greedily, so
    /// every boundary edge lands in exactly one loop.
    pub fn boundary_loops(&self) -> Vec<Vec<u32>> {
        let boundary: Vec<u32> = self.boundary_edges().collect();
        let mut pairs: Vec<(u32, u32)> = Vec::with_capacity(boundary.len() * 2);
        for &e in &boundary {
            let [a, b] = self.edges[e as usize];
            pairs.push((a, e));
            pairs.push((b, e));
        }
        pairs.sort_unstable();
        let (start, list) = csr_from_pairs(self.vertex_count(), &pairs);
        let mut used = vec![false; self.edges.len()];
        let mut loops = Vec::new();
        for &e0 in &boundary {
            if used[e0 as usize] {
                continue;
            }
            used[e0 as usize] = true;
            let [first, mut cur] = self.edges[e0 as usize];
            let mut lp = vec![first];
            // Each step consumes one unused edge, so the walk ends.
            while cur != first {
                lp.push(cur);
                let inc = &list[start[cur as usize] as usize..start[cur as usize + 1] as usize];
                let Some(&next_e) = inc.iter().find(|&&e| !used[e as usize]) else {
                    break;
                };
                used[next_e as usize] = true;
                let [a, b] = self.edges[next_e as usize];
                cur = if a == cur { b } else { a };
            }
            loops.push(lp);
        }
        loops
    }

    /// Connected components over edges: `(count, component id per vertex)`.
    /// Isolated vertices form components of their own.
    pub fn components(&self) -> (usize, Vec<u32>) {
        let n = self.vertex_count();
        let mut comp = vec![u32::MAX; n];
        let mut count = 0u32;
        let mut stack = Vec::new();
        for s in 0..n {
            if comp[s] != u32::MAX {
                continue;
            }
            comp[s] = count;
            stack.push(s as u32);
            while let Some(v) = stack.pop() {
                for &w in self.neighbours(v) {
                    if comp[w as usize] == u32::MAX {
                        comp[w as usize] = count;
                        stack.push(w);
                    }
                }
            }
            count += 1;
        }
        (count as usize, comp)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn two_quads() -> PolyMesh {
        let p = (0..6)
            .map(|i| Vec3::new((i % 3) as f32, (i / 3) as f32, 0.0))
            .collect();
        PolyMesh::from_polygons(p, [&[0u32, 1, 4, 3][..], &[1, 2, 5, 4][..]])
    }

    /// The partial topology's edges and vertex faces equal the full one's,
    /// also with a repeated vertex in a face.
    #[test]
    fn partial_topology_matches_the_full_one() {
        let p = (0..6)
            .map(|i| Vec3::new((i % 3) as f32, (i / 3) as f32, 0.0))
            .collect();
        let faces: [&[u32]; 3] = [&[0, 1, 4, 3], &[1, 2, 5, 4], &[4, 5, 4, 2]];
        let mesh = PolyMesh::from_polygons(p, faces);
        let full = Topology::build(&mesh);
        let part = Topology::build_edges_and_vertex_faces(&mesh);
        assert_eq!(part.edges, full.edges);
        assert_eq!(part.vertex_count(), full.vertex_count());
        for v in 0..6 {
            assert_eq!(part.vertex_faces(v), full.vertex_faces(v), "vertex {v}");
        }
    }

    #[test]
    fn quad_strip_has_one_boundary_loop_and_seven_edges() {
        let m = two_quads();
        let t = Topology::build(&m);
        assert_eq!(t.edges.len(), 7);
        assert_eq!(t.boundary_edges().count(), 6);
        let loops = t.boundary_loops();
        assert_eq!(loops.len(), 1);
        assert_eq!(loops[0].len(), 6);
        assert_eq!(t.neighbours(1), &[0, 2, 4]);
        assert_eq!(t.components().0, 1);
        assert_eq!(t.vertex_faces(4), &[0, 1]);
    }

    #[test]
    fn corner_edges_join_consecutive_corners() {
        let m = two_quads();
        let t = Topology::build(&m);
        for f in 0..m.face_count() {
            let face = m.face(f);
            for (i, c) in m.face_corners(f).enumerate() {
                let e = t.edges[t.corner_edge[c] as usize];
                let a = face[i];
                let b = face[(i + 1) % face.len()];
                assert_eq!(e, [a.min(b), a.max(b)]);
            }
        }
    }
}
