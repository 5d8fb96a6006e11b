//! Stage `tangent_field`: the per-face tangential vector field `T` of lapped
//! textures (Praun et al. 2000 §3.2) on the active mesh — its direction is
//! the texture's up, its length the texture scale (world units per texture
//! patch width). Modes: a global up direction projected onto each face; a
//! few constraints interpolated with Gaussian radial basis functions over
//! mesh distance on top of that global field (Fig. 1, "changing local
//! orientation and scale"); or the `t` axes of the `orientation` stage's
//! frames. With `isotropic = true` only the scale is used and each paste
//! propagates its own orientation.
//!
//! Constraint positions are face ids, world points (`at`) or fractions of
//! the mesh's bounding box (`at_bbox`, [`crate::stages::position`]). The
//! Gaussians spread over edges and never reach a connected component
//! without a constraint; that component keeps the global field, `up`
//! projected onto its faces (metric `fallback_components`), which is
//! already smooth, so it needs no automatic constraint.
//!
//! Lapped textures work on triangles: a polygon mesh is fan-triangulated
//! into a new active mesh level first.
//!
//! Reads: `ActiveMesh` (`Geometry`, `Frames` in frames mode),
//! `TextureScale`. Writes: `FaceField` on the active mesh (or on the new
//! triangulated level, which becomes the active mesh), metrics.

use crate::config::params::{ParamDoc, ParamRange, StageSettings, to_json};
use crate::kernels::lapped::TriMesh;
use crate::kernels::lapped::tangent_field::{
    FieldConstraint, field_from_vertex_frames, global_up_field, nearest_face, rbf_field,
};
use crate::kernels::surface::component_fallback::{Components, unseeded_components};
use crate::mesh::Topology;
use crate::stage::memory::{InputSizes, MemoryEstimate};
use crate::stage::{Datum, Stage, StageCtx, SystemResult};
use crate::stages::position;
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use glam::Vec3;
use serde::{Deserialize, Serialize};

/// Where the field comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FieldMode {
    /// `up` projected onto every face.
    #[default]
    Global,
    /// `constraints` interpolated over the global field.
    Constraints,
    /// The `t` axes of the per-vertex frames of an `orientation` stage.
    Frames,
}

/// Unit of lengths (`patch_size`, constraint radii).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LengthUnit {
    /// Fractions of the mesh's bounding-box diagonal.
    #[default]
    Diagonal,
    /// World units.
    World,
}

/// A constraint in the config:
/// `{ at = [x, y, z], up = [x, y, z], scale = 1.0, radius = 0.2, weight = 1.0 }`
/// (or `face = N` or `at_bbox = [u, v, w]` instead of `at`; exactly one).
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConstraintSpec {
    /// The face it sits on, or...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub face: Option<u32>,
    /// ...a point whose nearest face (by centroid) takes it, or...
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<[f32; 3]>,
    /// ...a point as fractions `[0, 1]` of the mesh's bounding box (0 =
    /// minimum, 1 = maximum), whose nearest face takes it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at_bbox: Option<[f32; 3]>,
    /// Texture up direction there (world space, projected onto the face).
    pub up: [f32; 3],
    /// Texture scale there, relative to `patch_size` (> 0).
    #[serde(default = "one")]
    pub scale: f32,
    /// Radius of the Gaussian, in `units` (> 0).
    pub radius: f32,
    /// Weight of the basis function (> 0).
    #[serde(default = "one")]
    pub weight: f32,
}

fn one() -> f32 {
    1.0
}

/// Settings of `tangent_field`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TangentFieldSettings {
    /// Global, constraints or frames.
    pub mode: FieldMode,
    /// The global up direction.
    pub up: [f32; 3],
    /// Isotropic texture (orientation propagated per paste).
    pub isotropic: bool,
    /// World size of one texture patch, in `units`; 0 = the texture scale
    /// of `[input] texture_scale`.
    pub patch_size: f64,
    /// Unit of `patch_size` and of constraint radii.
    pub units: LengthUnit,
    /// Constraints mode: the constraints.
    pub constraints: Vec<ConstraintSpec>,
    /// Constraints mode: weight of the global field against the Gaussians.
    pub background_weight: f64,
}

