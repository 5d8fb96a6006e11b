//! Integration tests of mesh loading, repairs, statistics, builtins and mesh
//! writers, on the shared mesh set in `data/meshes` and on bad
//! inputs made in a temporary folder.

use glam::{Vec2, Vec3};
use std::path::{Path, PathBuf};
use surfsynth::mesh::builtin::{BUILTIN_MESHES, BuiltinOptions, builtin_mesh};
use surfsynth::mesh::io::{MeshFormat, load_mesh_from_bytes};
use surfsynth::mesh::{LoadOptions, LoadReport, MeshError, MeshInfo, PolyMesh, load_mesh};
use surfsynth::output::{obj::write_obj, ply::write_ply};

/// `(file, vertices, faces)` as listed in `data/README.md`.
const SHARED: &[(&str, usize, usize)] = &[
    ("bunny_1k8.obj", 1839, 3674),
    ("knot.off", 3200, 6400),
    ("eight.off", 315, 634),
    ("mushroom.off", 2337, 4608),
    ("fandisk.off", 6475, 12946),
    ("teapot_open.obj", 529, 992),
    ("nut.ply", 523, 1046),
];

fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/meshes")
}

fn load_shared(name: &str) -> (PolyMesh, LoadReport) {
    let path = data_dir().join(name);
    load_mesh(&path, &LoadOptions::default())
        .unwrap_or_else(|e| panic!("loading {}: {e}", path.display()))
}

#[test]
fn shared_meshes_load_with_the_documented_counts() {
    for &(name, nv, nf) in SHARED {
        let (mesh, report) = load_shared(name);
        assert_eq!(
            mesh.vertex_count(),
            nv,
            "{name}: vertices ({})",
            report.summary()
        );
        assert_eq!(
            mesh.face_count(),
            nf,
            "{name}: faces ({})",
            report.summary()
        );
        assert!(report.is_clean(), "{name}: {}", report.summary());
        assert_eq!(
            (report.input_vertices, report.input_faces),
            (nv, nf),
            "{name}"
        );
        assert!(mesh.is_triangle_mesh(), "{name}");
        let info = MeshInfo::compute(&mesh);
        assert_eq!((info.vertices, info.faces), (nv, nf), "{name}");
    }
}

#[test]
fn shared_mesh_topology() {
    let info = |name: &str| MeshInfo::compute(&load_shared(name).0);
    for name in ["bunny_1k8.obj", "fandisk.off"] {
        let i = info(name);
        assert!(i.is_closed(), "{name}:\n{i}");
        assert_eq!(i.genus, Some(0), "{name}:\n{i}");
        assert_eq!(i.components, 1, "{name}:\n{i}");
    }
    for (name, genus) in [("knot.off", 1), ("eight.off", 2), ("nut.ply", 1)] {
        let i = info(name);
        assert!(i.is_closed(), "{name}:\n{i}");
        assert_eq!(i.genus, Some(genus), "{name}:\n{i}");
    }
    let i = info("mushroom.off");
    assert_eq!(i.boundary_loops, 1, "mushroom:\n{i}");
    assert!(i.boundary_edges > 0);
    assert_eq!(i.genus, Some(0), "mushroom:\n{i}");
    let i = info("teapot_open.obj");
    assert_eq!(i.components, 3, "teapot:\n{i}");
    assert!(i.boundary_loops > 0, "teapot:\n{i}");
}

#[test]
fn mesh_info_table_is_readable() {
    let (mesh, _) = load_shared("eight.off");
    let text = MeshInfo::compute(&mesh).to_string();
    for needle in [
        "vertices",
        "315",
        "634 triangles",
        "genus",
        "edge length",
        "bounding box",
        "area",
    ] {
        assert!(text.contains(needle), "missing {needle:?} in\n{text}");
    }
    // Labels are padded to one column, so values line up.
    for line in text.lines() {
        assert!(line.len() > 24 && line.as_bytes()[23] == b' ', "{line:?}");
    }
}

