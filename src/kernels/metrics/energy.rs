//! Texture energy (Kwatra et al. 2005, §3 eq. 1) of an output image or of a
//! signal over a surface, against an exemplar: sampled output neighbourhoods,
//! each compared with its nearest exemplar neighbourhood by exhaustive search.

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

use super::nearest::{ExemplarNeighbourhoods, QueryScratch};
use super::window_index::{BandedIndex, WindowIndex};
use super::{EnergySettings, EnergyStats, SurfaceSignal};
use crate::image::{Image, sample::Wrap};
use crate::kernels::surface::flatten::Pool;
use crate::kernels::surface::frames::TangentFrame;
use crate::kernels::surface::surface_sample::{ResampleScratch, resample_neighbourhood};
use crate::mesh::{PolyMesh, Topology};
use std::ops::Range;

/// Picks `samples` of `count` locations: all of them in order when
/// `samples >= count`, else uniform draws (with replacement) from a PCG
/// stream seeded with `seed`.
pub(super) fn sample_indices(count: usize, samples: usize, seed: u64) -> Vec<usize> {
    if samples >= count {
        return (0..count).collect();
    }
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    (0..samples).map(|_| rng.random_range(0..count)).collect()
}

/// Texture energy of the image `output` against `exemplar`.
///
/// Samples `settings.samples` output pixels (see [`EnergySettings`]; every
/// pixel once when there are fewer), takes the `n`×`n` window centred on each
/// (`n = settings.neighbourhood`; pixels outside the output addressed with
/// `wrap`), finds the nearest `n`×`n` window of the exemplar over all its
/// positions (toroidal) by exhaustive L2 search, and records the squared
/// distance divided by `n² · channels`. The result depends only on the inputs
/// and the seed, not on the number of threads.
///
/// The search is exact ([`WindowIndex`], parallel over samples); its cost is
/// a few dozen full window distances per sample rather than one per exemplar
/// pixel.
///
/// Preconditions: `settings` is valid ([`EnergySettings::validate`]); both
/// images have pixels and the same channel count.
pub fn image_texture_energy(
    output: &Image,
    exemplar: &Image,
    settings: &EnergySettings,
    wrap: Wrap,
) -> EnergyStats {
    assert_eq!(
        output.channels, exemplar.channels,
        "output and exemplar channel counts differ"
    );
    let windows = ExemplarWindows::new(exemplar, settings.neighbourhood as usize);
    image_texture_energy_in(output, &windows, settings, wrap)
}

/// [`image_texture_energy`] against the exemplar's windows already
/// indexed (`windows.n()` is `settings.neighbourhood`; the exemplar has the
/// output's channels).
pub fn image_texture_energy_in(
    output: &Image,
    windows: &ExemplarWindows,
    settings: &EnergySettings,
    wrap: Wrap,
) -> EnergyStats {
    let n = settings.neighbourhood as usize;
    assert_eq!(windows.n(), n, "windows of the metric neighbourhood");
    let ch = output.channels as usize;
    let r = (n / 2) as i64;
    let picks = sample_indices(output.pixel_count(), settings.samples, settings.seed);
    let width = output.width as usize;
    let dim = n * n * ch;
    let mut queries = Vec::new();
    let mut values = Vec::with_capacity(picks.len());
    for chunk in picks.chunks(QUERY_CHUNK) {
        queries.resize(chunk.len() * dim, 0.0);
        queries
            .par_chunks_exact_mut(dim)
            .zip(chunk)
            .for_each(|(query, &p)| {
                let (x, y) = ((p % width) as i64, (p / width) as i64);
                for dy in 0..n {
                    for dx in 0..n {
                        let px = output.texel(x + dx as i64 - r, y + dy as i64 - r, wrap);
                        query[(dy * n + dx) * ch..][..ch].copy_from_slice(px);
                    }
                }
            });
        values.extend(
            windows
                .nearest(&queries, dim)
                .into_iter()
                .map(|d| d / dim as f32),
        );
    }
    EnergyStats::from_values(&values)
}

/// The `n`×`n` templates of a signal over a surface at the sampled
/// vertices, resampled once ([`resample_neighbourhood`]) and read by both
/// the texture energy ([`surface_energy_of`]) and the surface measures
/// ([`super::surface_quality::surface_quality`]), which sample the same
/// vertices with the same template.
pub struct SampledTemplates {
    /// Points per side.
    pub n: usize,
    /// Values per point.
    pub channels: usize,
    /// The sampled vertices, in sample order (a vertex may repeat).
    pub vertices: Vec<u32>,
    /// Per sample, its `n²·channels` values (uncovered points hold the
    /// default).
    pub values: Vec<f32>,
    /// Per sample, its covered points.
    pub covered: Vec<u32>,
    /// Per sample, `n²` flags: point covered by a face.
    pub coverage: Vec<bool>,
}

