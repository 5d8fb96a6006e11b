//! Stage `jump_map`: analysis of the exemplar into a jump map (Zelinka &
//! Garland 2004 §4), cached on disk keyed by a hash of the exemplar pixels and
//! every analysis parameter. A cached file is re-validated (magic, version,
//! key, checksum) and rebuilt when stale or corrupt, never trusted.
//!
//! Reads: the exemplar; the analysis cache (`cache = true`). Writes:
//! `ExemplarJumpMap`.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::image::sample::Wrap;
use crate::kernels::jump_maps::jump_map::analysis::analysis_bytes;
use crate::kernels::jump_maps::jump_map::neighbourhoods::source_region;
use crate::kernels::jump_maps::jump_map::{
    Boundary, JumpMap, JumpMapError, JumpMapSettings, analysis::analyse_with_progress, map,
};
use crate::progress::Progress;
use crate::stage::memory::{Fit, InputSizes, MemoryEstimate};
use crate::stage::{Datum, InputView, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Settings of `jump_map`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct JumpMapStageSettings {
    /// Neighbourhood widths, finest level first.
    pub neighbourhoods: Vec<u32>,
    /// `auto` (from `input.exemplar_wrap`), `toroidal` or `inset`.
    pub boundary: String,
    /// Fraction of neighbourhoods sampled for PCA.
    pub pca_sample: f32,
    /// Fraction of variance the kept components explain.
    pub pca_variance: f32,
    /// Upper bound on kept components.
    pub max_components: u32,
    /// Approximate-nearest-neighbour error tolerance.
    pub ann_epsilon: f32,
    /// Nearest-neighbour search: `auto`, `kd_tree` or `exhaustive`.
    pub ann_search: String,
    /// Jumps kept per pixel (k).
    pub jumps: u32,
    /// Candidates per kept jump (s).
    pub candidates: u32,
    /// Normalisation exponent α (§4.5).
    pub alpha: f32,
    /// Read and write the on-disk cache.
    pub cache: bool,
}

impl Default for JumpMapStageSettings {
    fn default() -> Self {
        let d = JumpMapSettings::default();
        Self {
            neighbourhoods: d.neighbourhood_widths,
            boundary: "auto".into(),
            pca_sample: d.pca_sample_fraction,
            pca_variance: d.pca_variance,
            max_components: d.max_components,
            ann_epsilon: d.ann_epsilon,
            ann_search: "auto".into(),
            jumps: d.jumps_per_pixel,
            candidates: d.candidate_factor,
            alpha: d.alpha,
            cache: true,
        }
    }
}

impl StageSettings for JumpMapStageSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "neighbourhoods",
            unit: "pixels",
            range: ParamRange::OddInt(1, 31),
            doc: "neighbourhood width per Gaussian-pyramid level, finest first (§4.3; paper 9, 5, 3); each level weighted to contribute equally",
        },
        ParamDoc {
            name: "boundary",
            unit: "",
            range: ParamRange::OneOf(&["auto", "toroidal", "inset"]),
            doc: "toroidal neighbourhoods for tileable exemplars, inset otherwise; auto follows input.exemplar_wrap",
        },
        ParamDoc {
            name: "pca_sample",
            unit: "fraction",
            range: ParamRange::Float(0.001, 1.0),
            doc: "random fraction of neighbourhoods the PCA basis is computed from (§4.2; paper 10%)",
        },
        ParamDoc {
            name: "pca_variance",
            unit: "fraction",
            range: ParamRange::Float(0.01, 1.0),
            doc: "variance the kept principal components explain (§4.2; paper 97%)",
        },
        ParamDoc {
            name: "max_components",
            unit: "",
            range: ParamRange::Int(1, 256),
            doc: "upper bound on kept principal components",
        },
        ParamDoc {
            name: "ann_epsilon",
            unit: "fraction",
            range: ParamRange::Float(0.0, 10.0),
            doc: "relative error tolerance of the approximate nearest-neighbour search (paper 10%)",
        },
        ParamDoc {
            name: "ann_search",
            unit: "",
            range: ParamRange::OneOf(&["auto", "kd_tree", "exhaustive"]),
            doc: "kd_tree: (1+ε)-approximate search over a kd-tree of the leading PCA components, refined on all; exhaustive: exact blocked brute force; auto: the kd-tree only where it was measured faster (≤ 8 components and ≥ 32768 pixels)",
        },
        ParamDoc {
            name: "jumps",
            unit: "per pixel",
            range: ParamRange::Int(1, 16),
            doc: "jumps kept per pixel, k (§4.4; paper 2-4)",
        },
        ParamDoc {
            name: "candidates",
            unit: "per jump",
            range: ParamRange::Int(1, 64),
            doc: "candidate factor s: k·s nearest neighbours are Poisson-disc filtered down to k (§4.4; paper 5-10)",
        },
        ParamDoc {
            name: "alpha",
            unit: "",
            range: ParamRange::Float(0.0, 1.0),
            doc: "normalisation exponent α of §4.5",
        },
        ParamDoc {
            name: "cache",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "read and write the jump-map cache ($SURFSYNTH_CACHE, else $XDG_CACHE_HOME/surfsynth, else ~/.cache/surfsynth)",
        },
    ];

    /// What the analysis checks of its settings, at validation and under
    /// this stage's parameter names (an empty `neighbourhoods` was refused
    /// only once the stage ran, as the kernel's `neighbourhood_widths`).
    fn check(&self) -> Result<(), (String, String)> {
        let Err(JumpMapError::InvalidSetting {
            name,
            value,
            expected,
        }) = self.kernel_settings(Wrap::Clamp, 0).validate()
        else {
            return Ok(());
        };
        let param = match name {
            "neighbourhood_widths" => "neighbourhoods",
            "pca_sample_fraction" => "pca_sample",
            "jumps_per_pixel" => "jumps",
            "candidate_factor" => "candidates",
            other => other,
        };
        Err((
            param.to_string(),
            format!("{value} is not allowed; allowed: {expected}"),
        ))
    }
}

