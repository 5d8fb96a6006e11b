//! The quality gate of the synthesis tests: a method's result must look like
//! a synthesis of its exemplar, judged against the peer (Embark's
//! `texture-synthesis`, [`super::peer`]) on the same exemplar, at the same
//! output size, with a fixed seed, computed in the test.
//!
//! [`NEAR_PEER`] states the factors once; [`assert_near_peer`] applies them.
//! The rest are the few conversions every gate needs: results on a planar
//! grid at one vertex per exemplar pixel as images, grey exemplars as RGB
//! (the peer is RGB), and the measures of the peer's output.

use surfsynth::image::Image;
use surfsynth::kernels::metrics::{EnergySettings, ImageQuality, SourceMap, image_quality};

use super::peer::peer_synthesis;

/// Seed of the peer's synthesis in every gate.
pub const PEER_SEED: u64 = 1;

/// Threads of the peer's synthesis. One: the peer's result depends on its
/// thread count, and a gate must not change with the machine.
pub const PEER_THREADS: usize = 1;

/// How far a result may fall behind the peer on each measure
/// (`surfsynth::kernels::metrics::ImageQuality`; lower is better except
/// sharpness).
#[derive(Clone, Copy, Debug)]
pub struct Gate {
    /// Largest coherence mean as a multiple of the peer's (`INFINITY`: not
    /// gated; alone it rewards blur, so only gates that also bound
    /// completeness and sharpness use it).
    pub coherence_mean: f32,
    /// Largest coherence p90 (seams, tears, garbage) as a multiple of the peer's.
    pub coherence_p90: f32,
    /// Largest completeness (missing content) as a multiple of the peer's.
    pub completeness: f32,
    /// Smallest sharpness as a multiple of the peer's.
    pub sharpness: f32,
    /// Smallest sharpness outright (1 = the exemplar's own gradient energy).
    pub sharpness_at_least: f32,
    /// Largest structure distance above the peer's (structure is in `[0, 1]`).
    pub structure_above: f32,
    /// Largest histogram distance: `histogram_factor × peer + histogram_above`.
    pub histogram_factor: f32,
    pub histogram_above: f32,
}

/// The "looks like a synthesis of this exemplar" bar, the same for every
/// method:
///
/// - coherence p90 ≤ 1.5 × the peer's: seams and tears raise the worst tenth
///   of the windows; 1.5× leaves room for a method's own seams but not for a
///   grid of tears or garbage.
/// - completeness ≤ 1.5 × the peer's: the metric sanity test
///   (`tests/it/quality_metrics.rs`) measures a flat mean-colour image at ≥ 2×
///   and a tiling of one 32-px block at ≥ 1.5× the peer's, so both fail (the
///   tiling at the edge).
/// - sharpness ≥ 0.8 × the peer's: the exemplar blurred by σ = 2 px measures
///   ≤ 0.7× the peer's there, so blur fails; 0.8 leaves a method the slight
///   softening of averaging or resampling.
/// - structure ≤ the peer's + 0.1: structure is a total-variation distance in
///   `[0, 1]`; the sanity test's 90°-rotated anisotropic texture is at least
///   0.1 above the peer's (and 2×), and a flat image is at 1.
/// - histogram ≤ 2 × the peer's + 0.01: the peer's histogram distance is
///   small (a few thousandths), so a factor alone would fail on rounding; 0.01
///   (2.5 grey levels of 255) is far below the colour drift and inverted
///   contrast this catches.
///
/// Coherence mean is printed but not gated: it rewards blur and flat colour.
/// Never loosen these to make a method pass: mark its gate `#[ignore]` with
/// the measured figures instead.
pub const NEAR_PEER: Gate = Gate {
    coherence_mean: f32::INFINITY,
    coherence_p90: 1.5,
    completeness: 1.5,
    sharpness: 0.8,
    sharpness_at_least: 0.0,
    structure_above: 0.1,
    histogram_factor: 2.0,
    histogram_above: 0.01,
};

