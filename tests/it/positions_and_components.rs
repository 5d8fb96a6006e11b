//! Positions relative to the bounding box (`at_bbox`) and per-component
//! orientation fallbacks (issue 14): a bounding-box position resolves to
//! the same point as the equivalent world `at`, and keeps resolving to the
//! same place when the mesh is scaled and moved; every connected component
//! gets an orientation field even when no key or anchor is on it; bad
//! positions are refused before anything runs, naming the key.

use crate::common;

use bevy_ecs::prelude::*;
use glam::Vec3;
use surfsynth::mesh::PolyMesh;
use surfsynth::mesh::Topology;
use surfsynth::mesh::builtin::{BuiltinOptions, builtin_mesh};
use surfsynth::pipeline::PipelineError;
use surfsynth::world::FaceField;
use surfsynth::world::*;

/// Runs `config` on its input mesh, after `edit` changed that mesh.
fn world_with(config: &str, edit: impl FnOnce(&mut PolyMesh)) -> Result<World, PipelineError> {
    common::world_with(config, |input| edit(&mut input.mesh))
}

fn world_for(config: &str) -> World {
    common::world_for(config).expect("runs")
}

fn frames(w: &World) -> Vec<surfsynth::kernels::surface::frames::TangentFrame> {
    let e = w.resource::<ActiveMesh>().0;
    w.get::<Frames>(e).expect("frames").0.clone()
}

fn metric(w: &World, stage: usize, key: &str) -> serde_json::Value {
    w.resource::<Metrics>().stages[stage]
        .get(key)
        .unwrap_or_else(|| panic!("stage {stage} has no metric {key}"))
        .clone()
}

/// The world point of bounding-box fractions `f` on the torus of
/// [`TORUS`], written as a TOML array.
fn world_point(f: [f32; 3]) -> String {
    let opts = BuiltinOptions {
        resolution: [48, 16],
        ..Default::default()
    };
    let torus = builtin_mesh("torus", &opts).expect("torus");
    let (lo, hi) = torus.bounding_box().expect("a mesh");
    let q = lo + (hi - lo) * Vec3::from(f);
    format!("[{:?}, {:?}, {:?}]", q.x, q.y, q.z)
}

fn bbox_array(f: [f32; 3]) -> String {
    format!("[{:?}, {:?}, {:?}]", f[0], f[1], f[2])
}

/// Scaled by 100 and moved by 1000 on every axis. Positions near 1000 keep
/// about 1e-4 in f32, so normals differ by up to ~5e-4 and the frames by a
/// few 1e-3 (the tolerance below); a field that depended on the mesh's
/// units would differ by far more.
fn scale_and_move(mesh: &mut PolyMesh) {
    for p in &mut mesh.positions {
        *p = *p * 100.0 + Vec3::splat(1000.0);
    }
}

fn assert_same_frames(
    a: &[surfsynth::kernels::surface::frames::TangentFrame],
    b: &[surfsynth::kernels::surface::frames::TangentFrame],
    tol: f32,
    what: &str,
) {
    assert_eq!(a.len(), b.len(), "{what}: vertex counts");
    let worst = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x.t - y.t).length().max((x.n - y.n).length()))
        .fold(0.0f32, f32::max);
    assert!(
        worst <= tol,
        "{what}: frames differ by up to {worst} (allowed {tol})"
    );
}

/// The input of the position tests: a torus, so that nothing is symmetric
/// about the bounding box's centre in all three axes.
const TORUS: &str = r#"
seed = 3
[input]
mesh = "builtin:torus"
exemplar = "builtin:noise"
[input.mesh_options]
resolution = [48, 16]
"#;

const ORIENTATION: &str = r#"
[[stage]]
kind = "orientation"
mode = "field"
up = [0.0, 0.0, 1.0]
anchors = [{ POS_A, up = [0.0, 1.0, 0.0] }, { POS_B, up = [1.0, 0.0, 0.3] }]
singularities = [{ POS_S, kind = "source", strength = 0.2 }]
"#;

const DIFFUSE: &str = r#"
[[stage]]
kind = "diffuse_orientation"
keys = [{ POS_A, up = [0.0, 1.0, 0.0] }, { POS_B, up = [1.0, 0.0, 0.3] }]
sweep_anchor = { POS_S }
"#;

