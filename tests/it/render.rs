//! Preview renderer: silhouettes, lighting, colours, textures, layers,
//! determinism and degenerate input, on meshes built in code.

use glam::{Vec2, Vec3};
use surfsynth::image::Image;
use surfsynth::image::sample::Wrap;
use surfsynth::mesh::PolyMesh;
use surfsynth::output::render::{
    Background, DEFAULT_VIEWS, Layer, Normals, RenderOptions, Shading, View, gather_layer_uvs,
    render, render_views, write_previews,
};

const FRONT: View = View {
    azimuth_deg: 0.0,
    elevation_deg: 0.0,
};

/// A unit icosphere: the icosahedron with every triangle split in four
/// `levels` times and the vertices pushed onto the sphere.
fn icosphere(levels: u32) -> PolyMesh {
    let opts = surfsynth::mesh::builtin::BuiltinOptions {
        subdivisions: levels,
        radius: 1.0,
        ..Default::default()
    };
    surfsynth::mesh::builtin::builtin_mesh("icosphere", &opts).expect("a valid icosphere")
}

/// The square [-1, 1]² in the z = 0 plane as one quad facing +Z, with
/// texture coordinates putting the texture upright for the front view:
/// `v = 0` (the image's top row) at y = +1.
fn textured_quad() -> (PolyMesh, Vec<Vec2>) {
    let mesh = PolyMesh::from_polygons(
        vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        [&[0u32, 1, 2, 3][..]],
    );
    let uvs = vec![
        Vec2::new(0.0, 1.0),
        Vec2::new(1.0, 1.0),
        Vec2::new(1.0, 0.0),
        Vec2::new(0.0, 0.0),
    ];
    (mesh, uvs)
}

fn unlit() -> RenderOptions {
    RenderOptions {
        ambient: 1.0,
        background: Background::Solid([0.0; 3]),
        base_colour: [1.0; 3],
        ..RenderOptions::default()
    }
}

fn px(img: &Image, x: u32, y: u32) -> [f32; 3] {
    let p = img.pixel(x, y);
    [p[0], p[1], p[2]]
}

fn luminance(img: &Image, x: u32, y: u32) -> f32 {
    let p = px(img, x, y);
    (p[0] + p[1] + p[2]) / 3.0
}

#[test]
fn sphere_silhouette_covers_a_centred_disc() {
    let mesh = icosphere(4);
    let size = 256;
    let img = render(&mesh, &Shading::Plain, &FRONT, size, &unlit());
    // Unlit white on black: each pixel's value is its coverage.
    let (mut area, mut cx, mut cy) = (0.0f64, 0.0f64, 0.0f64);
    for y in 0..size {
        for x in 0..size {
            let v = luminance(&img, x, y) as f64;
            area += v;
            cx += v * (x as f64 + 0.5);
            cy += v * (y as f64 + 0.5);
        }
    }
    let fraction = area / (size * size) as f64;
    // The silhouette's radius is 85% of the half-frame.
    let expected = std::f64::consts::PI * 0.85 * 0.85 / 4.0;
    assert!(
        (fraction / expected - 1.0).abs() < 0.1,
        "covered fraction {fraction:.4}, expected {expected:.4}"
    );
    let (cx, cy) = (cx / area, cy / area);
    let c = size as f64 / 2.0;
    assert!(
        (cx - c).abs() < 1.0 && (cy - c).abs() < 1.0,
        "disc centred at ({cx:.2}, {cy:.2})"
    );
}

#[test]
fn dense_mesh_has_no_cracks() {
    // Without supersampling, unlit white on black: any sample that falls
    // between two triangles would leave a pixel below 1 inside the disc.
    let mesh = icosphere(5);
    let size = 300;
    let options = RenderOptions {
        supersample: 1,
        ..unlit()
    };
    for view in DEFAULT_VIEWS {
        let img = render(&mesh, &Shading::Plain, &view, size, &options);
        let c = size as f32 / 2.0;
        let inner = 0.95 * 0.85 * c;
        for y in 0..size {
            for x in 0..size {
                let (dx, dy) = (x as f32 + 0.5 - c, y as f32 + 0.5 - c);
                if dx * dx + dy * dy < inner * inner {
                    assert_eq!(px(&img, x, y), [1.0; 3], "crack at ({x}, {y}) in {view:?}");
                }
            }
        }
    }
}