/// The bar of issue 12 for the coherent synthesis: at least as good as the
/// peer on every measure, with a little room where a per-vertex method
/// copies smaller regions than a patch copier: coherence mean ≤ 1.2 × and
/// p90 ≤ 1.1 × the peer's, completeness ≤ the peer's, sharpness ≥ 0.9 of
/// the exemplar's (and ≥ 0.8 × the peer's), structure ≤ the peer's + 0.05,
/// histogram as [`NEAR_PEER`].
pub const AT_PEER: Gate = Gate {
    coherence_mean: 1.2,
    coherence_p90: 1.1,
    completeness: 1.0,
    sharpness: 0.8,
    sharpness_at_least: 0.9,
    structure_above: 0.05,
    histogram_factor: 2.0,
    histogram_above: 0.01,
};

/// The bar of issue 13 for the jump-map and lapped methods: coherence
/// p90 and completeness at most the peer's, coherence mean ≤ 1.1 × the
/// peer's, sharpness ≥ 0.9 of the exemplar's (and ≥ 0.8 × the peer's),
/// structure ≤ the peer's + 0.05; histogram as [`NEAR_PEER`].
pub const ISSUE_13: Gate = Gate {
    coherence_mean: 1.1,
    coherence_p90: 1.0,
    ..AT_PEER
};

/// The measures `gate` finds failing, one line each ("M: ours a vs peer b,
/// bound c"); empty when `ours` passes.
pub fn gate_failures(ours: &ImageQuality, peer: &ImageQuality, gate: &Gate) -> Vec<String> {
    let checks = [
        (
            "coherence mean",
            ours.coherence_mean,
            peer.coherence_mean,
            gate.coherence_mean * peer.coherence_mean,
            true,
        ),
        (
            "sharpness (of the exemplar's)",
            ours.sharpness,
            peer.sharpness,
            gate.sharpness_at_least,
            false,
        ),
        (
            "coherence p90",
            ours.coherence_p90,
            peer.coherence_p90,
            gate.coherence_p90 * peer.coherence_p90,
            true,
        ),
        (
            "completeness",
            ours.completeness,
            peer.completeness,
            gate.completeness * peer.completeness,
            true,
        ),
        (
            "sharpness",
            ours.sharpness,
            peer.sharpness,
            gate.sharpness * peer.sharpness,
            false,
        ),
        (
            "structure",
            ours.structure,
            peer.structure,
            peer.structure + gate.structure_above,
            true,
        ),
        (
            "histogram",
            ours.histogram,
            peer.histogram,
            gate.histogram_factor * peer.histogram + gate.histogram_above,
            true,
        ),
    ];
    checks
        .into_iter()
        // A measure fails unless it passes, so a NaN measure fails.
        .filter(|&(_, a, _, bound, at_most)| {
            let passes = if at_most { a <= bound } else { a >= bound };
            !passes
        })
        .map(|(name, a, b, bound, at_most)| {
            let rel = if at_most { "≤" } else { "≥" };
            format!(
                "{name}: ours {} vs peer {} (needs {rel} {})",
                figure(a),
                figure(b),
                figure(bound)
            )
        })
        .collect()
}

/// A measure with three significant digits (coherence and completeness are
/// often a few ten-thousandths).
fn figure(v: f32) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let decimals = (2 - v.abs().log10().floor() as i32).max(0) as usize;
    format!("{v:.decimals$}")
}

/// Every measure of `ours` beside the peer's, one line each ("ours vs peer
/// on M: a vs b").
pub fn comparison(label: &str, ours: &ImageQuality, peer: &ImageQuality) -> String {
    let coverage = |q: &ImageQuality| {
        q.verbatim
            .map_or("-".to_string(), |v| format!("{:.3}", v.source_coverage))
    };
    [
        ("coherence mean", ours.coherence_mean, peer.coherence_mean),
        ("coherence p90", ours.coherence_p90, peer.coherence_p90),
        ("completeness", ours.completeness, peer.completeness),
        ("sharpness", ours.sharpness, peer.sharpness),
        ("structure", ours.structure, peer.structure),
        ("histogram", ours.histogram, peer.histogram),
    ]
    .iter()
    .map(|(m, a, b)| {
        format!(
            "{label}: ours vs peer on {m}: {} vs {}",
            figure(*a),
            figure(*b)
        )
    })
    .chain(std::iter::once(format!(
        "{label}: ours vs peer on source coverage: {} vs {}",
        coverage(ours),
        coverage(peer)
    )))
    .collect::<Vec<_>>()
    .join("\n")
}

