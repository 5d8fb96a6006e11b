//! Parent faces on a coarser mesh level: where the normal line of a finer
//! vertex meets the coarser surface (Wei & Levoy 2001 §3.3), with the nearest
//! surface point as a fallback. A bounding-volume hierarchy over the
//! fan triangles of the coarser level answers both queries.

use glam::Vec3;

use crate::kernels::surface::flatten::TriangleAdjacency;

/// A point on a triangle of the coarser level.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfacePoint {
    /// Triangle index in the level's [`TriangleAdjacency`].
    pub tri: u32,
    /// Barycentric weights of the point over the triangle's vertices.
    pub weights: [f32; 3],
    /// The point.
    pub at: Vec3,
}

#[derive(Clone, Copy, Debug)]
struct Node {
    min: Vec3,
    max: Vec3,
    /// Leaf: first triangle slot; inner: index of the left child (the right
    /// child follows the left subtree, at `right`).
    start: u32,
    /// Leaf: number of triangles (> 0); inner: 0.
    count: u32,
    /// Inner: index of the right child.
    right: u32,
}

/// Triangles per leaf at most.
const LEAF_SIZE: usize = 4;

/// A bounding-volume hierarchy over the triangles of one mesh level.
#[derive(Clone, Debug)]
pub struct TriangleBvh {
    nodes: Vec<Node>,
    /// Triangle ids in leaf order.
    order: Vec<u32>,
    /// Corners of each triangle (by triangle id).
    corners: Vec<[Vec3; 3]>,
}

impl TriangleBvh {
    /// Builds the hierarchy (median splits along the widest centroid axis).
    /// Deterministic; O(t log² t).
    pub fn new(adjacency: &TriangleAdjacency, positions: &[Vec3]) -> Self {
        let corners: Vec<[Vec3; 3]> = adjacency
            .tris
            .iter()
            .map(|t| t.map(|v| positions[v as usize]))
            .collect();
        let centroids: Vec<Vec3> = corners.iter().map(|c| (c[0] + c[1] + c[2]) / 3.0).collect();
        let mut order: Vec<u32> = (0..corners.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * corners.len() / LEAF_SIZE + 1);
        if !corners.is_empty() {
            build(&mut nodes, &mut order, 0, &corners, &centroids);
        }
        Self {
            nodes,
            order,
            corners,
        }
    }

    /// Where the line through `origin` along `dir` meets the surface nearest
    /// to `origin` (in either direction along the line), within `max_dist`
    /// world units of it; `None` when it meets nothing that close.
    /// Möller–Trumbore intersection, both triangle sides count.
    pub fn cast_line(&self, origin: Vec3, dir: Vec3, max_dist: f32) -> Option<SurfacePoint> {
        let dir = dir.try_normalize()?;
        let inv = dir.recip();
        let mut best: Option<(f32, u32, f32, f32)> = None;
        let mut limit = max_dist;
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        if !self.nodes.is_empty() {
            stack.push(0);
        }
        while let Some(ni) = stack.pop() {
            let node = &self.nodes[ni as usize];
            if !slab_overlaps(node.min, node.max, origin, inv, limit) {
                continue;
            }
            if node.count > 0 {
                for &t in &self.order[node.start as usize..(node.start + node.count) as usize] {
                    let [a, b, c] = self.corners[t as usize];
                    let Some((s, u, v)) = intersect(origin, dir, a, b, c) else {
                        continue;
                    };
                    let better = match best {
                        None => s.abs() <= limit,
                        Some((bs, bt, _, _)) => {
                            s.abs() < bs.abs() || (s.abs() == bs.abs() && t < bt)
                        }
                    };
                    if better && s.abs() <= max_dist {
                        best = Some((s, t, u, v));
                        limit = s.abs();
                    }
                }
            } else {
                stack.push(node.right);
                stack.push(node.start);
            }
        }
        best.map(|(s, tri, u, v)| SurfacePoint {
            tri,
            weights: [1.0 - u - v, u, v],
            at: origin + dir * s,
        })
    }

