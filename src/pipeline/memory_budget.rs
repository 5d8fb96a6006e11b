//! Up-front memory estimates: a config whose legal parameters would need more
//! memory than [`MEMORY_BUDGET`] is refused at validation, before any work,
//! instead of aborting the process when an allocation fails mid-run.
//!
//! Checked: a builtin mesh's `resolution` in `[input]`, and the sizes of
//! `jump_image` (`width x height`), `builtin_pyramid` (plane, torus,
//! uv_sphere `resolution`), `retile` (`vertices`), `subdivide_sqrt2`
//! (`target_vertices`) and the `plane` format of `export` (`plane_size`).
//!
//! The estimates are deliberately coarse upper bounds per element, measured
//! from what the stages allocate (documented on each constant); they only
//! need to tell "fits" from "would abort", not predict the peak exactly.

use crate::config::{ConfigError, RawInput};
use crate::pipeline::registry::StagePlan;

/// Memory a run may plan for: 8 GiB. A documented constant rather than the
/// machine's memory, so a config that validates on one machine validates on
/// every machine (and sweeps can be validated on a small login node).
pub const MEMORY_BUDGET: u64 = 8 << 30;

/// Bytes per vertex of a builtin mesh over a whole pipeline: positions,
/// faces (two triangles per grid vertex), topology (edges, one-rings,
/// vertex→faces), tangent frames, scales, colours, source texels, the
/// neighbourhood vectors of the matching stages, and the copies later stages
/// and the exporter make (≈ 60 `f32`/`u32` arrays of 1–3 values). With it the
/// largest grid that fits the budget is about 2896 × 2896 vertices.
pub const BYTES_PER_MESH_VERTEX: u64 = 1024;

/// Bytes per output pixel of `jump_image`: the RGB result (12), its source
/// coordinates (8) and source image (12), the written 8- and 16-bit copies
/// (9), the patch visualisation (12) and the texture-energy buffers (≈ 11).
pub const BYTES_PER_JUMP_IMAGE_PIXEL: u64 = 64;

/// Bytes per pixel of the `plane` export format: the pixel hits (triangle
/// and barycentric weights, 20), the RGB image (12) and its exemplar
/// sources (8), the 16-bit source map (6) and both encoded copies (9), with
/// room for the encoder's buffers.
pub const BYTES_PER_PLANE_PIXEL: u64 = 64;

/// Shows a byte count in GiB (or MiB below 1 GiB).
fn show_bytes(bytes: u64) -> String {
    let gib = bytes as f64 / (1u64 << 30) as f64;
    if gib >= 1.0 {
        format!("{gib:.1} GiB")
    } else {
        format!("{:.0} MiB", bytes as f64 / (1u64 << 20) as f64)
    }
}

/// The message of an estimate over the budget.
pub fn over_budget_message(what: &str, estimate: u64) -> String {
    format!(
        "{what} needs an estimated {} of memory, over the budget of {} (MEMORY_BUDGET); use a smaller size",
        show_bytes(estimate),
        show_bytes(MEMORY_BUDGET)
    )
}

/// An integer setting as a count: at least 1 (absent or not an integer: 1).
fn count(value: Option<&toml::Value>) -> u64 {
    value.and_then(|v| v.as_integer()).unwrap_or(1).max(1) as u64
}

/// Checks the builtin mesh of `[input]` and every stage against the budget.
///
/// # Errors
/// [`ConfigError::Value`] naming the key, the estimate and the budget.
pub fn check_memory(
    input: &RawInput,
    stages: &[Box<dyn StagePlan>],
    file: &str,
) -> Result<(), ConfigError> {
    let over = |key: String, what: String, estimate: u64| {
        if estimate > MEMORY_BUDGET {
            Err(ConfigError::Value {
                file: file.to_string(),
                key,
                message: over_budget_message(&what, estimate),
            })
        } else {
            Ok(())
        }
    };
    let is_builtin = input
        .mesh
        .as_deref()
        .is_some_and(|m| m.trim().starts_with("builtin:"));
    if let Some(resolution) = input
        .mesh_options
        .get("resolution")
        .and_then(|r| r.as_array())
        .filter(|_| is_builtin)
    {
        let vertices: u64 = resolution.iter().map(|v| count(Some(v))).product();
        over(
            "input.mesh_options.resolution".into(),
            format!("a builtin mesh of {vertices} vertices"),
            vertices.saturating_mul(BYTES_PER_MESH_VERTEX),
        )?;
    }
    for (i, stage) in stages.iter().enumerate() {
        let kind = stage.kind();
        let table = stage.resolved();
        let int = |k: &str| count(table.get(k));
        let pair = |k: &str| {
            let side = |j: usize| count(table.get(k).and_then(|v| v.as_array()?.get(j)));
            (side(0), side(1))
        };
        let plane_format = || {
            table
                .get("formats")
                .and_then(|v| v.as_array())
                .is_some_and(|f| f.iter().any(|f| f.as_str() == Some("plane")))
        };
        let pyramid_grid = || {
            let mesh = table.get("mesh").and_then(|v| v.as_str());
            matches!(mesh, Some("plane" | "torus" | "uv_sphere"))
        };
        // With an `edge_length` the count depends on the mesh's area.
        let retile_by_count = || table.get("edge_length").and_then(|v| v.as_float()) == Some(0.0);
        // (key, what, bytes)
        let image = |key, name: &str, (w, h): (u64, u64), per_pixel: u64| {
            Some((
                key,
                format!("a {w}x{h}-pixel {name}"),
                (w * h).saturating_mul(per_pixel),
            ))
        };
        let estimate = match kind {
            "jump_image" => image(
                "width x height",
                "jump_image",
                (int("width"), int("height")),
                BYTES_PER_JUMP_IMAGE_PIXEL,
            ),
            "builtin_pyramid" if pyramid_grid() => {
                let (u, v) = pair("resolution");
                Some((
                    "resolution",
                    format!("a builtin_pyramid of {u}x{v} vertices at its finest level"),
                    (u * v).saturating_mul(BYTES_PER_MESH_VERTEX),
                ))
            }
            "retile" if retile_by_count() => Some((
                "vertices",
                format!("a retiled mesh of {} vertices", int("vertices")),
                int("vertices").saturating_mul(BYTES_PER_MESH_VERTEX),
            )),
            "subdivide_sqrt2" => Some((
                "target_vertices",
                format!(
                    "a subdivision hierarchy of {} vertices",
                    int("target_vertices")
                ),
                int("target_vertices").saturating_mul(BYTES_PER_MESH_VERTEX),
            )),
            "export" if plane_format() => image(
                "plane_size",
                "plane image",
                pair("plane_size"),
                BYTES_PER_PLANE_PIXEL,
            ),
            _ => None,
        };
        if let Some((k, what, bytes)) = estimate {
            over(format!("stage {} ({kind}) {k}", i + 1), what, bytes)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_give_estimate_and_budget() {
        let m = over_budget_message("a 32768x32768-pixel jump_image", 68 << 30);
        assert!(m.contains("68.0 GiB") && m.contains("8.0 GiB"), "{m}");
    }
}
