//! The planar quality benchmark (issue 11): every synthesis method and the
//! peer (Embark Studios' `texture-synthesis` 0.8.2, `tests/common/peer.rs`)
//! on every shared texture, measured with `kernels::metrics::image_quality`.
//!
//! ```text
//! cargo bench --bench quality
//! QUALITY_TEXTURES=stones QUALITY_METHODS=peer,jump_pixel QUALITY_SIZE=128 cargo bench --bench quality
//! ```
//!
//! Writes into `target/quality/` (under `$CARGO_TARGET_DIR` when set):
//! `quality.md` (a table texture × method with every metric, the seconds at
//! one thread and on all cores, whether the two results are identical, and a
//! second table of every metric as a ratio to the peer's on that texture),
//! `quality.csv` (the same, one row per texture × method) and
//! `sheet_<texture>.png` (exemplar at its true scale | peer | every method,
//! labelled). The run
//! folders of the methods are kept in `target/quality/runs/`.
//!
//! Environment knobs:
//! - `QUALITY_TEXTURE_DIR=FOLDER`: where the textures are (every `*.png`
//!   there); default `data/textures/`.
//! - `QUALITY_TEXTURES=stones,water`: textures to run, by file stem; default
//!   every `*.png` in `data/textures/` (listed at run time, so a new
//!   texture is picked up).
//! - `QUALITY_METHODS=peer,jump_pixel,...`: methods to run; default the peer
//!   and every method of `configs/plane/` below ([`METHODS`]).
//! - `QUALITY_SIZE=256`: side of the square output, in pixels (default 256).
//!   For our methods it sets the configs' `plane_size`, `width`/`height` and
//!   plane-mesh size ([`size_overrides`]; exact for the jump-map methods,
//!   approximate for those on coarse meshes); a result of another size is an
//!   error row.
//! - `QUALITY_THREADS=1,all`: thread settings, `all` = every core (default
//!   both). Our methods run inside a rayon pool of that many threads; the peer
//!   gets `max_thread_count` (it uses its own threads, not rayon).
//!
//! Every run uses seed [`SEED`]; the metrics are computed on the first
//! thread setting's result (one thread by default). The peer uses Embark's
//! defaults apart from size, seed and threads. Wall seconds cover the whole
//! pipeline run (loading, every stage, writing files) or, for the peer,
//! Embark's session; CPU seconds are the process's user + system time over
//! the same span (`/proc/self/stat`, 10 ms resolution; Linux only, else
//! blank). The jump-map cache is emptied before every run, so its analysis
//! is always timed. A method that fails (error or panic) is a row with its
//! error; the bench carries on. Progress lines go to stderr.

#[path = "../tests/common/peer.rs"]
#[allow(dead_code)]
mod peer;

#[path = "../tests/common/gates.rs"]
#[allow(dead_code)]
mod gates;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use surfsynth::config::ConfigSource;
use surfsynth::image::{Image, load_image};
use surfsynth::kernels::metrics::{ImageQuality, SourceMap, image_quality};
use surfsynth::output::contact_sheet::{SheetLayout, SheetTile, contact_sheet};
use surfsynth::output::{write_bytes_atomic, write_png};
use surfsynth::pipeline::{Pipeline, RunOptions};

/// The methods of `configs/plane/<method>.toml` (a public interface).
const METHODS: [&str; 10] = [
    "jump_pixel",
    "jump_patch",
    "jump_surface",
    "jump_surface_coherent",
    "lapped",
    "wei_levoy",
    "coherent",
    "bangay_morkel",
    "bangay_morkel_no_cut",
    "bangay_morkel_coherent",
];

/// The name of the peer's rows.
const PEER: &str = "peer";

/// Seed of every run.
const SEED: u64 = 1;

/// The metric columns, in table order.
const METRICS: [&str; 11] = [
    "coherence_mean",
    "coherence_p90",
    "completeness",
    "sharpness",
    "structure",
    "histogram",
    "source_coverage",
    "mean_region_area",
    "mean_region_fraction",
    "largest_region",
    "large_region_repeats",
];

