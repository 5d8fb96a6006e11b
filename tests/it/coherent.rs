//! The coherent coordinate synthesis (issue 12, `kernels::coherent`, stage
//! `coherent`): at the peer's quality on the planar benchmark, colours that
//! are exactly the exemplar at the recorded coordinates, determinism across
//! thread counts, falling energy, and any mesh pyramid (builtin planes,
//! √2 levels, meshes with boundaries and several components).

use crate::common;

use glam::{Vec2, Vec3};
use surfsynth::image::sample::Wrap;
use surfsynth::image::{Image, load_image};
use surfsynth::kernels::coherent::{
    CoherentLevel, CoherentSettings, coherent_refine, coherent_synthesis, pixel_centres,
};
use surfsynth::kernels::surface::frames::TangentFrame;
use surfsynth::kernels::wei_levoy::wl_match::SynthesisLevel;
use surfsynth::mesh::PolyMesh;
use surfsynth::progress::Progress;
use surfsynth::stages::builtin_pyramid::{BuiltinPyramidSettings, builtin_pyramid};

/// Frames with texture up = +y (s = +x on a plane facing +z).
fn frames_up_y(mesh: &PolyMesh) -> Vec<TangentFrame> {
    mesh.vertex_normals()
        .iter()
        .map(|&n| TangentFrame::from_up(n, Vec3::Y))
        .collect()
}

/// The builtin plane pyramid of the planar configs at `side`² vertices, one
/// world unit apart, and 4 levels.
fn plane_pyramid(side: u32) -> Vec<PolyMesh> {
    builtin_pyramid(&BuiltinPyramidSettings {
        mesh: "plane".into(),
        levels: 4,
        subdivisions: 0,
        resolution: [side, side],
        size: (side - 1) as f32,
        ..Default::default()
    })
    .expect("a valid builtin pyramid")
}

fn synthesise(
    meshes: &[PolyMesh],
    exemplar: &Image,
    settings: &CoherentSettings,
) -> Vec<CoherentLevel> {
    let frames: Vec<Vec<TangentFrame>> = meshes.iter().map(frames_up_y).collect();
    let levels: Vec<SynthesisLevel> = meshes
        .iter()
        .zip(&frames)
        .map(|(mesh, frames)| SynthesisLevel { mesh, frames })
        .collect();
    coherent_synthesis(&levels, exemplar, settings, None, None, &Progress::hidden())
        .expect("synthesis runs")
}

fn texture(name: &str) -> Image {
    load_image(&common::data_file(&format!("textures/{name}.png")))
        .unwrap_or_else(|e| panic!("shared texture {name}: {e}"))
}

/// The colours the stage writes: the exemplar pixel under each coordinate.
fn colours_of(coords: &[Vec2], exemplar: &Image, wrap: Wrap) -> (Vec<f32>, Vec<Vec2>) {
    let texels = pixel_centres(coords, exemplar.width, exemplar.height, wrap);
    let mut values = Vec::new();
    for t in &texels {
        values.extend_from_slice(exemplar.pixel(t.x as u32, t.y as u32));
    }
    (values, texels)
}

fn settings(seed: u64) -> CoherentSettings {
    CoherentSettings {
        seed,
        wrap: Wrap::Clamp,
        ..Default::default()
    }
}

/// Issue 12's gate (`common::gates::AT_PEER`) on every shared texture: a
/// 256² result from the whole 128² exemplar (the planar benchmark's size) on the planar pyramid (one
/// vertex per exemplar pixel), against the peer's 256² synthesis of the same
/// exemplar. The planar benchmark (`cargo bench --bench quality`) runs the
/// same method through `configs/plane/coherent.toml`. (At 160² the stones
/// histogram distance varies with the seed between 0.019 and 0.038 against
/// the peer's 0.0084, around its bound of 0.027: the exemplar's dark top-left
/// corner is under-used when the result is barely larger than the exemplar.)
#[test]
fn planar_synthesis_is_at_the_peers_quality_on_every_shared_texture() {
    const SIDE: u32 = 256;
    let meshes = plane_pyramid(SIDE);
    let mut results = Vec::new();
    for name in ["brick", "grass", "planks", "stones", "water"] {
        let exemplar = texture(name);
        let r = synthesise(&meshes, &exemplar, &settings(1));
        let (values, texels) = colours_of(&r[0].coords, &exemplar, Wrap::Clamp);
        let sources: Vec<[f32; 2]> = texels.iter().map(|t| [t.x, t.y]).collect();
        let (img, map) = common::gates::grid_image(
            &values,
            exemplar.channels as usize,
            SIDE,
            SIDE,
            Some(&sources),
        );
        let ours = common::gates::quality_of(&img, map.as_ref(), &exemplar);
        let peer = common::gates::peer_quality(&exemplar, SIDE, SIDE);
        results.push((name.to_string(), ours, peer));
    }
    common::gates::assert_all_near_peer(&results, &common::gates::AT_PEER);
}

