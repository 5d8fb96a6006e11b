//! Stage `jump_surface`: jump-map texture synthesis directly on the surface
//! (Zelinka & Garland 2004 §6). The mesh keeps its vertices; the result is
//! per-corner texture coordinates (one base vertex per face, for OBJ) plus
//! the three base-vertex layers of the §6.5 blend (for previews and bakes).
//! Texture scale is a parameter only: no remeshing.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::coherent::{CoherentSettings, coherent_refine};
use crate::kernels::jump_maps::jump_map::Boundary;
use crate::kernels::jump_maps::jump_surface::{
    Matcher, SurfaceSynthSettings, corner_side_offsets, corner_uvs, edge_offsets, seam_band,
    synthesize_surface_matched,
};
use crate::kernels::jump_maps::vertex_order::VertexOrder;
use crate::kernels::wei_levoy::wl_match::SynthesisLevel;
use crate::mesh::Topology;
use crate::stage::{Datum, Stage, StageCtx};
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::{Vec2, Vec3};
use serde::{Deserialize, Serialize};

/// Settings of `jump_surface`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct JumpSurfaceSettings {
    /// Exemplar pixels per world unit; 0 = `[input] texture_scale`.
    pub scale: f32,
    /// Scale multipliers at the lowest and highest vertex along `height_axis`.
    pub scale_by_height: [f32; 2],
    /// The axis `scale_by_height` varies along.
    pub height_axis: [f32; 3],
    /// Desired patch size, fraction of the exemplar side.
    pub patch_fraction: f32,
    /// Boundary-avoidance band, fraction of the exemplar size.
    pub boundary_fraction: f32,
    /// Vertex ordering.
    pub order: VertexOrder,
    /// Largest area one patch copies, fraction of the exemplar's area
    /// (extension; 0 = unbounded, the paper).
    pub max_patch_area: f32,
    /// Random starts at pixel centres (extension; false = the paper).
    pub pixel_aligned: bool,
    /// "random" (the paper) or "matched" (extension).
    pub choice: String,
    /// "none" (the paper) or "seams" (extension): coherent correction
    /// passes over the band around the seams.
    pub refine: String,
    /// Read and write the seam refinement's appearance analysis in the
    /// on-disk analysis cache.
    pub cache: bool,
}

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

/// Default of `max_patch_area`: a quarter of the exemplar, below the third
/// above which a copied region counts as a large verbatim copy (the quality
/// metrics' `large_region_repeats`), and the same bound as one lapped paste
/// (`kernels::lapped::auto_patches`).
pub const MAX_PATCH_AREA: f32 = 0.25;

impl Default for JumpSurfaceSettings {
    fn default() -> Self {
        Self {
            scale: 0.0,
            scale_by_height: [1.0, 1.0],
            height_axis: [0.0, 1.0, 0.0],
            patch_fraction: 0.5,
            boundary_fraction: 0.2,
            order: VertexOrder::EmergingFront,
            max_patch_area: MAX_PATCH_AREA,
            pixel_aligned: true,
            choice: "matched".into(),
            refine: "seams".into(),
            cache: true,
        }
    }
}