/// The metrics of [`METRICS`], in that order; NaN for the verbatim measures
/// of a result without source coordinates.
fn metric_values(q: &ImageQuality) -> [f32; 11] {
    let v = q.verbatim;
    let verbatim =
        |f: fn(&surfsynth::kernels::metrics::VerbatimStats) -> f32| v.as_ref().map_or(f32::NAN, f);
    [
        q.coherence_mean,
        q.coherence_p90,
        q.completeness,
        q.sharpness,
        q.structure,
        q.histogram,
        verbatim(|s| s.source_coverage),
        verbatim(|s| s.mean_region_area),
        verbatim(|s| s.mean_region_fraction),
        verbatim(|s| s.largest_region as f32),
        verbatim(|s| s.large_region_repeats as f32),
    ]
}

/// A thread setting of `QUALITY_THREADS`.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Threads {
    One,
    All,
}

impl Threads {
    fn count(self) -> usize {
        match self {
            Threads::One => 1,
            Threads::All => std::thread::available_parallelism().map_or(1, |n| n.get()),
        }
    }
    fn label(self) -> String {
        match self {
            Threads::One => "1 thread".into(),
            Threads::All => format!("all ({})", self.count()),
        }
    }
}

/// What the environment asks for.
struct Knobs {
    textures: Vec<(String, PathBuf)>,
    methods: Vec<String>,
    size: u32,
    threads: Vec<Threads>,
}

fn list_env(name: &str) -> Option<Vec<String>> {
    let v = std::env::var(name).ok()?;
    let items: Vec<String> = v
        .split(',')
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect();
    (!items.is_empty()).then_some(items)
}

fn knobs(manifest: &Path) -> Result<Knobs, String> {
    // QUALITY_TEXTURE_DIR=FOLDER: the PNGs of another folder (textures the
    // project never tuned on); default the shared photos.
    let dir = std::env::var_os("QUALITY_TEXTURE_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest.join("data/textures"));
    let mut all: Vec<(String, PathBuf)> = std::fs::read_dir(&dir)
        .map_err(|e| format!("cannot list {}: {e}", dir.display()))?
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x.eq_ignore_ascii_case("png")))
        .filter_map(|p| Some((p.file_stem()?.to_string_lossy().into_owned(), p)))
        .collect();
    all.sort();
    let textures = match list_env("QUALITY_TEXTURES") {
        None => all,
        Some(wanted) => {
            let mut picked = Vec::new();
            for w in wanted {
                let found = all.iter().find(|(n, _)| *n == w).ok_or_else(|| {
                    let names: Vec<&str> = all.iter().map(|(n, _)| n.as_str()).collect();
                    format!(
                        "QUALITY_TEXTURES: no texture {w:?}; allowed: {}",
                        names.join(", ")
                    )
                })?;
                picked.push(found.clone());
            }
            picked
        }
    };
    let allowed: Vec<&str> = std::iter::once(PEER).chain(METHODS).collect();
    let methods = match list_env("QUALITY_METHODS") {
        None => allowed.iter().map(|s| s.to_string()).collect(),
        Some(m) => {
            if let Some(bad) = m.iter().find(|m| !allowed.contains(&m.as_str())) {
                return Err(format!(
                    "QUALITY_METHODS: no method {bad:?}; allowed: {}",
                    allowed.join(", ")
                ));
            }
            m
        }
    };
    let size = match std::env::var("QUALITY_SIZE") {
        Err(_) => 256,
        Ok(s) => s
            .trim()
            .parse::<u32>()
            .ok()
            .filter(|&n| (16..=4096).contains(&n))
            .ok_or_else(|| format!("QUALITY_SIZE={s:?}; allowed: an integer in 16..=4096"))?,
    };
    let threads = match list_env("QUALITY_THREADS") {
        None => vec![Threads::One, Threads::All],
        Some(t) => t
            .iter()
            .map(|t| match t.as_str() {
                "1" => Ok(Threads::One),
                "all" => Ok(Threads::All),
                other => Err(format!("QUALITY_THREADS: {other:?}; allowed: 1, all")),
            })
            .collect::<Result<_, _>>()?,
    };
    Ok(Knobs {
        textures,
        methods,
        size,
        threads,
    })
}

