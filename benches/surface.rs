//! The surface benchmark (issue 40): every method of `configs/surface/` on
//! the shared meshes with one exemplar, each result baked into a 2048² atlas
//! of the original mesh at the same texture scale, against the artist's
//! alternative: `triplanar` fed with Embark's tileable synthesis of the same
//! exemplar (`texture-synthesis` 0.8 in tiling mode, 256² from the 128²
//! photo, seed 1). The quality is what each `result.glb` shows, measured by
//! the run itself (`result.quality` of `metrics.json`, measured on the baked
//! atlas against the `[input] exemplar`).
//!
//! ```text
//! cargo bench --bench surface
//! SURFACE_MESHES=bunny_1k8.obj SURFACE_METHODS=peer,jump_surface cargo bench --bench surface
//! ```
//!
//! Writes into `target/surface/` (under `$CARGO_TARGET_DIR` when set):
//! `surface.md` and `surface.csv` (mesh × method: completeness, sharpness,
//! structure, coherence mean and p90, histogram distance, mean copied-region
//! fraction of the exemplar (methods that record source texels), wall and CPU seconds, peak memory of
//! the run's process) and `surface_sheet_<mesh>_<texture>.png` (exemplar |
//! peer | methods, each the baked GLB's first preview, labelled). Runs keep
//! their folders in `target/surface/runs/`.
//!
//! Knobs: `SURFACE_MESHES` (file names in `data/meshes/`; default a closed
//! mesh, one with a boundary, one with several components and one with sharp
//! features), `SURFACE_TEXTURE` (a stem in `data/textures/`, default
//! `brick`), `SURFACE_METHODS` (default `peer` and every config of
//! `configs/surface/` but `triplanar`, which is the peer's config). Every run
//! is a child process of the built `surfsynth` (its own peak memory,
//! isolation from a failing method); its analysis cache is emptied first.

#[path = "../tests/common/peer.rs"]
#[allow(dead_code)]
mod peer;

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use surfsynth::image::{Image, load_image};
use surfsynth::output::contact_sheet::{SheetLayout, SheetTile, contact_sheet};
use surfsynth::output::{write_bytes_atomic, write_png};

/// The peer's label and run name.
const PEER: &str = "peer";
/// The methods of `configs/surface/` in sheet order (the peer's config,
/// `triplanar`, runs as `peer`).
const METHODS: &[&str] = &[
    "jump_surface",
    "lapped",
    "coherent",
    "wei_levoy",
    "bangay_morkel",
];
/// Side of the peer's tile, pixels (twice the shared photos' side).
const TILE: u32 = 256;
const SEED: u64 = 1;

/// One run's figures.
struct Row {
    mesh: String,
    method: String,
    quality: [Option<f64>; QUALITY.len()],
    wall: f64,
    cpu: Option<f64>,
    peak_mib: Option<f64>,
    error: Option<String>,
}

const QUALITY: [(&str, &str); 7] = [
    ("completeness", "completeness ↓"),
    ("sharpness", "sharpness →1"),
    ("structure", "structure ↓"),
    ("coherence.mean", "coherence mean ↓"),
    ("coherence.p90", "coherence p90 ↓"),
    ("histogram", "histogram ↓"),
    ("verbatim.mean_region_fraction", "verbatim region ↓"),
];

fn list_env(name: &str) -> Option<Vec<String>> {
    std::env::var(name).ok().map(|v| {
        v.split(',')
            .map(|s| s.trim().to_string())
            .filter(|s| !s.is_empty())
            .collect()
    })
}

/// User + system CPU seconds of the finished children so far (Linux).
fn children_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let fields: Vec<&str> = stat.rsplit(')').next()?.split_whitespace().collect();
    // After the command: state is field 3; cutime, cstime are 16 and 17.
    let ticks: f64 = fields.get(13)?.parse::<f64>().ok()? + fields.get(14)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

fn value_at(json: &serde_json::Value, path: &str) -> Option<f64> {
    path.split('.')
        .try_fold(json, |v, k| v.get(k))
        .and_then(|v| v.as_f64())
}

