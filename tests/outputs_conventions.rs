//! Issue 16, outputs and conventions: OBJ exports carry vertex normals and a
//! smoothing group, MTL files mark non-colour maps, every per-corner-UV
//! result writes `result.ply` with vertex colours, and relative paths
//! resolve against the config file's folder (`--set` and text configs:
//! against the current directory).

mod common;
use bevy_ecs::prelude::*;
use common::*;
use glam::{Vec2, Vec3};
use std::path::Path;
use surfsynth::config::ConfigSource;
use surfsynth::image::sample::Wrap;
use surfsynth::pipeline::{Pipeline, load_input, run_in_world};
use surfsynth::stages::world::*;

/// A small jump-map pipeline on a builtin sphere, exporting `formats`.
fn jump_config(formats: &str) -> String {
    format!(
        r#"
seed = 5
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
exemplar_wrap = "repeat"
[input.mesh_options]
subdivisions = 2
[input.exemplar_options]
size = 32

[[stage]]
kind = "orientation"
up = [0.0, 0.0, 1.0]

[[stage]]
kind = "jump_map"
cache = false

[[stage]]
kind = "jump_surface"
scale = 20.0

[[stage]]
kind = "export"
formats = {formats}
"#
    )
}

/// A vertex-colour pipeline (no texture coordinates) exporting `formats`.
fn colour_config(formats: &str) -> String {
    format!(
        r#"
seed = 5
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.mesh_options]
subdivisions = 2
[input.exemplar_options]
size = 32

[[stage]]
kind = "orientation"

[[stage]]
kind = "init_colours"

[[stage]]
kind = "export"
formats = {formats}
"#
    )
}

/// Runs `text` in a world; returns the world and the files its export job
/// writes into `dir`.
fn run_and_write(text: &str, dir: &Path) -> World {
    let p = Pipeline::from_source(ConfigSource::from_text("t.toml", text)).expect("valid config");
    let input = load_input(&p.input, &p.source.base_dir, &p.source.file).expect("inputs load");
    let mut w = World::new();
    run_in_world(&p, &mut w, input).expect("the pipeline runs");
    surfsynth::output::export::write_export(dir, w.resource::<ExportJob>()).expect("files write");
    w
}

/// The `v`, `vn` and face-corner `(v, vt, vn)` references (0-based) of an OBJ text.
struct ObjText {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    corners: Vec<Vec<(usize, Option<usize>, Option<usize>)>>,
    smoothing: bool,
}

fn parse_obj(text: &str) -> ObjText {
    let mut obj = ObjText {
        positions: Vec::new(),
        normals: Vec::new(),
        corners: Vec::new(),
        smoothing: false,
    };
    let vec3 = |rest: &mut std::str::SplitWhitespace| {
        let mut x = [0.0f32; 3];
        for v in &mut x {
            *v = rest.next().expect("3 numbers").parse().expect("a number");
        }
        Vec3::from_array(x)
    };
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => obj.positions.push(vec3(&mut it)),
            Some("vn") => obj.normals.push(vec3(&mut it)),
            Some("s") => obj.smoothing |= it.next() == Some("1"),
            Some("f") => obj.corners.push(
                it.map(|c| {
                    let mut parts = c.split('/');
                    let index = |p: Option<&str>| {
                        p.filter(|s| !s.is_empty())
                            .map(|s| s.parse::<usize>().expect("an index") - 1)
                    };
                    let v = index(parts.next()).expect("a vertex index");
                    (v, index(parts.next()), index(parts.next()))
                })
                .collect(),
            ),
            _ => {}
        }
    }
    obj
}

/// Every face corner references a normal, one `vn` per referenced index,
/// unit length, equal to the mesh's vertex normal at the corner's vertex.
fn assert_normals_match(obj: &ObjText, mesh: &surfsynth::mesh::PolyMesh, what: &str) {
    assert!(obj.smoothing, "{what}: no `s 1` smoothing group");
    assert_eq!(obj.positions.len(), mesh.vertex_count(), "{what}");
    assert_eq!(obj.corners.len(), mesh.face_count(), "{what}");
    let expected = mesh.vertex_normals();
    let mut referenced = vec![false; obj.normals.len()];
    for (f, face) in obj.corners.iter().enumerate() {
        for &(v, _, n) in face {
            let n = n.unwrap_or_else(|| panic!("{what}: face {f} has a corner without a normal"));
            assert!(n < obj.normals.len(), "{what}: vn {} missing", n + 1);
            referenced[n] = true;
            let normal = obj.normals[n];
            assert!(
                (normal.length() - 1.0).abs() < 1e-5,
                "{what}: vn {} has length {}",
                n + 1,
                normal.length()
            );
            assert!(
                normal.distance(expected[v]) < 1e-6,
                "{what}: corner of vertex {v} has normal {normal}, the mesh's is {}",
                expected[v]
            );
        }
    }
    assert!(
        referenced.iter().all(|&r| r),
        "{what}: {} normals, not all referenced",
        obj.normals.len()
    );
}

