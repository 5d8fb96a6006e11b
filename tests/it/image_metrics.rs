//! Integration tests of exemplar loading and of the texture metrics on the
//! shared texture photographs (`data/textures`).

use std::path::PathBuf;

use glam::{Vec2, Vec3};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_pcg::Pcg64Mcg;
use surfsynth::image::sample::Wrap;
use surfsynth::image::{ExemplarOptions, Image, exemplar_from_spec, load_image};
use surfsynth::kernels::metrics::{
    EnergySettings, SurfaceSignal, histogram_wasserstein, histogram_wasserstein_mean,
    image_texture_energy, surface_texture_energy,
};
use surfsynth::kernels::surface::frames::TangentFrame;
use surfsynth::kernels::surface::surface_sample::{ResampleScratch, resample_neighbourhood};
use surfsynth::mesh::{PolyMesh, Topology};

const TEXTURES: [&str; 5] = ["stones", "brick", "water", "planks", "grass"];

fn data_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data")
}

fn texture(name: &str) -> Image {
    let path = data_dir().join("textures").join(format!("{name}.png"));
    load_image(&path).unwrap_or_else(|e| panic!("shared test texture missing or unreadable: {e}"))
}

/// `img` repeated `nx`×`ny` times.
fn tile(img: &Image, nx: u32, ny: u32) -> Image {
    crop(img, 0, 0, img.width * nx, img.height * ny)
}

/// A `w`×`h` window at `(x0, y0)` of the infinite tiling of `img`.
fn crop(img: &Image, x0: u32, y0: u32, w: u32, h: u32) -> Image {
    let mut out = Image::new(w, h, img.channels);
    for y in 0..h {
        for x in 0..w {
            let src = img.texel((x0 + x) as i64, (y0 + y) as i64, Wrap::Repeat);
            out.pixel_mut(x, y).copy_from_slice(src);
        }
    }
    out
}

/// The pixels of `img` in a seeded random order (same histogram, no structure).
fn shuffled(img: &Image, seed: u64) -> Image {
    let c = img.channels as usize;
    let mut pixels: Vec<&[f32]> = img.data.chunks_exact(c).collect();
    pixels.shuffle(&mut Pcg64Mcg::seed_from_u64(seed));
    let data = pixels.concat();
    Image::from_data(img.width, img.height, img.channels, data).unwrap()
}

#[test]
fn shared_textures_load_as_128_square_rgb() {
    for name in TEXTURES {
        let img = texture(name);
        assert_eq!(
            (img.width, img.height, img.channels),
            (128, 128, 3),
            "{name}"
        );
        assert!(img.data.iter().all(|v| (0.0..=1.0).contains(v)), "{name}");
        let (lo, hi) = img
            .data
            .iter()
            .fold((1.0f32, 0.0f32), |(lo, hi), &v| (lo.min(v), hi.max(v)));
        assert!(hi - lo > 0.3, "{name} has contrast: {lo}..{hi}");
    }
    // The same file through an exemplar spec, relative to a base directory.
    let (img, name) = exemplar_from_spec(
        "textures/stones.png",
        &data_dir(),
        &ExemplarOptions::default(),
    )
    .unwrap();
    assert_eq!(name, "textures/stones.png");
    assert_eq!(img, texture("stones"));
}

