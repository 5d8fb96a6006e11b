//! Scaling of every method on messy scans (issue 15): each method's shipped
//! config runs, as its own process, on the messy-scan generator of the
//! tests (`tests/common/messy.rs`: holes, fins, 100+ small components,
//! slivers, duplicate vertices) at 10 k and 100 k vertices (add 1 M with
//! `SURFSYNTH_SCALING_1M=1`; `SURFSYNTH_SCALING_SIZES=1000000` and
//! `SURFSYNTH_SCALING_METHODS=jump_surface,wei_levoy` choose), and prints seconds per vertex and peak
//! resident bytes per vertex from each run's `metrics.json`, with the
//! slowest stage.
//!
//!     cargo bench --bench scaling
//!
//! The per-vertex methods synthesise at the texture's density, which the
//! config fixes: on a bigger scan of the same object they synthesise the
//! same number of vertices and map the result back. With
//! `SURFSYNTH_SCALING_DENSE=1` the synthesis follows the scan instead
//! (`[input] texture_scale` of one exemplar pixel per vertex
//! spacing of the scan, so `retile` and `subdivide_sqrt2` derive the scan's
//! vertex count), which measures the synthesis itself at 10 k to 1 M.
//!
//! Each method also runs once on a 2 k-vertex scan, the baseline: the
//! binary, the exemplar and its analysis, the atlas and preview images,
//! which do not grow with the mesh. The marginal columns are the
//! differences to it over the difference of vertex counts — the cost of
//! one more vertex, which stays flat when a method is linear (the raw
//! per-vertex figures fall with size where the fixed part dominates).
//! Between the baseline and 10 k that difference is small (0.1–0.3 CPU
//! seconds) and not all of it is per vertex: the result metrics' samples
//! saturate between 2 k and 100 k (on a small scan more of them fall on
//! chips and holes and are left out), and the per-vertex methods
//! synthesise at the config's texture density whatever the scan. The step
//! column is therefore the cost of one more vertex from the previous size
//! to this one (10 k → 100 k, 100 k → 1 M; "–" at the first size after the
//! baseline and after a failed run): the measure of linearity.
//! CPU seconds are the child's user + system time (`getrusage`), steadier
//! than wall time on a shared machine; scans of at most 100 k vertices run
//! `SURFSYNTH_SCALING_REPEATS` times (default 3) and the best is kept.
//!
//! Not a criterion bench: one run per size is the measurement (each takes
//! seconds to minutes), and peak memory needs a process of its own.

#[path = "../tests/common/messy.rs"]
mod messy;

use std::path::Path;
use std::process::Command;

const CONFIGS: [(&str, &str); 6] = [
    ("jump_surface", "02_jump_bunny_planks.toml"),
    ("wei_levoy", "17_wl_bunny.toml"),
    ("coherent", "19_coherent_bunny_brick.toml"),
    ("bangay_morkel", "23_bm_bunny_brick_graphcut.toml"),
    ("lapped", "31_lapped_bunny_planks.toml"),
    ("jump + bake", "40_bake_bunny.toml"),
];

/// Vertices of the baseline scan every method runs on first.
const BASELINE_VERTICES: usize = 2_000;

