//! The memory estimates against the allocation measured (issue 43): a
//! counting global allocator tracks the bytes live and their peak; a
//! tracing layer resets the peak when a stage's span is entered and reads
//! it when it is left, so each stage's peak is the most it held beyond
//! what was live when it started. Runs in-process, one at a time.

mod common;

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use tracing::span::Id;
use tracing::subscriber::Subscriber;
use tracing_subscriber::layer::{Context, Layer, SubscriberExt};
use tracing_subscriber::registry::LookupSpan;

/// [`System`] with the bytes live and their peak counted.
struct Counting;

static CURRENT: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

impl Counting {
    fn add(bytes: usize) {
        let now = CURRENT.fetch_add(bytes, Ordering::Relaxed) + bytes;
        PEAK.fetch_max(now, Ordering::Relaxed);
    }
    fn sub(bytes: usize) {
        CURRENT.fetch_sub(bytes, Ordering::Relaxed);
    }
}

// SAFETY: every call is forwarded to `System` with the same arguments; the
// counters only observe.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            Self::add(layout.size());
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            Self::add(layout.size());
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        Self::sub(layout.size());
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            // Old and new blocks may both be live while the bytes move.
            Self::add(new_size);
            Self::sub(layout.size());
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// One measurement at a time: the counters are the process's.
static SERIAL: Mutex<()> = Mutex::new(());

/// Per stage, in order: the peak bytes beyond those live at its start.
#[derive(Clone, Default)]
struct StagePeaks {
    peaks: Arc<Mutex<Vec<usize>>>,
    start: Arc<AtomicUsize>,
}

impl<S: Subscriber + for<'a> LookupSpan<'a>> Layer<S> for StagePeaks {
    fn on_enter(&self, id: &Id, ctx: Context<'_, S>) {
        if ctx.span(id).is_some_and(|s| measured_span(s.name())) {
            let now = CURRENT.load(Ordering::SeqCst);
            self.start.store(now, Ordering::SeqCst);
            PEAK.store(now, Ordering::SeqCst);
        }
    }
    fn on_exit(&self, id: &Id, ctx: Context<'_, S>) {
        if ctx.span(id).is_some_and(|s| measured_span(s.name())) {
            let peak = PEAK.load(Ordering::SeqCst);
            let start = self.start.load(Ordering::SeqCst);
            self.peaks.lock().unwrap().push(peak.saturating_sub(start));
        }
    }
}

/// The spans whose peaks are measured: every stage's, then the result
/// metrics' (last).
fn measured_span(name: &str) -> bool {
    name == surfsynth::telemetry::STAGE_SPAN || name == "result_metrics"
}

/// Runs `config` in-process and returns each stage's measured peak, then
/// the result metrics'.
fn measure(config: &str) -> Vec<usize> {
    let layer = StagePeaks::default();
    let subscriber = tracing_subscriber::registry().with(layer.clone());
    tracing::subscriber::with_default(subscriber, || {
        common::world_for(config).unwrap_or_else(|e| panic!("{e}\n{config}"));
    });
    layer.peaks.lock().unwrap().clone()
}

/// Each stage's largest estimate for `config`'s loaded input.
fn estimates(config: &str) -> Vec<u64> {
    use surfsynth::pipeline::{Pipeline, load_input};
    use surfsynth::stage::memory::InputSizes;
    let p = Pipeline::from_source(surfsynth::config::ConfigSource::from_text("t.toml", config))
        .unwrap_or_else(|e| panic!("{e}"));
    let input = load_input(&p.input, &p.source.base_dir, &p.source.file).unwrap();
    let sizes = InputSizes::of(&input, &p.input);
    let seen = surfsynth::pipeline::memory_budget::stage_sizes(&p.stages, &sizes);
    p.stages
        .iter()
        .zip(&seen)
        .map(|(s, sizes)| {
            s.memory_estimate(sizes)
                .iter()
                .map(|e| e.bytes)
                .max()
                .unwrap_or(0)
        })
        .collect()
}

fn mib(bytes: u64) -> f64 {
    bytes as f64 / (1 << 20) as f64
}

/// Runs `config` at each size (`{}` in it replaced) and checks the
/// estimate of stage `stage` (0-based) within [0.5, 2] of its measured
/// peak; returns the table rows.
fn check(label: &str, stage: usize, config: &str, sizes: &[&str]) -> Vec<String> {
    check_each(&[(stage, label)], config, sizes)
}

