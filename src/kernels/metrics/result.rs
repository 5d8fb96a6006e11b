//! The measures of a run's result on its surface, as the result metrics
//! take them: the texture energy with the surface measures in one pass
//! ([`measure_surface`]), and the samples of a histogram against the
//! exemplar's ([`histogram_density`], [`atlas_samples`],
//! [`histogram_distance`]).

use crate::image::Image;
use crate::image::sample::Wrap;
use crate::kernels::lapped::coverage::{lattice_level, lattice_samples_into};
use crate::kernels::metrics::energy::{
    ExemplarWindows, SampledTemplates, surface_energy_in, surface_energy_of,
};
use crate::kernels::metrics::surface_quality::{SurfaceQuality, SurfaceResult, surface_quality_of};
use crate::kernels::metrics::{EnergySettings, EnergyStats, SurfaceSignal, histogram_wasserstein};
use crate::kernels::surface::frames::TangentFrame;
use crate::mesh::{PolyMesh, Topology};
use crate::progress::Progress;
use glam::Vec2;

/// Histogram samples a result is read at, about this many spread by area.
pub const HISTOGRAM_SAMPLES: f32 = 20_000.0;

/// The texture energy ([`surface_energy_of`]) and the surface measures
/// ([`surface_quality_of`]) of `signal` on `mesh`, from one set of
/// templates ([`SampledTemplates`]), in `frames` at
/// `spacing` world units per exemplar pixel; `sources` are the per-vertex
/// exemplar pixels, when known; `windows` the exemplar's windows already
/// indexed, when the caller has them (else indexed here). Parts `"texture energy"` (one step) and
/// `"quality"` of `progress`.
///
/// Preconditions: as [`surface_energy_of`] and [`surface_quality_of`].
#[allow(clippy::too_many_arguments)]
pub fn measure_surface(
    mesh: &PolyMesh,
    frames: &[TangentFrame],
    spacing: f32,
    signal: &SurfaceSignal,
    exemplar: &Image,
    settings: &EnergySettings,
    sources: Option<&[Vec2]>,
    windows: Option<&ExemplarWindows>,
    progress: &Progress,
) -> (EnergyStats, SurfaceQuality) {
    progress.set_part("texture energy");
    // The metrics read only the edges and the faces of each vertex.
    let topo = Topology::build_edges_and_vertex_faces(mesh);
    let span = tracing::debug_span!("surface_texture_energy").entered();
    // The energy's templates are the surface measures' small ones: resampled
    // once for both.
    let small =
        SampledTemplates::for_energy(mesh, &topo, frames, spacing, signal, exemplar, settings);
    let stats = match windows {
        Some(w) => surface_energy_in(&small, exemplar, w, settings),
        None => surface_energy_of(&small, exemplar, settings),
    };
    drop(span);
    progress.inc(1);
    progress.set_part("quality");
    let result = SurfaceResult {
        mesh,
        topo: &topo,
        frames,
        spacing,
        signal,
    };
    (
        stats,
        surface_quality_of(&result, exemplar, settings, sources, &small),
    )
}

/// Samples per unit area for a histogram of about [`HISTOGRAM_SAMPLES`]
/// samples over a surface of `area`.
pub fn histogram_density(area: f32) -> f32 {
    HISTOGRAM_SAMPLES / area.max(f32::MIN_POSITIVE)
}

/// An atlas `image` as `mesh` shows it through its per-corner `uvs`: read
/// (bilinear, clamped) at lattice points of every triangle, `per_area`
/// per unit area ([`histogram_density`]); three values a sample. Faces
/// that are not triangles are skipped.
pub fn atlas_samples(mesh: &PolyMesh, uvs: &[Vec2], image: &Image, per_area: f32) -> Vec<f32> {
    let mut values = Vec::new();
    let mut px = [0.0f32; 3];
    let mut lattice = Vec::new();
    for f in 0..mesh.face_count() {
        let corners = mesh.face_corners(f);
        if corners.len() != 3 {
            continue;
        }
        let k = lattice_level(mesh.face_area(f), per_area);
        lattice_samples_into(k, &mut lattice);
        let uv = &uvs[corners];
        for b in &lattice {
            let p = uv[0] * b[0] + uv[1] * b[1] + uv[2] * b[2];
            image.sample_uv(p.x, p.y, Wrap::Clamp, &mut px);
            values.extend_from_slice(&px);
        }
    }
    values
}

/// The histogram distance of `values` (`channels` per sample) to the
/// exemplar's: per channel ([`histogram_wasserstein`]) and their mean;
/// `None` without samples.
pub fn histogram_distance(
    values: Vec<f32>,
    channels: usize,
    exemplar: &Image,
) -> Option<(Vec<f32>, f32)> {
    let as_image = Image::from_data(
        (values.len() / channels.max(1)) as u32,
        1,
        channels as u32,
        values,
    );
    as_image.filter(|i| i.width > 0).map(|img| {
        let w = histogram_wasserstein(&img, exemplar);
        let mean = w.iter().sum::<f32>() / w.len().max(1) as f32;
        (w, mean)
    })
}