/// The kernel's coordinates lie inside the clamped exemplar on every
/// level, and `pixel_centres` maps each to the centre of the pixel under
/// it (the stage's colours are checked against what it wrote in
/// `the_stage_colours_every_vertex_with_the_pixel_at_its_source_texel`).
#[test]
fn colours_are_the_exemplar_at_the_recorded_coordinates() {
    let meshes = plane_pyramid(48);
    let exemplar = texture("stones");
    let r = synthesise(&meshes, &exemplar, &settings(3));
    assert_eq!(r.len(), meshes.len());
    for (level, (lv, mesh)) in r.iter().zip(&meshes).enumerate() {
        assert_eq!(lv.coords.len(), mesh.vertex_count(), "level {level}");
        let (values, texels) = colours_of(&lv.coords, &exemplar, Wrap::Clamp);
        for (v, (t, c)) in texels.iter().zip(&lv.coords).enumerate() {
            // Inside the clamped exemplar, at the pixel under the coordinate.
            assert!(
                c.x >= 0.0 && c.y >= 0.0 && c.x < 128.0 && c.y < 128.0,
                "level {level} vertex {v}: {c}"
            );
            assert_eq!((t.x - 0.5, t.y - 0.5), (c.x.floor(), c.y.floor()));
            let px = exemplar.pixel(t.x as u32, t.y as u32);
            assert_eq!(&values[v * 3..v * 3 + 3], px);
        }
    }
}

/// The stage itself (not the kernel): on every level it wrote, each
/// vertex's `VertexColours` are the exemplar's pixel at its `SourceTexels`,
/// which sit on pixel centres inside the (clamped) exemplar — what the
/// bake and the material channels read.
#[test]
fn the_stage_colours_every_vertex_with_the_pixel_at_its_source_texel() {
    use bevy_ecs::prelude::*;
    use surfsynth::config::ConfigSource;
    use surfsynth::pipeline::{Pipeline, load_input, run_in_world};
    use surfsynth::world::{Exemplar, SourceTexels, VertexColours};
    let text = format!(
        r#"
seed = 3
[input]
mesh = "builtin:plane"
exemplar = "{}"
exemplar_wrap = "clamp"
texture_scale = 1.0
texture_scale_unit = "pixels_per_unit"

[[stage]]
kind = "builtin_pyramid"
mesh = "plane"
levels = 3
resolution = [48, 48]
size = 47.0

[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]

[[stage]]
kind = "coherent"
"#,
        common::data_file("textures/brick.png").display()
    );
    let mut source = ConfigSource::from_text("coherent.toml", &text);
    source.base_dir = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let p = Pipeline::from_source(source).expect("valid config");
    let input = load_input(&p.input, &p.source.base_dir, &p.source.file).expect("input loads");
    let mut world = World::new();
    run_in_world(&p, &mut world, input).expect("pipeline runs");
    let exemplar = world.resource::<Exemplar>().image.clone();
    let ch = exemplar.channels as usize;
    let mut levels = 0;
    let mut q = world.query::<(&VertexColours, &SourceTexels)>();
    for (colours, texels) in q.iter(&world) {
        levels += 1;
        assert_eq!(colours.channels, ch);
        assert_eq!(colours.values.len(), texels.0.len() * ch);
        for (v, t) in texels.0.iter().enumerate() {
            let (x, y) = (t.x - 0.5, t.y - 0.5);
            assert!(
                x.fract() == 0.0 && y.fract() == 0.0,
                "vertex {v}: {t} is not a pixel centre"
            );
            assert!(
                x >= 0.0 && y >= 0.0 && x < exemplar.width as f32 && y < exemplar.height as f32,
                "vertex {v}: {t} is outside the exemplar"
            );
            assert_eq!(
                &colours.values[v * ch..(v + 1) * ch],
                exemplar.pixel(x as u32, y as u32),
                "vertex {v} at {t}"
            );
        }
    }
    assert_eq!(levels, 3, "every pyramid level is coloured");
}