const TANGENT: &str = r#"
[[stage]]
kind = "tangent_field"
mode = "constraints"
patch_size = 0.1
constraints = [{ POS_A, up = [0.0, 1.0, 0.0], radius = 0.2 }, { POS_B, up = [1.0, 0.0, 0.3], radius = 0.2 }]
"#;

/// Fractions away from any symmetry of the torus, so the nearest vertex or
/// face is never a tie that rounding could flip.
const A: [f32; 3] = [0.93, 0.41, 0.57];
const B: [f32; 3] = [0.22, 0.08, 0.31];
const S: [f32; 3] = [0.61, 0.87, 0.45];

/// The torus config with `stage`, its positions written as `at_bbox`
/// (`bbox`) or as the equivalent world `at`.
fn with_positions(stage: &str, bbox: bool) -> String {
    let pos = |f: [f32; 3]| {
        if bbox {
            format!("at_bbox = {}", bbox_array(f))
        } else {
            format!("at = {}", world_point(f))
        }
    };
    format!("{TORUS}{stage}")
        .replace("POS_A", &pos(A))
        .replace("POS_B", &pos(B))
        .replace("POS_S", &pos(S))
}

#[test]
fn at_bbox_is_the_same_point_as_at_and_follows_the_mesh() {
    // orientation, field mode: anchors and a singularity.
    let by_bbox = with_positions(ORIENTATION, true);
    let by_world = with_positions(ORIENTATION, false);
    let a = world_for(&by_bbox);
    let b = world_for(&by_world);
    assert_same_frames(&frames(&a), &frames(&b), 1e-6, "orientation: at_bbox vs at");
    let moved = world_with(&by_bbox, scale_and_move).expect("runs");
    // The singularity's pull is measured in bounding-box diagonals, so the
    // whole field is the same on the scaled mesh.
    assert_same_frames(
        &frames(&a),
        &frames(&moved),
        1e-2,
        "orientation: scaled and moved",
    );
    assert_eq!(metric(&a, 0, "fallback_components"), 0);

    // diffuse_orientation: keys and the sweep anchor.
    let by_bbox = with_positions(DIFFUSE, true);
    let a = world_for(&by_bbox);
    let b = world_for(&with_positions(DIFFUSE, false));
    for key in ["key_vertices", "sweep_anchor"] {
        assert_eq!(metric(&a, 0, key), metric(&b, 0, key), "{key}");
    }
    assert_same_frames(&frames(&a), &frames(&b), 1e-6, "diffuse: at_bbox vs at");
    let moved = world_with(&by_bbox, scale_and_move).expect("runs");
    for key in ["key_vertices", "sweep_anchor"] {
        assert_eq!(
            metric(&a, 0, key),
            metric(&moved, 0, key),
            "{key} on the moved mesh"
        );
    }
    assert_same_frames(
        &frames(&a),
        &frames(&moved),
        1e-2,
        "diffuse: scaled and moved",
    );
    let sweep = |w: &World| {
        let e = w.resource::<ActiveMesh>().0;
        w.get::<SweepField>(e).expect("sweep").0.clone()
    };
    let (s0, s1) = (sweep(&a), sweep(&moved));
    let worst = s0
        .iter()
        .zip(&s1)
        .map(|(x, y)| (x * 100.0 - y).abs())
        .fold(0.0f32, f32::max);
    assert!(
        worst < 0.05,
        "the sweep scales with the mesh: off by {worst}"
    );

    // tangent_field constraints.
    let by_bbox = with_positions(TANGENT, true);
    let a = world_for(&by_bbox);
    let b = world_for(&with_positions(TANGENT, false));
    let moved = world_with(&by_bbox, scale_and_move).expect("runs");
    let faces = metric(&a, 0, "constraint_faces");
    assert_eq!(faces, metric(&b, 0, "constraint_faces"));
    assert_eq!(faces, metric(&moved, 0, "constraint_faces"));
    let field = |w: &World| {
        let e = w.resource::<ActiveMesh>().0;
        w.get::<FaceField>(e).expect("face field").t.clone()
    };
    let (f0, f1) = (field(&a), field(&moved));
    let worst = f0
        .iter()
        .zip(&f1)
        .map(|(x, y)| (x.normalize() - y.normalize()).length())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-2, "tangent field directions differ by {worst}");
}