    /// The surface point nearest to `p` (ties by triangle id); `None` without
    /// triangles.
    pub fn nearest_point(&self, p: Vec3) -> Option<SurfacePoint> {
        let mut best: Option<(f32, u32, [f32; 3], Vec3)> = None;
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        if !self.nodes.is_empty() {
            stack.push(0);
        }
        while let Some(ni) = stack.pop() {
            let node = &self.nodes[ni as usize];
            let box_d2 = (p.clamp(node.min, node.max) - p).length_squared();
            if best.is_some_and(|(d2, ..)| box_d2 > d2) {
                continue;
            }
            if node.count > 0 {
                for &t in &self.order[node.start as usize..(node.start + node.count) as usize] {
                    let [a, b, c] = self.corners[t as usize];
                    let (q, w) = closest_point_on_triangle(p, a, b, c);
                    let d2 = (q - p).length_squared();
                    let better = match best {
                        None => true,
                        Some((bd, bt, ..)) => d2 < bd || (d2 == bd && t < bt),
                    };
                    if better {
                        best = Some((d2, t, w, q));
                    }
                }
            } else {
                // Visit the nearer child first.
                let l = &self.nodes[node.start as usize];
                let r = &self.nodes[node.right as usize];
                let dl = (p.clamp(l.min, l.max) - p).length_squared();
                let dr = (p.clamp(r.min, r.max) - p).length_squared();
                if dl <= dr {
                    stack.push(node.right);
                    stack.push(node.start);
                } else {
                    stack.push(node.start);
                    stack.push(node.right);
                }
            }
        }
        best.map(|(_, tri, weights, at)| SurfacePoint { tri, weights, at })
    }
}

fn build(
    nodes: &mut Vec<Node>,
    order: &mut [u32],
    offset: u32,
    corners: &[[Vec3; 3]],
    centroids: &[Vec3],
) -> u32 {
    let (mut min, mut max) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    let (mut cmin, mut cmax) = (min, max);
    for &t in order.iter() {
        for c in corners[t as usize] {
            min = min.min(c);
            max = max.max(c);
        }
        cmin = cmin.min(centroids[t as usize]);
        cmax = cmax.max(centroids[t as usize]);
    }
    let index = nodes.len() as u32;
    nodes.push(Node {
        min,
        max,
        start: offset,
        count: order.len() as u32,
        right: 0,
    });
    if order.len() <= LEAF_SIZE {
        return index;
    }
    let ext = cmax - cmin;
    let axis = if ext.x >= ext.y && ext.x >= ext.z {
        0
    } else if ext.y >= ext.z {
        1
    } else {
        2
    };
    let mid = order.len() / 2;
    order.select_nth_unstable_by(mid, |&a, &b| {
        centroids[a as usize][axis]
            .total_cmp(&centroids[b as usize][axis])
            .then(a.cmp(&b))
    });
    let (left, right) = order.split_at_mut(mid);
    let l = build(nodes, left, offset, corners, centroids);
    let r = build(nodes, right, offset + mid as u32, corners, centroids);
    let node = &mut nodes[index as usize];
    node.start = l;
    node.count = 0;
    node.right = r;
    index
}

/// Whether the line segment `origin + s·dir`, `|s| <= limit`, meets the box
/// (slab test; an axis the line runs parallel to only needs the origin
/// inside the slab, boundary included).
#[inline]
fn slab_overlaps(min: Vec3, max: Vec3, origin: Vec3, inv: Vec3, limit: f32) -> bool {
    let (mut enter, mut exit) = (-limit, limit);
    for k in 0..3 {
        if inv[k].is_infinite() {
            if origin[k] < min[k] || origin[k] > max[k] {
                return false;
            }
            continue;
        }
        let t0 = (min[k] - origin[k]) * inv[k];
        let t1 = (max[k] - origin[k]) * inv[k];
        enter = enter.max(t0.min(t1));
        exit = exit.min(t0.max(t1));
    }
    enter <= exit
}

