//! Human-readable text: the end-of-run table and the stage reference.

use super::RunReport;
use crate::config::params::value_text;
use crate::stages::registry;
use std::fmt::Write;

/// The per-stage time table printed at the end of a run.
pub fn format_report(report: &RunReport) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "{:>5}  {:<20} {:>10}", "stage", "kind", "seconds");
    for t in &report.timings {
        let _ = writeln!(s, "{:>5}  {:<20} {:>10.3}", t.index, t.kind, t.seconds);
    }
    let total = report.metrics["total_seconds"].as_f64().unwrap_or(0.0);
    let _ = writeln!(s, "{:>5}  {:<20} {:>10.3}", "", "total (with I/O)", total);
    if let Some(rss) = report.metrics["peak_rss_bytes"].as_u64() {
        let _ = writeln!(
            s,
            "peak resident memory: {:.1} MiB",
            rss as f64 / (1024.0 * 1024.0)
        );
    }
    let q = &report.metrics["result"]["quality"]["texture_energy"];
    if let (Some(mean), Some(p90)) = (q["mean"].as_f64(), q["p90"].as_f64()) {
        let _ = writeln!(s, "texture energy: mean {mean:.5}, p90 {p90:.5}");
    }
    let _ = writeln!(s, "outputs in {}:", report.out_dir.display());
    for f in &report.files {
        let _ = writeln!(
            s,
            "  {}",
            f.file_name()
                .map(|n| n.to_string_lossy())
                .unwrap_or_default()
        );
    }
    s
}

/// The reference of every stage (or of `kind`): parameters with defaults,
/// units and ranges. `Err` carries the list of allowed kinds.
pub fn describe_stages(kind: Option<&str>) -> Result<String, String> {
    let all = registry();
    let selected: Vec<_> = all
        .iter()
        .filter(|s| kind.is_none_or(|k| k == s.kind))
        .collect();
    if selected.is_empty() {
        return Err(all.iter().map(|s| s.kind).collect::<Vec<_>>().join(", "));
    }
    let mut s = String::new();
    for info in selected {
        let _ = writeln!(s, "[[stage]] kind = \"{}\"", info.kind);
        let _ = writeln!(s, "  {}", info.summary);
        let _ = writeln!(s, "  paper: {}", info.paper);
        let defaults = (info.defaults)();
        if info.params.is_empty() {
            let _ = writeln!(s, "  (no parameters)");
        }
        for p in info.params {
            let default = defaults
                .get(p.name)
                .map(value_text)
                .unwrap_or_else(|| "(none)".into());
            let unit = if p.unit.is_empty() {
                String::new()
            } else {
                format!(" [{}]", p.unit)
            };
            let _ = writeln!(s, "  {:<22} = {default}{unit}", p.name);
            let _ = writeln!(s, "  {:<22}   allowed: {}", "", p.range);
            let _ = writeln!(s, "  {:<22}   {}", "", p.doc);
        }
        let _ = writeln!(s);
    }
    Ok(s)
}
