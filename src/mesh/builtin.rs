//! Procedural meshes, named `builtin:NAME` in configs and on the command line.
//!
//! Every mesh is deterministic (the same options give bit-identical output).
//! Closed meshes are watertight (every edge has exactly two faces) and
//! consistently oriented outward: faces are counter-clockwise seen from
//! outside. Lengths are in model units; the z axis is "up" (plane normal,
//! sphere poles, torus axis).

use super::PolyMesh;
use super::error::MeshError;
use glam::{DVec3, Vec3};
use std::collections::HashMap;
use std::f64::consts::{PI, TAU};

/// The builtin meshes and what they are for.
pub const BUILTIN_MESHES: &[(&str, &str)] = &[
    (
        "plane",
        "flat grid of resolution[0] x resolution[1] vertices in the xy-plane, facing +z; triangles, or quads with `quads`; one boundary loop",
    ),
    (
        "jittered_plane",
        "the plane with its interior vertices moved randomly in-plane by up to `jitter` x spacing (seeded); irregular triangles",
    ),
    (
        "icosphere",
        "icosahedron subdivided `subdivisions` times (0..=8) and projected on a sphere of `radius`; near-uniform triangles, closed, genus 0",
    ),
    (
        "uv_sphere",
        "latitude-longitude sphere, resolution = [segments, rings], triangle fans at the poles; closed, genus 0, anisotropic near the poles",
    ),
    (
        "torus",
        "ring torus around z with `radius` and tube `minor_radius`, resolution = [around the axis, around the tube]; closed, genus 1",
    ),
    (
        "torus_knot",
        "tube of `minor_radius` around a (p, q) torus knot (default trefoil 2, 3); closed, genus 1, strongly curved",
    ),
    (
        "cube",
        "axis-aligned cube of edge `size`, each side a 2^subdivisions grid of quads, welded; closed, genus 0, sharp edges",
    ),
];

/// Options of the builtin meshes. Each mesh reads only the fields it needs;
/// the others are ignored. Deserialises from a config table; unknown keys are
/// rejected and missing ones take the defaults below.
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BuiltinOptions {
    /// Subdivision level. `icosphere`: each level splits every triangle in
    /// four (level 0 is the icosahedron; 20·4^level faces). `cube`: each side
    /// is a 2^level × 2^level grid of quads. Default 3, range `0..=8`.
    pub subdivisions: u32,
    /// Tessellation `[u, v]`, each in `2..=4096` (`3..=4096` where noted).
    /// `plane`/`jittered_plane`: vertices along x and along y.
    /// `uv_sphere`: segments around the axis (≥ 3) and rings from pole to pole (≥ 2).
    /// `torus`: segments around the axis and around the tube (both ≥ 3).
    /// `torus_knot`: segments along the knot per unit of `p + q` (so the
    /// knot has `u·(p+q)` rings), and segments around the tube (≥ 3).
    /// Default `[32, 32]`.
    pub resolution: [u32; 2],
    /// Emit quads instead of splitting each grid cell into two triangles
    /// (`plane`, `jittered_plane`, `uv_sphere` bands, `torus`, `torus_knot`).
    /// `icosphere` is always triangles, `cube` always quads. Default `false`.
    pub quads: bool,
    /// `jittered_plane`: largest in-plane move of an interior vertex along x
    /// and along y, as a fraction of the grid spacing. Range `0.0..0.25`
    /// (below 0.25 no triangle can flip). Default `0.2`.
    pub jitter: f32,
    /// `jittered_plane`: seed of the jitter. Any value. Default 0.
    pub seed: u64,
    /// `plane`/`jittered_plane`: length of the longer side; `cube`: edge
    /// length. Model units, finite, `> 0`. Default `2.0` (so both span
    /// `[-1, 1]` like the unit sphere).
    pub size: f32,
    /// `icosphere`, `uv_sphere`: sphere radius. `torus`: distance from the
    /// axis to the tube centre. `torus_knot`: radius of the torus the knot
    /// winds on (whose own tube radius is `radius / 2`). Model units, finite,
    /// `> 0`. Default `1.0`.
    pub radius: f32,
    /// `torus`: tube radius, `0 < minor_radius < radius`. `torus_knot`: tube
    /// radius, `0 < minor_radius <= 0.4 · radius` (the trefoil's strands come
    /// within `0.83 · radius` of each other; knots with larger `p`, `q` may
    /// need thinner tubes to avoid self-intersection). Default `0.25`.
    pub minor_radius: f32,
    /// `torus_knot`: turns around the torus axis. Range `1..=16`, coprime with
    /// `q`. Default 2.
    pub p: u32,
    /// `torus_knot`: turns around the torus tube. Range `1..=16`, coprime
    /// with `p`. Default 3.
    pub q: u32,
}

