//! `index.html`: one self-contained page (inline CSS and JS, no network)
//! with the exemplar, every run's previews as thumbnails linking to the
//! full images, a link to each run's 3D viewer (`view.html`) when its folder
//! holds one, and the metrics in a table that sorts by any column header
//! (numerically when every value of the column is a number).
//!
//! The table scrolls inside a box the size of the window, with the header
//! row and the run and thumbnail columns sticky. Columns run: swept
//! parameters, quality measures, time and memory, the rest; each header
//! carries its unit and which way is better ([`super::columns`]). A column
//! chooser shows a default set that fits a laptop screen; the reader's
//! choice is kept in the URL hash (`#cols=+key,-key`) and in localStorage.

use super::SweepRecord;
use super::columns::{ColumnMeta, Group, column_meta, group, label, page_order, shown_by_default};
use super::execute::LOG;
use super::summary::{FIXED_COLUMNS, RunRow, Table, cell_text};
use serde_json::Value;
use std::fmt::Write;

pub use crate::output::html_escape as escape;

/// Percent-encodes a relative path for an `href`/`src` (folders kept).
pub fn url_path(path: &str) -> String {
    let mut out = String::new();
    for b in path.bytes() {
        match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'.' | b'_' | b'~' | b'/' => {
                out.push(b as char)
            }
            _ => {
                let _ = write!(out, "%{b:02X}");
            }
        }
    }
    out
}

/// A number with three significant digits below 1 (small measures such as a
/// texture energy of 0.000367 keep their digits); the exact value is in the
/// cell's `data-v` and tooltip.
fn number_display(v: f64) -> String {
    if v == v.trunc() && v.abs() < 1e15 {
        format!("{v:.0}")
    } else if v.abs() >= 1000.0 {
        format!("{v:.1}")
    } else if v.abs() >= 1e-6 {
        let decimals = (2 - v.abs().log10().floor() as i32).max(1) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.2e}")
    }
}

/// A `<td>` whose `data-v` holds the exact value the table sorts on;
/// `best` marks the column's best value, `group_start` a group's first
/// column.
fn cell(out: &mut String, v: Option<&Value>, best: bool, group_start: bool) {
    let mut classes: Vec<&str> = Vec::new();
    if group_start {
        classes.push("gs");
    }
    if let Some(Value::Number(_)) = v {
        classes.push("n");
        if best {
            classes.push("best");
        }
    }
    let class = if classes.is_empty() {
        String::new()
    } else {
        format!(" class=\"{}\"", classes.join(" "))
    };
    match v {
        Some(Value::Number(n)) => {
            let f = n.as_f64().unwrap_or(0.0);
            let exact = escape(&n.to_string());
            let _ = write!(
                out,
                "<td{class} data-v=\"{exact}\" title=\"{exact}\">{}</td>",
                escape(&number_display(f))
            );
        }
        Some(v) => {
            let t = escape(&cell_text(v));
            let _ = write!(out, "<td{class} data-v=\"{t}\">{t}</td>");
        }
        None => {
            let _ = write!(out, "<td{class} data-v=\"\"></td>");
        }
    }
}

const STYLE: &str = r#"
html, body { height: 100%; }
body { font: 13px/1.35 system-ui, sans-serif; margin: 0; color: #222; background: #fafafa;
  display: flex; flex-direction: column; }
