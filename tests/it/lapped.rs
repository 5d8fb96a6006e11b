//! Lapped textures (Praun, Finkelstein & Hoppe 2000) over the shared mesh
//! set: the parametrisation is the exact similarity where it can be, patches
//! are discs inside their hull, every face of every shared closed mesh gets
//! covered, the field interpolates its constraints, atlas charts never
//! overlap, and runs are byte-identical at 1 and 2 threads.
//!
//! Kernel-level tests (hull containment, CG against a dense least-squares
//! solve, skyline packing, ...) live next to the kernels in
//! `src/kernels/lapped/`.

use crate::common;
use crate::common::*;
use bevy_ecs::prelude::*;
use glam::{Vec2, Vec3};
use surfsynth::config::ConfigSource;
use surfsynth::image::sample::Wrap;
use surfsynth::image::{Image, load_image};
use surfsynth::kernels::lapped::atlas::{AtlasSettings, pack_charts, segment_charts};
use surfsynth::kernels::lapped::coverage::lattice_samples;
use surfsynth::kernels::lapped::grow::{GrowSettings, Grower};
use surfsynth::kernels::lapped::mask::{TexturePatch, circle_mask, splotch_mask};
use surfsynth::kernels::lapped::param::{SolveSettings, optimise_parametrisation};
use surfsynth::kernels::lapped::paste::{PasteSettings, paste_until_covered};
use surfsynth::kernels::lapped::tangent_field::{FieldConstraint, global_up_field, rbf_field};
use surfsynth::kernels::lapped::{FaceField, TriMesh};
use surfsynth::mesh::{LoadOptions, PolyMesh, Topology, load_mesh};
use surfsynth::pipeline::{Pipeline, load_input, run_in_world};
use surfsynth::progress::Progress;
use surfsynth::world::*;

const SHARED_CLOSED: [&str; 5] = [
    "bunny_1k8.obj",
    "knot.off",
    "eight.off",
    "nut.ply",
    "fandisk.off",
];

fn load(name: &str) -> PolyMesh {
    load_mesh(
        &data_file(&format!("meshes/{name}")),
        &LoadOptions::default(),
    )
    .unwrap_or_else(|e| panic!("{name}: {e}"))
    .0
}

fn diagonal(m: &PolyMesh) -> f32 {
    let (lo, hi) = m.bounding_box().unwrap();
    (hi - lo).length()
}

/// A 64-pixel texture patch of a plain exemplar (coverage ignores colour).
fn texture(splotch: bool) -> TexturePatch {
    let ex = Image::new(64, 64, 3);
    let mask = if splotch {
        splotch_mask(64, 7)
    } else {
        circle_mask(64)
    };
    TexturePatch::cut(&ex, Wrap::Repeat, [0, 0], &mask, 3.0, 16, "test").unwrap()
}

#[test]
fn flat_grid_with_constant_field_is_the_exact_similarity() {
    // A 20 × 20 grid in the plane z = 1, field rotated by 30° and scaled.
    let n = 20usize;
    let p: Vec<Vec3> = (0..n * n)
        .map(|i| Vec3::new((i % n) as f32 * 0.1, (i / n) as f32 * 0.1, 1.0))
        .collect();
    let mut tris = Vec::new();
    for y in 0..n - 1 {
        for x in 0..n - 1 {
            let i = (y * n + x) as u32;
            tris.push([i, i + 1, i + n as u32]);
            tris.push([i + 1, i + n as u32 + 1, i + n as u32]);
        }
    }
    let m = TriMesh::new(&PolyMesh::from_triangles(p, &tris)).unwrap();
    let up = Vec3::new(-0.5, 0.75f32.sqrt(), 0.0);
    let t = global_up_field(&m, up, 0.9);
    let field = FaceField {
        t: &t,
        isotropic: false,
        scale: 1.0,
    };
    let mut grower = Grower::new(&m, field, GrowSettings::default());
    let seed = 2 * (9 * 19 + 9);
    let bary = [0.6, 0.3, 0.1];
    // Both solvers: CG (the paper's) and the sparse Cholesky of large
    // patches, straight away or after a CG budget (which the growth's
    // parametrisation of a flat grid, near the optimum, converges within
    // at this tolerance).
    for (direct_from, cg_budget) in [(usize::MAX, 0), (0, 0), (0, 5000)] {
        let mut patch = grower.start(seed, bary, 0.0);
        grower.grow(&mut patch, &texture(false).hull);
        assert!(patch.faces.len() > 40, "{} faces", patch.faces.len());
        let report = optimise_parametrisation(
            &m,
            &mut patch,
            &SolveSettings {
                tolerance: 1e-12,
                max_iterations: 5000,
                direct_from,
                cg_budget,
                cg_first_below: 1e-3,
            },
        );
        assert_eq!(report.direct, direct_from == 0 && cg_budget == 0);
        assert!(report.energy < 1e-9, "residual {report:?}");
        let centre = m.point(seed as usize, bary);
        let right = up.cross(Vec3::Z);
        for (l, &v) in patch.vertices.iter().enumerate() {
            let d = m.positions[v as usize] - centre;
            let expected = Vec2::new(d.dot(right), d.dot(up)) / 0.9;
            assert!(
                (patch.st[l] - expected).length() < 1e-5,
                "vertex {v}: {:?} vs the similarity {expected:?}",
                patch.st[l]
            );
        }
    }
}

#[test]
fn grown_patches_are_discs_inside_the_hull() {
    let tex = texture(true);
    for name in SHARED_CLOSED {
        let mesh = load(name);
        let m = TriMesh::new(&mesh).unwrap();
        let t = global_up_field(&m, Vec3::Y, 0.2 * diagonal(&mesh));
        for isotropic in [false, true] {
            let field = FaceField {
                t: &t,
                isotropic,
                scale: 1.0,
            };
            let mut grower = Grower::new(&m, field, GrowSettings::default());
            for k in 0..12u32 {
                let seed = (k * 7919) % m.face_count() as u32;
                let mut patch = grower.start(seed, [0.3, 0.3, 0.4], k as f32);
                grower.grow(&mut patch, &tex.hull);
                let what = format!("{name}, isotropic {isotropic}, seed face {seed}");
                assert_eq!(patch.euler_characteristic(), 1, "{what}");
                assert_eq!(patch.boundary_loop_count(), 1, "{what}");
                // Every face joined over an edge that reaches into the hull.
                for (lf, tri) in patch.tris.iter().enumerate().skip(1) {
                    let reaches = (0..3).any(|i| {
                        tex.hull.segment_intersects(
                            patch.st[tri[i] as usize],
                            patch.st[tri[(i + 1) % 3] as usize],
                        )
                    });
                    assert!(reaches, "{what}: face {lf} is outside the hull");
                }
                // The grown patch still a disc after regrowing.
                optimise_parametrisation(&m, &mut patch, &SolveSettings::default());
                grower.grow(&mut patch, &tex.hull);
                assert_eq!(patch.euler_characteristic(), 1, "{what}, regrown");
                assert_eq!(patch.boundary_loop_count(), 1, "{what}, regrown");
            }
        }
    }
}