#[test]
fn obj_reader_agrees_with_tobj() {
    // tobj renumbers vertices per group, so compare face counts, corner
    // counts and the set of positions rather than indices.
    for name in ["bunny_1k8.obj", "teapot_open.obj"] {
        let path = data_dir().join(name);
        let (ours, _) = load_mesh(&path, &LoadOptions::default()).unwrap();
        let (models, _) = tobj::load_obj(
            &path,
            &tobj::LoadOptions {
                triangulate: false,
                single_index: false,
                ..Default::default()
            },
        )
        .unwrap();
        let faces: usize = models
            .iter()
            .map(|m| m.mesh.face_arities.len().max(m.mesh.indices.len() / 3))
            .sum();
        let corners: usize = models.iter().map(|m| m.mesh.indices.len()).sum();
        assert_eq!(ours.face_count(), faces, "{name}: faces");
        assert_eq!(ours.corner_count(), corners, "{name}: corners");
        let mut theirs: Vec<[u32; 3]> = models
            .iter()
            .flat_map(|m| m.mesh.positions.chunks_exact(3))
            .map(|p| [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()])
            .collect();
        let mut mine: Vec<[u32; 3]> = ours
            .positions
            .iter()
            .map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
            .collect();
        theirs.sort_unstable();
        theirs.dedup();
        mine.sort_unstable();
        mine.dedup();
        assert_eq!(mine, theirs, "{name}: the same positions");
    }
}

/// The shared files, plus STL and ASCII/big-endian PLY versions made from
/// them (the shared set has no STL): `(name, bytes, format)`.
fn fuzz_inputs() -> Vec<(String, Vec<u8>, MeshFormat)> {
    let mut inputs = Vec::new();
    for &(name, _, _) in SHARED {
        let path = data_dir().join(name);
        let bytes = std::fs::read(&path).unwrap();
        inputs.push((
            name.to_string(),
            bytes,
            MeshFormat::from_path(&path).unwrap(),
        ));
    }
    let (eight, _) = load_shared("eight.off");
    inputs.push(("eight_bin.stl".into(), stl_binary(&eight), MeshFormat::Stl));
    inputs.push((
        "eight_ascii.stl".into(),
        stl_ascii(&eight).into_bytes(),
        MeshFormat::Stl,
    ));
    let (nut, _) = load_shared("nut.ply");
    let (ascii, big) = ply_variants(&nut);
    inputs.push(("nut_ascii.ply".into(), ascii, MeshFormat::Ply));
    inputs.push(("nut_big.ply".into(), big, MeshFormat::Ply));
    inputs
}

#[test]
fn truncated_and_corrupted_files_never_panic() {
    for (name, bytes, format) in fuzz_inputs() {
        let path = PathBuf::from(&name);
        let n = bytes.len();
        let mut cuts: Vec<usize> = vec![0, 1, 2, 3, 4, 7, 10, 50, 80, 84, 100, 200, 300, 500, 1000];
        cuts.extend((1..40).map(|k| n * k / 40));
        cuts.extend([n - 3, n - 2, n - 1]);
        for cut in cuts.into_iter().filter(|&c| c <= n) {
            let result =
                load_mesh_from_bytes(&bytes[..cut], format, &path, &LoadOptions::default());
            if let Err(e) = result {
                // Every error names the file.
                assert!(e.to_string().contains(&name), "{name} cut at {cut}: {e}");
            }
        }
        // Overwrite bytes with pseudo-random values (fixed seed).
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        for _ in 0..60 {
            let mut bad = bytes.clone();
            for _ in 0..4 {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let at = (state % n as u64) as usize;
                bad[at] = (state >> 32) as u8;
            }
            let _ = load_mesh_from_bytes(&bad, format, &path, &LoadOptions::default());
        }
    }
}