/// [`check`] for several stages of one pipeline (`(stage, label)`), each
/// size run once.
fn check_each(stages: &[(usize, &str)], config: &str, sizes: &[&str]) -> Vec<String> {
    let mut rows = Vec::new();
    let mut bad = Vec::new();
    for size in sizes {
        let text = config.replace("{}", size);
        let estimates = estimates(&text);
        let measured = measure(&text);
        for &(stage, label) in stages {
            let (row, within) = compare(label, size, estimates[stage], measured[stage] as u64);
            if !within {
                bad.push(row.clone());
            }
            rows.push(row);
        }
    }
    assert!(
        bad.is_empty(),
        "estimates off by more than 2x:\n{}",
        bad.join("\n")
    );
    rows
}

/// The table row of an estimate against its measured peak, and whether
/// their ratio is within [0.5, 2].
fn compare(label: &str, size: &str, estimate: u64, measured: u64) -> (String, bool) {
    let ratio = estimate as f64 / measured.max(1) as f64;
    let row = format!(
        "| {label} | {size} | {:.1} MiB | {:.1} MiB | {ratio:.2} |",
        mib(estimate),
        mib(measured)
    );
    eprintln!("{row}");
    (row, (0.5..=2.0).contains(&ratio))
}

/// One-time allocations (the thread pool, lazily built tables) happen in
/// the first run of the process: a small run first keeps them out of the
/// measurements.
fn warm_up() {
    measure(&JUMP_MAP.replace("{}", "64"));
}

const JUMP_MAP: &str = r#"
seed = 1
[input]
exemplar = "builtin:noise"
[input.exemplar_options]
size = {}
[[stage]]
kind = "jump_map"
cache = false
"#;

const JUMP_IMAGE: &str = r#"
seed = 1
[input]
exemplar = "builtin:noise"
[[stage]]
kind = "jump_map"
cache = false
[[stage]]
kind = "jump_image"
width = {}
height = {}
"#;

const BAKE: &str = r#"
seed = 3
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.mesh_options]
subdivisions = 2
[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]
[[stage]]
kind = "jump_map"
cache = false
[[stage]]
kind = "jump_surface"
[[stage]]
kind = "bake"
size = {}
"#;

const LAPPED: &str = r#"
seed = 4
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:noise"
[input.mesh_options]
subdivisions = 2
[[stage]]
kind = "tangent_field"
[[stage]]
kind = "lapped_paste"
cache = false
atlas_size = {}
"#;

const RETILE: &str = r#"
seed = 5
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:noise"
[input.mesh_options]
subdivisions = 2
[[stage]]
kind = "retile"
vertices = {}
"#;

const SUBDIVIDE: &str = r#"
seed = 5
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:noise"
[input.mesh_options]
subdivisions = 1
[[stage]]
kind = "subdivide_sqrt2"
target_vertices = {}
"#;

const EXPORT: &str = r#"
seed = 3
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.mesh_options]
subdivisions = 2
[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]
[[stage]]
kind = "jump_map"
cache = false
[[stage]]
kind = "jump_surface"
[[stage]]
kind = "export"
FORMAT
"#;

#[test]
fn each_stage_estimate_is_within_2x_of_its_measured_peak_at_three_sizes() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    warm_up();
    let mut rows = vec![
        "| stage | size | estimate | measured peak | ratio |".to_string(),
        "|---|---|---|---|---|".to_string(),
    ];
    rows.extend(check(
        "jump_map (analysis)",
        0,
        JUMP_MAP,
        &["64", "128", "256"],
    ));
    // Wide neighbourhoods and the whole sample: the PCA's SVD dominates.
    let wide = JUMP_MAP.replace(
        "cache = false",
        "cache = false\nneighbourhoods = [15, 7]\npca_sample = 1.0",
    );
    rows.extend(check(
        "jump_map [15, 7], pca_sample 1",
        0,
        &wide,
        &["96", "128", "192"],
    ));
    // The kd-tree search over 8 components.
    let tree = JUMP_MAP.replace(
        "cache = false",
        "cache = false\nmax_components = 8\nann_search = \"kd_tree\"",
    );
    rows.extend(check("jump_map kd-tree", 0, &tree, &["128", "256", "384"]));
    rows.extend(check("jump_image", 1, JUMP_IMAGE, &["256", "512", "1024"]));
    rows.extend(check("bake", 3, BAKE, &["512", "1024", "2048"]));
    rows.extend(check(
        "lapped_paste atlas_size",
        1,
        LAPPED,
        &["1024", "2048", "4096"],
    ));
    rows.extend(check(
        "retile vertices",
        0,
        RETILE,
        &["4000", "16000", "64000"],
    ));
    rows.extend(check(
        "subdivide_sqrt2 target_vertices",
        0,
        SUBDIVIDE,
        &["10000", "40000", "160000"],
    ));
    let baked = EXPORT.replace("FORMAT", "formats = [\"baked\"]\nbake_size = {}");
    rows.extend(check(
        "export bake_size",
        3,
        &baked,
        &["512", "1024", "2048"],
    ));
    let preview = EXPORT.replace("FORMAT", "formats = [\"preview\"]\npreview_size = {}");
    rows.extend(check(
        "export preview_size",
        3,
        &preview,
        &["256", "512", "1024"],
    ));
    eprintln!("{}", rows.join("\n"));
}