#[test]
fn large_patches_iterate_only_from_a_near_optimal_start() {
    // On curved meshes the growth's parametrisation is far from the
    // optimum: such a large patch is factored without spending the CG
    // budget, and lands where the factorisation alone lands.
    use surfsynth::kernels::lapped::param::{alignment_system, relative_residual};
    let tex = texture(true);
    let mut factored = 0;
    for name in SHARED_CLOSED {
        let mesh = load(name);
        let m = TriMesh::new(&mesh).unwrap();
        let t = global_up_field(&m, Vec3::Y, 0.2 * diagonal(&mesh));
        let field = FaceField {
            t: &t,
            isotropic: false,
            scale: 1.0,
        };
        let mut grower = Grower::new(&m, field, GrowSettings::default());
        for k in 0..6u32 {
            let seed = (k * 7919) % m.face_count() as u32;
            let mut patch = grower.start(seed, [0.3, 0.3, 0.4], 0.0);
            grower.grow(&mut patch, &tex.hull);
            let (mat, bs, bt) = alignment_system(&m, &patch);
            let xs: Vec<f64> = patch.st.iter().map(|p| p.x as f64).collect();
            let xt: Vec<f64> = patch.st.iter().map(|p| p.y as f64).collect();
            let far = relative_residual(&mat, &bs, &xs).max(relative_residual(&mat, &bt, &xt));
            let budgeted = SolveSettings {
                direct_from: 0,
                ..SolveSettings::default()
            };
            let mut a = patch.clone();
            let ra = optimise_parametrisation(&m, &mut a, &budgeted);
            let mut b = patch.clone();
            let rb = optimise_parametrisation(
                &m,
                &mut b,
                &SolveSettings {
                    cg_budget: 0,
                    ..budgeted
                },
            );
            assert!(rb.direct, "{name}, seed face {seed}: not factored");
            if far > budgeted.cg_first_below {
                factored += 1;
                assert!(
                    ra.direct && ra.iterations == 0,
                    "{name}, seed face {seed}: {ra:?}"
                );
                assert_eq!(a, b, "{name}, seed face {seed}");
            } else {
                // Near the optimum either way: the same energy to the
                // solver's tolerance.
                assert!(
                    (ra.energy - rb.energy).abs() <= 1e-6 * rb.energy + 1e-9,
                    "{name}, seed face {seed}: {ra:?} vs {rb:?}"
                );
            }
        }
    }
    assert!(factored > 0, "no curved patch started far from the optimum");
}

#[test]
fn every_face_of_the_shared_closed_meshes_is_covered() {
    let textures = [texture(true)];
    for name in SHARED_CLOSED {
        let mesh = load(name);
        let m = TriMesh::new(&mesh).unwrap();
        let t = global_up_field(&m, Vec3::Y, 0.15 * diagonal(&mesh));
        for isotropic in [false, true] {
            let field = FaceField {
                t: &t,
                isotropic,
                scale: 1.0,
            };
            let settings = PasteSettings {
                seed: 11,
                ..Default::default()
            };
            let out = paste_until_covered(&m, field, &textures, &settings, &Progress::hidden());
            let what = format!("{name}, isotropic {isotropic}");
            assert!(
                out.report.uncovered_faces.is_empty(),
                "{what}: {:?}",
                out.report
            );
            assert!(
                out.report.mean_pastes_per_face > 1.0 && out.report.mean_pastes_per_face < 12.0,
                "{what}: {:?}",
                out.report
            );
            // Independently: every sample of every face is opaque under the
            // composite of the pastes that hold it.
            for f in 0..m.face_count() {
                let layers: Vec<_> = out.coverage.layers(f).collect();
                assert!(!layers.is_empty(), "{what}: face {f} has no paste");
                for b in lattice_samples(out.coverage.levels[f]) {
                    let clear: f32 = layers
                        .iter()
                        .map(|l| {
                            let uv = l.uv[0] * b[0] + l.uv[1] * b[1] + l.uv[2] * b[2];
                            1.0 - textures[l.texture as usize].alpha_at(uv)
                        })
                        .product();
                    assert!(
                        clear < 1.0 / 255.0,
                        "{what}: face {f} shows through at {b:?}"
                    );
                }
            }
            // The pastes list their faces consistently with the coverage.
            let held: usize = out.pastes.iter().map(|p| p.faces.len()).sum();
            let layered = out.coverage.held_layers();
            assert_eq!(held, layered, "{what}");
        }
    }
}

#[test]
fn rbf_field_returns_each_constraint_at_its_face() {
    let mesh = load("bunny_1k8.obj");
    let m = TriMesh::new(&mesh).unwrap();
    let topo = Topology::build(&mesh);
    let background = global_up_field(&m, Vec3::Y, 1.0);
    let constraints = [
        FieldConstraint {
            face: 100,
            direction: Vec3::new(1.0, 1.0, 0.0),
            scale: 1.6,
            radius: 3.0,
            weight: 1.0,
        },
        FieldConstraint {
            face: 2000,
            direction: Vec3::new(0.0, 0.3, 1.0),
            scale: 0.7,
            radius: 1.5,
            weight: 2.0,
        },
        FieldConstraint {
            face: 3000,
            direction: Vec3::X,
            scale: 1.0,
            radius: 5.0,
            weight: 0.5,
        },
    ];
    let (t, report) = rbf_field(&m, &topo, &constraints, &background, 0.05, 2.0).unwrap();
    assert!(report.exact);
    for c in &constraints {
        let f = c.face as usize;
        let n = m.normal(f);
        let expected = (c.direction - n * n.dot(c.direction)).normalize() * 2.0 * c.scale;
        assert!(
            (t[f] - expected).length() < 1e-3 * expected.length(),
            "face {f}: {:?} vs the constraint {expected:?}",
            t[f]
        );
    }
}