/// One run's result.
struct Outcome {
    image: Image,
    sources: Option<SourceMap>,
    wall: f64,
    cpu: Option<f64>,
}

/// The process's user + system CPU seconds (Linux: `/proc/self/stat` fields
/// 14 and 15, in USER_HZ = 100 ticks per second).
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // The command name (field 2) may contain spaces; fields after it are plain.
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split(' ').collect();
    let utime: f64 = fields.get(11)?.parse().ok()?;
    let stime: f64 = fields.get(12)?.parse().ok()?;
    Some((utime + stime) / 100.0)
}

/// Runs `f`, timing wall and CPU seconds; a panic becomes an error.
fn timed<T>(f: impl FnOnce() -> Result<T, String>) -> Result<(T, f64, Option<f64>), String> {
    let cpu0 = cpu_seconds();
    let t0 = Instant::now();
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|p| {
        let msg = p
            .downcast_ref::<String>()
            .cloned()
            .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
            .unwrap_or_else(|| "unknown panic".into());
        Err(format!("panicked: {msg}"))
    });
    let wall = t0.elapsed().as_secs_f64();
    let cpu = cpu0.zip(cpu_seconds()).map(|(a, b)| b - a);
    r.map(|v| (v, wall, cpu))
}

fn run_peer(exemplar: &Image, size: u32, threads: Threads) -> Result<Outcome, String> {
    let (r, _, cpu) = timed(|| {
        peer::try_peer_synthesis(exemplar, size, size, SEED, threads.count())
            .map_err(|e| format!("Embark's texture-synthesis: {e}"))
    })?;
    Ok(Outcome {
        wall: r.seconds,
        cpu,
        image: r.image,
        sources: Some(r.sources),
    })
}

/// `--set` overrides for a `size` × `size` result: every stage's
/// `plane_size` and `width`/`height` pair; a plane mesh's
/// `input.mesh_options.size` (world units, one exemplar pixel per unit:
/// `size - 1` when the image spans the mesh's box, `size × plane_pixel`
/// when pixels are `plane_pixel` units apart from its corner, as on
/// Bangay–Morkel's grid one vertex wider than the image) and, where the
/// mesh has one vertex per output pixel (its resolution equals the plane
/// size), its resolution. Nothing else is scaled
/// (e.g. coarse base meshes, patch sizes), so sizes other than the configs'
/// 256 are only exact for the image-space and per-pixel methods.
fn size_overrides(config_text: &str, size: u32) -> Vec<String> {
    let Ok(table) = config_text.parse::<toml::Table>() else {
        return Vec::new();
    };
    let mut out = Vec::new();
    let mut plane_size = None;
    let mut plane_pixel = None;
    let stages = table.get("stage").and_then(|s| s.as_array());
    for (i, stage) in stages.into_iter().flatten().enumerate() {
        if let Some(p) = stage.get("plane_pixel").and_then(|p| p.as_float())
            && p > 0.0
        {
            plane_pixel = Some(p);
        }
        if let Some(p) = stage.get("plane_size") {
            plane_size = Some(p.clone());
            out.push(format!("stage.{}.plane_size=[{size}, {size}]", i + 1));
        }
        if stage.get("width").is_some() && stage.get("height").is_some() {
            out.push(format!("stage.{}.width={size}", i + 1));
            out.push(format!("stage.{}.height={size}", i + 1));
        }
    }
    let options = table
        .get("input")
        .and_then(|i| i.get("mesh_options"))
        .and_then(|o| o.as_table());
    if let Some(options) = options {
        if options.contains_key("size") {
            match plane_pixel {
                Some(p) => out.push(format!("input.mesh_options.size={:?}", size as f64 * p)),
                None => out.push(format!("input.mesh_options.size={}.0", size - 1)),
            }
        }
        if let (Some(r), Some(p)) = (options.get("resolution"), &plane_size)
            && r.as_array()
                .map(|a| a.iter().map(|v| v.as_integer()).collect::<Vec<_>>())
                == p.as_array()
                    .map(|a| a.iter().map(|v| v.as_integer()).collect())
        {
            out.push(format!("input.mesh_options.resolution=[{size}, {size}]"));
        }
    }
    out
}

