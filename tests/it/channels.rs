//! Material channels that follow one synthesis (issue 7): extra exemplar maps
//! in `[input]`, their derivations and size checks, and the per-sample
//! exemplar coordinates every method records.

use crate::common;

use crate::common::world_for;
use bevy_ecs::prelude::*;
use surfsynth::config::ConfigSource;
use surfsynth::kernels::atlas::channels::{decode_normal, luminance_image};
use surfsynth::pipeline::{Pipeline, load_input};
use surfsynth::world::*;

fn pipeline(text: &str) -> Pipeline {
    Pipeline::from_source(ConfigSource::from_text("channels.toml", text)).expect("valid config")
}

fn input_error(text: &str) -> String {
    let p = pipeline(text);
    load_input(&p.input, &p.source.base_dir, &p.source.file)
        .expect_err("the input is refused")
        .to_string()
}

const BRICKS: &str = r#"
seed = 1
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
CHANNELS
"#;

fn with_channels(channels: &str) -> String {
    BRICKS.replace("CHANNELS", channels)
}

#[test]
fn no_maps_give_an_empty_channels_resource() {
    let w = world_for(&with_channels("")).expect("runs");
    let ch = w.resource::<ExemplarChannels>();
    assert!(ch.height.is_none() && ch.normal.is_none() && ch.roughness.is_none());
}

