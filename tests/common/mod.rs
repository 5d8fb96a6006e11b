//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod gates;
pub mod peer;

use std::path::{Path, PathBuf};
use std::process::Command;

/// The built CLI binary.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_surfsynth"))
}

/// Path of a shared data file (`../shared/data/...`, as CI lays it out).
pub fn shared(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(rel)
}

/// Runs the CLI, returning (exit code, stdout, stderr).
pub fn run_cli(args: &[&str]) -> (i32, String, String) {
    let out = bin()
        .args(args)
        .env("RUST_LOG", "warn")
        .env(
            "SURFSYNTH_CACHE",
            Path::new(env!("CARGO_TARGET_TMPDIR")).join("surfsynth-cache"),
        )
        .output()
        .expect("the surfsynth binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Files (recursively) under `dir`, empty when it does not exist.
pub fn files_under(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let Ok(rd) = std::fs::read_dir(dir) else {
        return out;
    };
    for e in rd.flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(files_under(&p));
        } else {
            out.push(p);
        }
    }
    out.sort();
    out
}