impl Default for TangentFieldSettings {
    fn default() -> Self {
        Self {
            mode: FieldMode::Global,
            up: [0.0, 1.0, 0.0],
            isotropic: false,
            patch_size: 0.0,
            units: LengthUnit::Diagonal,
            constraints: Vec::new(),
            background_weight: 0.05,
        }
    }
}

impl StageSettings for TangentFieldSettings {
    const PARAMS: &'static [ParamDoc] = &[
        ParamDoc {
            name: "mode",
            unit: "",
            range: ParamRange::OneOf(&["global", "constraints", "frames"]),
            doc: "global: `up` projected onto every face; constraints: Gaussian RBF interpolation of `constraints` over mesh distance, blended with the global field; frames: the t axes of an earlier `orientation` stage",
        },
        ParamDoc {
            name: "up",
            unit: "world axes",
            range: ParamRange::Float(-1e6, 1e6),
            doc: "texture up direction in world space (non-zero); where it is parallel to a face normal an arbitrary tangent is used",
        },
        ParamDoc {
            name: "isotropic",
            unit: "",
            range: ParamRange::Any("true or false"),
            doc: "isotropic texture: only the scale is used, each paste propagates its own random orientation (Praun et al. §3.2)",
        },
        ParamDoc {
            name: "patch_size",
            unit: "units",
            range: ParamRange::Float(0.0, 1e6),
            doc: "world size of one texture patch (its larger side), the length of T; 0 = from the run's `[input] texture_scale`: a patch of p exemplar pixels spans p / (exemplar pixels per unit), the same scale as every other method; a value here overrides it",
        },
        ParamDoc {
            name: "units",
            unit: "",
            range: ParamRange::OneOf(&["diagonal", "world"]),
            doc: "unit of patch_size and constraint radii: fractions of the bounding-box diagonal, or world units",
        },
        ParamDoc {
            name: "constraints",
            unit: "",
            range: ParamRange::Any(
                "list of { face = N | at = [x, y, z] | at_bbox = [u, v, w], up = [x, y, z], scale = 1.0, radius = R, weight = 1.0 }",
            ),
            doc: "constraints mode: direction, relative scale, Gaussian radius (in units) and weight at a face, or at the face nearest a point given in world coordinates (`at`) or as fractions 0..1 of the mesh's bounding box (`at_bbox`, 0 = min, 1 = max); a connected component without a constraint keeps the global field",
        },
        ParamDoc {
            name: "background_weight",
            unit: "",
            range: ParamRange::Float(0.0, 1e6),
            doc: "constraints mode: weight of the global field where the Gaussians fade out",
        },
    ];

    fn check(&self) -> Result<(), (String, String)> {
        if Vec3::from(self.up).length_squared() < 1e-12 {
            return Err(("up".into(), "must not be the zero vector".into()));
        }
        if !(self.patch_size.is_finite() && self.patch_size >= 0.0) {
            return Err((
                "patch_size".into(),
                "must be positive, or 0 for [input] texture_scale".into(),
            ));
        }
        if self.mode == FieldMode::Constraints && self.constraints.is_empty() {
            return Err((
                "mode".into(),
                "constraints mode needs at least one entry in `constraints`".into(),
            ));
        }
        for (i, c) in self.constraints.iter().enumerate() {
            let what = format!("constraint {}", i + 1);
            position::check(c.at, c.at_bbox)
                .map_err(|m| ("constraints".to_string(), format!("{what}: {m}")))?;
            let given = [c.face.is_some(), c.at.is_some(), c.at_bbox.is_some()];
            if given.iter().filter(|&&g| g).count() != 1 {
                return Err((
                    "constraints".into(),
                    format!("{what}: give exactly one of `face`, `at` and `at_bbox`"),
                ));
            }
            if Vec3::from(c.up).length_squared() < 1e-12 {
                return Err(("constraints".into(), format!("{what}: `up` is zero")));
            }
            for (name, v) in [
                ("scale", c.scale),
                ("radius", c.radius),
                ("weight", c.weight),
            ] {
                if !(v > 0.0 && v.is_finite()) {
                    return Err((
                        "constraints".into(),
                        format!("{what}: `{name}` = {v} must be positive"),
                    ));
                }
            }
        }
        Ok(())
    }
}

