//! Stage `triplanar`: the artist's alternative to synthesis — an image
//! (default the exemplar; typically a tileable texture) projected along the
//! three world axes with normal-based blend weights (box mapping with
//! blended seams, [`crate::kernels::atlas::triplanar`]), at the run's
//! `texture_scale`. The projection is evaluated per texel by `bake`, like any
//! other result, so it is the peer of the surface benchmark at the same
//! texel density as every method.
//!
//! Reads: `Exemplar`, `TextureScale`. Writes: the `TriplanarProjection`
//! resource, `TexelSpacing` (one image pixel), metrics.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Settings of `triplanar`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TriplanarSettings {
    /// The image to project; empty = the exemplar.
    pub image: String,
    /// The blend exponent.
    pub sharpness: f64,
}

impl Default for TriplanarSettings {
    fn default() -> Self {
        Self {
            image: String::new(),
            sharpness: 4.0,
        }
    }
}

impl StageSettings for TriplanarSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "image",
            unit: "path",
            range: ParamRange::Any("an image file (PNG, JPEG, BMP, TGA), or empty"),
            doc: "the image projected along the three axes, repeated (so a tileable texture shows no seams within a projection); empty = the run's exemplar. It is drawn at the run's texture scale in its own pixels (`[input] texture_scale`: image pixels per world unit as for the exemplar). A relative path resolves against the config's folder",
        },
        ParamDoc {
            name: "sharpness",
            unit: "exponent",
            range: ParamRange::Float(1.0, 64.0),
            doc: "blend weights are |n_axis|^sharpness normalised to one: 1 blends broadly (wide, blurry seams between projections), higher narrows the seams (4 is the usual choice)",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if !self.image.is_empty() {
            crate::image::load_image(Path::new(&self.image))
                .map_err(|e| ("image".to_string(), e.to_string()))?;
        }
        Ok(())
    }
}

/// The `triplanar` stage.
pub struct Triplanar;

impl Stage for Triplanar {
    const KIND: &'static str = "triplanar";
    const SUMMARY: &'static str = "projects an image (default the exemplar) along the three world axes with normal-based blend weights, at the run's texture scale: the artist's baseline, baked like any result";
    const PAPER: &'static str =
        "- (triplanar / box mapping, the common practice without synthesis)";
    type Settings = TriplanarSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Triplanar]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        // The image is read when the schedule is built (systems do no file
        // I/O); it was already checked when the config was loaded.
        let image = (!settings.image.is_empty())
            .then(|| crate::image::load_image(Path::new(&settings.image)))
            .transpose()
            .map_err(|e| e.to_string());
        let project = move |mut commands: Commands,
                            exemplar: Res<Exemplar>,
                            texture_scale: Option<Res<TextureScale>>,
                            mut spacing: ResMut<TexelSpacing>,
                            mut metrics: ResMut<Metrics>|
              -> SystemResult {
            let image = match &image {
                Ok(Some(img)) => img.clone(),
                Ok(None) => exemplar.image.clone(),
                Err(e) => return Err(e.clone()),
            };
            let texels_per_unit = run_texels_per_unit(texture_scale.as_deref(), &spacing);
            // The result metrics resample the surface at one image pixel.
            spacing.0 = 1.0 / texels_per_unit.max(f32::MIN_POSITIVE);
            metrics.record(ctx.index, "texels_per_unit", texels_per_unit);
            metrics.record(ctx.index, "image_size", [image.width, image.height]);
            commands.insert_resource(TriplanarProjection {
                image,
                texels_per_unit,
                sharpness: settings.sharpness as f32,
            });
            Ok(())
        };
        ctx.fallible(Self::KIND, project)
    }
}