#[test]
fn truncated_files_on_disk_are_errors_or_smaller_meshes() {
    let dir = tempfile::tempdir().unwrap();
    for &(name, nv, nf) in SHARED {
        let bytes = std::fs::read(data_dir().join(name)).unwrap();
        let path = dir.path().join(name);
        for cut in [0, bytes.len() / 3, bytes.len() / 2, bytes.len() - 1] {
            std::fs::write(&path, &bytes[..cut]).unwrap();
            match load_mesh(&path, &LoadOptions::default()) {
                Ok((m, _)) => assert!(m.vertex_count() <= nv && m.face_count() <= nf, "{name}"),
                Err(e) => assert!(e.to_string().contains(name), "{e}"),
            }
        }
    }
}

/// Writes `text` to `dir/name` and loads it, expecting an error.
fn load_err(dir: &Path, name: &str, text: &str) -> MeshError {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    match load_mesh(&path, &LoadOptions::default()) {
        Ok((m, _)) => panic!("{name} loaded with {} faces", m.face_count()),
        Err(e) => {
            assert!(
                e.to_string().contains(name),
                "message does not name the file: {e}"
            );
            e
        }
    }
}

#[test]
fn bad_inputs_give_the_right_error_naming_file_and_element() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();

    // Truncated in the middle of a vertex line.
    let e = load_err(d, "cut.obj", "v 0 0 0\nv 1 0 0\nv 0 1");
    assert!(matches!(e, MeshError::Parse { .. }), "{e}");
    assert!(e.to_string().contains("line 3"), "{e}");

    let e = load_err(
        d,
        "bad_token.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 three\n",
    );
    assert!(matches!(e, MeshError::Parse { .. }), "{e}");
    assert!(
        e.to_string().contains("line 4") && e.to_string().contains("three"),
        "{e}"
    );

    let e = load_err(d, "nan.obj", "v 0 0 0\nv 1 0 0\nv 0 NaN 0\nf 1 2 3\n");
    assert!(matches!(e, MeshError::NonFinite { vertex: 2, .. }), "{e}");
    assert!(e.to_string().contains("vertex 2"), "{e}");

    let e = load_err(d, "nan.off", "OFF\n3 1 0\n0 0 0\n1 0 0\ninf 1 0\n3 0 1 2\n");
    assert!(matches!(e, MeshError::NonFinite { vertex: 2, .. }), "{e}");
    assert!(e.to_string().contains("vertex 2"), "{e}");

    let e = load_err(
        d,
        "range.obj",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 7\n",
    );
    // OBJ errors name the reference as written (7, 1-based) and its line.
    assert!(
        matches!(
            e,
            MeshError::ReferenceOutOfRange {
                line: 5,
                face: 1,
                written: 7,
                ..
            }
        ),
        "{e}"
    );
    assert!(
        e.to_string().contains("line 5") && e.to_string().contains("vertex 7"),
        "{e}"
    );

    let e = load_err(
        d,
        "negative.off",
        "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 -2 1\n",
    );
    assert!(
        matches!(
            e,
            MeshError::IndexOutOfRange {
                face: 0,
                index: -2,
                ..
            }
        ),
        "{e}"
    );
    assert!(
        e.to_string().contains("face 0") && e.to_string().contains("-2"),
        "{e}"
    );

    let e = load_err(d, "short.off", "OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    assert!(matches!(e, MeshError::Parse { .. }), "{e}");
    assert!(e.to_string().contains("expected 2 faces"), "{e}");

    let e = load_err(d, "empty.obj", "");
    assert!(matches!(e, MeshError::NoFaces { .. }), "{e}");
    let e = load_err(d, "points.obj", "v 0 0 0\nv 1 0 0\n");
    assert!(matches!(e, MeshError::NoFaces { .. }), "{e}");
    assert!(e.to_string().contains("2 vertices"), "{e}");
    let e = load_err(d, "empty.off", "");
    assert!(matches!(e, MeshError::Parse { .. }), "{e}");
    let e = load_err(d, "empty.ply", "");
    assert!(matches!(e, MeshError::Parse { .. }), "{e}");
    let e = load_err(d, "empty.stl", "");
    assert!(matches!(e, MeshError::Parse { .. }), "{e}");

    let e = load_err(d, "mesh.fbx", "whatever");
    assert!(matches!(e, MeshError::UnknownFormat { .. }), "{e}");
    assert!(
        e.to_string().contains("fbx") && e.to_string().contains(".obj"),
        "{e}"
    );

    let missing = d.join("missing.obj");
    let e = load_mesh(&missing, &LoadOptions::default()).unwrap_err();
    assert!(matches!(e, MeshError::Io { .. }), "{e}");
    assert!(e.to_string().contains("missing.obj"), "{e}");

    let e = load_mesh(Path::new("builtin:teapot"), &LoadOptions::default()).unwrap_err();
    assert!(matches!(e, MeshError::Builtin { .. }), "{e}");
}