#[test]
fn tiled_exemplar_has_zero_energy_and_a_shuffle_is_far() {
    let settings = EnergySettings {
        neighbourhood: 7,
        samples: 400,
        seed: 11,
        ..Default::default()
    };
    for name in ["stones", "brick", "water"] {
        let ex = texture(name);
        let tiled = image_texture_energy(&tile(&ex, 2, 2), &ex, &settings, Wrap::Repeat);
        // Away from its borders a crop of the tiling is made of exemplar
        // windows; clamping at the borders makes a few windows new.
        let cropped =
            image_texture_energy(&crop(&ex, 37, 51, 150, 140), &ex, &settings, Wrap::Clamp);
        let shuffle = image_texture_energy(&shuffled(&ex, 5), &ex, &settings, Wrap::Repeat);
        println!(
            "{name}: tiled {:.3e}, crop {:.3e} (p90 {:.3e}), shuffle {:.3e} (p90 {:.3e})",
            tiled.mean, cropped.mean, cropped.p90, shuffle.mean, shuffle.p90
        );
        assert_eq!(tiled.samples, 400);
        assert!(tiled.mean < 1e-9, "{name}: tiled energy {}", tiled.mean);
        assert_eq!(
            cropped.p90, 0.0,
            "{name}: most crop windows are exemplar windows"
        );
        assert!(
            shuffle.mean > 5.0 * tiled.mean && shuffle.mean > 0.005,
            "{name}: shuffle energy {} not far above tiled {}",
            shuffle.mean,
            tiled.mean
        );
        assert!(
            shuffle.mean > 5.0 * cropped.mean,
            "{name}: shuffle {} vs crop {}",
            shuffle.mean,
            cropped.mean
        );
    }
}

#[test]
fn wasserstein_ignores_pixel_order_but_sees_colour() {
    for name in ["stones", "brick", "water"] {
        let ex = texture(name);
        let shuffle = histogram_wasserstein(&shuffled(&ex, 9), &ex);
        assert!(shuffle.iter().all(|&d| d < 1e-6), "{name}: {shuffle:?}");
        assert!(histogram_wasserstein_mean(&tile(&ex, 2, 3), &ex) < 1e-6);
        let grey = Image::from_data(64, 64, 3, vec![0.5; 64 * 64 * 3]).unwrap();
        let d = histogram_wasserstein_mean(&grey, &ex);
        println!("{name}: grey W1 {d:.4}");
        assert!(d > 0.05, "{name}: constant grey W1 {d}");
    }
}

/// A planar grid over the exemplar: vertex `(x, y)` at `(x, y, 0)` (one world
/// unit per texel, texel centres on vertices), quads counter-clockwise about
/// +Z. With frames `s = +X`, `t = +Y`, `n = +Z`, template column `i` and row
/// `j` run along image x and y.
fn grid(w: u32, h: u32) -> PolyMesh {
    let positions = (0..h)
        .flat_map(|y| (0..w).map(move |x| Vec3::new(x as f32, -(y as f32), 0.0)))
        .collect();
    let mut faces = Vec::new();
    for y in 0..h - 1 {
        for x in 0..w - 1 {
            let v = y * w + x;
            faces.push([v, v + w, v + w + 1, v + 1]);
        }
    }
    PolyMesh::from_polygons(positions, faces.iter().map(|f| &f[..]))
}

fn plane_frames(mesh: &PolyMesh) -> Vec<TangentFrame> {
    vec![TangentFrame::from_direction(Vec3::Z, Vec3::X); mesh.vertex_count()]
}

#[test]
fn grid_vertex_template_is_the_exemplar_window() {
    let ex = texture("water");
    let mesh = grid(ex.width, ex.height);
    let topo = Topology::build(&mesh);
    let frames = plane_frames(&mesh);
    let signal = SurfaceSignal::VertexColours {
        values: &ex.data,
        channels: 3,
    };
    let mut out = vec![0.0; 7 * 7 * 3];
    let mut scratch = ResampleScratch::new();
    for (cx, cy) in [(10u32, 20u32), (64, 64), (126, 1)] {
        let v = cy * ex.width + cx;
        let covered = resample_neighbourhood(
            &mesh,
            &topo,
            v,
            &frames[v as usize],
            1.0,
            7,
            &signal,
            &[0.0; 3],
            &mut out,
            &mut scratch,
        );
        for j in 0..7u32 {
            for i in 0..7u32 {
                let (x, y) = (cx as i64 + i as i64 - 3, cy as i64 + j as i64 - 3);
                let got = &out[((j * 7 + i) * 3) as usize..][..3];
                let inside =
                    (0..ex.width as i64).contains(&x) && (0..ex.height as i64).contains(&y);
                assert_eq!(scratch.coverage()[(j * 7 + i) as usize], inside);
                if inside {
                    assert_eq!(
                        got,
                        ex.pixel(x as u32, y as u32),
                        "template ({i}, {j}) at vertex ({cx}, {cy})"
                    );
                }
            }
        }
        // At (126, 1) the template sticks out two columns and two rows.
        let expected = if cy == 1 { 5 * 5 } else { 49 };
        assert_eq!(covered, expected);
    }
}

