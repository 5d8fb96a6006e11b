//! Small pipelines of every method on one small mesh and exemplar, shared
//! by the tests that run each method (texture scale, progress).

/// A 24 × 12 builtin torus with 32-pixel bricks at `texture_scale = 0.6`
/// (seed 5).
pub const HEADER: &str = r#"
seed = 5
[input]
mesh = "builtin:torus"
exemplar = "builtin:bricks"
exemplar_wrap = "clamp"
texture_scale = 0.6
[input.mesh_options]
resolution = [24, 12]
[input.exemplar_options]
size = 32
"#;

/// The methods, each a pipeline after [`HEADER`] that leaves per-vertex
/// colours or texture coordinates (and, for `bake`, an atlas).
pub const METHODS: [(&str, &str); 6] = [
    (
        "jump_surface",
        r#"
[[stage]]
kind = "orientation"
up = [0.0, 0.0, 1.0]
[[stage]]
kind = "jump_map"
cache = false
[[stage]]
kind = "jump_surface"
"#,
    ),
    (
        "graph_match",
        r#"
[[stage]]
kind = "subdivide_sqrt2"
[[stage]]
kind = "diffuse_orientation"
[[stage]]
kind = "graph_match"
region = 5.0
passes = [1]
"#,
    ),
    (
        "wei_levoy",
        r#"
[[stage]]
kind = "retile"
levels = 2
[[stage]]
kind = "orientation"
up = [0.0, 0.0, 1.0]
[[stage]]
kind = "init_colours"
[[stage]]
kind = "match"
passes = 1
[[stage]]
kind = "map_back"
"#,
    ),
    (
        "coherent",
        r#"
[[stage]]
kind = "retile"
levels = 2
[[stage]]
kind = "orientation"
up = [0.0, 0.0, 1.0]
[[stage]]
kind = "coherent"
[[stage]]
kind = "map_back"
"#,
    ),
    (
        "lapped",
        r#"
[[stage]]
kind = "tangent_field"
up = [0.0, 0.0, 1.0]
[[stage]]
kind = "lapped_paste"
"#,
    ),
    (
        "bake",
        r#"
[[stage]]
kind = "orientation"
up = [0.0, 0.0, 1.0]
[[stage]]
kind = "jump_map"
cache = false
[[stage]]
kind = "jump_surface"
[[stage]]
kind = "bake"
"#,
    ),
];

/// The stages of method `name` in [`METHODS`].
pub fn method(name: &str) -> &'static str {
    METHODS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, s)| *s)
        .unwrap_or_else(|| panic!("no method {name}"))
}
