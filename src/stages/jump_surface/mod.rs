//! Stage `jump_surface`: jump-map texture synthesis directly on the surface
//! (Zelinka & Garland 2004 §6). The mesh keeps its vertices; the result is
//! per-corner texture coordinates (one base vertex per face, for OBJ) plus
//! the three base-vertex layers of the §6.5 blend (for previews and bakes).
//! Texture scale is a parameter only: no remeshing.

use crate::config::params::{ParamDoc, ParamRange, StageSettings};
use crate::kernels::jump_map::Boundary;
use crate::kernels::jump_surface::{
    SurfaceSynthSettings, corner_side_offsets, corner_uvs, edge_offsets, synthesize_surface,
};
use crate::kernels::vertex_order::VertexOrder;
use crate::mesh::Topology;
use crate::pipeline::{Datum, Stage, StageCtx};
use crate::stages::world::*;
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
}

impl Default for JumpSurfaceSettings {
    fn default() -> Self {
        Self {
            scale: 0.0,
            scale_by_height: [1.0, 1.0],
            height_axis: [0.0, 1.0, 0.0],
            patch_fraction: 0.5,
            boundary_fraction: 0.2,
            order: VertexOrder::EmergingFront,
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
            };
            let progress =
                crate::progress::Progress::new(mesh.vertex_count() as u64, "jump_surface");
            let out = {
                let _s = tracing::info_span!("synthesize").entered();
                synthesize_surface(&topo, &offsets, map, &synth, &progress)
            };
            progress.finish();
            // The topology and the per-edge offsets (some 180 bytes per
            // vertex) go before the texture coordinates are made.
            let sides = corner_side_offsets(mesh, &topo, &offsets);
            drop((topo, offsets));
            let (single, blend) = {
                let _s = tracing::info_span!("corner_uvs").entered();
                // The side offsets move into the compact blend layers.
                corner_uvs(mesh, sides, &out.texel, (map.width(), map.height()))
            };
            let secs = started.elapsed().as_secs_f64();
            let n = mesh.vertex_count();
            metrics.record(ctx.index, "vertices", n);
            metrics.record(ctx.index, "vertices_per_second", n as f64 / secs.max(1e-9));
            metrics.record(ctx.index, "jumps", out.jumps);
            metrics.record(ctx.index, "random_assignments", out.random_assignments);
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
