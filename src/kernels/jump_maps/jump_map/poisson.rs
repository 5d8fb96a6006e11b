//! Poisson-disc filtering of jump candidates (Zelinka & Garland 2004, §4.4).
//!
//! Candidates arrive sorted by neighbourhood similarity, best first. They are
//! accepted greedily unless a disc of diameter `d` around them would overlap
//! the disc of the source pixel or of an already accepted candidate, that is
//! unless they lie closer than `d` to either. When fewer than `k` survive, `d`
//! is halved (never below `d_min`) and the filtering restarts.
//!
//! Guarantee after halving: every accepted jump lies at least the final `d`
//! (returned, and stored per pixel in the map) from its source pixel and from
//! every other accepted jump of that pixel, and the final `d >= d_min`. With
//! `d_min >= 1` a pixel never jumps to itself. If even `d_min` leaves fewer
//! than `k`, the pixel keeps those fewer jumps.

use super::{Boundary, TexelCoord};

/// Squared pixel distance between two exemplar pixels: Euclidean, or on the
/// torus of size `width × height` when toroidal.
#[inline]
pub fn pixel_dist2(
    a: TexelCoord,
    b: TexelCoord,
    width: u32,
    height: u32,
    boundary: Boundary,
) -> f32 {
    let mut dx = a.x.abs_diff(b.x);
    let mut dy = a.y.abs_diff(b.y);
    if boundary == Boundary::Toroidal {
        dx = dx.min(width - dx);
        dy = dy.min(height - dy);
    }
    (dx as f32) * (dx as f32) + (dy as f32) * (dy as f32)
}

/// Parameters of the filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PoissonDisc {
    /// Jumps wanted, `k`.
    pub k: usize,
    /// Initial disc diameter `d` in pixels.
    pub diameter: f32,
    /// Smallest diameter halving may reach, in pixels.
    pub min_diameter: f32,
    /// Exemplar width (for toroidal distances).
    pub width: u32,
    /// Exemplar height (for toroidal distances).
    pub height: u32,
    /// Whether distances wrap.
    pub boundary: Boundary,
}

impl PoissonDisc {
    /// Filters `candidates` (pixel, payload), best first, for source pixel
    /// `source`. Writes the indices into `candidates` of the accepted ones, in
    /// candidate order, into `accepted` (cleared) and returns the diameter
    /// they satisfy.
    pub fn filter<T>(
        &self,
        source: TexelCoord,
        candidates: &[(TexelCoord, T)],
        accepted: &mut Vec<usize>,
    ) -> f32 {
        let mut d = self.diameter.max(self.min_diameter);
        let mut best: Vec<usize> = Vec::new();
        let mut best_d = d;
        loop {
            accepted.clear();
            let d2 = d * d;
            for (i, (c, _)) in candidates.iter().enumerate() {
                if accepted.len() == self.k {
                    break;
                }
                let far = |p: TexelCoord| {
                    pixel_dist2(*c, p, self.width, self.height, self.boundary) >= d2
                };
                if far(source) && accepted.iter().all(|&a| far(candidates[a].0)) {
                    accepted.push(i);
                }
            }
            if accepted.len() > best.len() || best.is_empty() {
                best.clone_from(accepted);
                best_d = d;
            }
            if accepted.len() >= self.k || d <= self.min_diameter {
                break;
            }
            d = (d * 0.5).max(self.min_diameter);
        }
        accepted.clone_from(&best);
        best_d
    }
}