#[test]
fn derived_maps_have_the_exemplar_size_and_follow_the_height() {
    let w = world_for(&with_channels(
        r#"height_map = "derive:builtin"
normal_map = "derive:height"
roughness_map = "derive:luminance"
normal_strength = 6.0"#,
    ))
    .expect("runs");
    let ex = w.resource::<Exemplar>().image.clone();
    let ch = w.resource::<ExemplarChannels>().clone();
    let h = ch.height.expect("height");
    let n = ch.normal.expect("normal");
    let r = ch.roughness.expect("roughness");
    assert_eq!((h.width, h.height, h.channels), (ex.width, ex.height, 1));
    assert_eq!((n.width, n.height, n.channels), (ex.width, ex.height, 3));
    assert_eq!((r.width, r.height, r.channels), (ex.width, ex.height, 1));
    // The builtin bricks: mortar row 8 is low, brick row 4 high.
    let row = |y: u32| (0..h.width).map(|x| h.pixel(x, y)[0]).sum::<f32>() / h.width as f32;
    assert!(row(8) < 0.2 && row(4) > 0.5, "{} {}", row(8), row(4));
    // Just above a mortar row (y = 7, inside a brick's bottom edge) the
    // height falls downwards in the image, i.e. rises towards +t: the normal
    // tilts towards −Y. Just below it (y = 9) the opposite.
    let mean_y = |y: u32| {
        (0..n.width)
            .map(|x| decode_normal(n.pixel(x, y).try_into().unwrap()).y)
            .sum::<f32>()
            / n.width as f32
    };
    assert!(mean_y(7) < -0.1, "{}", mean_y(7));
    assert!(mean_y(9) > 0.1, "{}", mean_y(9));
    // Roughness: 1 − luminance.
    let lum = luminance_image(&ex);
    for i in [0usize, 100, 1000] {
        assert!((r.data[i] - (1.0 - lum.data[i])).abs() < 1e-6);
    }
    // derive:luminance height is the luminance itself.
    let w = world_for(&with_channels(r#"height_map = "derive:luminance""#)).expect("runs");
    assert_eq!(w.resource::<ExemplarChannels>().height.as_ref(), Some(&lum));
}

#[test]
fn map_files_load_and_mismatched_sizes_name_the_file_and_both_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("h64.png");
    let small = dir.path().join("h32.png");
    let grey = dir.path().join("n64.png");
    image::GrayImage::from_fn(64, 64, |x, _| image::Luma([(x * 4) as u8]))
        .save(&good)
        .unwrap();
    image::GrayImage::from_fn(32, 32, |_, _| image::Luma([7]))
        .save(&small)
        .unwrap();
    image::GrayImage::from_fn(64, 64, |_, _| image::Luma([7]))
        .save(&grey)
        .unwrap();
    let w = world_for(&with_channels(&format!(
        "height_map = {:?}\nnormal_map = \"derive:height\"",
        good.display().to_string()
    )))
    .expect("runs");
    let h = w.resource::<ExemplarChannels>().height.clone().unwrap();
    assert!((h.pixel(10, 3)[0] - 40.0 / 255.0).abs() < 1e-6);

    let e = input_error(&with_channels(&format!(
        "height_map = {:?}",
        small.display().to_string()
    )));
    assert!(
        e.contains("h32.png")
            && e.contains("32x32")
            && e.contains("64x64")
            && e.contains("height_map"),
        "{e}"
    );
    let e = input_error(&with_channels(&format!(
        "roughness_map = {:?}",
        small.display().to_string()
    )));
    assert!(e.contains("roughness_map") && e.contains("32x32"), "{e}");
    let e = input_error(&with_channels(&format!(
        "normal_map = {:?}",
        grey.display().to_string()
    )));
    assert!(e.contains("normal_map") && e.contains("needs 3"), "{e}");
    let e = input_error(&with_channels("height_map = \"missing/h.png\""));
    assert!(e.contains("h.png"), "{e}");
}

#[test]
fn bad_derivations_say_what_is_allowed() {
    let e = input_error(&with_channels("normal_map = \"derive:height\""));
    assert!(
        e.contains("input.normal_map") && e.contains("height_map"),
        "{e}"
    );
    let e = input_error(&with_channels("height_map = \"derive:magic\""));
    assert!(
        e.contains("derive:magic")
            && e.contains("derive:luminance")
            && e.contains("derive:builtin"),
        "{e}"
    );
    let e = input_error(&with_channels(
        "height_map = \"derive:luminance\"\nnormal_map = \"derive:height\"\nnormal_strength = 500.0",
    ));
    assert!(
        e.contains("normal_strength") && e.contains("0..=100"),
        "{e}"
    );
    let dir = tempfile::tempdir().unwrap();
    let ex = dir.path().join("ex.png");
    image::RgbImage::from_fn(16, 16, |x, y| image::Rgb([x as u8 * 9, y as u8 * 9, 3]))
        .save(&ex)
        .unwrap();
    let text = format!(
        "[input]\nmesh = \"builtin:icosphere\"\nexemplar = {:?}\nheight_map = \"derive:builtin\"\n",
        ex.display().to_string()
    );
    let e = input_error(&text);
    assert!(
        e.contains("derive:builtin") && e.contains("builtin exemplar"),
        "{e}"
    );
}

// ----- displacement ------------------------------------------------------------

/// A 16×16 height map: a diagonal ramp with a bump, values in [0, 1].
fn write_height_png(path: &std::path::Path) {
    image::GrayImage::from_fn(16, 16, |x, y| {
        let bump = if (5..9).contains(&x) && (6..10).contains(&y) {
            80
        } else {
            0
        };
        image::Luma([(x * 7 + y * 3 + bump) as u8])
    })
    .save(path)
    .unwrap();
}

fn plane_config(height: &str, synthesis: &str, amplitude: f32) -> String {
    format!(
        r#"
seed = 4
[input]
mesh = "builtin:plane"
exemplar = "builtin:noise"
height_map = {height:?}
[input.mesh_options]
resolution = [12, 9]
[input.exemplar_options]
size = 16

[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]

{synthesis}

[[stage]]
kind = "displace"
amplitude = {amplitude}
amplitude_unit = "world"
"#
    )
}

#[test]
fn displaced_plane_moves_by_amplitude_times_height_above_the_mean() {
    let dir = tempfile::tempdir().unwrap();
    let hp = dir.path().join("h.png");
    write_height_png(&hp);
    let text = plane_config(
        &hp.display().to_string(),
        "[[stage]]\nkind = \"init_colours\"",
        0.25,
    );
    let mut w = world_for(&text).expect("runs");
    let h = w.resource::<ExemplarChannels>().height.clone().unwrap();
    let mean = h.data.iter().map(|&v| v as f64).sum::<f64>() / h.data.len() as f64;
    let active = w.resource::<ActiveMesh>().0;
    let mut sources = w.query_filtered::<&Geometry, With<SourceMesh>>();
    let source = sources.single(&w).unwrap().0.clone();
    assert!(
        source.positions.iter().all(|p| p.z == 0.0),
        "the loaded mesh is untouched"
    );
    let mesh = &w.get::<Geometry>(active).unwrap().0;
    let texels = &w.get::<SourceTexels>(active).expect("texels kept").0;
    assert!(w.get::<VertexColours>(active).is_some(), "colours kept");
    let normals = source.vertex_normals();
    let mut distinct = std::collections::BTreeSet::new();
    for (v, p) in mesh.positions.iter().enumerate() {
        let t = texels[v];
        let hv = h.pixel(t.x as u32, t.y as u32)[0] as f64;
        let expected = normals[v].z as f64 * 0.25 * (hv - mean);
        assert!(
            (p.z as f64 - expected).abs() < 1e-5,
            "vertex {v}: z {} expected {expected}",
            p.z
        );
        assert_eq!((p.x, p.y), (source.positions[v].x, source.positions[v].y));
        distinct.insert((p.z * 1e4) as i64);
    }
    assert!(
        distinct.len() > 10,
        "the relief varies: {} levels",
        distinct.len()
    );
    let m = &w.resource::<Metrics>().stages[2];
    assert_eq!(m["coordinates"], "source_texels");
}

#[test]
fn displace_without_a_height_map_names_the_key() {
    let text = plane_config("x", "[[stage]]\nkind = \"init_colours\"", 0.1)
        .replace("height_map = \"x\"\n", "");
    let e = world_for(&text).expect_err("refused").to_string();
    assert!(
        e.contains("displace") && e.contains("input.height_map"),
        "{e}"
    );
    // No synthesis before it: no recorded coordinates.
    let text = plane_config("derive:luminance", "", 0.1);
    let e = world_for(&text).expect_err("refused").to_string();
    assert!(
        e.contains("SourceTexels") && e.contains("init_colours"),
        "{e}"
    );
}

#[test]
fn displace_after_jump_surface_averages_corner_heights() {
    let text = plane_config(
        "derive:luminance",
        "[[stage]]\nkind = \"jump_map\"\ncache = false\n\n[[stage]]\nkind = \"jump_surface\"\nscale = 8.0",
        0.5,
    );
    let w = world_for(&text).expect("runs");
    let h = w.resource::<ExemplarChannels>().height.clone().unwrap();
    let mean = surfsynth::kernels::atlas::channels::mean_height(&h);
    let active = w.resource::<ActiveMesh>().0;
    let mesh = &w.get::<Geometry>(active).unwrap().0;
    let uvs = &w.get::<CornerUvs>(active).expect("uvs kept").0;
    let mut sum = vec![0.0f32; mesh.vertex_count()];
    let mut count = vec![0u32; mesh.vertex_count()];
    for (c, &v) in mesh.corner_vertex.iter().enumerate() {
        let mut s = [0.0f32];
        h.sample_uv(
            uvs[c].x,
            uvs[c].y,
            surfsynth::image::sample::Wrap::Repeat,
            &mut s,
        );
        sum[v as usize] += s[0];
        count[v as usize] += 1;
    }
    for (v, p) in mesh.positions.iter().enumerate() {
        let expected = 0.5 * (sum[v] / count[v] as f32 - mean);
        assert!(
            (p.z.abs() - expected.abs()).abs() < 1e-4,
            "vertex {v}: {} vs {expected}",
            p.z
        );
    }
    assert_eq!(
        w.resource::<Metrics>().stages[3]["coordinates"],
        "corner_uvs"
    );
}

#[test]
fn displace_handles_a_messy_mesh() {
    // Two components, a boundary, a non-manifold edge (three triangles on
    // edge 1-2) and a sliver.
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("messy.obj");
    std::fs::write(
        &obj,
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 0.5 0.5 1\nv 0.5 0.5 -1\nv 3 0 0\nv 4 0 0\nv 3.5 1e-4 0\nv 3 1 0\n\
         f 1 2 3\nf 2 4 3\nf 2 3 5\nf 3 2 6\nf 7 8 9\nf 7 9 10\n",
    )
    .unwrap();
    let text = format!(
        r#"
[input]
mesh = {:?}
exemplar = "builtin:bricks"
height_map = "derive:builtin"

[[stage]]
kind = "orientation"

[[stage]]
kind = "init_colours"

[[stage]]
kind = "displace"
amplitude = 0.2
amplitude_unit = "world"
"#,
        obj.display().to_string()
    );
    let w = world_for(&text).expect("runs on a messy mesh");
    let active = w.resource::<ActiveMesh>().0;
    let mesh = &w.get::<Geometry>(active).unwrap().0;
    assert!(mesh.positions.iter().all(|p| p.is_finite()));
    assert!(
        w.resource::<Metrics>().stages[2]["max_offset"]
            .as_f64()
            .unwrap()
            > 0.0
    );
}

// ----- audit: every method records where each sample came from -------------------

#[test]
fn graph_cut_copies_record_their_source_texels() {
    let text = r#"
seed = 9
[input]
mesh = "builtin:plane"
exemplar = "builtin:noise"
[input.mesh_options]
resolution = [24, 24]
[input.exemplar_options]
size = 32

[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]

[[stage]]
kind = "graph_match"
r_scale = 12.0
region = 5.0
graph_cut = true
passes = [1]
"#;
    let w = world_for(text).expect("runs");
    let m = &w.resource::<Metrics>().stages[1]["total"];
    assert!(
        m["cut_vertices"].as_u64().unwrap() > m["cuts"].as_u64().unwrap(),
        "cuts copy regions: {m}"
    );
    let ex = w.resource::<Exemplar>().image.clone();
    let stack =
        surfsynth::image::pyramid::gaussian_stack(&ex, 8, surfsynth::image::sample::Wrap::Repeat);
    let active = w.resource::<ActiveMesh>().0;
    let colours = w.get::<VertexColours>(active).unwrap();
    let texels = &w.get::<SourceTexels>(active).unwrap().0;
    let mut mismatched = Vec::new();
    for (v, t) in texels.iter().enumerate() {
        let c = &colours.values[v * 3..v * 3 + 3];
        let (x, y) = (t.x.floor() as i64, t.y.floor() as i64);
        if !stack
            .iter()
            .any(|img| img.texel(x, y, surfsynth::image::sample::Wrap::Repeat) == c)
        {
            mismatched.push(v);
        }
    }
    assert!(
        mismatched.is_empty(),
        "vertices whose colour is not at their texel: {mismatched:?}"
    );
}

#[test]
fn jump_surface_texels_are_each_face_base_corner() {
    let text = plane_config(
        "derive:luminance",
        "[[stage]]\nkind = \"jump_map\"\ncache = false\n\n[[stage]]\nkind = \"jump_surface\"\nscale = 8.0",
        0.0,
    );
    let w = world_for(&text).expect("runs");
    let ex = w.resource::<Exemplar>().image.clone();
    let size = glam::Vec2::new(ex.width as f32, ex.height as f32);
    let active = w.resource::<ActiveMesh>().0;
    let mesh = &w.get::<Geometry>(active).unwrap().0;
    let uvs = &w.get::<CornerUvs>(active).unwrap().0;
    let texels = &w.get::<SourceTexels>(active).unwrap().0;
    for f in 0..mesh.face_count() {
        let c = mesh.face_corners(f).start;
        let v = mesh.face(f)[0] as usize;
        assert!((uvs[c] * size - texels[v]).length() < 1e-3, "face {f}");
    }
}

#[test]
fn wei_levoy_match_colours_are_their_texels() {
    let text = r#"
seed = 5
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:stripes"
[input.mesh_options]
subdivisions = 1
[input.exemplar_options]
size = 32

[[stage]]
kind = "builtin_pyramid"
mesh = "icosphere"
levels = 2
subdivisions = 3

[[stage]]
kind = "orientation"
mode = "global"

[[stage]]
kind = "init_colours"

[[stage]]
kind = "match"
search = "exhaustive"
"#;
    let w = world_for(text).expect("runs");
    let ex = w.resource::<Exemplar>().image.clone();
    let active = w.resource::<ActiveMesh>().0;
    let colours = w.get::<VertexColours>(active).unwrap();
    let texels = &w.get::<SourceTexels>(active).unwrap().0;
    for (v, t) in texels.iter().enumerate() {
        assert_eq!(
            &colours.values[v * 3..v * 3 + 3],
            ex.pixel(t.x as u32, t.y as u32),
            "vertex {v}"
        );
    }
}

#[test]
fn displaced_config_runs_end_to_end_at_small_size() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("configs/25_bm_eight_stones_displaced.toml");
    let (code, _, stderr) = common::run_cli(&[
        "run",
        cfg.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
        "--set",
        "stage.1.target_vertices=3000",
        "--set",
        "stage.4.amplitude=8",
    ]);
    assert_eq!(code, 0, "{stderr}");
    for name in ["result.ply", "result.obj", "preview_0.png", "metrics.json"] {
        assert!(dir.path().join(name).is_file(), "{name} written");
    }
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("metrics.json")).unwrap())
            .unwrap();
    let d = &m["stages"][3]["metrics"];
    assert_eq!(m["stages"][3]["kind"], "displace");
    assert_eq!(d["coordinates"], "source_texels");
    let max = d["max_offset"].as_f64().unwrap();
    // 8 texels at the config's 160 texels per unit is 0.05 units, times at
    // most one unit of height.
    let world = d["amplitude_world"].as_f64().unwrap();
    let tpu = m["result"]["scale"]["requested_texels_per_world_unit"]
        .as_f64()
        .unwrap();
    assert!((world * tpu - 8.0).abs() < 1e-3, "{world} x {tpu}");
    assert!(max > 0.1 * world && max <= world + 1e-6, "{max} vs {world}");
}