impl Default for BuiltinOptions {
    fn default() -> Self {
        Self {
            subdivisions: 3,
            resolution: [32, 32],
            quads: false,
            jitter: 0.2,
            seed: 0,
            size: 2.0,
            radius: 1.0,
            minor_radius: 0.25,
            p: 2,
            q: 3,
        }
    }
}

/// Largest `resolution` entry.
pub const MAX_RESOLUTION: u32 = 4096;
/// Largest `subdivisions`.
pub const MAX_SUBDIVISIONS: u32 = 8;

/// Builds the builtin mesh `name` (without the `builtin:` prefix).
///
/// # Errors
/// [`MeshError::Builtin`] for an unknown name (listing the known ones) or an
/// option out of its range (naming the option and the range).
pub fn builtin_mesh(name: &str, opts: &BuiltinOptions) -> Result<PolyMesh, MeshError> {
    let check = Check { name };
    match name {
        "plane" | "jittered_plane" => {
            check.resolution(opts.resolution, 2)?;
            check.positive("size", opts.size)?;
            let jitter = if name == "jittered_plane" {
                if !(0.0..0.25).contains(&opts.jitter) {
                    return Err(check.error(format!(
                        "jitter = {} is out of range (allowed 0.0 <= jitter < 0.25, a fraction of the grid spacing)",
                        opts.jitter
                    )));
                }
                opts.jitter
            } else {
                0.0
            };
            Ok(plane(
                opts.resolution,
                opts.size,
                opts.quads,
                jitter,
                opts.seed,
            ))
        }
        "icosphere" => {
            check.range("subdivisions", opts.subdivisions, 0, MAX_SUBDIVISIONS)?;
            check.positive("radius", opts.radius)?;
            Ok(icosphere(opts.subdivisions, opts.radius))
        }
        "uv_sphere" => {
            check.range(
                "resolution[0] (segments)",
                opts.resolution[0],
                3,
                MAX_RESOLUTION,
            )?;
            check.range(
                "resolution[1] (rings)",
                opts.resolution[1],
                2,
                MAX_RESOLUTION,
            )?;
            check.positive("radius", opts.radius)?;
            Ok(uv_sphere(opts.resolution, opts.radius, opts.quads))
        }
        "torus" => {
            check.resolution(opts.resolution, 3)?;
            check.positive("radius", opts.radius)?;
            check.positive("minor_radius", opts.minor_radius)?;
            if opts.minor_radius >= opts.radius {
                return Err(check.error(format!(
                    "minor_radius = {} must be smaller than radius = {}",
                    opts.minor_radius, opts.radius
                )));
            }
            Ok(torus(opts))
        }
        "torus_knot" => {
            check.resolution(opts.resolution, 3)?;
            check.positive("radius", opts.radius)?;
            check.positive("minor_radius", opts.minor_radius)?;
            if opts.minor_radius > 0.4 * opts.radius {
                return Err(check.error(format!(
                    "minor_radius = {} is out of range (allowed 0 < minor_radius <= 0.4 x radius = {})",
                    opts.minor_radius,
                    0.4 * opts.radius
                )));
            }
            check.range("p", opts.p, 1, 16)?;
            check.range("q", opts.q, 1, 16)?;
            if gcd(opts.p, opts.q) != 1 {
                return Err(check.error(format!(
                    "p = {} and q = {} must be coprime (otherwise the curve is a link of several knots)",
                    opts.p, opts.q
                )));
            }
            let along = opts.resolution[0] as u64 * (opts.p + opts.q) as u64;
            if along > MAX_RESOLUTION as u64 * 4 {
                return Err(check.error(format!(
                    "resolution[0] x (p + q) = {along} rings is too many (allowed up to {})",
                    MAX_RESOLUTION * 4
                )));
            }
            Ok(torus_knot(opts))
        }
        "cube" => {
            check.range("subdivisions", opts.subdivisions, 0, MAX_SUBDIVISIONS)?;
            check.positive("size", opts.size)?;
            Ok(cube(opts.subdivisions, opts.size))
        }
        _ => {
            let names: Vec<&str> = BUILTIN_MESHES.iter().map(|(n, _)| *n).collect();
            Err(check.error(format!(
                "unknown builtin mesh; allowed: {}",
                names.join(", ")
            )))
        }
    }
}