/// Same seed, same coordinates, bit for bit, at 1 and 2 threads.
#[test]
fn synthesis_is_deterministic_at_one_and_two_threads() {
    let meshes = plane_pyramid(40);
    let exemplar = texture("brick");
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("a pool")
            .install(|| synthesise(&meshes, &exemplar, &settings(11)))
    };
    let (a, b) = (run(1), run(2));
    for (x, y) in a.iter().zip(&b) {
        assert_eq!(x.coords, y.coords, "level {}", x.report.level);
    }
    // A different seed gives a different result.
    let c = synthesise(&meshes, &exemplar, &settings(12));
    assert_ne!(a[0].coords, c[0].coords);
}

/// The correction passes lower the level's appearance-space energy: every
/// pass ends at or below where it started (each vertex only takes a
/// candidate cheaper than its current coordinate, up to the occurrence
/// penalty, which is off here), and the finest level ends well below its
/// upsampled start.
#[test]
fn correction_passes_lower_the_energy() {
    let meshes = plane_pyramid(64);
    let exemplar = texture("water");
    let plain = CoherentSettings {
        spread: 0.0,
        ..settings(5)
    };
    let r = synthesise(&meshes, &exemplar, &plain);
    for lv in &r {
        let e = &lv.report.energy;
        assert_eq!(e.len(), plain.passes as usize + 1);
        for w in e.windows(2) {
            assert!(
                w[1] <= w[0] * 1.02,
                "level {}: energy rose {e:?}",
                lv.report.level
            );
        }
    }
    let e0 = &r[0].report.energy;
    assert!(e0[e0.len() - 1] < 0.8 * e0[0], "finest level: {e0:?}");
}

/// A mesh with a boundary and two components (two separate planes side by
/// side) and a √2 hierarchy (`subdivide_sqrt2` levels, shared vertex ids)
/// both synthesise: every vertex gets a coordinate inside the exemplar, and
/// the result is coherent (neighbouring vertices mostly keep their exemplar
/// offsets) on both components.
#[test]
fn works_on_several_components_and_on_sqrt2_levels() {
    use surfsynth::kernels::bangay_morkel::sqrt2::sqrt2_subdivide;
    let exemplar = texture("stones");
    // Two 24² planes, the second shifted by 40 units in x.
    let base = plane_pyramid(24);
    let two: Vec<PolyMesh> = base
        .iter()
        .map(|m| {
            let n = m.vertex_count() as u32;
            let mut positions = m.positions.clone();
            positions.extend(m.positions.iter().map(|p| *p + Vec3::new(40.0, 0.0, 0.0)));
            let tris: Vec<[u32; 3]> = m
                .triangulated()
                .faces()
                .map(|f| [f[0], f[1], f[2]])
                .collect();
            let both: Vec<[u32; 3]> = tris
                .iter()
                .copied()
                .chain(tris.iter().map(|t| t.map(|v| v + n)))
                .collect();
            PolyMesh::from_triangles(positions, &both)
        })
        .collect();
    let r = synthesise(&two, &exemplar, &settings(2));
    let coherent = |mesh: &PolyMesh, lv: &CoherentLevel| {
        let (coords, scale) = (&lv.coords, lv.report.texels_per_spacing / lv.report.spacing);
        let topo = surfsynth::mesh::Topology::build(mesh);
        let frames = frames_up_y(mesh);
        let (mut kept, mut total) = (0usize, 0usize);
        for v in 0..mesh.vertex_count() as u32 {
            for &w in topo.neighbours(v) {
                let d = frames[v as usize].texel_offset(
                    mesh.positions[w as usize] - mesh.positions[v as usize],
                    scale,
                );
                total += 1;
                if (coords[w as usize] - coords[v as usize] - d).length() < 0.5 {
                    kept += 1;
                }
            }
        }
        kept as f32 / total as f32
    };
    let c = coherent(&two[0], &r[0]);
    assert!(c > 0.5, "two components: coherent fraction {c}");
    let n = two[0].vertex_count() / 2;
    for half in [&r[0].coords[..n], &r[0].coords[n..]] {
        assert!(
            half.iter()
                .all(|p| p.x >= 0.0 && p.x < 128.0 && p.y >= 0.0 && p.y < 128.0)
        );
    }

    // √2 levels of a coarse plane.
    let mut meshes = vec![plane_pyramid(12)[0].clone()];
    for _ in 0..5 {
        let finer = sqrt2_subdivide(&meshes[0]).mesh;
        meshes.insert(0, finer);
    }
    let r = synthesise(&meshes, &exemplar, &settings(4));
    let c = coherent(&meshes[0], &r[0]);
    assert!(c > 0.3, "√2 finest level: coherent fraction {c}");
}

