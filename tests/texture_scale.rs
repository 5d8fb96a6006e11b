//! One texture scale for every method (issue 14): `[input] texture_scale`
//! is relative to the mesh's bounding-box diagonal, so every method gives
//! the same result on a mesh scaled by 0.01 or 100 or moved 1000 units
//! away, and every method synthesises at the scale it was asked for.

mod common;

use bevy_ecs::prelude::*;
use glam::Vec3;
use surfsynth::config::ConfigSource;
use surfsynth::pipeline::{Pipeline, load_input, run_in_world};
use surfsynth::stages::lapped_paste::components::{PasteOrder, PatchFaces, PatchUvs};
use surfsynth::stages::world::*;

const HEADER: &str = r#"
seed = 5
[input]
mesh = "builtin:torus"
exemplar = "builtin:bricks"
exemplar_wrap = "clamp"
texture_scale = 0.6
[input.mesh_options]
resolution = [24, 12]
[input.exemplar_options]
size = 32
"#;

/// The methods, each a pipeline after `HEADER` that leaves per-vertex
/// colours (and, for `bake`, an atlas).
const METHODS: [(&str, &str); 6] = [
    (
        "jump_surface",
        r#"
[[stage]]
kind = "orientation"
up = [0.0, 0.0, 1.0]
[[stage]]
kind = "jump_map"
cache = false
[[stage]]
kind = "jump_surface"
"#,
    ),
    (
        "graph_match",
        r#"
[[stage]]
kind = "subdivide_sqrt2"
[[stage]]
kind = "diffuse_orientation"
[[stage]]
kind = "graph_match"
region = 5.0
passes = [1]
"#,
    ),
    (
        "wei_levoy",
        r#"
[[stage]]
kind = "retile"
levels = 2
[[stage]]
kind = "orientation"
up = [0.0, 0.0, 1.0]
[[stage]]
kind = "init_colours"
[[stage]]
kind = "match"
passes = 1
[[stage]]
kind = "map_back"
"#,
    ),
    (
        "coherent",
        r#"
[[stage]]
kind = "retile"
levels = 2
[[stage]]
kind = "orientation"
up = [0.0, 0.0, 1.0]
[[stage]]
kind = "coherent"
[[stage]]
kind = "map_back"
"#,
    ),
    (
        "lapped",
        r#"
[[stage]]
kind = "tangent_field"
up = [0.0, 0.0, 1.0]
[[stage]]
kind = "lapped_paste"
"#,
    ),
    (
        "bake",
        r#"
[[stage]]
kind = "orientation"
up = [0.0, 0.0, 1.0]
[[stage]]
kind = "jump_map"
cache = false
[[stage]]
kind = "jump_surface"
[[stage]]
kind = "bake"
"#,
    ),
];

/// What a run leaves to compare.
struct Outcome {
    /// Per-vertex colours, or per-corner exemplar coordinates for methods
    /// that leave texture coordinates.
    values: Vec<f32>,
    stride: usize,
    /// Largest difference that is floating-point noise: 1/255 of a colour
    /// or half an exemplar texel.
    tolerance: f32,
    /// Effective exemplar texels per bounding-box diagonal of the result.
    texels_per_diagonal: f64,
    /// The resolved request, texels per diagonal.
    requested_per_diagonal: f64,
    baked: Option<Vec<f32>>,
}

fn run(text: &str, scale: f32, offset: Vec3) -> Outcome {
    let p = Pipeline::from_source(ConfigSource::from_text("scale.toml", text)).expect("valid");
    let mut input = load_input(&p.input, &p.source.base_dir, &p.source.file).expect("input");
    for q in &mut input.mesh.positions {
        *q = *q * scale + offset;
    }
    let mut w = World::new();
    run_in_world(&p, &mut w, input).expect("runs");
    if std::env::var("DEBUG_METRICS").is_ok() {
        eprintln!("{scale} {offset}: {:?}", w.resource::<Metrics>().stages.first());
    }
    let active = w.resource::<ActiveMesh>().0;
    let (values, stride, tolerance) = match w.get::<VertexColours>(active) {
        Some(c) => (c.values.clone(), c.channels, 1.0 / 255.0),
        None => {
            let width = w.resource::<Exemplar>().image.width as f32;
            let uvs: Vec<f32> = match w.get::<CornerUvs>(active) {
                Some(uvs) => uvs.0.iter().flat_map(|u| [u.x, u.y]).collect(),
                None => {
                    // Lapped textures: the pastes' faces and patch uvs, in
                    // paste order.
                    let mut pastes: Vec<(u32, Vec<f32>)> = w
                        .query::<(&PasteOrder, &PatchFaces, &PatchUvs)>()
                        .iter(&w)
                        .map(|(o, f, u)| {
                            let faces = f.0.iter().map(|&x| x as f32);
                            (o.0, faces.chain(u.0.iter().flat_map(|u| [u.x, u.y])).collect())
                        })
                        .collect();
                    assert!(!pastes.is_empty(), "colours, uvs or pastes");
                    pastes.sort_by_key(|p| p.0);
                    pastes.into_iter().flat_map(|p| p.1).collect()
                }
            };
            (uvs, 2, 0.5 / width)
        }
    };
    let (lo, hi) = w
        .get::<Geometry>(active)
        .unwrap()
        .0
        .bounding_box()
        .unwrap();
    let spacing = f64::from(w.resource::<TexelSpacing>().0);
    let baked = w
        .get_resource::<BakedAsset>()
        .filter(|b| b.colour.width > 0)
        .map(|b| b.colour.data.clone());
    Outcome {
        values,
        stride,
        tolerance,
        texels_per_diagonal: f64::from((hi - lo).length()) / spacing,
        requested_per_diagonal: f64::from(w.resource::<TextureScale>().texels_per_diagonal()),
        baked,
    }
}