#[test]
fn surface_energy_of_copied_colours_is_zero_and_of_shuffled_is_large() {
    let ex = texture("stones");
    let mesh = grid(ex.width, ex.height);
    let topo = Topology::build(&mesh);
    let frames = plane_frames(&mesh);
    let settings = EnergySettings {
        samples: 300,
        seed: 4,
        ..Default::default()
    };
    let copy = SurfaceSignal::VertexColours {
        values: &ex.data,
        channels: 3,
    };
    let e_copy = surface_texture_energy(&mesh, &topo, &frames, 1.0, &copy, &ex, &settings);
    let sh = shuffled(&ex, 3);
    let shuffle = SurfaceSignal::VertexColours {
        values: &sh.data,
        channels: 3,
    };
    let e_shuffle = surface_texture_energy(&mesh, &topo, &frames, 1.0, &shuffle, &ex, &settings);
    let image_shuffle = image_texture_energy(&sh, &ex, &settings, Wrap::Clamp);
    println!("copy {e_copy:?}\nshuffle {e_shuffle:?}\nimage shuffle {image_shuffle:?}");
    assert_eq!(e_copy.samples, 300);
    assert!(e_copy.mean < 1e-9, "{e_copy:?}");
    assert!(e_shuffle.mean > 0.01, "{e_shuffle:?}");
    // On a flat grid the surface and image energies measure the same thing.
    assert!(
        (e_shuffle.mean / image_shuffle.mean - 1.0).abs() < 0.2,
        "{e_shuffle:?} vs {image_shuffle:?}"
    );
}

#[test]
fn surface_energy_of_a_moved_and_triangulated_grid_stays_near_zero() {
    // The same grid rotated and shifted in space, triangulated, with frames
    // rotated along: the resampled templates must not change.
    let ex = texture("brick");
    let flat = grid(ex.width, ex.height).triangulated();
    let rot = glam::Quat::from_euler(glam::EulerRot::XYZ, 0.7, -0.4, 1.9);
    let shift = Vec3::new(3.0, -20.0, 7.5);
    let mut mesh = flat.clone();
    for p in &mut mesh.positions {
        *p = rot * *p + shift;
    }
    let topo = Topology::build(&mesh);
    let frames =
        vec![TangentFrame::from_direction(rot * Vec3::Z, rot * Vec3::X); mesh.vertex_count()];
    let settings = EnergySettings {
        samples: 200,
        seed: 8,
        ..Default::default()
    };
    let signal = SurfaceSignal::VertexColours {
        values: &ex.data,
        channels: 3,
    };
    let e = surface_texture_energy(&mesh, &topo, &frames, 1.0, &signal, &ex, &settings);
    println!("moved grid {e:?}");
    assert!(e.mean < 1e-6, "{e:?}");
}

#[test]
fn plane_with_uvs_onto_the_exemplar_has_near_zero_energy() {
    let ex = texture("water");
    // A coarser plane (4 texels per quad) whose corner UVs map vertex (x, y)
    // to the texel centre (x + 0.5, y + 0.5): template points land on texel
    // centres, so bilinear sampling returns exact pixels.
    let (w, h) = (33u32, 33u32);
    let mut mesh = grid(w, h);
    for p in &mut mesh.positions {
        *p *= 4.0;
    }
    let uvs: Vec<Vec2> = mesh
        .corner_vertex
        .iter()
        .map(|&v| {
            let p = mesh.positions[v as usize];
            Vec2::new(
                (p.x + 0.5) / ex.width as f32,
                (-p.y + 0.5) / ex.height as f32,
            )
        })
        .collect();
    let topo = Topology::build(&mesh);
    let frames = plane_frames(&mesh);
    let settings = EnergySettings {
        samples: 300,
        seed: 2,
        ..Default::default()
    };
    let signal = SurfaceSignal::CornerUvs {
        uvs: &uvs,
        texture: &ex,
        wrap: Wrap::Repeat,
    };
    let e = surface_texture_energy(&mesh, &topo, &frames, 1.0, &signal, &ex, &settings);
    // The same plane showing a shuffled texture.
    let sh = shuffled(&ex, 1);
    let signal_sh = SurfaceSignal::CornerUvs {
        uvs: &uvs,
        texture: &sh,
        wrap: Wrap::Repeat,
    };
    let e_sh = surface_texture_energy(&mesh, &topo, &frames, 1.0, &signal_sh, &ex, &settings);
    println!("uv plane {e:?}, shuffled {e_sh:?}");
    assert!(e.mean < 1e-8, "{e:?}");
    assert!(e_sh.mean > 0.01, "{e_sh:?}");
}

