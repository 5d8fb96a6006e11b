//! The system that follows every pipeline: texture energy (Kwatra et al.
//! 2005) and histogram distance of the result against the exemplar, written
//! to `metrics.json` under `result.quality`.
//!
//! The result is what the run delivers: after a `bake`, the baked atlas on
//! the original mesh (what `result.glb` shows, whatever the method);
//! otherwise whichever signal the active mesh carries: per-corner UVs
//! (jump maps), vertex colours (Wei–Levoy, Bangay–Morkel), or lapped-texture
//! pastes (Praun et al.), which are composited in paste order with alpha at
//! every template point (the renderer's compositing) and measured in the
//! frames of the topmost paste at each vertex.
//!
//! Reads: `ActiveMesh` (`Geometry`, `Frames`, `VertexColours`,
//! `CornerUvs`, `SourceTexels`, lapped pastes), `TexturePatches`,
//! `PlaneImage`, `BakedAsset`, the `SourceMesh`, `Exemplar`,
//! `TexelSpacing`. Writes: `Metrics::result`. The measuring is
//! `kernels::metrics` (`result::measure_surface`, the histogram samples).

use crate::config::params::to_json;
use crate::image::Image;
use crate::kernels::lapped::composite::{LappedComposite, PasteRecord};
use crate::kernels::metrics::energy::ExemplarWindows;
use crate::kernels::metrics::quality::image_quality_in;
use crate::kernels::metrics::result::{
    atlas_samples, histogram_density, histogram_distance, measure_surface,
};
use crate::kernels::metrics::surface_quality::{SurfaceResult, surface_verbatim};
use crate::kernels::metrics::{EnergySettings, SourceMap, SurfaceSignal};
use crate::kernels::surface::frames::frames_from_global_direction;
use crate::kernels::surface::surface_sample::CornerFn;
use crate::kernels::wei_levoy::retile::{ResultAttributes, map_back};
use crate::mesh::Topology;
use crate::progress::Progress;
use crate::world::*;
use crate::world::{PasteOf, PasteOrder, PatchFaces, PatchUvs, TexturePatchIndex, TexturePatches};
use bevy_ecs::prelude::*;
use bevy_ecs::query::ROQueryItem;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use std::borrow::Cow;

/// What the result metrics read of the active mesh.
type ResultData = (
    &'static Geometry,
    Option<&'static Frames>,
    Option<&'static VertexColours>,
    Option<&'static CornerUvs>,
    Option<&'static SourceTexels>,
);

type ResultQuery<'w, 's> = Query<'w, 's, ResultData>;

/// One item of [`ResultQuery`].
type ResultItem<'a> = ROQueryItem<'a, 'a, ResultData>;

type PasteQuery<'w, 's> = Query<
    'w,
    's,
    (
        &'static PasteOf,
        &'static PasteOrder,
        &'static TexturePatchIndex,
        &'static PatchFaces,
        &'static PatchUvs,
    ),
>;

/// The result-metrics system with its settings.
pub fn system(settings: EnergySettings) -> ScheduleConfigs<ScheduleSystem> {
    (move |active: Res<ActiveMesh>,
           exemplar: Res<Exemplar>,
           spacing: Res<TexelSpacing>,
           mut metrics: ResMut<Metrics>,
           meshes: ResultQuery,
           pastes: PasteQuery,
           patch_textures: Option<Res<TexturePatches>>,
           plane: Option<Res<PlaneImage>>,
           baked: Option<Res<BakedAsset>>,
           source: Query<(&Geometry, Option<&Frames>), With<SourceMesh>>| {
        let _span = tracing::info_span!("result_metrics").entered();
        // Phases: plane image, composite, texture energy, quality,
        // histogram (about 1.1-1.5 s at a million vertices on 2 cores).
        let progress = Progress::new(5, "result_metrics");
        let _finish = progress.finish_on_drop();
        progress.set_part("plane");
        // The exemplar's windows, indexed once for the plane's texture
        // energy and the surface's (the plane measures the RGB exemplar: the
        // same values when it has three channels).
        let n = settings.neighbourhood;
        let image = &exemplar.image;
        let shared =
            (plane.is_some() && image.channels == 3 && image.width >= n && image.height >= n)
                .then(|| ExemplarWindows::new(image, n as usize));
        if let Some(plane) = plane.as_deref() {
            plane_quality(plane, image, &settings, shared.as_ref(), &mut metrics);
        }
        progress.inc(1);
        let Ok(result) = meshes.get(active.0) else {
            return;
        };
        if exemplar.image.width < n || exemplar.image.height < n {
            metrics.result.insert(
                "texture_energy".into(),
                serde_json::Value::String(format!(
                    "skipped: exemplar smaller than the {n}x{n} metric neighbourhood"
                )),
            );
            return;
        }
        let measure = Measure {
            exemplar: &exemplar,
            spacing: spacing.0,
            settings: &settings,
            windows: shared.as_ref(),
        };
        if let (Some(asset), Ok(source)) = (baked.as_deref(), source.single()) {
            measure.baked(result, asset, source, &mut metrics);
            progress.inc(4);
            return;
        }
        let records = paste_records(&pastes, active.0);
        let textures = patch_textures.as_deref().map(|t| t.0.as_slice());
        measure.active(result, &records, textures, &mut metrics, &progress);
    })
    .into_configs()
}