#[test]
fn atlas_charts_do_not_overlap() {
    let mesh = load("bunny_1k8.obj");
    let m = TriMesh::new(&mesh).unwrap();
    let settings = AtlasSettings::default();
    let charts = segment_charts(&m, &settings);
    let size = 1024usize;
    let (uvs, scale) = pack_charts(&charts, size as u32, 2).unwrap();
    assert!(scale > 0.0);
    // Rasterise every face at the atlas resolution and count the texel
    // centres strictly inside more than one face.
    let mut hits = vec![0u8; size * size];
    for uv in &uvs {
        let t = uv.map(|p| p * size as f32);
        let area = (t[1] - t[0]).perp_dot(t[2] - t[0]);
        // Texture up is image up (y down): counter-clockwise faces have a
        // negative signed area in texel coordinates; none is flipped.
        assert!(area < 0.0, "charts keep the faces' orientation");
        let lo = t[0].min(t[1]).min(t[2]);
        let hi = t[0].max(t[1]).max(t[2]);
        assert!(lo.x >= 0.0 && lo.y >= 0.0 && hi.x <= size as f32 && hi.y <= size as f32);
        for y in lo.y.floor() as usize..(hi.y.ceil() as usize).min(size) {
            for x in lo.x.floor() as usize..(hi.x.ceil() as usize).min(size) {
                let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let b0 = (t[1] - p).perp_dot(t[2] - p) / area;
                let b1 = (t[2] - p).perp_dot(t[0] - p) / area;
                if b0 > 1e-4 && b1 > 1e-4 && 1.0 - b0 - b1 > 1e-4 {
                    hits[y * size + x] = hits[y * size + x].saturating_add(1);
                }
            }
        }
    }
    let overlapping = hits.iter().filter(|&&h| h > 1).count();
    let covered = hits.iter().filter(|&&h| h > 0).count();
    assert_eq!(
        overlapping, 0,
        "{overlapping} of {covered} texels in two faces"
    );
    assert!(
        covered as f32 > 0.25 * (size * size) as f32,
        "the atlas is used: {covered} texels"
    );
}

const PIPELINE: &str = r#"
seed = 4
[input]
mesh = "data/meshes/eight.off"
exemplar = "builtin:noise"

[[stage]]
kind = "tangent_field"
isotropic = true
patch_size = 0.25

[[stage]]
kind = "lapped_paste"
atlas_size = 256

[[stage]]
kind = "export"
formats = ["obj", "preview", "pastes"]
preview_size = 96
"#;

#[test]
fn pastes_are_entities_in_paste_order() {
    let mut source = ConfigSource::from_text("lapped.toml", PIPELINE);
    source.base_dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let p = Pipeline::from_source(source).expect("valid config");
    let input = load_input(&p.input, &p.source.base_dir, &p.source.file).unwrap();
    let mut world = World::new();
    run_in_world(&p, &mut world, input).expect("pipeline runs");
    let active = world.resource::<ActiveMesh>().0;
    let faces = world.get::<Geometry>(active).unwrap().0.face_count();
    let mut q = world.query::<(&PasteOf, &PasteOrder, &PatchFaces, &PatchUvs, &PatchDrawn)>();
    let mut orders: Vec<u32> = Vec::new();
    let mut drawn = 0usize;
    for (of, order, pf, uvs, d) in q.iter(&world) {
        assert_eq!(of.0, active);
        assert_eq!(uvs.0.len(), 3 * pf.0.len(), "one uv per corner");
        assert_eq!(d.0.len(), pf.0.len());
        assert!(pf.0.iter().all(|&f| (f as usize) < faces));
        orders.push(order.0);
        drawn += d.0.iter().filter(|&&x| x).count();
    }
    orders.sort_unstable();
    assert!(orders.len() > 3);
    assert_eq!(orders, (0..orders.len() as u32).collect::<Vec<_>>());
    // Runtime pasting draws each face between once and a few times.
    let draws = drawn as f64 / faces as f64;
    assert!((1.0..4.0).contains(&draws), "{draws} draws per face");
    assert_eq!(world.resource::<TexturePatches>().0.len(), 1);
    let atlas = world
        .get::<AtlasTexture>(active)
        .expect("atlas_size > 0 builds an atlas");
    assert_eq!(atlas.uvs.len(), 3 * faces);
    let job = world.resource::<ExportJob>();
    let pastes = job.pastes.as_ref().expect("the pastes format");
    assert_eq!(pastes.pastes.len(), orders.len());
    assert!(job.uvs.is_some(), "the atlas goes into the OBJ");
    assert_eq!(job.previews.len(), 3);
    assert!(job.images.iter().any(|(n, _)| n == "atlas_preview_0.png"));
}

#[test]
fn runs_are_identical_at_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    let cfg = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("configs/30_lapped_bunny_isotropic.toml");
    let mut outs = Vec::new();
    for threads in ["1", "2"] {
        let out = dir.path().join(format!("t{threads}"));
        let (code, _, stderr) = run_cli(&[
            "run",
            cfg.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--threads",
            threads,
            "--set",
            "output.metric_samples=10",
        ]);
        assert_eq!(code, 0, "{stderr}");
        outs.push(out);
    }
    for name in [
        "result_pastes.obj",
        "result_pastes.mtl",
        "result_patch_0.png",
        "preview_0.png",
        "preview_2.png",
    ] {
        let a = std::fs::read(outs[0].join(name)).unwrap();
        let b = std::fs::read(outs[1].join(name)).unwrap();
        assert!(a == b, "{name} differs between 1 and 2 threads");
    }
    // One OBJ group per paste, in order; every face drawn at least once.
    let obj = std::fs::read_to_string(outs[0].join("result_pastes.obj")).unwrap();
    let groups: Vec<&str> = obj.lines().filter(|l| l.starts_with("g ")).collect();
    let metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(outs[0].join("metrics.json")).unwrap())
            .unwrap();
    let lapped = &metrics["stages"][1]["metrics"];
    assert_eq!(groups.len() as u64, lapped["pastes"].as_u64().unwrap());
    assert_eq!(groups[0], "g paste_00000");
    assert_eq!(lapped["uncovered_faces"].as_u64(), Some(0));
    let draws = lapped["mean_draws_per_face"].as_f64().unwrap();
    assert!((1.0..4.0).contains(&draws), "{draws}");
    let mesh = load("bunny_1k8.obj");
    let face_of: std::collections::HashMap<Vec<u32>, usize> = (0..mesh.face_count())
        .map(|f| (mesh.face(f).to_vec(), f))
        .collect();
    let mut drawn = vec![false; mesh.face_count()];
    let mut group_faces = 0usize;
    for l in obj.lines().filter(|l| l.starts_with("f ")) {
        let vs: Vec<u32> = l[2..]
            .split(' ')
            .map(|c| c.split('/').next().unwrap().parse::<u32>().unwrap() - 1)
            .collect();
        group_faces += 1;
        // The OBJ keeps each face's corner order.
        drawn[face_of[&vs]] = true;
    }
    assert!(group_faces >= mesh.face_count());
    assert!(
        drawn.iter().all(|&d| d),
        "every face is drawn by some paste"
    );
}