/// User + system seconds of the finished child processes so far.
fn children_cpu_seconds() -> f64 {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        // SAFETY: `getrusage` fills the zeroed struct it is given and reads
        // nothing else.
        let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
        if unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage) } == 0 {
            let secs = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
            return secs(usage.ru_utime) + secs(usage.ru_stime);
        }
    }
    f64::NAN
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    // The binary `cargo build` writes: under `$CARGO_TARGET_DIR` when set
    // (relative to the crate root, where cargo runs benches), else `target/`.
    let target = std::env::var_os("CARGO_TARGET_DIR")
        .map(|t| root.join(t))
        .unwrap_or_else(|| root.join("target"));
    let bin = target.join("release/surfsynth");
    let built = Command::new(env!("CARGO"))
        .args(["build", "--release", "--bin", "surfsynth"])
        .current_dir(root)
        .status()
        .expect("cargo runs");
    assert!(built.success(), "the binary builds");
    let dir = tempfile::tempdir().expect("a temporary folder");
    let mut sizes = vec![10_000usize, 100_000];
    if std::env::var("SURFSYNTH_SCALING_1M").is_ok() {
        sizes.push(1_000_000);
    }
    // SURFSYNTH_SCALING_SIZES=1000000 and SURFSYNTH_SCALING_METHODS=
    // jump_surface,lapped pick what to run.
    if let Ok(list) = std::env::var("SURFSYNTH_SCALING_SIZES") {
        sizes = list
            .split(',')
            .filter_map(|s| s.trim().parse().ok())
            .collect();
    }
    let dense = std::env::var("SURFSYNTH_SCALING_DENSE").is_ok();
    // SURFSYNTH_SCALING_REPEATS: runs per scan of at most 100 k vertices
    // (the best is kept); default 3.
    let repeats: usize = std::env::var("SURFSYNTH_SCALING_REPEATS")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(3)
        .max(1);
    let methods: Option<Vec<String>> = std::env::var("SURFSYNTH_SCALING_METHODS")
        .ok()
        .map(|l| l.split(',').map(|s| s.trim().to_string()).collect());
    println!(
        "| method | vertices | seconds | CPU s | µs / vertex | peak MB | bytes / vertex | marginal CPU µs / vertex | marginal bytes / vertex | step CPU µs / vertex | slowest stage |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let mut baselines: std::collections::HashMap<&str, (f64, f64, f64)> = Default::default();
    // The previous size's (vertices, CPU seconds) per method, for the step
    // column.
    let mut previous: std::collections::HashMap<&str, (f64, f64)> = Default::default();
    for &n in std::iter::once(&BASELINE_VERTICES).chain(&sizes) {
        let (mesh, report) = messy::write_messy_scan(dir.path(), n, 1);
        // SURFSYNTH_SCALING_KEEP=FOLDER keeps the scans, to look or profile.
        if let Ok(keep) = std::env::var("SURFSYNTH_SCALING_KEEP") {
            let _ = std::fs::copy(&mesh, Path::new(&keep).join(mesh.file_name().unwrap()));
        }
        for (method, config) in CONFIGS {
            if methods
                .as_ref()
                .is_some_and(|m| !m.iter().any(|x| x == method))
            {
                continue;
            }
            let out = dir.path().join(format!("out_{n}_{method}"));
            let mut cmd = Command::new(&bin);
            cmd.arg("run").arg(root.join("configs").join(config));
            // Dense: one exemplar pixel per vertex spacing on the scan, so
            // the per-vertex methods synthesise as many vertices as it has.
            if dense && matches!(method, "wei_levoy" | "coherent" | "bangay_morkel") {
                let texels_per_unit = (report.vertices as f64 / report.area).sqrt();
                cmd.args([
                    "--set",
                    "input.texture_scale_unit=\"pixels_per_unit\"",
                    "--set",
                    &format!("input.texture_scale={texels_per_unit}"),
                ]);
            }
            cmd.arg("--set")
                .arg(format!("input.mesh={}", mesh.display()))
                .arg("--out")
                .arg(&out)
                .arg("-q");
            // Small scans take a second or two: the best of a few runs,
            // so that the marginal cost is not the noise of one.
            let runs = if n <= 100_000 { repeats } else { 1 };
            let (mut cpu, mut secs, mut peak) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
            let mut m = serde_json::Value::Null;
            let mut failed = None;
            for _ in 0..runs {
                let _ = std::fs::remove_dir_all(&out);
                let cpu_before = children_cpu_seconds();
                let run = cmd.output().expect("the binary runs");
                if !run.status.success() {
                    failed = Some(
                        String::from_utf8_lossy(&run.stderr)
                            .lines()
                            .last()
                            .unwrap_or("")
                            .to_string(),
                    );
                    break;
                }
                cpu = cpu.min(children_cpu_seconds() - cpu_before);
                m = serde_json::from_str(
                    &std::fs::read_to_string(out.join("metrics.json")).expect("metrics.json"),
                )
                .expect("json");
                secs = secs.min(m["total_seconds"].as_f64().unwrap_or(f64::NAN));
                peak = peak.min(m["peak_rss_bytes"].as_f64().unwrap_or(f64::NAN));
            }
            if let Some(reason) = failed {
                // The next size's step would span two intervals.
                previous.remove(method);
                println!(
                    "| {method} | {} | failed: {reason} | | | | | | | | |",
                    report.vertices
                );
                continue;
            }
            let slowest = m["stages"]
                .as_array()
                .into_iter()
                .flatten()
                .max_by(|a, b| {
                    let s = |x: &serde_json::Value| x["seconds"].as_f64().unwrap_or(0.0);
                    s(a).total_cmp(&s(b))
                })
                .map(|s| {
                    format!(
                        "{} {:.1} s",
                        s["kind"].as_str().unwrap_or("?"),
                        s["seconds"].as_f64().unwrap_or(0.0)
                    )
                })
                .unwrap_or_default();
            // The bake's own seconds and atlas (issue 15: linear in texels
            // and faces, half the atlas filled).
            let bake = m["stages"]
                .as_array()
                .into_iter()
                .flatten()
                .find(|s| s["kind"] == "bake")
                .map(|s| {
                    format!(
                        "; bake {:.1} s, {} charts, fill {:.3}",
                        s["seconds"].as_f64().unwrap_or(f64::NAN),
                        s["metrics"]["atlas_charts"],
                        s["metrics"]["atlas_fill"].as_f64().unwrap_or(f64::NAN)
                    )
                })
                .unwrap_or_default();
            let v = report.vertices as f64;
            let (marginal_cpu, marginal_bytes) = match baselines.get(method) {
                Some(&(bv, bcpu, bpeak)) if v > bv => (
                    format!("{:.1}", (cpu - bcpu) / (v - bv) * 1e6),
                    format!("{:.0}", (peak - bpeak) / (v - bv)),
                ),
                _ => {
                    baselines.insert(method, (v, cpu, peak));
                    ("baseline".into(), "baseline".into())
                }
            };
            // The cost of one more vertex between this size and the one
            // before: what stays of the fixed part (exemplar analysis,
            // atlas, previews, result metrics whose samples saturate on
            // small scans, the synthesis at the config's texture density
            // for the per-vertex methods) cancels, so a linear method
            // shows the same figure at every step.
            // (Not from the baseline: that is the marginal column.)
            let step_cpu = match baselines.get(method) {
                Some(&(bv, _, _)) if bv < v => match previous.insert(method, (v, cpu)) {
                    Some((pv, pcpu)) if v > pv => {
                        format!("{:.1}", (cpu - pcpu) / (v - pv) * 1e6)
                    }
                    _ => "–".into(),
                },
                _ => "–".into(),
            };
            println!(
                "| {method} | {} | {secs:.2} | {cpu:.2} | {:.1} | {:.0} | {:.0} | {marginal_cpu} | {marginal_bytes} | {step_cpu} | {slowest}{bake} |",
                report.vertices,
                secs / v * 1e6,
                peak / 1e6,
                peak / v
            );
            let _ = std::fs::remove_dir_all(&out);
        }
    }
}
