//! Mesh statistics: what `surfsynth mesh-info FILE` prints.
//!
//! [`MeshInfo::compute`] counts elements, face kinds, boundaries, non-manifold
//! elements, components, orientation and genus, and measures edge lengths,
//! bounding box and area.
//!
//! Genus: for a connected, orientable, manifold surface with Euler
//! characteristic `χ = V − E + F` and `b` boundary loops,
//! `genus = (2 − χ − b) / 2`. We apply it per connected component and sum, so
//! a mesh of two spheres has genus 0 (not −1). It is `None` when the formula
//! does not apply: non-manifold edges or vertices, a non-orientable surface,
//! or an odd or negative `2 − χ − b` for some component. Isolated vertices
//! (in no face) are not surfaces and are left out of the sum.

use super::{PolyMesh, Topology};
use glam::Vec3;
use std::collections::BTreeMap;
use std::fmt;

/// Summary statistics of edge lengths, in model units (0 without edges).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EdgeLengthStats {
    pub min: f64,
    pub max: f64,
    pub mean: f64,
    /// Population standard deviation.
    pub std: f64,
}

/// Everything `mesh-info` reports about a mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshInfo {
    pub vertices: usize,
    pub faces: usize,
    /// Face degree (3 = triangle, 4 = quad, ...) → number of faces.
    pub face_kinds: BTreeMap<usize, usize>,
    /// Unique undirected edges.
    pub edges: usize,
    /// Edges with exactly one face.
    pub boundary_edges: usize,
    /// Closed loops of boundary edges.
    pub boundary_loops: usize,
    /// Edges with more than two faces.
    pub non_manifold_edges: usize,
    /// Vertices whose faces do not form one fan (e.g. two cones touching at
    /// their tips), over manifold edges.
    pub non_manifold_vertices: usize,
    /// Vertices in no face.
    pub isolated_vertices: usize,
    /// Connected components (isolated vertices count as their own).
    pub components: usize,
    /// `V − E + F` of the whole mesh.
    pub euler_characteristic: i64,
    /// Every edge with two faces is traversed once in each direction.
    pub consistently_oriented: bool,
    /// The faces could be flipped to make the orientation consistent
    /// (ignoring non-manifold edges).
    pub orientable: bool,
    /// Sum of per-component genus; see the module docs for when it is `None`.
    pub genus: Option<i64>,
    /// Lengths of the unique edges.
    pub edge_length: EdgeLengthStats,
    /// Axis-aligned bounding box `(min, max)`; `None` without vertices.
    pub bbox: Option<(Vec3, Vec3)>,
    /// Total surface area (model units squared).
    pub area: f64,
}

impl MeshInfo {
    /// Computes the statistics of `mesh`. O(corners · log corners).
    pub fn compute(mesh: &PolyMesh) -> MeshInfo {
        let topo = Topology::build(mesh);
        Self::compute_with(mesh, &topo)
    }

    /// Like [`MeshInfo::compute`], reusing a [`Topology`] built for `mesh`.
    pub fn compute_with(mesh: &PolyMesh, topo: &Topology) -> MeshInfo {
        let nv = mesh.vertex_count();
        let nf = mesh.face_count();
        let ne = topo.edges.len();

        let mut face_kinds = BTreeMap::new();
        for face in mesh.faces() {
            *face_kinds.entry(face.len()).or_insert(0) += 1;
        }
        let boundary_edges = topo.boundary_edges().count();
        let loops = topo.boundary_loops();
        let non_manifold_edges = topo.non_manifold_edges().count();
        let isolated_vertices = (0..nv as u32)
            .filter(|&v| topo.vertex_faces(v).is_empty())
            .count();
        let (components, comp) = topo.components();
        let euler_characteristic = nv as i64 - ne as i64 + nf as i64;

        let corner_face = corner_faces(mesh);
        let sides = EdgeSides::build(mesh, topo, corner_face);
        let consistently_oriented = sides.consistently_oriented();
        let orientable = sides.orientable(nf);
        let non_manifold_vertices = non_manifold_vertex_count(mesh, topo, &sides);

        let genus = if non_manifold_edges > 0 || non_manifold_vertices > 0 || !orientable {
            None
        } else {
            genus_per_component(mesh, topo, &loops, components, &comp)
        };

        MeshInfo {
            vertices: nv,
            faces: nf,
            face_kinds,
            edges: ne,
            boundary_edges,
            boundary_loops: loops.len(),
            non_manifold_edges,
            non_manifold_vertices,
            isolated_vertices,
            components,
            euler_characteristic,
            consistently_oriented,
            orientable,
            genus,
            edge_length: edge_length_stats(mesh, topo),
            bbox: mesh.bounding_box(),
            area: (0..nf)
                .map(|f| super::repair::polygon_area(&mesh.positions, mesh.face(f)))
                .sum(),
        }
    }

