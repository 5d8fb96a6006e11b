//! Retiling (Wei & Levoy 2001, §3.1) on the shared mesh set and the builtin
//! meshes: topology kept, no flipped faces, even edge lengths, vertex counts
//! on target, a faithful map back to the input, typed errors for bad input.

use crate::common;

use glam::Vec3;
use surfsynth::kernels::wei_levoy::retile::{
    RetileError, RetileSettings, RetileTarget, RetiledPyramid, SurfaceProjector, retile,
};
use surfsynth::mesh::builtin::{BuiltinOptions, builtin_mesh};
use surfsynth::mesh::{LoadOptions, MeshInfo, PolyMesh, Topology, load_mesh};

fn shared_mesh(file: &str) -> PolyMesh {
    let path = common::data_file(&format!("meshes/{file}"));
    load_mesh(&path, &LoadOptions::default())
        .unwrap_or_else(|e| panic!("loading {}: {e}", path.display()))
        .0
}

/// Edge-length coefficient of variation (std / mean) over the unique edges.
fn edge_cv(mesh: &PolyMesh) -> f64 {
    let topo = Topology::build(mesh);
    let lens: Vec<f64> = topo
        .edges
        .iter()
        .map(|&[a, b]| (mesh.positions[a as usize] - mesh.positions[b as usize]).length() as f64)
        .collect();
    let n = lens.len() as f64;
    let mean = lens.iter().sum::<f64>() / n;
    let var = lens.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / n;
    var.sqrt() / mean
}

/// Faces whose normal points against the input surface at the projection
/// of their centroid (the first few are described on stdout).
fn flipped_faces(mesh: &PolyMesh, input: &SurfaceProjector) -> usize {
    let bad: Vec<usize> = (0..mesh.face_count())
        .filter(|&f| {
            let sp = input
                .project(mesh.face_centroid(f))
                .expect("input has triangles");
            mesh.face_normal_scaled(f).dot(input.face_normal(sp.face)) <= 0.0
        })
        .collect();
    for &f in bad.iter().take(4) {
        let c = mesh.face_centroid(f);
        let sp = input.project(c).unwrap();
        let n = mesh.face_normal(f);
        let corner_dots: Vec<f32> = mesh
            .face(f)
            .iter()
            .map(|&v| {
                let q = input.project(mesh.positions[v as usize]).unwrap();
                n.dot(input.face_normal(q.face))
            })
            .collect();
        println!(
            "  flipped face {f} {:?}: centroid {c:?} is {:.4} off the input, normal dot {:.3}, \
             corner dots {corner_dots:?}, area {:.2e}",
            mesh.face(f),
            (sp.point - c).length(),
            n.dot(input.face_normal(sp.face)),
            mesh.face_area(f)
        );
    }
    bad.len()
}