impl JumpMapStageSettings {
    /// The kernel settings for an exemplar addressed with `wrap`.
    pub fn kernel_settings(&self, wrap: Wrap, seed: u64) -> JumpMapSettings {
        let boundary = match self.boundary.as_str() {
            "toroidal" => Boundary::Toroidal,
            "inset" => Boundary::Inset,
            _ if wrap == Wrap::Repeat => Boundary::Toroidal,
            _ => Boundary::Inset,
        };
        JumpMapSettings {
            neighbourhood_widths: self.neighbourhoods.clone(),
            boundary,
            pca_sample_fraction: self.pca_sample,
            pca_variance: self.pca_variance,
            max_components: self.max_components,
            ann_epsilon: self.ann_epsilon,
            ann_search: match self.ann_search.as_str() {
                "kd_tree" => crate::kernels::jump_maps::jump_map::AnnSearch::KdTree,
                "exhaustive" => crate::kernels::jump_maps::jump_map::AnnSearch::Exhaustive,
                _ => crate::kernels::jump_maps::jump_map::AnnSearch::Auto,
            },
            jumps_per_pixel: self.jumps,
            candidate_factor: self.candidates,
            alpha: self.alpha,
            seed,
            ..JumpMapSettings::default()
        }
    }
}

/// Loads the jump map from the cache or analyses the exemplar (and caches it).
/// Returns the map and whether it came from the cache.
pub fn load_or_analyse(
    exemplar: &crate::image::Image,
    settings: &JumpMapSettings,
    cache: bool,
) -> Result<
    (
        JumpMap,
        bool,
        Option<crate::kernels::jump_maps::jump_map::analysis::AnalysisStats>,
    ),
    String,