    /// No boundary and no non-manifold edge.
    pub fn is_closed(&self) -> bool {
        self.boundary_edges == 0 && self.non_manifold_edges == 0
    }

    /// Face kinds as text, e.g. `3674 triangles` or `10 triangles, 2 quads, 1 5-gon`.
    pub fn face_kinds_text(&self) -> String {
        let parts: Vec<String> = self
            .face_kinds
            .iter()
            .map(|(&k, &n)| {
                let (one, many) = match k {
                    3 => ("triangle".to_string(), "triangles".to_string()),
                    4 => ("quad".to_string(), "quads".to_string()),
                    k => (format!("{k}-gon"), format!("{k}-gons")),
                };
                format!("{n} {}", if n == 1 { one } else { many })
            })
            .collect();
        if parts.is_empty() {
            "none".to_string()
        } else {
            parts.join(", ")
        }
    }
}

fn corner_faces(mesh: &PolyMesh) -> Vec<u32> {
    let mut corner_face = vec![0u32; mesh.corner_count()];
    for f in 0..mesh.face_count() {
        corner_face[mesh.face_corners(f)].fill(f as u32);
    }
    corner_face
}

/// For each edge with exactly two sides: the two corners that traverse it.
struct EdgeSides {
    /// Per edge, up to two corners `c` whose side `c → next(c)` lies on it.
    corners: Vec<[u32; 2]>,
    /// Per edge, how many sides lie on it.
    count: Vec<u32>,
    /// Per corner, whether its side goes from the smaller to the larger vertex id.
    forward: Vec<bool>,
    corner_face: Vec<u32>,
}

impl EdgeSides {
    fn build(mesh: &PolyMesh, topo: &Topology, corner_face: Vec<u32>) -> Self {
        let ne = topo.edges.len();
        let mut corners = vec![[u32::MAX; 2]; ne];
        let mut count = vec![0u32; ne];
        let mut forward = vec![false; mesh.corner_count()];
        crate::mesh::topology::for_each_side(mesh, |a, b, c, _| {
            forward[c] = a < b;
            let e = topo.corner_edge[c] as usize;
            if count[e] < 2 {
                corners[e][count[e] as usize] = c as u32;
            }
            count[e] += 1;
        });
        Self {
            corners,
            count,
            forward,
            corner_face,
        }
    }

    /// The two `(face, forward)` sides of a manifold interior edge.
    fn pair(&self, e: usize) -> Option<[(u32, bool); 2]> {
        (self.count[e] == 2).then(|| {
            self.corners[e].map(|c| (self.corner_face[c as usize], self.forward[c as usize]))
        })
    }

    fn consistently_oriented(&self) -> bool {
        (0..self.count.len()).all(|e| self.pair(e).is_none_or(|[(_, d0), (_, d1)]| d0 != d1))
    }

