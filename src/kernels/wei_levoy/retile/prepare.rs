//! Turns a user's polygon mesh into the manifold triangle mesh the remesher
//! needs, or says precisely why it cannot.
//!
//! Steps, in order: fan-triangulate every polygon (the same triangles, in the
//! same order, as [`PolyMesh::triangulated`]); drop triangles with a repeated
//! vertex; cut non-manifold edges (more than two triangles: the two that
//! best continue each other stay joined, the others are detached along that
//! edge, and the vertices of the cut get one copy per fan); orient every
//! component consistently (keeping the orientation most of its triangles
//! already have) or reject it as non-orientable; split non-manifold vertices
//! (several fans of triangles meeting at one vertex) into one vertex per fan;
//! number the boundary loops. Vertices in no triangle are left out.

use super::RetileError;
use super::trimesh::{NONE, TriMesh, next, prev};
use crate::mesh::{PolyMesh, edge_key, union_find_root as root};
use glam::Vec3;

/// What preparing the input changed, so callers can tell the user.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct InputReport {
    /// Input polygons with more than three corners (fan-triangulated).
    pub triangulated_polygons: usize,
    /// Triangles dropped because two of their corners are the same vertex.
    pub dropped_degenerate_triangles: usize,
    /// Triangles turned over to orient their component consistently.
    pub reoriented_triangles: usize,
    /// Extra vertices made by splitting non-manifold vertices (one per
    /// additional fan).
    pub split_vertices: usize,
    /// Non-manifold edges (three or more triangles) cut apart.
    pub cut_edges: usize,
    /// Extra vertices made where those cuts separated fans.
    pub cut_vertices: usize,
    /// Input vertices in no face (not part of any surface; left out).
    pub isolated_vertices: usize,
    /// Connected components of the surface.
    pub components: usize,
    /// Boundary loops of the surface.
    pub boundary_loops: usize,
}

/// The prepared input: the manifold mesh plus the way back to the input.
#[derive(Debug)]
pub(crate) struct Prepared {
    /// Oriented manifold triangle mesh; `loop_id` is set on boundary vertices.
    pub mesh: TriMesh,
    /// For each triangle of `mesh`: its index among the triangles of
    /// `input.triangulated()`.
    pub tri_source: Vec<u32>,
    /// Whether the triangle was turned over (its corners 1 and 2 swapped).
    pub tri_flipped: Vec<bool>,
    pub report: InputReport,
}

/// Prepares `input` for remeshing; see the module docs.
///
/// # Errors
/// [`RetileError::NoFaces`], [`RetileError::NonFinite`],
/// [`RetileError::NonManifoldEdge`], [`RetileError::NonOrientable`].
pub(crate) fn prepare(input: &PolyMesh) -> Result<Prepared, RetileError> {
    if input.face_count() == 0 {
        return Err(RetileError::NoFaces {
            detail: String::new(),
        });
    }
    if let Some((v, p)) = input
        .positions
        .iter()
        .enumerate()
        .find(|(_, p)| !p.is_finite())
    {
        return Err(RetileError::NonFinite {
            vertex: v as u32,
            position: p.to_array(),
        });
    }
    let mut report = InputReport {
        triangulated_polygons: input.faces().filter(|f| f.len() > 3).count(),
        ..InputReport::default()
    };
    let (corner_tris, _) = input.triangulate_corners();
    let mut tris: Vec<[u32; 3]> = Vec::with_capacity(corner_tris.len());
    let mut tri_source: Vec<u32> = Vec::with_capacity(corner_tris.len());
    for (i, t) in corner_tris.iter().enumerate() {
        let [a, b, c] = t.map(|c| input.corner_vertex[c as usize]);
        if a == b || b == c || c == a {
            report.dropped_degenerate_triangles += 1;
        } else {
            tris.push([a, b, c]);
            tri_source.push(i as u32);
        }
    }
    if tris.is_empty() {
        return Err(RetileError::NoFaces {
            detail: format!(
                " (all {} triangles repeat a vertex)",
                report.dropped_degenerate_triangles
            ),
        });
    }
    let mut used = vec![false; input.vertex_count()];
    tris.iter().flatten().for_each(|&v| used[v as usize] = true);
    report.isolated_vertices = used.iter().filter(|&&u| !u).count();

    let mut positions = input.positions.clone();
    (report.cut_edges, report.cut_vertices) = cut_nonmanifold_edges(&mut tris, &mut positions);

    let tri_flipped = orient(&mut tris, &tri_source)?;
    report.reoriented_triangles = tri_flipped.iter().filter(|&&f| f).count();

    let mut mesh = TriMesh::from_triangles(positions, &tris).map_err(|(a, b)| {
        // `orient` leaves no directed edge twice; keep a message anyway.
        RetileError::NonManifoldEdge {
            a,
            b,
            faces: 2,
            total: 1,
        }
    })?;
    report.split_vertices = split_nonmanifold_vertices(&mut mesh);
    report.boundary_loops = number_boundary_loops(&mut mesh);
    report.components = count_components(&mesh);
    Ok(Prepared {
        mesh,
        tri_source,
        tri_flipped,
        report,
    })
}

