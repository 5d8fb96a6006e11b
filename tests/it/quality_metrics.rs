//! Metric sanity: each quality measure sees the failure it is meant to catch.
//!
//! On every shared texture, four failure images — the exemplar blurred
//! (Gaussian, σ = 2 px), a flat mean-colour image, the exemplar rotated by 90°
//! (anisotropic textures only), and a tiling of one 32-px block — must score
//! clearly worse than an honest synthesis (the peer, Embark's
//! `texture-synthesis`, same exemplar, fixed seed, one thread: reproducible) on the measure meant to
//! catch them. The factors are stated at each assertion. The texture energy
//! (coherence) is printed beside them: it does not see blur or flat colour,
//! which is why the other measures exist.

use crate::common;

use crate::common::gates::to_rgb;
use crate::common::peer::peer_synthesis;
use surfsynth::image::Image;
use surfsynth::image::io::load_image;
use surfsynth::kernels::metrics::quality::{luma, structure_features, structure_scales};
use surfsynth::kernels::metrics::{EnergySettings, ImageQuality, SourceMap, image_quality};

/// The shared textures, found by listing the folder (new ones join in).
fn shared_textures() -> Vec<(String, Image)> {
    let dir = common::data_file("textures");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "png"))
        .collect();
    names.sort();
    names
        .into_iter()
        .map(|p| {
            let img = load_image(&p).unwrap();
            let img = to_rgb(&img);
            (p.file_stem().unwrap().to_string_lossy().into_owned(), img)
        })
        .collect()
}

/// Separable Gaussian blur with clamped borders.
fn gaussian_blur(img: &Image, sigma: f32) -> Image {
    let r = (3.0 * sigma).ceil() as i64;
    let k: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let sum: f32 = k.iter().sum();
    let k: Vec<f32> = k.iter().map(|v| v / sum).collect();
    let pass = |src: &Image, horizontal: bool| {
        let mut out = Image::new(src.width, src.height, src.channels);
        for y in 0..src.height as i64 {
            for x in 0..src.width as i64 {
                let o = out.offset(x as u32, y as u32);
                for (j, w) in k.iter().enumerate() {
                    let d = j as i64 - r;
                    let (sx, sy) = if horizontal { (x + d, y) } else { (x, y + d) };
                    let p = src.texel(sx, sy, surfsynth::image::sample::Wrap::Clamp);
                    for (a, v) in out.data[o..o + src.channels as usize].iter_mut().zip(p) {
                        *a += w * v;
                    }
                }
            }
        }
        out
    };
    pass(&pass(img, true), false)
}

fn flat(img: &Image) -> Image {
    let mean = img.mean();
    Image::from_data(
        img.width,
        img.height,
        img.channels,
        mean.repeat(img.pixel_count()),
    )
    .unwrap()
}

fn rotate90(img: &Image) -> Image {
    let (w, h) = (img.width, img.height);
    let mut out = Image::new(h, w, img.channels);
    for y in 0..h {
        for x in 0..w {
            out.pixel_mut(h - 1 - y, x).copy_from_slice(img.pixel(x, y));
        }
    }
    out
}

/// A `w`×`h` tiling of the 32-px block at `(bx, by)`, with its source map.
fn tiling(img: &Image, bx: u32, by: u32, w: u32, h: u32) -> (Image, SourceMap) {
    let mut out = Image::new(w, h, img.channels);
    let mut texels = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        for x in 0..w {
            let (sx, sy) = (bx + x % 32, by + y % 32);
            out.pixel_mut(x, y).copy_from_slice(img.pixel(sx, sy));
            texels.push([sx as f32 + 0.5, sy as f32 + 0.5]);
        }
    }
    (
        out,
        SourceMap {
            width: w,
            height: h,
            texels,
        },
    )
}