#[test]
fn extension_is_case_insensitive() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("NUT.PLY");
    std::fs::copy(data_dir().join("nut.ply"), &path).unwrap();
    let (m, _) = load_mesh(&path, &LoadOptions::default()).unwrap();
    assert_eq!(m.vertex_count(), 523);
}

#[test]
fn merge_duplicates_is_opt_in() {
    // The bunny split into a triangle soup: every corner its own vertex.
    let (bunny, _) = load_shared("bunny_1k8.obj");
    let mut text = String::new();
    for face in bunny.faces() {
        for &v in face {
            let p = bunny.positions[v as usize];
            text.push_str(&format!("v {} {} {}\n", p.x, p.y, p.z));
        }
    }
    for f in 0..bunny.face_count() {
        text.push_str(&format!("f {} {} {}\n", 3 * f + 1, 3 * f + 2, 3 * f + 3));
    }
    let path = Path::new("soup.obj");
    let (soup, r) = load_mesh_from_bytes(
        text.as_bytes(),
        MeshFormat::Obj,
        path,
        &LoadOptions::default(),
    )
    .unwrap();
    assert_eq!(soup.vertex_count(), 3 * bunny.face_count());
    assert_eq!(r.merged_vertices, 0);
    let merge = LoadOptions {
        merge_duplicates: true,
        merge_tolerance: 0.0,
    };
    let (welded, r) = load_mesh_from_bytes(text.as_bytes(), MeshFormat::Obj, path, &merge).unwrap();
    assert_eq!(welded.vertex_count(), bunny.vertex_count());
    assert_eq!(
        r.merged_vertices,
        3 * bunny.face_count() - bunny.vertex_count()
    );
    assert!(r.summary().contains("merged"), "{}", r.summary());
    assert_eq!(MeshInfo::compute(&welded).genus, Some(0));
}

/// Binary STL of a triangle mesh.
fn stl_binary(m: &PolyMesh) -> Vec<u8> {
    let mut b = vec![b' '; 80];
    b.extend_from_slice(&(m.face_count() as u32).to_le_bytes());
    for face in m.faces() {
        b.extend_from_slice(&[0; 12]);
        for &v in face {
            for x in m.positions[v as usize].to_array() {
                b.extend_from_slice(&x.to_le_bytes());
            }
        }
        b.extend_from_slice(&[0; 2]);
    }
    b
}

fn stl_ascii(m: &PolyMesh) -> String {
    let mut s = String::from("solid test\n");
    for face in m.faces() {
        s.push_str("facet normal 0 0 0\nouter loop\n");
        for &v in face {
            let p = m.positions[v as usize];
            s.push_str(&format!("vertex {} {} {}\n", p.x, p.y, p.z));
        }
        s.push_str("endloop\nendfacet\n");
    }
    s.push_str("endsolid test\n");
    s
}

#[test]
fn stl_is_welded_on_load() {
    let (knot, _) = load_shared("knot.off");
    let path = Path::new("knot.stl");
    for bytes in [stl_binary(&knot), stl_ascii(&knot).into_bytes()] {
        let (m, _) =
            load_mesh_from_bytes(&bytes, MeshFormat::Stl, path, &LoadOptions::default()).unwrap();
        assert_eq!((m.vertex_count(), m.face_count()), (3200, 6400));
        assert_eq!(MeshInfo::compute(&m).genus, Some(1));
    }
}