/// The config of a method and the overrides it needs besides the exemplar,
/// the output folder and the size.
fn method_config(manifest: &Path, method: &str) -> Result<(PathBuf, Vec<String>), String> {
    let plane = manifest.join(format!("configs/plane/{method}.toml"));
    if plane.is_file() {
        return Ok((plane, Vec::new()));
    }
    Err(format!(
        "configs/plane/{method}.toml does not exist (yet) on this branch"
    ))
}

fn run_method(
    manifest: &Path,
    method: &str,
    exemplar_path: &Path,
    out_dir: &Path,
    size: u32,
    threads: Threads,
    cache_dir: &Path,
) -> Result<Outcome, String> {
    let (config, extra) = method_config(manifest, method)?;
    let mut source = ConfigSource::from_file(&config).map_err(|e| e.to_string())?;
    let mut overrides = vec![
        format!("input.exemplar={}", exemplar_path.display()),
        format!("output.dir={}", out_dir.display()),
    ];
    overrides.extend(extra);
    overrides.extend(size_overrides(&source.text, size));
    source
        .apply_overrides(&overrides)
        .map_err(|e| e.to_string())?;
    let pipeline = Pipeline::from_source(source).map_err(|e| e.to_string())?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.count())
        .build()
        .map_err(|e| format!("thread pool: {e}"))?;
    // An empty jump-map cache: every run pays for its analysis.
    let _ = std::fs::remove_dir_all(cache_dir);
    let _ = std::fs::remove_dir_all(out_dir);
    let options = RunOptions {
        out_dir: Some(out_dir.to_path_buf()),
    };
    let ((), wall, cpu) = timed(|| {
        pool.install(|| surfsynth::pipeline::run(&pipeline, &options))
            .map(|_| ())
            .map_err(|e| e.to_string())
    })?;
    let image_path = out_dir.join("plane.png");
    let image = load_image(&image_path).map_err(|e| e.to_string())?;
    if (image.width, image.height) != (size, size) {
        return Err(format!(
            "plane.png is {}x{}, {size}x{size} was asked for",
            image.width, image.height
        ));
    }
    let image = rgb(image);
    let sources = read_sources(&out_dir.join("plane_sources.png"), size)?;
    Ok(Outcome {
        image,
        sources,
        wall,
        cpu,
    })
}

/// The first three channels (grey replicated), as the exemplar has.
fn rgb(img: Image) -> Image {
    if img.channels == 3 {
        return img;
    }
    let c = img.channels.max(1) as usize;
    let data = img
        .data
        .chunks_exact(c)
        .flat_map(|p| if c < 3 { [p[0]; 3] } else { [p[0], p[1], p[2]] })
        .collect();
    Image::from_data(img.width, img.height, 3, data).unwrap_or_default()
}

/// Reads `plane_sources.png` (16-bit RGB: R = exemplar x index, G = y,
/// B = 65535 where known); `None` when the method writes none or an 8-bit
/// one (a visualisation, not coordinates).
fn read_sources(path: &Path, size: u32) -> Result<Option<SourceMap>, String> {
    if !path.is_file() {
        return Ok(None);
    }
    let img = image::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    if !matches!(
        img.color(),
        image::ColorType::Rgb16 | image::ColorType::Rgba16
    ) {
        return Ok(None);
    }
    let img = img.into_rgb16();
    if (img.width(), img.height()) != (size, size) {
        return Err(format!(
            "{} is {}x{}, not {size}x{size}",
            path.display(),
            img.width(),
            img.height()
        ));
    }
    Ok(Some(gates::source_map(&img)))
}

/// One thread setting's wall and CPU seconds, or why it failed.
type Timing = Result<(f64, Option<f64>), String>;

/// One texture × method row.
struct Row {
    texture: String,
    method: String,
    quality: Result<ImageQuality, String>,
    /// Per thread setting: the wall and CPU seconds, or the error.
    times: Vec<(Threads, Timing)>,
    /// Whether every thread setting gave the same image (None: fewer than two results).
    identical: Option<bool>,
}

