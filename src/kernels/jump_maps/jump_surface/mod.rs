//! Jump-map texture synthesis directly on surfaces (Zelinka & Garland 2004 §6).
//!
//! One pass over the vertices in a chosen order (§6.2) assigns each vertex a
//! floating-point exemplar address (pixels). Each already-synthesized
//! neighbour suggests "copy": its address plus the texture-space offset of the
//! edge (§6.3), and "jump": the destinations of the floating-point jump-map
//! look-up (§6.4) at that copy address (the paper looks up at the
//! neighbour's address and adds the offset; both agree for one-pixel steps,
//! and ours keeps jumps matched across long edges of coarse meshes). Suggestions that keep
//! the vertex's flattened one-ring inside the exemplar are valid (§6.5,
//! Fig. 18); one random number picks among all valid suggestions of all
//! neighbours (the selection table of §6.6). Only when none is valid is the
//! vertex placed at random. Per-corner texture coordinates then come from each
//! face's base vertex plus edge offsets, for every choice of base vertex, so a
//! renderer can blend the three (§6.5).
//!
//! Extensions, each an option whose default in [`SurfaceSynthSettings`] is
//! the paper's (the `jump_surface` stage turns them on; measured in
//! ARCHITECTURE.md, "Jump maps on surfaces without blur, repeats or seams"):
//! - `pixel_aligned`: random starts at pixel centres. Copies and jumps keep
//!   a start's sub-pixel phase, so a start between centres resamples its
//!   whole patch (bilinear blur) wherever the mapping is pixel-aligned.
//! - `max_patch_area`: a patch stops suggesting copies once it covers this
//!   much of the exemplar, so no large region is copied again and again.
//! - the matched choice ([`synthesize_surface_matched`]): where the draw
//!   leaves a choice, the candidate whose exemplar neighbourhood best
//!   matches the synthesised vertices wins.
//!
//! Coordinates: pixel addresses with x right, y down, integer values at pixel
//! centres (`(x + 0.5) / width` is the texture coordinate u).
//!
//! Files: this one (settings, the output, edge offsets, the paper's
//! synthesis, per-vertex scales); [`matched`] (the matched choice and the
//! seam band); [`seams`] (the seam refinement, an extension); [`uvs`]
//! (per-corner texture coordinates and the 3-way blend layers).

mod matched;
mod seams;
mod uvs;

pub use matched::*;
pub use seams::*;
pub use uvs::*;

use crate::kernels::jump_maps::vertex_order::VertexOrder;
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::Topology;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Read access to a jump map for the surface synthesizer.
pub trait JumpLookup: Sync {
    /// Width and height of the analysed exemplar, pixels.
    fn dims(&self) -> (u32, u32);
    /// Calls `f(dest_x, dest_y, weight)` for each jump stored at pixel `(x, y)`.
    fn for_each_jump<F: FnMut(u32, u32, f32)>(&self, x: u32, y: u32, f: F);
}

/// Settings of surface synthesis.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceSynthSettings {
    /// Desired patch size as a fraction of the exemplar's side `L`: patches
    /// of about `(f·L)²` pixels are wanted, so random numbers are drawn over
    /// twice that many pixels (§5.1). Each vertex counts for the texture area
    /// it covers (its mean squared edge offset), so the patch size in texels
    /// does not depend on the mesh resolution. 0.05..=16.
    pub patch_fraction: f32,
    /// Width of the boundary-avoidance band as a fraction of the exemplar
    /// size (§5.2; 0 turns it off). Ignored for tileable exemplars.
    pub boundary_fraction: f32,
    /// The exemplar tiles: addresses wrap and every suggestion is valid.
    pub tileable: bool,
    /// Vertex ordering.
    pub order: VertexOrder,
    /// Seed of the order and of every random choice.
    pub seed: u64,
    /// Largest area one patch may copy, as a fraction of the exemplar's
    /// area (an extension; 0 = unbounded, the paper). A patch is the set of
    /// vertices grown by copies from one jump or random start; once its
    /// texel area reaches this, its vertices no longer suggest copies, so
    /// the next vertex jumps. Bounds the tail of the patch sizes, which
    /// otherwise copies large parts of the exemplar verbatim again and
    /// again. 0..=1.
    pub max_patch_area: f32,
    /// Random starts at pixel centres (an extension; false = anywhere, the
    /// paper). Copies and jumps keep a start's sub-pixel phase, so a start
    /// between pixel centres resamples the whole patch it grows (bilinear
    /// blur) wherever the mapping is pixel-aligned (a flat mesh at one pixel
    /// per vertex spacing); elsewhere it changes nothing.
    pub pixel_aligned: bool,
}