/// Computes the field of `settings` on a triangle mesh; `frames` are the
/// per-vertex frames for `frames` mode; `texels_per_unit` is the run's
/// texture scale (exemplar pixels per world unit), used when
/// `patch_size` is 0. Errors name what to fix.
pub fn face_field(
    mesh: &crate::mesh::PolyMesh,
    tri: &TriMesh,
    settings: &TangentFieldSettings,
    frames: Option<&[crate::kernels::surface::frames::TangentFrame]>,
    texels_per_unit: f32,
) -> Result<(FaceField, serde_json::Map<String, serde_json::Value>), String> {
    let mut metrics = serde_json::Map::new();
    let bbox = mesh.bounding_box();
    let diagonal = bbox.map_or(1.0, |(lo, hi)| (hi - lo).length().max(f32::MIN_POSITIVE));
    let unit = match settings.units {
        LengthUnit::Diagonal => diagonal,
        LengthUnit::World => 1.0,
    };
    let per_pixel = settings.patch_size == 0.0;
    let scale = if per_pixel {
        1.0 / texels_per_unit.max(f32::MIN_POSITIVE)
    } else {
        settings.patch_size as f32 * unit
    };
    let up = Vec3::from(settings.up);
    let t = match settings.mode {
        FieldMode::Global => global_up_field(tri, up, scale),
        FieldMode::Frames => {
            let frames = frames.ok_or("frames mode needs an `orientation` stage before it")?;
            if frames.len() != mesh.vertex_count() {
                return Err(format!(
                    "the frames have {} entries for {} vertices; run `orientation` on this mesh",
                    frames.len(),
                    mesh.vertex_count()
                ));
            }
            field_from_vertex_frames(tri, frames, scale, up)
        }
        FieldMode::Constraints => {
            let mut constraints = Vec::with_capacity(settings.constraints.len());
            for (i, c) in settings.constraints.iter().enumerate() {
                let at = position::resolve(c.at, c.at_bbox, bbox)
                    .map_err(|m| format!("constraints: constraint {}: {m}", i + 1))?;
                let face = match (c.face, at) {
                    (Some(f), _) => f,
                    (None, Some(p)) => nearest_face(tri, p),
                    (None, None) => {
                        return Err(format!(
                            "constraints: constraint {}: give `face`, `at` or `at_bbox`",
                            i + 1
                        ));
                    }
                };
                constraints.push(FieldConstraint {
                    face,
                    direction: Vec3::from(c.up),
                    scale: c.scale,
                    radius: c.radius * unit,
                    weight: c.weight,
                });
            }
            let background = global_up_field(tri, up, 1.0);
            let topo = Topology::build(mesh);
            // Components without a constraint keep the background field.
            let (count, of_vertex) = topo.components();
            let constrained: Vec<u32> = constraints
                .iter()
                .filter_map(|c| tri.tris.get(c.face as usize).map(|t| t[0]))
                .collect();
            let unconstrained = unseeded_components(
                Components {
                    count,
                    of_vertex: &of_vertex,
                },
                &constrained,
            );
            metrics.insert("fallback_components".into(), unconstrained.len().into());
            let (t, report) = rbf_field(
                tri,
                &topo,
                &constraints,
                &background,
                settings.background_weight as f32,
                scale,
            )
            .map_err(|e| e.to_string())?;
            metrics.insert("rbf_exact".into(), report.exact.into());
            metrics.insert(
                "constraint_faces".into(),
                constraints
                    .iter()
                    .map(|c| c.face)
                    .collect::<Vec<_>>()
                    .into(),
            );
            t
        }
    };
    let lengths: Vec<f32> = t.iter().map(|v| v.length()).collect();
    let mean = lengths.iter().map(|&l| l as f64).sum::<f64>() / lengths.len().max(1) as f64;
    let (lo, hi) = lengths
        .iter()
        .fold((f32::INFINITY, 0.0f32), |(a, b), &l| (a.min(l), b.max(l)));
    metrics.insert(
        if per_pixel {
            "world_units_per_pixel"
        } else {
            "patch_size_world"
        }
        .into(),
        to_json(&scale),
    );
    metrics.insert("scale_mean".into(), mean.into());
    metrics.insert("scale_min".into(), to_json(&lo));
    metrics.insert("scale_max".into(), to_json(&hi));
    Ok((
        FaceField {
            t,
            isotropic: settings.isotropic,
            per_pixel,
        },
        metrics,
    ))
}