impl SampledTemplates {
    /// Resamples the `n`×`n` template of each of `vertices` (repeats
    /// allowed) in its frame, `spacing` world units between points,
    /// uncovered points taking `default`. Parallel over vertices; the result
    /// does not depend on the thread count.
    #[allow(clippy::too_many_arguments)]
    pub fn at(
        mesh: &PolyMesh,
        topo: &Topology,
        frames: &[TangentFrame],
        spacing: f32,
        signal: &SurfaceSignal,
        default: &[f32],
        vertices: Vec<u32>,
        n: usize,
    ) -> Self {
        let ch = signal.channels();
        let dim = n * n * ch;
        let mut values = vec![0.0f32; vertices.len() * dim];
        let mut coverage = vec![false; vertices.len() * n * n];
        let mut covered = vec![0u32; vertices.len()];
        // Resampled in order of vertex index, each into its own slot: nearby
        // vertices share faces, which then are still in cache (meshes number
        // their vertices with some locality). The values do not depend on
        // the order.
        let mut jobs: Vec<(u32, &mut [f32], &mut [bool], &mut u32)> = vertices
            .iter()
            .zip(values.chunks_exact_mut(dim.max(1)))
            .zip(coverage.chunks_exact_mut((n * n).max(1)))
            .zip(covered.iter_mut())
            .map(|(((&v, out), mask), c)| (v, out, mask, c))
            .collect();
        jobs.sort_by_key(|job| job.0);
        let pool = Pool::<ResampleScratch>::new();
        jobs.par_iter_mut().for_each(|(v, out, mask, c)| {
            pool.with(|resample| {
                **c = resample_neighbourhood(
                    mesh,
                    topo,
                    *v,
                    &frames[*v as usize],
                    spacing,
                    n as u32,
                    signal,
                    default,
                    out,
                    resample,
                ) as u32;
                mask.copy_from_slice(resample.coverage());
            })
        });
        drop(jobs);
        Self {
            n,
            channels: ch,
            vertices,
            values,
            covered,
            coverage,
        }
    }

    /// [`Self::at`] as the texture energy reads the result: at
    /// `settings.samples` vertices that have faces drawn with
    /// `settings.seed` (every such vertex once when there are fewer), with
    /// the settings' neighbourhood and the exemplar's mean as the default.
    #[allow(clippy::too_many_arguments)]
    pub fn for_energy(
        mesh: &PolyMesh,
        topo: &Topology,
        frames: &[TangentFrame],
        spacing: f32,
        signal: &SurfaceSignal,
        exemplar: &Image,
        settings: &EnergySettings,
    ) -> Self {
        let candidates: Vec<u32> = (0..mesh.vertex_count() as u32)
            .filter(|&v| !topo.vertex_faces(v).is_empty())
            .collect();
        let vertices = sample_indices(candidates.len(), settings.samples, settings.seed)
            .into_iter()
            .map(|k| candidates[k])
            .collect();
        Self::at(
            mesh,
            topo,
            frames,
            spacing,
            signal,
            &exemplar.mean(),
            vertices,
            settings.neighbourhood as usize,
        )
    }

    /// Samples.
    pub fn len(&self) -> usize {
        self.vertices.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.vertices.is_empty()
    }

    /// The values of sample `i`.
    pub fn template(&self, i: usize) -> &[f32] {
        let dim = self.n * self.n * self.channels;
        &self.values[i * dim..(i + 1) * dim]
    }

    /// The values of the samples covered at `min_covered` points or more,
    /// one after another in sample order.
    pub fn kept(&self, min_covered: usize) -> Vec<f32> {
        (0..self.len())
            .filter(|&i| self.covered[i] as usize >= min_covered)
            .flat_map(|i| self.template(i).iter().copied())
            .collect()
    }
}