/// A cylinder around +Z with the texture wrapped once around it (one world
/// unit per texel along the surface), outward normals.
fn cylinder(around: u32, rows: u32) -> (PolyMesh, Vec<Vec2>, Vec<TangentFrame>) {
    let radius = around as f32 / std::f32::consts::TAU;
    let mut positions = Vec::new();
    let mut frames = Vec::new();
    for y in 0..rows {
        for x in 0..around {
            let a = x as f32 / around as f32 * std::f32::consts::TAU;
            let n = Vec3::new(a.cos(), a.sin(), 0.0);
            positions.push(n * radius - Vec3::Z * y as f32);
            // s along increasing angle (texture x), t = +Z (texture up; image
            // rows run down, toward −Z).
            frames.push(TangentFrame::from_direction(
                n,
                Vec3::new(-a.sin(), a.cos(), 0.0),
            ));
        }
    }
    let mut faces = Vec::new();
    let mut uvs = Vec::new();
    for y in 0..rows - 1 {
        for x in 0..around {
            let x1 = (x + 1) % around;
            faces.push([
                y * around + x,
                (y + 1) * around + x,
                (y + 1) * around + x1,
                y * around + x1,
            ]);
            // Per-corner UVs: the seam column uses u = 1 rather than 0.
            for (cx, cy) in [(x, y), (x, y + 1), (x + 1, y + 1), (x + 1, y)] {
                uvs.push(Vec2::new(
                    (cx as f32 + 0.5) / around as f32,
                    (cy as f32 + 0.5) / rows as f32,
                ));
            }
        }
    }
    let mesh = PolyMesh::from_polygons(positions, faces.iter().map(|f| &f[..]));
    (mesh, uvs, frames)
}

#[test]
fn textured_cylinder_has_low_energy() {
    let ex = texture("stones");
    let (mesh, uvs, frames) = cylinder(ex.width, ex.height);
    let topo = Topology::build(&mesh);
    let settings = EnergySettings {
        samples: 300,
        seed: 6,
        ..Default::default()
    };
    let signal = SurfaceSignal::CornerUvs {
        uvs: &uvs,
        texture: &ex,
        wrap: Wrap::Repeat,
    };
    let e = surface_texture_energy(&mesh, &topo, &frames, 1.0, &signal, &ex, &settings);
    let sh = shuffled(&ex, 2);
    let signal_sh = SurfaceSignal::CornerUvs {
        uvs: &uvs,
        texture: &sh,
        wrap: Wrap::Repeat,
    };
    let e_sh = surface_texture_energy(&mesh, &topo, &frames, 1.0, &signal_sh, &ex, &settings);
    println!("cylinder {e:?}, shuffled {e_sh:?}");
    assert!(e.mean < 0.05 * e_sh.mean, "{e:?} vs {e_sh:?}");
    // A frame turned by a quarter turn reads the texture sideways: worse.
    let turned: Vec<TangentFrame> = frames
        .iter()
        .map(|f| f.rotated(std::f32::consts::FRAC_PI_2))
        .collect();
    let e_turned = surface_texture_energy(&mesh, &topo, &turned, 1.0, &signal, &ex, &settings);
    println!("cylinder turned frames {e_turned:?}");
    assert!(e_turned.mean > 3.0 * e.mean, "{e_turned:?} vs {e:?}");
}

/// The exemplar blurred by the binomial 5-tap kernel (σ ≈ 1 px), clamped.
fn blurred(img: &Image) -> Image {
    surfsynth::image::pyramid::blur_binomial(img, 1, Wrap::Clamp)
}