/// Line–triangle intersection: `(s, u, v)` with the point at
/// `origin + s·dir = (1−u−v)·a + u·b + v·c`.
#[inline]
fn intersect(origin: Vec3, dir: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Option<(f32, f32, f32)> {
    const EPS: f32 = 1e-7;
    let e1 = b - a;
    let e2 = c - a;
    let h = dir.cross(e2);
    let det = e1.dot(h);
    let scale = e1.length() * e2.length();
    if det.abs() <= EPS * scale || scale == 0.0 {
        return None;
    }
    let f = 1.0 / det;
    let s0 = origin - a;
    let u = f * s0.dot(h);
    // Lines through a shared edge or vertex hit one of its triangles even
    // after rounding (coordinates far from the origin lose digits).
    let tol = 1e-4;
    if !(-tol..=1.0 + tol).contains(&u) {
        return None;
    }
    let q = s0.cross(e1);
    let v = f * dir.dot(q);
    if v < -tol || u + v > 1.0 + tol {
        return None;
    }
    let s = f * e2.dot(q);
    Some((s, u.clamp(0.0, 1.0), v.clamp(0.0, 1.0 - u.clamp(0.0, 1.0))))
}

/// The point of triangle `abc` nearest to `p` and its barycentric weights
/// (Ericson, Real-Time Collision Detection §5.1.5).
fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> (Vec3, [f32; 3]) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, [0.0, 1.0 - w, w]);
    }
    let denom = va + vb + vc;
    if denom.abs() < f32::MIN_POSITIVE {
        return (a, [1.0, 0.0, 0.0]);
    }
    let v = vb / denom;
    let w = vc / denom;
    (a + ab * v + ac * w, [1.0 - v - w, v, w])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::builtin::{BuiltinOptions, builtin_mesh};

    fn sphere(s: u32) -> crate::mesh::PolyMesh {
        builtin_mesh(
            "icosphere",
            &BuiltinOptions {
                subdivisions: s,
                ..Default::default()
            },
        )
        .unwrap()
    }

    #[test]
    fn normals_of_a_fine_sphere_hit_the_coarse_one_nearby() {
        let fine = sphere(3);
        let coarse = sphere(1);
        let adj = TriangleAdjacency::new(&coarse);
        let bvh = TriangleBvh::new(&adj, &coarse.positions);
        let normals = fine.vertex_normals();
        for (p, n) in fine.positions.iter().zip(&normals) {
            let hit = bvh
                .cast_line(*p, *n, 1.0)
                .expect("the coarse sphere is hit");
            // The hit is just inside the unit sphere, along the normal.
            assert!((hit.at - *p).cross(*n).length() < 1e-4);
            assert!(hit.at.length() <= 1.0 + 1e-4 && hit.at.length() > 0.85);
            let tri = adj.tris[hit.tri as usize].map(|v| coarse.positions[v as usize]);
            let back: Vec3 = (0..3).map(|k| tri[k] * hit.weights[k]).sum();
            assert!((back - hit.at).length() < 1e-4);
            let near = bvh.nearest_point(*p).unwrap();
            assert!((near.at - *p).length() <= (hit.at - *p).length() + 1e-5);
            // Brute force agrees with the hierarchy.
            let brute = (0..adj.len())
                .map(|t| {
                    let [a, b, c] = adj.tris[t].map(|v| coarse.positions[v as usize]);
                    (closest_point_on_triangle(*p, a, b, c).0 - *p).length()
                })
                .fold(f32::INFINITY, f32::min);
            assert!(((near.at - *p).length() - brute).abs() < 1e-6);
        }
        // A line on the border of a flat mesh still finds it.
        let plane = builtin_mesh("plane", &BuiltinOptions::default()).unwrap();
        let adj = TriangleAdjacency::new(&plane);
        let bvh = TriangleBvh::new(&adj, &plane.positions);
        for p in &plane.positions {
            assert!(bvh.cast_line(*p, Vec3::Z, 0.1).is_some(), "{p}");
        }
        // Too short a reach finds nothing.
        assert!(
            bvh.cast_line(Vec3::new(0.0, 0.0, 3.0), Vec3::Z, 0.5)
                .is_none()
        );
    }
}