/// The `tangent_field` stage.
pub struct TangentField;

impl Stage for TangentField {
    const KIND: &'static str = "tangent_field";
    const SUMMARY: &'static str = "per-face texture up and scale for lapped textures: global up, RBF-interpolated constraints, or frames";
    const PAPER: &'static str = "Praun, Finkelstein & Hoppe 2000 §3.2";
    type Settings = TangentFieldSettings;

    /// The per-face field, about 120 bytes a vertex (two faces a vertex),
    /// and in constraints mode the edge graph and the Gaussians' distances
    /// over it, about 290 (measured: `tests/memory_estimates.rs`).
    fn memory_estimate(settings: &Self::Settings, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        let per_vertex = match settings.mode {
            FieldMode::Constraints => 290,
            FieldMode::Global | FieldMode::Frames => 120,
        };
        MemoryEstimate::per_vertex("the per-face tangent field", sizes, 0, per_vertex)
    }
    fn requires(settings: &Self::Settings) -> Vec<Datum> {
        if settings.mode == FieldMode::Frames {
            vec![Datum::Mesh, Datum::Frames]
        } else {
            vec![Datum::Mesh]
        }
    }
    fn produces(_: &Self::Settings) -> Vec<Datum> {
        vec![Datum::FaceField]
    }
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        let field = move |mut commands: Commands,
                          mut active: ResMut<ActiveMesh>,
                          texture_scale: Res<TextureScale>,
                          mut metrics: ResMut<Metrics>,
                          meshes: Query<(&Geometry, Option<&Frames>)>|
              -> SystemResult {
            let Ok((geometry, frames)) = meshes.get(active.0) else {
                return Ok(());
            };
            // Lapped textures need triangles: fan-triangulate polygons
            // into a new mesh level (vertices, and so frames, unchanged).
            let triangulated = (!geometry.0.is_triangle_mesh()).then(|| geometry.0.triangulated());
            let mesh = triangulated.as_ref().unwrap_or(&geometry.0);
            let tri = TriMesh::new(mesh).map_err(|e| e.to_string())?;
            let frames = frames.map(|f| f.0.as_slice());
            let (field, stage_metrics) =
                face_field(mesh, &tri, &settings, frames, texture_scale.texels_per_unit)?;
            for (k, v) in stage_metrics {
                metrics.record(ctx.index, &k, v);
            }
            metrics.record(ctx.index, "faces", tri.face_count());
            metrics.record(ctx.index, "triangulated", triangulated.is_some());
            match triangulated {
                Some(mesh) => {
                    let mut entity = commands.spawn((MeshLevel(0), Geometry(mesh), field));
                    if let Some(f) = frames {
                        entity.insert(Frames(f.to_vec()));
                    }
                    active.0 = entity.id();
                }
                None => {
                    commands.entity(active.0).insert(field);
                }
            }
            Ok(())
        };
        ctx.fallible(Self::KIND, field)
    }
}
