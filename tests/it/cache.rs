//! The analysis cache from the command line: `surfsynth cache` and `cache
//! clear`, `SURFSYNTH_CACHE_LIMIT` (0 writes nothing, a malformed value is
//! refused before any work, a small one evicts the least recently used
//! entries), and a cache hit giving the same outputs.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

const CONFIG: &str = "configs/01_jump_map_image.toml";
const OUTPUTS: [&str; 3] = [
    "jump_image.png",
    "jump_image_sources.png",
    "jump_image_patches.png",
];

/// The CLI with `cache` as its cache folder and no limit set.
fn cli(cache: &Path) -> Command {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_surfsynth"));
    cmd.current_dir(env!("CARGO_MANIFEST_DIR"))
        .env("RUST_LOG", "warn")
        .env("SURFSYNTH_CACHE", cache)
        .env_remove("SURFSYNTH_CACHE_LIMIT");
    cmd
}

/// Runs `cmd`: (exit code, stdout, stderr).
fn output(cmd: &mut Command) -> (i32, String, String) {
    let out = cmd.output().expect("the surfsynth binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs the small jump-map config into `out` and checks it succeeded.
fn run_config(cache: &Path, out: &Path, limit: Option<&str>) {
    let mut cmd = cli(cache);
    cmd.args(["run", CONFIG, "-q", "--out"]).arg(out);
    if let Some(l) = limit {
        cmd.env("SURFSYNTH_CACHE_LIMIT", l);
    }
    let (code, _, stderr) = output(&mut cmd);
    assert_eq!(code, 0, "{stderr}");
}

/// A name of an entry of `kind`.
fn entry_name(kind: &str, i: u8) -> String {
    format!("{kind}-{}.bin", format!("{i:02x}").repeat(32))
}

/// The names of the `*-*.bin` files in `dir` (entries and look-alikes),
/// sorted.
fn bin_files(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .map(|rd| {
            rd.map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .filter(|n| n.ends_with(".bin") && n.contains('-'))
                .collect()
        })
        .unwrap_or_default();
    names.sort();
    names
}

fn set_time(path: &Path, secs: u64) {
    surfsynth::cache::set_last_use(path, UNIX_EPOCH + Duration::from_secs(secs)).unwrap();
}

fn modified(path: &Path) -> SystemTime {
    std::fs::metadata(path).unwrap().modified().unwrap()
}

#[test]
fn cache_show_and_clear_name_the_folder_and_sizes_and_keep_foreign_files() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("cache");

    // A folder that does not exist yet is empty, not an error.
    let (code, stdout, stderr) = output(cli(&dir).arg("cache"));
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains(&dir.display().to_string()), "{stdout}");
    assert!(stdout.contains("does not exist yet"), "{stdout}");
    assert!(stdout.contains("total: 0 entries, 0 B"), "{stdout}");
    assert!(stdout.contains("limit: 1.0 GiB"), "{stdout}");

    std::fs::create_dir(&dir).unwrap();
    std::fs::write(dir.join(entry_name("jumpmap", 1)), vec![0; 1024]).unwrap();
    std::fs::write(dir.join(entry_name("jumpmap", 2)), vec![0; 2048]).unwrap();
    std::fs::write(dir.join(entry_name("appearance", 3)), vec![0; 100]).unwrap();
    let foreign = dir.join("notes-mine.bin");
    std::fs::write(&foreign, b"keep me").unwrap();

    let (code, stdout, stderr) = output(
        cli(&dir)
            .args(["cache", "show"])
            .env("SURFSYNTH_CACHE_LIMIT", "500M"),
    );
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains(&dir.display().to_string()), "{stdout}");
    assert!(!stdout.contains("does not exist"), "{stdout}");
    assert!(stdout.contains("jumpmap: 2 entries, 3.0 KiB"), "{stdout}");
    assert!(stdout.contains("appearance: 1 entry, 100 B"), "{stdout}");
    assert!(stdout.contains("other files"), "{stdout}");
    assert!(stdout.contains("total: 3 entries, 3.1 KiB"), "{stdout}");
    assert!(
        stdout.contains("limit: 500.0 MiB (SURFSYNTH_CACHE_LIMIT)"),
        "{stdout}"
    );

    let (code, stdout, stderr) = output(cli(&dir).args(["cache", "clear"]));
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains(&dir.display().to_string()), "{stdout}");
    assert!(
        stdout.contains("3 files deleted, 3.1 KiB freed"),
        "{stdout}"
    );
    assert!(
        bin_files(&dir) == ["notes-mine.bin"],
        "{:?}",
        bin_files(&dir)
    );
    assert_eq!(std::fs::read(&foreign).unwrap(), b"keep me");

    let (code, stdout, _) = output(cli(&dir).arg("cache"));
    assert_eq!(code, 0);
    assert!(stdout.contains("total: 0 entries, 0 B"), "{stdout}");
    // Clearing a folder that does not exist is fine too.
    let (code, stdout, _) = output(cli(&tmp.path().join("none")).args(["cache", "clear"]));
    assert_eq!(code, 0);
    assert!(stdout.contains("0 files deleted, 0 B freed"), "{stdout}");
}

