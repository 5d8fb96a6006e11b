//! The seam refinement of surface synthesis (an extension; `jump_surface`'s
//! `refine = "seams"`): coherent correction passes
//! ([`coherent_refine`]) over the band of vertices around the patches'
//! seams ([`seam_band`]), on meshes of about a pixel per edge.

use super::seam_band;
use crate::cache_format::AnalysisStore;
use crate::image::Image;
use crate::kernels::coherent::{CoherentLevelReport, CoherentSettings, coherent_refine};
use crate::kernels::wei_levoy::wl_match::{SynthesisLevel, WlError};
use crate::mesh::Topology;
use crate::progress::Progress;
use glam::Vec2;

/// The seam refinement's correction (`refine = "seams"`): the coherent
/// kernel's defaults with coherent shifts only (k = 0: a seam vertex takes
/// a neighbour's patch, never a new exemplar place) over three rings.
pub const REFINE_SETTINGS: CoherentSettings = CoherentSettings {
    k: 0,
    ..CoherentSettings::DEFAULT
};

/// The band `refine = "seams"` corrects: vertices within this many edges
/// of a seam (their neighbourhoods are compared over
/// [`REFINE_SETTINGS`]`.ring` rings). Once a vertex moves, its neighbours
/// in the band are revisited. On the planar benchmark (seeds 1–3, the five
/// shared photos) one ring gives the same quality as three within ±0.04
/// of the peer's figures, and on a messy 92 k-vertex scan it holds 40 %
/// rather than 87 % of the vertices (the band's neighbourhoods are its
/// memory).
pub const REFINE_BAND_RINGS: u32 = 1;

/// The coarsest mesh `refine = "seams"` works on, in exemplar pixels per
/// edge (mean). The refinement moves seams by whole vertices and compares
/// neighbourhoods at vertex spacing: on a mesh as fine as the texture or
/// finer it follows the texture's features; on a coarser one a seam lies
/// inside faces, where the per-corner blend covers it, and moving whole
/// vertices only shifts patches by many pixels (measured on the 1.8 k-vertex
/// bunny of config 02, 15.5 pixels per edge: every vertex moved and the
/// texture energy rose 0.0024 → 0.0029).
pub const REFINE_MAX_TEXELS_PER_EDGE: f32 = 2.0;

/// The finest mesh `refine = "seams"` works on, in exemplar pixels per
/// edge (mean). On a mesh with several vertices per pixel the three rings
/// compared span about one pixel and see nothing of the texture's
/// structure, and the band is a large part of the mesh (a 901 k-vertex
/// messy scan at 0.44 pixels per edge: 40 % of the vertices, 5.7 s against
/// the synthesis's 0.7 s).
pub const REFINE_MIN_TEXELS_PER_EDGE: f32 = 0.5;

/// Exemplar pixels per edge, on average, of the per-edge `offsets`.
pub fn texels_per_edge(offsets: &[Vec2]) -> f32 {
    offsets.iter().map(|o| o.length()).sum::<f32>() / offsets.len().max(1) as f32
}

/// Why the seam refinement does not apply to a mesh whose vertices have
/// `uniform` scales or not, at `texels_per_edge` pixels per edge: `None`
/// when it does.
pub fn refine_skipped(uniform: bool, texels_per_edge: f32) -> Option<String> {
    if !uniform {
        Some("scale_by_height is not [1, 1]".into())
    } else if !(REFINE_MIN_TEXELS_PER_EDGE..=REFINE_MAX_TEXELS_PER_EDGE).contains(&texels_per_edge)
    {
        Some(format!(
            "{texels_per_edge:.2} exemplar pixels per edge, outside {REFINE_MIN_TEXELS_PER_EDGE}..={REFINE_MAX_TEXELS_PER_EDGE}"
        ))
    } else {
        None
    }
}

/// The vertices the refinement corrects: those within
/// [`REFINE_BAND_RINGS`] edges of a seam between `patch`es.
pub fn refine_band(topo: &Topology, patch: &[u32]) -> Vec<bool> {
    seam_band(topo, patch, REFINE_BAND_RINGS)
}

/// What the refinement did.
#[derive(Clone, Debug)]
pub struct RefinedSeams {
    /// Vertices in the band.
    pub band_vertices: usize,
    /// Vertices whose coordinates changed.
    pub moved: usize,
    /// The correction's figures.
    pub report: CoherentLevelReport,
}

/// Corrects `texel` (per vertex, exemplar pixels with integer values at
/// pixel centres, as the synthesis gives them) on the vertices of `band`
/// ([`coherent_refine`] with `settings`, its appearance analysis through
/// `store`); the others keep theirs and serve as context.
///
/// # Errors
/// As [`coherent_refine`].
#[allow(clippy::too_many_arguments)] // the refinement's inputs and its two services (store, progress)
pub fn refine_seams(
    level: &SynthesisLevel,
    topo: &Topology,
    exemplar: &Image,
    settings: &CoherentSettings,
    texel: &mut [Vec2],
    band: &[bool],
    store: Option<&dyn AnalysisStore>,
    progress: &Progress,
) -> Result<RefinedSeams, WlError> {
    let start: Vec<Vec2> = texel.iter().map(|&t| t + Vec2::splat(0.5)).collect();
    let refined = coherent_refine(
        level,
        Some(topo),
        exemplar,
        settings,
        &start,
        band,
        store,
        progress,
    )?;
    let moved = refined
        .coords
        .iter()
        .zip(&start)
        .filter(|(a, b)| a != b)
        .count();
    for (t, c) in texel.iter_mut().zip(&refined.coords) {
        *t = *c - Vec2::splat(0.5);
    }
    Ok(RefinedSeams {
        band_vertices: band.iter().filter(|&&b| b).count(),
        moved,
        report: refined.report,
    })
}