fn fmt_metric(v: f32) -> String {
    if v.is_nan() {
        "–".into()
    } else if v.abs() >= 100.0 || v == v.trunc() {
        format!("{v:.0}")
    } else {
        format!("{v:.4}")
    }
}

fn fmt_time(t: &Timing) -> (String, String) {
    match t {
        Ok((wall, cpu)) => (
            format!("{wall:.2}"),
            cpu.map_or(String::new(), |c| format!("{c:.2}")),
        ),
        Err(_) => ("failed".into(), String::new()),
    }
}

fn markdown(rows: &[Row], knobs: &Knobs) -> String {
    let mut md = String::new();
    let _ = writeln!(
        md,
        "# Quality benchmark\n\n{s}×{s} output from each exemplar, seed {SEED}; peer = Embark's \
         texture-synthesis 0.8.2 with its defaults. Metrics from the first thread setting's \
         result ({}). Wall and CPU seconds per thread setting; `same` = identical images \
         across thread settings. `–`: not applicable (no source coordinates).\n",
        knobs.threads[0].label(),
        s = knobs.size
    );
    let mut head = vec!["texture".to_string(), "method".to_string()];
    head.extend(METRICS.iter().map(|m| m.to_string()));
    for t in &knobs.threads {
        head.push(format!("s {}", t.label()));
        head.push(format!("cpu s {}", t.label()));
    }
    head.push("same".into());
    table_header(&mut md, &head);
    let mut errors = Vec::new();
    for r in rows {
        let mut cells = vec![r.texture.clone(), r.method.clone()];
        match &r.quality {
            Ok(q) => cells.extend(metric_values(q).map(fmt_metric)),
            Err(e) => {
                cells.extend(METRICS.map(|_| "failed".to_string()));
                errors.push(format!("- {} / {}: {e}", r.texture, r.method));
            }
        }
        for (t, time) in &r.times {
            let (w, c) = fmt_time(time);
            cells.push(w);
            cells.push(c);
            if let Err(e) = time
                && r.quality.as_ref().err() != Some(e)
            {
                errors.push(format!(
                    "- {} / {} ({}): {e}",
                    r.texture,
                    r.method,
                    t.label()
                ));
            }
        }
        cells.push(match r.identical {
            Some(true) => "yes".into(),
            Some(false) => "no".into(),
            None => String::new(),
        });
        let _ = writeln!(md, "| {} |", cells.join(" | "));
    }
    let _ = writeln!(
        md,
        "\n## Ratio to the peer\n\nEach metric over the peer's on the same texture \
         (coherence, completeness, structure, histogram: lower is better; sharpness: \
         1 = as sharp as the peer; coverage: higher is better).\n"
    );
    let mut head = vec!["texture".to_string(), "method".to_string()];
    head.extend(METRICS.iter().map(|m| m.to_string()));
    table_header(&mut md, &head);
    for r in rows.iter().filter(|r| r.method != PEER) {
        let mut cells = vec![r.texture.clone(), r.method.clone()];
        cells.extend(
            ratios(r, rows).map_or_else(|| METRICS.map(|_| "–".to_string()), |v| v.map(fmt_ratio)),
        );
        let _ = writeln!(md, "| {} |", cells.join(" | "));
    }
    if !errors.is_empty() {
        let _ = writeln!(md, "\n## Errors\n\n{}", errors.join("\n"));
    }
    md
}

fn table_header(md: &mut String, head: &[String]) {
    let _ = writeln!(md, "| {} |", head.join(" | "));
    let _ = writeln!(md, "|{}", "---|".repeat(head.len()));
}

fn fmt_ratio(v: f32) -> String {
    if v.is_finite() {
        format!("{v:.2}")
    } else {
        "–".into()
    }
}

/// A row's metrics over the peer's on the same texture, when both exist.
fn ratios(r: &Row, rows: &[Row]) -> Option<[f32; 11]> {
    let q = r.quality.as_ref().ok()?;
    let peer = rows
        .iter()
        .find(|p| p.texture == r.texture && p.method == PEER)?
        .quality
        .as_ref()
        .ok()?;
    let (a, b) = (metric_values(q), metric_values(peer));
    Some(std::array::from_fn(|i| a[i] / b[i]))
}

