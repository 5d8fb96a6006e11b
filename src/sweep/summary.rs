//! The summary of a sweep folder: one row per run folder present (a folder
//! with a `run.json`), its overrides, its status and the key metrics of its
//! `metrics.json` flattened into columns; written as `summary.csv`,
//! `summary.json` and `index.html`.

use super::execute::{Completion, DONE, FAILED, LOG, RUN_RECORD, RunRecord};
use super::{SweepError, SweepRecord, io_err};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The result images shown as thumbnails of a run without `preview*.png`:
/// the planar result, the jump-map image.
pub const RESULT_IMAGES: [&str; 2] = ["plane.png", "jump_image.png"];

/// The 3D viewer page a run writes beside its `result.glb`.
pub const VIEWER: &str = "view.html";

/// One run folder, read back.
#[derive(Clone, Debug)]
pub struct RunRow {
    /// Folder name.
    pub name: String,
    /// Index in the full run list.
    pub index: usize,
    /// `ok`, `failed` or `incomplete` (started, never finished).
    pub status: String,
    /// Exit code of the child, when it exited.
    pub exit_code: Option<i32>,
    /// `ok`, `exit 2`, `killed by signal 9`, `timed out after 5 s`, ...
    pub reason: String,
    /// Child wall time measured by the sweep.
    pub wall_seconds: Option<f64>,
    /// `(path, value)` per grid axis.
    pub overrides: Vec<(String, String)>,
    /// Flattened metrics, keyed by [`MetricKey`].
    pub metrics: Vec<(MetricKey, Value)>,
    /// Preview images (`preview*.png`, else the result image of a run that
    /// has no shaded views: [`RESULT_IMAGES`]), paths relative to the sweep
    /// folder.
    pub previews: Vec<String>,
    /// Last lines of the log of a failed run.
    pub log_tail: Vec<String>,
    /// `<name>/view.html`, the run's 3D viewer, when the folder holds one.
    pub viewer: Option<String>,
}

/// A metric column: sorted by group, then stage index, then name.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct MetricKey {
    group: u8,
    order: usize,
    /// Column name.
    pub name: String,
}

impl MetricKey {
    fn new(group: u8, order: usize, name: impl Into<String>) -> Self {
        Self {
            group,
            order,
            name: name.into(),
        }
    }
}

/// Reads every run folder of `dir`, in run order.
pub fn collect(dir: &Path) -> Result<Vec<RunRow>, SweepError> {
    let mut rows = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io_err(dir))? {
        let entry = entry.map_err(io_err(dir))?;
        let path = entry.path();
        if !path.is_dir() {
            continue;
        }
        let Ok(text) = std::fs::read_to_string(path.join(RUN_RECORD)) else {
            continue;
        };
        let Ok(record) = serde_json::from_str::<RunRecord>(&text) else {
            tracing::warn!(
                "{}: unreadable {RUN_RECORD}, not summarised",
                path.display()
            );
            continue;
        };
        rows.push(read_row(&path, record));
    }
    rows.sort_by(|a, b| (a.index, &a.name).cmp(&(b.index, &b.name)));
    Ok(rows)
}

fn read_completion(path: &Path) -> Option<Completion> {
    let text = std::fs::read_to_string(path).ok()?;
    serde_json::from_str(&text).ok()
}

fn read_row(dir: &Path, record: RunRecord) -> RunRow {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or(record.name);
    let (status, completion) = match read_completion(&dir.join(DONE)) {
        Some(c) if c.exit_code == Some(0) => ("ok", Some(c)),
        _ => match read_completion(&dir.join(FAILED)) {
            Some(c) => ("failed", Some(c)),
            None => ("incomplete", None),
        },
    };
    let metrics = std::fs::read_to_string(dir.join("metrics.json"))
        .ok()
        .and_then(|t| serde_json::from_str::<Value>(&t).ok())
        .map(|m| flatten_metrics(&m))
        .unwrap_or_default();
    let mut previews: Vec<String> = std::fs::read_dir(dir)
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| {
            let f = e.file_name().to_string_lossy().into_owned();
            (f.starts_with("preview") && f.ends_with(".png")).then(|| format!("{name}/{f}"))
        })
        .collect();
    previews.sort();
    if previews.is_empty() {
        // Runs without shaded views: their result image, when they wrote one.
        previews.extend(
            RESULT_IMAGES
                .iter()
                .filter(|f| dir.join(f).is_file())
                .map(|f| format!("{name}/{f}")),
        );
    }
    let viewer = dir
        .join(VIEWER)
        .is_file()
        .then(|| format!("{name}/{VIEWER}"));
    RunRow {
        index: record.index,
        status: status.to_string(),
        exit_code: completion.as_ref().and_then(|c| c.exit_code),
        reason: completion
            .as_ref()
            .map_or_else(|| "never finished".to_string(), |c| c.status.clone()),
        wall_seconds: completion.as_ref().map(|c| c.wall_seconds),
        overrides: record.overrides,
        log_tail: completion.map(|c| c.log_tail).unwrap_or_default(),
        metrics,
        previews,
        viewer,
        name,
    }
}