/// Checks every promise of `retile` for `input`, returns the level-0 CV.
fn check_pyramid(
    name: &str,
    input: &PolyMesh,
    pyramid: &RetiledPyramid,
    settings: &RetileSettings,
) -> f64 {
    let before = MeshInfo::compute(input);
    let proj = SurfaceProjector::new(input);
    let diag = {
        let (lo, hi) = input.bounding_box().unwrap();
        (hi - lo).length()
    };
    assert_eq!(
        pyramid.levels.len(),
        settings.levels as usize,
        "{name}: level count"
    );
    let RetileTarget::Vertices(v0) = settings.target else {
        panic!("tests use vertex targets")
    };
    let mut cv0 = 0.0;
    for (l, level) in pyramid.levels.iter().enumerate() {
        let mesh = &level.mesh;
        let info = MeshInfo::compute(mesh);
        let target = (v0 as f64 / 4f64.powi(l as i32)).round();
        let cv = edge_cv(mesh);
        let flipped = flipped_faces(mesh, &proj);
        println!(
            "{name} level {l}: {} vertices (target {target}), {} faces, edge CV {cv:.3}, \
             genus {:?}, loops {}, components {}, flipped {flipped}",
            info.vertices, info.faces, info.genus, info.boundary_loops, info.components
        );
        assert!(mesh.is_triangle_mesh(), "{name} level {l}: triangles only");
        assert!(
            (info.vertices as f64 - target).abs() <= 0.05 * target,
            "{name} level {l}: {} vertices, target {target} ± 5%",
            info.vertices
        );
        assert_eq!(info.genus, before.genus, "{name} level {l}: genus");
        assert_eq!(
            info.boundary_loops, before.boundary_loops,
            "{name} level {l}: boundary loops"
        );
        assert_eq!(
            info.components, before.components,
            "{name} level {l}: components"
        );
        assert_eq!(
            info.non_manifold_edges, 0,
            "{name} level {l}: non-manifold edges"
        );
        assert_eq!(
            info.non_manifold_vertices, 0,
            "{name} level {l}: non-manifold vertices"
        );
        assert!(info.consistently_oriented, "{name} level {l}: orientation");
        assert_eq!(flipped, 0, "{name} level {l}: flipped faces");
        // The map back onto the input reproduces every vertex.
        assert_eq!(level.source_face.len(), info.vertices);
        assert_eq!(level.source_bary.len(), info.vertices);
        for (v, (&f, &b)) in level.source_face.iter().zip(&level.source_bary).enumerate() {
            assert!(
                (b.x + b.y + b.z - 1.0).abs() < 1e-4,
                "{name} level {l}: bary of {v} sums to 1"
            );
            assert!(
                b.min_element() >= -1e-5,
                "{name} level {l}: bary of {v} inside its face"
            );
            let p = proj.point_at(f, b);
            assert!(
                (p - mesh.positions[v]).length() <= 1e-4 * diag,
                "{name} level {l}: vertex {v} at {:?} but its source point is {p:?}",
                mesh.positions[v]
            );
        }
        if l == 0 {
            cv0 = cv;
        }
    }
    assert!(cv0 <= 0.25, "{name}: level-0 edge CV {cv0:.3} > 0.25");
    cv0
}

fn retile_and_check(name: &str, input: &PolyMesh, vertices: u32) -> RetiledPyramid {
    let settings = RetileSettings::with_vertices(vertices);
    let t = std::time::Instant::now();
    let pyramid = retile(input, &settings).unwrap_or_else(|e| panic!("{name}: {e}"));
    println!(
        "{name}: retiled to {vertices} vertices, 4 levels, in {:.2?}",
        t.elapsed()
    );
    check_pyramid(name, input, &pyramid, &settings);
    pyramid
}

#[test]
fn bunny_to_24k_vertices() {
    retile_and_check("bunny_1k8.obj", &shared_mesh("bunny_1k8.obj"), 24_576);
}

#[test]
fn knot_keeps_genus_one() {
    retile_and_check("knot.off", &shared_mesh("knot.off"), 12_288);
}

#[test]
fn eight_keeps_genus_two() {
    retile_and_check("eight.off", &shared_mesh("eight.off"), 6_144);
}

#[test]
fn mushroom_keeps_its_boundary_on_the_input_boundary() {
    let input = shared_mesh("mushroom.off");
    let pyramid = retile_and_check("mushroom.off", &input, 6_144);
    // Boundary vertices lie on input boundary edges: their barycentric
    // coordinates have a zero, on a side the input has no other face at.
    let topo = Topology::build(&input);
    for (l, level) in pyramid.levels.iter().enumerate() {
        let out = Topology::build(&level.mesh);
        for v in 0..level.mesh.vertex_count() as u32 {
            if !out.is_boundary_vertex(v) {
                continue;
            }
            let f = level.source_face[v as usize] as usize;
            let b = level.source_bary[v as usize].to_array();
            let face = input.face(f);
            let on_boundary_side = (0..3).any(|i| {
                let (a, c) = (face[i], face[(i + 1) % 3]);
                b[(i + 2) % 3].abs() < 1e-6
                    && topo
                        .find_edge(a, c)
                        .is_some_and(|e| topo.edge_faces(e).len() == 1)
            });
            assert!(
                on_boundary_side,
                "mushroom level {l}: boundary vertex {v} is off the input boundary"
            );
        }
    }
}