/// Two icospheres of radius 1, centred at the origin and at (4, 0, 0).
fn two_spheres(mesh: &mut PolyMesh) {
    let opts = BuiltinOptions {
        subdivisions: 2,
        ..Default::default()
    };
    let one = builtin_mesh("icosphere", &opts).expect("icosphere");
    let n = one.vertex_count() as u32;
    let mut positions = one.positions.clone();
    positions.extend(one.positions.iter().map(|&p| p + Vec3::new(4.0, 0.0, 0.0)));
    let faces: Vec<Vec<u32>> = one
        .faces()
        .map(|f| f.to_vec())
        .chain(one.faces().map(|f| f.iter().map(|&v| v + n).collect()))
        .collect();
    *mesh = PolyMesh::from_polygons(positions, faces.iter().map(|f| &f[..]));
}

/// Every vertex's `t` is a unit vector in its tangent plane, and on the
/// component without a key most edges join directions less than 45° apart
/// (a smooth field; a sphere's field must turn somewhere, so not all; the
/// keyed sphere of this mesh has 95% such edges).
fn assert_tangent_and_smooth(w: &World, what: &str) {
    let e = w.resource::<ActiveMesh>().0;
    let mesh = &w.get::<Geometry>(e).expect("mesh").0;
    let frames = &w.get::<Frames>(e).expect("frames").0;
    let normals = mesh.vertex_normals();
    assert_eq!(frames.len(), mesh.vertex_count());
    for (v, (f, n)) in frames.iter().zip(&normals).enumerate() {
        assert!(
            (f.t.length() - 1.0).abs() < 1e-4 && f.t.dot(*n).abs() < 1e-3,
            "{what}: vertex {v} has t = {:?} for normal {n:?}",
            f.t
        );
    }
    let topo = Topology::build(mesh);
    let (count, of) = topo.components();
    assert_eq!(count, 2, "{what}: two components");
    let (mut smooth, mut total) = (0, 0);
    for &[a, b] in &topo.edges {
        if of[a as usize] == 1 {
            total += 1;
            if frames[a as usize].t.dot(frames[b as usize].t) > 0.7 {
                smooth += 1;
            }
        }
    }
    assert!(
        smooth as f32 >= 0.9 * total as f32,
        "{what}: only {smooth} of {total} edges of the keyless component are smooth"
    );
}

const TWO_COMPONENTS: &str = r#"
seed = 5
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:noise"
[input.exemplar_options]
size = 32
STAGES
"#;