/// The key metrics of a `metrics.json`: run time, peak memory, counts, every
/// scalar of `result.quality` (texture energy, Wasserstein, ...), per-stage
/// times, and the scalar metrics each stage reported.
pub fn flatten_metrics(m: &Value) -> Vec<(MetricKey, Value)> {
    let mut out = Vec::new();
    let mut push = |key: MetricKey, v: &Value| {
        if !v.is_null() {
            out.push((key, v.clone()));
        }
    };
    push(MetricKey::new(0, 0, "run_seconds"), &m["total_seconds"]);
    if let Some(b) = m["peak_rss_bytes"].as_f64() {
        push(
            MetricKey::new(0, 1, "peak_rss_mib"),
            &serde_json::json!((b / 1048576.0 * 10.0).round() / 10.0),
        );
    }
    push(
        MetricKey::new(0, 2, "input.vertices"),
        &m["input"]["vertices"],
    );
    push(MetricKey::new(0, 3, "input.faces"), &m["input"]["faces"]);
    push(
        MetricKey::new(0, 4, "result.vertices"),
        &m["result"]["mesh"]["vertices"],
    );
    push(
        MetricKey::new(0, 5, "result.faces"),
        &m["result"]["mesh"]["faces"],
    );
    let mut quality = Vec::new();
    flatten_scalars("quality", &m["result"]["quality"], &mut quality);
    for (k, v) in quality {
        push(MetricKey::new(1, 0, k), &v);
    }
    for s in m["stages"].as_array().into_iter().flatten() {
        let index = s["index"].as_u64().unwrap_or(0) as usize;
        let kind = s["kind"].as_str().unwrap_or("stage");
        push(
            MetricKey::new(2, index, format!("time.s{index}.{kind}")),
            &s["seconds"],
        );
        let mut stage = Vec::new();
        flatten_scalars(&format!("s{index}.{kind}"), &s["metrics"], &mut stage);
        for (k, v) in stage {
            push(MetricKey::new(3, index, k), &v);
        }
    }
    out
}

/// Scalars (numbers, strings, booleans) under `v`, keys joined by dots.
fn flatten_scalars(prefix: &str, v: &Value, out: &mut Vec<(String, Value)>) {
    match v {
        Value::Object(map) => {
            for (k, child) in map {
                flatten_scalars(&format!("{prefix}.{k}"), child, out);
            }
        }
        Value::Number(_) | Value::String(_) | Value::Bool(_) => {
            out.push((prefix.to_string(), v.clone()))
        }
        Value::Array(_) | Value::Null => {}
    }
}

/// The table: override columns (in order of first appearance), then every
/// metric column of any run (sorted).
#[derive(Clone, Debug)]
pub struct Table {
    /// Grid paths.
    pub override_columns: Vec<String>,
    /// Metric column names.
    pub metric_columns: Vec<String>,
}

/// The columns over all rows.
pub fn table(rows: &[RunRow]) -> Table {
    let mut override_columns: Vec<String> = Vec::new();
    let mut metrics: BTreeMap<&MetricKey, ()> = BTreeMap::new();
    for r in rows {
        for (p, _) in &r.overrides {
            if !override_columns.contains(p) {
                override_columns.push(p.clone());
            }
        }
        for (k, _) in &r.metrics {
            metrics.insert(k, ());
        }
    }
    let mut metric_columns: Vec<String> = Vec::new();
    for k in metrics.keys() {
        if !metric_columns.contains(&k.name) {
            metric_columns.push(k.name.clone());
        }
    }
    Table {
        override_columns,
        metric_columns,
    }
}