.top { display: flex; gap: 1em; align-items: flex-start; padding: .6em 1em .5em; }
h1 { font-size: 1.25em; margin: 0 0 .2em; }
.meta { color: #555; }
.meta code { background: #eee; padding: 0 .3em; border-radius: 3px; }
.exemplars { display: flex; gap: .5em; flex: none; }
.exemplars figure { margin: 0; text-align: center; }
.exemplars img { width: 72px; height: 72px; image-rendering: pixelated; border: 1px solid #ccc; display: block; }
.exemplars figcaption { font-size: 11px; color: #555; max-width: 140px; overflow-wrap: anywhere; }
.hint { color: #777; font-size: 12px; margin-top: .2em; }
.hint b { color: #444; }
.top { position: relative; }
.chooser { display: inline-block; margin-top: .3em; }
.chooser summary { cursor: pointer; color: #1a4fa0; }
.chooser .panel { position: absolute; z-index: 20; top: 100%; left: 1em; right: 1em; background: #fff;
  border: 1px solid #bbb; box-shadow: 0 4px 14px rgba(0,0,0,.2); padding: .5em .8em; max-height: 70vh;
  overflow: auto; display: flex; gap: .8em 1.2em; align-items: flex-start; flex-wrap: wrap; }
.chooser fieldset { border: 0; border-left: 3px solid #ddd; margin: 0; padding: 0 .6em; max-width: 22em; }
.chooser legend { font-weight: bold; padding: 0; }
.chooser label { display: block; white-space: nowrap; overflow: hidden; text-overflow: ellipsis; }
.chooser .actions { flex-basis: 100%; }
.chooser button { font: inherit; margin-right: .4em; }
.wrap { flex: 1 1 auto; min-height: 0; overflow: auto; margin: 0 1em 1em; border: 1px solid #ccc; background: #fff; }
table { border-collapse: separate; border-spacing: 0; }
th, td { border-right: 1px solid #e2e2e2; border-bottom: 1px solid #e2e2e2; padding: 3px 6px;
  white-space: nowrap; vertical-align: middle; background: #fff; }
th { background: #f0f0f0; cursor: pointer; user-select: none; position: sticky; top: 0; z-index: 3;
  white-space: normal; min-width: 4.2em; max-width: 7.5em; vertical-align: bottom; text-align: left;
  font-weight: 600; border-bottom: 2px solid #bbb; }
th:hover { background: #e4e4ff; }
th .pre { display: block; font-weight: normal; color: #777; font-size: 11px; }
th .unit { display: block; font-weight: normal; color: #777; font-size: 11px; }
th .dir { color: #1a7f37; font-weight: bold; white-space: nowrap; }
th.asc::after { content: " \25B2"; } th.desc::after { content: " \25BC"; }
th.gs, td.gs { border-left: 2px solid #999; }
.c-run { position: sticky; left: 0; z-index: 2; min-width: 11.5em; max-width: 13em; white-space: normal;
  overflow-wrap: anywhere; }
.c-prev { position: sticky; left: var(--prev-left, 13em); z-index: 2; box-shadow: 3px 0 4px -2px rgba(0,0,0,.25); }
th.c-run, th.c-prev { z-index: 4; }
td.n { text-align: right; font-variant-numeric: tabular-nums; }
td.best { color: #1a7f37; font-weight: bold; }
td.c-prev img { height: 64px; width: 64px; object-fit: contain; margin-right: 2px; vertical-align: middle; }
tr.failed td { background: #fff0f0; } tr.incomplete td { background: #fffbe6; }
tbody tr:hover td { background: #eef4ff; }
a.v3d { display: inline-block; margin-left: .3em; padding: 0 .35em; border-radius: 3px; background: #1a4fa0;
  color: #fff; font-size: 11px; font-weight: bold; text-decoration: none; }
.badge { color: #b00020; font-weight: bold; }
.why { color: #b00020; font-size: 11px; }
details.log pre { margin: .3em 0 0; font-size: 11px; white-space: pre-wrap; max-width: 40em; }
"#;

const SCRIPT: &str = r#"
(function () {
  var table = document.getElementById('runs');
  var body = table.tBodies[0];
  var headers = table.tHead.rows[0].cells;
  var boxes = Array.prototype.slice.call(document.querySelectorAll('.chooser input[data-col]'));
  var vis = document.getElementById('colvis');
  var count = document.getElementById('ncols');
  var store = 'surfsynth-sweep-columns:' + location.pathname;
  function value(row, col) { var c = row.cells[col]; return c ? (c.getAttribute('data-v') || '') : ''; }
  Array.prototype.forEach.call(headers, function (th, col) {
    th.addEventListener('click', function (e) {
      if (e.target.closest('a')) return;
      var rows = Array.prototype.slice.call(body.rows);
      var numeric = rows.every(function (r) { var v = value(r, col); return v === '' || isFinite(Number(v)); });
      var dir = th.classList.contains('asc') ? -1 : 1;
      Array.prototype.forEach.call(headers, function (h) { h.classList.remove('asc', 'desc'); });
      th.classList.add(dir === 1 ? 'asc' : 'desc');
      rows.sort(function (a, b) {
        var x = value(a, col), y = value(b, col);
        if (x === '' && y !== '') return 1;
        if (y === '' && x !== '') return -1;
        var c = numeric ? Number(x) - Number(y) : x.localeCompare(y, undefined, { numeric: true });
        return c * dir || (Number(a.getAttribute('data-i')) - Number(b.getAttribute('data-i')));
      });
      rows.forEach(function (r) { body.appendChild(r); });
    });
  });
  // Sticky columns: the thumbnails sit right of the run column.
  function stick() {
    var run = headers[0];
    table.style.setProperty('--prev-left', run.getBoundingClientRect().width + 'px');
  }
  // Column choice: differences from the defaults, '+key' shown, '-key'
  // hidden, kept in the URL hash (#cols=...) and in localStorage.
  function diffs() {
    return boxes.filter(function (b) { return b.checked !== (b.getAttribute('data-def') === '1'); })
      .map(function (b) { return (b.checked ? '+' : '-') + encodeURIComponent(b.value); });
  }
  function apply() {
    var css = '', shown = 1;
    boxes.forEach(function (b) {
      if (b.checked) shown++;
      else css += '#runs tr > :nth-child(' + (Number(b.getAttribute('data-col')) + 1) + ') { display: none; }\n';
    });
    vis.textContent = css;
    count.textContent = shown + ' of ' + (boxes.length + 1);
    stick();
  }
  function save() {
    var d = diffs().join(',');
    var hash = d ? '#cols=' + d : ' ';
    try { history.replaceState(null, '', hash === ' ' ? location.pathname + location.search : hash); }
    catch (e) { location.hash = d ? 'cols=' + d : ''; }
    try { localStorage.setItem(store, d); } catch (e) {}
  }
  function load(text) {
    boxes.forEach(function (b) { b.checked = b.getAttribute('data-def') === '1'; });
    (text || '').split(',').forEach(function (t) {
      if (!t) return;
      var key = decodeURIComponent(t.slice(1));
      boxes.forEach(function (b) { if (b.value === key) b.checked = t[0] === '+'; });
    });
  }
  var m = /(?:^#|&)cols=([^&]*)/.exec(location.hash);
  var saved = null;
  if (!m) { try { saved = localStorage.getItem(store); } catch (e) {} }
  load(m ? m[1] : saved);
  apply();
  boxes.forEach(function (b) { b.addEventListener('change', function () { apply(); save(); }); });
  Array.prototype.forEach.call(document.querySelectorAll('.chooser button'), function (btn) {
    btn.addEventListener('click', function () {
      var act = btn.getAttribute('data-act');
      boxes.forEach(function (b) {
        var g = b.closest('fieldset').getAttribute('data-group');
        if (act === 'default') b.checked = b.getAttribute('data-def') === '1';
        else if (act === 'all') b.checked = true;
        else if (act === 'none') b.checked = g === 'run' || g === 'param';
      });
      apply(); save();
    });
  });
  window.addEventListener('resize', stick);
  window.addEventListener('load', stick);
})();
"#;

/// Where a column's cells come from.
enum Source {
    Previews,
    Override,
    Status,
    ExitCode,
    Reason,
    Error,
    Wall,
    Metric,
}

/// One column of the page after the run column.
struct Column {
    key: String,
    source: Source,
    group: Group,
    meta: Option<ColumnMeta>,
    shown: bool,
}

impl Column {
    fn value(&self, r: &RunRow) -> Option<Value> {
        match self.source {
            Source::Previews => None,
            Source::Override => r.override_value(&self.key).map(override_cell),
            Source::Status => Some(Value::String(r.status.clone())),
            Source::ExitCode => r.exit_code.map(Value::from),
            Source::Reason => Some(Value::String(r.reason.clone())),
            Source::Error => Some(Value::String(r.error().to_string())),
            Source::Wall => r.wall_seconds.map(Value::from),
            Source::Metric => r.metric(&self.key).cloned(),
        }
    }

    /// Header text: prefix, name, direction mark, unit; tooltip in words.
    fn header(&self, out: &mut String, group_start: bool) {
        let (prefix, name, unit, mark, title) = match (&self.source, &self.meta) {
            (Source::Previews, _) => (
                String::new(),
                "thumbnails".to_string(),
                "previews".to_string(),
                String::new(),
                "the run's preview images; click one for the full image".to_string(),
            ),
            (Source::Override, _) => (
                String::new(),
                self.key.clone(),
                "swept".to_string(),
                String::new(),
                format!(
                    "{}: swept parameter (--grid); neither way is better",
                    self.key
                ),
            ),
            (_, Some(m)) => {
                let (prefix, name) = label(&self.key);
                let unit_words = if m.unit.is_empty() { "text" } else { m.unit };
                (
                    prefix,
                    name,
                    m.unit.to_string(),
                    m.direction.mark(),
                    format!(
                        "{}: {} ({unit_words}, {})",
                        self.key,
                        m.about,
                        m.direction.phrase()
                    ),
                )
            }
            (_, None) => {
                let (prefix, name) = label(&self.key);
                (
                    prefix,
                    name,
                    "?".to_string(),
                    String::new(),
                    format!(
                        "{}: reported by the stage; unit not recorded (see the stage's docs); neither way is better",
                        self.key
                    ),
                )
            }
        };
        let class = format!(
            "g-{}{}{}",
            self.group.slug(),
            if group_start { " gs" } else { "" },
            if matches!(self.source, Source::Previews) {
                " c-prev"
            } else {
                ""
            }
        );
        let _ = write!(
            out,
            "<th class=\"{class}\" data-key=\"{}\" title=\"{}\">",
            escape(&self.key),
            escape(&title)
        );
        if !prefix.is_empty() {
            let _ = write!(out, "<span class=\"pre\">{}</span>", escape(&prefix));
        }
        // Break long names after dots.
        out.push_str(&breakable(&name));
        if !mark.is_empty() {
            let _ = write!(out, " <span class=\"dir\">{}</span>", escape(&mark));
        }
        let _ = write!(out, "<span class=\"unit\">{}</span></th>", escape(&unit));
    }
}

/// The columns after `run`, in page order.
fn columns(t: &Table, any_previews: bool) -> Vec<Column> {
    let mut cols = vec![Column {
        key: "previews".into(),
        source: Source::Previews,
        group: Group::Run,
        meta: None,
        shown: any_previews,
    }];
    cols.extend(t.override_columns.iter().map(|p| Column {
        key: p.clone(),
        source: Source::Override,
        group: Group::Parameter,
        meta: None,
        shown: true,
    }));
    let fixed = &FIXED_COLUMNS[1..];
    let keys: Vec<String> = fixed
        .iter()
        .map(|s| s.to_string())
        .chain(t.metric_columns.iter().cloned())
        .collect();
    for key in page_order(&keys) {
        let source = match key.as_str() {
            "status" => Source::Status,
            "exit_code" => Source::ExitCode,
            "reason" => Source::Reason,
            "error" => Source::Error,
            "wall_seconds" => Source::Wall,
            _ => Source::Metric,
        };
        cols.push(Column {
            group: group(&key),
            meta: column_meta(&key),
            shown: shown_by_default(&key, &keys),
            source,
            key,
        });
    }
    cols
}

/// The best value of a column among the runs that finished, when its
/// direction has one and at least two runs have a finite value.
fn best_value(col: &Column, rows: &[RunRow]) -> Option<f64> {
    let direction = col.meta?.direction;
    let values: Vec<f64> = rows
        .iter()
        .filter(|r| r.status == "ok")
        .filter_map(|r| col.value(r)?.as_f64())
        .filter(|v| v.is_finite())
        .collect();
    if values.len() < 2 {
        return None;
    }
    let mut best = values[0];
    for &v in &values[1..] {
        if direction.better(v, best)? == std::cmp::Ordering::Less {
            best = v;
        }
    }
    Some(best)
}

/// The column chooser: one checkbox per column, grouped.
fn chooser(out: &mut String, cols: &[Column]) {
    let shown = 1 + cols.iter().filter(|c| c.shown).count();
    let _ = write!(
        out,
        "<details class=\"chooser\"><summary>Columns: <span id=\"ncols\">{shown} of {}</span> shown (choose)</summary><div class=\"panel\">\
         <div class=\"actions\"><button type=\"button\" data-act=\"default\">defaults</button>\
         <button type=\"button\" data-act=\"all\">all</button>\
         <button type=\"button\" data-act=\"none\">parameters only</button>\
         <span class=\"hint\">The choice is kept in the address (#cols=…) and in this browser.</span></div>",
        cols.len() + 1
    );
    for g in [
        Group::Run,
        Group::Parameter,
        Group::Quality,
        Group::TimeMemory,
        Group::Other,
    ] {
        if !cols.iter().any(|c| c.group == g) {
            continue;
        }
        let _ = write!(
            out,
            "<fieldset data-group=\"{}\"><legend>{}</legend>",
            g.slug(),
            escape(g.title())
        );
        for (i, c) in cols.iter().enumerate().filter(|(_, c)| c.group == g) {
            let mark = c.meta.map(|m| m.direction.mark()).unwrap_or_default();
            let (prefix, name) = label(&c.key);
            let text = [prefix.as_str(), name.as_str(), mark.as_str()]
                .iter()
                .filter(|s| !s.is_empty())
                .copied()
                .collect::<Vec<_>>()
                .join(" ");
            let _ = write!(
                out,
                "<label title=\"{k}\"><input type=\"checkbox\" data-col=\"{}\" data-def=\"{d}\" value=\"{k}\"{checked}> {}</label>",
                i + 1,
                escape(&text),
                k = escape(&c.key),
                d = u8::from(c.shown),
                checked = if c.shown { " checked" } else { "" },
            );
        }
        out.push_str("</fieldset>");
    }
    out.push_str("</div></details>\n");
}

/// A style element (for the head) hiding the columns not shown by default;
/// the script keeps it in step with the chooser's boxes.
fn hidden_columns_style(out: &mut String, cols: &[Column]) {
    out.push_str("<style id=\"colvis\">\n");
    for (i, _) in cols.iter().enumerate().filter(|(_, c)| !c.shown) {
        let _ = writeln!(out, "#runs tr > :nth-child({}) {{ display: none; }}", i + 2);
    }
    out.push_str("</style>\n");
}

/// Escaped text that may wrap after `.`, `_` and `=` unless a digit
/// follows (long dotted keys and run names; `0.2` stays whole).
fn breakable(text: &str) -> String {
    let mut out = String::with_capacity(text.len() * 2);
    let mut chars = text.chars().peekable();
    while let Some(c) = chars.next() {
        out.push_str(&escape(c.encode_utf8(&mut [0; 4])));
        let next = chars.peek().copied();
        if matches!(c, '.' | '_' | '=') && next.is_some_and(|n| !n.is_ascii_digit() && n != '_') {
            out.push_str("<wbr>");
        }
    }
    out
}

/// The run cell: folder link, 3D viewer link, status badge and log.
fn run_cell(out: &mut String, r: &RunRow) {
    let _ = write!(
        out,
        "<td class=\"c-run\" data-v=\"{n}\"><a href=\"{u}/\">{}</a>",
        breakable(&r.name),
        n = escape(&r.name),
        u = escape(&url_path(&r.name))
    );
    if let Some(v) = &r.viewer {
        let _ = write!(
            out,
            "<a class=\"v3d\" href=\"{}\" title=\"3D viewer of the result\">3D</a>",
            escape(&url_path(v))
        );
    }
    if r.status != "ok" {
        let _ = write!(
            out,
            " <span class=\"badge\">{}</span> <span class=\"why\">{}</span>",
            escape(&r.status),
            escape(&r.reason)
        );
    }
    if !r.log_tail.is_empty() || r.status != "ok" {
        let _ = write!(
            out,
            "<details class=\"log\"><summary>log</summary><pre>{}</pre><a href=\"{}\">log.txt</a></details>",
            escape(&r.log_tail.join("\n")),
            escape(&url_path(&format!("{}/{LOG}", r.name)))
        );
    }
    out.push_str("</td>");
}

/// The page. `exemplars` are `(file, caption)` inside the sweep folder.
pub fn render(
    rows: &[RunRow],
    t: &Table,
    record: Option<&SweepRecord>,
    exemplars: &[(String, String)],
) -> String {
    let mut s = String::new();
    let title = record.map_or_else(
        || "surfsynth sweep".to_string(),
        |r| format!("surfsynth sweep: {}", r.config),
    );
    let _ = write!(
        s,
        "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n\
         <meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n\
         <title>{}</title>\n<style>{STYLE}</style>\n",
        escape(&title),
    );
    let cols = columns(t, rows.iter().any(|r| !r.previews.is_empty()));
    hidden_columns_style(&mut s, &cols);
    s.push_str("</head>\n<body>\n<div class=\"top\">\n");
    if !exemplars.is_empty() {
        s.push_str("<div class=\"exemplars\">\n");
        for (file, caption) in exemplars {
            let _ = writeln!(
                s,
                "<figure><a href=\"{u}\"><img src=\"{u}\" alt=\"exemplar\"></a><figcaption>exemplar: {c}</figcaption></figure>",
                u = escape(&url_path(file)),
                c = escape(caption)
            );
        }
        s.push_str("</div>\n");
    }
    let _ = write!(s, "<div>\n<h1>{}</h1>\n", escape(&title));
    let ok = rows.iter().filter(|r| r.status == "ok").count();
    let failed = rows.iter().filter(|r| r.status == "failed").count();
    let incomplete = rows.len() - ok - failed;
    s.push_str("<div class=\"meta\">");
    if let Some(r) = record {
        for g in &r.grid {
            let _ = write!(s, "<code>--grid {}</code> ", escape(g));
        }
        for f in &r.fixed {
            let _ = write!(s, "<code>--set {}</code> ", escape(f));
        }
        let _ = write!(s, "<br>grid of {} runs; ", r.total_runs);
    }
    let _ = write!(
        s,
        "{} run folders here: {ok} ok, {failed} failed, {incomplete} incomplete.",
        rows.len()
    );
    if let Some(inv) = record.and_then(|r| r.last_invocation.as_ref()) {
        let _ = write!(
            s,
            "<br>last invocation (shard {}): {} ran, {} skipped, {} failed in {:.2} s with {} jobs × {} threads",
            escape(&inv.shard),
            inv.ran,
            inv.skipped,
            inv.failed,
            inv.wall_seconds,
            inv.jobs,
            inv.threads
        );
        if let Some(o) = inv.overhead_per_run_seconds {
            let _ = write!(s, "; sweep overhead {:.0} ms per run", o * 1000.0);
        }
        s.push('.');
    }
    s.push_str("</div>\n");
    s.push_str(
        "<div class=\"hint\">Click a header to sort (again to reverse); hover it for its unit and meaning. \
         <b>\u{2193}</b> lower is better, <b>\u{2191}</b> higher, <b>\u{2192}1</b> nearest 1, \
         <b>\u{2264}2</b> at most 2; the best finished run of a column is in green. \
         docs/metrics.md explains the measures. Thumbnails open the full image, a run name its folder, \
         <b>3D</b> its viewer. summary.csv and summary.json hold every column.</div>\n",
    );
    chooser(&mut s, &cols);
    s.push_str("</div>\n</div>\n");
    s.push_str("<div class=\"wrap\"><table id=\"runs\">\n<thead><tr>");
    s.push_str(
        "<th class=\"c-run g-run\" data-key=\"run\" title=\"run folder (its name lists the swept values)\">run<span class=\"unit\">folder</span></th>",
    );
    let mut previous = Group::Run;
    for (i, c) in cols.iter().enumerate() {
        c.header(&mut s, i > 0 && c.group != previous);
        previous = c.group;
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    let best: Vec<Option<f64>> = cols.iter().map(|c| best_value(c, rows)).collect();
    for (i, r) in rows.iter().enumerate() {
        let _ = write!(s, "<tr class=\"{}\" data-i=\"{i}\">", escape(&r.status));
        run_cell(&mut s, r);
        let mut previous = Group::Run;
        for (c, best) in cols.iter().zip(&best) {
            let start = c.group != previous;
            previous = c.group;
            if matches!(c.source, Source::Previews) {
                let _ = write!(s, "<td class=\"c-prev\" data-v=\"{}\">", r.previews.len());
                for p in &r.previews {
                    let _ = write!(
                        s,
                        "<a href=\"{u}\"><img src=\"{u}\" loading=\"lazy\" alt=\"{a}\"></a>",
                        u = escape(&url_path(p)),
                        a = escape(p)
                    );
                }
                s.push_str("</td>");
                continue;
            }
            let v = c.value(r);
            let is_best = r.status == "ok"
                && matches!((best, v.as_ref().and_then(Value::as_f64)), (Some(b), Some(x)) if x == *b);
            cell(&mut s, v.as_ref(), is_best, start);
        }
        s.push_str("</tr>\n");
    }
    let _ = write!(
        s,
        "</tbody>\n</table></div>\n<script>{SCRIPT}</script>\n</body>\n</html>\n"
    );
    s
}

/// An override value as a cell: numbers sort numerically.
fn override_cell(v: &str) -> Value {
    match v.trim().parse::<f64>() {
        Ok(f) if f.is_finite() => serde_json::Number::from_f64(f)
            .map(Value::Number)
            .unwrap_or_else(|| Value::String(v.to_string())),
        _ => Value::String(v.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_and_urls_are_escaped() {
        assert_eq!(
            escape(r#"<a href="x">&'"#),
            "&lt;a href=&quot;x&quot;&gt;&amp;&#39;"
        );
        assert_eq!(url_path("seed=1__x=a b/p.png"), "seed%3D1__x%3Da%20b/p.png");
    }

    #[test]
    fn page_escapes_run_text_and_has_one_row_per_run() {
        let row = |name: &str, status: &str| RunRow {
            name: name.into(),
            index: 0,
            status: status.into(),
            exit_code: Some(2),
            reason: "exit 2".into(),
            wall_seconds: Some(0.5),
            overrides: vec![("input.mesh".into(), "<script>alert(1)</script>".into())],
            metrics: vec![],
            previews: vec![format!("{name}/preview_0.png")],
            log_tail: vec!["error: <bad> & worse".into()],
            viewer: None,
        };
        let rows = [row("a", "failed"), row("b", "ok")];
        let t = super::super::summary::table(&rows);
        let page = render(
            &rows,
            &t,
            None,
            &[("exemplar_1.png".into(), "builtin:bricks".into())],
        );
        assert!(!page.contains("<script>alert"), "unescaped override");
        assert!(page.contains("&lt;script&gt;alert(1)&lt;/script&gt;"));
        assert!(page.contains("error: &lt;bad&gt; &amp; worse"));
        assert_eq!(page.matches("<tr class=").count(), 2);
        assert!(
            page.contains("src=\"a/preview_0.png\"") && page.contains("src=\"exemplar_1.png\"")
        );
        assert!(
            !page.contains("http://") && !page.contains("https://"),
            "no network"
        );
    }

    fn header_cells(page: &str) -> Vec<&str> {
        let head = &page[page.find("<thead>").unwrap()..page.find("</thead>").unwrap()];
        head.split("<th ").skip(1).collect()
    }

    #[test]
    fn page_orders_quality_first_labels_every_header_and_links_3d_viewers() {
        let m = serde_json::json!({
            "total_seconds": 1.5,
            "peak_rss_bytes": 10485760,
            "input": {"vertices": 10, "faces": 16},
            "result": {"mesh": {"vertices": 12, "faces": 20},
                       "quality": {"texture_energy": {"mean": 0.25, "p90": 0.5, "samples": 1000},
                                   "coherence": {"mean": 0.000367, "p90": 0.5},
                                   "completeness": 0.1, "sharpness": 0.9, "structure": 0.2,
                                   "histogram": 0.05,
                                   "verbatim": {"source_coverage": 0.7, "large_region_repeats": 1,
                                                "largest_region": 40}}},
            "stages": [{"index": 2, "kind": "jump_map", "seconds": 1.0,
                        "metrics": {"pca_components": 7}}],
        });
        let row = |name: &str, viewer: bool, sharpness: f64| {
            let mut m = m.clone();
            m["result"]["quality"]["sharpness"] = sharpness.into();
            RunRow {
                name: name.into(),
                index: 0,
                status: "ok".into(),
                exit_code: Some(0),
                reason: "ok".into(),
                wall_seconds: Some(2.0),
                overrides: vec![("seed".into(), "1".into())],
                metrics: super::super::summary::flatten_metrics(&m),
                previews: vec![format!("{name}/preview_0.png")],
                log_tail: vec![],
                viewer: viewer.then(|| format!("{name}/view.html")),
            }
        };
        let rows = [row("seed=1 a", true, 0.9), row("seed=2", false, 1.2)];
        let t = super::super::summary::table(&rows);
        let page = render(&rows, &t, None, &[]);

        // Sticky run and thumbnail columns, sticky header, a scroll box.
        assert!(page.contains(".c-run { position: sticky; left: 0;"));
        assert!(page.contains(".c-prev { position: sticky; left: var(--prev-left"));
        assert!(page.contains("position: sticky; top: 0;"));
        assert!(page.contains(".wrap { flex: 1 1 auto; min-height: 0; overflow: auto;"));

        // Order: run, thumbnails, parameters, quality, time & memory, rest.
        let heads = header_cells(&page);
        let keys: Vec<&str> = heads
            .iter()
            .map(|h| {
                h.split("data-key=\"")
                    .nth(1)
                    .unwrap()
                    .split('"')
                    .next()
                    .unwrap()
            })
            .collect();
        let at = |k: &str| {
            keys.iter()
                .position(|x| *x == k)
                .unwrap_or_else(|| panic!("{k}"))
        };
        assert_eq!(&keys[..3], ["run", "previews", "seed"]);
        assert_eq!(keys[3], "quality.coherence.mean");
        let last_quality = keys
            .iter()
            .rposition(|k| k.starts_with("quality."))
            .unwrap();
        assert!(last_quality < at("run_seconds") && at("run_seconds") < at("time.s2.jump_map"));
        assert!(
            at("time.s2.jump_map") < at("status")
                && at("status") < at("s2.jump_map.pca_components")
        );

        // Every header has a unit line and a tooltip; known measures say
        // which way is better, in the header and in the tooltip.
        for h in &heads {
            assert!(
                h.contains("<span class=\"unit\">") && h.contains("title=\""),
                "{h}"
            );
        }
        let sharp = heads
            .iter()
            .find(|h| h.contains("data-key=\"quality.sharpness\""))
            .unwrap();
        assert!(
            sharp.contains("<span class=\"dir\">→1</span>")
                && sharp.contains("ratio, best near 1)"),
            "{sharp}"
        );
        let coh = heads
            .iter()
            .find(|h| h.contains("data-key=\"quality.coherence.mean\""))
            .unwrap();
        assert!(
            coh.contains("↓")
                && coh.contains("(MSE, lower is better)")
                && coh.contains(">MSE</span>")
        );
        let rss = heads
            .iter()
            .find(|h| h.contains("data-key=\"peak_rss_mib\""))
            .unwrap();
        assert!(rss.contains(">MiB</span>") && rss.contains("lower is better"));

        // The chooser: a checkbox per column after `run`, grouped; the
        // defaults hide the rest with one rule each.
        assert!(page.contains("<details class=\"chooser\">"));
        assert!(page.find("<style id=\"colvis\">").unwrap() < page.find("</head>").unwrap());
        for g in ["parameters", "quality", "time &amp; memory", "other"] {
            assert!(page.contains(&format!("<legend>{g}</legend>")), "{g}");
        }
        assert_eq!(
            page.matches("<input type=\"checkbox\" data-col=").count(),
            keys.len() - 1
        );
        let hidden = |k: &str| {
            page.contains(&format!(
                "#runs tr > :nth-child({}) {{ display: none; }}",
                at(k) + 1
            ))
        };
        for k in [
            "previews",
            "seed",
            "quality.coherence.mean",
            "quality.sharpness",
            "run_seconds",
            "peak_rss_mib",
        ] {
            assert!(!hidden(k), "{k} hidden by default");
        }
        for k in [
            "quality.texture_energy.mean",
            "quality.verbatim.largest_region",
            "time.s2.jump_map",
            "status",
            "input.vertices",
        ] {
            assert!(hidden(k), "{k} shown by default");
        }

        // The 3D viewer link only where the run folder holds view.html.
        assert_eq!(page.matches("class=\"v3d\"").count(), 1);
        assert!(page.contains("<a class=\"v3d\" href=\"seed%3D1%20a/view.html\""));
        // Small numbers keep their digits; the best sharpness (nearest 1) is marked.
        assert!(page.contains(">0.000367</td>"));
        assert!(page.contains("<td class=\"n best\" data-v=\"0.9\""));
        assert!(!page.contains("<td class=\"n best\" data-v=\"1.2\""));
        assert!(!page.contains("http://") && !page.contains("https://"));
    }
}