#[test]
fn interpolation_is_perspective_correct() {
    // A planar quad receding in depth, coloured by a linear function of
    // position. Perspective-correct interpolation reproduces it whichever
    // diagonal splits the quad; screen-space (affine) interpolation would
    // not agree across the two splits.
    let positions = vec![
        Vec3::new(-1.0, 0.0, 1.0),
        Vec3::new(1.0, 0.0, 1.0),
        Vec3::new(1.0, 0.0, -1.0),
        Vec3::new(-1.0, 0.0, -1.0),
    ];
    let values: Vec<f32> = positions
        .iter()
        .flat_map(|p| [(p.x + 1.0) / 2.0, (p.z + 1.0) / 2.0, 0.0])
        .collect();
    let shading = Shading::VertexColours {
        values: &values,
        channels: 3,
    };
    let view = View {
        azimuth_deg: 0.0,
        elevation_deg: 20.0,
    };
    let options = RenderOptions {
        supersample: 1,
        ..unlit()
    };
    let split_a = PolyMesh::from_triangles(positions.clone(), &[[0, 1, 2], [0, 2, 3]]);
    let split_b = PolyMesh::from_triangles(positions, &[[0, 1, 3], [1, 2, 3]]);
    let a = render(&split_a, &shading, &view, 128, &options);
    let b = render(&split_b, &shading, &view, 128, &options);
    let mut compared = 0;
    for (pa, pb) in a.data.chunks_exact(3).zip(b.data.chunks_exact(3)) {
        if pa != [0.0; 3] && pb != [0.0; 3] {
            compared += 1;
            for k in 0..3 {
                assert!((pa[k] - pb[k]).abs() < 2e-3, "{pa:?} vs {pb:?}");
            }
        }
    }
    assert!(compared > 2000, "only {compared} pixels covered");
}

#[test]
fn lambert_centre_is_brighter_than_rim() {
    let mesh = icosphere(4);
    let size = 256;
    let img = render(
        &mesh,
        &Shading::Plain,
        &FRONT,
        size,
        &RenderOptions::default(),
    );
    let c = size as f32 / 2.0;
    let centre = luminance(&img, c as u32, c as u32);
    let radius = 0.85 * c * 0.92;
    // The key light sits up and to the left of the camera, so only the rim
    // on the far side from it (lower right, screen y down) must be darker
    // than the centre everywhere; on average the whole rim is.
    let mut rim = 0.0;
    for k in 0..16 {
        let a = k as f32 * std::f32::consts::TAU / 16.0;
        let (dx, dy) = (a.cos(), a.sin());
        let v = luminance(&img, (c + radius * dx) as u32, (c + radius * dy) as u32);
        if dx + dy > 0.0 {
            assert!(
                v < centre - 0.1,
                "rim sample {k} ({v}) vs centre ({centre})"
            );
        }
        rim += v / 16.0;
    }
    assert!(centre > rim + 0.1, "centre {centre}, mean rim {rim}");
}

#[test]
fn vertex_colours_show_in_the_expected_halves() {
    let mesh = icosphere(3);
    // Red on the -X half, green on the +X half.
    let values: Vec<f32> = mesh
        .positions
        .iter()
        .flat_map(|p| {
            if p.x < 0.0 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 1.0, 0.0]
            }
        })
        .collect();
    let shading = Shading::VertexColours {
        values: &values,
        channels: 3,
    };
    let img = render(&mesh, &shading, &FRONT, 128, &unlit());
    let left = px(&img, 32, 64);
    let right = px(&img, 96, 64);
    assert!(left[0] > 0.9 && left[1] < 0.1, "left half red: {left:?}");
    assert!(
        right[1] > 0.9 && right[0] < 0.1,
        "right half green: {right:?}"
    );

    // Grey (1 channel) shows as grey.
    let grey = vec![0.5f32; mesh.vertex_count()];
    let shading = Shading::VertexColours {
        values: &grey,
        channels: 1,
    };
    let img = render(&mesh, &shading, &FRONT, 64, &unlit());
    let p = px(&img, 32, 32);
    assert!(p.iter().all(|v| (v - 0.5).abs() < 1e-3), "grey: {p:?}");
}

