//! The layout of the tests (issue 41): with `autotests = false`, a file in
//! `tests/` is built only once it is declared, so a forgotten declaration
//! would drop its tests without a word. Every `tests/it/<topic>.rs` is a
//! `mod <topic>;` of `tests/it/main.rs`, and every other test file (a
//! `tests/<name>.rs`, or a `tests/<folder>/main.rs` but `common/`'s) is a
//! `[[test]]` of Cargo.toml.

use std::path::Path;

/// The `.rs` files directly in `dir`, by stem, sorted.
fn rust_stems(dir: &Path) -> Vec<String> {
    let mut stems: Vec<String> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "rs"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    stems.sort();
    stems
}

#[test]
fn every_test_file_is_declared_so_it_is_built_and_run() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let main = std::fs::read_to_string(root.join("tests/it/main.rs")).unwrap();
    let undeclared_modules: Vec<String> = rust_stems(&root.join("tests/it"))
        .into_iter()
        .filter(|s| s != "main" && !main.lines().any(|l| l.trim() == format!("mod {s};")))
        .collect();
    assert!(
        undeclared_modules.is_empty(),
        "tests/it/ files without a `mod NAME;` in tests/it/main.rs (never built): \
         {undeclared_modules:?}"
    );

    let manifest: toml::Table =
        toml::from_str(&std::fs::read_to_string(root.join("Cargo.toml")).unwrap()).unwrap();
    let declared: Vec<&str> = manifest
        .get("test")
        .and_then(|t| t.as_array())
        .map(|tests| {
            tests
                .iter()
                .filter_map(|t| t.get("path")?.as_str())
                .collect()
        })
        .unwrap_or_default();
    assert!(declared.contains(&"tests/it/main.rs"), "{declared:?}");
    let mut files: Vec<String> = rust_stems(&root.join("tests"))
        .into_iter()
        .map(|s| format!("tests/{s}.rs"))
        .collect();
    for entry in std::fs::read_dir(root.join("tests")).unwrap().flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        if entry.path().is_dir() && name != "common" {
            files.push(format!("tests/{name}/main.rs"));
        }
    }
    let undeclared: Vec<&String> = files
        .iter()
        .filter(|f| !declared.contains(&f.as_str()))
        .collect();
    assert!(
        undeclared.is_empty(),
        "test files without a [[test]] in Cargo.toml (never built; a test that can share \
         a process belongs in tests/it/ as a module): {undeclared:?}"
    );
}
