//! Stage `jump_image`: jump-map synthesis of a planar image (Zelinka &
//! Garland 2004 §5 pixel-based, §7.1 patch-based, §7.2 controlled by
//! orientation and scale fields). Writes the image, the exact source
//! coordinate map (16-bit PNG: red = x, green = y, normalised), and a patch
//! visualisation (Fig. 5). Its quality is measured by `result_metrics`
//! with every other method's (the stage's own texture energy against a
//! shuffled exemplar, 0.12–0.16 s per 256² image, was dropped in stop 28:
//! a baseline nothing real fails, and it made the stage look 5× slower).
//!
//! Reads: `ExemplarJumpMap`, the exemplar. Writes: `SynthesisedImage`, and
//! the three images in `ExportJob`.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::jump_maps::jump_image::{
    PixelRefine, PlaneMethod, patches_image, synthesize_plane,
};
use crate::kernels::jump_maps::jump_map::refine::SEAM_REFINE_LEVELS;
use crate::kernels::jump_maps::jump_map::{
    ControlField, ControlledSynthesisSettings, PatchSeams, PatchSynthesisSettings, PixelChoice,
    PixelOrder, PixelSynthesisSettings,
};
use crate::progress::Progress;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use serde::{Deserialize, Serialize};

/// Settings of `jump_image`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct JumpImageSettings {
    /// Output width, pixels.
    pub width: u32,
    /// Output height, pixels.
    pub height: u32,
    /// `pixel` (§5), `patch` (§7.1) or `controlled` (§7.2).
    pub method: String,
    /// Pixel order of the pixel and controlled methods.
    pub order: String,
    /// Desired patch size of the pixel and controlled methods.
    pub patch_fraction: f32,
    /// Patch side of the patch method.
    pub patch_side: f32,
    /// How the patch method's patches meet: `cut` or `straight`.
    pub seams: String,
    /// How the pixel method picks a source: `matched` or `random`.
    pub choice: String,
    /// The pixel method's seam refinement: `aligned_seams`, `seams` or
    /// `none` (the paper).
    pub refine: String,
    /// Boundary-avoidance band.
    pub boundary_fraction: f32,
    /// Control field of the controlled method.
    pub field: String,
    /// Field parameters: scales at the two ends of the field.
    pub field_scale: [f32; 2],
    /// Rotation of the uniform field, degrees clockwise.
    pub field_angle: f32,
    /// Stem of the written files.
    pub name: String,
}

impl Default for JumpImageSettings {
    fn default() -> Self {
        Self {
            width: 256,
            height: 256,
            method: "pixel".into(),
            order: "hilbert".into(),
            patch_fraction: 0.5,
            patch_side: 0.3,
            seams: "cut".into(),
            choice: "matched".into(),
            refine: "aligned_seams".into(),
            boundary_fraction: 0.2,
            field: "perspective".into(),
            field_scale: [1.0, 0.25],
            field_angle: 0.0,
            name: "jump_image".into(),
        }
    }
}