#[test]
fn builtin_icosphere_and_torus() {
    let ico = builtin_mesh("icosphere", &BuiltinOptions::default()).unwrap();
    retile_and_check("icosphere", &ico, 6_144);
    let torus = builtin_mesh("torus", &BuiltinOptions::default()).unwrap();
    retile_and_check("torus", &torus, 6_144);
}

#[test]
fn quads_are_triangulated_first() {
    let opts = BuiltinOptions {
        quads: true,
        ..BuiltinOptions::default()
    };
    let torus = builtin_mesh("torus", &opts).unwrap();
    assert!(!torus.is_triangle_mesh());
    let pyramid = retile_and_check("quad torus", &torus, 3_072);
    assert_eq!(pyramid.input.triangulated_polygons, torus.face_count());
    assert_eq!(pyramid.triangle_polygon.len(), 2 * torus.face_count());
}

#[test]
fn several_components_are_each_remeshed() {
    let ico = builtin_mesh("icosphere", &BuiltinOptions::default()).unwrap();
    let torus = builtin_mesh("torus", &BuiltinOptions::default()).unwrap();
    let n = ico.vertex_count() as u32;
    let mut positions = ico.positions.clone();
    positions.extend(
        torus
            .positions
            .iter()
            .map(|p| *p + Vec3::new(3.0, 0.0, 0.0)),
    );
    let faces: Vec<Vec<u32>> = ico
        .faces()
        .map(|f| f.to_vec())
        .chain(torus.faces().map(|f| f.iter().map(|v| v + n).collect()))
        .collect();
    let both = PolyMesh::from_polygons(positions, faces.iter().map(|f| f.as_slice()));
    let pyramid = retile_and_check("icosphere + torus", &both, 6_144);
    assert_eq!(pyramid.input.components, 2);
}

#[test]
fn teapot_with_a_non_manifold_vertex_does_not_panic() {
    let input = shared_mesh("teapot_open.obj");
    // Three levels: the spout and handle are thin tubes that need more
    // vertices than a fourth level would have.
    let settings = RetileSettings {
        levels: 3,
        ..RetileSettings::with_vertices(12_288)
    };
    let pyramid = retile(&input, &settings).expect("the non-manifold vertex is split");
    assert!(pyramid.input.split_vertices >= 1);
    let proj = SurfaceProjector::new(&input);
    for (l, level) in pyramid.levels.iter().enumerate() {
        let info = MeshInfo::compute(&level.mesh);
        println!(
            "teapot level {l}: {} vertices, CV {:.3}, components {}, loops {}",
            info.vertices,
            edge_cv(&level.mesh),
            info.components,
            info.boundary_loops
        );
        assert_eq!(info.non_manifold_edges, 0);
        assert_eq!(info.non_manifold_vertices, 0);
        assert_eq!(
            info.components, pyramid.input.components,
            "teapot level {l}: components"
        );
        assert_eq!(info.boundary_loops, 6, "teapot level {l}: boundary loops");
        // Not asserted: the spout and handle pass through the body (so the
        // nearest input point of a face may lie on another sheet), and the
        // Utah teapot's poles are fans of slivers whose normals say little.
        let flipped = flipped_faces(&level.mesh, &proj);
        println!("teapot level {l}: {flipped} faces against the input at their centroid");
        assert!(info.consistently_oriented, "teapot level {l}: orientation");
        let target = 12_288.0 / 4f64.powi(l as i32);
        assert!(
            (info.vertices as f64 - target).abs() <= 0.05 * target,
            "teapot level {l}: count"
        );
        if l == 0 {
            let cv = edge_cv(&level.mesh);
            assert!(cv <= 0.25, "teapot level 0: edge CV {cv:.3} > 0.25");
        }
    }
}

#[test]
fn fandisk_and_nut_reach_the_edge_length_bound() {
    // Sharp feature lines (fandisk) and a genus-1 PLY (nut): the remaining
    // closed shared meshes, under the same checks as the bunny.
    retile_and_check("fandisk.off", &shared_mesh("fandisk.off"), 12_288);
    retile_and_check("nut.ply", &shared_mesh("nut.ply"), 6_144);
}