#[test]
fn lapped_texture_patches_record_their_exemplar_origin() {
    let text = r#"
seed = 2
[input]
mesh = "builtin:cube"
exemplar = "builtin:noise"
[input.mesh_options]
subdivisions = 2

[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]

[[stage]]
kind = "tangent_field"
mode = "frames"
patch_size = 0.6

[[stage]]
kind = "lapped_paste"
patches = 3
"#;
    let w = world_for(text).expect("runs");
    let ex = w.resource::<Exemplar>().image.clone();
    let patches = w.resource::<surfsynth::world::TexturePatches>().0.clone();
    let origins = w
        .resource::<surfsynth::world::TexturePatchOrigins>()
        .0
        .clone();
    assert_eq!(patches.len(), origins.len());
    assert!(patches.len() >= 2);
    for (k, (p, o)) in patches.iter().zip(&origins).enumerate() {
        let mut opaque = 0;
        for y in 0..p.height {
            for x in 0..p.width {
                let px = p.pixel(x, y);
                if px[3] <= 0.0 {
                    continue;
                }
                opaque += 1;
                let e = ex.texel(
                    o[0] + x as i64,
                    o[1] + y as i64,
                    surfsynth::image::sample::Wrap::Repeat,
                );
                assert_eq!(&px[..3], &e[..3], "patch {k} pixel ({x}, {y})");
            }
        }
        assert!(opaque > 0, "patch {k} has opaque pixels");
    }
}