#[test]
fn plane_size_estimate_is_within_2x_of_its_measured_peak_at_three_sizes() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    warm_up();
    let plane = r#"
seed = 3
[input]
mesh = "builtin:plane"
exemplar = "builtin:bricks"
[input.mesh_options]
resolution = [64, 64]
[[stage]]
kind = "orientation"
[[stage]]
kind = "init_colours"
[[stage]]
kind = "export"
formats = ["plane"]
plane_size = [{}, {}]
"#;
    check("export plane_size", 2, plane, &["256", "512", "1024"]);
}

/// The per-vertex stages of every method: orientation fields, Wei–Levoy's
/// match and map-back, the coherent synthesis, Bangay–Morkel's
/// `graph_match`, jump_surface, displace, lapped's tangent field, each at
/// three mesh sizes; the stages that hold the exemplar's analysis also at
/// three exemplar sizes.
#[test]
fn per_vertex_stage_estimates_are_within_2x_of_their_measured_peaks() {
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    warm_up();
    let mut rows = vec![
        "| stage | size | estimate | measured peak | ratio |".to_string(),
        "|---|---|---|---|---|".to_string(),
    ];
    let mesh = |config: &str| config.replace("{E}", "64");
    let exemplar =
        |config: &str, vertices: &str| config.replace("{}", vertices).replace("{E}", "{}");
    rows.extend(check_each(
        &[
            (0, "orientation (icosphere subdivisions)"),
            (2, "jump_surface"),
            (3, "displace"),
        ],
        &mesh(JUMP_SURFACE),
        &["4", "5", "6"],
    ));
    rows.extend(check_each(
        &[
            (1, "relax_orientation (pyramid subdivisions)"),
            (2, "init_colours"),
            (3, "match pca_kdtree"),
            (4, "map_back"),
        ],
        &mesh(WEI_LEVOY),
        &["4", "5", "6"],
    ));
    rows.extend(check_each(
        &[(2, "init_colours (exemplar side)"), (3, "match pca_kdtree")],
        &exemplar(WEI_LEVOY, "4"),
        &["64", "128", "256"],
    ));
    let field = JUMP_SURFACE.replace(
        "mode = \"global\"",
        "mode = \"field\"\nanchors = [{ at_bbox = [0.5, 0.5, 1.0], up = [1.0, 0.0, 0.0] }]",
    );
    rows.extend(check(
        "orientation field (icosphere subdivisions)",
        0,
        &mesh(&field),
        &["4", "5", "6"],
    ));
    let exhaustive = WEI_LEVOY.replace("pca_kdtree", "exhaustive");
    rows.extend(check(
        "match exhaustive (exemplar side)",
        3,
        &exemplar(&exhaustive, "4"),
        &["64", "128", "256"],
    ));
    let tsvq = WEI_LEVOY.replace("pca_kdtree", "tsvq");
    rows.extend(check(
        "match tsvq (exemplar side)",
        3,
        &exemplar(&tsvq, "4"),
        &["64", "128", "256"],
    ));
    rows.extend(check(
        "coherent (retile vertices)",
        2,
        &mesh(COHERENT),
        &["4000", "16000", "64000"],
    ));
    rows.extend(check(
        "coherent (exemplar side)",
        2,
        &exemplar(COHERENT, "4000"),
        &["64", "128", "256"],
    ));
    rows.extend(check_each(
        &[
            (1, "diffuse_orientation (target_vertices)"),
            (2, "graph_match"),
        ],
        &mesh(BANGAY_MORKEL),
        &["2000", "8000", "32000"],
    ));
    rows.extend(check(
        "graph_match (exemplar side)",
        2,
        &exemplar(BANGAY_MORKEL, "2000"),
        &["64", "128", "256"],
    ));
    for mode in ["constraints", "global"] {
        let config = mesh(TANGENT_FIELD).replace("constraints\"", &format!("{mode}\""));
        let label = format!("tangent_field {mode} (icosphere subdivisions)");
        rows.extend(check(&label, 0, &config, &["4", "5", "6"]));
    }
    eprintln!("{}", rows.join("\n"));
}