/// The lapped pastes on `mesh`, in paste order.
fn paste_records<'a>(pastes: &'a PasteQuery, mesh: Entity) -> Vec<PasteRecord<'a>> {
    let mut records: Vec<(u32, PasteRecord)> = pastes
        .iter()
        .filter(|(of, ..)| of.0 == mesh)
        .map(|(_, order, tex, faces, puv)| {
            (
                order.0,
                PasteRecord {
                    texture: tex.0,
                    faces: &faces.0,
                    uvs: &puv.0,
                },
            )
        })
        .collect();
    records.sort_by_key(|r| r.0);
    records.into_iter().map(|r| r.1).collect()
}

/// What every measure reads: the exemplar, the world units of one
/// exemplar pixel, the settings.
struct Measure<'a> {
    exemplar: &'a Exemplar,
    spacing: f32,
    settings: &'a EnergySettings,
    /// The exemplar's windows, indexed once when the plane measured them.
    windows: Option<&'a ExemplarWindows<'a>>,
}

impl Measure<'_> {
    /// After a `bake`: the baked atlas on the source mesh
    /// ([`baked_quality`]), and the synthesis's copied regions on the
    /// active mesh (a bake blends look-ups at seams but moves no source).
    fn baked(
        &self,
        (geometry, frames, _, _, sources): ResultItem,
        asset: &BakedAsset,
        (source, source_frames): (&Geometry, Option<&Frames>),
        metrics: &mut Metrics,
    ) {
        let mesh = &geometry.0;
        let sources = sources
            .map(|s| &s.0[..])
            .filter(|s| s.len() == mesh.vertex_count());
        // Measured in the source's frames, else in the synthesis frames
        // carried onto it, else texture-up along +y (`orientation`'s
        // default).
        let carried = match (source_frames, frames) {
            (None, Some(f)) if f.0.len() == mesh.vertex_count() => {
                frames_carried_onto(mesh, &f.0, &source.0)
            }
            _ => None,
        };
        let source_frames = source_frames.map(|f| &f.0[..]).or(carried.as_deref());
        baked_quality(asset, &source.0, source_frames, self, metrics);
        let frames = frames
            .map(|f| &f.0[..])
            .filter(|f| f.len() == mesh.vertex_count());
        if let (Some(s), Some(frames)) = (sources, frames) {
            let topo = Topology::build_edges_and_vertex_faces(mesh);
            let result = SurfaceResult {
                mesh,
                topo: &topo,
                frames,
                spacing: self.spacing,
                signal: &SurfaceSignal::VertexColours {
                    values: &[],
                    channels: 0,
                },
            };
            let image = &self.exemplar.image;
            let v = surface_verbatim(&result, s, image.width, image.height);
            metrics.result.insert("verbatim".into(), to_json(&v));
        }
    }

    /// Whichever signal the active mesh carries: per-corner UVs, vertex
    /// colours, or lapped pastes (`records` of `textures`) composited in
    /// paste order and measured in the frames of the topmost paste.
    fn active(
        &self,
        (geometry, frames, colours, uvs, sources): ResultItem,
        records: &[PasteRecord],
        textures: Option<&[Image]>,
        metrics: &mut Metrics,
        progress: &Progress,
    ) {
        let mesh = &geometry.0;
        let exemplar = self.exemplar;
        progress.set_part("composite");
        let background = exemplar.image.mean();
        let composite = match (uvs, colours, textures) {
            (None, None, Some(textures)) if !records.is_empty() => {
                match LappedComposite::new(mesh, records, textures, &background) {
                    Ok(c) => Some(c),
                    Err(e) => {
                        metrics.result.insert(
                            "texture_energy".into(),
                            serde_json::Value::String(format!("skipped: {e}")),
                        );
                        return;
                    }
                }
            }
            _ => None,
        };
        let eval = |corners: [u32; 3], w: [f32; 3], out: &mut [f32]| {
            if let Some(c) = &composite {
                c.eval_corners(corners, w, out);
            }
        };
        let signal = match (uvs, colours, &composite) {
            (Some(uv), _, _) => SurfaceSignal::CornerUvs {
                uvs: &uv.0,
                texture: &exemplar.image,
                wrap: exemplar.wrap,
            },
            (None, Some(c), _) => SurfaceSignal::VertexColours {
                values: &c.values,
                channels: c.channels,
            },
            (None, None, Some(c)) => SurfaceSignal::Corners {
                channels: c.channels(),
                eval: CornerFn(&eval),
            },
            (None, None, None) => return,
        };
        let frames = match (&composite, frames) {
            (Some(c), _) => Cow::Owned(c.frames(mesh, glam::Vec3::X)),
            (None, Some(f)) if f.0.len() == mesh.vertex_count() => Cow::Borrowed(&f.0[..]),
            _ => Cow::Owned(frames_from_global_direction(
                &mesh.vertex_normals(),
                glam::Vec3::X,
            )),
        };
        progress.inc(1);
        // The measures that see what the energy forgives (kernels/metrics).
        let sources = sources
            .map(|s| &s.0[..])
            .filter(|s| s.len() == mesh.vertex_count());
        let (stats, q) = measure_surface(
            mesh,
            &frames,
            self.spacing,
            &signal,
            &exemplar.image,
            self.settings,
            sources,
            self.windows,
            progress,
        );
        record_surface_measures(
            metrics,
            &stats,
            &q,
            self.settings.neighbourhood,
            self.spacing,
        );
        if let Some(v) = q.verbatim {
            metrics.result.insert("verbatim".into(), to_json(&v));
        }
        progress.inc(1);
        progress.set_part("histogram");
        let span = tracing::debug_span!("histogram_samples").entered();
        let values = match (colours, &composite) {
            (Some(c), _) => Some((c.values.clone(), c.channels)),
            (None, Some(c)) => {
                let density = histogram_density(mesh.face_areas().iter().sum());
                Some((c.sample_colours(mesh, density), c.channels()))
            }
            _ => None,
        };
        drop(span);
        if let Some((values, channels)) = values {
            record_histogram(metrics, values, channels, &exemplar.image);
        }
        progress.inc(1);
    }
}