#[test]
fn lapped_configs_are_valid() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs");
    let mut found = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        if name.contains("_lapped_") && name.ends_with(".toml") {
            let source = ConfigSource::from_file(&path).unwrap();
            Pipeline::from_source(source).unwrap_or_else(|e| panic!("{name}: {e}"));
            found += 1;
        }
    }
    assert!(found >= 3);
}

/// Runs a config text (relative paths from the package root) in a world.
fn world_of(text: &str) -> World {
    let mut source = ConfigSource::from_text("lapped.toml", text);
    source.base_dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let p = Pipeline::from_source(source).expect("valid config");
    let input = load_input(&p.input, &p.source.base_dir, &p.source.file).unwrap();
    let mut world = World::new();
    run_in_world(&p, &mut world, input).expect("pipeline runs");
    world
}

fn stage_metrics(world: &World, index: usize) -> serde_json::Map<String, serde_json::Value> {
    world.resource::<Metrics>().stages[index].clone()
}

#[test]
fn quads_are_triangulated_and_frames_drive_the_field() {
    let world = world_of(
        r#"
seed = 2
[input]
mesh = "builtin:cube"
exemplar = "builtin:stripes"
[input.mesh_options]
subdivisions = 3

[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]

[[stage]]
kind = "tangent_field"
mode = "frames"
patch_size = 0.3

[[stage]]
kind = "lapped_paste"
"#,
    );
    let active = world.resource::<ActiveMesh>().0;
    let mesh = &world.get::<Geometry>(active).unwrap().0;
    assert!(mesh.is_triangle_mesh());
    assert_eq!(
        mesh.face_count(),
        2 * 6 * 64,
        "6 sides of 8 × 8 quads, split"
    );
    let field = world.get::<surfsynth::world::FaceField>(active).unwrap();
    // On the cube's sides the frames' up is +Y, projected (vertex frames
    // at the cube's edges lean a little: their normals are averaged).
    let normals = mesh.face_normals();
    for (t, n) in field.t.iter().zip(&normals) {
        if n.y.abs() < 0.5 {
            assert!(t.normalize().y > 0.95, "{t:?} on a side with normal {n:?}");
        }
    }
    let m = stage_metrics(&world, 2);
    assert_eq!(m["uncovered_faces"], 0, "{m:?}");
    assert_eq!(stage_metrics(&world, 1)["triangulated"], true);
}

#[test]
fn a_user_mask_cuts_the_patch_along_it() {
    let world = world_of(
        r#"
seed = 5
[input]
mesh = "data/meshes/eight.off"
exemplar = "data/textures/brick.png"

[[stage]]
kind = "tangent_field"
patch_size = 0.3

[[stage]]
kind = "lapped_paste"
mask = "image"
mask_image = "configs/masks/brick_patch.png"
"#,
    );
    let m = stage_metrics(&world, 1);
    assert_eq!(m["uncovered_faces"], 0, "{m:?}");
    // The texture patch is the mask's bounding box plus a clear border, and
    // its alpha is zero exactly outside the mask.
    let textures = &world.resource::<TexturePatches>().0;
    assert_eq!(textures.len(), 1);
    let patch = &textures[0];
    let mask = surfsynth::image::load_image(
        &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/masks/brick_patch.png"),
    )
    .unwrap();
    let inside = mask.data.iter().filter(|&&v| v >= 0.5).count();
    let visible = patch.data.chunks_exact(4).filter(|p| p[3] > 0.0).count();
    assert_eq!(visible, inside);
    assert!(patch.width < mask.width && patch.height < mask.height);
}

#[test]
fn mask_errors_are_caught_when_the_config_loads() {
    let text = r#"
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:noise"

[[stage]]
kind = "tangent_field"

[[stage]]
kind = "lapped_paste"
mask = "image"
"#;
    let e = Pipeline::from_source(ConfigSource::from_text("bad.toml", text)).unwrap_err();
    let msg = e.to_string();
    assert!(
        msg.contains("mask_image") && msg.contains("bad.toml"),
        "{msg}"
    );
    let text = text.replace(
        "mask = \"image\"",
        "mask = \"image\"\nmask_image = \"no/such/mask.png\"",
    );
    let e = Pipeline::from_source(ConfigSource::from_text("bad.toml", &text)).unwrap_err();
    assert!(e.to_string().contains("no/such/mask.png"), "{e}");
    // lapped_paste needs the field first.
    let text = "[input]\nmesh = \"builtin:icosphere\"\nexemplar = \"builtin:noise\"\n[[stage]]\nkind = \"lapped_paste\"\n";
    let e = Pipeline::from_source(ConfigSource::from_text("bad.toml", text)).unwrap_err();
    assert!(e.to_string().contains("tangent_field"), "{e}");
}

// ----- audit of the remaining checklist items ------------------------------------

use rand::{Rng, SeedableRng};
use surfsynth::kernels::lapped::composite::{LappedComposite, PasteRecord};
use surfsynth::kernels::lapped::coverage::drawn_faces;
use surfsynth::kernels::lapped::paste::face_difficulty;
use surfsynth::kernels::metrics::{EnergySettings, SurfaceSignal, surface_texture_energy};
use surfsynth::kernels::surface::surface_sample::CornerFn;

/// A texture patch with random colours, so composites differ by paste.
fn noisy_texture(seed: u64) -> TexturePatch {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let data: Vec<f32> = (0..64 * 64 * 3).map(|_| rng.random::<f32>()).collect();
    let ex = Image::from_data(64, 64, 3, data).unwrap();
    TexturePatch::cut(
        &ex,
        Wrap::Repeat,
        [0, 0],
        &splotch_mask(64, 3),
        3.0,
        16,
        "noisy",
    )
    .unwrap()
}

/// The pastes of a lapped result in paste order: (order, texture patch,
/// faces, per-corner patch UVs).
type Paste = (u32, u32, Vec<u32>, Vec<Vec2>);

fn pastes_of(world: &mut World) -> Vec<Paste> {
    let mut records: Vec<Paste> = Vec::new();
    let mut q = world.query::<(&PasteOrder, &TexturePatchIndex, &PatchFaces, &PatchUvs)>();
    for (o, t, f, u) in q.iter(world) {
        records.push((o.0, t.0, f.0.clone(), u.0.clone()));
    }
    records.sort_by_key(|r| r.0);
    records
}