/// A triangle's side along an edge: (edge key, triangle, corner).
type Side = (u64, u32, u8);

/// Cuts every edge that three or more triangles share, as a scan's fins,
/// flaps and touching parts need: the triangles on the edge are paired
/// greedily, each with the next one running along it in the opposite
/// direction (a consistently oriented pair; else the next one), and only
/// pairs stay joined there (a side past the eighth stays alone). Then every
/// vertex gets one copy per fan of its triangles still joined through
/// edges (corners joined by union-find across the kept edges), so each
/// detached triangle's corners on the cut become their own vertices.
///
/// The pairing can disagree with the fans: two cubes sharing an edge, with
/// a triangle of each cube paired, join both cubes' fans at the edge's ends
/// into one, so all four triangles stay on one edge. Such an edge keeps no
/// pair in a second pass: around a vertex, the corners joined through
/// edges form paths and cycles (a corner has two edges, and each edge
/// joins it to at most one other), and an edge with no pair joined ends
/// paths, two per path, so at most two triangles stay on each copy of it.
/// Dropping joins never puts more triangles on another edge's copies, so
/// the mesh is then edge-manifold. Linear in the triangles (one sort, at
/// most two passes). Returns (edges cut, vertices added); nothing changes
/// on an edge-manifold mesh.
fn cut_nonmanifold_edges(tris: &mut [[u32; 3]], positions: &mut Vec<Vec3>) -> (usize, usize) {
    // Sides keyed by their undirected edge: (key, triangle, corner of a).
    let mut sides: Vec<Side> = Vec::with_capacity(tris.len() * 3);
    for (t, tri) in tris.iter().enumerate() {
        for i in 0..3 {
            sides.push((edge_key(tri[i], tri[(i + 1) % 3]), t as u32, i as u8));
        }
    }
    sides.sort_unstable();
    // Sides that stay joined, with the non-manifold edge (its index in
    // `cut`) they were paired on, if any.
    let mut pairs: Vec<(Side, Side, Option<usize>)> = Vec::new();
    // The sides of each non-manifold edge.
    let mut cut: Vec<&[Side]> = Vec::new();
    let forward = |s: &Side| {
        let tri = tris[s.1 as usize];
        tri[s.2 as usize] < tri[(s.2 as usize + 1) % 3]
    };
    for group in sides.chunk_by(|a, b| a.0 == b.0) {
        let edge = (group.len() > 2).then_some(cut.len());
        if edge.is_some() {
            cut.push(group);
        }
        // Pair the sides greedily: each unpaired side with the next one
        // running the other way along the edge (else the next one).
        let mut paired = [false; 8];
        let n = group.len().min(paired.len());
        for a in 0..n {
            if paired[a] {
                continue;
            }
            let free = (a + 1..n).filter(|&b| !paired[b]);
            let partner = free
                .clone()
                .find(|&b| forward(&group[b]) != forward(&group[a]))
                .or_else(|| free.clone().next());
            if let Some(b) = partner {
                paired[a] = true;
                paired[b] = true;
                pairs.push((group[a], group[b], edge));
            }
        }
    }
    if cut.is_empty() {
        return (0, 0);
    }
    let mut unpaired = vec![false; cut.len()];
    let (split, added) = loop {
        let (split, added) = split_fans(tris, positions.len(), &pairs, &unpaired);
        // A cut edge whose sides still share a copy of the edge three or
        // more times loses its pairs; the second pass always succeeds.
        let mut again = false;
        for (e, group) in cut.iter().enumerate() {
            let mut keys: Vec<u64> = group
                .iter()
                .map(|&(_, t, c)| {
                    let tri = split[t as usize];
                    edge_key(tri[c as usize].0, tri[(c as usize + 1) % 3].0)
                })
                .collect();
            keys.sort_unstable();
            if !unpaired[e] && keys.chunk_by(|a, b| a == b).any(|k| k.len() > 2) {
                unpaired[e] = true;
                again = true;
            }
        }
        if !again {
            break (split, added);
        }
    };
    positions.resize(positions.len() + added, Vec3::ZERO);
    for (tri, new) in tris.iter_mut().zip(&split) {
        for (corner, &(v, copy_of)) in tri.iter_mut().zip(new) {
            if let Some(from) = copy_of {
                positions[v as usize] = positions[from as usize];
            }
            *corner = v;
        }
    }
    (cut.len(), added)
}

