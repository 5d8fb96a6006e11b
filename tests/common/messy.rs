//! A generator of messy scans (issue 15): what real scanned meshes throw at
//! the stages, at a chosen vertex count, deterministic in its seed.
//!
//! - a closed noisy surface (a bumpy torus) carrying most of the vertices,
//! - holes punched through it (faces removed in small geodesic disks),
//! - non-manifold fins (a third and fourth triangle on existing edges),
//! - non-manifold vertices (small fans touching the surface at one vertex),
//! - 100+ small closed components (noisy octahedra) scattered around it,
//! - slivers (near-degenerate triangles), isolated triangles,
//! - duplicate vertices (faces of a patch using unmerged copies),
//!
//! placed away from the origin and in arbitrary units, so nothing can rely
//! on a unit-size mesh at the origin.

#![allow(dead_code)]

use std::f32::consts::TAU;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What was put into a generated scan, for assertions.
#[derive(Debug, Clone, Default)]
pub struct MessyReport {
    pub vertices: usize,
    pub faces: usize,
    pub holes: usize,
    pub fins: usize,
    pub fans: usize,
    pub small_components: usize,
    pub slivers: usize,
    pub isolated_triangles: usize,
    pub duplicated_vertices: usize,
    /// Surface area of all faces (fan-triangulated), world units².
    pub area: f64,
}

/// A tiny deterministic generator (splitmix64).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
}

