//! Mapping a result on the retiled surface back onto the ORIGINAL input mesh
//! (Wei & Levoy 2001 §5, stage `map_back`): a smooth colour function given on
//! the retiled mesh comes back at the original vertices; matched texels and
//! frames follow; boundaries and several components work; bad input is a
//! typed error; the CLI writes `<stem>_original.ply`.

use crate::common;

use glam::{Vec2, Vec3};
use surfsynth::kernels::surface::frames::TangentFrame;
use surfsynth::kernels::wei_levoy::retile::{
    MapBackError, ResultAttributes, RetileSettings, map_back, retile,
};
use surfsynth::mesh::builtin::{BuiltinOptions, builtin_mesh};
use surfsynth::mesh::{LoadOptions, PolyMesh, load_mesh};

/// A smooth RGB function of position, in [0, 1].
fn smooth(p: Vec3) -> [f32; 3] {
    [
        0.5 + 0.5 * (2.0 * p.x).sin(),
        0.5 + 0.5 * (1.5 * p.y + 0.3).cos(),
        0.5 + 0.25 * (p.z * 2.0).sin() + 0.25 * (p.x * p.y),
    ]
}

struct Case {
    /// Mean and largest per-channel error at the original vertices.
    mean: f32,
    max: f32,
    /// Largest distance of an original vertex to the retiled surface, in
    /// retiled mean edge lengths.
    max_distance_edges: f32,
    /// Retiled mean edge length.
    edge: f32,
}

/// Retiles `input`, defines [`smooth`] plus a texel (its own vertex id) and a
/// frame on the finest level, maps them back onto `input` and checks them.
fn map_smooth_function_back(name: &str, input: &PolyMesh, vertices: u32) -> Case {
    let settings = RetileSettings {
        levels: 1,
        ..RetileSettings::with_vertices(vertices)
    };
    let pyramid = retile(input, &settings).unwrap_or_else(|e| panic!("{name}: {e}"));
    let result = &pyramid.levels[0].mesh;
    let colours: Vec<f32> = result.positions.iter().flat_map(|&p| smooth(p)).collect();
    let texels: Vec<Vec2> = (0..result.vertex_count())
        .map(|v| Vec2::new(v as f32 + 0.5, 0.5))
        .collect();
    let normals = result.vertex_normals();
    let frames: Vec<TangentFrame> = normals
        .iter()
        .map(|&n| TangentFrame::from_up(n, Vec3::Y))
        .collect();
    let attributes = ResultAttributes {
        colours: &colours,
        channels: 3,
        texels: Some(&texels),
        frames: Some(&frames),
    };
    let input_normals = input.vertex_normals();
    let mapped = map_back(result, &attributes, &input.positions, &input_normals)
        .unwrap_or_else(|e| panic!("{name}: {e}"));
    let edge = result.average_edge_length();
    let n = input.vertex_count();
    assert_eq!(mapped.colours.len(), 3 * n, "{name}");
    let (mut sum, mut max) = (0.0f64, 0.0f32);
    for (v, &p) in input.positions.iter().enumerate() {
        let want = smooth(p);
        for (c, w) in want.iter().enumerate() {
            let e = (mapped.colours[3 * v + c] - w).abs();
            sum += e as f64;
            max = max.max(e);
        }
    }
    // Texels are copied from one corner of the closest triangle, never
    // interpolated: each names a retiled vertex near the original vertex.
    let mapped_texels = mapped.texels.as_ref().expect("texels follow");
    for (v, t) in mapped_texels.iter().enumerate() {
        assert_eq!(t.y, 0.5, "{name}: texel of vertex {v} was interpolated");
        let id = t.x - 0.5;
        assert_eq!(
            id.fract(),
            0.0,
            "{name}: texel of vertex {v} was interpolated"
        );
        let near = (result.positions[id as usize] - input.positions[v]).length();
        assert!(
            near <= 2.0 * edge,
            "{name}: vertex {v} took the texel of a retiled vertex {near} away (edge {edge})"
        );
    }
    // Frames lie in the original vertex's tangent plane and keep the direction.
    let mapped_frames = mapped.frames.as_ref().expect("frames follow");
    for (v, f) in mapped_frames.iter().enumerate() {
        if input_normals[v].length_squared() == 0.0 {
            continue;
        }
        assert!(
            f.n.dot(input_normals[v].normalize()) > 0.999,
            "{name}: frame {v} is not in the original tangent plane"
        );
        assert!((f.s.length() - 1.0).abs() < 1e-4 && f.s.dot(f.n).abs() < 1e-4);
    }
    Case {
        mean: (sum / (3 * n) as f64) as f32,
        max,
        max_distance_edges: mapped.distance.iter().copied().fold(0.0, f32::max) / edge,
        edge,
    }
}

fn check(name: &str, case: &Case) {
    println!(
        "{name}: mean error {:.5}, max {:.5}, max distance {:.3} edges (edge {:.4})",
        case.mean, case.max, case.max_distance_edges, case.edge
    );
    // Linear interpolation of a function with bounded second derivatives over
    // triangles of edge h: error O(h²); with h ≈ 0.05–0.1 and |f''| ≤ 2 the
    // bound is well under 0.02; mean far lower.
    assert!(
        case.mean < 0.004,
        "{name}: mean error {} too large",
        case.mean
    );
    assert!(case.max < 0.03, "{name}: max error {} too large", case.max);
    assert!(
        case.max_distance_edges < 0.5,
        "{name}: an original vertex lies {} edges off the retiled surface",
        case.max_distance_edges
    );
}

#[test]
fn smooth_colours_come_back_on_the_original_torus() {
    let torus = builtin_mesh("torus", &BuiltinOptions::default()).expect("torus");
    let case = map_smooth_function_back("torus", &torus, 3_000);
    check("torus", &case);
}

