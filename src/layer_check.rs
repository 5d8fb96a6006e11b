//! The layers of ARCHITECTURE.md, checked: a module may name (`crate::X`)
//! in code (not in comments, not in its unit tests) only modules of its own
//! layer or below. Known violations are listed; a new one fails, and so
//! does a listed one that is gone, so the list only shrinks.

use std::path::{Path, PathBuf};

/// Layer of a module, 0 the top.
fn layer(module: &str) -> Option<u8> {
    Some(match module {
        "main" => 0,
        "sweep" | "pipeline" | "preflight" => 1,
        "stages" => 2,
        "output" | "cache" => 3,
        "world" | "stage" => 4,
        "kernels" => 5,
        "mesh" | "image" | "config" | "progress" | "telemetry" => 6,
        _ => return None,
    })
}

/// The module a source file belongs to.
fn module_of(rel: &Path) -> String {
    let parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    match parts.as_slice() {
        [file] => file.trim_end_matches(".rs").into(),
        [dir, ..] => dir.clone(),
        [] => String::new(),
    }
}

/// The module a `crate::X…` path names.
fn target_of(path: &str) -> String {
    path.split("::").next().unwrap_or_default().into()
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("src is readable").flatten() {
        let p = e.path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// Every `(file's module, named module, file)` where the named module is
/// on a higher layer, outside `#[cfg(test)]` modules (tests may reach up).
fn violations() -> Vec<(String, String, String)> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let mut out = Vec::new();
    for f in files {
        let rel = f.strip_prefix(&src).expect("under src");
        let from = module_of(rel);
        let Some(from_layer) = layer(&from) else {
            continue;
        };
        let text = std::fs::read_to_string(&f).expect("a source file");
        // Code before the unit tests.
        let code: String = text
            .split("#[cfg(test)]\nmod tests")
            .next()
            .unwrap_or("")
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        for (i, _) in code.match_indices("crate::") {
            let rest = &code[i + "crate::".len()..];
            let path: String = rest
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
                .collect();
            let to = target_of(&path);
            if to == from {
                continue;
            }
            if let Some(to_layer) = layer(&to)
                && to_layer < from_layer
            {
                let item = (from.clone(), to, rel.display().to_string());
                if !out.contains(&item) {
                    out.push(item);
                }
            }
        }
    }
    out
}

/// Today's imports up a layer, as `(from, to, file)` (`*`: any file of
/// `from`): the work left of issue 41's first part. Most are the stage
/// contract (`Stage`, `Datum`, `StageCtx`, `PipelineError`), which lives in
/// `pipeline` but every stage implements.
const KNOWN: &[(&str, &str, &str)] = &[];

/// Whether `v` is listed in [`KNOWN`].
fn known(v: &(String, String, String)) -> bool {
    KNOWN
        .iter()
        .any(|(a, b, f)| v.0 == *a && v.1 == *b && (*f == "*" || v.2 == *f))
}

#[test]
fn no_module_imports_from_a_layer_above_it() {
    let found = violations();
    let new: Vec<_> = found.iter().filter(|v| !known(v)).collect();
    let gone: Vec<_> = KNOWN
        .iter()
        .filter(|(a, b, f)| {
            !found
                .iter()
                .any(|v| v.0 == *a && v.1 == *b && (*f == "*" || v.2 == *f))
        })
        .collect();
    assert!(
        new.is_empty(),
        "imports from a layer above (from, to, file): {new:?}; the layers are in ARCHITECTURE.md"
    );
    assert!(
        gone.is_empty(),
        "fixed, take them off KNOWN in src/layer_check.rs: {gone:?}"
    );
}

#[test]
fn the_check_sees_an_upward_import() {
    assert_eq!(
        module_of(Path::new("kernels/jump_maps/jump_map/ann.rs")),
        "kernels"
    );
    assert_eq!(module_of(Path::new("world/mesh.rs")), "world");
    assert_eq!(target_of("world::Geometry"), "world");
    assert_eq!(target_of("pipeline::PipelineError"), "pipeline");
    assert!(layer("kernels") > layer("stages"));
}