impl Default for SurfaceSynthSettings {
    fn default() -> Self {
        Self {
            patch_fraction: 0.5,
            boundary_fraction: 0.2,
            tileable: false,
            order: VertexOrder::EmergingFront,
            seed: 0,
            max_patch_area: 0.0,
            pixel_aligned: false,
        }
    }
}

/// The result of surface synthesis.
#[derive(Clone, Debug, Default)]
pub struct SurfaceSynthOutput {
    /// Exemplar address per vertex, pixels.
    pub texel: Vec<Vec2>,
    /// Vertices that took a jump suggestion.
    pub jumps: usize,
    /// Vertices placed at random (component starts and vertices with no valid suggestion).
    pub random_assignments: usize,
    /// Vertices whose flattened one-ring is larger than the exemplar, so no
    /// address is valid (their texture is clamped).
    pub unfit: usize,
    /// Vertices without a valid suggestion (the paper places them at
    /// random) that the matched choice placed by matching their
    /// neighbourhood; counted in `jumps`, not in `random_assignments`.
    pub matched_starts: usize,
    /// Per vertex, its patch: the jump or random start whose copies reached
    /// it (numbered in synthesis order).
    pub patch: Vec<u32>,
}

/// Texture-space offset of every directed edge `v → w`, aligned with
/// `topo.neighbour_list` (§6.3, Fig. 13): the edge is projected onto the
/// average of its endpoints' bases, scaled by the mean of their scales
/// (pixels per world unit). `offset(v→w) = −offset(w→v)` exactly.
pub fn edge_offsets(
    positions: &[Vec3],
    frames: &[TangentFrame],
    scale: &[f32],
    topo: &Topology,
) -> Vec<Vec2> {
    let mut out = vec![Vec2::ZERO; topo.neighbour_list.len()];
    let starts = &topo.neighbour_start;
    out.par_chunks_mut(4096)
        .enumerate()
        .for_each(|(chunk, slots)| {
            let first = chunk * 4096;
            // The vertex owning slot `first`.
            let mut v = starts.partition_point(|&s| s as usize <= first) - 1;
            for (k, slot) in slots.iter_mut().enumerate() {
                let i = first + k;
                while starts[v + 1] as usize <= i {
                    v += 1;
                }
                let w = topo.neighbour_list[i] as usize;
                *slot = edge_offset(positions, frames, scale, v, w);
            }
        });
    out
}

#[inline]
fn edge_offset(
    positions: &[Vec3],
    frames: &[TangentFrame],
    scale: &[f32],
    a: usize,
    b: usize,
) -> Vec2 {
    // Symmetric in (a, b) so both directions share one basis; where the
    // mean degenerates (opposite frames), the lower vertex's frame, so the
    // fallback is symmetric too and the offsets stay exactly antisymmetric.
    let (fa, fb) = (&frames[a], &frames[b]);
    let low = &frames[a.min(b)];
    let up = (fa.t + fb.t).try_normalize().unwrap_or(low.t);
    let right_avg = fa.s + fb.s;
    let right = (right_avg - up * up.dot(right_avg))
        .try_normalize()
        .unwrap_or(low.s);
    let k = 0.5 * (scale[a] + scale[b]);
    let d = positions[b] - positions[a];
    Vec2::new(d.dot(right), -d.dot(up)) * k
}

/// Offset of the edge `a → b` from the CSR arrays (`None` when not adjacent).
#[inline]
pub fn offset_between(topo: &Topology, offsets: &[Vec2], a: u32, b: u32) -> Option<Vec2> {
    let nb = topo.neighbours(a);
    let i = nb.binary_search(&b).ok()?;
    Some(offsets[topo.neighbour_start[a as usize] as usize + i])
}

/// Runs the synthesis pass. `offsets` come from [`edge_offsets`].
pub fn synthesize_surface<J: JumpLookup>(
    topo: &Topology,
    offsets: &[Vec2],
    jumps: &J,
    settings: &SurfaceSynthSettings,
    progress: &crate::progress::Progress,
) -> SurfaceSynthOutput {
    synthesize_surface_matched(topo, offsets, jumps, settings, None, progress)
}

