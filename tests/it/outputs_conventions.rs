//! Issue 16, outputs and conventions: OBJ exports carry vertex normals and a
//! smoothing group, MTL files mark non-colour maps, every per-corner-UV
//! result writes `result.ply` with vertex colours, and relative paths
//! resolve against the config file's folder (`--set` and text configs:
//! against the current directory).

use crate::common::*;
use bevy_ecs::prelude::*;
use glam::{Vec2, Vec3};
use std::path::Path;
use surfsynth::config::ConfigSource;
use surfsynth::image::sample::Wrap;
use surfsynth::pipeline::{Pipeline, check_input_files, load_input, run_in_world};
use surfsynth::world::*;

/// A pipeline on a small builtin sphere with the builtin bricks: `stages`
/// (TOML `[[stage]]` entries), then `export` with `formats`.
fn sphere_config(stages: &str, formats: &str) -> String {
    format!(
        "seed = 5\n[input]\nmesh = \"builtin:icosphere\"\nexemplar = \"builtin:bricks\"\n\
         exemplar_wrap = \"repeat\"\n[input.mesh_options]\nsubdivisions = 2\n\
         [input.exemplar_options]\nsize = 32\n\n{stages}\n\
         [[stage]]\nkind = \"export\"\nformats = {formats}\n"
    )
}

/// A small jump-map pipeline (per-corner UVs) exporting `formats`.
fn jump_config(formats: &str) -> String {
    sphere_config(
        "[[stage]]\nkind = \"orientation\"\nup = [0.0, 0.0, 1.0]\n\n\
         [[stage]]\nkind = \"jump_map\"\ncache = false\n\n\
         [[stage]]\nkind = \"jump_surface\"\nscale = 20.0\n",
        formats,
    )
}