#[test]
fn surface_quality_on_a_flat_grid_agrees_with_the_image_measures() {
    use surfsynth::kernels::metrics::surface_quality::{SurfaceResult, surface_quality};
    use surfsynth::kernels::metrics::{completeness, sharpness, structure_distance};
    let ex = texture("planks");
    let mesh = grid(ex.width, ex.height);
    let topo = Topology::build(&mesh);
    let frames = plane_frames(&mesh);
    let settings = EnergySettings {
        samples: 2000,
        seed: 5,
        ..Default::default()
    };
    let soft = blurred(&ex);
    // Vertex (x, y) of the grid copies exemplar pixel (x, y).
    let sources: Vec<Vec2> = (0..ex.width * ex.height)
        .map(|i| Vec2::new((i % ex.width) as f32 + 0.5, (i / ex.width) as f32 + 0.5))
        .collect();
    let measure = |img: &Image| {
        let signal = SurfaceSignal::VertexColours {
            values: &img.data,
            channels: 3,
        };
        let r = SurfaceResult {
            mesh: &mesh,
            topo: &topo,
            frames: &frames,
            spacing: 1.0,
            signal: &signal,
        };
        surface_quality(&r, &ex, &settings, Some(&sources))
    };
    let (copy, soft_q) = (measure(&ex), measure(&soft));
    println!("copy {copy:?}\nblurred {soft_q:?}");
    // A verbatim copy: complete, as sharp as the exemplar, same structure,
    // one copied region covering the exemplar.
    assert!(copy.completeness < 2e-3, "{copy:?}");
    // The surface sharpness reads the continuous texture: here the vertex
    // colours interpolated over the grid's triangles, whose creases make it
    // steeper than the exemplar's bilinear interpolant (1.12 here).
    assert!((copy.sharpness - 1.0).abs() < 0.15, "{copy:?}");
    assert!(copy.structure < 0.05, "{copy:?}");
    let v = copy.verbatim.unwrap();
    assert!(
        v.source_coverage > 0.99 && v.mean_region_fraction > 0.9,
        "{v:?}"
    );
    // The blurred copy: the surface sees the blur at least as plainly as
    // the image measures do (the continuous texture's gradient drops more
    // under a blur than the pixel-scale Sobel's: 0.37 against 0.52 here),
    // and completeness and structure are worse than the copy's.
    let image_sharp = sharpness(&soft, &ex);
    assert!(
        soft_q.sharpness / copy.sharpness <= image_sharp,
        "surface {} (copy {}) vs image {image_sharp}",
        soft_q.sharpness,
        copy.sharpness
    );
    assert!(soft_q.sharpness < 0.8 * copy.sharpness);
    assert!(soft_q.completeness > 2.0 * copy.completeness.max(1e-4));
    assert!(soft_q.structure > copy.structure + 0.05);
    println!(
        "image: completeness {} structure {}",
        completeness(&soft, &ex, 7),
        structure_distance(&soft, &ex)
    );
}

/// `img` beside its mirror image, over both mirrored: twice the size and
/// tileable without a seam.
fn mirrored(img: &Image) -> Image {
    let (w, h) = (img.width, img.height);
    let mut out = Image::new(2 * w, 2 * h, img.channels);
    for y in 0..2 * h {
        for x in 0..2 * w {
            let sx = if x < w { x } else { 2 * w - 1 - x };
            let sy = if y < h { y } else { 2 * h - 1 - y };
            out.pixel_mut(x, y).copy_from_slice(img.pixel(sx, sy));
        }
    }
    out
}