#[test]
fn a_malformed_limit_is_refused_before_any_work() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("cache");
    for bad in ["-1", "abc", "1T", "1.5G"] {
        let out = tmp.path().join("out");
        let (code, _, stderr) = output(
            cli(&dir)
                .args(["run", CONFIG, "--out"])
                .arg(&out)
                .env("SURFSYNTH_CACHE_LIMIT", bad),
        );
        assert_eq!(code, 2, "{bad}: {stderr}");
        for needle in ["SURFSYNTH_CACHE_LIMIT", &format!("{bad:?}"), "K, M or G"] {
            assert!(stderr.contains(needle), "{needle}: {stderr}");
        }
        assert!(!out.exists() && !dir.exists(), "{bad}: nothing was done");
        let (code, _, stderr) = output(cli(&dir).arg("cache").env("SURFSYNTH_CACHE_LIMIT", bad));
        assert_eq!(code, 2, "{bad}: {stderr}");
        assert!(stderr.contains("SURFSYNTH_CACHE_LIMIT"), "{stderr}");
    }
    let sweep = tmp.path().join("sweep");
    let (code, _, stderr) = output(
        cli(&dir)
            .args(["sweep", CONFIG, "--grid", "seed=1,2", "--dry-run", "--out"])
            .arg(&sweep)
            .env("SURFSYNTH_CACHE_LIMIT", "lots"),
    );
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("SURFSYNTH_CACHE_LIMIT"), "{stderr}");
    assert!(!sweep.exists());
}

#[test]
fn limit_zero_writes_nothing_and_a_cache_hit_gives_the_same_outputs() {
    let tmp = tempfile::tempdir().unwrap();
    let t = tmp.path();

    let off = t.join("off");
    run_config(&off, &t.join("out0"), Some("0"));
    assert!(bin_files(&off).is_empty(), "{:?}", bin_files(&off));

    let dir = t.join("cache");
    run_config(&dir, &t.join("out1"), None);
    let written = bin_files(&dir);
    assert_eq!(written.len(), 1, "{written:?}");
    assert!(written[0].starts_with("jumpmap-"), "{written:?}");
    // An old last use, refreshed by the hit.
    let entry: PathBuf = dir.join(&written[0]);
    set_time(&entry, 1_000_000);
    run_config(&dir, &t.join("out2"), None);
    assert_eq!(bin_files(&dir), written);
    let age = SystemTime::now()
        .duration_since(modified(&entry))
        .unwrap_or_default();
    assert!(age < Duration::from_secs(600), "the hit refreshed the time");
    let metrics = std::fs::read_to_string(t.join("out2/metrics.json")).unwrap();
    assert!(metrics.contains("\"cache_hit\": true"), "{metrics}");
    for f in OUTPUTS {
        assert!(
            std::fs::read(t.join("out1").join(f)).unwrap()
                == std::fs::read(t.join("out2").join(f)).unwrap(),
            "{f} differs between the analysed and the cached run"
        );
        assert!(
            std::fs::read(t.join("out0").join(f)).unwrap()
                == std::fs::read(t.join("out2").join(f)).unwrap(),
            "{f} differs with the cache off"
        );
    }

    // A run's write evicts the least recently used entries over the limit.
    let size = std::fs::metadata(&entry).unwrap().len();
    let small = t.join("small");
    std::fs::create_dir(&small).unwrap();
    let staged: Vec<PathBuf> = (1..=6)
        .map(|i| {
            let p = small.join(entry_name("patches", i));
            std::fs::write(&p, vec![i; 100 * 1024]).unwrap();
            set_time(&p, 1_000_000 + u64::from(i));
            p
        })
        .collect();
    let foreign = small.join("README.txt");
    std::fs::write(&foreign, vec![b'x'; 1 << 20]).unwrap();
    set_time(&foreign, 1);
    let limit = size + 250 * 1024;
    run_config(&small, &t.join("out3"), Some(&limit.to_string()));
    assert!(small.join(&written[0]).exists(), "the entry written stays");
    for (i, p) in staged.iter().enumerate() {
        assert_eq!(p.exists(), i >= 4, "staged entry {}", i + 1);
    }
    let total: u64 = bin_files(&small)
        .iter()
        .map(|n| std::fs::metadata(small.join(n)).unwrap().len())
        .sum();
    assert!(total <= limit, "{total} > {limit}");
    assert_eq!(std::fs::read(&foreign).unwrap().len(), 1 << 20);
}