impl JumpLookup for crate::kernels::jump_maps::jump_map::JumpMap {
    fn dims(&self) -> (u32, u32) {
        (self.width(), self.height())
    }
    #[inline]
    fn for_each_jump<F: FnMut(u32, u32, f32)>(&self, x: u32, y: u32, mut f: F) {
        for j in self.jumps_at(x, y) {
            f(j.to.x, j.to.y, j.weight);
        }
    }
}

/// Per-vertex scale (exemplar pixels per world unit): `base` times a ramp
/// from `factors[0]` at the lowest vertex along `axis` to `factors[1]` at
/// the highest (`base` everywhere when both are 1).
pub fn height_scales(positions: &[Vec3], base: f32, factors: [f32; 2], axis: Vec3) -> Vec<f32> {
    let [lo_f, hi_f] = factors;
    if (lo_f - 1.0).abs() < 1e-9 && (hi_f - 1.0).abs() < 1e-9 {
        return vec![base; positions.len()];
    }
    let axis = axis.normalize_or_zero();
    let (lo, hi) = positions.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| {
        let h = p.dot(axis);
        (lo.min(h), hi.max(h))
    });
    let span = (hi - lo).max(1e-12);
    positions
        .iter()
        .map(|p| {
            let t = (p.dot(axis) - lo) / span;
            base * (lo_f + (hi_f - lo_f) * t)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::PolyMesh;

    /// A jump map with no jumps: synthesis must then copy everywhere.
    struct NoJumps(u32, u32);
    impl JumpLookup for NoJumps {
        fn dims(&self) -> (u32, u32) {
            (self.0, self.1)
        }
        fn for_each_jump<F: FnMut(u32, u32, f32)>(&self, _: u32, _: u32, _: F) {}
    }

    fn plane(n: usize) -> PolyMesh {
        let p = (0..n * n)
            .map(|i| Vec3::new((i % n) as f32, -((i / n) as f32), 0.0))
            .collect();
        let mut faces = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = (y * n + x) as u32;
                let n = n as u32;
                faces.push([i, i + n, i + n + 1]);
                faces.push([i, i + n + 1, i + 1]);
            }
        }
        PolyMesh::from_triangles(p, &faces)
    }

    #[test]
    fn without_jumps_a_plane_is_a_translated_copy() {
        let m = plane(8);
        let t = Topology::build(&m);
        let frames = vec![TangentFrame::from_up(Vec3::Z, Vec3::Y); m.vertex_count()];
        let scale = vec![1.0; m.vertex_count()];
        let off = edge_offsets(&m.positions, &frames, &scale, &t);
        // +x world is +x pixels; world -y (down the grid) is +y pixels.
        assert_eq!(offset_between(&t, &off, 0, 1), Some(Vec2::new(1.0, 0.0)));
        assert_eq!(offset_between(&t, &off, 0, 8), Some(Vec2::new(0.0, 1.0)));
        let s = SurfaceSynthSettings {
            tileable: true,
            ..Default::default()
        };
        let out = synthesize_surface(&t, &off, &NoJumps(32, 32), &s, &Default::default());
        assert_eq!(out.random_assignments, 1, "only the start is random");
        let p0 = out.texel[0];
        for (v, p) in out.texel.iter().enumerate() {
            let expect = p0 + Vec2::new((v % 8) as f32, (v / 8) as f32);
            let d = (*p - expect).abs();
            let d = Vec2::new(d.x.min(32.0 - d.x), d.y.min(32.0 - d.y));
            assert!(d.max_element() < 1e-3, "vertex {v}: {p} vs {expect}");
        }
    }

    /// A unit grid plane at one pixel per edge and its offsets.
    fn unit_plane(n: usize) -> (PolyMesh, Topology, Vec<Vec2>) {
        let m = plane(n);
        let t = Topology::build(&m);
        let frames = vec![TangentFrame::from_up(Vec3::Z, Vec3::Y); m.vertex_count()];
        let off = edge_offsets(&m.positions, &frames, &vec![1.0; m.vertex_count()], &t);
        (m, t, off)
    }

    #[test]
    fn pixel_aligned_starts_keep_every_address_on_a_pixel_centre() {
        let (_, t, off) = unit_plane(24);
        for aligned in [false, true] {
            let s = SurfaceSynthSettings {
                pixel_aligned: aligned,
                seed: 5,
                ..Default::default()
            };
            let out = synthesize_surface(&t, &off, &NoJumps(16, 16), &s, &Default::default());
            // A 24² plane in a 16² exemplar: copies run out, so starts recur.
            assert!(out.random_assignments > 1);
            let on_centres = out
                .texel
                .iter()
                .all(|p| (*p - p.round()).abs().max_element() < 1e-4);
            assert_eq!(on_centres, aligned, "pixel_aligned {aligned}");
        }
    }

    #[test]
    fn patches_stop_copying_at_the_area_cap() {
        let (_, t, off) = unit_plane(40);
        let area = |cap: f32| {
            let s = SurfaceSynthSettings {
                tileable: true,
                max_patch_area: cap,
                ..Default::default()
            };
            let out = synthesize_surface(&t, &off, &NoJumps(32, 32), &s, &Default::default());
            let mut count = vec![0usize; out.patch.iter().max().map_or(0, |&p| p as usize + 1)];
            for &p in &out.patch {
                count[p as usize] += 1;
            }
            count.into_iter().max().unwrap_or(0)
        };
        // Without a cap one start covers the whole 40² plane. With a cap of
        // a quarter of the 32² exemplar (256 pixels), each vertex counting
        // its mean squared edge offset (4/3 of a pixel on this triangulated
        // grid: four unit edges and two diagonals), a patch stops at 192
        // vertices plus the front that completes it.
        assert_eq!(area(0.0), 1600);
        let capped = area(0.25);
        assert!((192..=192 + 40).contains(&capped), "largest patch {capped}");
    }

    #[test]
    fn seam_band_holds_the_vertices_next_to_another_patch() {
        let (m, t, _) = unit_plane(10);
        // Two patches split at x = 5.
        let patch: Vec<u32> = (0..m.vertex_count())
            .map(|v| u32::from(v % 10 >= 5))
            .collect();
        let band = seam_band(&t, &patch, 0);
        for (v, &b) in band.iter().enumerate() {
            let x = v % 10;
            // The grid's diagonals reach one column across.
            assert_eq!(b, x == 4 || x == 5, "vertex {v}");
        }
        let wider = seam_band(&t, &patch, 1);
        assert!((0..m.vertex_count()).all(|v| wider[v] == (3..=6).contains(&(v % 10))));
    }

    #[test]
    fn clamped_addresses_keep_one_rings_inside() {
        let m = plane(12);
        let t = Topology::build(&m);
        let frames = vec![TangentFrame::from_up(Vec3::Z, Vec3::Y); m.vertex_count()];
        let scale = vec![1.5; m.vertex_count()];
        let off = edge_offsets(&m.positions, &frames, &scale, &t);
        let s = SurfaceSynthSettings::default();
        let out = synthesize_surface(&t, &off, &NoJumps(10, 10), &s, &Default::default());
        assert_eq!(out.unfit, 0);
        for v in 0..m.vertex_count() as u32 {
            for &w in t.neighbours(v) {
                let q = out.texel[v as usize] + offset_between(&t, &off, v, w).unwrap();
                assert!(q.cmpge(Vec2::splat(-1e-3)).all() && q.cmple(Vec2::splat(9.001)).all());
            }
        }
        let sides = corner_side_offsets(&m, &t, &off);
        let (single, compact) = corner_uvs(&m, sides, &out.texel, (10, 10));
        let blend = compact.to_vec(&m);
        for (t, layers) in blend.iter().enumerate() {
            assert_eq!(compact.triangle(&m, t), *layers, "triangle {t}");
        }
        assert!(
            single
                .iter()
                .all(|uv| uv.cmpge(Vec2::ZERO).all() && uv.cmple(Vec2::ONE).all())
        );
        assert_eq!(blend.len(), m.face_count());
        // A triangle's layers differ only by where the base vertex sits.
        for (f, layers) in blend.iter().enumerate() {
            let e01 = layers[0][1] - layers[0][0];
            let e01b = layers[1][1] - layers[1][0];
            assert!((e01 - e01b).length() < 1e-5, "face {f}: edge offsets agree");
        }
    }
}