> {
    let key = settings.cache_key(exemplar);
    let dir = if cache {
        crate::cache::default_dir()
    } else {
        None
    };
    if let Some(bytes) = dir
        .as_ref()
        .and_then(|dir| crate::cache::read(dir, "jumpmap", &key))
    {
        match JumpMap::from_bytes(&bytes, &key) {
            Ok(map) => return Ok((map, true, None)),
            Err(e) => tracing::warn!("jump-map cache entry rejected ({e}); rebuilding"),
        }
    }
    let progress = Progress::new(0, JumpMapStage::KIND);
    let _finish = progress.finish_on_drop();
    let analysed = analyse_with_progress(exemplar, settings, &progress);
    progress.finish();
    let (map, stats) = analysed.map_err(|e| e.to_string())?;
    if let Some(dir) = &dir {
        crate::cache::write(dir, "jumpmap", &key, &map.to_bytes());
    }
    Ok((map, false, Some(stats)))
}

/// The `jump_map` stage.
pub struct JumpMapStage;

/// How the exemplar of `sizes` is addressed.
fn wrap_of(sizes: &InputSizes) -> Wrap {
    if sizes.exemplar_repeats {
        Wrap::Repeat
    } else {
        Wrap::Clamp
    }
}

impl Stage for JumpMapStage {
    const KIND: &'static str = "jump_map";
    const SUMMARY: &'static str =
        "analyses the exemplar into a jump map (PCA, ANN, Poisson-disc filtering), cached on disk";
    const PAPER: &'static str = "Zelinka & Garland 2004 §4";
    type Settings = JumpMapStageSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::JumpMap]
    }
    /// The analysis (`analysis_bytes`): estimated whether or not the map is
    /// cached (a cache hit needs far less). Ways out: narrower
    /// neighbourhoods (every level capped at one width), a smaller PCA
    /// sample, fewer principal components (at most 8 also lets the search
    /// use the kd-tree), a smaller exemplar.
    fn memory_estimate(settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        if sizes.exemplar_pixels() == 0 {
            return Vec::new();
        }
        let ks = settings.kernel_settings(wrap_of(sizes), 0);
        let (w, h, c) = (
            sizes.exemplar_width,
            sizes.exemplar_height,
            sizes.exemplar_channels,
        );
        let widths = ks.neighbourhood_widths.clone();
        let capped =
            move |cap: u64| -> Vec<u32> { widths.iter().map(|&n| n.min(cap as u32)).collect() };
        let show = {
            let capped = capped.clone();
            move |cap: u64| format!("{:?}", capped(cap))
        };
        let with_cap = {
            let ks = ks.clone();
            move |cap: u64| {
                let mut s = ks.clone();
                s.neighbourhood_widths = capped(cap);
                analysis_bytes(w, h, c, &s)
            }
        };
        let widest = u64::from(ks.neighbourhood_widths.iter().copied().max().unwrap_or(1));
        let bytes = analysis_bytes(w, h, c, &ks);
        let sample = {
            let ks = ks.clone();
            move |thousandths: u64| {
                let mut s = ks.clone();
                s.pca_sample_fraction = thousandths as f32 / 1000.0;
                analysis_bytes(w, h, c, &s)
            }
        };
        let now_sample = (f64::from(ks.pca_sample_fraction) * 1000.0).floor() as u64;
        let exemplar = {
            let ks = ks.clone();
            move |side: u64| {
                let long = u64::from(w.max(h));
                let scale = |d: u32| ((u64::from(d) * side).div_ceil(long)).max(1) as u32;
                analysis_bytes(scale(w), scale(h), c, &ks)
            }
        };
        let long = u64::from(w.max(h));
        let show_exemplar = move |side: u64| {
            let scale = |d: u32| ((u64::from(d) * side).div_ceil(long)).max(1);
            format!("{}x{} pixels", scale(w), scale(h))
        };
        let components = {
            let ks = ks.clone();
            move |m: u64| {
                let mut s = ks.clone();
                s.max_components = m as u32;
                analysis_bytes(w, h, c, &s)
            }
        };
        let now_components = u64::from(ks.max_components);
        vec![MemoryEstimate {
            param: "neighbourhoods",
            value: format!("{:?}", ks.neighbourhood_widths),
            what: format!(
                "the jump-map analysis of the {w}x{h} exemplar: the PCA sample and its SVD, the projected neighbourhoods, the nearest neighbours and the map"
            ),
            bytes,
            fits: vec![
                Fit::scan(
                    "neighbourhoods",
                    (1..=widest).step_by(2).collect(),
                    with_cap,
                    show,
                ),
                Fit::growing("pca_sample", (1, now_sample.max(1)), sample, |t| {
                    format!("{}", t as f64 / 1000.0)
                }),
                Fit::growing("max_components", (1, now_components), components, |m| {
                    m.to_string()
                }),
                Fit::growing("an exemplar of", (1, long), exemplar, show_exemplar).separated(" "),
            ],
        }]
    }
    /// An inset analysis needs the exemplar to leave its neighbourhoods a
    /// source region: refused before any stage, naming the exemplar and
    /// the smallest size allowed.
    fn check_input(settings: &Self::Settings, input: &InputView) -> Result<(), String> {
        let s = input.sizes;
        if s.exemplar_pixels() == 0 {
            return Ok(());
        }
        let ks = settings.kernel_settings(wrap_of(s), 0);
        source_region(
            s.exemplar_width,
            s.exemplar_height,
            &ks.neighbourhood_widths,
            ks.boundary,
        )
        .map(|_| ())
        .map_err(|e| {
            format!(
                "`neighbourhoods` = {:?} (inset: `boundary` = {:?}, input.exemplar_wrap = {:?}) on the exemplar {}: {e}",
                settings.neighbourhoods,
                settings.boundary,
                if s.exemplar_repeats { "repeat" } else { "clamp" },
                input.exemplar
            )
        })
    }
    /// A jump map in the analysis cache for this exemplar and these
    /// settings is read, not analysed: the analysis estimate does not
    /// apply (issue 43). Only the entry's header is checked here; an entry
    /// that then fails its checksum is analysed after all.
    fn analysis_cached(
        settings: &Self::Settings,
        exemplar: &crate::image::Image,
        wrap: Wrap,
        seed: u64,
        ctx: StageCtx,
    ) -> bool {
        if !settings.cache {
            return false;
        }
        let Some(dir) = crate::cache::default_dir() else {
            return false;
        };
        let ks = settings.kernel_settings(wrap, RunSeed(seed).derive(ctx.index, 0));
        let key = ks.cache_key(exemplar);
        let header = crate::cache_format::entry_header(&map::MAGIC, map::FORMAT_VERSION, &key);
        crate::cache::holds(&dir, "jumpmap", &key, &header)
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let analyse = move |mut commands: Commands,
                            exemplar: Res<Exemplar>,
                            seed: Res<RunSeed>,
                            mut metrics: ResMut<Metrics>|
              -> SystemResult {
            let ks = settings.kernel_settings(exemplar.wrap, seed.derive(ctx.index, 0));
            let started = std::time::Instant::now();
            let (map, cached, stats) = load_or_analyse(&exemplar.image, &ks, settings.cache)?;
            let secs = started.elapsed().as_secs_f64();
            metrics.record(ctx.index, "cache_hit", cached);
            metrics.record(ctx.index, "seconds", secs);
            metrics.record(
                ctx.index,
                "boundary",
                format!("{:?}", map.boundary()).to_lowercase(),
            );
            if let Some(s) = stats {
                metrics.record(ctx.index, "pca_components", s.components);
                metrics.record(ctx.index, "explained_variance", s.explained_variance);
                metrics.record(ctx.index, "mean_jumps", s.mean_jumps);
                metrics.record(ctx.index, "full_fraction", s.full_fraction);
            }
            tracing::info!(
                "jump map {}x{} {} in {secs:.3} s",
                map.width(),
                map.height(),
                if cached {
                    "loaded from cache"
                } else {
                    "analysed"
                }
            );
            commands.insert_resource(ExemplarJumpMap(Arc::new(map)));
            Ok(())
        };
        ctx.fallible(Self::KIND, analyse)
    }
}