/// Texture energy of a signal over a surface against `exemplar`.
///
/// Samples `settings.samples` vertices that have faces (every such vertex
/// once when there are fewer), resamples the signal on an `n`×`n` template in
/// each vertex's tangent frame with `spacing` world units between template
/// points ([`resample_neighbourhood`]; template column along `s` = exemplar
/// x, row along `t` = exemplar y), and compares it with its nearest exemplar
/// window (toroidal, exhaustive) over the template points that faces cover.
/// A vertex whose template is covered less than `settings.min_coverage`
/// (boundaries, holes) is left out; the value of the others is the squared
/// distance divided by `covered points · channels`. `spacing` is normally the
/// world size of one exemplar pixel at the synthesis scale. The result does
/// not depend on the number of threads.
///
/// Preconditions: `settings` is valid; `topo` was built for `mesh`;
/// `frames.len() == mesh.vertex_count()`; `spacing > 0`; the signal has the
/// exemplar's channel count and covers the mesh.
pub fn surface_texture_energy(
    mesh: &PolyMesh,
    topo: &Topology,
    frames: &[TangentFrame],
    spacing: f32,
    signal: &SurfaceSignal,
    exemplar: &Image,
    settings: &EnergySettings,
) -> EnergyStats {
    assert_eq!(frames.len(), mesh.vertex_count(), "one frame per vertex");
    let templates =
        SampledTemplates::for_energy(mesh, topo, frames, spacing, signal, exemplar, settings);
    surface_energy_of(&templates, exemplar, settings)
}

/// [`surface_texture_energy`] of templates already resampled (with
/// `settings.neighbourhood`, `settings.samples` and `settings.seed`, and the
/// exemplar's mean as the default).
pub fn surface_energy_of(
    templates: &SampledTemplates,
    exemplar: &Image,
    settings: &EnergySettings,
) -> EnergyStats {
    let windows = ExemplarWindows::new(exemplar, settings.neighbourhood as usize);
    surface_energy_in(templates, exemplar, &windows, settings)
}

/// [`surface_energy_of`] against `exemplar`'s windows already indexed
/// (`windows`, of `exemplar` or of an image with its values).
pub fn surface_energy_in(
    templates: &SampledTemplates,
    exemplar: &Image,
    windows: &ExemplarWindows,
    settings: &EnergySettings,
) -> EnergyStats {
    let ch = exemplar.channels as usize;
    assert_eq!(
        templates.channels, ch,
        "signal and exemplar channel counts differ"
    );
    let n = templates.n;
    assert_eq!(windows.n(), n, "windows of the templates' size");
    let dim = n * n * ch;
    // Templates partly covered compare only their covered points: the
    // exhaustive search, made when the first one comes.
    let masked = std::sync::OnceLock::new();
    let min_covered = (settings.min_coverage * (n * n) as f32).ceil().max(1.0) as usize;
    let mut values = Vec::with_capacity(templates.len());
    for first in (0..templates.len()).step_by(QUERY_CHUNK) {
        let samples = first..(first + QUERY_CHUNK).min(templates.len());
        let queries = &templates.values[samples.start * dim..samples.end * dim];
        // The distance of a partly covered template (else its query is
        // searched below).
        let partial: Vec<Option<f32>> = samples
            .clone()
            .into_par_iter()
            .map_init(QueryScratch::default, |scratch, i| {
                let covered = templates.covered[i] as usize;
                (covered >= min_covered && covered < n * n).then(|| {
                    masked
                        .get_or_init(|| ExemplarNeighbourhoods::new(exemplar, n as u32))
                        .nearest_sq_distance(
                            templates.template(i),
                            Some(&templates.coverage[i * n * n..(i + 1) * n * n]),
                            scratch,
                        )
                })
            })
            .collect();
        let full = windows.nearest(queries, dim);
        values.extend(
            samples
                .zip(partial)
                .zip(full)
                .map(|((i, partial), d)| (templates.covered[i] as usize, partial, d))
                .filter(|&(covered, ..)| covered >= min_covered)
                .map(|(covered, partial, d)| partial.unwrap_or(d) / (covered * ch) as f32),
        );
    }
    EnergyStats::from_values(&values)
}

/// Samples whose queries are made and searched at once at most (their
/// windows take `QUERY_CHUNK · n² · channels` values).
const QUERY_CHUNK: usize = 1 << 16;

/// Every `n`×`n` window of an exemplar, toroidally, indexed for exact
/// nearest-window queries (one index, or bands of one for a large
/// exemplar): the exemplar side of the texture energy, built once per run
/// and shared by the plane's energy and the surface's
/// ([`image_texture_energy_in`], [`surface_energy_in`]).
pub struct ExemplarWindows<'a> {
    n: usize,
    index: BandedIndex<Box<dyn Fn(Range<usize>) -> WindowIndex + Send + Sync + 'a>>,
}

impl<'a> ExemplarWindows<'a> {
    /// The `n`×`n` windows of `exemplar`, toroidally.
    ///
    /// Preconditions: `n >= 1`; the exemplar has pixels.
    pub fn new(exemplar: &'a Image, n: usize) -> Self {
        Self {
            n,
            index: BandedIndex::new(
                exemplar.height as usize,
                exemplar.width as usize,
                Box::new(move |rows| WindowIndex::toroidal(exemplar, n as u32, rows)),
            ),
        }
    }