/// The shipped surface config on `retile` levels of the bunny (a mesh with
/// its own pyramid, 4 levels, smaller here) through the CLI: exit 0, every
/// level synthesised with falling energy, the result coloured and baked,
/// and the same bytes at 1 and 2 threads.
#[test]
fn the_surface_config_runs_on_retile_levels_and_is_deterministic() {
    let tmp = tempfile::tempdir().expect("a temporary folder");
    let run = |threads: &str| {
        let out = tmp.path().join(format!("t{threads}"));
        let m = run_config(
            "19_coherent_bunny_brick.toml",
            &["--set", "stage.1.vertices=6144", "--threads", threads],
            &out,
        );
        (out, m)
    };
    let ((a, metrics), (b, _)) = (run("1"), run("2"));
    let stage = coherent_metrics(&metrics);
    let levels = stage["levels"].as_array().expect("levels");
    assert_eq!(levels.len(), 4);
    for l in levels {
        let e: Vec<f64> = l["energy"]
            .as_array()
            .expect("energy")
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert!(e.last().unwrap() < &e[0], "level {}: {e:?}", l["level"]);
    }
    assert!(stage["texels_per_world_unit"].as_f64().unwrap() > 0.0);
    for f in ["result.ply", "result.glb"] {
        assert_eq!(
            std::fs::read(a.join(f)).expect("written"),
            std::fs::read(b.join(f)).expect("written"),
            "{f} differs between 1 and 2 threads"
        );
    }
}

/// Composability across papers: `coherent` with `start = "sources"` refines
/// a jump-map result (`configs/plane/jump_surface_coherent.toml` = the
/// `jump_surface` planar config, without its own seam refinement, plus the
/// refinement). Both runs take the paper's random choice of jumps
/// (`choice = "random"`), so the refinement has the paper's seams to
/// mend. On the configs' 256² plane (at 128², as large as the exemplar,
/// completeness is the same for both: there is no room to use more of the
/// exemplar), the refined result has lower coherence error (mean and p90)
/// and better completeness than the jump-map result alone, for stones and
/// brick. With the matched choice over four rings (stop 30) the jump-map
/// result leaves little to mend: on brick the refinement lowered the mean
/// (0.000294 → 0.000245) but not p90 (0.000443 → 0.000505) or completeness
/// (0.0000520 → 0.0000528), pipeline metrics, seed 1.
#[test]
fn refining_a_jump_map_result_lowers_its_errors() {
    let tmp = tempfile::tempdir().expect("a temporary folder");
    let quality = |config: &str, texture: &str, extra: &[&str]| {
        let exemplar = common::data_file(&format!("textures/{texture}.png"));
        let set = format!("input.exemplar={}", exemplar.display());
        let mut args = vec![
            "--set",
            &set,
            "--set",
            "seed=1",
            "--set",
            "stage.3.choice=random",
        ];
        args.extend_from_slice(extra);
        let m = run_config(
            &format!("plane/{config}.toml"),
            &args,
            &tmp.path().join(format!("{config}_{texture}")),
        );
        let q = &m["result"]["quality"]["plane"];
        let f = |k: &str| q[k].as_f64().unwrap_or_else(|| panic!("{config}: no {k}"));
        (f("coherence_mean"), f("coherence_p90"), f("completeness"))
    };
    for texture in ["stones", "brick"] {
        // The jump-map result the composed config refines: its own seam
        // refinement off, as in jump_surface_coherent.toml.
        let jump = quality("jump_surface", texture, &["--set", "stage.3.refine=none"]);
        let refined = quality("jump_surface_coherent", texture, &[]);
        eprintln!(
            "{texture}: jump_surface {jump:?} vs refined {refined:?} (coherence mean, p90, completeness)"
        );
        assert!(
            refined.0 < jump.0,
            "{texture}: coherence mean {refined:?} vs {jump:?}"
        );
        assert!(
            refined.1 < jump.1,
            "{texture}: coherence p90 {refined:?} vs {jump:?}"
        );
        assert!(
            refined.2 < jump.2,
            "{texture}: completeness {refined:?} vs {jump:?}"
        );
    }
}

/// Refining keeps the scale of the result it refines: after `jump_surface`
/// at 0.5 exemplar pixels per world unit, `coherent` with `start =
/// "sources"` and its default `scale = 0` works at 0.5 too (not at its own
/// default of one pixel per vertex spacing, 1 on this plane).
#[test]
fn refinement_works_at_the_scale_of_the_result_it_refines() {
    let tmp = tempfile::tempdir().expect("a temporary folder");
    let m = run_config(
        "plane/jump_surface_coherent.toml",
        &[
            "--set",
            "input.mesh_options.resolution=[64,64]",
            "--set",
            "input.mesh_options.size=63.0",
            "--set",
            "stage.3.scale=0.5",
            "--set",
            "stage.5.plane_size=[64,64]",
        ],
        &tmp.path().join("half"),
    );
    let stage = coherent_metrics(&m);
    let used = stage["texels_per_world_unit"].as_f64().expect("a scale");
    assert!(
        (used - 0.5).abs() < 1e-3,
        "refined at {used} texels per unit"
    );
    assert!(
        (m["result"]["scale"]["texels_per_world_unit"]
            .as_f64()
            .unwrap()
            - 0.5)
            .abs()
            < 1e-3
    );
}