    /// Two-colours the faces by "flipped or not" across manifold edges; a
    /// conflict means the surface is non-orientable.
    fn orientable(&self, face_count: usize) -> bool {
        // Face adjacency over manifold edges, with "needs opposite flip" flags.
        let mut links: Vec<(u32, u32, bool)> = Vec::new();
        for e in 0..self.count.len() {
            if let Some([(f, d0), (g, d1)]) = self.pair(e)
                && f != g
            {
                // Consistent neighbours traverse the edge in opposite
                // directions; if they agree, exactly one must flip.
                let differ = d0 == d1;
                links.push((f, g, differ));
                links.push((g, f, differ));
            }
        }
        links.sort_unstable();
        let mut start = vec![0usize; face_count + 1];
        for &(f, _, _) in &links {
            start[f as usize + 1] += 1;
        }
        for i in 0..face_count {
            start[i + 1] += start[i];
        }
        let mut flip: Vec<Option<bool>> = vec![None; face_count];
        let mut stack = Vec::new();
        for s in 0..face_count {
            if flip[s].is_some() {
                continue;
            }
            flip[s] = Some(false);
            stack.push(s);
            while let Some(f) = stack.pop() {
                let ff = flip[f].unwrap_or(false);
                for &(_, g, differ) in &links[start[f]..start[f + 1]] {
                    let want = ff ^ differ;
                    match flip[g as usize] {
                        None => {
                            flip[g as usize] = Some(want);
                            stack.push(g as usize);
                        }
                        Some(have) if have != want => return false,
                        Some(_) => {}
                    }
                }
            }
        }
        true
    }
}

/// Counts vertices whose incident corners fall into more than one fan, where
/// two corners at a vertex are in the same fan when their faces share a
/// manifold edge incident to that vertex.
fn non_manifold_vertex_count(mesh: &PolyMesh, topo: &Topology, sides: &EdgeSides) -> usize {
    let nc = mesh.corner_count();
    let mut parent: Vec<u32> = (0..nc as u32).collect();
    use super::union_find_root as find;
    // The corner of face `f` at vertex `v`.
    let corner_at = |f: u32, v: u32| {
        mesh.face_corners(f as usize)
            .find(|&c| mesh.corner_vertex[c] == v)
            .map(|c| c as u32)
    };
    for (e, [a, b]) in topo.edges.iter().enumerate() {
        let Some([(f, _), (g, _)]) = sides.pair(e) else {
            continue;
        };
        if f == g {
            continue;
        }
        for v in [*a, *b] {
            if let (Some(cf), Some(cg)) = (corner_at(f, v), corner_at(g, v)) {
                let (rf, rg) = (find(&mut parent, cf), find(&mut parent, cg));
                parent[rf as usize] = rg;
            }
        }
    }
    let mut pairs: Vec<(u32, u32)> = (0..nc as u32)
        .map(|c| (mesh.corner_vertex[c as usize], find(&mut parent, c)))
        .collect();
    pairs.sort_unstable();
    pairs.dedup();
    let mut count = 0;
    for run in pairs.chunk_by(|x, y| x.0 == y.0) {
        if run.len() > 1 {
            count += 1;
        }
    }
    count
}

fn genus_per_component(
    mesh: &PolyMesh,
    topo: &Topology,
    loops: &[Vec<u32>],
    components: usize,
    comp: &[u32],
) -> Option<i64> {
    // Per component: V, E, F, boundary loops.
    let mut counts = vec![[0i64; 4]; components];
    for &c in comp {
        counts[c as usize][0] += 1;
    }
    for [a, _] in &topo.edges {
        counts[comp[*a as usize] as usize][1] += 1;
    }
    for face in mesh.faces() {
        counts[comp[face[0] as usize] as usize][2] += 1;
    }
    for lp in loops {
        if let Some(&v) = lp.first() {
            counts[comp[v as usize] as usize][3] += 1;
        }
    }
    let mut genus = 0;
    for [v, e, f, b] in counts {
        if f == 0 {
            continue; // an isolated vertex
        }
        let twice = 2 - (v - e + f) - b;
        if twice < 0 || twice % 2 != 0 {
            return None;
        }
        genus += twice / 2;
    }
    Some(genus)
}