/// An 8×8-cell checker, 8 pixels per cell, with the top-left cell red so a
/// flip or mirror shows.
fn checker() -> Image {
    let mut img = Image::new(64, 64, 3);
    for y in 0..64 {
        for x in 0..64 {
            let (i, j) = (x / 8, y / 8);
            let c = if i == 0 && j == 0 {
                [1.0, 0.0, 0.0]
            } else if (i + j) % 2 == 0 {
                [1.0; 3]
            } else {
                [0.0; 3]
            };
            img.pixel_mut(x, y).copy_from_slice(&c);
        }
    }
    img
}

#[test]
fn corner_uvs_reproduce_the_checker_upright() {
    let (mesh, uvs) = textured_quad();
    let texture = checker();
    let shading = Shading::CornerUvs {
        uvs: &uvs,
        texture: &texture,
        wrap: Wrap::Clamp,
    };
    let size = 256u32;
    let img = render(&mesh, &shading, &FRONT, size, &unlit());
    // The quad faces the camera, so the mapping is affine: it spans
    // ±85% of the half-frame.
    let half = 0.85 * size as f32 / 2.0;
    let origin = size as f32 / 2.0 - half;
    let cell = 2.0 * half / 8.0;
    for j in 0..8 {
        for i in 0..8 {
            let x = (origin + (i as f32 + 0.5) * cell) as u32;
            let y = (origin + (j as f32 + 0.5) * cell) as u32;
            let p = px(&img, x, y);
            let expected = if i == 0 && j == 0 {
                [1.0, 0.0, 0.0]
            } else if (i + j) % 2 == 0 {
                [1.0; 3]
            } else {
                [0.0; 3]
            };
            for k in 0..3 {
                assert!(
                    (p[k] - expected[k]).abs() < 0.02,
                    "cell ({i}, {j}) at pixel ({x}, {y}): {p:?}, expected {expected:?}"
                );
            }
        }
    }
}

fn rgba(w: u32, h: u32, f: impl Fn(u32, u32) -> [f32; 4]) -> Image {
    let mut img = Image::new(w, h, 4);
    for y in 0..h {
        for x in 0..w {
            img.pixel_mut(x, y).copy_from_slice(&f(x, y));
        }
    }
    img
}

#[test]
fn later_layers_win_where_opaque_and_show_through_where_transparent() {
    // Two quads side by side: face 0 covers x in [-1, 0], face 1 x in [0, 1].
    let mesh = PolyMesh::from_polygons(
        vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(0.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        [&[0u32, 1, 4, 5][..], &[1, 2, 3, 4][..]],
    );
    let red = rgba(1, 1, |_, _| [1.0, 0.0, 0.0, 1.0]);
    // Blue and opaque on the left half, green but fully transparent on the right.
    let half = rgba(16, 1, |x, _| {
        if x < 8 {
            [0.0, 0.0, 1.0, 1.0]
        } else {
            [0.0, 1.0, 0.0, 0.0]
        }
    });
    // uvs per corner of the listed faces, u = (x + 1) / 2 across the square.
    let uv = |x: f32, y: f32| Vec2::new((x + 1.0) / 2.0, (1.0 - y) / 2.0);
    let face0 = [uv(-1.0, -1.0), uv(0.0, -1.0), uv(0.0, 1.0), uv(-1.0, 1.0)];
    let face1 = [uv(0.0, -1.0), uv(1.0, -1.0), uv(1.0, 1.0), uv(0.0, 1.0)];
    let both: Vec<Vec2> = face0.iter().chain(&face1).copied().collect();
    // The same from a whole-mesh per-corner array, listing the faces in
    // another order: the layer's own face order decides the layout.
    assert_eq!(
        gather_layer_uvs(&mesh, &[1, 0], &both),
        [face1, face0].concat()
    );
    let layers = [
        Layer {
            faces: &[0, 1],
            uvs: &both,
            texture: &red,
            wrap: Wrap::Clamp,
        },
        Layer {
            faces: &[0, 1],
            uvs: &both,
            texture: &half,
            wrap: Wrap::Clamp,
        },
    ];
    let img = render(&mesh, &Shading::Layers(&layers), &FRONT, 128, &unlit());
    let left = px(&img, 40, 64);
    let right = px(&img, 88, 64);
    assert_eq!(left, [0.0, 0.0, 1.0], "opaque later layer wins");
    assert_eq!(
        right,
        [1.0, 0.0, 0.0],
        "transparent later layer shows the earlier one"
    );

    // A layer covering only face 1 leaves face 0 at the base colour.
    let only_right = [Layer {
        faces: &[1],
        uvs: &face1,
        texture: &red,
        wrap: Wrap::Clamp,
    }];
    let options = RenderOptions {
        base_colour: [0.5; 3],
        ..unlit()
    };
    let img = render(&mesh, &Shading::Layers(&only_right), &FRONT, 128, &options);
    assert_eq!(
        px(&img, 40, 64),
        [0.5; 3],
        "uncovered face keeps the base colour"
    );
    assert_eq!(px(&img, 88, 64), [1.0, 0.0, 0.0]);
}

fn coloured_sphere() -> (PolyMesh, Vec<f32>) {
    let mesh = icosphere(4);
    let values = mesh
        .positions
        .iter()
        .flat_map(|p| [0.5 + 0.5 * p.x, 0.5 + 0.5 * p.y, 0.5 + 0.5 * p.z])
        .collect();
    (mesh, values)
}

#[test]
fn rendering_is_deterministic_across_thread_counts() {
    let (mesh, values) = coloured_sphere();
    let shading = Shading::VertexColours {
        values: &values,
        channels: 3,
    };
    let options = RenderOptions::default();
    let once = render_views(&mesh, &shading, 200, &options);
    let twice = render_views(&mesh, &shading, 200, &options);
    assert_eq!(once, twice);
    let in_pool = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .expect("thread pool")
            .install(|| render_views(&mesh, &shading, 200, &options))
    };
    let one = in_pool(1);
    let two = in_pool(2);
    for (a, b) in one.iter().zip(&two) {
        assert!(
            a.data
                .iter()
                .zip(&b.data)
                .all(|(x, y)| x.to_bits() == y.to_bits()),
            "1 and 2 threads differ"
        );
    }
    assert_eq!(one, once);
}

