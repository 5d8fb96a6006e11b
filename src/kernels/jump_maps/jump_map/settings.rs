//! Jump map analysis settings (Zelinka & Garland 2004, §4) and the cache key.

use super::JumpMapError;
use super::ann::AnnSearch;
use crate::image::Image;

/// Version of the analysis algorithm and of the byte format; part of the cache
/// key, so a change to either invalidates old caches.
pub const ANALYSIS_VERSION: u32 = 1;

/// How neighbourhoods are formed at the exemplar border (§4.2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Boundary {
    /// The exemplar tiles seamlessly: neighbourhoods wrap around the border,
    /// every pixel gets a jump list and synthesis addresses wrap.
    Toroidal,
    /// The exemplar does not tile: only pixels whose whole multi-resolution
    /// neighbourhood lies inside the exemplar get jump lists, and synthesis
    /// stays inside that inset region. The safe choice for an arbitrary photo.
    #[default]
    Inset,
}

/// Parameters of jump map analysis (§4). Defaults follow the paper.
#[derive(Clone, Debug, PartialEq)]
pub struct JumpMapSettings {
    /// Neighbourhood width per pyramid level, finest first (§4.3). Level `l`
    /// is read from Gaussian pyramid level `l` (half the resolution per level).
    /// Unit: pixels of that level. Default `[9, 5, 3]`. Range: 1 to 6 levels,
    /// each width odd and in `1..=31`.
    pub neighbourhood_widths: Vec<u32>,
    /// Border handling (§4.2). Default [`Boundary::Inset`].
    pub boundary: Boundary,
    /// Fraction of all neighbourhoods sampled (without replacement) to compute
    /// the principal components (§4.2). Default 0.1. Range `(0, 1]`. At least
    /// `min(256, pixel count)` neighbourhoods are sampled whatever the fraction.
    pub pca_sample_fraction: f32,
    /// Fraction of the sample's variance the kept principal components must
    /// explain (§4.2). Default 0.97. Range `(0, 1]`.
    pub pca_variance: f32,
    /// Upper bound on the number of principal components kept. Default 64.
    /// Range `1..=256`.
    pub max_components: u32,
    /// Approximate nearest-neighbour error tolerance ε (§4.2, after Mount's
    /// ANN): every returned candidate's PCA-space distance is at most `1 + ε`
    /// times that of the true neighbour of the same rank. Unit: fraction.
    /// Default 0.1 (the paper's "10%"). Range `[0, 10]`; 0 is exact search.
    pub ann_epsilon: f32,
    /// Nearest-neighbour search (see [`super::ann`]). Default
    /// [`AnnSearch::Auto`]: the kd-tree for exemplars of at least 32768
    /// source pixels with at most 8 components, exhaustive (exact) search
    /// otherwise, where it is faster.
    pub ann_search: AnnSearch,
    /// Jumps kept per pixel, `k` (§4.4). Default 3. Range `1..=16`.
    pub jumps_per_pixel: u32,
    /// Candidate factor `s`: `k·s` nearest neighbours are gathered before
    /// Poisson-disc filtering (§4.4). Default 8 (paper: 5 to 10). Range `1..=64`.
    pub candidate_factor: u32,
    /// Poisson-disc diameter `d` (§4.4). Unit: exemplar pixels. `None` (the
    /// default) uses the finest neighbourhood width, as the paper does.
    /// Range `[min_disc_diameter, 4096]`.
    pub disc_diameter: Option<f32>,
    /// Smallest diameter the disc may be halved to when fewer than `k`
    /// candidates survive (§4.4). This is the guarantee that always holds:
    /// no jump ends closer than this to its own pixel or to another jump of the
    /// same pixel. Unit: exemplar pixels. Default 2.0 (so the pixel and its 8
    /// immediate neighbours are never jump destinations). Range `[1, 4096]`.
    pub min_disc_diameter: f32,
    /// α of the global normalisation (§4.5): the pixel with the worst jumps
    /// gets total jump weight α, the best gets 1. Default 0.5. Range `[0, 1]`.
    pub alpha: f32,
    /// Seed of the random PCA sample, the only randomness of the analysis
    /// (the per-pixel work is deterministic). Default 0. Any value.
    pub seed: u64,
}

impl Default for JumpMapSettings {
    fn default() -> Self {
        Self {
            neighbourhood_widths: vec![9, 5, 3],
            boundary: Boundary::Inset,
            pca_sample_fraction: 0.1,
            pca_variance: 0.97,
            max_components: 64,
            ann_epsilon: 0.1,
            ann_search: AnnSearch::Auto,
            jumps_per_pixel: 3,
            candidate_factor: 8,
            disc_diameter: None,
            min_disc_diameter: 2.0,
            alpha: 0.5,
            seed: 0,
        }
    }
}