/// A copy of `texture` (the exemplar or a resampling of it) laid on a flat
/// grid of vertex spacing `step` exemplar pixels, turned by `angle` and
/// shifted by `offset` pixels: per-corner UVs, repeating. Measured against
/// `ex`.
fn turned_copy_quality(
    ex: &Image,
    texture: &Image,
    step: f32,
    angle: f32,
    offset: Vec2,
) -> surfsynth::kernels::metrics::surface_quality::SurfaceQuality {
    use surfsynth::kernels::metrics::surface_quality::{SurfaceResult, surface_quality};
    let n = (ex.width as f32 / step) as u32;
    let mut mesh = grid(n, n);
    mesh.positions.iter_mut().for_each(|p| *p *= step);
    let (s, c) = angle.sin_cos();
    let size = Vec2::new(ex.width as f32, ex.height as f32);
    let uvs: Vec<Vec2> = mesh
        .corner_vertex
        .iter()
        .map(|&v| {
            let p = mesh.positions[v as usize];
            let (x, y) = (p.x, -p.y);
            (Vec2::new(c * x - s * y, s * x + c * y) + offset) / size
        })
        .collect();
    let topo = Topology::build(&mesh);
    let frames = plane_frames(&mesh);
    let signal = SurfaceSignal::CornerUvs {
        uvs: &uvs,
        texture,
        wrap: Wrap::Repeat,
    };
    let r = SurfaceResult {
        mesh: &mesh,
        topo: &topo,
        frames: &frames,
        spacing: 1.0,
        signal: &signal,
    };
    let settings = EnergySettings {
        samples: 1500,
        seed: 3,
        ..Default::default()
    };
    surface_quality(&r, ex, &settings, None)
}