#[test]
fn same_seed_same_result_at_any_thread_count() {
    let input = shared_mesh("eight.off");
    let settings = RetileSettings {
        seed: 7,
        ..RetileSettings::with_vertices(6_144)
    };
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| retile(&input, &settings).unwrap())
    };
    let one = run(1);
    assert_eq!(one, run(3), "1 thread vs 3 threads");
    let other = retile(
        &input,
        &RetileSettings {
            seed: 8,
            ..settings.clone()
        },
    )
    .unwrap();
    assert_ne!(one.levels[0].mesh, other.levels[0].mesh, "the seed matters");
}

#[test]
fn edge_length_target_sets_the_spacing() {
    let ico = builtin_mesh("icosphere", &BuiltinOptions::default()).unwrap();
    let settings = RetileSettings {
        target: RetileTarget::EdgeLength(0.05),
        levels: 2,
        ..RetileSettings::default()
    };
    let pyramid = retile(&ico, &settings).unwrap();
    let mean0 = pyramid.levels[0].mesh.average_edge_length();
    let mean1 = pyramid.levels[1].mesh.average_edge_length();
    println!("edge length 0.05: level means {mean0} and {mean1}");
    assert!(
        (mean0 - 0.05).abs() < 0.1 * 0.05,
        "level 0 mean edge {mean0}"
    );
    assert!(
        (mean1 / mean0 - 2.0).abs() < 0.2,
        "level 1 doubles the spacing"
    );
}

#[test]
fn non_manifold_edges_are_cut_and_the_surface_retiled() {
    // An icosphere with a fin: a third and a fourth triangle on one edge.
    let mut ico = builtin_mesh("icosphere", &BuiltinOptions::default()).unwrap();
    let face: Vec<u32> = ico.face(0).to_vec();
    let (a, b) = (face[0], face[1]);
    let tip = ico.positions[a as usize] * 1.5;
    let mut positions = ico.positions.clone();
    positions.push(tip);
    positions.push(tip * 1.1);
    let n = positions.len() as u32;
    let mut faces: Vec<Vec<u32>> = ico.faces().map(|f| f.to_vec()).collect();
    faces.push(vec![a, b, n - 2]);
    faces.push(vec![b, a, n - 1]);
    let refs: Vec<&[u32]> = faces.iter().map(Vec::as_slice).collect();
    ico = PolyMesh::from_polygons(positions, refs);
    let settings = RetileSettings {
        target: RetileTarget::Vertices(2000),
        levels: 1,
        ..RetileSettings::default()
    };
    let pyramid = retile(&ico, &settings).expect("the fin is cut, not refused");
    assert_eq!(pyramid.input.cut_edges, 1, "{:?}", pyramid.input);
    assert!(pyramid.input.components >= 2, "{:?}", pyramid.input);
    let level = &pyramid.levels[0];
    assert!(
        Topology::build(&level.mesh)
            .non_manifold_edges()
            .next()
            .is_none()
    );
    let n = level.mesh.vertex_count() as f64;
    assert!((n / 2000.0 - 1.0).abs() <= 0.05, "{n} vertices");
}

#[test]
fn bad_settings_and_empty_meshes_are_typed_errors() {
    let ico = builtin_mesh("icosphere", &BuiltinOptions::default()).unwrap();
    let bad = |s: RetileSettings| retile(&ico, &s).unwrap_err();
    let e = bad(RetileSettings {
        levels: 0,
        ..RetileSettings::default()
    });
    assert!(
        matches!(e, RetileError::InvalidSetting { name: "levels", .. }),
        "{e}"
    );
    let e = bad(RetileSettings::with_vertices(100));
    assert!(e.to_string().contains("768..="), "{e}");
    let e = bad(RetileSettings {
        target: RetileTarget::EdgeLength(f32::NAN),
        ..RetileSettings::default()
    });
    assert!(
        matches!(
            e,
            RetileError::InvalidSetting {
                name: "edge_length",
                ..
            }
        ),
        "{e}"
    );
    let e = retile(&PolyMesh::new(), &RetileSettings::default()).unwrap_err();
    assert!(matches!(e, RetileError::NoFaces { .. }), "{e}");
    let flat = PolyMesh::from_triangles(vec![Vec3::ZERO, Vec3::X, 2.0 * Vec3::X], &[[0, 1, 2]]);
    let e = retile(&flat, &RetileSettings::default()).unwrap_err();
    assert!(e.to_string().contains("degenerate"), "{e}");
    let mut nan = ico.clone();
    nan.positions[5].x = f32::NAN;
    let e = retile(&nan, &RetileSettings::default()).unwrap_err();
    assert!(matches!(e, RetileError::NonFinite { vertex: 5, .. }), "{e}");
}