impl StageSettings for JumpImageSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "width",
            unit: "pixels",
            range: ParamRange::Int(1, 32768),
            doc: "output width",
        },
        ParamDoc {
            name: "height",
            unit: "pixels",
            range: ParamRange::Int(1, 32768),
            doc: "output height",
        },
        ParamDoc {
            name: "method",
            unit: "",
            range: ParamRange::OneOf(&["pixel", "patch", "controlled"]),
            doc: "pixel: per-pixel copy/jump (§5); patch: patches chosen by the jump map (§7.1), quilted with minimum-error seams unless seams = \"straight\"; controlled: orientation and scale fields (§7.2)",
        },
        ParamDoc {
            name: "order",
            unit: "",
            range: ParamRange::OneOf(&["hilbert", "serpentine", "scanline"]),
            doc: "pixel order (§5.3); Hilbert gives the best patch shapes",
        },
        ParamDoc {
            name: "patch_fraction",
            unit: "fraction",
            range: ParamRange::Float(0.01, 16.0),
            doc: "pixel/controlled: desired patch size as a fraction of the exemplar side (§5.1; paper 1/3-3/4)",
        },
        ParamDoc {
            name: "patch_side",
            unit: "fraction",
            range: ParamRange::Float(0.01, 1.0),
            doc: "patch: patch side as a fraction of the exemplar side (§7.1; paper 1/5-1/2)",
        },
        ParamDoc {
            name: "seams",
            unit: "",
            range: ParamRange::OneOf(&["cut", "straight"]),
            doc: "patch: cut = patches overlap a sixth of their side, are chosen among the jump map's suggestions by their overlap error and meet along its minimum-error path (image quilting, an extension); straight = edge to edge as in §7.1",
        },
        ParamDoc {
            name: "choice",
            unit: "",
            range: ParamRange::OneOf(&["matched", "random"]),
            doc: "pixel: matched (default; an extension) = the paper's draw decides whether a pixel jumps; then the destination in any synthesised neighbour's jump list, or the neighbour continuation, whose 5x5 exemplar window best matches the synthesised pixels around wins (k-coherent candidates with the jump map as the similarity set; planar benchmark, seeds 1-3, with refine = seams: issue 13's failing cells 7 -> 3 of 15, brick meets the gate, planks p90 still 1.18-1.33x the peer's; aligned_seams meets it on planks too; the next best candidate is taken where the best would join copied regions into a copy of a third of the exemplar or add to one an exemplar pixel two such copies take already); random = a random neighbour and a jump by weight (§5.1, the paper)",
        },
        ParamDoc {
            name: "refine",
            unit: "",
            range: ParamRange::OneOf(&["aligned_seams", "seams", "none"]),
            doc: "pixel: aligned_seams (default) = an extension: seams between two alignments that move whole copied regions (4-connected pixels whose sources continue each other, at least 16) by up to 6 exemplar pixels per axis where that lowers the seam cost along their border (continuations 5 pixels deep; every shift screened 2 pixels deep, the 8 cheapest compared in full), at most 4 sweeps each, never joining regions into a copied region of a third of the exemplar or more nor moving a large one where two large ones copy the exemplar already (planar benchmark, seeds 1-3, ratio to the peer: planks p90 1.13-1.27 -> 0.86-0.97x, issue 13's gate met on all 15 cells; 0.08-0.10 s at 256x256, 25-31x faster than the peer); seams = an extension: after synthesis, 3 passes over the pixels next to a seam, each taking the continuation of one of its 8 neighbours whose 5x5 exemplar window best matches the output around it (texture optimisation restricted to coherent candidates; no move joins regions into a large copied region or adds a pixel to one where two large ones copy its source already), first on the source map and exemplar halved (windows then see twice the structure; a moved coarse pixel sets its 2x2 block to its donor's fine continuation), then at full size (0.03 s; planks p90 1.13-1.27x the peer's); none = the paper's result",
        },
        ParamDoc {
            name: "boundary_fraction",
            unit: "fraction",
            range: ParamRange::Float(0.0, 0.5),
            doc: "band near the exemplar border where jumps become likelier (§5.2; paper 1/5)",
        },
        ParamDoc {
            name: "field",
            unit: "",
            range: ParamRange::OneOf(&["perspective", "radial", "uniform"]),
            doc: "controlled: perspective scale ramp, radial orientation toward the centre, or uniform rotation/scale (Fig. 24)",
        },
        ParamDoc {
            name: "field_scale",
            unit: "exemplar pixels per output pixel",
            range: ParamRange::Float(0.01, 64.0),
            doc: "controlled: [bottom, top] for perspective, [edge, centre] for radial, [scale, ignored] for uniform",
        },
        ParamDoc {
            name: "field_angle",
            unit: "degrees",
            range: ParamRange::Float(-360.0, 360.0),
            doc: "controlled, uniform field: clockwise rotation of the texture",
        },
        ParamDoc {
            name: "name",
            unit: "",
            range: ParamRange::Any("a file name stem"),
            doc: "stem of the written files: NAME.png, NAME_sources.png, NAME_patches.png",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if self.name.is_empty() || self.name.contains(['/', '\\']) || self.name.starts_with('.') {
            return Err((
                "name".into(),
                format!("{:?} is not a plain file name stem", self.name),
            ));
        }
        Ok(())
    }
}

fn pixel_order(name: &str) -> PixelOrder {
    match name {
        "scanline" => PixelOrder::Scanline,
        "serpentine" => PixelOrder::Serpentine,
        _ => PixelOrder::Hilbert,
    }
}