/// Runs `configs/<config>` with `args` (`--set`s, `--threads`) into `out`
/// through the CLI, asserts exit 0, and returns its metrics.json.
fn run_config(config: &str, args: &[&str], out: &std::path::Path) -> serde_json::Value {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("configs")
        .join(config);
    let mut argv = vec!["run", path.to_str().expect("utf-8 path")];
    argv.extend_from_slice(args);
    argv.extend_from_slice(&["--out", out.to_str().expect("utf-8 path"), "-q"]);
    let (code, _, stderr) = common::run_cli(&argv);
    assert_eq!(code, 0, "{config}: {stderr}");
    serde_json::from_slice(&std::fs::read(out.join("metrics.json")).expect("metrics.json"))
        .expect("json")
}

/// The metrics of the run's `coherent` stage.
fn coherent_metrics(m: &serde_json::Value) -> &serde_json::Value {
    &m["stages"]
        .as_array()
        .expect("stages")
        .iter()
        .find(|s| s["kind"] == "coherent")
        .expect("a coherent stage")["metrics"]
}

/// `coherent_refine` (the seam refinement of `jump_surface`): on a 48²
/// plane copied from two places of the exemplar with a straight seam down
/// the middle, a mask of the four columns at the seam. Vertices outside the
/// mask keep their coordinates exactly; the masked ones only take a
/// neighbour's patch (k = 0), so every coordinate is one of the two
/// patches'; the neighbourhood energy falls; the result is the same at 1
/// and 2 threads.
#[test]
fn masked_refinement_moves_only_the_masked_vertices_and_lowers_the_energy() {
    const SIDE: usize = 48;
    let mesh = &plane_pyramid(SIDE as u32)[0];
    let frames = frames_up_y(mesh);
    let exemplar = texture("stones");
    // Each vertex's column and row, from its position (x right, y up).
    let min = mesh
        .positions
        .iter()
        .fold(Vec3::splat(f32::INFINITY), |a, p| a.min(*p));
    let max = mesh
        .positions
        .iter()
        .fold(Vec3::splat(f32::NEG_INFINITY), |a, p| a.max(*p));
    let grid = |p: Vec3| {
        (
            (p.x - min.x).round() as usize,
            (max.y - p.y).round() as usize,
        )
    };
    let (left, right) = (Vec2::new(10.5, 20.5), Vec2::new(70.5, 60.5));
    let start: Vec<Vec2> = mesh
        .positions
        .iter()
        .map(|&p| {
            let (x, y) = grid(p);
            let origin = if x < SIDE / 2 { left } else { right };
            origin + Vec2::new(x as f32, y as f32)
        })
        .collect();
    let mask: Vec<bool> = mesh
        .positions
        .iter()
        .map(|&p| (SIDE / 2 - 2..SIDE / 2 + 2).contains(&grid(p).0))
        .collect();
    let settings = CoherentSettings {
        k: 0,
        seed: 3,
        wrap: Wrap::Clamp,
        ..Default::default()
    };
    let level = SynthesisLevel {
        mesh,
        frames: &frames,
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                coherent_refine(
                    &level,
                    None,
                    &exemplar,
                    &settings,
                    &start,
                    &mask,
                    None,
                    &Progress::hidden(),
                )
                .expect("refinement runs")
            })
    };
    let r = run(1);
    assert_eq!(r.coords, run(2).coords, "1 and 2 threads");
    let mut moved = 0;
    for (v, (&c, &s0)) in r.coords.iter().zip(&start).enumerate() {
        if !mask[v] {
            assert_eq!(c, s0, "vertex {v} outside the mask moved");
            continue;
        }
        moved += usize::from(c != s0);
        let (x, y) = grid(mesh.positions[v]);
        let from = c - Vec2::new(x as f32, y as f32);
        assert!(
            from == left || from == right,
            "vertex {v} left both patches: {c}"
        );
    }
    let e = &r.report.energy;
    eprintln!(
        "moved {moved}, energy {e:?}, visited {:?}",
        r.report.visited
    );
    assert!(moved > 0 && e[e.len() - 1] < e[0], "energy {e:?}");
}
