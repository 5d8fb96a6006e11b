//! Peak memory per vertex of the jump-map surface method and of lapped
//! textures on a messy scan (issue 15), without timing: a regression in the
//! data layout (a buffer kept too long, a whole file built in memory, a
//! component cloned) shows up as bytes per vertex.
//!
//! Each run is a child process of the real binary with the shipped config
//! `configs/02_jump_bunny_planks.toml` (formats ply, obj, preview, baked)
//! or `configs/31_lapped_bunny_planks.toml` (lapped textures),
//! read back from `metrics.json` (`peak_rss_bytes`, the process's VmHWM).
//! The baseline is the same config on a small scan (2 k vertices): the
//! binary, the exemplar and its jump map, the 1024² bake atlas and the
//! preview buffers, which do not grow with the mesh. The per-vertex figure
//! is the difference of the two peaks over the difference of the vertex
//! counts. A warm-up run fills the jump-map cache first, so both measured
//! runs load the map instead of analysing the exemplar.

use crate::common;

use std::path::Path;

fn peak_and_vertices_of(config: &str, scan: &Path, out: &Path) -> (f64, f64) {
    let config = Path::new(env!("CARGO_MANIFEST_DIR")).join(config);
    let run = common::bin()
        .arg("run")
        .arg(&config)
        .arg("--set")
        .arg(format!("input.mesh={}", scan.display()))
        .arg("--out")
        .arg(out)
        .arg("-q")
        .env(
            "SURFSYNTH_CACHE",
            Path::new(env!("CARGO_TARGET_TMPDIR")).join("surfsynth-cache"),
        )
        .output()
        .expect("the binary runs");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let peak = m["peak_rss_bytes"]
        .as_f64()
        .expect("peak_rss_bytes (Linux)");
    let vertices = m["input"]["vertices"].as_f64().unwrap();
    (peak, vertices)
}

/// Bytes per vertex of `config` beyond its baseline: runs on messy scans
/// (seed 7) of 2 k and `large` vertices, after a warm-up run on the small
/// one when `warm` (it fills the jump-map cache), and prints both peaks.
fn bytes_per_vertex(label: &str, config: &str, large: usize, warm: bool) -> f64 {
    let dir = tempfile::tempdir().unwrap();
    let (small, _) = common::messy::write_messy_scan(dir.path(), 2_000, 7);
    let (large, _) = common::messy::write_messy_scan(dir.path(), large, 7);
    let run = |scan: &Path, name: &str| peak_and_vertices_of(config, scan, &dir.path().join(name));
    if warm {
        run(&small, "warm");
    }
    let ((base, base_v), (peak, v)) = (run(&small, "small"), run(&large, "large"));
    let per_vertex = (peak - base) / (v - base_v);
    eprintln!(
        "{label}: baseline {:.1} MB at {base_v} vertices, peak {:.1} MB at {v} vertices: {per_vertex:.0} B/v",
        base / 1e6,
        peak / 1e6
    );
    per_vertex
}

/// Bytes per vertex beyond the baseline. Measured on 2 cores: 322 B/v at
/// 137 k vertices (baseline 43 MB at 2.6 k); at 901 k the raw peak is
/// 351 MB, 389 B/v (see ARCHITECTURE.md, "Memory at a million vertices").
/// Earlier layouts held 610 B/v (blend layers per fan triangle, the
/// renderer's per-corner normals and whole-mesh triangle set-up, a full
/// topology for the result metrics) and ~1 000 B/v (whole OBJ text in
/// memory, the export job's copies). The bound leaves ~15 % for allocator
/// noise and more threads (some kernels keep per-thread scratch).
const MAX_BYTES_PER_VERTEX: f64 = 380.0;

#[test]
#[cfg(target_os = "linux")]
fn jump_surface_peak_memory_per_vertex() {
    let per_vertex = bytes_per_vertex(
        "jump_surface",
        "configs/02_jump_bunny_planks.toml",
        150_000,
        true,
    );
    assert!(
        per_vertex <= MAX_BYTES_PER_VERTEX,
        "jump_surface holds {per_vertex:.0} bytes per vertex beyond the baseline (bound {MAX_BYTES_PER_VERTEX})"
    );
}

/// The same for `configs/40_bake_bunny.toml` (jump_surface baked into a
/// 2048² atlas of the scan, exported as GLB, OBJ and previews; the atlas
/// images are in the baseline). Measured on 2 cores: 293 B/v at 137 k
/// vertices (baseline 102 MB at 2.6 k); at 901 k the raw peak is 429 MB
/// (475 B/v raw, 364 B/v beyond the baseline). It was 755 MB (838 B/v) at
/// 901 k before the bake's memory work, 493 MB (547 B/v) when the bake
/// held small-chart hosts in arrays instead of maps of vectors, and 461 MB
/// (511 B/v) before the asset stopped holding its own copy of a triangle
/// mesh (`BakedAsset::on_source`) and the preview normals their per-face
/// arrays. The bound leaves ~30 % for allocator noise and threads.
const MAX_BAKE_BYTES_PER_VERTEX: f64 = 380.0;

#[test]
#[cfg(target_os = "linux")]
fn jump_surface_bake_peak_memory_per_vertex() {
    let per_vertex = bytes_per_vertex("bake", "configs/40_bake_bunny.toml", 150_000, true);
    assert!(
        per_vertex <= MAX_BAKE_BYTES_PER_VERTEX,
        "jump_surface + bake holds {per_vertex:.0} bytes per vertex beyond the baseline (bound {MAX_BAKE_BYTES_PER_VERTEX})"
    );
}

/// Bytes per vertex of lapped textures beyond the baseline
/// (`configs/31_lapped_bunny_planks.toml`: formats obj, preview, pastes,
/// a 1024² atlas). Measured on 2 cores: 321 B/v at 92 k vertices
/// (baseline 50 MB at 2.6 k: the atlas image, the previews, the binary);
/// at 901 k the raw peak is 388–393 MB (431–435 B/v raw, 375–380 B/v
/// beyond the baseline; there the paste loop is the peak). It was 352 B/v
/// while the tangent field stayed through the result metrics, and 427–502
/// B/v while the paste loop copied the mesh's positions and triangles,
/// stored face normals and areas and a scaled copy of the field, and the
/// export copied the pastes it writes; before the
/// first memory work ~3 700 B/v: every paste kept every face it was grown
/// over (4.8 per face, 11 with the per-face distortion rule) in a `Vec`
/// per face of the coverage, in the paste records and in the world, and the
/// result metrics copied them once more. See ARCHITECTURE.md, "Lapped
/// textures on dense scans".
const LAPPED_MAX_BYTES_PER_VERTEX: f64 = 400.0;

#[test]
#[cfg(target_os = "linux")]
fn lapped_peak_memory_per_vertex() {
    let per_vertex = bytes_per_vertex(
        "lapped",
        "configs/31_lapped_bunny_planks.toml",
        100_000,
        false,
    );
    assert!(
        per_vertex <= LAPPED_MAX_BYTES_PER_VERTEX,
        "lapped textures hold {per_vertex:.0} B/v beyond the baseline (bound {LAPPED_MAX_BYTES_PER_VERTEX})"
    );
}