/// Builds a messy scan of about `vertices` vertices (at least ~2 000).
pub fn messy_scan(vertices: usize, seed: u64) -> (Vec<[f32; 3]>, Vec<Vec<u32>>, MessyReport) {
    let mut rng = Rng(seed ^ 0x5EED_5CA7);
    let mut p: Vec<[f32; 3]> = Vec::new();
    let mut f: Vec<Vec<u32>> = Vec::new();
    let mut report = MessyReport::default();
    let origin = [140.0f32, -60.0, 25.0];
    let (big_r, small_r) = (30.0f32, 11.0f32);

    // The main surface: a bumpy torus grid with ~90 % of the vertices.
    let main = (vertices as f32 * 0.9) as usize;
    let nu = ((main as f32 * 2.7).sqrt() as usize).max(12);
    let nv = (main / nu).max(6);
    let bumps: Vec<(f32, f32, f32)> = (0..24)
        .map(|_| {
            (
                rng.range(0.0, TAU),
                rng.range(0.0, TAU),
                rng.range(-1.5, 1.5),
            )
        })
        .collect();
    for i in 0..nu {
        for j in 0..nv {
            let (u, v) = (i as f32 / nu as f32 * TAU, j as f32 / nv as f32 * TAU);
            let mut r = small_r;
            for &(bu, bv, a) in &bumps {
                r += a * ((u - bu).cos() * 3.0 + (v - bv).cos() * 2.0 - 5.0).exp();
            }
            r += rng.range(-0.05, 0.05); // scanner noise
            let ring = big_r + r * v.cos();
            p.push([
                origin[0] + ring * u.cos(),
                origin[1] + ring * u.sin(),
                origin[2] + r * v.sin(),
            ]);
        }
    }
    let id = |i: usize, j: usize| ((i % nu) * nv + (j % nv)) as u32;
    let mut main_faces = Vec::new();
    for i in 0..nu {
        for j in 0..nv {
            main_faces.push(vec![id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            main_faces.push(vec![id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    // Holes: drop the faces within a few grid cells of 12 random centres.
    let mut removed = vec![false; main_faces.len()];
    for _ in 0..12 {
        let (ci, cj) = (rng.below(nu), rng.below(nv));
        let rad = 1 + rng.below(3) as isize;
        for di in -rad..=rad {
            for dj in -rad..=rad {
                if di * di + dj * dj <= rad * rad {
                    let i = (ci as isize + di).rem_euclid(nu as isize) as usize;
                    let j = (cj as isize + dj).rem_euclid(nv as isize) as usize;
                    removed[2 * (i * nv + j)] = true;
                    removed[2 * (i * nv + j) + 1] = true;
                }
            }
        }
        report.holes += 1;
    }
    // Duplicate vertices: 3 patches whose faces use unmerged copies.
    for _ in 0..3 {
        let (ci, cj) = (rng.below(nu), rng.below(nv));
        let mut copy = std::collections::HashMap::new();
        for di in 0..4 {
            for dj in 0..4 {
                let k = 2 * (((ci + di) % nu) * nv + (cj + dj) % nv);
                for face in &mut main_faces[k..k + 2] {
                    for v in face.iter_mut() {
                        let c = *copy.entry(*v).or_insert_with(|| {
                            p.push(p[*v as usize]);
                            (p.len() - 1) as u32
                        });
                        *v = c;
                    }
                }
            }
        }
        report.duplicated_vertices += copy.len();
    }
    f.extend(
        main_faces
            .into_iter()
            .zip(&removed)
            .filter(|(_, r)| !**r)
            .map(|(face, _)| face),
    );

    let add = |p: &mut Vec<[f32; 3]>, q: [f32; 3]| {
        p.push(q);
        (p.len() - 1) as u32
    };
    let near =
        |q: [f32; 3], d: [f32; 3], s: f32| [q[0] + d[0] * s, q[1] + d[1] * s, q[2] + d[2] * s];
    let main_faces_count = f.len();
    // Non-manifold fins: a third and a fourth triangle on existing edges.
    for _ in 0..20 {
        let face = f[rng.below(main_faces_count)].clone();
        let (a, b) = (face[0], face[1]);
        let pa = p[a as usize];
        for k in 0..2 {
            let tip = add(&mut p, near(pa, [0.3, -0.2, 1.0 + k as f32], 1.2));
            f.push(vec![a, b, tip]);
        }
        report.fins += 1;
    }
    // Non-manifold vertices: a small fan touching the surface at one vertex.
    for _ in 0..10 {
        let v = f[rng.below(main_faces_count)][2];
        let pv = p[v as usize];
        let a = add(&mut p, near(pv, [1.0, 0.5, 1.5], 1.0));
        let b = add(&mut p, near(pv, [-0.5, 1.0, 1.5], 1.0));
        let c = add(&mut p, near(pv, [0.2, -1.0, 1.5], 1.0));
        f.push(vec![v, a, b]);
        f.push(vec![v, b, c]);
        report.fans += 1;
    }
    // Slivers: triangles whose third vertex sits almost on the first edge.
    for _ in 0..30 {
        let face = f[rng.below(main_faces_count)].clone();
        let (pa, pb) = (p[face[0] as usize], p[face[1] as usize]);
        let mid = [
            (pa[0] + pb[0]) * 0.5 + 1e-5,
            (pa[1] + pb[1]) * 0.5,
            (pa[2] + pb[2]) * 0.5,
        ];
        let m = add(&mut p, mid);
        f.push(vec![face[0], face[1], m]);
        report.slivers += 1;
    }
    // Small closed components: noisy octahedra scattered around the torus.
    let used = p.len() + 30 * 3;
    let budget = vertices.saturating_sub(used).max(120 * 6);
    let comps = (budget / 6).clamp(120, 400);
    for _ in 0..comps {
        let c = [
            origin[0] + rng.range(-60.0, 60.0),
            origin[1] + rng.range(-60.0, 60.0),
            origin[2] + rng.range(-30.0, 30.0),
        ];
        let s = rng.range(0.3, 1.5);
        let dirs = [
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ];
        let ids: Vec<u32> = dirs
            .iter()
            .map(|d| {
                let j = rng.range(0.8, 1.2);
                add(&mut p, near(c, *d, s * j))
            })
            .collect();
        for (a, b, top) in [
            (0, 2, 4),
            (2, 1, 4),
            (1, 3, 4),
            (3, 0, 4),
            (2, 0, 5),
            (1, 2, 5),
            (3, 1, 5),
            (0, 3, 5),
        ] {
            f.push(vec![ids[a], ids[b], ids[top]]);
        }
        report.small_components += 1;
    }
    // Isolated triangles.
    for _ in 0..30 {
        let c = [
            origin[0] + rng.range(-50.0, 50.0),
            origin[1] + rng.range(-50.0, 50.0),
            origin[2] + rng.range(-50.0, 50.0),
        ];
        let a = add(&mut p, c);
        let b = add(&mut p, near(c, [1.0, 0.0, 0.2], 0.8));
        let d = add(&mut p, near(c, [0.1, 1.0, 0.0], 0.8));
        f.push(vec![a, b, d]);
        report.isolated_triangles += 1;
    }
    report.vertices = p.len();
    report.faces = f.len();
    let sub = |a: [f32; 3], b: [f32; 3]| [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
    report.area = f
        .iter()
        .flat_map(|face| (1..face.len() - 1).map(move |i| (face[0], face[i], face[i + 1])))
        .map(|(a, b, c)| {
            let (u, v) = (
                sub(p[a as usize], p[b as usize]),
                sub(p[a as usize], p[c as usize]),
            );
            let n = [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ];
            0.5 * f64::from(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt()
        })
        .sum();
    (p, f, report)
}

/// Writes a messy scan of about `vertices` vertices as an OFF file in
/// `dir` and returns its path and report.
pub fn write_messy_scan(dir: &Path, vertices: usize, seed: u64) -> (PathBuf, MessyReport) {
    let (p, f, report) = messy_scan(vertices, seed);
    let mut text = String::with_capacity(p.len() * 40 + f.len() * 20);
    let _ = writeln!(text, "OFF\n{} {} 0", p.len(), f.len());
    for q in &p {
        let _ = writeln!(text, "{} {} {}", q[0], q[1], q[2]);
    }
    for face in &f {
        let _ = write!(text, "{}", face.len());
        for v in face {
            let _ = write!(text, " {v}");
        }
        text.push('\n');
    }
    let path = dir.join(format!("messy_{vertices}_{seed}.off"));
    std::fs::write(&path, text).expect("the scan is written");
    (path, report)
}

/// A plate of `n × n` cells of side 1 and thickness `t`, with a square
/// hole through every interior cell of odd row and column: genus = the
/// number of holes. Quads, outward.
pub fn perforated_plate(n: usize, t: f32) -> (surfsynth::mesh::PolyMesh, usize) {
    let hole = |i: usize, j: usize| i % 2 == 1 && j % 2 == 1 && i + 1 < n && j + 1 < n;
    let solid = |i: isize, j: isize| {
        i >= 0 && j >= 0 && (i as usize) < n && (j as usize) < n && !hole(i as usize, j as usize)
    };
    let id = |i: usize, j: usize, top: bool| ((i * (n + 1) + j) * 2 + top as usize) as u32;
    let mut p = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            p.push(glam::Vec3::new(i as f32, j as f32, 0.0));
            p.push(glam::Vec3::new(i as f32, j as f32, t));
        }
    }
    let mut faces: Vec<Vec<u32>> = Vec::new();
    let mut holes = 0;
    for i in 0..n {
        for j in 0..n {
            if !solid(i as isize, j as isize) {
                holes += 1;
                continue;
            }
            faces.push(vec![
                id(i, j, true),
                id(i + 1, j, true),
                id(i + 1, j + 1, true),
                id(i, j + 1, true),
            ]);
            faces.push(vec![
                id(i, j, false),
                id(i, j + 1, false),
                id(i + 1, j + 1, false),
                id(i + 1, j, false),
            ]);
            let (ii, jj) = (i as isize, j as isize);
            // Side walls where the neighbour is not solid, facing it.
            if !solid(ii - 1, jj) {
                faces.push(vec![
                    id(i, j, false),
                    id(i, j, true),
                    id(i, j + 1, true),
                    id(i, j + 1, false),
                ]);
            }
            if !solid(ii + 1, jj) {
                faces.push(vec![
                    id(i + 1, j, false),
                    id(i + 1, j + 1, false),
                    id(i + 1, j + 1, true),
                    id(i + 1, j, true),
                ]);
            }
            if !solid(ii, jj - 1) {
                faces.push(vec![
                    id(i, j, false),
                    id(i + 1, j, false),
                    id(i + 1, j, true),
                    id(i, j, true),
                ]);
            }
            if !solid(ii, jj + 1) {
                faces.push(vec![
                    id(i, j + 1, false),
                    id(i, j + 1, true),
                    id(i + 1, j + 1, true),
                    id(i + 1, j + 1, false),
                ]);
            }
        }
    }
    let refs: Vec<&[u32]> = faces.iter().map(Vec::as_slice).collect();
    (surfsynth::mesh::PolyMesh::from_polygons(p, refs), holes)
}