const JUMP_SURFACE: &str = r#"
seed = 3
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
height_map = "derive:luminance"
[input.exemplar_options]
size = {E}
[input.mesh_options]
subdivisions = {}
[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]
[[stage]]
kind = "jump_map"
cache = false
[[stage]]
kind = "jump_surface"
[[stage]]
kind = "displace"
amplitude = 1.0
smoothing = 2
"#;

const WEI_LEVOY: &str = r#"
seed = 3
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.exemplar_options]
size = {E}
[[stage]]
kind = "builtin_pyramid"
mesh = "icosphere"
levels = 4
subdivisions = {}
[[stage]]
kind = "relax_orientation"
mode = "relax"
symmetry = 4
iterations = 30
[[stage]]
kind = "init_colours"
[[stage]]
kind = "match"
search = "pca_kdtree"
[[stage]]
kind = "map_back"
"#;

const COHERENT: &str = r#"
seed = 3
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.exemplar_options]
size = {E}
[input.mesh_options]
subdivisions = 2
[[stage]]
kind = "retile"
levels = 4
vertices = {}
[[stage]]
kind = "orientation"
mode = "global"
up = [0.0, 1.0, 0.0]
[[stage]]
kind = "coherent"
cache = false
"#;

const BANGAY_MORKEL: &str = r#"
seed = 3
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.exemplar_options]
size = {E}
[input.mesh_options]
subdivisions = 1
[[stage]]
kind = "subdivide_sqrt2"
target_vertices = {}
[[stage]]
kind = "diffuse_orientation"
keys = [{ at_bbox = [0.5, 0.5, 1.0], up = [0.0, 1.0, 0.0] }]
[[stage]]
kind = "graph_match"
graph_cut = true
"#;

const TANGENT_FIELD: &str = r#"
seed = 3
[input]
mesh = "builtin:icosphere"
exemplar = "builtin:bricks"
[input.mesh_options]
subdivisions = {}
[[stage]]
kind = "tangent_field"
mode = "constraints"
up = [0.0, 1.0, 0.0]
units = "diagonal"
constraints = [{ at_bbox = [0.5, 0.5, 1.0], up = [1.0, 0.0, 0.0], radius = 0.3 }]
"#;

/// The result metrics' estimate (`output.metric_samples`) against their
/// measured peak, on a displaced jump_surface result (templates, surface energy,
/// completeness against the templates), at three sample counts and three
/// mesh sizes.
#[test]
fn result_metrics_estimate_is_within_2x_of_its_measured_peak() {
    use surfsynth::pipeline::Pipeline;
    use surfsynth::pipeline::memory_budget::{metrics_estimate, stage_sizes};
    use surfsynth::stage::memory::InputSizes;
    let _one = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    warm_up();
    let mut bad = Vec::new();
    for (subdivisions, samples) in [(5, 1000), (5, 10000), (5, 50000), (4, 2000), (6, 2000)] {
        let text = format!(
            "{}\n[output]\nmetric_samples = {samples}\n",
            JUMP_SURFACE
                .replace("{}", &subdivisions.to_string())
                .replace("{E}", "128")
        );
        let p = Pipeline::from_source(surfsynth::config::ConfigSource::from_text("t.toml", &text))
            .unwrap_or_else(|e| panic!("{e}"));
        let input =
            surfsynth::pipeline::load_input(&p.input, &p.source.base_dir, &p.source.file).unwrap();
        let sizes = InputSizes::of(&input, &p.input);
        let seen = stage_sizes(&p.stages, &sizes);
        let last = p.stages.last().unwrap().sizes_after(seen.last().unwrap());
        let estimate = metrics_estimate(&p.output, &last).bytes;
        let measured = *measure(&text).last().unwrap() as u64;
        let size = format!("subdivisions {subdivisions}, {samples} samples");
        let (row, within) = compare("result metrics", &size, estimate, measured);
        if !within {
            bad.push(row);
        }
    }
    assert!(
        bad.is_empty(),
        "estimates off by more than 2x:\n{}",
        bad.join("\n")
    );
}