/// Runs `config` on `mesh` with `exemplar` (and `extra` overrides) into
/// `out` as a child process.
fn run(
    config: &Path,
    mesh: &Path,
    exemplar: &Path,
    extra: &[String],
    out: &Path,
    cache: &Path,
) -> Result<(serde_json::Value, f64, Option<f64>), String> {
    let _ = std::fs::remove_dir_all(cache);
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_surfsynth"));
    cmd.arg("run")
        .arg(config)
        .arg("--out")
        .arg(out)
        .arg("--quiet")
        .arg("--set")
        .arg(format!("input.mesh={}", mesh.display()))
        .arg("--set")
        .arg(format!("input.exemplar={}", exemplar.display()))
        .env("SURFSYNTH_CACHE", cache);
    for s in extra {
        cmd.arg("--set").arg(s);
    }
    let cpu_before = children_cpu_seconds();
    let started = Instant::now();
    let output = cmd.output().map_err(|e| e.to_string())?;
    let wall = started.elapsed().as_secs_f64();
    let cpu = children_cpu_seconds().zip(cpu_before).map(|(a, b)| a - b);
    if !output.status.success() {
        let err = String::from_utf8_lossy(&output.stderr);
        return Err(err.lines().last().unwrap_or("failed").to_string());
    }
    let text = std::fs::read_to_string(out.join("metrics.json")).map_err(|e| e.to_string())?;
    let json = serde_json::from_str(&text).map_err(|e| e.to_string())?;
    Ok((json, wall, cpu))
}

fn fmt(v: Option<f64>) -> String {
    match v {
        Some(v) if v.abs() >= 100.0 => format!("{v:.0}"),
        Some(v) if v.abs() >= 1.0 => format!("{v:.2}"),
        Some(v) => format!("{v:.4}"),
        None => "–".into(),
    }
}

fn markdown(rows: &[Row], texture: &str) -> String {
    let mut md = format!(
        "# Surface benchmark: `{texture}` on the shared meshes\n\n\
         `cargo bench --bench surface`; every method of `configs/surface/` at texture_scale 0.2 \
         baked into a 2048² atlas of the original mesh; peer = `triplanar` of Embark's tileable \
         synthesis ({TILE}², seed {SEED}). Quality measured on the baked atlas against the \
         exemplar (docs/metrics.md: ↓ lower is better, →1 nearest one). Seconds: wall and CPU of \
         the whole run (child process, 2 cores); memory: the run's peak RSS.\n\n"
    );
    let mut head = vec!["mesh".to_string(), "method".into()];
    head.extend(QUALITY.iter().map(|q| q.1.to_string()));
    head.extend(["wall s".into(), "CPU s".into(), "peak MiB".into()]);
    let _ = writeln!(md, "| {} |", head.join(" | "));
    let _ = writeln!(md, "|{}", "---|".repeat(head.len()));
    for r in rows {
        let mut cells = vec![r.mesh.clone(), r.method.clone()];
        match &r.error {
            Some(e) => {
                cells.push(format!("FAILED: {e}"));
                cells.extend((1..QUALITY.len() + 3).map(|_| String::new()));
            }
            None => {
                cells.extend(r.quality.iter().map(|v| fmt(*v)));
                cells.extend([format!("{:.2}", r.wall), fmt(r.cpu), fmt(r.peak_mib)]);
            }
        }
        let _ = writeln!(md, "| {} |", cells.join(" | "));
    }
    md
}

fn csv(rows: &[Row]) -> String {
    let mut out = String::from("mesh,method,");
    out.push_str(&QUALITY.map(|q| q.0).join(","));
    out.push_str(",wall_seconds,cpu_seconds,peak_rss_mib,error\n");
    for r in rows {
        let cells: Vec<String> = r
            .quality
            .iter()
            .chain([Some(r.wall), r.cpu, r.peak_mib].iter())
            .map(|v| v.map(|v| v.to_string()).unwrap_or_default())
            .collect();
        let _ = writeln!(
            out,
            "{},{},{},{}",
            r.mesh,
            r.method,
            cells.join(","),
            r.error.as_deref().unwrap_or("").replace(',', ";")
        );
    }
    out
}