fn edge_length_stats(mesh: &PolyMesh, topo: &Topology) -> EdgeLengthStats {
    if topo.edges.is_empty() {
        return EdgeLengthStats::default();
    }
    let mut s = EdgeLengthStats {
        min: f64::INFINITY,
        max: 0.0,
        mean: 0.0,
        std: 0.0,
    };
    let (mut sum, mut sum2) = (0.0f64, 0.0f64);
    for [a, b] in &topo.edges {
        let l = (mesh.positions[*a as usize].as_dvec3() - mesh.positions[*b as usize].as_dvec3())
            .length();
        s.min = s.min.min(l);
        s.max = s.max.max(l);
        sum += l;
        sum2 += l * l;
    }
    let n = topo.edges.len() as f64;
    s.mean = sum / n;
    s.std = (sum2 / n - s.mean * s.mean).max(0.0).sqrt();
    s
}

/// Formats a float with 6 significant digits, without trailing zeros noise.
fn num(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let mag = x.abs().log10().floor() as i32;
    if (-4..6).contains(&mag) {
        let decimals = (5 - mag).max(0) as usize;
        let s = format!("{x:.decimals$}");
        if s.contains('.') {
            s.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            s
        }
    } else {
        format!("{x:.5e}")
    }
}

impl fmt::Display for MeshInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let row = |f: &mut fmt::Formatter<'_>, label: &str, value: String| {
            writeln!(f, "{label:<24}{value}")
        };
        let int = |n: usize| format!("{n:>10}");
        row(f, "vertices", int(self.vertices))?;
        row(
            f,
            "faces",
            format!("{}  ({})", int(self.faces), self.face_kinds_text()),
        )?;
        row(f, "edges", int(self.edges))?;
        row(f, "boundary edges", int(self.boundary_edges))?;
        row(f, "boundary loops", int(self.boundary_loops))?;
        row(f, "non-manifold edges", int(self.non_manifold_edges))?;
        row(f, "non-manifold vertices", int(self.non_manifold_vertices))?;
        row(f, "isolated vertices", int(self.isolated_vertices))?;
        row(f, "components", int(self.components))?;
        row(
            f,
            "Euler characteristic",
            format!("{:>10}", self.euler_characteristic),
        )?;
        let orientation = if self.consistently_oriented {
            "consistent"
        } else if self.orientable {
            "inconsistent (orientable: some faces are flipped)"
        } else {
            "non-orientable"
        };
        row(f, "orientation", format!("{orientation:>10}"))?;
        let closed = if self.is_closed() { "closed" } else { "open" };
        let genus = match self.genus {
            Some(g) => format!("{g:>10}  ({closed}; (2 - chi - b) / 2 summed over components)"),
            None => format!("{:>10}  ({closed}; non-manifold or non-orientable)", "n/a"),
        };
        row(f, "genus", genus)?;
        let e = &self.edge_length;
        row(
            f,
            "edge length",
            format!(
                "min {}  mean {}  max {}  std {}",
                num(e.min),
                num(e.mean),
                num(e.max),
                num(e.std)
            ),
        )?;
        match self.bbox {
            Some((lo, hi)) => {
                let v = |p: Vec3| {
                    format!(
                        "[{}, {}, {}]",
                        num(p.x as f64),
                        num(p.y as f64),
                        num(p.z as f64)
                    )
                };
                let size = (hi - lo).as_dvec3();
                row(f, "bounding box", format!("{} .. {}", v(lo), v(hi)))?;
                row(
                    f,
                    "size",
                    format!(
                        "{} x {} x {}  (diagonal {})",
                        num(size.x),
                        num(size.y),
                        num(size.z),
                        num(size.length())
                    ),
                )?;
            }
            None => row(f, "bounding box", "empty".into())?,
        }
        row(f, "area", num(self.area))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tetra() -> PolyMesh {
        let p = vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        PolyMesh::from_triangles(p, &[[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    }

    #[test]
    fn tetrahedron() {
        let i = MeshInfo::compute(&tetra());
        assert_eq!((i.vertices, i.faces, i.edges), (4, 4, 6));
        assert_eq!(i.euler_characteristic, 2);
        assert_eq!(i.genus, Some(0));
        assert!(i.is_closed() && i.consistently_oriented && i.orientable);
        assert_eq!(i.face_kinds.get(&3), Some(&4));
        assert!((i.edge_length.min - 1.0).abs() < 1e-6);
        assert!((i.edge_length.max - 2f64.sqrt()).abs() < 1e-6);
        let text = i.to_string();
        assert!(text.contains("4 triangles"), "{text}");
        assert!(text.lines().all(|l| l.len() > 24), "{text}");
    }

    #[test]
    fn flipped_face_is_inconsistent_but_orientable() {
        let mut m = tetra();
        m.corner_vertex[0..3].copy_from_slice(&[0, 1, 2]);
        let i = MeshInfo::compute(&m);
        assert!(!i.consistently_oriented);
        assert!(i.orientable);
        assert_eq!(i.genus, Some(0));
    }

    #[test]
    fn two_tetrahedra_touching_at_a_vertex() {
        let mut p = tetra().positions;
        p.extend([
            Vec3::new(-1.0, 0.0, 0.0),
            Vec3::new(0.0, -1.0, 0.0),
            Vec3::new(0.0, 0.0, -1.0),
        ]);
        let m = PolyMesh::from_triangles(
            p,
            &[
                [0, 2, 1],
                [0, 1, 3],
                [1, 2, 3],
                [0, 3, 2],
                [0, 4, 5],
                [0, 6, 4],
                [4, 6, 5],
                [0, 5, 6],
            ],
        );
        let i = MeshInfo::compute(&m);
        assert_eq!(i.non_manifold_vertices, 1);
        assert_eq!(i.components, 1);
        assert_eq!(i.genus, None);
    }

    #[test]
    fn open_square_and_non_manifold_fin() {
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::Y,
            Vec3::Z,
        ];
        let sq = PolyMesh::from_polygons(p.clone(), [&[0u32, 1, 2, 3][..]]);
        let i = MeshInfo::compute(&sq);
        assert_eq!(
            (i.boundary_loops, i.boundary_edges, i.genus),
            (1, 4, Some(0))
        );
        assert_eq!(i.isolated_vertices, 1);
        assert_eq!(i.components, 2);
        assert!((i.area - 1.0).abs() < 1e-9);

        let fin = PolyMesh::from_triangles(p, &[[0, 1, 2], [0, 2, 3], [0, 2, 4]]);
        let i = MeshInfo::compute(&fin);
        assert_eq!(i.non_manifold_edges, 1);
        assert_eq!(i.genus, None);
        assert!(i.to_string().contains("n/a"));
    }

    #[test]
    fn mobius_strip_is_non_orientable() {
        // A strip of 4 quads whose ends are glued with a half twist.
        let n = 4;
        let mut p = Vec::new();
        for i in 0..n {
            let a = i as f32 / n as f32 * std::f32::consts::TAU;
            p.push(Vec3::new(a.cos(), a.sin(), -0.2));
            p.push(Vec3::new(a.cos(), a.sin(), 0.2));
        }
        let mut faces: Vec<[u32; 4]> = (0..n - 1)
            .map(|i| [2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1])
            .collect();
        let last = 2 * (n - 1);
        faces.push([last, 1, 0, last + 1]);
        let m = PolyMesh::from_polygons(p, faces.iter().map(|f| &f[..]));
        let i = MeshInfo::compute(&m);
        assert!(!i.orientable);
        assert_eq!(i.genus, None);
        assert_eq!(i.boundary_loops, 1);
    }
}
