//! Resampling a surface signal on a square template in a vertex's tangent
//! plane: the "flattened neighbourhood" of Turk 2001 §4 and Wei & Levoy 2001
//! §3.2, made by projecting the nearby faces onto the tangent plane and
//! interpolating the signal at regularly spaced template points.
//!
//! # Template convention
//!
//! A template of `size`×`size` points is laid out like an image: point
//! `(i, j)` (column `i`, row `j`, both in `0..size`) lies at the tangent-plane
//! offset `((i - size/2) · spacing, (j - size/2) · spacing)` along `(s, t)`
//! of the frame's `(s, −t)` axes, with `size/2` rounded down (the centre
//! point for odd sizes). So `i` runs along `+s` (image x, to the right) and
//! `j` along `−t` (image y, downwards: `t` is the texture's up direction, see
//! [`crate::kernels::surface::frames`]). `out` receives the points row-major, `j` then `i`, with the
//! signal's channels interleaved: value `c` of point `(i, j)` is at
//! `(j · size + i) · channels + c`, the layout of an [`Image`] of the template.
//! Texture coordinates follow the same convention (`v = 0` at the top row).
//!
//! With `(s, t, n)` right-handed and `t` pointing up the image, an image laid
//! out this way reads unmirrored seen from the side `n` points to; every
//! stage uses this one convention, so synthesis and its metrics agree.

use glam::{Vec2, Vec3};

use crate::image::{Image, sample::Wrap};
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::{PolyMesh, Topology};

/// A signal over the surface to resample.
#[derive(Clone, Copy, Debug)]
pub enum SurfaceSignal<'a> {
    /// Per-vertex values, `channels` per vertex, interleaved; interpolated
    /// linearly over each (fan-triangulated) face.
    VertexColours {
        /// `vertex_count · channels` values.
        values: &'a [f32],
        /// Values per vertex.
        channels: usize,
    },
    /// A texture mapped by per-corner texture coordinates: the colour at a
    /// point is the bilinear texture sample at the barycentrically
    /// interpolated corner coordinates of the face containing it.
    CornerUvs {
        /// One `(u, v)` per corner of the mesh, in units of the texture size
        /// (`[0, 1]` spans it once), `v = 0` at the top row.
        uvs: &'a [Vec2],
        /// The texture.
        texture: &'a Image,
        /// Addressing of coordinates outside `[0, 1]`.
        wrap: Wrap,
    },
    /// Any signal evaluated by a function of a fan triangle's mesh corner
    /// indices and barycentric weights (e.g. lapped-texture pastes
    /// composited in order with alpha).
    Corners {
        /// Values per sample.
        channels: usize,
        /// Writes the signal at the point into the `channels`-value buffer.
        eval: CornerFn<'a>,
    },
}

/// The function of [`SurfaceSignal::Corners`]: `(corners, weights, out)`,
/// with `corners` the mesh corner indices of a fan triangle
/// `[c0, c, c + 1]` of one face ([`PolyMesh::triangulate_corners`]).
#[derive(Clone, Copy)]
pub struct CornerFn<'a>(pub &'a CornerEval<'a>);

/// The signature of a [`CornerFn`].
pub type CornerEval<'a> = dyn Fn([u32; 3], [f32; 3], &mut [f32]) + Sync + 'a;

impl std::fmt::Debug for CornerFn<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("CornerFn")
    }
}

impl SurfaceSignal<'_> {
    /// Values per sample.
    pub fn channels(&self) -> usize {
        match self {
            Self::VertexColours { channels, .. } => *channels,
            Self::CornerUvs { texture, .. } => texture.channels as usize,
            Self::Corners { channels, .. } => *channels,
        }
    }

    /// The signal at the point with barycentric weights `w` over the corners
    /// `corners`, written into `out` (`channels()` values).
    #[inline]
    fn eval(&self, mesh: &PolyMesh, corners: [u32; 3], w: [f32; 3], out: &mut [f32]) {
        match *self {
            Self::VertexColours { values, channels } => {
                out.fill(0.0);
                for k in 0..3 {
                    let v = mesh.corner_vertex[corners[k] as usize] as usize;
                    let src = &values[v * channels..(v + 1) * channels];
                    for (o, s) in out.iter_mut().zip(src) {
                        *o += w[k] * s;
                    }
                }
            }
            Self::CornerUvs { uvs, texture, wrap } => {
                let uv = uvs[corners[0] as usize] * w[0]
                    + uvs[corners[1] as usize] * w[1]
                    + uvs[corners[2] as usize] * w[2];
                texture.sample_uv(uv.x, uv.y, wrap, out);
            }
            Self::Corners { eval, .. } => (eval.0)(corners, w, out),
        }
    }
}