fn main() {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| manifest.join("target"));
    let out = target.join("surface");
    let runs = out.join("runs");
    let cache = out.join("cache");
    std::fs::create_dir_all(&runs).expect("the bench's output folder");
    let meshes = list_env("SURFACE_MESHES").unwrap_or_else(|| {
        [
            "bunny_1k8.obj",
            "mushroom.off",
            "teapot_open.obj",
            "fandisk.off",
        ]
        .map(String::from)
        .to_vec()
    });
    let texture = std::env::var("SURFACE_TEXTURE").unwrap_or_else(|_| "brick".into());
    let methods = list_env("SURFACE_METHODS").unwrap_or_else(|| {
        std::iter::once(PEER)
            .chain(METHODS.iter().copied())
            .map(String::from)
            .collect()
    });
    let exemplar_path = manifest.join(format!("data/textures/{texture}.png"));
    let exemplar = load_image(&exemplar_path).expect("the exemplar loads");
    // The peer's tile: Embark in tiling mode, once per texture.
    let tile_path = out.join(format!("tile_{texture}.png"));
    if methods.iter().any(|m| m == PEER) {
        let tile = peer::try_peer_tile(&exemplar, TILE, TILE, SEED, 2)
            .expect("Embark's tiling synthesis runs");
        eprintln!("surface: Embark tile {TILE}² in {:.2} s", tile.seconds);
        write_png(&tile_path, &tile.image).expect("the tile is written");
    }
    let mut rows = Vec::new();
    for mesh in &meshes {
        let mesh_path = manifest.join("data/meshes").join(mesh);
        let mut sheet: Vec<(String, Image)> =
            vec![(format!("exemplar\n{texture}"), exemplar.clone())];
        for method in &methods {
            let (config, extra) = if method == PEER {
                (
                    manifest.join("configs/surface/triplanar.toml"),
                    vec![format!("stage.1.image={}", tile_path.display())],
                )
            } else {
                (
                    manifest.join(format!("configs/surface/{method}.toml")),
                    vec![],
                )
            };
            let run_dir = runs.join(format!("{mesh}_{texture}_{method}"));
            // The bench's own folder: a run from an older surfsynth (without
            // a run marker) would be refused as someone else's.
            let _ = std::fs::remove_dir_all(&run_dir);
            eprintln!("surface: {mesh} × {method} …");
            let result = run(
                &config,
                &mesh_path,
                &exemplar_path,
                &extra,
                &run_dir,
                &cache,
            );
            let label = if method == PEER {
                "peer: triplanar of\nEmbark's tile".to_string()
            } else {
                method.clone()
            };
            match result {
                Ok((json, wall, cpu)) => {
                    let q = &json["result"]["quality"];
                    rows.push(Row {
                        mesh: mesh.clone(),
                        method: method.clone(),
                        quality: QUALITY.map(|(k, _)| value_at(q, k)),
                        wall,
                        cpu,
                        peak_mib: value_at(&json, "peak_rss_bytes").map(|b| b / 1048576.0),
                        error: None,
                    });
                    let preview = load_image(&run_dir.join("bake_preview_0.png"))
                        .unwrap_or_else(|_| Image::new(512, 512, 3));
                    sheet.push((format!("{label}\n{wall:.1} s"), preview));
                }
                Err(e) => {
                    eprintln!("surface: {mesh} × {method} failed: {e}");
                    rows.push(Row {
                        mesh: mesh.clone(),
                        method: method.clone(),
                        quality: [None; QUALITY.len()],
                        wall: 0.0,
                        cpu: None,
                        peak_mib: None,
                        error: Some(e),
                    });
                    sheet.push((format!("{label}\nFAILED"), Image::new(512, 512, 3)));
                }
            }
        }
        let tiles: Vec<SheetTile<'_>> = sheet
            .iter()
            .map(|(label, image)| SheetTile { image, label })
            .collect();
        let image = contact_sheet(
            &tiles,
            &SheetLayout {
                tile_height: Some(384),
                ..SheetLayout::default()
            },
        )
        .image;
        let stem = mesh.rsplit_once('.').map_or(mesh.as_str(), |(s, _)| s);
        let path = out.join(format!("surface_sheet_{stem}_{texture}.png"));
        match write_png(&path, &image) {
            Ok(()) => eprintln!("surface: wrote {}", path.display()),
            Err(e) => eprintln!("surface: {e}"),
        }
    }
    let _ = std::fs::remove_dir_all(&cache);
    for (name, text) in [
        ("surface.md", markdown(&rows, &texture)),
        ("surface.csv", csv(&rows)),
    ] {
        let path = out.join(name);
        match write_bytes_atomic(&path, text.as_bytes()) {
            Ok(()) => eprintln!("surface: wrote {}", path.display()),
            Err(e) => eprintln!("surface: {e}"),
        }
    }
}