/// `img` resampled bilinearly to `factor` times its size (an atlas denser
/// than the exemplar, as a bake makes).
fn upsampled(img: &Image, factor: f32) -> Image {
    let (w, h) = (
        (img.width as f32 * factor) as u32,
        (img.height as f32 * factor) as u32,
    );
    let mut up = Image::new(w, h, img.channels);
    for y in 0..h {
        for x in 0..w {
            let (u, v) = ((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32);
            img.sample_uv(u, v, Wrap::Repeat, up.pixel_mut(x, y));
        }
    }
    up
}

/// The surface sharpness reads the texture, not how the measuring lattice
/// happens to fall on its pixels: a copy of the exemplar, at any turn and
/// sub-pixel shift, directly or through an atlas 2.7 times denser (a bake),
/// is as sharp as the exemplar — resampling a copy between its pixels must
/// not read as blur (at one sample per pixel it read 0.81-0.94) — and a
/// blurred copy reads blurred.
#[test]
fn surface_sharpness_of_a_copy_is_one_at_any_turn_and_shift() {
    for name in ["brick", "planks"] {
        // Mirrored 2 × 2: tileable without a seam, so the repeats of the
        // turned copy add no edges of their own.
        let ex = mirrored(&texture(name));
        let soft = blurred(&ex);
        let atlas = upsampled(&ex, 2.7);
        for (angle, offset) in [
            (0.0, Vec2::ZERO),
            (0.0, Vec2::new(0.5, 0.5)),
            (0.3, Vec2::new(0.25, 0.7)),
            (std::f32::consts::FRAC_PI_4, Vec2::new(0.5, 0.0)),
            (1.2, Vec2::new(0.9, 0.4)),
        ] {
            let copy = turned_copy_quality(&ex, &ex, 1.7, angle, offset);
            let baked = turned_copy_quality(&ex, &atlas, 1.7, angle, offset);
            let soft_q = turned_copy_quality(&ex, &soft, 1.7, angle, offset);
            println!(
                "{name} angle {angle} offset {offset}: copy {:.3} through an atlas {:.3} blurred {:.3}",
                copy.sharpness, baked.sharpness, soft_q.sharpness
            );
            for (what, q) in [("copy", copy), ("baked copy", baked)] {
                assert!(
                    (q.sharpness - 1.0).abs() < 0.07,
                    "{name} turned {angle} shifted {offset}: {what} reads {}",
                    q.sharpness
                );
            }
            assert!(
                soft_q.sharpness < 0.85 * baked.sharpness.min(copy.sharpness),
                "{name} turned {angle} shifted {offset}: blurred {} vs copy {}",
                soft_q.sharpness,
                copy.sharpness
            );
        }
    }
}

/// The metrics' exact index ([`WindowIndex`]) against the exhaustive scan
/// ([`ExemplarNeighbourhoods`]) on every shared photo, both ways the result
/// metrics use it: a result's windows against the exemplar's (toroidal, the
/// texture energy) and the exemplar's against the result's (inside it,
/// completeness). Results: a crop of the exemplar's tiling (nearest at 0),
/// its shuffled pixels (far), another photo, and the exemplar blurred by
/// a box (near, but not equal). Equal within 10⁻⁵ relative (the sums run in
/// another order).
#[test]
fn the_metrics_index_finds_the_exhaustive_minimum_on_the_shared_photos() {
    use surfsynth::kernels::metrics::window_index::{IndexScratch, WindowIndex};
    use surfsynth::kernels::metrics::{ExemplarNeighbourhoods, QueryScratch, completeness};
    let n = 7u32;
    let window = |img: &Image, x: i64, y: i64| -> Vec<f32> {
        let mut q = Vec::new();
        for dy in 0..n as i64 {
            for dx in 0..n as i64 {
                q.extend_from_slice(img.texel(x + dx, y + dy, Wrap::Clamp));
            }
        }
        q
    };
    let box_blur = |img: &Image| -> Image {
        let mut out = img.clone();
        for y in 0..img.height {
            for x in 0..img.width {
                for c in 0..img.channels as usize {
                    let mut s = 0.0;
                    for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        s += img.texel(x as i64 + dx, y as i64 + dy, Wrap::Clamp)[c];
                    }
                    out.pixel_mut(x, y)[c] = s / 4.0;
                }
            }
        }
        out
    };
    let mut scratch = (IndexScratch::default(), QueryScratch::default());
    for (k, name) in TEXTURES.iter().enumerate() {
        let ex = texture(name);
        let other = texture(TEXTURES[(k + 1) % TEXTURES.len()]);
        let results = [
            ("tiling", crop(&ex, 37, 11, 96, 80)),
            ("shuffled", shuffled(&crop(&ex, 0, 0, 96, 80), 5)),
            ("other photo", crop(&other, 3, 0, 96, 80)),
            ("blurred", box_blur(&crop(&ex, 20, 30, 96, 80))),
        ];
        let fast_ex = WindowIndex::toroidal(&ex, n, 0..128);
        let slow_ex = ExemplarNeighbourhoods::new(&ex, n);
        for (label, result) in &results {
            let fast_out = WindowIndex::interior(result, n, 0..74);
            let slow_out = ExemplarNeighbourhoods::interior(result, n);
            for i in 0..40i64 {
                let (x, y) = ((i * 37) % 90, (i * 53) % 74);
                let q_out = window(result, x, y);
                let q_ex = window(&ex, (i * 29) % 122, (i * 17) % 122);
                for (what, fast, slow) in [
                    (
                        "energy",
                        fast_ex.nearest_sq_distance(&q_out, &mut scratch.0),
                        slow_ex.nearest_sq_distance(&q_out, None, &mut scratch.1),
                    ),
                    (
                        "completeness",
                        fast_out.nearest_sq_distance(&q_ex, &mut scratch.0),
                        slow_out.nearest_sq_distance(&q_ex, None, &mut scratch.1),
                    ),
                ] {
                    assert!(
                        (fast - slow).abs() <= 1e-5 * slow.max(1e-3),
                        "{name}, {label}, {what}, query {i}: index {fast}, exhaustive {slow}"
                    );
                }
            }
        }
        // The whole measure, once per photo, against its exhaustive sum.
        let result = &results[3].1;
        let slow_out = ExemplarNeighbourhoods::interior(result, n);
        let picks = surfsynth::kernels::metrics::quality::completeness_windows(128, 128, n);
        let sum: f64 = picks
            .iter()
            .map(|&(x, y)| {
                let q = window(&ex, x as i64, y as i64);
                f64::from(slow_out.nearest_sq_distance(&q, None, &mut scratch.1))
            })
            .sum();
        let exhaustive = (sum / picks.len() as f64 / f64::from(n * n * 3)) as f32;
        let fast = completeness(result, &ex, n);
        assert!(
            (fast - exhaustive).abs() <= 1e-5 * exhaustive,
            "{name}: completeness {fast} vs exhaustive {exhaustive}"
        );
    }
}