#[test]
fn degenerate_meshes_render_the_background() {
    let options = RenderOptions {
        background: Background::Solid([0.25, 0.5, 0.75]),
        ..RenderOptions::default()
    };
    let point = PolyMesh::from_triangles(vec![Vec3::new(1.0, 2.0, 3.0)], &[[0, 0, 0]]);
    let collinear = PolyMesh::from_triangles(
        vec![Vec3::ZERO, Vec3::X, Vec3::X * 2.0],
        &[[0, 1, 2], [2, 1, 0]],
    );
    let no_faces = PolyMesh::from_triangles(vec![Vec3::ZERO, Vec3::Y], &[]);
    for (name, mesh) in [
        ("empty", PolyMesh::new()),
        ("default", PolyMesh::default()),
        ("point", point),
        ("collinear", collinear),
        ("no faces", no_faces),
    ] {
        for size in [0, 1, 7, 32] {
            for img in render_views(&mesh, &Shading::Plain, size, &options) {
                assert_eq!(
                    (img.width, img.height, img.channels),
                    (size, size, 3),
                    "{name}"
                );
                for p in img.data.chunks_exact(3) {
                    assert_eq!(p, [0.25, 0.5, 0.75], "{name} at size {size}");
                }
            }
        }
    }
}

#[test]
fn shading_that_does_not_fit_is_reported() {
    let mesh = icosphere(0);
    let short = vec![0.0f32; 5];
    let bad = Shading::VertexColours {
        values: &short,
        channels: 3,
    };
    assert!(bad.check(&mesh).is_err());
    let texture = checker();
    let uvs = vec![Vec2::ZERO; 3];
    let layers = [Layer {
        faces: &[0, 99],
        uvs: &uvs,
        texture: &texture,
        wrap: Wrap::Repeat,
    }];
    let err = Shading::Layers(&layers).check(&mesh).unwrap_err();
    assert!(err.to_string().contains("face 99"), "{err}");
    assert!(Shading::Plain.check(&mesh).is_ok());
}

#[test]
#[should_panic(expected = "does not fit the mesh")]
fn render_panics_on_mismatched_uvs() {
    let (mesh, _) = textured_quad();
    let texture = checker();
    let shading = Shading::CornerUvs {
        uvs: &[],
        texture: &texture,
        wrap: Wrap::Repeat,
    };
    render(&mesh, &shading, &FRONT, 16, &RenderOptions::default());
}