/// Share of vertices (or corners) whose colour (or coordinate) differs
/// from `a`'s by more than floating-point noise.
fn changed_share(a: &Outcome, b: &Outcome) -> f64 {
    if a.values.len() != b.values.len() {
        return 1.0;
    }
    let n = a.values.len() / a.stride;
    let changed = a
        .values
        .chunks_exact(a.stride)
        .zip(b.values.chunks_exact(a.stride))
        .filter(|(x, y)| x.iter().zip(*y).any(|(p, q)| (p - q).abs() > a.tolerance))
        .count();
    changed as f64 / n.max(1) as f64
}

fn atlas_changed_share(a: &[f32], b: &[f32]) -> f64 {
    assert_eq!(a.len(), b.len(), "same atlas size");
    a.iter()
        .zip(b)
        .filter(|(x, y)| (**x - **y).abs() > 1.0 / 255.0)
        .count() as f64
        / a.len().max(1) as f64
}

/// Every method gives the same result on the mesh scaled by 0.01, by 100,
/// and moved by 1000 units, and reports the same texels per diagonal.
#[test]
fn every_method_is_invariant_to_the_mesh_scale_and_position() {
    let mut report = Vec::new();
    let mut failures = Vec::new();
    for (name, stages) in METHODS {
        let text = format!("{HEADER}{stages}");
        let base = run(&text, 1.0, Vec3::ZERO);
        for (scale, offset) in [
            (0.01, Vec3::ZERO),
            (100.0, Vec3::ZERO),
            (1.0, Vec3::splat(1000.0)),
        ] {
            let other = run(&text, scale, offset);
            let share = changed_share(&base, &other);
            let rel = (other.texels_per_diagonal / base.texels_per_diagonal - 1.0).abs();
            report.push(format!(
                "{name} x{scale} +{}: changed vertices {:.4}, texels/diagonal {:.3} vs {:.3}",
                offset.x, share, other.texels_per_diagonal, base.texels_per_diagonal
            ));
            if rel >= 1e-3 {
                failures.push(format!(
                    "{name} x{scale} +{offset}: texels per diagonal {} vs {}",
                    other.texels_per_diagonal, base.texels_per_diagonal
                ));
            }
            if share > 0.02 {
                failures.push(format!(
                    "{name} x{scale} +{offset}: {share} of the vertices changed"
                ));
            }
            if let (Some(a), Some(b)) = (&base.baked, &other.baked) {
                let s = atlas_changed_share(a, b);
                if s > 0.02 {
                    failures.push(format!("{name} x{scale} +{offset}: {s} of the atlas changed"));
                }
            }
        }
    }
    eprintln!("{}", report.join("\n"));
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// Given one `texture_scale`, every method synthesises within 10 % of the
/// same effective texels per bounding-box diagonal, and of the request.
#[test]
fn every_method_synthesises_at_the_requested_scale() {
    let mut got = Vec::new();
    for (name, stages) in METHODS {
        let o = run(&format!("{HEADER}{stages}"), 1.0, Vec3::ZERO);
        got.push((name, o.texels_per_diagonal, o.requested_per_diagonal));
    }
    let requested = got[0].2;
    let lo = got.iter().map(|g| g.1).fold(f64::INFINITY, f64::min);
    let hi = got.iter().map(|g| g.1).fold(0.0, f64::max);
    for (name, eff, req) in &got {
        assert!((req - requested).abs() < 1e-6 * requested, "{name}: {req}");
        assert!(
            (eff / req - 1.0).abs() <= 0.10,
            "{name}: effective {eff:.2} texels per diagonal vs requested {req:.2}: {got:?}"
        );
    }
    assert!(hi / lo <= 1.10, "methods disagree: {got:?}");
}