/// Option checks that produce [`MeshError::Builtin`].
struct Check<'a> {
    name: &'a str,
}

impl Check<'_> {
    fn error(&self, message: String) -> MeshError {
        MeshError::Builtin {
            name: self.name.to_string(),
            message,
        }
    }

    fn range(&self, option: &str, value: u32, lo: u32, hi: u32) -> Result<(), MeshError> {
        if (lo..=hi).contains(&value) {
            Ok(())
        } else {
            Err(self.error(format!(
                "{option} = {value} is out of range (allowed {lo}..={hi})"
            )))
        }
    }

    fn resolution(&self, r: [u32; 2], lo: u32) -> Result<(), MeshError> {
        self.range("resolution[0]", r[0], lo, MAX_RESOLUTION)?;
        self.range("resolution[1]", r[1], lo, MAX_RESOLUTION)
    }

    fn positive(&self, option: &str, value: f32) -> Result<(), MeshError> {
        if value.is_finite() && value > 0.0 && value <= 1e6 {
            Ok(())
        } else {
            Err(self.error(format!(
                "{option} = {value} is out of range (allowed a finite number > 0 and <= 1e6, model units)"
            )))
        }
    }
}

fn gcd(a: u32, b: u32) -> u32 {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// A uniform number in `[-1, 1)` from `(seed, index)`, by SplitMix64.
/// Counter-based, so it does not depend on the order of calls.
fn hash_signed_unit(seed: u64, index: u64) -> f32 {
    let mut z = seed
        .wrapping_add(index.wrapping_mul(0x9E37_79B9_7F4A_7C15))
        .wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    // 24 random bits give every f32 step in [0, 1).
    ((z >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
}

/// Pushes a grid cell `a b c d` (counter-clockwise) as a quad or two triangles.
fn push_cell(mesh: &mut PolyMesh, [a, b, c, d]: [u32; 4], quads: bool) {
    if quads {
        mesh.push_face(&[a, b, c, d]);
    } else {
        mesh.push_face(&[a, b, c]);
        mesh.push_face(&[a, c, d]);
    }
}

/// The (jittered) plane. Square cells of side `size / (max(n, m) - 1)`,
/// centred on the origin.
fn plane(resolution: [u32; 2], size: f32, quads: bool, jitter: f32, seed: u64) -> PolyMesh {
    let [n, m] = resolution;
    let h = size as f64 / (n.max(m) - 1) as f64;
    let x0 = -0.5 * h * (n - 1) as f64;
    let y0 = -0.5 * h * (m - 1) as f64;
    let mut mesh = PolyMesh::new();
    mesh.positions.reserve(n as usize * m as usize);
    for j in 0..m {
        for i in 0..n {
            let mut x = x0 + h * i as f64;
            let mut y = y0 + h * j as f64;
            let interior = i > 0 && j > 0 && i < n - 1 && j < m - 1;
            if interior && jitter > 0.0 {
                let v = (j as u64) * n as u64 + i as u64;
                x += (jitter * hash_signed_unit(seed, 2 * v)) as f64 * h;
                y += (jitter * hash_signed_unit(seed, 2 * v + 1)) as f64 * h;
            }
            mesh.positions.push(Vec3::new(x as f32, y as f32, 0.0));
        }
    }
    let id = |i: u32, j: u32| j * n + i;
    for j in 0..m - 1 {
        for i in 0..n - 1 {
            push_cell(
                &mut mesh,
                [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)],
                quads,
            );
        }
    }
    mesh
}

/// Subdivided icosahedron on a sphere of `radius`.
fn icosphere(level: u32, radius: f32) -> PolyMesh {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut pos: Vec<DVec3> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|p| DVec3::from_array(*p).normalize())
    .collect();
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..level {
        let mut midpoint: HashMap<(u32, u32), u32> = HashMap::with_capacity(tris.len() * 3 / 2);
        let mut mid = |a: u32, b: u32, pos: &mut Vec<DVec3>| {
            let key = (a.min(b), a.max(b));
            *midpoint.entry(key).or_insert_with(|| {
                pos.push((pos[a as usize] + pos[b as usize]).normalize());
                pos.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(tris.len() * 4);
        for &[a, b, c] in &tris {
            let ab = mid(a, b, &mut pos);
            let bc = mid(b, c, &mut pos);
            let ca = mid(c, a, &mut pos);
            next.extend_from_slice(&[[a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca]]);
        }
        tris = next;
    }
    let r = radius as f64;
    let positions = pos.iter().map(|p| (*p * r).as_vec3()).collect();
    PolyMesh::from_triangles(positions, &tris)
}

/// Latitude-longitude sphere around the z axis.
fn uv_sphere([segments, rings]: [u32; 2], radius: f32, quads: bool) -> PolyMesh {
    let r = radius as f64;
    let mut mesh = PolyMesh::new();
    mesh.positions.push(Vec3::new(0.0, 0.0, radius));
    for k in 1..rings {
        let theta = PI * k as f64 / rings as f64;
        for s in 0..segments {
            let phi = TAU * s as f64 / segments as f64;
            let p = DVec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            );
            mesh.positions.push((p * r).as_vec3());
        }
    }
    mesh.positions.push(Vec3::new(0.0, 0.0, -radius));
    let north = 0;
    let south = mesh.positions.len() as u32 - 1;
    let v = |k: u32, s: u32| 1 + (k - 1) * segments + s % segments;
    for s in 0..segments {
        mesh.push_face(&[north, v(1, s), v(1, s + 1)]);
    }
    for k in 1..rings - 1 {
        for s in 0..segments {
            push_cell(
                &mut mesh,
                [v(k, s), v(k + 1, s), v(k + 1, s + 1), v(k, s + 1)],
                quads,
            );
        }
    }
    for s in 0..segments {
        mesh.push_face(&[south, v(rings - 1, s + 1), v(rings - 1, s)]);
    }
    mesh
}

/// Pushes the faces of a closed `n × m` tube grid (vertex `i * m + j`),
/// oriented so that the normal is `d/di × d/dj`.
fn tube_faces(mesh: &mut PolyMesh, n: u32, m: u32, quads: bool) {
    let id = |i: u32, j: u32| (i % n) * m + j % m;
    for i in 0..n {
        for j in 0..m {
            push_cell(
                mesh,
                [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)],
                quads,
            );
        }
    }
}

/// Ring torus around the z axis.
fn torus(opts: &BuiltinOptions) -> PolyMesh {
    let [n, m] = opts.resolution;
    let (big_r, r) = (opts.radius as f64, opts.minor_radius as f64);
    let mut mesh = PolyMesh::new();
    mesh.positions.reserve(n as usize * m as usize);
    for i in 0..n {
        let a = TAU * i as f64 / n as f64;
        for j in 0..m {
            let b = TAU * j as f64 / m as f64;
            let rho = big_r + r * b.cos();
            mesh.positions
                .push(DVec3::new(rho * a.cos(), rho * a.sin(), r * b.sin()).as_vec3());
        }
    }
    // d/da is the direction of travel around the axis, d/db goes up the
    // outside of the tube, and (d/da) × (d/db) points outward.
    tube_faces(&mut mesh, n, m, opts.quads);
    mesh
}

/// Tube around a (p, q) torus knot. The centreline frames are parallel
/// transported along the knot, and the leftover twist is spread evenly so the
/// tube closes without a seam.
fn torus_knot(opts: &BuiltinOptions) -> PolyMesh {
    let (p, q) = (opts.p as f64, opts.q as f64);
    let big_r = opts.radius as f64;
    let a = 0.5 * big_r;
    let r = opts.minor_radius as f64;
    let n = opts.resolution[0] * (opts.p + opts.q);
    let m = opts.resolution[1];
    let centre = |t: f64| {
        let rho = big_r + a * (q * t).cos();
        DVec3::new(rho * (p * t).cos(), rho * (p * t).sin(), a * (q * t).sin())
    };
    let c: Vec<DVec3> = (0..n).map(|i| centre(TAU * i as f64 / n as f64)).collect();
    let ni = n as usize;
    let tangent: Vec<DVec3> = (0..ni)
        .map(|i| (c[(i + 1) % ni] - c[(i + ni - 1) % ni]).normalize())
        .collect();
    // Parallel transport by projection, once around and back to the start.
    let mut normal = Vec::with_capacity(ni + 1);
    normal.push(tangent[0].any_orthonormal_vector());
    for i in 1..=ni {
        let t = tangent[i % ni];
        let prev: DVec3 = normal[i - 1];
        normal.push((prev - prev.dot(t) * t).normalize());
    }
    // Twist between the transported frame and the start frame.
    let (n0, nn, t0) = (normal[0], normal[ni], tangent[0]);
    let twist = n0.cross(nn).dot(t0).atan2(n0.dot(nn));
    let mut mesh = PolyMesh::new();
    mesh.positions.reserve(ni * m as usize);
    for i in 0..ni {
        let t = tangent[i];
        let angle = -twist * i as f64 / n as f64;
        let nrm = rotate_about(normal[i], t, angle);
        let bin = t.cross(nrm);
        for j in 0..m {
            let th = TAU * j as f64 / m as f64;
            // Going around the tube from N towards -B makes (d/di) × (d/dj),
            // that is T × (-B) = N, point outward.
            let offset = nrm * th.cos() - bin * th.sin();
            mesh.positions.push((c[i] + offset * r).as_vec3());
        }
    }
    tube_faces(&mut mesh, n, m, opts.quads);
    mesh
}

/// Rotates `v` about the unit axis `k` by `angle` (Rodrigues).
fn rotate_about(v: DVec3, k: DVec3, angle: f64) -> DVec3 {
    let (s, c) = angle.sin_cos();
    v * c + k.cross(v) * s + k * k.dot(v) * (1.0 - c)
}

/// Axis-aligned cube of edge `size`, each side a `2^level` grid of quads.
fn cube(level: u32, size: f32) -> PolyMesh {
    let n = 1u32 << level;
    let h = size as f64 / n as f64;
    let half = 0.5 * size as f64;
    let mut mesh = PolyMesh::new();
    let mut index: HashMap<[u32; 3], u32> = HashMap::with_capacity(6 * (n as usize + 1).pow(2));
    let mut vertex = |l: [u32; 3], mesh: &mut PolyMesh| {
        *index.entry(l).or_insert_with(|| {
            let p = l.map(|c| (c as f64 * h - half) as f32);
            mesh.positions.push(Vec3::from_array(p));
            mesh.positions.len() as u32 - 1
        })
    };
    for axis in 0..3 {
        for positive in [false, true] {
            // (e1, e2) with e1 × e2 along the outward normal.
            let (e1, e2) = if positive {
                ((axis + 1) % 3, (axis + 2) % 3)
            } else {
                ((axis + 2) % 3, (axis + 1) % 3)
            };
            let fixed = if positive { n } else { 0 };
            let lattice = |u: u32, v: u32| {
                let mut l = [0u32; 3];
                l[axis] = fixed;
                l[e1] = u;
                l[e2] = v;
                l
            };
            for v in 0..n {
                for u in 0..n {
                    let quad = [
                        vertex(lattice(u, v), &mut mesh),
                        vertex(lattice(u + 1, v), &mut mesh),
                        vertex(lattice(u + 1, v + 1), &mut mesh),
                        vertex(lattice(u, v + 1), &mut mesh),
                    ];
                    mesh.push_face(&quad);
                }
            }
        }
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Topology;

    /// Signed volume by the divergence theorem; positive when faces point out.
    fn signed_volume(m: &PolyMesh) -> f64 {
        let tm = m.triangulated();
        tm.faces()
            .map(|f| {
                let [a, b, c] = [0, 1, 2].map(|k| tm.positions[f[k] as usize].as_dvec3());
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// Every edge has two faces that traverse it in opposite directions.
    fn assert_watertight_and_oriented(name: &str, m: &PolyMesh) {
        let t = Topology::build(m);
        for (e, [a, b]) in t.edges.iter().enumerate() {
            let faces = t.edge_faces(e as u32);
            assert_eq!(
                faces.len(),
                2,
                "{name}: edge {a}-{b} has {} faces",
                faces.len()
            );
        }
        let mut sides: Vec<(u32, u32)> = m.face_sides().collect();
        sides.sort_unstable();
        assert!(
            sides.windows(2).all(|w| w[0] != w[1]),
            "{name}: a directed edge appears twice (inconsistent orientation)"
        );
        assert_eq!(t.components().0, 1, "{name}: not connected");
        assert!(signed_volume(m) > 0.0, "{name}: faces point inward");
    }

    #[test]
    fn closed_meshes_are_watertight_and_outward() {
        for quads in [false, true] {
            for name in ["icosphere", "uv_sphere", "torus", "torus_knot", "cube"] {
                let opts = BuiltinOptions {
                    quads,
                    ..BuiltinOptions::default()
                };
                let m = builtin_mesh(name, &opts).unwrap();
                assert_watertight_and_oriented(name, &m);
            }
        }
    }

    #[test]
    fn euler_characteristics() {
        let chi = |m: &PolyMesh| {
            let t = Topology::build(m);
            m.vertex_count() as i64 - t.edges.len() as i64 + m.face_count() as i64
        };
        let d = BuiltinOptions::default();
        assert_eq!(chi(&builtin_mesh("icosphere", &d).unwrap()), 2);
        assert_eq!(chi(&builtin_mesh("uv_sphere", &d).unwrap()), 2);
        assert_eq!(chi(&builtin_mesh("cube", &d).unwrap()), 2);
        assert_eq!(chi(&builtin_mesh("torus", &d).unwrap()), 0);
        assert_eq!(chi(&builtin_mesh("torus_knot", &d).unwrap()), 0);
        assert_eq!(chi(&builtin_mesh("plane", &d).unwrap()), 1);
    }

    #[test]
    fn sizes_follow_the_options() {
        let o = |f: fn(&mut BuiltinOptions)| {
            let mut o = BuiltinOptions::default();
            f(&mut o);
            o
        };
        let ico = builtin_mesh("icosphere", &o(|o| o.subdivisions = 2)).unwrap();
        assert_eq!((ico.vertex_count(), ico.face_count()), (162, 320));
        let ico0 = builtin_mesh("icosphere", &o(|o| o.subdivisions = 0)).unwrap();
        assert_eq!((ico0.vertex_count(), ico0.face_count()), (12, 20));
        for p in &ico.positions {
            assert!((p.length() - 1.0).abs() < 1e-6);
        }
        let plane = builtin_mesh("plane", &o(|o| o.resolution = [5, 3])).unwrap();
        assert_eq!((plane.vertex_count(), plane.face_count()), (15, 16));
        let (lo, hi) = plane.bounding_box().unwrap();
        assert_eq!((lo.x, hi.x, lo.y, hi.y), (-1.0, 1.0, -0.5, 0.5));
        assert!(plane.face_normals().iter().all(|n| n.z > 0.99));
        let quads = builtin_mesh(
            "plane",
            &o(|o| {
                o.resolution = [5, 3];
                o.quads = true
            }),
        )
        .unwrap();
        assert_eq!(quads.face_count(), 8);
        assert!(!quads.is_triangle_mesh());
        let cube = builtin_mesh("cube", &o(|o| o.subdivisions = 1)).unwrap();
        assert_eq!((cube.vertex_count(), cube.face_count()), (26, 24));
        let knot = builtin_mesh("torus_knot", &BuiltinOptions::default()).unwrap();
        assert_eq!(knot.vertex_count(), 32 * 5 * 32);
    }

    #[test]
    fn jittered_plane_is_deterministic_interior_only_and_unflipped() {
        let opts = BuiltinOptions {
            resolution: [9, 7],
            jitter: 0.249,
            seed: 42,
            ..BuiltinOptions::default()
        };
        let a = builtin_mesh("jittered_plane", &opts).unwrap();
        let b = builtin_mesh("jittered_plane", &opts).unwrap();
        assert_eq!(a, b);
        let c = builtin_mesh(
            "jittered_plane",
            &BuiltinOptions {
                seed: 43,
                ..opts.clone()
            },
        )
        .unwrap();
        assert_ne!(a, c);
        let flat = builtin_mesh("plane", &opts).unwrap();
        assert_eq!(a.face_start, flat.face_start);
        assert_eq!(a.corner_vertex, flat.corner_vertex);
        let mut moved = 0;
        for (v, (p, q)) in a.positions.iter().zip(&flat.positions).enumerate() {
            let (i, j) = (v % 9, v / 9);
            if i == 0 || j == 0 || i == 8 || j == 6 {
                assert_eq!(p, q, "boundary vertex {v} moved");
            } else if p != q {
                moved += 1;
            }
            assert!((*p - *q).abs().max_element() <= 0.25 * 0.25 + 1e-6);
        }
        assert_eq!(moved, 7 * 5);
        assert!(a.face_normals().iter().all(|n| n.z > 0.0));
    }

    #[test]
    fn errors_name_the_option_and_range() {
        let err = builtin_mesh("teapot", &BuiltinOptions::default()).unwrap_err();
        let s = err.to_string();
        assert!(
            s.contains("teapot") && s.contains("icosphere") && s.contains("torus_knot"),
            "{s}"
        );
        let bad = |name: &str, f: fn(&mut BuiltinOptions), needle: &str| {
            let mut o = BuiltinOptions::default();
            f(&mut o);
            let err = builtin_mesh(name, &o).unwrap_err();
            assert!(matches!(err, MeshError::Builtin { .. }));
            assert!(err.to_string().contains(needle), "{name}: {err}");
        };
        bad("icosphere", |o| o.subdivisions = 9, "0..=8");
        bad("plane", |o| o.resolution = [1, 4], "resolution[0]");
        bad("jittered_plane", |o| o.jitter = 0.3, "jitter");
        bad("torus", |o| o.minor_radius = 1.5, "smaller than radius");
        bad("torus_knot", |o| o.p = 3, "coprime");
        bad("torus_knot", |o| o.minor_radius = 0.5, "minor_radius");
        bad("uv_sphere", |o| o.radius = f32::NAN, "radius");
        bad("cube", |o| o.size = -1.0, "size");
    }

    #[test]
    fn options_deserialise_strictly() {
        let o: BuiltinOptions =
            serde_json::from_str(r#"{"subdivisions": 2, "quads": true}"#).unwrap();
        assert_eq!(o.subdivisions, 2);
        assert!(o.quads);
        assert_eq!(o.radius, 1.0);
        assert!(serde_json::from_str::<BuiltinOptions>(r#"{"subdivision": 2}"#).is_err());
    }

    #[test]
    fn every_listed_name_builds() {
        for (name, _) in BUILTIN_MESHES {
            let m = builtin_mesh(name, &BuiltinOptions::default()).unwrap();
            assert!(m.face_count() > 0, "{name}");
        }
    }
}