/// Issue 15: a coarse level the surface keeps above its target no longer
/// fails the run. The perforated plate of genus 100 (its hole walls need
/// about 700 vertices) in 2 levels from 2,400: level 0 lands within 5 % of
/// 2,400; level 1 asks for 600 and is kept above it, with at most half the
/// vertices of level 0; the genus is kept on both.
#[test]
fn coarse_levels_above_their_target_are_kept_not_refused() {
    let (plate, holes) = common::messy::perforated_plate(21, 0.1);
    let settings = RetileSettings {
        levels: 2,
        ..RetileSettings::with_vertices(2_400)
    };
    let pyramid = retile(&plate, &settings).unwrap_or_else(|e| panic!("{e}"));
    let counts: Vec<usize> = pyramid
        .levels
        .iter()
        .map(|l| l.mesh.vertex_count())
        .collect();
    println!("plate at 2400: {counts:?}");
    assert_eq!(counts.len(), 2, "{counts:?}");
    assert!(
        (counts[0] as f64 - 2_400.0).abs() <= 0.05 * 2_400.0,
        "{counts:?}"
    );
    for w in counts.windows(2) {
        assert!(2 * w[1] <= w[0], "a level that does not halve: {counts:?}");
    }
    let last = pyramid.levels.last().expect("a level");
    assert!(
        last.mesh.vertex_count() > last.target_vertices + last.target_vertices / 20,
        "the case keeps a level above its target: {counts:?}"
    );
    for level in &pyramid.levels {
        assert_eq!(
            MeshInfo::compute(&level.mesh).genus,
            Some(holes as i64),
            "genus kept: {counts:?}"
        );
    }
}

// ------------------------------------------------ feasible counts (issue 15)

/// Issue 15: a scan's chips keep the few vertices their topology needs and
/// the main surface keeps the density asked for, instead of being made
/// coarser to pay for them. A 20 k messy scan (hundreds of small pieces)
/// retiled to 5,000 vertices: level 0 lands within 5 % of its derived
/// target (the large pieces' shares plus what the chips hold), and the
/// largest piece holds its area share of the 5,000 within 5 %.
#[test]
fn chips_keep_their_vertices_and_the_surface_its_density() {
    let (p, f, report) = common::messy::messy_scan(20_000, 1);
    let pos: Vec<Vec3> = p.iter().map(|a| Vec3::from(*a)).collect();
    let refs: Vec<&[u32]> = f.iter().map(Vec::as_slice).collect();
    let input = PolyMesh::from_polygons(pos, refs);
    let asked = 5_000u32;
    let settings = RetileSettings {
        levels: 1,
        ..RetileSettings::with_vertices(asked)
    };
    let pyramid = retile(&input, &settings).unwrap_or_else(|e| panic!("{e}"));
    let level = &pyramid.levels[0];
    let n = level.mesh.vertex_count();
    println!(
        "messy 20 k ({} small pieces) at {asked}: {n} vertices, target {}",
        report.small_components, level.target_vertices
    );
    assert!(
        level.target_vertices > asked as usize,
        "the chips add to the target"
    );
    assert!(
        (n as f64 - level.target_vertices as f64).abs() <= 0.05 * level.target_vertices as f64,
        "{n} vertices for a target of {}",
        level.target_vertices
    );
    // The largest piece of the result (by area) and its share of the input area.
    let topo = Topology::build(&level.mesh);
    let (count, label) = topo.components();
    let mut area = vec![0.0f64; count];
    let mut verts = vec![0usize; count];
    for (fi, face) in level.mesh.faces().enumerate() {
        area[label[face[0] as usize] as usize] += f64::from(level.mesh.face_area(fi));
    }
    for &c in &label {
        verts[c as usize] += 1;
    }
    let main = (0..count)
        .max_by(|&a, &b| area[a].total_cmp(&area[b]))
        .unwrap();
    let share = f64::from(asked) * area[main] / f64::from(input.area());
    println!(
        "largest piece: {} vertices for a share of {share:.0}",
        verts[main]
    );
    assert!(
        (verts[main] as f64 - share).abs() <= 0.05 * share,
        "largest piece: {} vertices, its share of the target {share:.0}",
        verts[main]
    );
}