#[test]
fn smooth_colours_come_back_on_a_mesh_with_a_boundary_and_two_components() {
    // The shared mushroom (open, one boundary loop) and a torus beside it.
    let path = common::data_file("meshes/mushroom.off");
    let mushroom = load_mesh(&path, &LoadOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .0;
    let lo = mushroom
        .positions
        .iter()
        .fold(Vec3::splat(f32::INFINITY), |a, &p| a.min(p));
    let hi = mushroom
        .positions
        .iter()
        .fold(Vec3::splat(f32::NEG_INFINITY), |a, &p| a.max(p));
    // Scale the mushroom to a unit box so `smooth` varies over it.
    let scale = 2.0 / (hi - lo).max_element();
    let torus = builtin_mesh("torus", &BuiltinOptions::default()).expect("torus");
    let mut positions: Vec<Vec3> = mushroom
        .positions
        .iter()
        .map(|&p| (p - lo) * scale)
        .collect();
    let n = positions.len() as u32;
    positions.extend(
        torus
            .positions
            .iter()
            .map(|&p| p + Vec3::new(4.0, 0.0, 0.0)),
    );
    let faces: Vec<Vec<u32>> = mushroom
        .faces()
        .map(|f| f.to_vec())
        .chain(torus.faces().map(|f| f.iter().map(|v| v + n).collect()))
        .collect();
    let both = PolyMesh::from_polygons(positions, faces.iter().map(|f| f.as_slice()));
    let case = map_smooth_function_back("mushroom + torus", &both, 4_000);
    check("mushroom + torus", &case);
}

#[test]
fn bad_attributes_are_typed_errors() {
    let ico = builtin_mesh("icosphere", &BuiltinOptions::default()).expect("icosphere");
    let colours = vec![0.5f32; 3 * ico.vertex_count() - 3];
    let attributes = ResultAttributes {
        colours: &colours,
        channels: 3,
        texels: None,
        frames: None,
    };
    let err = map_back(&ico, &attributes, &ico.positions, &[]).unwrap_err();
    assert_eq!(
        err,
        MapBackError::Length {
            what: "colours",
            got: ico.vertex_count() - 1,
            vertices: ico.vertex_count()
        }
    );
    assert!(err.to_string().contains("colours"), "{err}");
    let texels = vec![Vec2::ZERO; 5];
    let colours = vec![0.5f32; 3 * ico.vertex_count()];
    let attributes = ResultAttributes {
        colours: &colours,
        channels: 3,
        texels: Some(&texels),
        frames: None,
    };
    let err = map_back(&ico, &attributes, &ico.positions, &[]).unwrap_err();
    assert!(err.to_string().contains("texels has 5 entries"), "{err}");
    let empty = PolyMesh::from_triangles(vec![Vec3::ZERO], &[]);
    let colours = [0.0f32; 3];
    let attributes = ResultAttributes {
        colours: &colours,
        channels: 3,
        texels: None,
        frames: None,
    };
    assert_eq!(
        map_back(&empty, &attributes, &ico.positions, &[]).unwrap_err(),
        MapBackError::NoFaces
    );
}

/// Vertex count and colour properties from a PLY header.
fn ply_header(path: &std::path::Path) -> (usize, bool) {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let end = bytes
        .windows(10)
        .position(|w| w == b"end_header")
        .expect("a PLY header");
    let header = String::from_utf8_lossy(&bytes[..end]);
    let vertices = header
        .lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .and_then(|n| n.trim().parse().ok())
        .expect("a vertex element");
    (vertices, header.contains("property uchar red"))
}

#[test]
fn the_cli_writes_the_result_mapped_back_onto_the_original_mesh() {
    let config = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("configs/12_wl_sphere_stones_random.toml");
    let run = |threads: &str| {
        let out = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"))
            .join(format!("map_back_cli_{threads}"));
        let _ = std::fs::remove_dir_all(&out);
        let (code, _, stderr) = common::run_cli(&[
            "run",
            config.to_str().expect("utf-8 path"),
            "--out",
            out.to_str().expect("utf-8 path"),
            "--threads",
            threads,
            "--quiet",
            "--set",
            "input.mesh_options.subdivisions=3",
            "--set",
            "stage.1.vertices=1536",
            "--set",
            "stage.1.levels=2",
            "--set",
            "stage.4.neighbourhoods=[[3, 1], [5, 2]]",
        ]);
        assert_eq!(code, 0, "{stderr}");
        out
    };
    let out = run("2");
    // Same bytes at one thread.
    let one = run("1");
    assert!(
        std::fs::read(out.join("result_original.ply")).expect("written")
            == std::fs::read(one.join("result_original.ply")).expect("written"),
        "result_original.ply differs between 1 and 2 threads"
    );
    let (vertices, coloured) = ply_header(&out.join("result_original.ply"));
    // The original icosphere at 3 subdivisions has 642 vertices.
    assert_eq!(vertices, 642);
    assert!(coloured, "result_original.ply has no vertex colours");
    let (retiled, _) = ply_header(&out.join("result.ply"));
    assert!(retiled.abs_diff(1536) <= 1536 / 20, "{retiled}");
    for i in 0..3 {
        assert!(out.join(format!("original_preview_{i}.png")).is_file());
    }
    let metrics: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out.join("metrics.json")).expect("metrics.json"),
    )
    .expect("JSON");
    let m = &metrics["stages"][4]["metrics"];
    assert_eq!(m["mapped"], true, "{m}");
    assert_eq!(m["vertices"], 642, "{m}");
    assert!(
        m["max_distance_texels"].as_f64().expect("a number") < 1.0,
        "{m}"
    );
}