fn csv(rows: &[Row], knobs: &Knobs) -> String {
    let mut head = vec!["texture".to_string(), "method".to_string()];
    head.extend(METRICS.iter().map(|m| m.to_string()));
    head.extend(METRICS.iter().map(|m| format!("{m}_vs_peer")));
    for t in &knobs.threads {
        let key = match t {
            Threads::One => "1".to_string(),
            Threads::All => "all".to_string(),
        };
        head.push(format!("seconds_{key}"));
        head.push(format!("cpu_seconds_{key}"));
    }
    head.push("identical_across_threads".into());
    head.push("error".into());
    let mut out = head.join(",") + "\n";
    let num = |v: f32| {
        if v.is_finite() {
            v.to_string()
        } else {
            String::new()
        }
    };
    for r in rows {
        let mut cells = vec![r.texture.clone(), r.method.clone()];
        match &r.quality {
            Ok(q) => cells.extend(metric_values(q).map(num)),
            Err(_) => cells.extend(METRICS.map(|_| String::new())),
        }
        match ratios(r, rows) {
            Some(v) if r.method != PEER => cells.extend(v.map(num)),
            _ => cells.extend(METRICS.map(|_| String::new())),
        }
        let mut errors = Vec::new();
        if let Err(e) = &r.quality {
            errors.push(e.clone());
        }
        for (_, t) in &r.times {
            match t {
                Ok((wall, cpu)) => {
                    cells.push(format!("{wall:.4}"));
                    cells.push(cpu.map_or(String::new(), |c| format!("{c:.2}")));
                }
                Err(e) => {
                    cells.push(String::new());
                    cells.push(String::new());
                    if !errors.contains(e) {
                        errors.push(e.clone());
                    }
                }
            }
        }
        cells.push(r.identical.map_or(String::new(), |b| b.to_string()));
        cells.push(format!("\"{}\"", errors.join("; ").replace('"', "'")));
        out += &cells.join(",");
        out.push('\n');
    }
    out
}

/// The exemplar centred on a `size`² tile of the sheet's background, so it
/// shows at the scale of the results (one exemplar pixel per output pixel)
/// rather than magnified to the tiles' height; a larger exemplar is left
/// as it is (the sheet scales it).
fn at_true_scale(exemplar: &Image, size: u32) -> Image {
    if exemplar.width > size || exemplar.height > size {
        return exemplar.clone();
    }
    let mut tile = Image::new(size, size, 3);
    for px in tile.data.chunks_exact_mut(3) {
        px.copy_from_slice(&SheetLayout::default().background);
    }
    let (x0, y0) = ((size - exemplar.width) / 2, (size - exemplar.height) / 2);
    for y in 0..exemplar.height {
        for x in 0..exemplar.width {
            tile.pixel_mut(x0 + x, y0 + y)
                .copy_from_slice(exemplar.pixel(x, y));
        }
    }
    tile
}

/// A grey placeholder tile for a method without a result.
fn placeholder(size: u32) -> Image {
    let mut img = Image::new(size, size, 3);
    img.data.fill(0.3);
    img
}

