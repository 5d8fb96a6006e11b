//! Material channels that follow one synthesis (issue 7): extra exemplar maps
//! in `[input]`, their derivations and size checks, and the per-sample
//! exemplar coordinates every method records.

mod common;

use bevy_ecs::prelude::*;
use surfsynth::config::ConfigSource;
use surfsynth::kernels::channels::{decode_normal, luminance_image};
use surfsynth::pipeline::{Pipeline, PipelineError, load_input, run_in_world};
use surfsynth::stages::world::*;

fn pipeline(text: &str) -> Pipeline {
    Pipeline::from_source(ConfigSource::from_text("channels.toml", text)).expect("valid config")
}

fn input_error(text: &str) -> String {
    let p = pipeline(text);
    load_input(&p.input, &p.source.base_dir, &p.source.file)
        .expect_err("the input is refused")
        .to_string()
}

fn world_for(config: &str) -> Result<World, PipelineError> {
    let p = pipeline(config);
    let input = load_input(&p.input, &p.source.base_dir, &p.source.file)?;
    let mut world = World::new();
    run_in_world(&p, &mut world, input).map(|_| world)
}

const BRICKS: &str = r#"
seed = 1
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
CHANNELS
"#;

fn with_channels(channels: &str) -> String {
    BRICKS.replace("CHANNELS", channels)
}

#[test]
fn no_maps_give_an_empty_channels_resource() {
    let w = world_for(&with_channels("")).expect("runs");
    let ch = w.resource::<ExemplarChannels>();
    assert!(ch.height.is_none() && ch.normal.is_none() && ch.roughness.is_none());
}

#[test]
fn derived_maps_have_the_exemplar_size_and_follow_the_height() {
    let w = world_for(&with_channels(
        r#"height_map = "derive:builtin"
normal_map = "derive:height"
roughness_map = "derive:luminance"
normal_strength = 6.0"#,
    ))
    .expect("runs");
    let ex = w.resource::<Exemplar>().image.clone();
    let ch = w.resource::<ExemplarChannels>().clone();
    let h = ch.height.expect("height");
    let n = ch.normal.expect("normal");
    let r = ch.roughness.expect("roughness");
    assert_eq!((h.width, h.height, h.channels), (ex.width, ex.height, 1));
    assert_eq!((n.width, n.height, n.channels), (ex.width, ex.height, 3));
    assert_eq!((r.width, r.height, r.channels), (ex.width, ex.height, 1));
    // The builtin bricks: mortar row 8 is low, brick row 4 high.
    let row = |y: u32| (0..h.width).map(|x| h.pixel(x, y)[0]).sum::<f32>() / h.width as f32;
    assert!(row(8) < 0.2 && row(4) > 0.5, "{} {}", row(8), row(4));
    // Just above a mortar row (y = 7, inside a brick's bottom edge) the
    // height falls downwards in the image, i.e. rises towards +t: the normal
    // tilts towards −Y. Just below it (y = 9) the opposite.
    let mean_y = |y: u32| {
        (0..n.width)
            .map(|x| decode_normal(n.pixel(x, y).try_into().unwrap()).y)
            .sum::<f32>()
            / n.width as f32
    };
    assert!(mean_y(7) < -0.1, "{}", mean_y(7));
    assert!(mean_y(9) > 0.1, "{}", mean_y(9));
    // Roughness: 1 − luminance.
    let lum = luminance_image(&ex);
    for i in [0usize, 100, 1000] {
        assert!((r.data[i] - (1.0 - lum.data[i])).abs() < 1e-6);
    }
    // derive:luminance height is the luminance itself.
    let w = world_for(&with_channels(r#"height_map = "derive:luminance""#)).expect("runs");
    assert_eq!(w.resource::<ExemplarChannels>().height.as_ref(), Some(&lum));
}

#[test]
fn map_files_load_and_mismatched_sizes_name_the_file_and_both_sizes() {
    let dir = tempfile::tempdir().unwrap();
    let good = dir.path().join("h64.png");
    let small = dir.path().join("h32.png");
    let grey = dir.path().join("n64.png");
    image::GrayImage::from_fn(64, 64, |x, _| image::Luma([(x * 4) as u8]))
        .save(&good)
        .unwrap();
    image::GrayImage::from_fn(32, 32, |_, _| image::Luma([7]))
        .save(&small)
        .unwrap();
    image::GrayImage::from_fn(64, 64, |_, _| image::Luma([7]))
        .save(&grey)
        .unwrap();
    let w = world_for(&with_channels(&format!(
        "height_map = {:?}\nnormal_map = \"derive:height\"",
        good.display().to_string()
    )))
    .expect("runs");
    let h = w.resource::<ExemplarChannels>().height.clone().unwrap();
    assert!((h.pixel(10, 3)[0] - 40.0 / 255.0).abs() < 1e-6);

    let e = input_error(&with_channels(&format!(
        "height_map = {:?}",
        small.display().to_string()
    )));
    assert!(
        e.contains("h32.png")
            && e.contains("32x32")
            && e.contains("64x64")
            && e.contains("height_map"),
        "{e}"
    );
    let e = input_error(&with_channels(&format!(
        "roughness_map = {:?}",
        small.display().to_string()
    )));
    assert!(e.contains("roughness_map") && e.contains("32x32"), "{e}");
    let e = input_error(&with_channels(&format!(
        "normal_map = {:?}",
        grey.display().to_string()
    )));
    assert!(e.contains("normal_map") && e.contains("needs 3"), "{e}");
    let e = input_error(&with_channels("height_map = \"missing/h.png\""));
    assert!(e.contains("h.png"), "{e}");
}

#[test]
fn bad_derivations_say_what_is_allowed() {
    let e = input_error(&with_channels("normal_map = \"derive:height\""));
    assert!(
        e.contains("input.normal_map") && e.contains("height_map"),
        "{e}"
    );
    let e = input_error(&with_channels("height_map = \"derive:magic\""));
    assert!(
        e.contains("derive:magic")
            && e.contains("derive:luminance")
            && e.contains("derive:builtin"),
        "{e}"
    );
    let e = input_error(&with_channels(
        "height_map = \"derive:luminance\"\nnormal_map = \"derive:height\"\nnormal_strength = 500.0",
    ));
    assert!(
        e.contains("normal_strength") && e.contains("0..=100"),
        "{e}"
    );
    let dir = tempfile::tempdir().unwrap();
    let ex = dir.path().join("ex.png");
    image::RgbImage::from_fn(16, 16, |x, y| image::Rgb([x as u8 * 9, y as u8 * 9, 3]))
        .save(&ex)
        .unwrap();
    let text = format!(
        "[input]\nmesh = \"builtin:icosphere\"\nexemplar = {:?}\nheight_map = \"derive:builtin\"\n",
        ex.display().to_string()
    );
    let e = input_error(&text);
    assert!(
        e.contains("derive:builtin") && e.contains("builtin exemplar"),
        "{e}"
    );
}