#[test]
fn a_component_without_a_key_gets_a_smooth_tangent_field() {
    // Up along z: at the poles of the second sphere it is along the normal,
    // and the vertex nearest its centre decides whether the principal axis
    // is needed; either way the field must be tangent.
    for (what, stages) in [
        (
            "diffuse_orientation",
            r#"
[[stage]]
kind = "diffuse_orientation"
keys = [{ at = [-1.0, 0.0, 0.0], up = [0.0, 0.0, 1.0] }]
fallback_up = [0.0, 0.0, 1.0]
"#,
        ),
        (
            "diffuse_orientation on a sqrt2 hierarchy",
            r#"
[[stage]]
kind = "subdivide_sqrt2"
target_vertices = 2000

[[stage]]
kind = "diffuse_orientation"
keys = [{ at_bbox = [0.0, 0.5, 0.5], up = [0.0, 0.0, 1.0] }]
"#,
        ),
        (
            "orientation field",
            r#"
[[stage]]
kind = "orientation"
mode = "field"
up = [0.0, 0.0, 1.0]
anchors = [{ at = [-1.0, 0.0, 0.0], up = [0.0, 1.0, 1.0] }]
"#,
        ),
    ] {
        let config = TWO_COMPONENTS.replace("STAGES", stages);
        let w = world_with(&config, two_spheres).unwrap_or_else(|e| panic!("{what}: {e}"));
        let stage = if what.contains("hierarchy") { 1 } else { 0 };
        assert_eq!(metric(&w, stage, "fallback_components"), 1, "{what}");
        assert_tangent_and_smooth(&w, what);
        if what.starts_with("diffuse") {
            assert_eq!(metric(&w, stage, "fallback_vertices"), 0, "{what}");
            // The sweep is finite and continues on the second sphere after
            // the first one's values.
            let e = w.resource::<ActiveMesh>().0;
            let sweep = &w.get::<SweepField>(e).expect("sweep").0;
            let mesh = &w.get::<Geometry>(e).unwrap().0;
            let (_, of) = Topology::build(mesh).components();
            let key_component = of[0];
            let max_first = sweep
                .iter()
                .zip(&of)
                .filter(|&(_, &c)| c == key_component)
                .map(|(s, _)| *s)
                .fold(f32::NEG_INFINITY, f32::max);
            let min_second = sweep
                .iter()
                .zip(&of)
                .filter(|&(_, &c)| c != key_component)
                .map(|(s, _)| *s)
                .fold(f32::INFINITY, f32::min);
            assert!(sweep.iter().all(|s| s.is_finite()), "{what}");
            assert!(
                min_second >= max_first - 1e-3,
                "{what}: the second sphere's sweep starts at {min_second}, the first ends at {max_first}"
            );
        }
    }
    // tangent_field: the component without a constraint keeps the global
    // field (no automatic constraint needed), and says so.
    let config = TWO_COMPONENTS.replace(
        "STAGES",
        r#"
[[stage]]
kind = "tangent_field"
mode = "constraints"
constraints = [{ at = [-1.0, 0.0, 0.0], up = [0.0, 0.0, 1.0], radius = 0.1 }]
"#,
    );
    let w = world_with(&config, two_spheres).expect("runs");
    assert_eq!(metric(&w, 0, "fallback_components"), 1);
    let e = w.resource::<ActiveMesh>().0;
    let field = &w.get::<FaceField>(e).expect("face field").t;
    assert!(field.iter().all(|t| t.length() > 0.0 && t.is_finite()));
}

#[test]
fn bad_positions_are_refused_naming_the_key() {
    let base = r#"
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:noise"
"#;
    let cases = [
        (
            r#"[[stage]]
kind = "diffuse_orientation"
keys = [{ at = [0.0, 0.0, 1.0], at_bbox = [0.5, 0.5, 1.0], up = [0.0, 1.0, 0.0] }]"#,
            vec!["keys", "at_bbox", "not both"],
        ),
        (
            r#"[[stage]]
kind = "diffuse_orientation"
keys = [{ at_bbox = [2.0, 0.0, 0.0], up = [0.0, 1.0, 0.0] }]"#,
            vec!["keys", "at_bbox", "[0, 1]"],
        ),
        (
            r#"[[stage]]
kind = "diffuse_orientation"
sweep_anchor = { vertex = 1, at_bbox = [0.5, 0.5, 0.5] }"#,
            vec!["sweep_anchor", "at_bbox"],
        ),
        (
            r#"[[stage]]
kind = "orientation"
mode = "field"
anchors = [{ at = [0.0, 0.0, 1.0], at_bbox = [0.5, 0.5, 1.0], up = [0.0, 1.0, 0.0] }]"#,
            vec!["anchors", "at_bbox", "not both"],
        ),
        (
            r#"[[stage]]
kind = "orientation"
mode = "field"
singularities = [{ at_bbox = [2.0, 0.0, 0.0], kind = "sink" }]"#,
            vec!["singularities", "at_bbox", "[0, 1]"],
        ),
        (
            r#"[[stage]]
kind = "orientation"
mode = "field"
anchors = [{ up = [0.0, 1.0, 0.0] }]"#,
            vec!["anchors", "at_bbox"],
        ),
        (
            r#"[[stage]]
kind = "tangent_field"
mode = "constraints"
constraints = [{ at_bbox = [2.0, 0.0, 0.0], up = [0.0, 1.0, 0.0], radius = 0.1 }]"#,
            vec!["constraints", "at_bbox", "[0, 1]"],
        ),
        (
            r#"[[stage]]
kind = "tangent_field"
mode = "constraints"
constraints = [{ face = 0, at_bbox = [0.5, 0.5, 0.5], up = [0.0, 1.0, 0.0], radius = 0.1 }]"#,
            vec!["constraints", "at_bbox", "face"],
        ),
    ];
    for (stage, needles) in cases {
        let config = format!("{base}\n{stage}\n");
        common::expect_refused(&config, &[], &needles);
    }
}