/// The composite of `pastes` as the records `LappedComposite` takes.
fn paste_records(pastes: &[Paste]) -> Vec<PasteRecord<'_>> {
    pastes
        .iter()
        .map(|r| PasteRecord {
            texture: r.1,
            faces: &r.2,
            uvs: &r.3,
        })
        .collect()
}

/// The bunny with planks along the global up field (config 31, no atlas):
/// the paste loop's report, the texture energy and histogram distance in
/// metrics.json, and the energy recomputed here from the pastes.
///
/// The result's quality is gated against the peer on a plane
/// (`lapped_result_on_a_plane_looks_like_the_peers`), not here: the peer
/// makes images, and on a curved surface only the surface measures apply,
/// whose completeness has fewer candidate templates than an image of equal
/// area has windows (docs/metrics.md), so it would not compare like with like.
#[test]
fn lapped_result_reports_its_pastes_and_quality() {
    let mut world = world_of(
        r#"
seed = 3
[input]
mesh = "data/meshes/bunny_1k8.obj"
exemplar = "data/textures/planks.png"

[[stage]]
kind = "tangent_field"
mode = "global"
up = [0.0, 1.0, 0.0]
patch_size = 0.2

[[stage]]
kind = "lapped_paste"

[output]
metric_samples = 200
"#,
    );
    // The paste loop's report (§3.6) is in the stage metrics.
    let m = stage_metrics(&world, 1);
    let pastes = m["pastes"].as_u64().unwrap() as usize;
    assert_eq!(m["uncovered_faces"].as_u64(), Some(0), "{m:?}");
    let active = world.resource::<ActiveMesh>().0;
    let mesh = world.get::<Geometry>(active).unwrap().0.clone();
    let records = pastes_of(&mut world);
    assert_eq!(records.len(), pastes);
    // The paste entities hold the faces runtime pasting draws (§4).
    let held: usize = records.iter().map(|r| r.2.len()).sum();
    let per_face = m["mean_pastes_per_face"].as_f64().unwrap();
    let draws = m["mean_draws_per_face"].as_f64().unwrap();
    assert!((draws - held as f64 / mesh.face_count() as f64).abs() < 1e-9);
    assert!(draws <= per_face);

    // metrics.json gets a texture energy and a histogram distance.
    let result = &world.resource::<Metrics>().result;
    let reported = result["texture_energy"]["mean"]
        .as_f64()
        .unwrap_or_else(|| panic!("no texture energy for a lapped result: {result:?}"));
    let wasserstein = result["histogram_wasserstein"]
        .as_array()
        .expect("a Wasserstein distance per channel")
        .iter()
        .map(|v| v.as_f64().unwrap())
        .fold(0.0f64, f64::max);
    assert!(
        wasserstein.is_finite() && wasserstein < 0.1,
        "{wasserstein}"
    );

    // The same measure, recomputed here from the pastes.
    let exemplar = world.resource::<Exemplar>().image.clone();
    let spacing = world.resource::<TexelSpacing>().0;
    let textures = world.resource::<TexturePatches>().0.clone();
    let recs = paste_records(&records);
    let topo = Topology::build(&mesh);
    let settings = EnergySettings {
        neighbourhood: 7,
        samples: 200,
        seed: 3,
        ..Default::default()
    };
    let c = LappedComposite::new(&mesh, &recs, &textures, &exemplar.mean()).unwrap();
    let frames = c.frames(&mesh, Vec3::X);
    let eval = |cs: [u32; 3], w: [f32; 3], out: &mut [f32]| c.eval_corners(cs, w, out);
    let signal = SurfaceSignal::Corners {
        channels: c.channels(),
        eval: CornerFn(&eval),
    };
    let e = surface_texture_energy(
        &mesh, &topo, &frames, spacing, &signal, &exemplar, &settings,
    )
    .mean as f64;
    eprintln!("lapped energy {e:.5} (reported {reported:.5}), wasserstein {wasserstein:.4}");
    assert!(
        (e - reported).abs() <= 1e-6 * e.max(1e-3),
        "{e} vs {reported}"
    );
}

/// Lapped textures on a flat plane: the centre 64² crop of planks (so each
/// paste, a splotch of the whole crop, is about half the image), pasted
/// along the global up field on a 2-unit plane at 0.8 units per texture
/// patch (160 exemplar pixels across), covering every face; the composite
/// resampled at one exemplar pixel per pixel around the centre, a 127² image
/// the pastes cover wholly, and the crop.
fn lapped_plane_image() -> (Image, Image) {
    let full = load_image(&data_file("textures/planks.png")).unwrap();
    let crop = gates::to_rgb(&gates::crop(&full, 32, 32, 64, 64));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("planks_64.png");
    let bytes: Vec<u8> = crop
        .data
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    image::save_buffer(&path, &bytes, 64, 64, image::ColorType::Rgb8).unwrap();
    let mut world = world_of(&format!(
        r#"
seed = 3
[input]
mesh = "builtin:plane"
exemplar = "{}"
[input.mesh_options]
resolution = [41, 41]

[[stage]]
kind = "tangent_field"
mode = "global"
up = [0.0, 1.0, 0.0]
patch_size = 0.8
units = "world"

[[stage]]
kind = "lapped_paste"
"#,
        path.display()
    ));
    let m = stage_metrics(&world, 1);
    assert_eq!(m["uncovered_faces"].as_u64(), Some(0), "{m:?}");
    let active = world.resource::<ActiveMesh>().0;
    let mesh = world.get::<Geometry>(active).unwrap().0.clone();
    let exemplar = world.resource::<Exemplar>().image.clone();
    let spacing = world.resource::<TexelSpacing>().0;
    let textures = world.resource::<TexturePatches>().0.clone();
    let records = pastes_of(&mut world);
    let recs = paste_records(&records);
    let c = LappedComposite::new(&mesh, &recs, &textures, &exemplar.mean()).unwrap();
    let eval = |cs: [u32; 3], w: [f32; 3], out: &mut [f32]| c.eval_corners(cs, w, out);
    let signal = SurfaceSignal::Corners {
        channels: c.channels(),
        eval: CornerFn(&eval),
    };
    // The field's frame on the plane: normal +z, texture up +y.
    let frame = surfsynth::kernels::surface::frames::TangentFrame::from_up(Vec3::Z, Vec3::Y);
    let img = gates::plane_image(&mesh, &signal, &frame, Vec3::ZERO, spacing, 127);
    (img, exemplar)
}