/// The gate: prints every measure of `ours` and `peer`, and panics naming
/// the failing measures (with every measure in the message) when `ours` does
/// not meet `gate` relative to `peer`.
pub fn assert_near_peer(label: &str, ours: &ImageQuality, peer: &ImageQuality, gate: &Gate) {
    let table = comparison(label, ours, peer);
    eprintln!("{table}");
    let failures = gate_failures(ours, peer, gate);
    assert!(
        failures.is_empty(),
        "{label} fails the peer gate on {}\n{table}",
        failures.join("; ")
    );
}

/// [`assert_near_peer`] over several results at once: prints every
/// comparison first, then panics naming every result that fails, so one run
/// shows all the figures.
pub fn assert_all_near_peer(results: &[(String, ImageQuality, ImageQuality)], gate: &Gate) {
    let mut failed = Vec::new();
    for (label, ours, peer) in results {
        eprintln!("{}", comparison(label, ours, peer));
        let f = gate_failures(ours, peer, gate);
        if !f.is_empty() {
            failed.push(format!("{label}: {}", f.join("; ")));
        }
    }
    assert!(
        failed.is_empty(),
        "fails the peer gate:\n{}",
        failed.join("\n")
    );
}

/// Coherence windows the gates measure: every window of a 256² result
/// (and of anything smaller). 1000 random windows, the measure until stop
/// 29, left the mean and p90 of a result with a few strong seams (brick)
/// at the mercy of which windows were drawn: one `jump_surface` brick
/// result measured 0.000367–0.000512 (mean) and 0.00058–0.00101 (p90)
/// over sample seeds 0–7, against 0.000380 and 0.00069 over every window —
/// ±20 % and more around a gate of 1.1 ×. Every window costs 2–3 s per
/// 256² image on two cores (exhaustive search, pruned).
pub const GATE_SAMPLES: usize = 1 << 16;

/// Settings of the measures in every gate: 7×7 windows, every window up
/// to [`GATE_SAMPLES`], seed 1 (for larger results).
pub fn gate_settings() -> EnergySettings {
    EnergySettings {
        neighbourhood: 7,
        samples: GATE_SAMPLES,
        seed: 1,
        ..Default::default()
    }
}

/// The measures of `result` (any channel count, converted to RGB) against
/// the RGB `exemplar`.
pub fn quality_of(result: &Image, sources: Option<&SourceMap>, exemplar: &Image) -> ImageQuality {
    image_quality(
        &to_rgb(result),
        &to_rgb(exemplar),
        sources,
        &gate_settings(),
    )
}

/// The measures of the peer's `width`×`height` synthesis of `exemplar`
/// (converted to RGB), seed [`PEER_SEED`], [`PEER_THREADS`] threads.
pub fn peer_quality(exemplar: &Image, width: u32, height: u32) -> ImageQuality {
    let ex = to_rgb(exemplar);
    let peer = peer_synthesis(&ex, width, height, PEER_SEED, PEER_THREADS);
    eprintln!(
        "peer: {width}×{height} from {}×{} in {:.2} s",
        ex.width, ex.height, peer.seconds
    );
    image_quality(&peer.image, &ex, Some(&peer.sources), &gate_settings())
}

/// Gates a result image against the peer's synthesis of the same exemplar
/// at the result's size: [`quality_of`], [`peer_quality`], [`assert_near_peer`]
/// with [`NEAR_PEER`].
pub fn assert_image_near_peer(
    label: &str,
    result: &Image,
    sources: Option<&SourceMap>,
    exemplar: &Image,
) {
    let ours = quality_of(result, sources, exemplar);
    let peer = peer_quality(exemplar, result.width, result.height);
    assert_near_peer(label, &ours, &peer, &NEAR_PEER);
}

/// `img` with 3 channels: RGB kept, grey repeated, alpha dropped.
pub fn to_rgb(img: &Image) -> Image {
    img.to_rgb()
}

/// The `w`×`h` crop of `img` at `(x0, y0)`.
pub fn crop(img: &Image, x0: u32, y0: u32, w: u32, h: u32) -> Image {
    let mut out = Image::new(w, h, img.channels);
    for y in 0..h {
        for x in 0..w {
            out.pixel_mut(x, y)
                .copy_from_slice(img.pixel(x0 + x, y0 + y));
        }
    }
    out
}