#[test]
fn open_surfaces_are_lit_from_both_sides() {
    // The quad faces +Z; seen from behind it must still be lit, not black.
    let (mesh, _) = textured_quad();
    let back = View {
        azimuth_deg: 180.0,
        elevation_deg: 0.0,
    };
    let options = RenderOptions::default();
    let front = render(&mesh, &Shading::Plain, &FRONT, 64, &options);
    let behind = render(&mesh, &Shading::Plain, &back, 64, &options);
    let (f, b) = (luminance(&front, 32, 32), luminance(&behind, 32, 32));
    assert!((f - b).abs() < 1e-4, "front {f}, back {b}");
    assert!(f > 0.6, "lit: {f}");
}

#[test]
fn flat_and_smooth_normals_differ_only_in_shading() {
    let mesh = icosphere(2);
    let smooth = render(
        &mesh,
        &Shading::Plain,
        &FRONT,
        96,
        &RenderOptions::default(),
    );
    let flat = render(
        &mesh,
        &Shading::Plain,
        &FRONT,
        96,
        &RenderOptions {
            normals: Normals::Flat,
            ..RenderOptions::default()
        },
    );
    assert_ne!(smooth, flat);
    // Same silhouette: the corners stay background in both.
    assert_eq!(px(&smooth, 2, 2), px(&flat, 2, 2));
}

#[test]
fn previews_are_written_as_pngs() {
    let dir = tempfile::tempdir().expect("temp dir");
    let mesh = icosphere(2);
    let images = render_views(&mesh, &Shading::Plain, 32, &RenderOptions::default());
    assert_eq!(images.len(), DEFAULT_VIEWS.len());
    let paths = write_previews(dir.path(), "preview", &images).expect("written");
    let names: Vec<_> = paths
        .iter()
        .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["preview_0.png", "preview_1.png", "preview_2.png"]);
    for p in &paths {
        let decoded = image::open(p).expect("decodes").to_rgb8();
        assert_eq!(decoded.dimensions(), (32, 32));
    }
}

/// A bumpy UV sphere with `n` × `2n` quads, fan-split into triangles when
/// `triangles` is set, with per-corner (u, v) in [0, 1]² (seam kept).
fn bumpy_sphere(n: u32, triangles: bool) -> (PolyMesh, Vec<Vec2>) {
    let m = 2 * n;
    let mut pos = Vec::new();
    for i in 0..=n {
        let theta = std::f32::consts::PI * i as f32 / n as f32;
        for j in 0..m {
            let phi = std::f32::consts::TAU * j as f32 / m as f32;
            let d = Vec3::new(
                theta.sin() * phi.sin(),
                theta.cos(),
                theta.sin() * phi.cos(),
            );
            let bump = 1.0 + 0.06 * (7.0 * d.x).sin() * (7.0 * d.y).sin() * (7.0 * d.z).sin();
            pos.push(d * bump);
        }
    }
    let id = |i: u32, j: u32| i * m + j % m;
    let uv = |i: u32, j: u32| Vec2::new(j as f32 / m as f32, i as f32 / n as f32);
    let mut mesh = PolyMesh::new();
    mesh.positions = pos;
    let mut uvs = Vec::new();
    for i in 0..n {
        for j in 0..m {
            // Counter-clockwise seen from outside.
            let quad = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)];
            if triangles {
                for t in [[0, 1, 2], [0, 2, 3]] {
                    mesh.push_face(&t.map(|k| id(quad[k].0, quad[k].1)));
                    uvs.extend(t.map(|k| uv(quad[k].0, quad[k].1)));
                }
            } else {
                mesh.push_face(&quad.map(|(a, b)| id(a, b)));
                uvs.extend(quad.map(|(a, b)| uv(a, b)));
            }
        }
    }
    (mesh, uvs)
}

/// An open heightfield with a square hole, `n` × `n` quads over [-1, 1]².
fn terrain(n: u32) -> PolyMesh {
    let mut pos = Vec::new();
    for i in 0..=n {
        for j in 0..=n {
            let (x, z) = (
                2.0 * j as f32 / n as f32 - 1.0,
                2.0 * i as f32 / n as f32 - 1.0,
            );
            pos.push(Vec3::new(x, 0.25 * (3.0 * x).sin() * (2.0 * z).cos(), z));
        }
    }
    let mut mesh = PolyMesh::new();
    mesh.positions = pos;
    for i in 0..n {
        for j in 0..n {
            let (a, b) = (i as i64 - n as i64 / 2, j as i64 - n as i64 / 3);
            if a.abs() < 4 && b.abs() < 4 {
                continue;
            }
            let v = |i: u32, j: u32| i * (n + 1) + j;
            // Counter-clockwise seen from above (+Y).
            mesh.push_face(&[v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]);
        }
    }
    mesh
}