#[test]
fn obj_exports_carry_unit_vertex_normals_and_a_smoothing_group() {
    let dir = tempfile::tempdir().unwrap();
    // Per-corner UVs (f v/vt/vn) and vertex colours (f v//vn).
    for (name, text) in [
        ("jump", jump_config(r#"["obj"]"#)),
        ("colours", colour_config(r#"["obj"]"#)),
    ] {
        let out = dir.path().join(name);
        let w = run_and_write(&text, &out);
        let mesh = &w.resource::<ExportJob>().mesh;
        let obj = parse_obj(&std::fs::read_to_string(out.join("result.obj")).unwrap());
        assert_normals_match(&obj, mesh, name);
        let with_uv = obj.corners.iter().flatten().all(|c| c.1.is_some());
        assert_eq!(with_uv, name == "jump", "{name}: texture references");
    }
}

#[test]
fn baked_obj_is_smooth_and_its_mtl_marks_non_colour_maps() {
    let dir = tempfile::tempdir().unwrap();
    let text = jump_config(r#"["baked_obj"]"#)
        .replace(
            "exemplar_wrap = \"repeat\"",
            "exemplar_wrap = \"repeat\"\nheight_map = \"derive:luminance\"\nnormal_map = \"derive:height\"\nroughness_map = \"derive:luminance\"",
        )
        .replace(
            "[[stage]]\nkind = \"export\"",
            "[[stage]]\nkind = \"bake\"\nsize = 256\n\n[[stage]]\nkind = \"export\"",
        );
    let w = run_and_write(&text, dir.path());
    let asset = w.resource::<BakedAsset>();
    let obj = parse_obj(&std::fs::read_to_string(dir.path().join("result_atlas.obj")).unwrap());
    assert_normals_match(&obj, &asset.mesh, "baked_obj");
    let mtl = std::fs::read_to_string(dir.path().join("result_atlas.mtl")).unwrap();
    for line in [
        "map_Kd result_atlas.png",
        "norm result_atlas_normal.png",
        "map_Bump -bm 1 result_atlas_normal.png",
        "map_Pr result_atlas_roughness.png",
        "disp result_atlas_height.png",
    ] {
        assert!(mtl.lines().any(|l| l == line), "{line:?} missing:\n{mtl}");
    }
}

/// The vertex count and RGB(A) bytes of a binary PLY written by surfsynth
/// (`float x y z`, then `uchar red green blue [alpha]`).
fn read_ply_colours(bytes: &[u8]) -> (usize, usize, Vec<u8>) {
    let end = b"end_header\n";
    let header_len = bytes
        .windows(end.len())
        .position(|w| w == end)
        .expect("a PLY header")
        + end.len();
    let header = std::str::from_utf8(&bytes[..header_len]).unwrap();
    let count: usize = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .expect("a vertex element")
        .parse()
        .unwrap();
    let channels = ["red", "green", "blue", "alpha"]
        .iter()
        .filter(|c| header.contains(&format!("property uchar {c}\n")))
        .count();
    let stride = 12 + channels;
    let colours = (0..count)
        .flat_map(|v| {
            let at = header_len + v * stride + 12;
            bytes[at..at + channels].to_vec()
        })
        .collect();
    (count, channels, colours)
}

#[test]
fn jump_surface_ply_has_the_blended_exemplar_colour_at_each_vertex() {
    let dir = tempfile::tempdir().unwrap();
    let w = run_and_write(&jump_config(r#"["ply"]"#), dir.path());
    let bytes = std::fs::read(dir.path().join("result.ply")).expect("result.ply written");
    let (count, channels, colours) = read_ply_colours(&bytes);
    let active = w.resource::<ActiveMesh>().0;
    let mesh = &w.get::<Geometry>(active).unwrap().0;
    let blend = &w.get::<BlendUvs>(active).expect("blend layers").0;
    let exemplar = w.resource::<Exemplar>();
    assert_eq!(count, mesh.vertex_count());
    assert_eq!(channels, 3, "RGB exemplar, RGB colours");
    // The oracle: at triangle corner k the 3-way blend is the exemplar at the
    // UV of base k, layer k; averaged over the vertex's corners.
    let (tris, _) = mesh.triangulate_corners();
    let mut sum = vec![[0.0f64; 3]; count];
    let mut n = vec![0u32; count];
    let mut px = [0.0f32; 3];
    for (tri, layer) in tris.iter().zip(blend) {
        for k in 0..3 {
            let v = mesh.corner_vertex[tri[k] as usize] as usize;
            let uv: Vec2 = layer[k][k];
            exemplar.image.sample_uv(uv.x, uv.y, Wrap::Repeat, &mut px);
            for c in 0..3 {
                sum[v][c] += f64::from(px[c]);
            }
            n[v] += 1;
        }
    }
    // Tolerance: the 8-bit quantisation of the PLY (half a step) plus
    // float rounding.
    let tolerance = 0.5 / 255.0 + 1e-4;
    for v in 0..count {
        assert!(n[v] > 0, "vertex {v} has no corner");
        for c in 0..3 {
            let expected = sum[v][c] / f64::from(n[v]);
            let got = f64::from(colours[v * 3 + c]) / 255.0;
            assert!(
                (got - expected).abs() <= tolerance,
                "vertex {v} channel {c}: PLY {got}, exemplar blend {expected}"
            );
        }
    }
}
