//! Planar jump-map synthesis as the `jump_image` stage runs it (Zelinka &
//! Garland 2004 §5 pixel-based, §7.1 patch-based, §7.2 controlled): one of
//! the three methods, the pixel method's seam refinement and region
//! alignment (extensions, [`PixelRefine`]), and the images shown beside the
//! result: the source-coordinate map and the patch visualisation (Fig. 5).

use crate::image::Image;
use crate::kernels::jump_maps::jump_map::refine::{
    ALIGN_SWEEPS, AlignReport, SEAM_REFINE_LEVELS, SEAM_REFINE_PASSES, SEAM_REFINE_RADIUS,
    SeamRefineReport, align_regions, refine_seams_pyramid,
};
use crate::kernels::jump_maps::jump_map::{
    Boundary, ControlField, ControlledSynthesisSettings, JumpMap, JumpMapError,
    PatchSynthesisSettings, PixelSynthesisSettings, SourceMap, SynthesisOutput,
    synthesize_controlled_with_progress, synthesize_patches_with_progress,
    synthesize_pixels_with_progress,
};
use crate::progress::Progress;

/// The pixel method's refinement of its source map (extensions).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PixelRefine {
    /// None (the paper).
    None,
    /// Seam refinement ([`refine_seams_pyramid`]).
    Seams,
    /// Seam refinement with whole coherent regions aligned before and
    /// after it ([`align_regions`]).
    AlignedSeams,
}

/// A planar synthesis method with its settings.
#[derive(Clone, Debug)]
pub enum PlaneMethod {
    /// Pixel-based (§5), optionally refined.
    Pixels(PixelSynthesisSettings, PixelRefine),
    /// Patch-based (§7.1).
    Patches(PatchSynthesisSettings),
    /// Controlled by orientation and scale fields (§7.2).
    Controlled(ControlField, ControlledSynthesisSettings),
}

/// A synthesised image and where its pixels came from.
#[derive(Clone, Debug)]
pub struct PlaneSynthesis {
    /// The image (the exemplar's channel count).
    pub image: Image,
    /// Per pixel, row-major, its exemplar address in pixels.
    pub sources: Vec<[f32; 2]>,
    /// The source-coordinate map (red = x, green = y, normalised).
    pub source_image: Image,
    /// What the seam refinement did, if it ran.
    pub refined: Option<SeamRefineReport>,
    /// What each region alignment did.
    pub aligned: Vec<AlignReport>,
}

/// Synthesises an image from `exemplar` and its jump `map` by `method`.
///
/// # Errors
/// As the method's synthesis.
pub fn synthesize_plane(
    exemplar: &Image,
    map: &JumpMap,
    method: &PlaneMethod,
    progress: &Progress,
) -> Result<PlaneSynthesis, JumpMapError> {
    let from_sources = |o: SynthesisOutput, refined, aligned| PlaneSynthesis {
        source_image: o.sources.patch_visualisation(),
        sources: texel_sources(&o.sources),
        image: o.image,
        refined,
        aligned,
    };
    match method {
        PlaneMethod::Patches(settings) => {
            let o = synthesize_patches_with_progress(exemplar, map, settings, progress)?;
            Ok(from_sources(o, None, Vec::new()))
        }
        PlaneMethod::Controlled(field, settings) => {
            let o = synthesize_controlled_with_progress(exemplar, map, field, settings, progress)?;
            Ok(PlaneSynthesis {
                source_image: o.patch_visualisation(exemplar.width, exemplar.height),
                image: o.image,
                sources: o.sources,
                refined: None,
                aligned: Vec::new(),
            })
        }
        PlaneMethod::Pixels(settings, refine) => {
            let mut o = synthesize_pixels_with_progress(exemplar, map, settings, progress)?;
            let toroidal = map.boundary() == Boundary::Toroidal;
            let mut aligned = Vec::new();
            let refined = (*refine != PixelRefine::None).then(|| {
                refine_pixels(&mut o, exemplar, toroidal, *refine, &mut aligned, progress)
            });
            Ok(from_sources(o, refined, aligned))
        }
    }
}

/// The pixel method's seam refinement of `o` (with whole regions aligned
/// before and after it for [`PixelRefine::AlignedSeams`], each alignment's
/// report pushed to `aligned`); the image is gathered again from the
/// refined sources.
fn refine_pixels(
    o: &mut SynthesisOutput,
    exemplar: &Image,
    toroidal: bool,
    refine: PixelRefine,
    aligned: &mut Vec<AlignReport>,
    progress: &Progress,
) -> SeamRefineReport {
    let mut align_now = |sources: &mut SourceMap| {
        if refine == PixelRefine::AlignedSeams {
            let _s = tracing::info_span!("align_regions").entered();
            progress.start_part("align", 0);
            aligned.push(align_regions(
                sources,
                exemplar,
                toroidal,
                ALIGN_SWEEPS,
                progress,
            ));
        }
    };
    align_now(&mut o.sources);
    progress.start_part("seams", 0);
    let seams_span = tracing::info_span!("refine_seams").entered();
    let report = refine_seams_pyramid(
        &mut o.sources,
        exemplar,
        toroidal,
        SEAM_REFINE_PASSES,
        SEAM_REFINE_RADIUS,
        SEAM_REFINE_LEVELS,
        progress,
    );
    drop(seams_span);
    align_now(&mut o.sources);
    if let Ok(image) = o.sources.gather(exemplar) {
        o.image = image;
    }
    report
}

/// Per pixel, its source texel as a continuous address.
fn texel_sources(sources: &SourceMap) -> Vec<[f32; 2]> {
    sources
        .texels
        .iter()
        .map(|t| [t.x as f32, t.y as f32])
        .collect()
}

/// The patch visualisation `jump_image` writes beside the result: the
/// source-coordinate map `sources` with blue 0.25.
pub fn patches_image(sources: &Image) -> Image {
    let mut patches = sources.clone();
    for px in patches.data.chunks_exact_mut(3) {
        px[2] = 0.25;
    }
    patches
}