impl StageSettings for JumpSurfaceSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "scale",
            unit: "pixels per world unit",
            range: ParamRange::Float(0.0, 1e9),
            doc: "texture scale (§6.1); 0 = the run's `[input] texture_scale` (default: the exemplar's width spans half the bounding-box diagonal); a value here overrides it for this stage",
        },
        ParamDoc {
            name: "scale_by_height",
            unit: "factor",
            range: ParamRange::Float(0.01, 100.0),
            doc: "scale multiplier at the lowest and the highest vertex along height_axis, linear between (Fig. 15); [1, 1] = uniform",
        },
        ParamDoc {
            name: "height_axis",
            unit: "world axes",
            range: ParamRange::Float(-1e6, 1e6),
            doc: "direction along which scale_by_height varies (non-zero)",
        },
        ParamDoc {
            name: "patch_fraction",
            unit: "fraction",
            range: ParamRange::Float(0.01, 16.0),
            doc: "desired patch size as a fraction of the exemplar side: patches of about (f·side)² pixels (§5.1; paper 1/3-3/4)",
        },
        ParamDoc {
            name: "boundary_fraction",
            unit: "fraction",
            range: ParamRange::Float(0.0, 0.5),
            doc: "band near the exemplar border where jumps become likelier (§5.2; paper 1/5); inset maps only",
        },
        ParamDoc {
            name: "order",
            unit: "",
            range: ParamRange::OneOf(&["emerging_front", "breadth_first", "random"]),
            doc: "vertex order: emerging front (§6.2, the paper's), or breadth-first / random for comparison",
        },
        ParamDoc {
            name: "max_patch_area",
            unit: "fraction of the exemplar's area",
            range: ParamRange::Float(0.0, 1.0),
            doc: "an extension: once the vertices copied from one jump or random start cover this much texel area, they stop suggesting copies and the next vertex jumps, so no patch copies a large part of the exemplar verbatim again and again; 0 = unbounded (the paper)",
        },
        ParamDoc {
            name: "choice",
            unit: "",
            range: ParamRange::OneOf(&["random", "matched"]),
            doc: "random = the paper's selection table (§6.6); matched = an extension: the paper's draw still decides whether a vertex copies or jumps, but where patches meet, which jump, and where a random start goes, the candidate whose exemplar neighbourhood best matches the vertices already synthesised within four edges wins",
        },
        ParamDoc {
            name: "refine",
            unit: "",
            range: ParamRange::OneOf(&["none", "seams"]),
            doc: "none = the paper's result; seams = an extension (the `coherent` stage's kernel): the vertices next to a seam (an edge between two patches) get up to 3 correction passes that may take any neighbour's shifted address, compared in appearance space over three rings; a vertex that moves puts its neighbours back in the band, so seams move to where the patches agree and the rest of each patch stays as copied. Applies on meshes of 0.5 to 2 exemplar pixels per edge with a uniform scale (scale_by_height [1, 1]); skipped otherwise (metric refine_skipped says why)",
        },
        ParamDoc {
            name: "cache",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "read and write the seam refinement's appearance analysis (exemplar only) in the analysis cache, as jump_map's ($SURFSYNTH_CACHE, else $XDG_CACHE_HOME/surfsynth, else ~/.cache/surfsynth); results are the same either way",
        },
        ParamDoc {
            name: "pixel_aligned",
            unit: "",
            range: ParamRange::Any("true | false"),
            doc: "an extension: random starts at exemplar pixel centres; copies and jumps keep a start's sub-pixel phase, so a start between centres blurs its whole patch (bilinear resampling) wherever the mapping is pixel-aligned; false = anywhere (the paper)",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if Vec3::from(self.height_axis).length_squared() < 1e-12 {
            return Err(("height_axis".into(), "must not be the zero vector".into()));
        }
        Ok(())
    }
}

/// Per-vertex scale (pixels per world unit) for a mesh: `settings.scale`,
/// or `texture_scale` (the run's `[input] texture_scale`, pixels per unit)
/// when it is 0, times the `scale_by_height` ramp.
pub fn vertex_scales(
    positions: &[Vec3],
    settings: &JumpSurfaceSettings,
    texture_scale: f32,
) -> Vec<f32> {
    let base = if settings.scale > 0.0 {
        settings.scale
    } else {
        texture_scale
    };
    let [lo_f, hi_f] = settings.scale_by_height;
    if (lo_f - 1.0).abs() < 1e-9 && (hi_f - 1.0).abs() < 1e-9 {
        return vec![base; positions.len()];
    }
    let axis = Vec3::from(settings.height_axis).normalize_or_zero();
    let (lo, hi) = positions.iter().fold((f32::MAX, f32::MIN), |(lo, hi), p| {
        let h = p.dot(axis);
        (lo.min(h), hi.max(h))
    });
    let span = (hi - lo).max(1e-12);
    positions
        .iter()
        .map(|p| {
            let t = (p.dot(axis) - lo) / span;
            base * (lo_f + (hi_f - lo_f) * t)
        })
        .collect()
}