fn main() {
    // `cargo bench` passes `--bench`; a filter argument is not supported.
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let knobs = match knobs(manifest) {
        Ok(k) => k,
        Err(e) => {
            eprintln!("quality: {e}");
            std::process::exit(2);
        }
    };
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest.join("target"));
    let out = target.join("quality");
    let cache_dir = out.join("jump-map-cache");
    // SAFETY: set before any other thread exists (no pool has been built yet);
    // the pipeline reads it to find the jump-map cache.
    unsafe { std::env::set_var("SURFSYNTH_CACHE", &cache_dir) };
    surfsynth::progress::set_enabled(false);
    eprintln!(
        "quality: {} texture(s) × {} method(s) at {s}×{s}, threads {:?} → {}",
        knobs.textures.len(),
        knobs.methods.len(),
        knobs.threads.iter().map(|t| t.label()).collect::<Vec<_>>(),
        out.display(),
        s = knobs.size
    );
    // The gates' measure: every window of a 256² result.
    let settings = gates::gate_settings();
    let mut rows = Vec::new();
    for (texture, path) in &knobs.textures {
        let exemplar = match load_image(path) {
            Ok(img) => rgb(img),
            Err(e) => {
                eprintln!("quality: {texture}: {e}");
                continue;
            }
        };
        let exemplar_path = path.canonicalize().unwrap_or_else(|_| path.clone());
        let mut sheet: Vec<(String, Image)> = vec![(
            "exemplar (1:1)".into(),
            at_true_scale(&exemplar, knobs.size),
        )];
        for method in &knobs.methods {
            let mut first: Option<Outcome> = None;
            let mut times = Vec::new();
            let mut identical = None;
            for &t in &knobs.threads {
                eprintln!("quality: {texture} / {method} / {} ...", t.label());
                let result = if method == PEER {
                    run_peer(&exemplar, knobs.size, t)
                } else {
                    let run_dir = out.join("runs").join(texture).join(method);
                    run_method(
                        manifest,
                        method,
                        &exemplar_path,
                        &run_dir,
                        knobs.size,
                        t,
                        &cache_dir,
                    )
                };
                match result {
                    Ok(o) => {
                        eprintln!(
                            "quality: {texture} / {method} / {}: {:.2} s wall{}",
                            t.label(),
                            o.wall,
                            o.cpu.map_or(String::new(), |c| format!(", {c:.2} s CPU"))
                        );
                        times.push((t, Ok((o.wall, o.cpu))));
                        match &first {
                            None => first = Some(o),
                            Some(f) => {
                                identical = Some(identical.unwrap_or(true) && f.image == o.image)
                            }
                        }
                    }
                    Err(e) => {
                        eprintln!("quality: {texture} / {method} / {}: FAILED: {e}", t.label());
                        times.push((t, Err(e)));
                    }
                }
            }
            let quality = match &first {
                Some(o) => {
                    let q = image_quality(&o.image, &exemplar, o.sources.as_ref(), &settings);
                    eprintln!(
                        "quality: {texture} / {method}: coherence {:.4}, completeness {:.4}, sharpness {:.3}, structure {:.3}",
                        q.coherence_mean, q.completeness, q.sharpness, q.structure
                    );
                    Ok(q)
                }
                None => Err(times
                    .iter()
                    .find_map(|(_, t)| t.as_ref().err().cloned())
                    .unwrap_or_else(|| "no thread setting ran".into())),
            };
            let label = if method == PEER {
                "peer (Embark 0.8.2)".to_string()
            } else {
                method.clone()
            };
            let second = match (&first, times.first()) {
                (Some(_), Some((t, Ok((wall, _))))) => format!("{wall:.1} s, {}", t.label()),
                _ => "FAILED (see quality.md)".into(),
            };
            sheet.push((
                format!("{label}\n{second}"),
                first.map_or_else(|| placeholder(knobs.size), |o| o.image),
            ));
            rows.push(Row {
                texture: texture.clone(),
                method: method.clone(),
                quality,
                times,
                identical,
            });
        }
        let tiles: Vec<SheetTile<'_>> = sheet
            .iter()
            .map(|(label, image)| SheetTile { image, label })
            .collect();
        let sheet_image = contact_sheet(
            &tiles,
            &SheetLayout {
                tile_height: Some(knobs.size),
                ..SheetLayout::default()
            },
        )
        .image;
        let sheet_path = out.join(format!("sheet_{texture}.png"));
        match write_png(&sheet_path, &sheet_image) {
            Ok(()) => eprintln!("quality: wrote {}", sheet_path.display()),
            Err(e) => eprintln!("quality: {e}"),
        }
    }
    let _ = std::fs::remove_dir_all(&cache_dir);
    for (name, text) in [
        ("quality.md", markdown(&rows, &knobs)),
        ("quality.csv", csv(&rows, &knobs)),
    ] {
        let path = out.join(name);
        match write_bytes_atomic(&path, text.as_bytes()) {
            Ok(()) => eprintln!("quality: wrote {}", path.display()),
            Err(e) => eprintln!("quality: {e}"),
        }
    }
}
