//! Face coverage (Praun et al. 2000 §3.6) and the culling of occluded faces
//! for runtime pasting (§4).
//!
//! After each paste, every face of the new surface patch is rasterised in
//! texture space: each face carries a fixed set of samples at the texture
//! patch's pixel density (the centroids of a `k × k` subdivision of the
//! face, `k² ≈` the face's area in texture pixels, see [`sample_levels`]).
//! Each sample is mapped through every paste that holds the face
//! (barycentric coordinates carry it from one paste's texture space to
//! another's) and the alphas are accumulated, `1 − Π (1 − α)`. A sample is
//! covered when the accumulated alpha is opaque; a face is covered when the
//! fraction of covered samples reaches [`CoverageSettings::threshold`]. For
//! an uncovered face the least covered sample is remembered, to centre a
//! later paste there.
//!
//! Two departures from the paper's colour-coded face ids in an off-screen
//! buffer: samples are generated per face, which handles patches that
//! overlap themselves in texture space without extra passes; and they do
//! not depend on which paste is being tested, so coverage only ever grows
//! (with the pixel grid of the newest paste, a face found covered could
//! later be probed at a point that was missed before).

use super::mask::TexturePatch;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Settings of the coverage test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoverageSettings {
    /// Fraction of a face's samples that must be covered, `(0, 1]`. Default 1.
    pub threshold: f32,
    /// Accumulated alpha from which a sample counts as covered. Default
    /// `1 − 0.5 / 255` (opaque in 8 bits).
    pub opaque: f32,
    /// Largest subdivision level `k` of a face (`k²` samples). Default 64.
    pub max_level: u16,
}

impl Default for CoverageSettings {
    fn default() -> Self {
        Self {
            threshold: 1.0,
            opaque: 1.0 - 0.5 / 255.0,
            max_level: 64,
        }
    }
}

/// Per face, the subdivision level `k` of its coverage samples: `k²`
/// about the face's area in texture pixels, where a face of world area `A`
/// under the field `T` covers `A / ‖T‖² · unit_px²` pixels (`unit_px`:
/// pixels per patch unit of the finest texture patch). At least 1, at most
/// `max_level`.
pub fn sample_levels(areas: &[f32], field: &[Vec3], unit_px: f32, max_level: u16) -> Vec<u16> {
    areas
        .iter()
        .zip(field)
        .map(|(&a, t)| {
            let scale2 = t.length_squared().max(f32::MIN_POSITIVE);
            let px = (a / scale2) * unit_px * unit_px;
            (px.max(0.0).sqrt().ceil() as u16).clamp(1, max_level.max(1))
        })
        .collect()
}

/// The `k²` sample points of a face at level `k`: barycentric coordinates
/// of the centroids of the sub-triangles of its `k`-fold subdivision.
pub fn lattice_samples(k: u16) -> Vec<[f32; 3]> {
    let k = k.max(1) as usize;
    let inv = 1.0 / k as f32;
    let mut out = Vec::with_capacity(k * k);
    for j in 0..k {
        for i in 0..k - j {
            let (u, v) = ((i as f32 + 1.0 / 3.0) * inv, (j as f32 + 1.0 / 3.0) * inv);
            out.push([1.0 - u - v, u, v]);
            if i + j + 2 <= k {
                let (u, v) = ((i as f32 + 2.0 / 3.0) * inv, (j as f32 + 2.0 / 3.0) * inv);
                out.push([1.0 - u - v, u, v]);
            }
        }
    }
    out
}

/// One paste holding a face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaceLayer {
    /// The paste, in paste order.
    pub paste: u32,
    /// Its texture patch.
    pub texture: u32,
    /// Position of the face in the paste's face list.
    pub slot: u32,
    /// Texture coordinates of the face's corners in that paste.
    pub uv: [Vec2; 3],
}

/// Coverage state of every face.
#[derive(Clone, Debug, Default)]
pub struct Coverage {
    /// Whether the face is covered.
    pub covered: Vec<bool>,
    /// Covered fraction of the face's samples at its last test.
    pub fraction: Vec<f32>,
    /// Barycentric coordinates of the least covered sample of the face's
    /// last test; `None` before the first test and once covered.
    pub uncovered_point: Vec<Option<[f32; 3]>>,
    /// The pastes holding each face, in paste order.
    pub layers: Vec<Vec<FaceLayer>>,
    /// Subdivision level of each face's samples ([`sample_levels`]).
    pub levels: Vec<u16>,
}

#[inline]
fn at(uv: &[Vec2; 3], b: [f32; 3]) -> Vec2 {
    uv[0] * b[0] + uv[1] * b[1] + uv[2] * b[2]
}