/// A planar grid result at one vertex per exemplar pixel as an image:
/// vertex `j·columns + i` (column `i` along +x, row `j` along +y, frames
/// s = +x, t = +y) is pixel `(i, rows − 1 − j)`, since texture up is image
/// row −1. `values` has `channels` values per vertex; `sources` (if any) is
/// each vertex's exemplar coordinate in level-0 pixels.
pub fn grid_image(
    values: &[f32],
    channels: usize,
    columns: u32,
    rows: u32,
    sources: Option<&[[f32; 2]]>,
) -> (Image, Option<SourceMap>) {
    let n = (columns * rows) as usize;
    assert_eq!(values.len(), n * channels, "one colour per grid vertex");
    let mut img = Image::new(columns, rows, channels as u32);
    let mut texels = vec![[f32::NAN; 2]; n];
    for j in 0..rows {
        for i in 0..columns {
            let v = (j * columns + i) as usize;
            let y = rows - 1 - j;
            img.pixel_mut(i, y)
                .copy_from_slice(&values[v * channels..(v + 1) * channels]);
            if let Some(s) = sources {
                texels[(y * columns + i) as usize] = s[v];
            }
        }
    }
    let map = sources.map(|_| SourceMap {
        width: columns,
        height: rows,
        texels,
    });
    (img, map)
}

/// A result on a flat mesh as a `side`² image at one exemplar pixel per
/// pixel: `signal` resampled (`surfsynth::kernels::surface::surface_sample`, linear
/// over the faces) at the `side`² template points `spacing` world units
/// apart around the vertex nearest `centre`, in `frame` (image x along `s`,
/// image y along `−t`). For meshes whose vertices are not on a pixel
/// lattice (√2 hierarchies, coarse planes with corner UVs, lapped pastes);
/// panics unless the faces cover every point.
pub fn plane_image(
    mesh: &surfsynth::mesh::PolyMesh,
    signal: &surfsynth::kernels::metrics::SurfaceSignal,
    frame: &surfsynth::kernels::surface::frames::TangentFrame,
    centre: glam::Vec3,
    spacing: f32,
    side: u32,
) -> Image {
    use surfsynth::kernels::surface::surface_sample::{ResampleScratch, resample_neighbourhood};
    let vertex = (0..mesh.vertex_count())
        .min_by(|&a, &b| {
            let d = |v: usize| (mesh.positions[v] - centre).length();
            d(a).total_cmp(&d(b))
        })
        .expect("a mesh with vertices");
    let topo = surfsynth::mesh::Topology::build(mesh);
    let ch = signal.channels();
    let mut out = vec![0.0; (side * side) as usize * ch];
    let covered = resample_neighbourhood(
        mesh,
        &topo,
        vertex as u32,
        frame,
        spacing,
        side,
        signal,
        &vec![0.0; ch],
        &mut out,
        &mut ResampleScratch::new(),
    );
    assert_eq!(
        covered,
        (side * side) as usize,
        "the mesh covers the {side}² image"
    );
    Image::from_data(side, side, ch as u32, out).expect("image size")
}

/// `plane.png` and `plane_sources.png` of a planar run in `dir`, as the
/// quality bench reads them: the image, and per pixel the exemplar texel.
pub fn plane_result(dir: &std::path::Path) -> (Image, SourceMap) {
    let img = surfsynth::image::load_image(&dir.join("plane.png")).expect("plane.png");
    let src = image::open(dir.join("plane_sources.png"))
        .expect("plane_sources.png")
        .into_rgb16();
    (img, source_map(&src))
}

/// The source map of a `plane_sources.png` (16-bit RGB: R = exemplar x
/// index, G = y, B = 65535 where known; texel centres at `+ 0.5`).
pub fn source_map(src: &image::ImageBuffer<image::Rgb<u16>, Vec<u16>>) -> SourceMap {
    let texels = src
        .pixels()
        .map(|p| {
            if p.0[2] == u16::MAX {
                [f32::from(p.0[0]) + 0.5, f32::from(p.0[1]) + 0.5]
            } else {
                [f32::NAN; 2]
            }
        })
        .collect();
    SourceMap {
        width: src.width(),
        height: src.height(),
        texels,
    }
}