/// Every face of the plane is covered and the pastes cover the gate's image
/// (the checks of `lapped_plane_image`).
#[test]
fn lapped_result_on_a_plane_covers_it() {
    let (img, exemplar) = lapped_plane_image();
    assert_eq!((img.width, img.height), (127, 127));
    assert_eq!(img.channels, exemplar.channels);
}

/// The plane's image against the peer's 127² synthesis of the same crop
/// (`tests/common/gates.rs`, `NEAR_PEER`), with the paper's single texture
/// patch (an explicit `patch_size` cuts one, so every paste is the same
/// patch and no choice is made). Fails: splotch outlines cut the planks
/// and the exemplar's variety is missing; measured (every window, stop
/// 33; ours vs peer, bound): coherence p90 0.00409 vs 0.00152 (≤ 0.00229),
/// completeness 0.00121 vs 0.000785 (≤ 0.00118); structure 0.166 vs 0.103,
/// sharpness 1.00 vs 0.708 and histogram 0.0210 vs 0.0357 pass. The
/// stage's defaults (automatic texture patches, the matched choice and its
/// shift) meet issue 13's stricter gate on planks and every shared photo
/// at 256² (`tests/it/plane.rs`).
#[test]
#[ignore = "fails the peer gate with one texture patch (the paper): coherence p90: ours 0.00409 vs peer 0.00152; completeness: ours 0.00121 vs peer 0.000785 (the defaults pass issue 13's gate in tests/it/plane.rs)"]
fn lapped_result_on_a_plane_looks_like_the_peers() {
    let (img, exemplar) = lapped_plane_image();
    gates::assert_image_near_peer("lapped on a plane, planks", &img, None, &exemplar);
}

#[test]
fn difficult_faces_are_seeded_first_early_on() {
    // The fandisk: flat regions, sharp creases and a few curved parts.
    let mesh = load("fandisk.off");
    let m = TriMesh::new(&mesh).unwrap();
    let t = global_up_field(&m, Vec3::Y, 0.1 * diagonal(&mesh));
    let field = FaceField {
        t: &t,
        isotropic: false,
        scale: 1.0,
    };
    let difficulty = face_difficulty(&m, field);
    let areas: Vec<f32> = (0..m.face_count()).map(|f| m.area(f)).collect();
    let area: f64 = areas.iter().map(|&a| a as f64).sum();
    let mesh_mean: f64 = difficulty
        .iter()
        .zip(&areas)
        .map(|(&d, &a)| d as f64 * a as f64)
        .sum::<f64>()
        / area;
    let textures = [texture(true)];
    let seeds_mean = |boost: f32| -> f64 {
        let mut sum = 0.0;
        let mut n = 0;
        for seed in 0..4 {
            let settings = PasteSettings {
                difficult_first: boost,
                max_pastes: 12,
                seed,
                ..Default::default()
            };
            let out = paste_until_covered(&m, field, &textures, &settings, &Progress::hidden());
            for p in &out.pastes {
                sum += difficulty[p.faces[0] as usize] as f64;
                n += 1;
            }
        }
        sum / n as f64
    };
    let uniform = seeds_mean(0.0);
    let boosted = seeds_mean(50.0);
    eprintln!(
        "mesh mean difficulty {mesh_mean:.3}, seeds: uniform {uniform:.3}, boosted {boosted:.3}"
    );
    assert!(
        boosted >= 1.5 * uniform && boosted >= 1.5 * mesh_mean,
        "boosted {boosted} vs uniform {uniform} (mesh mean {mesh_mean})"
    );
}

/// Points on a grid over the hull's bounds that lie inside it.
fn hull_points(hull: &surfsynth::kernels::lapped::hull::Hull, n: usize) -> Vec<Vec2> {
    let (lo, hi) = hull.bounds;
    (0..n * n)
        .map(|i| {
            let f = Vec2::new((i % n) as f32 + 0.5, (i / n) as f32 + 0.5) / n as f32;
            lo + (hi - lo) * f
        })
        .filter(|&p| hull.contains(p))
        .collect()
}

/// Fraction of `points` inside some triangle of the patch in `(s, t)`.
fn covered_fraction(
    patch: &surfsynth::kernels::lapped::grow::SurfacePatch,
    points: &[Vec2],
) -> f64 {
    let inside = |p: Vec2, t: &[u32; 3]| {
        let [a, b, c] = t.map(|v| patch.st[v as usize]);
        let cross = |u: Vec2, v: Vec2| u.perp_dot(v);
        let (d1, d2, d3) = (
            cross(b - a, p - a),
            cross(c - b, p - b),
            cross(a - c, p - c),
        );
        (d1 >= 0.0 && d2 >= 0.0 && d3 >= 0.0) || (d1 <= 0.0 && d2 <= 0.0 && d3 <= 0.0)
    };
    let hit = points
        .iter()
        .filter(|&&p| patch.tris.iter().any(|t| inside(p, t)))
        .count();
    hit as f64 / points.len() as f64
}

#[test]
fn regrowing_covers_hull_area_the_solve_uncovered() {
    let tex = texture(true);
    let points = hull_points(&tex.hull, 32);
    let mesh = load("knot.off");
    let m = TriMesh::new(&mesh).unwrap();
    let t = global_up_field(&m, Vec3::Y, 0.2 * diagonal(&mesh));
    let field = FaceField {
        t: &t,
        isotropic: false,
        scale: 1.0,
    };
    let mut grower = Grower::new(&m, field, GrowSettings::default());
    let (mut before_sum, mut after_sum, mut regrown) = (0.0, 0.0, 0usize);
    let seeds = 10u32;
    for k in 0..seeds {
        let seed = (k * 7919) % m.face_count() as u32;
        let mut patch = grower.start(seed, [0.3, 0.3, 0.4], k as f32);
        grower.grow(&mut patch, &tex.hull);
        optimise_parametrisation(&m, &mut patch, &SolveSettings::default());
        let before = covered_fraction(&patch, &points);
        // Grow again and re-solve until nothing is added (the paste loop's
        // regrow rounds).
        for _ in 0..4 {
            let added = grower.grow(&mut patch, &tex.hull);
            regrown += added;
            if added == 0 {
                break;
            }
            optimise_parametrisation(&m, &mut patch, &SolveSettings::default());
        }
        let after = covered_fraction(&patch, &points);
        eprintln!("seed face {seed}: hull covered {before:.3} -> {after:.3}");
        before_sum += before;
        after_sum += after;
    }
    let (before, after) = (before_sum / seeds as f64, after_sum / seeds as f64);
    assert!(regrown > 0, "the solve never uncovered hull area");
    // The anisotropic field does not integrate on the knot: solving bends
    // the parametrisation away from the grown faces and leaves a fifth of
    // the hull uncovered; regrowing covers nearly all of it again (what
    // remains is refused for distortion or reach).
    assert!(
        after >= before + 0.1,
        "regrowing did not cover more: {before} -> {after}"
    );
    assert!(
        after >= 0.95,
        "hull covered {after} on average after regrowing"
    );

    // The paste loop does the same and reports it; with no regrow rounds
    // it never regrows.
    let textures = [tex.clone()];
    for (rounds, expect_regrown) in [(0u32, false), (2, true)] {
        let settings = PasteSettings {
            regrow_rounds: rounds,
            max_pastes: 20,
            seed: 1,
            ..Default::default()
        };
        let out = paste_until_covered(&m, field, &textures, &settings, &Progress::hidden());
        assert_eq!(
            out.report.regrown_faces > 0,
            expect_regrown,
            "{:?}",
            out.report
        );
    }
}