/// ASCII and binary big-endian PLY encodings of `m`, with double
/// coordinates, an extra vertex property and `uint` indices named `vertex_index`.
fn ply_variants(m: &PolyMesh) -> (Vec<u8>, Vec<u8>) {
    let head = |format: &str| {
        format!(
            "ply\nformat {format} 1.0\nelement vertex {}\nproperty double x\nproperty double y\n\
             property double z\nproperty float nx\nelement face {}\nproperty list uchar uint vertex_index\nend_header\n",
            m.vertex_count(),
            m.face_count()
        )
    };
    let mut ascii = head("ascii");
    let mut big = head("binary_big_endian").into_bytes();
    for p in &m.positions {
        ascii.push_str(&format!("{} {} {} 0.5\n", p.x, p.y, p.z));
        for x in p.to_array() {
            big.extend_from_slice(&(x as f64).to_be_bytes());
        }
        big.extend_from_slice(&0.5f32.to_be_bytes());
    }
    for face in m.faces() {
        ascii.push_str(&format!("{}", face.len()));
        big.push(face.len() as u8);
        for &v in face {
            ascii.push_str(&format!(" {v}"));
            big.extend_from_slice(&v.to_be_bytes());
        }
        ascii.push('\n');
    }
    (ascii.into_bytes(), big)
}

#[test]
fn ply_ascii_and_big_endian_variants_of_nut() {
    let (nut, _) = load_shared("nut.ply");
    let (ascii, big) = ply_variants(&nut);
    for bytes in [ascii, big] {
        let (m, _) = load_mesh_from_bytes(
            &bytes,
            MeshFormat::Ply,
            Path::new("n.ply"),
            &LoadOptions::default(),
        )
        .unwrap();
        assert_eq!(m, nut);
    }
}

#[test]
fn writers_round_trip_every_shared_mesh() {
    let dir = tempfile::tempdir().unwrap();
    for &(name, _, _) in SHARED {
        let (mesh, _) = load_shared(name);
        let stem = name.replace('.', "_");

        let ply = dir.path().join(format!("{stem}.ply"));
        let grey: Vec<f32> = (0..mesh.vertex_count())
            .map(|v| (v % 7) as f32 / 6.0)
            .collect();
        write_ply(&ply, &mesh, Some((&grey, 1)), &[("weight", &grey)]).unwrap();
        let (back, report) = load_mesh(&ply, &LoadOptions::default()).unwrap();
        assert!(report.is_clean(), "{name}: {}", report.summary());
        assert_eq!(back, mesh, "{name} via PLY");

        let uvs: Vec<Vec2> = (0..mesh.corner_count())
            .map(|c| Vec2::new((c % 3) as f32 / 2.0, (c % 5) as f32 / 4.0))
            .collect();
        let tex = surfsynth::image::Image::new(8, 8, 3);
        let paths = write_obj(dir.path(), &stem, &mesh, Some(&uvs), Some(&tex), None).unwrap();
        assert_eq!(paths[0], dir.path().join(format!("{stem}.obj")));
        let (back, _) = load_mesh(&paths[0], &LoadOptions::default()).unwrap();
        assert_eq!(back.positions, mesh.positions, "{name} via OBJ");
        assert_eq!(back.corner_vertex, mesh.corner_vertex, "{name} via OBJ");
    }
}

#[test]
fn ply_output_is_byte_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, _) = load_shared("eight.off");
    let (a, b) = (dir.path().join("a.ply"), dir.path().join("b.ply"));
    write_ply(&a, &mesh, None, &[]).unwrap();
    write_ply(&b, &mesh, None, &[]).unwrap();
    assert_eq!(std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
}