#[test]
fn graph_match_keeps_the_texels_of_colours_it_starts_from() {
    // With no pass on the level, the colours of init_colours stay: their
    // source texels must stay with them (they used to be reset to 0, 0).
    let text = r#"
seed = 3
[input]
mesh = "builtin:plane"
exemplar = "builtin:noise"
[input.mesh_options]
resolution = [10, 10]
[input.exemplar_options]
size = 32

[[stage]]
kind = "orientation"
mode = "global"

[[stage]]
kind = "init_colours"

[[stage]]
kind = "graph_match"
r_scale = 10.0
passes = [0]
"#;
    let w = world_for(text).expect("runs");
    let ex = w.resource::<Exemplar>().image.clone();
    let active = w.resource::<ActiveMesh>().0;
    let colours = w.get::<VertexColours>(active).unwrap();
    let texels = &w.get::<SourceTexels>(active).unwrap().0;
    for (v, t) in texels.iter().enumerate() {
        assert_eq!(
            &colours.values[v * 3..v * 3 + 3],
            ex.pixel(t.x as u32, t.y as u32),
            "vertex {v} at {t}"
        );
    }
}

#[test]
fn displacement_is_identical_at_one_and_two_threads() {
    let text = plane_config(
        "derive:luminance",
        "[[stage]]\nkind = \"init_colours\"",
        0.3,
    )
    .replace("amplitude = 0.3", "amplitude = 0.3\nsmoothing = 3");
    let positions = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let w = world_for(&text).expect("runs");
                let e = w.resource::<ActiveMesh>().0;
                w.get::<Geometry>(e).unwrap().0.positions.clone()
            })
    };
    let (a, b) = (positions(1), positions(2));
    assert!(a.iter().any(|p| p.z != 0.0), "something moved");
    assert!(
        a.iter()
            .zip(&b)
            .all(|(x, y)| x.to_array().map(f32::to_bits) == y.to_array().map(f32::to_bits))
    );
}
