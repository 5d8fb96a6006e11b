//! Compares two renders of one object on a plain or vertically graded
//! background (a run's `preview_0.png` and a screenshot of its `view.html`,
//! by `scripts/viewer/screenshot.sh`): the object's silhouette in each, their
//! intersection over union, the mean absolute colour difference over the
//! pixels both cover, each silhouette's bounding box, and optionally a
//! picture of the two side by side with their difference.
//!
//!     cargo run --release --example compare_images -- A.png B.png [SIDE_BY_SIDE.png]
//!
//! A pixel belongs to the object when it differs from the background of its
//! row by more than 8/255 in some channel; the background of a row is its
//! first or last pixel, whichever is nearer the image's corner colours (so
//! an object touching one side does not become background). Both images
//! must be the same size. Prints one JSON object.

use image::{Rgb, RgbImage};
use std::error::Error;

const THRESHOLD: i32 = 8;

fn distance(a: &Rgb<u8>, b: &Rgb<u8>) -> i32 {
    (0..3)
        .map(|c| (i32::from(a[c]) - i32::from(b[c])).abs())
        .max()
        .unwrap_or(0)
}

/// Per pixel: whether it is the object's.
fn silhouette(img: &RgbImage) -> Vec<bool> {
    let (w, h) = img.dimensions();
    let corners = [
        *img.get_pixel(0, 0),
        *img.get_pixel(w - 1, 0),
        *img.get_pixel(0, h - 1),
        *img.get_pixel(w - 1, h - 1),
    ];
    let near_corner = |p: &Rgb<u8>| corners.iter().map(|c| distance(p, c)).min().unwrap_or(0);
    let mut mask = Vec::with_capacity((w * h) as usize);
    for y in 0..h {
        let (l, r) = (img.get_pixel(0, y), img.get_pixel(w - 1, y));
        let bg = if near_corner(l) <= near_corner(r) {
            l
        } else {
            r
        };
        for x in 0..w {
            mask.push(distance(img.get_pixel(x, y), bg) > THRESHOLD);
        }
    }
    mask
}

/// `[x0, y0, x1, y1]` of the set pixels (inclusive), or `None`.
fn bounds(mask: &[bool], w: u32) -> Option<[u32; 4]> {
    let mut b: Option<[u32; 4]> = None;
    for (i, _) in mask.iter().enumerate().filter(|(_, m)| **m) {
        let (x, y) = (i as u32 % w, i as u32 / w);
        b = Some(match b {
            None => [x, y, x, y],
            Some([x0, y0, x1, y1]) => [x0.min(x), y0.min(y), x1.max(x), y1.max(y)],
        });
    }
    b
}

fn luma(p: &Rgb<u8>) -> f64 {
    0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2])
}

fn main() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        return Err("usage: compare_images A.png B.png [SIDE_BY_SIDE.png]".into());
    }
    let a = image::open(&args[0])?.to_rgb8();
    let b = image::open(&args[1])?.to_rgb8();
    if a.dimensions() != b.dimensions() {
        return Err(format!(
            "{} is {:?} but {} is {:?}",
            args[0],
            a.dimensions(),
            args[1],
            b.dimensions()
        )
        .into());
    }
    let (w, h) = a.dimensions();
    let (ma, mb) = (silhouette(&a), silhouette(&b));
    let (mut both, mut either) = (0u64, 0u64);
    let (mut diff_sum, mut luma_a, mut luma_b) = (0f64, 0f64, 0f64);
    let (mut count_a, mut count_b) = (0u64, 0u64);
    let (mut all_sum, mut sum_a, mut sum_b) = (0f64, 0f64, 0f64);
    for (i, (pa, pb)) in a.pixels().zip(b.pixels()).enumerate() {
        let d: f64 = (0..3)
            .map(|c| (f64::from(pa[c]) - f64::from(pb[c])).abs())
            .sum::<f64>()
            / 3.0;
        all_sum += d;
        if ma[i] {
            count_a += 1;
            sum_a += luma(pa);
        }
        if mb[i] {
            count_b += 1;
            sum_b += luma(pb);
        }
        if ma[i] || mb[i] {
            either += 1;
        }
        if ma[i] && mb[i] {
            both += 1;
            diff_sum += d;
            luma_a += luma(pa);
            luma_b += luma(pb);
        }
    }
    let per = |s: f64, n: u64| if n > 0 { s / n as f64 } else { f64::NAN };
    let report = serde_json::json!({
        "a": args[0],
        "b": args[1],
        "size": [w, h],
        "object_pixels": [count_a, count_b],
        "silhouette_iou": per(both as f64, either),
        "mean_abs_diff_on_object": per(diff_sum, both),
        "mean_abs_diff_all": per(all_sum, u64::from(w) * u64::from(h)),
        "mean_luma_on_common_object": [per(luma_a, both), per(luma_b, both)],
        "mean_luma_on_own_object": [per(sum_a, count_a), per(sum_b, count_b)],
        "bounds": [bounds(&ma, w), bounds(&mb, w)],
    });
    println!("{}", serde_json::to_string_pretty(&report)?);
    if let Some(out) = args.get(2) {
        // A | B | |A − B| ×3, with the silhouettes' outlines on the difference:
        // red where only A has the object, blue where only B has it.
        let mut sheet = RgbImage::new(3 * w, h);
        for y in 0..h {
            for x in 0..w {
                let i = (y * w + x) as usize;
                let (pa, pb) = (a.get_pixel(x, y), b.get_pixel(x, y));
                sheet.put_pixel(x, y, *pa);
                sheet.put_pixel(w + x, y, *pb);
                let d = Rgb(std::array::from_fn(|c| {
                    ((i32::from(pa[c]) - i32::from(pb[c])).abs() * 3).min(255) as u8
                }));
                let d = match (ma[i], mb[i]) {
                    (true, false) => Rgb([200, 40, 40]),
                    (false, true) => Rgb([40, 60, 200]),
                    _ => d,
                };
                sheet.put_pixel(2 * w + x, y, d);
            }
        }
        sheet.save(out)?;
    }
    Ok(())
}