impl JumpImageSettings {
    /// The synthesis method of these settings, seeded with `seed`.
    fn plane_method(&self, seed: u64) -> PlaneMethod {
        let (w, h) = (self.width, self.height);
        match self.method.as_str() {
            "patch" => PlaneMethod::Patches(PatchSynthesisSettings {
                width: w,
                height: h,
                patch_fraction: self.patch_side,
                seed,
                seams: if self.seams == "straight" {
                    PatchSeams::Straight
                } else {
                    PatchSeams::Cut
                },
            }),
            "controlled" => {
                let [a, b] = self.field_scale;
                let field = match self.field.as_str() {
                    "radial" => ControlField::radial(w, h, a, b),
                    "uniform" => ControlField::uniform(w, h, self.field_angle.to_radians(), a),
                    _ => ControlField::perspective(w, h, a, b),
                };
                let settings = ControlledSynthesisSettings {
                    order: pixel_order(&self.order),
                    patch_fraction: self.patch_fraction,
                    boundary_fraction: self.boundary_fraction,
                    seed,
                };
                PlaneMethod::Controlled(field, settings)
            }
            _ => {
                let settings = PixelSynthesisSettings {
                    width: w,
                    height: h,
                    order: pixel_order(&self.order),
                    patch_fraction: self.patch_fraction,
                    boundary_fraction: self.boundary_fraction,
                    seed,
                    choice: if self.choice == "matched" {
                        PixelChoice::Matched
                    } else {
                        PixelChoice::Random
                    },
                };
                let refine = match self.refine.as_str() {
                    "aligned_seams" => PixelRefine::AlignedSeams,
                    "seams" => PixelRefine::Seams,
                    _ => PixelRefine::None,
                };
                PlaneMethod::Pixels(settings, refine)
            }
        }
    }
}

/// Bytes per output pixel at the stage's peak, measured with a counting
/// allocator (`tests/memory_estimates.rs`; 56-60 by method at 1024²): the
/// RGB result (12), its source texels (8) and coordinates (8), the
/// resource's copy (12), the source and patch images (12 each) and the
/// kernels' buffers.
pub const BYTES_PER_PIXEL: u64 = 60;

/// The `jump_image` stage.
pub struct JumpImage;

impl Stage for JumpImage {
    const KIND: &'static str = "jump_image";
    const SUMMARY: &'static str =
        "jump-map synthesis of a planar image: pixel-based, patch-based or controlled";
    const PAPER: &'static str = "Zelinka & Garland 2004 §5, §7.1, §7.2";
    type Settings = JumpImageSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::JumpMap]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Image]
    }
    /// The output (`width x height`): the image, its source map, the
    /// written copies and the kernels' buffers.
    fn memory_estimate(settings: &Self::Settings, _sizes: &InputSizes) -> Vec<MemoryEstimate> {
        vec![MemoryEstimate::image(
            "width x height",
            "the synthesised image, its source coordinates, the images written and the synthesis buffers",
            (settings.width, settings.height),
            32768,
            |w, h| (w * h).saturating_mul(BYTES_PER_PIXEL),
        )]
    }
    fn plane_role(settings: &Self::Settings) -> crate::stage::PlaneRole {
        crate::stage::PlaneRole::Image {
            width: settings.width,
            height: settings.height,
        }
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let synthesize = move |mut commands: Commands,
                               exemplar: Res<Exemplar>,
                               map: Res<ExemplarJumpMap>,
                               seed: Res<RunSeed>,
                               mut job: ResMut<ExportJob>,
                               mut metrics: ResMut<Metrics>|
              -> SystemResult {
            let started = std::time::Instant::now();
            // The kernels set the length: pixels, or patches.
            let progress = Progress::new(0, Self::KIND);
            let _finish = progress.finish_on_drop();
            let method = settings.plane_method(seed.derive(ctx.index, 0));
            let result = synthesize_plane(&exemplar.image, &map.0, &method, &progress);
            progress.finish();
            let out = result.map_err(|e| e.to_string())?;
            let secs = started.elapsed().as_secs_f64();
            if let Some(r) = &out.refined {
                metrics.record(ctx.index, "refine_visited", &r.visited);
                metrics.record(ctx.index, "refine_moved", &r.moved);
                metrics.record(ctx.index, "refine_levels", SEAM_REFINE_LEVELS);
            }
            if !out.aligned.is_empty() {
                metrics.record(ctx.index, "align", &out.aligned);
            }
            let px = out.image.pixel_count() as f64;
            metrics.record(ctx.index, "pixels", px);
            metrics.record(ctx.index, "pixels_per_second", px / secs.max(1e-9));
            commands.insert_resource(SynthesisedImage {
                image: out.image.clone(),
                sources: out.sources,
            });
            let name = &settings.name;
            let patches = patches_image(&out.source_image);
            job.images
                .push((format!("{name}_sources.png"), out.source_image));
            job.images.push((format!("{name}_patches.png"), patches));
            job.images.push((format!("{name}.png"), out.image));
            Ok(())
        };
        ctx.fallible(Self::KIND, synthesize)
    }
}