/// Orientation anisotropy of a texture, independent of any result: the
/// share of its gradient energy in its strongest orientation bin and the
/// two beside it (3 of 8 bins: 0.375 for an isotropic texture).
fn anisotropy(img: &Image) -> f64 {
    let scales = structure_scales((img.width, img.height), (img.width, img.height));
    let f = structure_features(&luma(img), img.width as usize, img.height as usize, scales);
    let bins = f.len() / scales;
    let per: Vec<f64> = (0..bins)
        .map(|b| (0..scales).map(|s| f[s * bins + b]).sum())
        .collect();
    let total: f64 = per.iter().sum();
    (0..bins)
        .map(|b| per[b] + per[(b + 1) % bins] + per[(b + bins - 1) % bins])
        .fold(0.0, f64::max)
        / total
}

fn show(label: &str, q: &ImageQuality) {
    eprintln!(
        "  {label:9} coherence {:.4}/{:.4} completeness {:.4} sharpness {:.3} structure {:.3} histogram {:.4} coverage {}",
        q.coherence_mean,
        q.coherence_p90,
        q.completeness,
        q.sharpness,
        q.structure,
        q.histogram,
        q.verbatim
            .map_or("-".into(), |v| format!("{:.3}", v.source_coverage)),
    );
}

#[test]
fn each_measure_sees_the_failure_it_is_meant_to_catch() {
    let settings = EnergySettings {
        samples: 600,
        ..Default::default()
    };
    let size = 128;
    for (name, ex) in shared_textures() {
        let peer = peer_synthesis(&ex, size, size, 1, 1);
        let honest = image_quality(&peer.image, &ex, Some(&peer.sources), &settings);
        let blurred = image_quality(&gaussian_blur(&ex, 2.0), &ex, None, &settings);
        let flat_q = image_quality(&flat(&ex), &ex, None, &settings);
        let (tiled_img, tiled_src) = tiling(&ex, ex.width / 2 - 16, ex.height / 2 - 16, size, size);
        let tiled = image_quality(&tiled_img, &ex, Some(&tiled_src), &settings);
        let aniso = anisotropy(&ex);
        eprintln!("{name} (anisotropy {aniso:.3}):");
        show("peer", &honest);
        show("blurred", &blurred);
        show("flat", &flat_q);
        show("tiled", &tiled);
        // Blur: sharpness at most 0.7× the honest synthesis's.
        assert!(
            blurred.sharpness <= 0.7 * honest.sharpness,
            "{name}: blurred sharpness {} vs peer {}",
            blurred.sharpness,
            honest.sharpness
        );
        // Flat colour: completeness at least 2× the peer's, sharpness 0,
        // structure 1 (all energy missing).
        assert!(
            flat_q.completeness >= 2.0 * honest.completeness,
            "{name}: flat completeness {} vs peer {}",
            flat_q.completeness,
            honest.completeness
        );
        assert_eq!((flat_q.sharpness, flat_q.structure), (0.0, 1.0), "{name}");
        // One 32-px block tiled: completeness at least 1.5× the peer's, and
        // source coverage at most a third of the peer's.
        let (tv, hv) = (tiled.verbatim.unwrap(), honest.verbatim.unwrap());
        assert!(
            tiled.completeness >= 1.5 * honest.completeness,
            "{name}: tiled completeness {} vs peer {}",
            tiled.completeness,
            honest.completeness
        );
        assert!(
            tv.source_coverage <= hv.source_coverage / 3.0,
            "{name}: tiled coverage {} vs peer {}",
            tv.source_coverage,
            hv.source_coverage
        );
        // Rotation by 90° of an anisotropic texture (over half its gradient
        // energy within ±22.5° of one orientation): structure distance at
        // least 2× the peer's and 0.1 above it.
        if aniso > 0.5 {
            let rotated = image_quality(&rotate90(&ex), &ex, None, &settings);
            show("rotated", &rotated);
            assert!(
                rotated.structure >= 2.0 * honest.structure
                    && rotated.structure >= honest.structure + 0.1,
                "{name}: rotated structure {} vs peer {}",
                rotated.structure,
                honest.structure
            );
        }
    }
}