fn preview_dir() -> std::path::PathBuf {
    std::env::var_os("SURFSYNTH_PREVIEW_DIR")
        .map(Into::into)
        .unwrap_or_else(|| std::env::temp_dir().join("surfsynth_render"))
}

/// Writes a gallery of previews for a human to look at:
/// `SURFSYNTH_PREVIEW_DIR=/tmp/r cargo test --release --test it -- --ignored render::gallery`.
#[test]
#[ignore = "writes PNG files for visual inspection"]
fn gallery() {
    let dir = preview_dir();
    let options = RenderOptions::default();
    let size = 512;

    let (sphere, sphere_uvs) = bumpy_sphere(60, false);
    let images = render_views(&sphere, &Shading::Plain, size, &options);
    write_previews(&dir, "plain", &images).expect("written");

    let texture = checker();
    let shading = Shading::CornerUvs {
        uvs: &sphere_uvs,
        texture: &texture,
        wrap: Wrap::Repeat,
    };
    let images = render_views(&sphere, &shading, size, &options);
    write_previews(&dir, "checker", &images).expect("written");

    let (quad, quad_uvs) = textured_quad();
    let shading = Shading::CornerUvs {
        uvs: &quad_uvs,
        texture: &texture,
        wrap: Wrap::Clamp,
    };
    let img = render(&quad, &shading, &FRONT, size, &options);
    write_previews(&dir, "quad", &[img]).expect("written");

    let ground = terrain(80);
    let heights: Vec<f32> = ground
        .positions
        .iter()
        .flat_map(|p| {
            let t = (p.y / 0.5 + 0.5).clamp(0.0, 1.0);
            [0.2 + 0.7 * t, 0.6, 0.9 - 0.7 * t]
        })
        .collect();
    let shading = Shading::VertexColours {
        values: &heights,
        channels: 3,
    };
    let mut images = render_views(&ground, &shading, size, &options);
    images.push(render(
        &ground,
        &shading,
        &View {
            azimuth_deg: 30.0,
            elevation_deg: -30.0,
        },
        size,
        &options,
    ));
    write_previews(&dir, "terrain", &images).expect("written");

    // Lapped-texture-like layers: round splats with soft alpha, each
    // covering the faces around a seed, in planar projection.
    let splat = rgba(64, 64, |x, y| {
        let (dx, dy) = (x as f32 / 32.0 - 1.0, y as f32 / 32.0 - 1.0);
        let r = (dx * dx + dy * dy).sqrt();
        let stripes = if ((x + y) / 8) % 2 == 0 { 1.0 } else { 0.3 };
        let top = if y < 8 { 0.0 } else { 1.0 };
        [
            stripes,
            0.5 * stripes * top,
            0.2,
            (1.0 - r).clamp(0.0, 0.25) * 4.0,
        ]
    });
    let ico = icosphere(4);
    let mut layer_faces = Vec::new();
    let mut layer_uvs = Vec::new();
    let seeds = icosphere(1).positions;
    for seed in &seeds {
        let seed = seed.normalize();
        let t = seed.any_orthonormal_vector();
        let b = seed.cross(t);
        let faces: Vec<u32> = (0..ico.face_count() as u32)
            .filter(|&f| ico.face_centroid(f as usize).normalize().dot(seed) > 0.85)
            .collect();
        let uvs: Vec<Vec2> = faces
            .iter()
            .flat_map(|&f| ico.face(f as usize).to_vec())
            .map(|v| {
                let p = ico.positions[v as usize];
                Vec2::new(0.5 + p.dot(t) / 1.1, 0.5 - p.dot(b) / 1.1)
            })
            .collect();
        layer_faces.push(faces);
        layer_uvs.push(uvs);
    }
    let layers: Vec<Layer> = layer_faces
        .iter()
        .zip(&layer_uvs)
        .map(|(faces, uvs)| Layer {
            faces,
            uvs,
            texture: &splat,
            wrap: Wrap::Clamp,
        })
        .collect();
    let images = render_views(&ico, &Shading::Layers(&layers), size, &options);
    write_previews(&dir, "layers", &images).expect("written");
    eprintln!("gallery written to {}", dir.display());
}