/// One vertex per fan of corners joined across `pairs` (except those on
/// the edges marked in `unpaired`): the first fan met keeps the vertex,
/// each further one gets a new vertex numbered from `vertex_count`. Returns
/// each triangle's corners as (vertex, the vertex it copies if new) and
/// the number of new vertices.
#[allow(clippy::type_complexity)]
fn split_fans(
    tris: &[[u32; 3]],
    vertex_count: usize,
    pairs: &[(Side, Side, Option<usize>)],
    unpaired: &[bool],
) -> (Vec<[(u32, Option<u32>); 3]>, usize) {
    let mut parent: Vec<u32> = (0..tris.len() as u32 * 3).collect();
    for &(s, t, edge) in pairs {
        if edge.is_some_and(|e| unpaired[e]) {
            continue;
        }
        // Join the corners of s and t at each end of the edge.
        let (ts, cs) = (s.1 as usize, s.2 as usize);
        let tt = t.1 as usize;
        for v in [tris[ts][cs], tris[ts][(cs + 1) % 3]] {
            let corner_s = 3 * ts + (0..3).find(|&k| tris[ts][k] == v).unwrap_or(0);
            let corner_t = 3 * tt + (0..3).find(|&k| tris[tt][k] == v).unwrap_or(0);
            let (a, b) = (
                root(&mut parent, corner_s as u32),
                root(&mut parent, corner_t as u32),
            );
            if a != b {
                parent[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut fan_vertex: Vec<(u32, Option<u32>)> = vec![(u32::MAX, None); parent.len()];
    let mut vertex_taken = vec![false; vertex_count];
    let mut added = 0;
    let mut split = vec![[(0, None); 3]; tris.len()];
    for c in 0..parent.len() {
        let r = root(&mut parent, c as u32) as usize;
        let v = tris[c / 3][c % 3];
        if fan_vertex[r].0 == u32::MAX {
            fan_vertex[r] = if vertex_taken[v as usize] {
                added += 1;
                ((vertex_count + added - 1) as u32, Some(v))
            } else {
                vertex_taken[v as usize] = true;
                (v, None)
            };
        }
        split[c / 3][c % 3] = fan_vertex[r];
    }
    (split, added)
}

/// Checks edge manifoldness and orients each component consistently.
/// Returns which triangles were turned over.
fn orient(tris: &mut [[u32; 3]], tri_source: &[u32]) -> Result<Vec<bool>, RetileError> {
    // Sides keyed by their undirected edge: (key, triangle, forward).
    let mut sides: Vec<(u64, u32, bool)> = Vec::with_capacity(tris.len() * 3);
    for (t, tri) in tris.iter().enumerate() {
        for i in 0..3 {
            let (a, b) = (tri[i], tri[(i + 1) % 3]);
            sides.push((edge_key(a, b), t as u32, a < b));
        }
    }
    sides.sort_unstable();
    // Adjacency across manifold edges, and the first non-manifold edge.
    let mut adj: Vec<(u32, u32, bool)> = Vec::with_capacity(sides.len());
    let mut bad: Option<(u64, usize)> = None;
    let mut bad_total = 0;
    let mut i = 0;
    while i < sides.len() {
        let mut j = i + 1;
        while j < sides.len() && sides[j].0 == sides[i].0 {
            j += 1;
        }
        match j - i {
            1 => {}
            2 => {
                let (s, t) = (sides[i], sides[i + 1]);
                // Same direction along the shared edge: orientations disagree.
                let same = s.2 == t.2;
                adj.push((s.1, t.1, same));
                adj.push((t.1, s.1, same));
            }
            n => {
                bad_total += 1;
                if bad.is_none() {
                    bad = Some((sides[i].0, n));
                }
            }
        }
        i = j;
    }
    if let Some((key, faces)) = bad {
        return Err(RetileError::NonManifoldEdge {
            a: (key >> 32) as u32,
            b: key as u32,
            faces,
            total: bad_total,
        });
    }
    adj.sort_unstable();
    let mut start = vec![0u32; tris.len() + 1];
    for &(t, _, _) in &adj {
        start[t as usize + 1] += 1;
    }
    for t in 0..tris.len() {
        start[t + 1] += start[t];
    }

    // Breadth-first 2-colouring: flip[t] says whether t disagrees with the root.
    const UNSET: u8 = 2;
    let mut flip = vec![UNSET; tris.len()];
    let mut queue: Vec<u32> = Vec::new();
    let mut turned = vec![false; tris.len()];
    for root in 0..tris.len() {
        if flip[root] != UNSET {
            continue;
        }
        flip[root] = 0;
        queue.clear();
        queue.push(root as u32);
        let mut head = 0;
        while head < queue.len() {
            let t = queue[head] as usize;
            head += 1;
            for &(_, u, same) in &adj[start[t] as usize..start[t + 1] as usize] {
                let want = flip[t] ^ same as u8;
                let u = u as usize;
                if flip[u] == UNSET {
                    flip[u] = want;
                    queue.push(u as u32);
                } else if flip[u] != want {
                    return Err(RetileError::NonOrientable {
                        face: tri_source[u],
                    });
                }
            }
        }
        // Keep the orientation most of the component already has.
        let disagree = queue.iter().filter(|&&t| flip[t as usize] == 1).count();
        let turn_disagreeing = 2 * disagree <= queue.len();
        for &t in &queue {
            let t = t as usize;
            turned[t] = (flip[t] == 1) == turn_disagreeing;
        }
    }
    for (tri, &turn) in tris.iter_mut().zip(&turned) {
        if turn {
            tri.swap(1, 2);
        }
    }
    Ok(turned)
}

/// Gives every extra fan at a vertex its own copy of the vertex. Returns the
/// number of copies made.
fn split_nonmanifold_vertices(mesh: &mut TriMesh) -> usize {
    let nh = mesh.halfedge_slots() as u32;
    let mut visited = vec![false; nh as usize];
    let mut fan_seen = vec![false; mesh.pos.len()];
    let mut copies = 0;
    for h0 in 0..nh {
        if visited[h0 as usize] {
            continue;
        }
        let v = mesh.vert[h0 as usize];
        // Rewind to the start of this fan, then walk it.
        let mut s = h0;
        loop {
            let t = mesh.twin[prev(s) as usize];
            if t == NONE || t == h0 {
                s = if t == NONE { s } else { h0 };
                break;
            }
            s = t;
        }
        let target = if fan_seen[v as usize] {
            copies += 1;
            let p = mesh.pos[v as usize];
            mesh.pos.push(p);
            mesh.out.push(NONE);
            mesh.on_boundary.push(false);
            mesh.loop_id.push(NONE);
            mesh.src_face.push(0);
            mesh.src_bary.push(Vec3::X);
            mesh.ref_normal.push(Vec3::Z);
            (mesh.pos.len() - 1) as u32
        } else {
            fan_seen[v as usize] = true;
            v
        };
        let mut h = s;
        loop {
            visited[h as usize] = true;
            mesh.vert[h as usize] = target;
            let t = mesh.twin[h as usize];
            if t == NONE {
                break;
            }
            h = next(t);
            if h == s {
                break;
            }
        }
    }
    if copies > 0 {
        mesh.rebuild_vertex_links();
    }
    copies
}

/// Numbers the boundary loops (sets `loop_id` of boundary vertices); returns
/// how many there are.
fn number_boundary_loops(mesh: &mut TriMesh) -> usize {
    let nh = mesh.halfedge_slots() as u32;
    let mut done = vec![false; nh as usize];
    let mut loops = 0u32;
    for h0 in 0..nh {
        if mesh.twin[h0 as usize] != NONE || done[h0 as usize] {
            continue;
        }
        let mut h = h0;
        loop {
            done[h as usize] = true;
            mesh.loop_id[mesh.vert[h as usize] as usize] = loops;
            // The boundary half-edge leaving the target: the last of its fan.
            let mut g = next(h);
            while mesh.twin[g as usize] != NONE {
                g = next(mesh.twin[g as usize]);
            }
            h = g;
            if h == h0 || done[h as usize] {
                break;
            }
        }
        loops += 1;
    }
    loops as usize
}

/// Connected components of the live part of the mesh.
pub(crate) fn count_components(mesh: &TriMesh) -> usize {
    component_labels(mesh).1 as usize
}

/// Per vertex, its connected component of the live part of the mesh
/// (`NONE` for dead vertices), numbered in order of their lowest vertex;
/// and the number of components.
pub(crate) fn component_labels(mesh: &TriMesh) -> (Vec<u32>, u32) {
    let nv = mesh.pos.len();
    let mut label = vec![NONE; nv];
    let mut stack = Vec::new();
    let mut ring = Vec::new();
    let mut count = 0u32;
    for s in 0..nv as u32 {
        if label[s as usize] != NONE || mesh.out[s as usize] == NONE {
            continue;
        }
        label[s as usize] = count;
        stack.push(s);
        while let Some(v) = stack.pop() {
            mesh.ring(v, &mut ring);
            for &w in &ring {
                if label[w as usize] == NONE {
                    label[w as usize] = count;
                    stack.push(w);
                }
            }
        }
        count += 1;
    }
    (label, count)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_cones_touching_at_the_tip_are_split() {
        // Two triangle fans (open cones) sharing only vertex 0.
        let mut pos = vec![Vec3::ZERO];
        for s in [1.0f32, -1.0] {
            for i in 0..4 {
                let a = i as f32 * std::f32::consts::FRAC_PI_2;
                pos.push(Vec3::new(a.cos(), a.sin(), s));
            }
        }
        let mut faces: Vec<[u32; 3]> = Vec::new();
        for k in 0..2u32 {
            for i in 0..4 {
                faces.push([0, 1 + 4 * k + i, 1 + 4 * k + (i + 1) % 4]);
            }
        }
        let mesh = PolyMesh::from_triangles(pos, &faces);
        let p = prepare(&mesh).unwrap();
        assert_eq!(p.report.split_vertices, 1);
        assert_eq!(p.report.components, 2);
        assert_eq!(p.report.boundary_loops, 2);
        p.mesh.check().unwrap();
    }

    #[test]
    fn inconsistent_orientation_is_repaired() {
        let pos = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::Y,
            Vec3::new(2.0, 0.5, 0.0),
        ];
        let mesh = PolyMesh::from_triangles(pos, &[[0, 1, 2], [0, 3, 2], [1, 4, 2]]);
        let p = prepare(&mesh).unwrap();
        assert_eq!(p.report.reoriented_triangles, 1);
        assert_eq!(p.tri_flipped, vec![false, true, false]);
        p.mesh.check().unwrap();
    }

    #[test]
    fn non_manifold_edge_is_cut_keeping_the_oriented_pair() {
        let pos = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z, Vec3::NEG_Y];
        // Three triangles on edge 0-1: [0,1,2] and [1,0,3] run along it in
        // opposite directions and stay joined; [0,1,4] is cut off.
        let mesh = PolyMesh::from_triangles(pos, &[[0, 1, 2], [1, 0, 3], [0, 1, 4]]);
        let p = prepare(&mesh).unwrap();
        p.mesh.check().unwrap();
        assert_eq!(p.report.cut_edges, 1);
        assert_eq!(p.report.cut_vertices, 2);
        assert_eq!(p.report.components, 2);
        assert_eq!(p.report.reoriented_triangles, 0);
    }

    #[test]
    fn a_fan_of_four_triangles_on_one_edge_becomes_two_manifold_pieces() {
        let pos = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::Z,
            Vec3::NEG_Y,
            Vec3::NEG_Z,
        ];
        let mesh = PolyMesh::from_triangles(pos, &[[0, 1, 2], [1, 0, 3], [0, 1, 4], [1, 0, 5]]);
        let p = prepare(&mesh).unwrap();
        p.mesh.check().unwrap();
        assert_eq!(p.report.cut_edges, 1);
        assert_eq!(p.report.components, 2);
    }
}
