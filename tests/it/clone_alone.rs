//! Issue 39, "anyone can clone it": the repository alone — its tracked files
//! copied into a fresh folder with nothing beside it — runs shipped configs
//! that read meshes and photos. The data they name is in `data/`, found
//! relative to each config's own folder.

use crate::common::*;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The repository's tracked files, relative to its root: `git ls-files`,
/// or, where the source is not a git checkout (a crate tarball), every file
/// but the build and output folders.
fn tracked_files(root: &Path) -> Vec<PathBuf> {
    let listed = Command::new("git")
        .args(["ls-files", "-z"])
        .current_dir(root)
        .output()
        .ok()
        .filter(|o| o.status.success() && !o.stdout.is_empty());
    match listed {
        Some(out) => out
            .stdout
            .split(|&b| b == 0)
            .filter(|p| !p.is_empty())
            .map(|p| PathBuf::from(String::from_utf8_lossy(p).into_owned()))
            .collect(),
        None => files_under(root)
            .into_iter()
            .filter_map(|p| p.strip_prefix(root).ok().map(Path::to_path_buf))
            .filter(|p| {
                !matches!(
                    p.components().next().and_then(|c| c.as_os_str().to_str()),
                    Some("target" | "out" | ".git")
                )
            })
            .collect(),
    }
}

#[test]
fn shipped_configs_run_from_a_copy_of_the_tracked_files_alone() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let scratch = tempfile::tempdir().expect("a temporary folder");
    let clone = scratch.path().join("surfsynth");
    let files = tracked_files(root);
    assert!(
        files.iter().any(|f| f.starts_with("data/meshes")),
        "the data is tracked"
    );
    for rel in &files {
        let (from, to) = (root.join(rel), clone.join(rel));
        if !from.is_file() {
            continue; // deleted in the work tree but still in the index
        }
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(&from, &to).unwrap_or_else(|e| panic!("copy {}: {e}", rel.display()));
    }
    // Nothing beside the copy: no sibling data folder to fall back on.
    let siblings: Vec<_> = std::fs::read_dir(scratch.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(siblings, ["surfsynth"]);

    // A texture alone, a mesh and a texture, and a baked GLB.
    for (config, expected) in [
        ("configs/01_jump_map_image.toml", &["jump_image.png"][..]),
        (
            "configs/02_jump_bunny_planks.toml",
            &["result.obj", "result.ply", "preview_0.png"][..],
        ),
        (
            "configs/40_bake_bunny.toml",
            &["result.glb", "result_atlas.obj"][..],
        ),
    ] {
        let out = scratch
            .path()
            .join("out")
            .join(Path::new(config).file_stem().expect("a config file name"));
        let result = bin()
            .args(["run", config, "--out", out.to_str().unwrap(), "--quiet"])
            .current_dir(&clone)
            .env(
                "SURFSYNTH_CACHE",
                Path::new(env!("CARGO_TARGET_TMPDIR")).join("surfsynth-cache"),
            )
            .output()
            .expect("the surfsynth binary runs");
        assert!(
            result.status.success(),
            "{config} in a lone copy: exit {:?}\n{}",
            result.status.code(),
            String::from_utf8_lossy(&result.stderr)
        );
        for name in expected.iter().chain(&["metrics.json"]) {
            assert!(out.join(name).is_file(), "{config} wrote no {name}");
        }
    }
}
