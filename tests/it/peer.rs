//! The peer (Embark's texture-synthesis, `common::peer`): its result is read
//! back correctly and is reproducible at one thread.

use crate::common::data_file;
use crate::common::peer::peer_synthesis;
use surfsynth::image::{Image, load_image};

/// The top-left `side`² block of a shared texture (small, so the test is fast).
fn exemplar(name: &str, side: u32) -> Image {
    let full = load_image(&data_file(&format!("textures/{name}.png"))).expect("shared texture");
    let c = full.channels as usize;
    let mut data = Vec::with_capacity((side * side) as usize * c);
    for y in 0..side {
        for x in 0..side {
            data.extend_from_slice(full.pixel(x, y));
        }
    }
    Image::from_data(side, side, full.channels, data).expect("crop")
}

#[test]
fn every_output_pixel_is_the_exemplar_pixel_its_source_names() {
    let ex = exemplar("stones", 48);
    let r = peer_synthesis(&ex, 40, 32, 7, 1);
    assert_eq!(
        (r.image.width, r.image.height, r.image.channels),
        (40, 32, 3)
    );
    assert_eq!((r.sources.width, r.sources.height), (40, 32));
    assert_eq!(r.sources.texels.len(), 40 * 32);
    assert!(r.seconds > 0.0);
    for (i, t) in r.sources.texels.iter().enumerate() {
        assert!(
            t[0] > 0.0 && t[0] < 48.0 && t[1] > 0.0 && t[1] < 48.0,
            "pixel {i}: source {t:?} outside the 48² exemplar"
        );
        assert_eq!(t[0].fract(), 0.5, "pixel centres are index + 0.5");
        let (x, y) = ((i % 40) as u32, (i / 40) as u32);
        assert_eq!(
            r.image.pixel(x, y),
            ex.pixel(t[0] as u32, t[1] as u32),
            "pixel ({x}, {y}) is a copy of its source"
        );
    }
}

#[test]
fn one_thread_same_seed_same_result() {
    let ex = exemplar("brick", 48);
    let a = peer_synthesis(&ex, 48, 48, 3, 1);
    let b = peer_synthesis(&ex, 48, 48, 3, 1);
    assert_eq!(a.image, b.image, "same seed, one thread: same image");
    assert_eq!(a.sources.texels, b.sources.texels);
    let c = peer_synthesis(&ex, 48, 48, 4, 1);
    assert_ne!(a.image, c.image, "another seed gives another image");
}

/// Not a gate: prints whether Embark's result depends on the thread count
/// (what the doc comment of `common::peer` states). Run with
/// `cargo test --release --test it -- --ignored --nocapture peer::`.
#[test]
#[ignore = "a measurement, not a gate: Embark is not deterministic above one thread"]
fn report_thread_count_dependence() {
    let ex = exemplar("stones", 64);
    let one = peer_synthesis(&ex, 96, 96, 1, 1);
    for run in 0..3 {
        let two = peer_synthesis(&ex, 96, 96, 1, 2);
        let again = peer_synthesis(&ex, 96, 96, 1, 2);
        let differ = |a: &Image, b: &Image| {
            a.data
                .chunks_exact(3)
                .zip(b.data.chunks_exact(3))
                .filter(|(p, q)| p != q)
                .count()
        };
        eprintln!(
            "run {run}: 2 threads vs 1: {} of {} pixels differ; 2 threads twice: {} differ",
            differ(&one.image, &two.image),
            96 * 96,
            differ(&two.image, &again.image)
        );
    }
}