/// The surface measures of the baked atlas on the original mesh (what
/// `result.glb` shows), against the exemplar in RGB (the atlas is RGB):
/// coherence, completeness, sharpness and structure, as for any result.
fn baked_quality(
    asset: &BakedAsset,
    source: &crate::mesh::PolyMesh,
    source_frames: Option<&[crate::kernels::surface::frames::TangentFrame]>,
    measure: &Measure,
    metrics: &mut Metrics,
) {
    let mesh = asset.mesh_or(source);
    let rgb = measure.exemplar.image.to_rgb();
    let signal = SurfaceSignal::CornerUvs {
        uvs: &asset.uvs,
        texture: &asset.colour,
        wrap: crate::image::sample::Wrap::Clamp,
    };
    let owned;
    let frames = match source_frames {
        Some(f) if f.len() == mesh.vertex_count() => f,
        _ => {
            owned = frames_from_global_direction(&mesh.vertex_normals(), glam::Vec3::Y);
            &owned
        }
    };
    let (spacing, settings) = (measure.spacing, measure.settings);
    let hidden = Progress::hidden();
    let (stats, q) = measure_surface(
        mesh,
        frames,
        spacing,
        &signal,
        &rgb,
        settings,
        None,
        measure.windows,
        &hidden,
    );
    record_surface_measures(metrics, &stats, &q, settings.neighbourhood, spacing);
    // The histogram of the atlas as the mesh shows it.
    let per_area = histogram_density(mesh.face_areas().iter().sum());
    let values = atlas_samples(mesh, &asset.uvs, &asset.colour, per_area);
    record_histogram(metrics, values, 3, &rgb);
    metrics
        .result
        .insert("measured_on".into(), "baked atlas".into());
}