/// The leading fixed columns of the CSV.
pub const FIXED_COLUMNS: [&str; 6] = [
    "run",
    "status",
    "exit_code",
    "reason",
    "error",
    "wall_seconds",
];

/// A cell's text: numbers as Rust prints them, strings as they are.
pub fn cell_text(v: &Value) -> String {
    match v {
        Value::String(s) => s.clone(),
        Value::Null => String::new(),
        other => other.to_string(),
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

impl RunRow {
    /// The value of a metric column.
    pub fn metric(&self, name: &str) -> Option<&Value> {
        self.metrics
            .iter()
            .find(|(k, _)| k.name == name)
            .map(|(_, v)| v)
    }

    /// The value of an override column.
    pub fn override_value(&self, path: &str) -> Option<&str> {
        self.overrides
            .iter()
            .find(|(p, _)| p == path)
            .map(|(_, v)| v.as_str())
    }

    /// The last line of a failed run's log (its error message), else empty.
    pub fn error(&self) -> &str {
        if self.status == "ok" {
            ""
        } else {
            self.log_tail.last().map_or("", |s| s.as_str())
        }
    }

    fn fixed_values(&self) -> [String; 6] {
        [
            self.name.clone(),
            self.status.clone(),
            self.exit_code.map(|c| c.to_string()).unwrap_or_default(),
            self.reason.clone(),
            self.error().to_string(),
            self.wall_seconds
                .map(|s| format!("{s:.3}"))
                .unwrap_or_default(),
        ]
    }
}

/// `summary.csv`: a header line and one line per run.
pub fn to_csv(rows: &[RunRow], t: &Table) -> String {
    let mut lines = Vec::with_capacity(rows.len() + 1);
    let header: Vec<String> = FIXED_COLUMNS
        .iter()
        .map(|s| s.to_string())
        .chain(t.override_columns.iter().cloned())
        .chain(t.metric_columns.iter().cloned())
        .map(|s| csv_field(&s))
        .collect();
    lines.push(header.join(","));
    for r in rows {
        let mut fields: Vec<String> = r.fixed_values().to_vec();
        fields.extend(
            t.override_columns
                .iter()
                .map(|p| r.override_value(p).unwrap_or("").to_string()),
        );
        fields.extend(
            t.metric_columns
                .iter()
                .map(|c| r.metric(c).map(cell_text).unwrap_or_default()),
        );
        lines.push(
            fields
                .iter()
                .map(|f| csv_field(f))
                .collect::<Vec<_>>()
                .join(","),
        );
    }
    let mut s = lines.join("\n");
    s.push('\n');
    s
}

/// `summary.json`: the sweep record, the columns, and one object per run.
pub fn to_json(rows: &[RunRow], t: &Table, record: Option<&SweepRecord>) -> Value {
    let runs: Vec<Value> = rows
        .iter()
        .map(|r| {
            let overrides: serde_json::Map<String, Value> = r
                .overrides
                .iter()
                .map(|(p, v)| (p.clone(), Value::String(v.clone())))
                .collect();
            let metrics: serde_json::Map<String, Value> = r
                .metrics
                .iter()
                .map(|(k, v)| (k.name.clone(), v.clone()))
                .collect();
            serde_json::json!({
                "run": r.name,
                "index": r.index,
                "status": r.status,
                "exit_code": r.exit_code,
                "reason": r.reason,
                "error": r.error(),
                "wall_seconds": r.wall_seconds,
                "overrides": overrides,
                "metrics": metrics,
                "previews": r.previews,
                "viewer": r.viewer,
                "log": format!("{}/{LOG}", r.name),
                "log_tail": r.log_tail,
            })
        })
        .collect();
    serde_json::json!({
        "sweep": record,
        "override_columns": t.override_columns,
        "metric_columns": t.metric_columns,
        "runs": runs,
    })
}

/// Writes `summary.csv`, `summary.json` and `index.html` into `dir`, atomically.
pub fn write_all(
    dir: &Path,
    rows: &[RunRow],
    record: Option<&SweepRecord>,
) -> Result<Vec<PathBuf>, SweepError> {
    let t = table(rows);
    let csv = dir.join("summary.csv");
    crate::output::write_bytes_atomic(&csv, to_csv(rows, &t).as_bytes())?;
    let json = dir.join("summary.json");
    let text =
        serde_json::to_string_pretty(&to_json(rows, &t, record)).map_err(|e| SweepError::Io {
            path: json.clone(),
            message: e.to_string(),
        })?;
    crate::output::write_bytes_atomic(&json, text.as_bytes())?;
    let html = dir.join("index.html");
    let exemplars = exemplar_files(dir, record);
    let page = super::html::render(rows, &t, record, &exemplars);
    crate::output::write_bytes_atomic(&html, page.as_bytes())?;
    Ok(vec![csv, json, html])
}

/// `(file, caption)` of the exemplar pictures present in `dir`.
fn exemplar_files(dir: &Path, record: Option<&SweepRecord>) -> Vec<(String, String)> {
    let mut out: Vec<(String, String)> = record
        .map(|r| {
            r.exemplars
                .iter()
                .filter(|e| dir.join(&e.file).is_file())
                .map(|e| {
                    let caption = if e.options.is_empty() {
                        e.spec.clone()
                    } else {
                        format!("{} ({})", e.spec, e.options.trim().replace('\n', ", "))
                    };
                    (e.file.clone(), caption)
                })
                .collect()
        })
        .unwrap_or_default();
    if out.is_empty() {
        let mut files: Vec<String> = std::fs::read_dir(dir)
            .into_iter()
            .flatten()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|f| f.starts_with("exemplar") && f.ends_with(".png"))
            .collect();
        files.sort();
        out = files.into_iter().map(|f| (f.clone(), f)).collect();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn metrics_flatten_into_ordered_columns() {
        let m = serde_json::json!({
            "total_seconds": 1.5,
            "peak_rss_bytes": 10485760,
            "input": {"vertices": 10, "faces": 16},
            "result": {"mesh": {"vertices": 12, "faces": 20},
                       "quality": {"texture_energy": {"mean": 0.25, "histogram_wasserstein": 0.1}}},
            "stages": [
                {"index": 10, "kind": "export", "seconds": 0.5, "metrics": {}},
                {"index": 2, "kind": "jump_map", "seconds": 1.0,
                 "metrics": {"pca_components": 7, "boundary": "toroidal", "list": [1, 2]}},
            ],
        });
        let row = RunRow {
            name: "a".into(),
            index: 0,
            status: "ok".into(),
            exit_code: Some(0),
            reason: "ok".into(),
            wall_seconds: Some(2.0),
            overrides: vec![("seed".into(), "1".into())],
            metrics: flatten_metrics(&m),
            previews: vec![],
            log_tail: vec![],
            viewer: None,
        };
        let t = table(std::slice::from_ref(&row));
        assert_eq!(
            t.metric_columns,
            [
                "run_seconds",
                "peak_rss_mib",
                "input.vertices",
                "input.faces",
                "result.vertices",
                "result.faces",
                "quality.texture_energy.histogram_wasserstein",
                "quality.texture_energy.mean",
                "time.s2.jump_map",
                "time.s10.export",
                "s2.jump_map.boundary",
                "s2.jump_map.pca_components",
            ]
        );
        assert_eq!(row.metric("peak_rss_mib"), Some(&serde_json::json!(10.0)));
        let csv = to_csv(&[row], &t);
        let lines: Vec<&str> = csv.lines().collect();
        assert_eq!(lines.len(), 2);
        assert!(
            lines[0].starts_with("run,status,exit_code,reason,error,wall_seconds,seed,run_seconds")
        );
        assert!(
            lines[1]
                .starts_with("a,ok,0,ok,,2.000,1,1.5,10.0,10,16,12,20,0.1,0.25,1.0,0.5,toroidal,7"),
            "{}",
            lines[1]
        );
    }

    #[test]
    fn csv_quotes_fields_with_commas_and_quotes() {
        assert_eq!(csv_field("a,b"), "\"a,b\"");
        assert_eq!(csv_field("say \"hi\""), "\"say \"\"hi\"\"\"");
        assert_eq!(csv_field("plain"), "plain");
    }
}