/// Issue 15: a target the surface's thin parts cannot reach is not refused
/// after remeshing: a plate of genus 100 whose hole walls need about 700
/// vertices, asked for 400, comes out as coarse as its shape and topology
/// allow (genus kept), with `target_vertices` still the 400 asked for. Any
/// target the walls leave room for lands within 5 %: before collapses could
/// go into the end of an edge on a crease, 1,000 gave 1,203 and 1,500 gave
/// 2,477, the walls' vertices kept by collapses to the midpoint that would
/// cut the rims.
#[test]
fn thin_parts_above_the_target_are_kept_not_refused() {
    let (plate, holes) = common::messy::perforated_plate(21, 0.1);
    let settings = RetileSettings {
        levels: 1,
        ..RetileSettings::with_vertices(400)
    };
    let pyramid = retile(&plate, &settings).unwrap_or_else(|e| panic!("{e}"));
    let level = &pyramid.levels[0];
    let info = MeshInfo::compute(&level.mesh);
    println!(
        "plate genus {holes} at 400: {} vertices",
        level.mesh.vertex_count()
    );
    assert_eq!(info.genus, Some(holes as i64), "genus kept");
    assert_eq!(level.target_vertices, 400);
    assert!(
        level.mesh.vertex_count() > 420,
        "the walls hold more than asked"
    );
    // At targets the surface allows, the count is on target.
    for target in [800u32, 1_000, 1_500, 3_000] {
        let settings = RetileSettings {
            levels: 1,
            ..RetileSettings::with_vertices(target)
        };
        let level = &retile(&plate, &settings).unwrap().levels[0];
        let got = level.mesh.vertex_count();
        println!("plate at {target}: {got} vertices");
        assert!(
            (got as f64 - f64::from(target)).abs() <= 0.05 * f64::from(target),
            "plate at {target}: {got} vertices"
        );
        assert_eq!(
            MeshInfo::compute(&level.mesh).genus,
            Some(holes as i64),
            "plate at {target}: genus kept"
        );
    }
}

/// Issue 43: `retile` refused a non-manifold scan ("non-manifold edge
/// between vertices 267 and 322 (4 faces meet there)") that every other
/// method runs on. Two cubes sharing an edge, in every face order: the cut
/// paired the four triangles on the edge by their order, across the cubes
/// in half of the orders, so the edge stayed non-manifold and was refused.
/// Each cube is now retiled as a closed piece of its own.
#[test]
fn two_cubes_sharing_an_edge_are_retiled_in_any_face_order() {
    for seed in 0..16 {
        let (positions, triangles) = common::two_cubes_sharing_an_edge(seed);
        let input = PolyMesh::from_triangles(positions, &triangles);
        let settings = RetileSettings {
            target: RetileTarget::Vertices(1200),
            levels: 2,
            ..RetileSettings::default()
        };
        let pyramid =
            retile(&input, &settings).unwrap_or_else(|e| panic!("face order {seed}: {e}"));
        assert_eq!(
            pyramid.input.cut_edges, 1,
            "order {seed}: {:?}",
            pyramid.input
        );
        assert_eq!(
            pyramid.input.components, 2,
            "order {seed}: {:?}",
            pyramid.input
        );
        let proj = SurfaceProjector::new(&input);
        for (l, level) in pyramid.levels.iter().enumerate() {
            let info = MeshInfo::compute(&level.mesh);
            let target = 1200.0 / 4f64.powi(l as i32);
            assert!(
                (info.vertices as f64 - target).abs() <= 0.05 * target,
                "order {seed} level {l}: {} vertices",
                info.vertices
            );
            assert_eq!(info.non_manifold_edges, 0, "order {seed} level {l}");
            assert_eq!(info.non_manifold_vertices, 0, "order {seed} level {l}");
            assert_eq!(
                info.boundary_loops, 0,
                "order {seed} level {l}: each cube closed"
            );
            assert_eq!(info.components, 2, "order {seed} level {l}");
            assert!(info.consistently_oriented, "order {seed} level {l}");
            assert_eq!(
                flipped_faces(&level.mesh, &proj),
                0,
                "order {seed} level {l}"
            );
            let area = level.mesh.area();
            // The cubes' sharp edges and corners are cut by chords.
            assert!(
                (9.6..=12.1).contains(&area),
                "order {seed} level {l}: area {area} of 12"
            );
        }
    }
}