/// A fan triangle of a gathered face, projected into the tangent plane.
#[derive(Clone, Copy, Debug)]
struct ProjectedTriangle {
    /// Projected corners in tangent-plane coordinates.
    p: [Vec2; 3],
    /// Heights of the corners above the tangent plane (along `n`).
    h: [f32; 3],
    /// Mesh corner indices.
    corners: [u32; 3],
}

/// The triangle chosen for a template point so far.
#[derive(Clone, Copy, Debug)]
struct Hit {
    tri: u32,
    w: [f32; 3],
    /// Smallest barycentric weight (how far inside).
    inside: f32,
    /// Absolute interpolated height above the tangent plane.
    height: f32,
}

/// Reusable buffers of [`resample_neighbourhood`], so repeated calls do not
/// allocate. One per thread.
#[derive(Clone, Debug, Default)]
pub struct ResampleScratch {
    /// Per-face visit stamp, compared with `generation`.
    stamp: Vec<u32>,
    generation: u32,
    queue: Vec<u32>,
    tris: Vec<ProjectedTriangle>,
    hits: Vec<Option<Hit>>,
    /// Per template point: covered by a projected face.
    covered: Vec<bool>,
    /// Per vertex: projected position, height and whether it is near the
    /// centre, valid when `vstamp` matches.
    vproj: Vec<(Vec2, f32, bool)>,
    vstamp: Vec<u32>,
    /// Per vertex: its faces were queued, when equal to `generation`.
    vqueued: Vec<u32>,
}

impl ResampleScratch {
    /// Empty buffers; they grow on first use.
    pub fn new() -> Self {
        Self::default()
    }

    /// After a call, whether each template point (row-major) was covered by a
    /// projected face; uncovered points hold the default value.
    pub fn coverage(&self) -> &[bool] {
        &self.covered
    }

    fn begin(&mut self, faces: usize, vertices: usize, points: usize) {
        if self.stamp.len() != faces || self.vstamp.len() != vertices {
            self.stamp.clear();
            self.stamp.resize(faces, 0);
            self.vstamp.clear();
            self.vstamp.resize(vertices, 0);
            self.vqueued.clear();
            self.vqueued.resize(vertices, 0);
            self.vproj.resize(vertices, (Vec2::ZERO, 0.0, false));
            self.generation = 0;
        }
        self.generation = self.generation.wrapping_add(1);
        if self.generation == 0 {
            self.stamp.fill(0);
            self.vstamp.fill(0);
            self.vqueued.fill(0);
            self.generation = 1;
        }
        self.queue.clear();
        self.tris.clear();
        self.hits.clear();
        self.hits.resize(points, None);
        self.covered.clear();
        self.covered.resize(points, false);
    }
}

/// Tolerance on barycentric weights, so template points on shared edges and
/// vertices are found.
const INSIDE_EPS: f32 = 1e-5;