fn invalid(
    name: &'static str,
    value: impl std::fmt::Debug,
    expected: &'static str,
) -> JumpMapError {
    JumpMapError::InvalidSetting {
        name,
        value: format!("{value:?}"),
        expected,
    }
}

fn in_range(v: f32, lo: f32, hi: f32) -> bool {
    v.is_finite() && v >= lo && v <= hi
}

impl JumpMapSettings {
    /// Checks every parameter against its documented range.
    ///
    /// # Errors
    /// [`JumpMapError::InvalidSetting`] naming the first bad parameter.
    pub fn validate(&self) -> Result<(), JumpMapError> {
        let w = &self.neighbourhood_widths;
        if w.is_empty() || w.len() > 6 || w.iter().any(|&n| n % 2 == 0 || !(1..=31).contains(&n)) {
            return Err(invalid(
                "neighbourhood_widths",
                w,
                "1 to 6 odd widths, each in 1..=31",
            ));
        }
        let f = self.pca_sample_fraction;
        if !(f.is_finite() && f > 0.0 && f <= 1.0) {
            return Err(invalid("pca_sample_fraction", f, "a fraction in (0, 1]"));
        }
        let v = self.pca_variance;
        if !(v.is_finite() && v > 0.0 && v <= 1.0) {
            return Err(invalid("pca_variance", v, "a fraction in (0, 1]"));
        }
        if !(1..=256).contains(&self.max_components) {
            return Err(invalid("max_components", self.max_components, "1..=256"));
        }
        if !in_range(self.ann_epsilon, 0.0, 10.0) {
            return Err(invalid("ann_epsilon", self.ann_epsilon, "[0, 10]"));
        }
        if !(1..=16).contains(&self.jumps_per_pixel) {
            return Err(invalid("jumps_per_pixel", self.jumps_per_pixel, "1..=16"));
        }
        if !(1..=64).contains(&self.candidate_factor) {
            return Err(invalid("candidate_factor", self.candidate_factor, "1..=64"));
        }
        if !in_range(self.min_disc_diameter, 1.0, 4096.0) {
            return Err(invalid(
                "min_disc_diameter",
                self.min_disc_diameter,
                "[1, 4096] pixels",
            ));
        }
        if let Some(d) = self.disc_diameter
            && !in_range(d, self.min_disc_diameter, 4096.0)
        {
            return Err(invalid(
                "disc_diameter",
                d,
                "[min_disc_diameter, 4096] pixels",
            ));
        }
        if !in_range(self.alpha, 0.0, 1.0) {
            return Err(invalid("alpha", self.alpha, "[0, 1]"));
        }
        Ok(())
    }

    /// The Poisson-disc diameter actually used: [`Self::disc_diameter`] or the
    /// finest neighbourhood width, never below [`Self::min_disc_diameter`].
    pub fn effective_disc_diameter(&self) -> f32 {
        let d = self
            .disc_diameter
            .unwrap_or(self.neighbourhood_widths.first().copied().unwrap_or(1) as f32);
        d.max(self.min_disc_diameter)
    }

    /// A key identifying the jump map of `exemplar` under these settings:
    /// blake3 over the algorithm version, the exemplar's size, channel count
    /// and pixel bits, and every parameter. Equal keys mean an equal map.
    pub fn cache_key(&self, exemplar: &Image) -> [u8; 32] {
        let mut h =
            crate::cache_format::key_hasher(b"surfsynth jump map", ANALYSIS_VERSION, exemplar);
        h.update(&(self.neighbourhood_widths.len() as u32).to_le_bytes());
        for w in &self.neighbourhood_widths {
            h.update(&w.to_le_bytes());
        }
        h.update(&[match self.boundary {
            Boundary::Toroidal => 0,
            Boundary::Inset => 1,
        }]);
        h.update(&self.pca_sample_fraction.to_bits().to_le_bytes());
        h.update(&self.pca_variance.to_bits().to_le_bytes());
        h.update(&self.max_components.to_le_bytes());
        h.update(&self.ann_epsilon.to_bits().to_le_bytes());
        h.update(&[match self.ann_search {
            AnnSearch::Auto => 0,
            AnnSearch::KdTree => 1,
            AnnSearch::Exhaustive => 2,
        }]);
        h.update(&self.jumps_per_pixel.to_le_bytes());
        h.update(&self.candidate_factor.to_le_bytes());
        match self.disc_diameter {
            None => h.update(&[0]),
            Some(d) => h.update(&[1]).update(&d.to_bits().to_le_bytes()),
        };
        h.update(&self.min_disc_diameter.to_bits().to_le_bytes());
        h.update(&self.alpha.to_bits().to_le_bytes());
        h.update(&self.seed.to_le_bytes());
        *h.finalize().as_bytes()
    }
}