#[test]
fn culled_faces_leave_the_composite_unchanged() {
    // Runtime pasting (§4) drops faces hidden by later pastes; drawing only
    // the kept faces must give the same picture.
    let textures = [noisy_texture(1), noisy_texture(2)];
    let mesh = load("eight.off");
    let m = TriMesh::new(&mesh).unwrap();
    let t = global_up_field(&m, Vec3::Y, 0.2 * diagonal(&mesh));
    let field = FaceField {
        t: &t,
        isotropic: true,
        scale: 1.0,
    };
    // Every layer kept, to compare with what is drawn.
    let mut settings = PasteSettings {
        seed: 5,
        ..Default::default()
    };
    settings.coverage.keep_hidden = true;
    let out = paste_until_covered(&m, field, &textures, &settings, &Progress::hidden());
    assert!(out.report.uncovered_faces.is_empty());
    let sizes: Vec<usize> = out.pastes.iter().map(|p| p.faces.len()).collect();
    let drawn = drawn_faces(&out.coverage, &sizes, &textures, &settings.coverage);
    let composite =
        |layers: &mut dyn Iterator<Item = &surfsynth::kernels::lapped::coverage::FaceLayer>,
         b: [f32; 3]| {
            let mut c = [0.5f32; 3];
            let mut px = [0.0f32; 4];
            for l in layers {
                let uv = l.uv[0] * b[0] + l.uv[1] * b[1] + l.uv[2] * b[2];
                let tex = &textures[l.texture as usize];
                tex.image.sample_uv(uv.x, uv.y, Wrap::Clamp, &mut px);
                let a = tex.alpha_at(uv);
                for i in 0..3 {
                    c[i] += (px[i] - c[i]) * a;
                }
            }
            c
        };
    let (mut layers_total, mut drawn_total, mut worst) = (0usize, 0usize, 0.0f32);
    for f in 0..m.face_count() {
        let layers: Vec<_> = out.coverage.layers(f).collect();
        let kept: Vec<_> = layers
            .iter()
            .filter(|l| drawn[l.paste as usize][l.slot as usize])
            .copied()
            .collect();
        assert!(!kept.is_empty(), "face {f} is never drawn");
        layers_total += layers.len();
        drawn_total += kept.len();
        for b in lattice_samples(out.coverage.levels[f]) {
            let all = composite(&mut layers.iter(), b);
            let culled = composite(&mut kept.iter(), b);
            for i in 0..3 {
                worst = worst.max((all[i] - culled[i]).abs());
            }
        }
    }
    let draws = drawn_total as f64 / m.face_count() as f64;
    let per_face = layers_total as f64 / m.face_count() as f64;
    eprintln!("pastes per face {per_face:.2}, draws per face {draws:.2}, worst change {worst}");
    assert!(worst <= 2.0 / 255.0, "culling changed a colour by {worst}");
    assert!(
        draws < per_face,
        "nothing was culled: {draws} draws vs {per_face} layers"
    );
    assert!(draws >= 1.0);
}

/// A paste's texture patch and the faces it draws with their coordinates.
type Shown = (u32, Vec<(u32, [Vec2; 3])>);

/// The paste loop drops layers that can no longer be seen as it goes
/// (`Coverage::add_paste`); that changes nothing it decides: the same
/// pastes, the same report, and exactly the same drawn faces with the same
/// coordinates as when every layer is kept. Only the held layers shrink.
#[test]
fn dropping_hidden_layers_changes_no_decision() {
    let textures = [noisy_texture(1), noisy_texture(2)];
    for (name, isotropic) in [("eight.off", true), ("bunny_1k8.obj", false)] {
        let mesh = load(name);
        let m = TriMesh::new(&mesh).unwrap();
        let t = global_up_field(&m, Vec3::Y, 0.2 * diagonal(&mesh));
        let field = FaceField {
            t: &t,
            isotropic,
            scale: 1.0,
        };
        let run = |keep_hidden: bool| {
            let mut settings = PasteSettings {
                seed: 9,
                ..Default::default()
            };
            settings.coverage.keep_hidden = keep_hidden;
            let out = paste_until_covered(&m, field, &textures, &settings, &Progress::hidden());
            let sizes: Vec<usize> = out.pastes.iter().map(|p| p.faces.len()).collect();
            let drawn = drawn_faces(&out.coverage, &sizes, &textures, &settings.coverage);
            let shown: Vec<Shown> = out
                .pastes
                .iter()
                .zip(&drawn)
                .map(|(p, d)| {
                    let faces = p
                        .faces
                        .iter()
                        .zip(&p.uvs)
                        .zip(d)
                        .filter(|(_, d)| **d)
                        .map(|((&f, &uv), _)| (f, uv))
                        .collect();
                    (p.texture, faces)
                })
                .collect();
            (out.report, shown, out.coverage.held_layers())
        };
        let (kept_report, kept_shown, kept_layers) = run(true);
        let (report, shown, layers) = run(false);
        let mut expected = kept_report.clone();
        expected.mean_held_per_face = report.mean_held_per_face;
        expected.max_held_per_face = report.max_held_per_face;
        assert_eq!(report, expected, "{name}");
        assert!(shown == kept_shown, "{name}: the drawn faces differ");
        assert!(
            4 * layers < 3 * kept_layers,
            "{name}: {layers} layers held vs {kept_layers} kept"
        );
    }
}