#[test]
fn builtins_have_the_expected_topology() {
    let expect = [
        ("plane", Some(0), 1),
        ("jittered_plane", Some(0), 1),
        ("icosphere", Some(0), 0),
        ("uv_sphere", Some(0), 0),
        ("torus", Some(1), 0),
        ("torus_knot", Some(1), 0),
        ("cube", Some(0), 0),
    ];
    assert_eq!(expect.len(), BUILTIN_MESHES.len());
    for (name, genus, loops) in expect {
        let (mesh, _) = load_mesh(
            Path::new(&format!("builtin:{name}")),
            &LoadOptions::default(),
        )
        .unwrap_or_else(|e| panic!("{e}"));
        let info = MeshInfo::compute(&mesh);
        assert_eq!(info.genus, genus, "{name}:\n{info}");
        assert_eq!(info.boundary_loops, loops, "{name}:\n{info}");
        assert!(info.consistently_oriented, "{name}");
        assert_eq!(info.components, 1, "{name}");
    }
    let level8 = builtin_mesh(
        "icosphere",
        &BuiltinOptions {
            subdivisions: 5,
            ..BuiltinOptions::default()
        },
    )
    .unwrap();
    assert_eq!(level8.face_count(), 20 * 4usize.pow(5));
    let centre: Vec3 = level8.positions.iter().sum::<Vec3>() / level8.vertex_count() as f32;
    assert!(centre.length() < 1e-5);
}

/// A star of `spikes` points, outer radius 1 and inner radius 0.3, in the
/// plane z = 0 (counter-clockwise seen from +z), and its exact area.
fn star(spikes: usize) -> (Vec<Vec3>, f64) {
    let n = 2 * spikes;
    let points = (0..n)
        .map(|i| {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            let r = if i % 2 == 0 { 1.0 } else { 0.3 };
            Vec3::new((r * a.cos()) as f32, (r * a.sin()) as f32, 0.0)
        })
        .collect();
    let area = spikes as f64 * 0.3 * (std::f64::consts::PI / spikes as f64).sin();
    (points, area)
}

/// One polygon as OBJ text: optional leading lines, then `v` lines, then the face.
fn polygon_obj(points: &[Vec3]) -> String {
    let mut text = String::from("# a polygon\n");
    for p in points {
        text.push_str(&format!("v {} {} {}\n", p.x, p.y, p.z));
    }
    text.push('f');
    for i in 1..=points.len() {
        text.push_str(&format!(" {i}"));
    }
    text.push('\n');
    text
}

/// Sum of the areas of the triangles every kernel cuts the mesh into (the
/// fan of `PolyMesh::triangulated`), and the number of them facing against
/// `normal`.
fn fan_area_and_folds(mesh: &PolyMesh, normal: Vec3) -> (f64, usize) {
    let tris = mesh.triangulated();
    let area = tris
        .faces()
        .map(|f| surfsynth::mesh::repair::polygon_area(&tris.positions, f))
        .sum();
    let folded = (0..tris.face_count())
        .filter(|&f| tris.face_normal_scaled(f).dot(normal) < 0.0)
        .count();
    (area, folded)
}

/// Issue 43: a non-convex polygon of 400 corners (a star) was cut by the
/// zigzag strip, whose triangles fold over each other: area 57.9 instead
/// of 0.94, exit 0, no warning. A smaller one (kept as a polygon) was cut
/// by every kernel's fan, folding the same way. Both are now cut by ear
/// clipping in the polygon's plane: the triangles cover the polygon once.
#[test]
fn non_convex_polygons_are_triangulated_with_their_true_area() {
    for spikes in [200, 20] {
        let (points, area) = star(spikes);
        let text = polygon_obj(&points);
        let (mesh, report) = load_mesh_from_bytes(
            text.as_bytes(),
            MeshFormat::Obj,
            Path::new("star.obj"),
            &LoadOptions::default(),
        )
        .unwrap();
        let (got, folded) = fan_area_and_folds(&mesh, Vec3::Z);
        assert!(
            (got - area).abs() < 1e-4 * area,
            "{} corners: the triangles cover {got}, the star {area}",
            2 * spikes
        );
        assert_eq!(folded, 0, "{} corners: triangles facing down", 2 * spikes);
        assert_eq!(mesh.triangulated().face_count(), 2 * spikes - 2);
        assert!(!report.is_clean(), "the report tells: {report}");
    }
}