/// A vertex-colour pipeline (no texture coordinates) exporting `formats`.
fn colour_config(formats: &str) -> String {
    sphere_config(
        "[[stage]]\nkind = \"orientation\"\n\n[[stage]]\nkind = \"init_colours\"\n",
        formats,
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

/// A face corner's `(v, vt, vn)` references, 0-based.
type CornerRef = (usize, Option<usize>, Option<usize>);

/// The `v`, `vt`, `vn` and face-corner references of an OBJ text.
struct ObjText {
    positions: Vec<Vec3>,
    /// As written: `v = 0` at the bottom.
    texcoords: Vec<Vec2>,
    normals: Vec<Vec3>,
    corners: Vec<Vec<CornerRef>>,
    smoothing: bool,
}

fn parse_obj(text: &str) -> ObjText {
    let mut obj = ObjText {
        positions: Vec::new(),
        texcoords: Vec::new(),
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
            Some("vt") => {
                let mut x = [0.0f32; 2];
                for v in &mut x {
                    *v = it.next().expect("2 numbers").parse().expect("a number");
                }
                obj.texcoords.push(Vec2::from_array(x));
            }
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
        "disp -mm 0 0 result_atlas_height.png",
    ] {
        assert!(mtl.lines().any(|l| l == line), "{line:?} missing:\n{mtl}");
    }
    // Every map a statement names (its last word, after any options) is a
    // file next to the MTL.
    for line in mtl.lines().filter(|l| !l.starts_with('#')) {
        let mut words = line.split_whitespace();
        let statement = words.next().unwrap_or("");
        if ["map_", "norm", "disp", "bump"]
            .iter()
            .any(|p| statement.starts_with(p))
        {
            let file = words.next_back().expect("a file name");
            assert!(dir.path().join(file).is_file(), "{line}: {file} missing");
        }
    }
}

/// The vertex count and RGB(A) bytes of a binary PLY written by surfsynth
/// (`float x y z nx ny nz`, then `uchar red green blue [alpha]`).
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
    assert!(
        header.contains(
            "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
        )
    );
    let stride = 24 + channels;
    let colours = (0..count)
        .flat_map(|v| {
            let at = header_len + v * stride + 24;
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
    let blend = w
        .get::<BlendUvs>(active)
        .expect("blend layers")
        .0
        .to_vec(mesh);
    let exemplar = w.resource::<Exemplar>();
    assert_eq!(count, mesh.vertex_count());
    assert_eq!(channels, 3, "RGB exemplar, RGB colours");
    // The oracle: at triangle corner k the 3-way blend is the exemplar at the
    // UV of base k, layer k; averaged over the vertex's corners.
    let (tris, _) = mesh.triangulate_corners();
    let mut sum = vec![[0.0f64; 3]; count];
    let mut n = vec![0u32; count];
    let mut px = [0.0f32; 3];
    for (tri, layer) in tris.iter().zip(&blend) {
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

/// The OBJ's mesh and its per-corner texture coordinates in image
/// convention (`v = 0` at the top), for rendering.
fn obj_mesh_and_uvs(obj: &ObjText) -> (surfsynth::mesh::PolyMesh, Vec<Vec2>) {
    let mut mesh = surfsynth::mesh::PolyMesh::new();
    mesh.positions = obj.positions.clone();
    let mut uvs = Vec::new();
    for face in &obj.corners {
        let vertices: Vec<u32> = face.iter().map(|c| c.0 as u32).collect();
        mesh.push_face(&vertices);
        for c in face {
            let t = obj.texcoords[c.1.expect("a vt per corner")];
            uvs.push(Vec2::new(t.x, 1.0 - t.y));
        }
    }
    (mesh, uvs)
}

/// Mean absolute difference over the pixels either image covers (not the
/// background of both).
fn mean_abs_difference(a: &surfsynth::image::Image, b: &surfsynth::image::Image) -> f64 {
    assert_eq!(
        (a.width, a.height, a.channels),
        (b.width, b.height, b.channels)
    );
    let background = a.pixel(0, 0).to_vec();
    let (mut sum, mut n) = (0.0f64, 0usize);
    for y in 0..a.height {
        for x in 0..a.width {
            let (pa, pb) = (a.pixel(x, y), b.pixel(x, y));
            if pa == background.as_slice() && pb == background.as_slice() {
                continue;
            }
            sum += pa
                .iter()
                .zip(pb)
                .map(|(p, q)| f64::from((p - q).abs()))
                .sum::<f64>();
            n += pa.len();
        }
    }
    sum / n.max(1) as f64
}

/// Issue 39: a jump-map `result.obj` looks like its preview in any OBJ
/// reader (Blender, MeshLab), which cannot do the 3-way blend: it is the
/// blend baked into a per-triangle atlas, and the raw per-corner
/// coordinates go to `result_corner_uvs.obj`. Rendered through our own
/// rasteriser from the files alone, `result.obj` is close to the preview and
/// much closer than the raw coordinates are.
#[test]
fn a_jump_map_result_obj_looks_like_its_preview() {
    let dir = tempfile::tempdir().unwrap();
    let w = run_and_write(&jump_config(r#"["obj", "preview"]"#), dir.path());
    let preview = &w.resource::<ExportJob>().previews[0];
    let render = |stem: &str, wrap: Wrap| {
        let text = std::fs::read_to_string(dir.path().join(format!("{stem}.obj"))).unwrap();
        let texture = surfsynth::image::load_image(&dir.path().join(format!("{stem}.png")))
            .expect("the OBJ's texture is written");
        let (mesh, uvs) = obj_mesh_and_uvs(&parse_obj(&text));
        let shading = surfsynth::output::render::Shading::CornerUvs {
            uvs: &uvs,
            texture: &texture,
            wrap,
        };
        let options = surfsynth::output::render::RenderOptions::default();
        surfsynth::output::render::render_views(&mesh, &shading, preview.width, &options).remove(0)
    };
    let blended = mean_abs_difference(&render("result", Wrap::Clamp), preview);
    let raw = mean_abs_difference(&render("result_corner_uvs", Wrap::Repeat), preview);
    assert!(
        // Measured: 0.0008 against 0.0217.
        blended < 0.005 && blended < raw / 4.0,
        "result.obj vs preview {blended:.4}, raw corner UVs vs preview {raw:.4}"
    );
}

/// A per-vertex result's `result.obj` is unchanged: no baked atlas, no
/// `result_corner_uvs.obj`.
#[test]
fn a_vertex_colour_result_obj_is_not_baked() {
    let dir = tempfile::tempdir().unwrap();
    run_and_write(&colour_config(r#"["obj"]"#), dir.path());
    assert!(dir.path().join("result.obj").exists());
    assert!(!dir.path().join("result_corner_uvs.obj").exists());
    assert!(
        !dir.path().join("result.png").exists(),
        "vertex colours need no texture"
    );
}

// ----- the path rule ---------------------------------------------------------

/// An octahedron, as OBJ text.
const OCTAHEDRON: &str = "v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n\
f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n";

/// A config naming `mesh` and the exemplar `e.png` by relative paths.
fn path_config(mesh: &str) -> String {
    format!(
        "seed = 1\n[input]\nmesh = \"{mesh}\"\nexemplar = \"e.png\"\n\n\
         [[stage]]\nkind = \"orientation\"\n\n[[stage]]\nkind = \"init_colours\"\n\n\
         [[stage]]\nkind = \"export\"\nformats = [\"ply\"]\n"
    )
}

/// A folder holding `c.toml` (`mesh = MESH`), `m.obj` and `e.png`.
fn config_folder(mesh: &str) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("c.toml"), path_config(mesh)).unwrap();
    std::fs::write(dir.path().join("m.obj"), OCTAHEDRON).unwrap();
    let mut img = surfsynth::image::Image::new(8, 8, 3);
    for (i, v) in img.data.iter_mut().enumerate() {
        *v = (i % 7) as f32 / 7.0;
    }
    surfsynth::output::write_png(&dir.path().join("e.png"), &img).unwrap();
    dir
}

/// Runs the CLI in `cwd`; returns (exit code, stderr).
fn run_in(cwd: &Path, args: &[&str]) -> (i32, String) {
    let out = bin()
        .args(args)
        .current_dir(cwd)
        .env("RUST_LOG", "warn")
        .output()
        .expect("the surfsynth binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn paths_in_a_config_file_resolve_against_its_folder_from_any_directory() {
    let folder = config_folder("m.obj");
    let elsewhere = tempfile::tempdir().unwrap();
    let config = folder.path().join("c.toml");
    let (code, stderr) = run_in(
        elsewhere.path(),
        &["run", config.to_str().unwrap(), "--out", "out", "-q"],
    );
    assert_eq!(code, 0, "{stderr}");
    // The output folder is relative to the current directory, not the config.
    assert!(
        elsewhere.path().join("out/result.ply").is_file(),
        "{stderr}"
    );
    assert!(!folder.path().join("out").exists());
}

#[test]
fn a_set_path_resolves_against_the_current_directory() {
    let folder = config_folder("m.obj");
    let cwd = tempfile::tempdir().unwrap();
    std::fs::create_dir(cwd.path().join("sub")).unwrap();
    std::fs::write(cwd.path().join("sub/m2.obj"), OCTAHEDRON).unwrap();
    let config = folder.path().join("c.toml");
    let args = |mesh: &'static str| {
        vec![
            "run".to_string(),
            config.display().to_string(),
            "--out".into(),
            "out".into(),
            "-q".into(),
            "--set".into(),
            format!("input.mesh={mesh}"),
        ]
    };
    let run = |mesh| {
        let a = args(mesh);
        run_in(
            cwd.path(),
            &a.iter().map(String::as_str).collect::<Vec<_>>(),
        )
    };
    let (code, stderr) = run("sub/m2.obj");
    assert_eq!(code, 0, "{stderr}");
    // `m.obj` sits beside the config but not in the current directory.
    let (code, stderr) = run("m.obj");
    assert_eq!(code, 2, "{stderr}");
    let cwd_abs = std::path::absolute(cwd.path()).unwrap();
    assert!(
        stderr.contains("--set input.mesh") && stderr.contains(&cwd_abs.display().to_string()),
        "{stderr}"
    );
}

#[test]
fn a_missing_input_file_names_key_file_line_and_directory() {
    let folder = config_folder("nowhere/missing.obj");
    let config = folder.path().join("c.toml");
    let elsewhere = tempfile::tempdir().unwrap();
    let (code, stderr) = run_in(
        elsewhere.path(),
        &["run", config.to_str().unwrap(), "--out", "out", "-q"],
    );
    assert_eq!(code, 2, "{stderr}");
    let dir = std::path::absolute(folder.path()).unwrap();
    for needle in [
        "`input.mesh`",
        "\"nowhere/missing.obj\"",
        &format!("{}:3:", config.display()),
        &dir.display().to_string(),
    ] {
        assert!(stderr.contains(needle), "{needle:?} not in: {stderr}");
    }
    assert!(
        !elsewhere.path().join("out").exists(),
        "nothing was written"
    );
    // Another override rewrites the text; the line is still the file's.
    let (code, stderr) = run_in(
        elsewhere.path(),
        &["run", config.to_str().unwrap(), "--set", "seed=3", "-q"],
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(
        stderr.contains(&format!("{}:3:", config.display())),
        "{stderr}"
    );
}

#[test]
fn a_text_config_resolves_against_the_current_directory() {
    // `cargo test` runs in the package root, where Cargo.toml is.
    let text = path_config("Cargo.toml").replace("e.png", "builtin:bricks");
    let source = ConfigSource::from_text("t.toml", &text);
    let p = Pipeline::from_source(source).unwrap();
    let files = check_input_files(&p.input, &p.source).unwrap();
    assert_eq!(files, vec![Path::new(".").join("Cargo.toml")]);
    let source = ConfigSource::from_text("t.toml", &path_config("no_such.obj"));
    let p = Pipeline::from_source(source).unwrap();
    let e = check_input_files(&p.input, &p.source)
        .unwrap_err()
        .to_string();
    assert!(e.contains("t.toml:3") && e.contains("no_such.obj"), "{e}");
}

#[test]
fn every_shipped_config_validates_and_finds_its_files() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let mut configs: Vec<_> = [root.clone(), root.join("plane")]
        .iter()
        .flat_map(|d| std::fs::read_dir(d).unwrap())
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    configs.sort();
    assert!(configs.len() >= 30, "{configs:?}");
    for path in configs {
        let source = ConfigSource::from_file(&path).unwrap();
        let p = Pipeline::from_source(source).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        check_input_files(&p.input, &p.source).unwrap_or_else(|e| panic!("{e}"));
    }
}
