//! Quality metrics of a synthesised texture against its exemplar.
//!
//! - [`image_texture_energy`] and [`surface_texture_energy`]: the texture
//!   energy of Kwatra et al. 2005 ("Texture Optimization for Example-based
//!   Synthesis", §3, eq. 1): for sampled output neighbourhoods, the squared
//!   distance to the nearest exemplar neighbourhood. Low when every local
//!   window of the output looks like some window of the exemplar.
//! - [`histogram_wasserstein`]: per-channel 1-D Wasserstein-1 distance of the
//!   value distributions, which catches colour drift the energy forgives.
//! - [`quality`]: completeness (missing content), sharpness (blur), structure
//!   (orientation/scale energy), verbatim copying (tiling, repeats), and
//!   [`image_quality`], all of them for one result image.
//! - [`result`]: a run's result on its surface as the result metrics
//!   measure it (energy and surface measures in one pass, histogram
//!   samples).

pub mod energy;
mod histogram;
mod nearest;
pub mod quality;
pub mod result;
pub mod surface_quality;
pub mod window_index;

pub use crate::kernels::surface::surface_sample::SurfaceSignal;
pub use energy::{image_texture_energy, surface_texture_energy};
pub use histogram::{histogram_wasserstein, histogram_wasserstein_mean};
pub use nearest::{ExemplarNeighbourhoods, QueryScratch};
pub use quality::{
    ImageQuality, SourceMap, VerbatimStats, completeness, image_quality, sharpness,
    structure_distance, verbatim_copying,
};

/// Settings of the texture energy (the `[metrics]` options of a config).
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EnergySettings {
    /// Side of the square neighbourhood in pixels (or template points on a
    /// surface); odd, 1..=31, default 7.
    pub neighbourhood: u32,
    /// Number of sampled output locations (pixels or vertices); when at least
    /// the number of locations, every location is used once. 1..=10⁷, default 1000.
    pub samples: usize,
    /// Seed of the sampled locations; any value, default 0.
    pub seed: u64,
    /// Surface energy only: the smallest fraction of a template that faces must
    /// cover (near boundaries and holes) for the vertex to count; in `(0, 1]`,
    /// default 0.5.
    pub min_coverage: f32,
}

impl Default for EnergySettings {
    fn default() -> Self {
        Self {
            neighbourhood: 7,
            samples: 1000,
            seed: 0,
            min_coverage: 0.5,
        }
    }
}

impl EnergySettings {
    /// Checks the ranges documented on the fields.
    pub fn validate(&self) -> Result<(), MetricsError> {
        let bad = |name: &'static str, value: String, allowed: &'static str| {
            Err(MetricsError::Setting {
                name,
                value,
                allowed,
            })
        };
        if self.neighbourhood.is_multiple_of(2) || !(1..=31).contains(&self.neighbourhood) {
            return bad(
                "neighbourhood",
                self.neighbourhood.to_string(),
                "an odd number in 1..=31",
            );
        }
        if !(1..=10_000_000).contains(&self.samples) {
            return bad("samples", self.samples.to_string(), "1..=10000000");
        }
        if !(self.min_coverage > 0.0 && self.min_coverage <= 1.0) {
            return bad("min_coverage", self.min_coverage.to_string(), "(0, 1]");
        }
        Ok(())
    }
}

/// A setting of the metrics is out of range.
#[derive(Debug, thiserror::Error)]
pub enum MetricsError {
    /// The named setting has a value outside its allowed range.
    #[error("metrics setting {name} = {value} is out of range; allowed: {allowed}")]
    Setting {
        name: &'static str,
        value: String,
        allowed: &'static str,
    },
}

/// Summary of a texture energy over the sampled locations.
///
/// Each sample's value is the squared L2 distance to the nearest exemplar
/// neighbourhood divided by the number of values compared (pixels ×
/// channels), i.e. a mean squared error per value, for values in `[0, 1]`.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct EnergyStats {
    /// Mean over the samples; NaN when there are none.
    pub mean: f32,
    /// 90th percentile (nearest rank) over the samples; NaN when there are none.
    pub p90: f32,
    /// Number of samples that contributed.
    pub samples: usize,
}

impl EnergyStats {
    /// Statistics of per-sample values, in a fixed order so the result does
    /// not depend on how they were computed.
    pub fn from_values(values: &[f32]) -> Self {
        if values.is_empty() {
            return Self {
                mean: f32::NAN,
                p90: f32::NAN,
                samples: 0,
            };
        }
        let mean = values.iter().map(|&v| v as f64).sum::<f64>() / values.len() as f64;
        let mut sorted = values.to_vec();
        sorted.sort_unstable_by(f32::total_cmp);
        let rank = (0.9 * sorted.len() as f64).ceil() as usize;
        Self {
            mean: mean as f32,
            p90: sorted[rank.clamp(1, sorted.len()) - 1],
            samples: values.len(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stats_of_values() {
        let v: Vec<f32> = (1..=10).map(|i| i as f32).collect();
        let s = EnergyStats::from_values(&v);
        assert_eq!((s.mean, s.p90, s.samples), (5.5, 9.0, 10));
        assert!(EnergyStats::from_values(&[]).mean.is_nan());
    }

    #[test]
    fn settings_validate_and_deserialize() {
        assert!(EnergySettings::default().validate().is_ok());
        let e = EnergySettings {
            neighbourhood: 6,
            ..Default::default()
        }
        .validate()
        .unwrap_err()
        .to_string();
        assert!(e.contains("neighbourhood") && e.contains("odd"), "{e}");
        let s: EnergySettings = toml::from_str("samples = 50").unwrap();
        assert_eq!(s.samples, 50);
        assert_eq!(s.neighbourhood, 7);
        assert!(toml::from_str::<EnergySettings>("size = 5").is_err());
    }
}