    /// Window side.
    pub fn n(&self) -> usize {
        self.n
    }

    fn nearest(&self, queries: &[f32], dim: usize) -> Vec<f32> {
        self.index.nearest(queries, dim)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: u32, h: u32) -> Image {
        Image::from_data(
            w,
            h,
            1,
            (0..w * h)
                .map(|i| ((i * 37 + (i / w) * 11) % 17) as f32 / 17.0)
                .collect(),
        )
        .unwrap()
    }

    #[test]
    fn exemplar_against_itself_is_zero_and_thread_count_does_not_matter() {
        let ex = ramp(19, 13);
        let settings = EnergySettings {
            neighbourhood: 5,
            samples: 200,
            seed: 3,
            ..Default::default()
        };
        let s = image_texture_energy(&ex, &ex, &settings, Wrap::Repeat);
        assert_eq!((s.mean, s.samples), (0.0, 200));

        let mut noisy = ex.clone();
        for (i, v) in noisy.data.iter_mut().enumerate() {
            *v = (*v + (i % 5) as f32 * 0.13).fract();
        }
        let a = image_texture_energy(&noisy, &ex, &settings, Wrap::Clamp);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let b = pool.install(|| image_texture_energy(&noisy, &ex, &settings, Wrap::Clamp));
        assert_eq!(a, b);
        assert!(a.mean > 0.0 && a.p90 >= a.mean * 0.5);
    }

    /// One index of the exemplar's windows, shared, gives each energy the
    /// value it gets with an index of its own.
    #[test]
    fn shared_exemplar_windows_give_the_same_energy() {
        let ex = ramp(19, 13);
        let mut out = ramp(23, 17);
        for (i, v) in out.data.iter_mut().enumerate() {
            *v = (*v + (i % 7) as f32 * 0.11).fract();
        }
        let settings = EnergySettings {
            neighbourhood: 5,
            samples: 150,
            seed: 9,
            ..Default::default()
        };
        let windows = ExemplarWindows::new(&ex, 5);
        for wrap in [Wrap::Clamp, Wrap::Repeat] {
            assert_eq!(
                image_texture_energy_in(&out, &windows, &settings, wrap),
                image_texture_energy(&out, &ex, &settings, wrap)
            );
        }
    }

    /// Templates are resampled in order of vertex index into their own
    /// slots: listing the same vertices in another order (with repeats)
    /// gives each sample the same values, coverage and count.
    #[test]
    fn sampled_templates_do_not_depend_on_the_order_of_the_vertices() {
        use crate::mesh::builtin::{BuiltinOptions, builtin_mesh};
        let opts = BuiltinOptions {
            resolution: [14, 11],
            size: 13.0,
            ..Default::default()
        };
        let mesh = builtin_mesh("jittered_plane", &opts).unwrap();
        let topo = Topology::build(&mesh);
        let frames =
            vec![TangentFrame::from_direction(glam::Vec3::Z, glam::Vec3::X); mesh.vertex_count()];
        let values: Vec<f32> = (0..mesh.vertex_count())
            .map(|v| ((v * 7) % 13) as f32 / 13.0)
            .collect();
        let signal = SurfaceSignal::VertexColours {
            values: &values,
            channels: 1,
        };
        let list: Vec<u32> = vec![100, 3, 77, 3, 150, 0, 64, 121];
        let at = |vertices: Vec<u32>| {
            SampledTemplates::at(&mesh, &topo, &frames, 1.0, &signal, &[0.5], vertices, 5)
        };
        let forward = at(list.clone());
        let reversed = at(list.iter().rev().copied().collect());
        let k = list.len();
        for i in 0..k {
            let j = k - 1 - i;
            assert_eq!(forward.template(i), reversed.template(j), "sample {i}");
            assert_eq!(forward.covered[i], reversed.covered[j]);
            assert_eq!(
                forward.coverage[i * 25..(i + 1) * 25],
                reversed.coverage[j * 25..(j + 1) * 25]
            );
        }
        assert!(forward.covered.contains(&25) && forward.covered.iter().any(|&c| c < 25));
    }

    #[test]
    fn all_pixels_when_samples_exceed_them() {
        assert_eq!(sample_indices(5, 10, 0), vec![0, 1, 2, 3, 4]);
        let s = sample_indices(100, 10, 7);
        assert_eq!(s, sample_indices(100, 10, 7));
        assert_ne!(s, sample_indices(100, 10, 8));
    }
}