/// `k` closed wedges (triangular prisms of 60°) around the z axis from
/// z = 0 to 1, all sharing that edge (2k triangles on it), triangles facing
/// out, in an order shuffled by `seed`.
fn wedges_around_an_edge(k: usize, seed: u64) -> PolyMesh {
    let mut positions = vec![Vec3::ZERO, Vec3::Z];
    let mut triangles: Vec<[u32; 3]> = Vec::new();
    for w in 0..k {
        let angle = |d: f32| {
            let a = (w as f32 * 360.0 / k as f32 + d).to_radians();
            Vec3::new(a.cos(), a.sin(), 0.0)
        };
        let base = positions.len() as u32;
        for p in [angle(0.0), angle(60.0)] {
            positions.push(p);
            positions.push(p + Vec3::Z);
        }
        // O0 O1 A0 A1 B0 B1
        let [o0, o1, a0, a1, b0, b1] = [0, 1, base, base + 1, base + 2, base + 3];
        let centre = (positions[a0 as usize] + positions[b0 as usize]) / 3.0 + Vec3::Z * 0.5;
        for mut t in [
            [o0, a0, b0],
            [o1, b1, a1],
            [o0, o1, a1],
            [o0, a1, a0],
            [a0, a1, b1],
            [a0, b1, b0],
            [b0, b1, o1],
            [b0, o1, o0],
        ] {
            let [p, q, r] = t.map(|v| positions[v as usize]);
            if (q - p).cross(r - p).dot((p + q + r) / 3.0 - centre) < 0.0 {
                t.swap(1, 2);
            }
            triangles.push(t);
        }
    }
    let mut state = seed;
    for i in (1..triangles.len()).rev() {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        triangles.swap(i, (state >> 33) as usize % (i + 1));
    }
    PolyMesh::from_triangles(positions, &triangles)
}

/// Issue 43: three closed wedges around one edge (six triangles on it), in
/// many face orders: each is retiled as a closed piece of its own, never
/// refused for the edge.
#[test]
fn three_wedges_around_one_edge_are_retiled_in_any_face_order() {
    for seed in 0..16 {
        let input = wedges_around_an_edge(3, seed);
        let settings = RetileSettings {
            target: RetileTarget::Vertices(900),
            levels: 1,
            ..RetileSettings::default()
        };
        let pyramid =
            retile(&input, &settings).unwrap_or_else(|e| panic!("face order {seed}: {e}"));
        assert_eq!(
            pyramid.input.components, 3,
            "order {seed}: {:?}",
            pyramid.input
        );
        let info = MeshInfo::compute(&pyramid.levels[0].mesh);
        assert_eq!(
            (
                info.non_manifold_edges,
                info.non_manifold_vertices,
                info.boundary_loops
            ),
            (0, 0, 0),
            "order {seed}"
        );
        assert_eq!(info.components, 3, "order {seed}");
        assert!(info.consistently_oriented, "order {seed}");
        let proj = SurfaceProjector::new(&input);
        assert_eq!(
            flipped_faces(&pyramid.levels[0].mesh, &proj),
            0,
            "order {seed}"
        );
    }
}