/// The `jump_surface` stage.
pub struct JumpSurface;

impl Stage for JumpSurface {
    const KIND: &'static str = "jump_surface";
    const SUMMARY: &'static str =
        "jump-map synthesis on the mesh: per-corner texture coordinates with a 3-way blend";
    const PAPER: &'static str = "Zelinka & Garland 2004 §6";
    type Settings = JumpSurfaceSettings;

    fn requires(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::Mesh, Datum::Frames, Datum::JumpMap]
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::CornerUvs]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        (move |mut commands: Commands,
               active: Res<ActiveMesh>,
               seed: Res<RunSeed>,
               map: Res<ExemplarJumpMap>,
               exemplar: Res<Exemplar>,
               texture_scale: Res<TextureScale>,
               mut spacing: ResMut<TexelSpacing>,
               mut metrics: ResMut<Metrics>,
               mut failure: ResMut<StageFailure>,
               meshes: Query<(&Geometry, &Frames)>| {
            let Ok((geometry, frames)) = meshes.get(active.0) else {
                fail(
                    &mut failure,
                    ctx.index,
                    Self::KIND,
                    "the active mesh has no tangent frames",
                );
                return;
            };
            let mesh = &geometry.0;
            if frames.0.len() != mesh.vertex_count() {
                fail(
                    &mut failure,
                    ctx.index,
                    Self::KIND,
                    "tangent frames do not match the mesh",
                );
                return;
            }
            let started = std::time::Instant::now();
            let map = &*map.0;
            let scales = vertex_scales(&mesh.positions, &settings, texture_scale.texels_per_unit);
            let topo = {
                let _s = tracing::info_span!("topology").entered();
                Topology::build(mesh)
            };
            let offsets = {
                let _s = tracing::info_span!("edge_offsets").entered();
                edge_offsets(&mesh.positions, &frames.0, &scales, &topo)
            };
            let synth = SurfaceSynthSettings {
                patch_fraction: settings.patch_fraction,
                boundary_fraction: settings.boundary_fraction,
                tileable: map.boundary() == Boundary::Toroidal,
                order: settings.order,
                seed: seed.derive(ctx.index, 0),
                max_patch_area: settings.max_patch_area,
                pixel_aligned: settings.pixel_aligned,
            };
            let progress =
                crate::progress::Progress::new(mesh.vertex_count() as u64, "jump_surface");
            let _finish = progress.finish_on_drop();
            let out = {
                let _s = tracing::info_span!("synthesize").entered();
                let matcher = (settings.choice == "matched").then_some(Matcher {
                    image: &exemplar.image,
                    wrap: exemplar.wrap,
                });
                synthesize_surface_matched(&topo, &offsets, map, &synth, matcher, &progress)
            };
            progress.finish();
            let synthesis_seconds = started.elapsed().as_secs_f64();
            let uniform = scales.iter().all(|&s| s == scales[0]);
            // Exemplar pixels per edge, on average.
            let texels_per_edge =
                offsets.iter().map(|o| o.length()).sum::<f32>() / offsets.len().max(1) as f32;
            let fine = (REFINE_MIN_TEXELS_PER_EDGE..=REFINE_MAX_TEXELS_PER_EDGE)
                .contains(&texels_per_edge);
            let refine = settings.refine == "seams" && uniform && fine && !scales.is_empty();
            let band = refine.then(|| {
                seam_band(&topo, &out.patch, REFINE_BAND_RINGS)
            });
            metrics.record(ctx.index, "texels_per_edge", texels_per_edge);
            if settings.refine == "seams" && !uniform {
                metrics.record(ctx.index, "refine_skipped", "scale_by_height is not [1, 1]");
            } else if settings.refine == "seams" && !fine {
                metrics.record(
                    ctx.index,
                    "refine_skipped",
                    format!(
                        "{texels_per_edge:.2} exemplar pixels per edge, outside {REFINE_MIN_TEXELS_PER_EDGE}..={REFINE_MAX_TEXELS_PER_EDGE}"
                    ),
                );
            }
            // The per-edge offsets and, after the refinement, the topology
            // (some 180 bytes per vertex together) go before the texture
            // coordinates are made.
            let sides = corner_side_offsets(mesh, &topo, &offsets);
            drop(offsets);
            let mut out = out;
            if let Some(band) = band {
                let _s = tracing::info_span!("refine_seams").entered();
                let refine_started = std::time::Instant::now();
                let kernel = CoherentSettings {
                    scale: scales[0],
                    seed: seed.derive(ctx.index, 1),
                    wrap: exemplar.wrap,
                    ..REFINE_SETTINGS
                };
                let store = crate::cache::DiskCache::if_enabled(settings.cache);
                let start: Vec<Vec2> = out.texel.iter().map(|&t| t + Vec2::splat(0.5)).collect();
                // Its own bar: on a large fine mesh the refinement can take
                // longer than the synthesis.
                let refine_progress = crate::progress::Progress::new(0, "jump_surface seams");
                let _finish = refine_progress.finish_on_drop();
                let level = SynthesisLevel {
                    mesh,
                    frames: &frames.0,
                };
                match coherent_refine(
                    &level,
                    Some(&topo),
                    &exemplar.image,
                    &kernel,
                    &start,
                    &band,
                    store.as_ref().map(|s| s as _),
                    &refine_progress,
                ) {
                    Ok(refined) => {
                        let moved = refined
                            .coords
                            .iter()
                            .zip(&start)
                            .filter(|(a, b)| a != b)
                            .count();
                        for (t, c) in out.texel.iter_mut().zip(&refined.coords) {
                            *t = *c - Vec2::splat(0.5);
                        }
                        metrics.record(
                            ctx.index,
                            "refine_band_vertices",
                            band.iter().filter(|&&b| b).count(),
                        );
                        metrics.record(ctx.index, "refine_moved_vertices", moved);
                        metrics.record(ctx.index, "refine_energy", refined.report.energy);
                        metrics.record(ctx.index, "refine_visited", refined.report.visited);
                        metrics.record(
                            ctx.index,
                            "refine_analysis_seconds",
                            refined.report.analysis_seconds,
                        );
                        metrics.record(
                            ctx.index,
                            "refine_analysis_cached",
                            refined.report.analysis_cached,
                        );
                    }
                    Err(e) => {
                        fail(&mut failure, ctx.index, Self::KIND, format!("refine: {e}"));
                        return;
                    }
                }
                // With the appearance analysis (exemplar only) included.
                refine_progress.finish();
                metrics.record(
                    ctx.index,
                    "refine_seconds",
                    refine_started.elapsed().as_secs_f64(),
                );
            }
            drop(topo);
            let (single, blend) = {
                let _s = tracing::info_span!("corner_uvs").entered();
                // The side offsets move into the compact blend layers.
                corner_uvs(mesh, sides, &out.texel, (map.width(), map.height()))
            };
            let secs = started.elapsed().as_secs_f64();
            let n = mesh.vertex_count();
            metrics.record(ctx.index, "vertices", n);
            metrics.record(ctx.index, "vertices_per_second", n as f64 / secs.max(1e-9));
            metrics.record(ctx.index, "synthesis_seconds", synthesis_seconds);
            metrics.record(ctx.index, "jumps", out.jumps);
            metrics.record(ctx.index, "random_assignments", out.random_assignments);
            metrics.record(ctx.index, "matched_starts", out.matched_starts);
            metrics.record(ctx.index, "unfit_vertices", out.unfit);
            let mean_scale = scales.iter().sum::<f32>() / scales.len().max(1) as f32;
            metrics.record(ctx.index, "mean_scale_pixels_per_unit", mean_scale);
            if mean_scale > 0.0 {
                spacing.0 = 1.0 / mean_scale;
            }
            let mut texels = out.texel;
            for p in &mut texels {
                *p += Vec2::splat(0.5);
            }
            commands.entity(active.0).insert((
                CornerUvs(single),
                BlendUvs(blend),
                SourceTexels(texels),
                VertexScale(scales),
            ));
        })
        .into_configs()
    }
}