/// Growth rule 3 at the texel scale (`distortion_texels`, the default)
/// keeps the pastes per face flat as a scan gets denser under noise of a
/// fixed amplitude, where the paper's per-face rule fragments patches: on
/// the messy-scan generator at ~10 k and ~40 k vertices.
#[test]
fn pastes_per_face_do_not_grow_with_scan_density() {
    let dir = tempfile::tempdir().unwrap();
    let per_face = |vertices: usize, texels: f32| {
        let (scan, _) = common::messy::write_messy_scan(dir.path(), vertices, 1);
        let world = world_of(&format!(
            r#"
seed = 3
[input]
mesh = "{}"
exemplar = "data/textures/planks.png"
texture_scale = 0.2

[[stage]]
kind = "tangent_field"
mode = "global"
up = [0.0, 1.0, 0.0]

[[stage]]
kind = "lapped_paste"
distortion_texels = {texels}

[output]
metric_samples = 100
"#,
            scan.display()
        ));
        let m = stage_metrics(&world, 1);
        assert_eq!(m["uncovered_faces"].as_u64(), Some(0), "{m:?}");
        m["mean_pastes_per_face"].as_f64().unwrap()
    };
    let (small, large) = (per_face(10_000, 4.0), per_face(40_000, 4.0));
    eprintln!("texel-scale rule: {small:.2} pastes per face at 10 k, {large:.2} at 40 k");
    assert!(large < 1.15 * small, "{small} -> {large}");
    // The per-face rule, for contrast: the same scans fragment it.
    let (small_face, large_face) = (per_face(10_000, 0.0), per_face(40_000, 0.0));
    eprintln!("per-face rule: {small_face:.2} at 10 k, {large_face:.2} at 40 k");
    assert!(
        large_face > 1.3 * small_face,
        "{small_face} -> {large_face}"
    );
}

/// The `pastes` export reads the paste entities when the run ends (so they
/// are moved, not copied, through the result metrics): a stage after
/// `export` that pastes again would write pastes the previews do not show,
/// so it is refused, naming the fix, and no output folder is left.
#[test]
fn pastes_changed_after_export_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("after_export.toml");
    let out = dir.path().join("out");
    let text = format!(
        r#"seed = 1
[input]
mesh = "{}"
exemplar = "{}"
texture_scale = 0.15

[[stage]]
kind = "tangent_field"
isotropic = true

[[stage]]
kind = "lapped_paste"

[[stage]]
kind = "export"
formats = ["pastes"]

[[stage]]
kind = "lapped_paste"
"#,
        common::data_file("meshes/bunny_1k8.obj").display(),
        common::data_file("textures/stones.png").display()
    );
    std::fs::write(&config, text).unwrap();
    let (code, _, stderr) = common::run_cli(&[
        "run",
        config.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "-q",
    ]);
    assert_ne!(code, 0, "a later paste must not be written unpreviewed");
    assert!(
        stderr.contains("changed the pastes it exports") && stderr.contains("put `export` last"),
        "{stderr}"
    );
    assert!(!out.join("result_pastes.obj").exists());
}

/// The automatic patch count assumes a splotch fills [`SPLOTCH_FILL`] of
/// its square: the masks' mean fill is within 0.05 of it.
#[test]
fn splotches_fill_the_share_of_their_square_the_patch_count_assumes() {
    use surfsynth::stages::lapped_paste::SPLOTCH_FILL;
    let fills: Vec<f64> = (0..64u64)
        .map(|seed| {
            let m = splotch_mask(96, seed);
            m.inside.iter().filter(|&&i| i).count() as f64 / m.inside.len() as f64
        })
        .collect();
    let mean = fills.iter().sum::<f64>() / fills.len() as f64;
    assert!(
        (mean - SPLOTCH_FILL).abs() < 0.05,
        "splotches fill {mean:.3} of their square on average, SPLOTCH_FILL is {SPLOTCH_FILL}"
    );
}

/// Automatic texture patches: at most 3/4 of the exemplar's side (one
/// paste then copies under a third of the exemplar), at most 0.3 of the
/// diagonal, and enough of them to cover the exemplar.
#[test]
fn automatic_patches_copy_under_a_third_of_the_exemplar_and_cover_it() {
    use surfsynth::stages::lapped_paste::{LappedPasteSettings, SPLOTCH_FILL, auto_patches};
    let matched = LappedPasteSettings::default();
    assert_eq!(
        (matched.patch_pixels, matched.patches),
        (0, 0),
        "both automatic by default"
    );
    // The paper's random draw: the cover rule alone.
    let auto = LappedPasteSettings {
        choice: "random".into(),
        ..matched.clone()
    };
    // A large mesh against a 128² exemplar: the side cap binds.
    let (px, n) = auto_patches(&auto, (128, 128), 1.0, 10_000.0);
    assert_eq!(px, 96);
    assert!(SPLOTCH_FILL * f64::from(px * px) < 16_384.0 / 3.0);
    // n random splotches leave at most 5 % of the exemplar uncovered.
    let a = SPLOTCH_FILL * f64::from(px * px) / 16_384.0;
    assert!(
        (1.0 - a).powi(n as i32) <= 0.05 && (1.0 - a).powi(n as i32 - 1) > 0.05,
        "{n}"
    );
    // A small mesh: 0.3 of its diagonal.
    let (px, _) = auto_patches(&auto, (128, 128), 1.0, 200.0);
    assert_eq!(px, 60);
    // A tiny exemplar: 3/4 of its side, never more than the side.
    let (px, _) = auto_patches(&auto, (20, 40), 1.0, 10_000.0);
    assert_eq!(px, 15);
    // Explicit settings are kept.
    let fixed = LappedPasteSettings {
        patch_pixels: 32,
        patches: 3,
        ..auto.clone()
    };
    assert_eq!(auto_patches(&fixed, (128, 128), 1.0, 10_000.0), (32, 3));
    // The matched choice (the default) gets more candidates, within the
    // pixel budget: 48 of 96², but a large exemplar's large patches are
    // bounded by the budget (and never fewer than the cover rule's).
    use surfsynth::stages::lapped_paste::{MATCHED_PATCH_PIXELS, MATCHED_PATCHES};
    assert_eq!(
        auto_patches(&matched, (128, 128), 1.0, 10_000.0),
        (96, MATCHED_PATCHES)
    );
    let (px, n) = auto_patches(&matched, (1024, 1024), 1.0, 100_000.0);
    let (_, cover) = auto_patches(&auto, (1024, 1024), 1.0, 100_000.0);
    assert_eq!(px, 768);
    assert_eq!(
        n,
        cover.max((MATCHED_PATCH_PIXELS / u64::from(px * px)) as u32)
    );
}