/// User + system CPU seconds of this process so far (Linux; 0 elsewhere),
/// so the timing stays meaningful on a loaded machine.
fn cpu_seconds() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // Fields after the command name (which is in parentheses).
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let fields: Vec<&str> = rest.split_whitespace().collect();
    let ticks = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // utime and stime are fields 14 and 15 (1-based), 11 and 12 here; 100 Hz.
    (ticks(11) + ticks(12)) / 100.0
}

/// Wall-clock and CPU time per view for 100k triangles at 512² with 2×2
/// supersampling: `cargo test --release --test it -- --ignored --nocapture render::timing`.
#[test]
#[ignore = "timing, run by hand"]
fn timing() {
    let (mesh, uvs) = bumpy_sphere(158, true);
    let texture = checker();
    eprintln!(
        "{} triangles, {} threads",
        mesh.face_count(),
        rayon::current_num_threads()
    );
    let options = RenderOptions::default();
    for (name, shading) in [
        ("plain", Shading::Plain),
        (
            "textured",
            Shading::CornerUvs {
                uvs: &uvs,
                texture: &texture,
                wrap: Wrap::Repeat,
            },
        ),
    ] {
        let runs = 10;
        let (wall, cpu) = (std::time::Instant::now(), cpu_seconds());
        for _ in 0..runs {
            std::hint::black_box(render_views(&mesh, &shading, 512, &options));
        }
        let per_view = |total: f64| total * 1e3 / (3 * runs) as f64;
        eprintln!(
            "{name}: {:.1} ms wall, {:.1} ms CPU per view (render_views)",
            per_view(wall.elapsed().as_secs_f64()),
            per_view(cpu_seconds() - cpu)
        );
        let (wall, cpu) = (std::time::Instant::now(), cpu_seconds());
        for _ in 0..runs {
            std::hint::black_box(render(&mesh, &shading, &DEFAULT_VIEWS[0], 512, &options));
        }
        let per = |total: f64| total * 1e3 / runs as f64;
        eprintln!(
            "{name}: {:.1} ms wall, {:.1} ms CPU per render() call",
            per(wall.elapsed().as_secs_f64()),
            per(cpu_seconds() - cpu)
        );
    }
}

/// Issue 40: `Shading::Coordinates` continues each vertex's exemplar
/// coordinate through its frame. On a jittered plane whose vertices all
/// carry the coordinates of one coherent mapping (x right, y up, 10 texels
/// per unit), the three continued look-ups agree everywhere, so the drawing
/// equals the same mapping given as per-corner texture coordinates.
#[test]
fn coordinate_shading_continues_vertex_coordinates_through_their_frames() {
    let opts = surfsynth::mesh::builtin::BuiltinOptions {
        resolution: [5, 5],
        size: 2.0,
        jitter: 0.2,
        ..Default::default()
    };
    let mesh = surfsynth::mesh::builtin::builtin_mesh("jittered_plane", &opts).unwrap();
    let texture = checker();
    let size = Vec2::new(texture.width as f32, texture.height as f32);
    let scale = 10.0f32;
    let origin = Vec2::new(3.0, 5.0);
    // Image x = world x, image y = −world y (image rows grow downwards).
    let coordinate = |p: Vec3| origin + Vec2::new(p.x, -p.y) * scale;
    let sources: Vec<Vec2> = mesh.positions.iter().map(|&p| coordinate(p)).collect();
    let frames =
        vec![
            surfsynth::kernels::surface::frames::TangentFrame::from_direction(Vec3::Z, Vec3::X);
            mesh.vertex_count()
        ];
    let uvs: Vec<Vec2> = mesh
        .corner_vertex
        .iter()
        .map(|&v| coordinate(mesh.positions[v as usize]) / size)
        .collect();
    let options = RenderOptions::default();
    let draw = |shading: &Shading| render(&mesh, shading, &FRONT, 96, &options);
    let by_coordinates = draw(&Shading::Coordinates {
        sources: &sources,
        frames: &frames,
        texels_per_unit: &[scale],
        texture: &texture,
        wrap: Wrap::Repeat,
    });
    let by_uvs = draw(&Shading::CornerUvs {
        uvs: &uvs,
        texture: &texture,
        wrap: Wrap::Repeat,
    });
    let worst = by_coordinates
        .data
        .iter()
        .zip(&by_uvs.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(worst < 1e-3, "largest difference {worst}");
}