/// The synthesis frames of `result` carried onto the vertices of `source`
/// (each takes the frame of its closest result triangle's heaviest corner,
/// turned into its tangent plane: [`map_back`]); `None` when that fails.
fn frames_carried_onto(
    result: &crate::mesh::PolyMesh,
    frames: &[crate::kernels::surface::frames::TangentFrame],
    source: &crate::mesh::PolyMesh,
) -> Option<Vec<crate::kernels::surface::frames::TangentFrame>> {
    let attributes = ResultAttributes {
        colours: &[],
        channels: 0,
        texels: None,
        frames: Some(frames),
    };
    map_back(
        result,
        &attributes,
        &source.positions,
        &source.vertex_normals(),
    )
    .ok()
    .and_then(|m| m.frames)
}

/// Writes the histogram distance of `values` (`channels` per sample) to the
/// exemplar's, per channel (`histogram_wasserstein`) and their mean
/// (`histogram`).
fn record_histogram(metrics: &mut Metrics, values: Vec<f32>, channels: usize, exemplar: &Image) {
    let _span = tracing::debug_span!("histogram").entered();
    if let Some((w, mean)) = histogram_distance(values, channels, exemplar) {
        metrics
            .result
            .insert("histogram_wasserstein".into(), to_json(&w));
        metrics.result.insert("histogram".into(), to_json(&mean));
    }
}

/// Writes the texture energy (as `texture_energy` and `coherence`) and the
/// surface measures under `result`.
fn record_surface_measures(
    metrics: &mut Metrics,
    stats: &crate::kernels::metrics::EnergyStats,
    q: &crate::kernels::metrics::surface_quality::SurfaceQuality,
    neighbourhood: u32,
    spacing: f32,
) {
    let json = |v: f32| to_json(&v.is_finite().then_some(v));
    metrics.result.insert(
        "texture_energy".into(),
        serde_json::json!({
            "mean": to_json(&stats.mean), "p90": to_json(&stats.p90), "samples": stats.samples,
            "neighbourhood": neighbourhood, "spacing_world_units": to_json(&spacing),
        }),
    );
    metrics.result.insert(
        "coherence".into(),
        serde_json::json!({ "mean": to_json(&stats.mean), "p90": to_json(&stats.p90) }),
    );
    metrics
        .result
        .insert("completeness".into(), json(q.completeness));
    metrics.result.insert("sharpness".into(), json(q.sharpness));
    metrics.result.insert("structure".into(), json(q.structure));
    metrics.result.insert(
        "templates".into(),
        serde_json::json!({ "small": to_json(&q.templates), "structure": to_json(&q.structure_templates) }),
    );
}

/// Every image measure of the planar result (`plane.png`) against the
/// exemplar, under `result.quality.plane` (see docs/metrics.md).
fn plane_quality(
    plane: &PlaneImage,
    exemplar: &Image,
    settings: &EnergySettings,
    windows: Option<&ExemplarWindows>,
    metrics: &mut Metrics,
) {
    let n = settings.neighbourhood;
    let rgb = exemplar.to_rgb();
    let img = &plane.image;
    if img.width < n || img.height < n || rgb.width < n || rgb.height < n {
        metrics.result.insert(
            "plane".into(),
            serde_json::Value::String(format!(
                "skipped: image or exemplar smaller than the {n}x{n} metric neighbourhood"
            )),
        );
        return;
    }
    let sources = plane.sources.as_ref().map(|t| SourceMap {
        width: img.width,
        height: img.height,
        texels: t.clone(),
    });
    let _span = tracing::debug_span!("plane_quality").entered();
    let q = image_quality_in(img, &rgb, windows, sources.as_ref(), settings);
    metrics.result.insert("plane".into(), to_json(&q));
}