/// Accumulated alpha `1 − Π (1 − α)` of `layers` at barycentric point `b`.
#[inline]
fn accumulated_alpha(layers: &[FaceLayer], textures: &[TexturePatch], b: [f32; 3]) -> f32 {
    let mut clear = 1.0f32;
    for l in layers {
        clear *= 1.0 - textures[l.texture as usize].alpha_at(at(&l.uv, b));
        if clear <= 0.0 {
            break;
        }
    }
    1.0 - clear
}

impl Coverage {
    /// Nothing covered yet; `levels` gives each face's sample level.
    pub fn new(levels: Vec<u16>) -> Self {
        let n = levels.len();
        Self {
            covered: vec![false; n],
            fraction: vec![0.0; n],
            uncovered_point: vec![None; n],
            layers: vec![Vec::new(); n],
            levels,
        }
    }

    /// Records paste `paste` (texture patch `texture`, its `faces` with
    /// per-corner texture coordinates `uvs`) and re-tests its faces.
    pub fn add_paste(
        &mut self,
        paste: u32,
        texture: u32,
        faces: &[u32],
        uvs: &[[Vec2; 3]],
        textures: &[TexturePatch],
        settings: &CoverageSettings,
    ) {
        let _span = tracing::trace_span!("coverage", faces = faces.len()).entered();
        for (slot, (&f, uv)) in faces.iter().zip(uvs).enumerate() {
            self.layers[f as usize].push(FaceLayer {
                paste,
                texture,
                slot: slot as u32,
                uv: *uv,
            });
        }
        let results: Vec<(f32, Option<[f32; 3]>)> = faces
            .par_iter()
            .map(|&f| {
                let layers = &self.layers[f as usize];
                let samples = lattice_samples(self.levels[f as usize]);
                let mut covered = 0usize;
                let mut worst: Option<(f32, [f32; 3])> = None;
                for b in &samples {
                    let a = accumulated_alpha(layers, textures, *b);
                    if a >= settings.opaque {
                        covered += 1;
                    } else if worst.is_none_or(|(w, _)| a < w) {
                        worst = Some((a, *b));
                    }
                }
                (covered as f32 / samples.len() as f32, worst.map(|w| w.1))
            })
            .collect();
        for (&f, (fraction, worst)) in faces.iter().zip(results) {
            let f = f as usize;
            self.fraction[f] = fraction;
            self.covered[f] = fraction >= settings.threshold || worst.is_none();
            self.uncovered_point[f] = worst;
        }
    }

    /// Mean number of pastes holding a face.
    pub fn mean_layers(&self) -> f64 {
        let total: usize = self.layers.iter().map(Vec::len).sum();
        total as f64 / self.layers.len().max(1) as f64
    }
}

/// For runtime pasting (§4): per paste, per face of it, whether the face
/// must be drawn. A face is dropped from a paste when, at every one of the
/// face's coverage samples, the paste is transparent or the later pastes
/// holding the face are together opaque.
pub fn drawn_faces(
    coverage: &Coverage,
    paste_sizes: &[usize],
    textures: &[TexturePatch],
    settings: &CoverageSettings,
) -> Vec<Vec<bool>> {
    let _span = tracing::debug_span!("cull_occluded_faces").entered();
    let per_face: Vec<Vec<bool>> = coverage
        .layers
        .par_iter()
        .zip(coverage.levels.par_iter())
        .map(|(layers, &level)| {
            let samples = lattice_samples(level);
            (0..layers.len())
                .map(|k| {
                    let own = &layers[k];
                    let tex = &textures[own.texture as usize];
                    let later = &layers[k + 1..];
                    samples.iter().any(|&b| {
                        tex.alpha_at(at(&own.uv, b)) > 1.0 - settings.opaque
                            && accumulated_alpha(later, textures, b) < settings.opaque
                    })
                })
                .collect()
        })
        .collect();
    let mut drawn: Vec<Vec<bool>> = paste_sizes.iter().map(|&n| vec![false; n]).collect();
    for (layers, flags) in coverage.layers.iter().zip(per_face) {
        for (l, d) in layers.iter().zip(flags) {
            drawn[l.paste as usize][l.slot as usize] = d;
        }
    }
    drawn
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lattice_samples_fill_the_face_evenly() {
        for k in [1u16, 2, 5, 17] {
            let s = lattice_samples(k);
            assert_eq!(s.len(), k as usize * k as usize);
            for b in &s {
                assert!(b.iter().all(|&v| v > 0.0) && (b.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            }
            // The mean is the centroid.
            let mean: f32 = s.iter().map(|b| b[1]).sum::<f32>() / s.len() as f32;
            assert!((mean - 1.0 / 3.0).abs() < 1e-5, "{k}: {mean}");
        }
        // A face of 100 square texture pixels gets level 10.
        let levels = sample_levels(&[4.0], &[Vec3::new(0.0, 2.0, 0.0)], 10.0, 64);
        assert_eq!(levels, vec![10]);
    }
}