/// Resamples `signal` at the `size`×`size` template points around `vertex`
/// in `frame` (see the module doc for the layout), `spacing` world units
/// apart, into `out`. Returns how many template points were covered by a face.
///
/// Faces are gathered by a breadth-first walk over faces sharing a vertex,
/// starting from the faces of `vertex`, and expanded past a face only while
/// one of its vertices lies within `1.5 · (size/2) · spacing` of `vertex`
/// (3D distance), or while its projection overlaps the template square. Their
/// vertices are projected to `((p - p0)·s, (p - p0)·t)`; polygons are
/// fan-triangulated and triangles whose projection is flipped (clockwise
/// seen along `n`) or degenerate are skipped. Each template point takes the
/// projected triangle containing it (up to a small tolerance); where several
/// do (folds), the one whose surface is nearest the tangent plane, then the
/// one it lies deepest in. Points no triangle covers get `default`;
/// [`ResampleScratch::coverage`] tells which.
///
/// Preconditions: `topo` was built for `mesh`; `vertex < mesh.vertex_count()`;
/// `spacing > 0`; `default.len() == signal.channels()`;
/// `out.len() == size² · signal.channels()`; vertex values or corner UVs
/// cover the mesh.
#[allow(clippy::too_many_arguments)]
pub fn resample_neighbourhood(
    mesh: &PolyMesh,
    topo: &Topology,
    vertex: u32,
    frame: &TangentFrame,
    spacing: f32,
    size: u32,
    signal: &SurfaceSignal,
    default: &[f32],
    out: &mut [f32],
    scratch: &mut ResampleScratch,
) -> usize {
    let channels = signal.channels();
    let n = size as usize;
    assert_eq!(out.len(), n * n * channels, "template buffer size");
    assert_eq!(default.len(), channels, "default value size");
    scratch.begin(mesh.face_count(), mesh.vertex_count(), n * n);
    let gen_ = scratch.generation;

    let p0 = mesh.positions[vertex as usize];
    let half = (size / 2) as f32;
    let radius = 1.5 * half * spacing;
    let radius_sq = radius * radius;
    // The template square, enlarged by one spacing.
    let lo = -(half + 1.0) * spacing;
    let hi = ((n as f32 - 1.0 - half) + 1.0) * spacing;

    let ResampleScratch {
        stamp,
        queue,
        tris,
        hits,
        covered,
        vproj,
        vstamp,
        vqueued,
        ..
    } = scratch;

    let mut project = |v: u32| -> (Vec2, f32, bool) {
        let vi = v as usize;
        if vstamp[vi] != gen_ {
            let d: Vec3 = mesh.positions[vi] - p0;
            // (d·s, −d·t): image x right, image y down.
            vproj[vi] = (
                Vec2::new(d.dot(frame.s), -d.dot(frame.t)),
                d.dot(frame.n),
                d.length_squared() <= radius_sq,
            );
            vstamp[vi] = gen_;
        }
        vproj[vi]
    };

    for &f in topo.vertex_faces(vertex) {
        stamp[f as usize] = gen_;
        queue.push(f);
    }
    let mut head = 0;
    while head < queue.len() {
        let f = queue[head] as usize;
        head += 1;
        let corners = mesh.face_corners(f);
        let face = mesh.face(f);

        // Project the face, fan-triangulate it and note whether it is near.
        let mut near = false;
        let mut bb_min = Vec2::splat(f32::INFINITY);
        let mut bb_max = Vec2::splat(f32::NEG_INFINITY);
        for &v in face {
            let (q, _, v_near) = project(v);
            near |= v_near;
            bb_min = bb_min.min(q);
            bb_max = bb_max.max(q);
        }
        let c0 = corners.start;
        let mut any_front = false;
        let first_tri = tris.len();
        for c in (corners.start + 1)..(corners.end - 1) {
            let ids = [c0, c, c + 1];
            let pr = ids.map(|k| project(mesh.corner_vertex[k]));
            let p = pr.map(|x| x.0);
            // Front faces (counter-clockwise about n) turn clockwise in
            // (x right, y down) coordinates: negative signed area.
            let area2 = (p[1] - p[0]).perp_dot(p[2] - p[0]);
            if area2 >= 0.0 {
                continue;
            }
            any_front = true;
            tris.push(ProjectedTriangle {
                p,
                h: pr.map(|x| x.1),
                corners: ids.map(|k| k as u32),
            });
        }
        let overlaps =
            any_front && bb_max.x >= lo && bb_min.x <= hi && bb_max.y >= lo && bb_min.y <= hi;
        // Its triangles are kept only where the rasteriser below could
        // place a lattice point in them: within its margin (for the face's
        // extent, at least that of any of its triangles) of the lattice,
        // and never less than the one spacing `overlaps` allows. The
        // triangles kept keep their order, so ties fall as before.
        let reach = spacing * (1.0 + 1e-3 + 1e-4 * ((bb_max - bb_min).max_element() / spacing));
        let (first, last) = (
            -half * spacing - reach,
            (n as f32 - 1.0 - half) * spacing + reach,
        );
        if !(bb_max.x >= first && bb_min.x <= last && bb_max.y >= first && bb_min.y <= last) {
            tris.truncate(first_tri);
        }
        if !(near || overlaps) {
            continue;
        }
        // A vertex's faces are queued once: after that every one of them
        // is stamped, so going over them again would queue nothing (the
        // queue, and the faces found, are those of going over them again).
        for &v in face {
            if vqueued[v as usize] == gen_ {
                continue;
            }
            vqueued[v as usize] = gen_;
            for &g in topo.vertex_faces(v) {
                if stamp[g as usize] != gen_ {
                    stamp[g as usize] = gen_;
                    queue.push(g);
                }
            }
        }
    }

    // Rasterise each triangle over the template lattice it overlaps.
    let to_index = |x: f32| x / spacing + half;
    for (ti, tri) in tris.iter().enumerate() {
        let [a, b, c] = tri.p;
        let mn = a.min(b).min(c);
        let mx = a.max(b).max(c);
        // Points a hair outside the bounding box still count: a point
        // whose weights are all at least −INSIDE_EPS lies within
        // 3·INSIDE_EPS of the triangle's extent beyond it on each axis, so
        // a margin of 10⁻⁴ of the extent (plus 10⁻³ of a lattice step for
        // rounding) keeps every point the test below can accept.
        let extent = (mx - mn) / spacing;
        let margin = 1e-3 + 1e-4 * extent.x.max(extent.y);
        let i0 = (to_index(mn.x) - margin).ceil().max(0.0);
        let i1 = (to_index(mx.x) + margin).floor().min(n as f32 - 1.0);
        let j0 = (to_index(mn.y) - margin).ceil().max(0.0);
        let j1 = (to_index(mx.y) + margin).floor().min(n as f32 - 1.0);
        if i0 > i1 || j0 > j1 {
            continue;
        }
        let den = (b - a).perp_dot(c - a);
        for j in j0 as usize..=j1 as usize {
            for i in i0 as usize..=i1 as usize {
                let q = Vec2::new((i as f32 - half) * spacing, (j as f32 - half) * spacing);
                let w1 = (q - a).perp_dot(c - a) / den;
                let w2 = (b - a).perp_dot(q - a) / den;
                let w0 = 1.0 - w1 - w2;
                let inside = w0.min(w1).min(w2);
                if inside < -INSIDE_EPS {
                    continue;
                }
                let height = (w0 * tri.h[0] + w1 * tri.h[1] + w2 * tri.h[2]).abs();
                let cand = Hit {
                    tri: ti as u32,
                    w: [w0, w1, w2],
                    inside,
                    height,
                };
                let slot = &mut hits[j * n + i];
                let better = match slot {
                    None => true,
                    Some(best) => {
                        let tol = 1e-4 * spacing;
                        height < best.height - tol
                            || (height <= best.height + tol && inside > best.inside)
                    }
                };
                if better {
                    *slot = Some(cand);
                }
            }
        }
    }

    let mut count = 0;
    for (k, hit) in hits.iter().enumerate() {
        let dst = &mut out[k * channels..(k + 1) * channels];
        match hit {
            Some(h) => {
                signal.eval(mesh, tris[h.tri as usize].corners, h.w, dst);
                covered[k] = true;
                count += 1;
            }
            None => dst.copy_from_slice(default),
        }
    }
    count
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A planar grid with vertex `(x, y)` at `(x, −y, 0)` (image rows run
    /// down), quads counter-clockwise about +Z, so the frame `s = X`, `t = Y`,
    /// `n = Z` matches image axes.
    fn grid(w: u32, h: u32) -> PolyMesh {
        let positions = (0..h)
            .flat_map(|y| (0..w).map(move |x| Vec3::new(x as f32, -(y as f32), 0.0)))
            .collect();
        let mut faces = Vec::new();
        for y in 0..h - 1 {
            for x in 0..w - 1 {
                let v = y * w + x;
                faces.push([v, v + w, v + w + 1, v + 1]);
            }
        }
        PolyMesh::from_polygons(positions, faces.iter().map(|f| &f[..]))
    }

    fn frame() -> TangentFrame {
        TangentFrame::from_direction(Vec3::Z, Vec3::X)
    }

    #[test]
    fn template_at_grid_vertex_copies_values_in_image_order() {
        let (w, h) = (9u32, 8u32);
        let mesh = grid(w, h);
        let topo = Topology::build(&mesh);
        // Distinct values per vertex, so any flip or transpose shows.
        let values: Vec<f32> = (0..w * h)
            .flat_map(|v| [(v % w) as f32, (v / w) as f32 * 100.0])
            .collect();
        let signal = SurfaceSignal::VertexColours {
            values: &values,
            channels: 2,
        };
        let mut scratch = ResampleScratch::new();
        let size = 5u32;
        let mut out = vec![0.0; 25 * 2];
        let (cx, cy) = (4u32, 3u32);
        let covered = resample_neighbourhood(
            &mesh,
            &topo,
            cy * w + cx,
            &frame(),
            1.0,
            size,
            &signal,
            &[-1.0, -1.0],
            &mut out,
            &mut scratch,
        );
        assert_eq!(covered, 25);
        for j in 0..5u32 {
            for i in 0..5u32 {
                let k = ((j * 5 + i) * 2) as usize;
                let (x, y) = (cx + i - 2, cy + j - 2);
                assert_eq!(out[k], x as f32, "x at template ({i}, {j})");
                assert_eq!(out[k + 1], y as f32 * 100.0, "y at template ({i}, {j})");
            }
        }
    }

    #[test]
    fn half_spacing_interpolates_and_border_gets_default() {
        let mesh = grid(4, 4);
        let topo = Topology::build(&mesh);
        let values: Vec<f32> = (0..16)
            .map(|v| (v % 4) as f32 + 10.0 * (v / 4) as f32)
            .collect();
        let signal = SurfaceSignal::VertexColours {
            values: &values,
            channels: 1,
        };
        let mut scratch = ResampleScratch::new();
        let mut out = vec![0.0; 25];
        // Vertex (0, 0) is a corner: only the quadrant i, j >= 2 is covered.
        let covered = resample_neighbourhood(
            &mesh,
            &topo,
            0,
            &frame(),
            0.5,
            5,
            &signal,
            &[-7.0],
            &mut out,
            &mut scratch,
        );
        assert_eq!(covered, 9);
        for j in 0..5 {
            for i in 0..5 {
                let v = out[j * 5 + i];
                if i >= 2 && j >= 2 {
                    let expect = (i - 2) as f32 * 0.5 + 10.0 * (j - 2) as f32 * 0.5;
                    assert!((v - expect).abs() < 1e-5, "({i}, {j}): {v} vs {expect}");
                    assert!(scratch.coverage()[j * 5 + i]);
                } else {
                    assert_eq!(v, -7.0);
                    assert!(!scratch.coverage()[j * 5 + i]);
                }
            }
        }
    }

    #[test]
    fn rotated_frame_rotates_the_template() {
        // With s = +Y (t = -X), template column i runs up the world's Y axis.
        let (w, h) = (7u32, 7u32);
        let mesh = grid(w, h);
        let topo = Topology::build(&mesh);
        let values: Vec<f32> = (0..w * h).map(|v| v as f32).collect();
        let signal = SurfaceSignal::VertexColours {
            values: &values,
            channels: 1,
        };
        let f = TangentFrame::from_direction(Vec3::Z, Vec3::Y);
        let mut out = vec![0.0; 9];
        let c = 3 * w + 3;
        resample_neighbourhood(
            &mesh,
            &topo,
            c,
            &f,
            1.0,
            3,
            &signal,
            &[0.0],
            &mut out,
            &mut ResampleScratch::new(),
        );
        for j in 0..3i32 {
            for i in 0..3i32 {
                // offset = (i-1)·s − (j-1)·t = (i-1)·Y + (j-1)·X in world;
                // grid y runs along −Y.
                let (x, y) = (3 + (j - 1), 3 - (i - 1));
                assert_eq!(out[(j * 3 + i) as usize], (y * w as i32 + x) as f32);
            }
        }
    }

    #[test]
    fn corner_uvs_sample_the_texture_and_flipped_faces_are_skipped() {
        let (w, h) = (6u32, 6u32);
        let mut mesh = grid(w, h);
        let tex = Image::from_data(w, h, 1, (0..w * h).map(|i| i as f32 / 36.0).collect()).unwrap();
        // Vertex (x, y) maps to the centre of texel (x, y).
        let uvs: Vec<Vec2> = mesh
            .corner_vertex
            .iter()
            .map(|&v| {
                Vec2::new(
                    ((v % w) as f32 + 0.5) / w as f32,
                    ((v / w) as f32 + 0.5) / h as f32,
                )
            })
            .collect();
        let topo = Topology::build(&mesh);
        let signal = SurfaceSignal::CornerUvs {
            uvs: &uvs,
            texture: &tex,
            wrap: Wrap::Clamp,
        };
        let mut out = vec![0.0; 9];
        let mut scratch = ResampleScratch::new();
        let c = 2 * w + 2;
        let n = resample_neighbourhood(
            &mesh,
            &topo,
            c,
            &frame(),
            1.0,
            3,
            &signal,
            &[9.0],
            &mut out,
            &mut scratch,
        );
        assert_eq!(n, 9);
        for j in 0..3 {
            for i in 0..3 {
                let expect = tex.pixel(1 + i, 1 + j)[0];
                assert!((out[(j * 3 + i) as usize] - expect).abs() < 1e-6);
            }
        }
        // Reversing every face flips its projection: nothing is covered.
        let reversed: Vec<Vec<u32>> = mesh
            .faces()
            .map(|f| f.iter().rev().copied().collect())
            .collect();
        mesh = PolyMesh::from_polygons(mesh.positions.clone(), reversed.iter().map(|f| &f[..]));
        let topo = Topology::build(&mesh);
        let n = resample_neighbourhood(
            &mesh,
            &topo,
            c,
            &frame(),
            1.0,
            3,
            &signal,
            &[9.0],
            &mut out,
            &mut scratch,
        );
        assert_eq!(n, 0);
        assert!(out.iter().all(|&v| v == 9.0));
    }
}