/// Issue 43: an L-shaped hexagon, tilted out of every coordinate plane and
/// far from the origin, whose first corner does not see the whole polygon:
/// its fan folded (area 4 instead of 3). Cut in its best-fit plane.
#[test]
fn a_tilted_l_shape_is_triangulated_in_its_plane() {
    let flat = [
        (2.0, 1.0),
        (1.0, 1.0),
        (1.0, 2.0),
        (0.0, 2.0),
        (0.0, 0.0),
        (2.0, 0.0),
    ];
    let rotation = glam::Quat::from_euler(glam::EulerRot::XYZ, 0.5, -0.3, 0.2);
    let offset = Vec3::new(5.0, -3.0, 100.0);
    let points: Vec<Vec3> = flat
        .iter()
        .map(|&(x, y)| rotation * Vec3::new(x, y, 0.0) + offset)
        .collect();
    for (name, text, format) in [
        ("l.obj", polygon_obj(&points), MeshFormat::Obj),
        ("l.off", polygon_off(&points), MeshFormat::Off),
    ] {
        let (mesh, _) = load_mesh_from_bytes(
            text.as_bytes(),
            format,
            Path::new(name),
            &LoadOptions::default(),
        )
        .unwrap();
        let (area, folded) = fan_area_and_folds(&mesh, rotation * Vec3::Z);
        assert!((area - 3.0).abs() < 1e-3, "{name}: area {area}");
        assert_eq!(folded, 0, "{name}");
    }
    // A convex polygon keeps its corners as one face.
    let square = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
    let (mesh, report) = load_mesh_from_bytes(
        polygon_obj(&square).as_bytes(),
        MeshFormat::Obj,
        Path::new("q.obj"),
        &LoadOptions::default(),
    )
    .unwrap();
    assert_eq!(mesh.face(0), &[0, 1, 2, 3]);
    assert!(report.is_clean(), "{report}");
}

/// One polygon as OFF text.
fn polygon_off(points: &[Vec3]) -> String {
    let mut text = format!("OFF\n{} 1 0\n", points.len());
    for p in points {
        text.push_str(&format!("{} {} {}\n", p.x, p.y, p.z));
    }
    text.push_str(&points.len().to_string());
    for i in 0..points.len() {
        text.push_str(&format!(" {i}"));
    }
    text.push('\n');
    text
}

/// Issue 43: a face that cannot be cut into triangles (it crosses itself,
/// so no corner can be cut off) is an error naming its line, in every text
/// format, and the command exits 2; it was kept and folded.
#[test]
fn a_face_that_cannot_be_triangulated_is_named_by_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A bow tie with lobes of different size (so its area is not zero),
    // after a good triangle.
    let obj = "v 0 0 0\nv 2 2 0\nv 2 0 0\nv 0 1 0\nv 5 5 5\n\nf 1 3 5\nf 1 2 3 4\n";
    let off = "OFF\n5 2 0\n0 0 0\n2 2 0\n2 0 0\n0 1 0\n5 5 5\n3 0 2 4\n4 0 1 2 3\n";
    let ply = "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n\
               property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n\
               0 0 0\n2 2 0\n2 0 0\n0 1 0\n5 5 5\n3 0 2 4\n4 0 1 2 3\n";
    for (name, text, line) in [
        ("bow.obj", obj, 8),
        ("bow.off", off, 9),
        ("bow.ply", ply, 16),
    ] {
        let e = load_err(d, name, text).to_string();
        assert!(e.contains(&format!("line {line}")), "{name}: {e}");
        assert!(e.contains("cannot be cut into triangles"), "{name}: {e}");
        assert!(e.contains("allowed:"), "{name}: {e}");
    }
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_surfsynth"))
        .args(["mesh-info", d.join("bow.obj").to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("line 8") && !stderr.contains("panicked"),
        "{stderr}"
    );
}
