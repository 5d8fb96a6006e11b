//! `index.html`: one self-contained page (inline CSS and JS, no network)
//! with the exemplar, every run's previews as thumbnails linking to the
//! full images, and the metrics in a table that sorts by any column header
//! (numerically when every value of the column is a number).

use super::SweepRecord;
use super::summary::{FIXED_COLUMNS, RunRow, Table, cell_text};
use serde_json::Value;
use std::fmt::Write;

/// Escapes text for HTML element content and quoted attribute values.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            _ => out.push(c),
        }
    }
    out
}

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

fn number_display(v: f64) -> String {
    if v == v.trunc() && v.abs() < 1e15 {
        format!("{v:.0}")
    } else if v.abs() >= 1000.0 {
        format!("{v:.1}")
    } else if v.abs() >= 1.0 {
        format!("{v:.3}")
    } else {
        format!("{v:.4}")
    }
}

/// A `<td>` whose `data-v` holds the exact value the table sorts on.
fn cell(out: &mut String, v: Option<&Value>) {
    match v {
        Some(Value::Number(n)) => {
            let f = n.as_f64().unwrap_or(0.0);
            let _ = write!(
                out,
                "<td class=\"n\" data-v=\"{}\" title=\"{}\">{}</td>",
                escape(&n.to_string()),
                escape(&n.to_string()),
                escape(&number_display(f))
            );
        }
        Some(v) => {
            let t = cell_text(v);
            let _ = write!(out, "<td data-v=\"{}\">{}</td>", escape(&t), escape(&t));
        }
        None => out.push_str("<td data-v=\"\"></td>"),
    }
}

const STYLE: &str = r#"
body { font: 14px/1.4 system-ui, sans-serif; margin: 1.5em; color: #222; background: #fafafa; }
h1 { font-size: 1.4em; margin: 0 0 .3em; }
.meta { color: #555; margin-bottom: 1em; }
.meta code { background: #eee; padding: 0 .3em; border-radius: 3px; }
.exemplars { display: flex; gap: 1em; flex-wrap: wrap; margin-bottom: 1em; }
.exemplars figure { margin: 0; text-align: center; }
.exemplars img { width: 128px; height: 128px; image-rendering: pixelated; border: 1px solid #ccc; }
.exemplars figcaption { font-size: 12px; color: #555; max-width: 220px; }
.wrap { overflow-x: auto; }
table { border-collapse: collapse; background: #fff; }
th, td { border: 1px solid #ddd; padding: 3px 6px; white-space: nowrap; vertical-align: middle; }
th { background: #f0f0f0; cursor: pointer; position: sticky; top: 0; user-select: none; }
th:hover { background: #e4e4ff; }
th.asc::after { content: " \25B2"; } th.desc::after { content: " \25BC"; }
td.n { text-align: right; font-variant-numeric: tabular-nums; }
td.previews img { height: 96px; width: 96px; object-fit: contain; margin-right: 2px; background: #fff; }
tr.failed td { background: #fff0f0; } tr.incomplete td { background: #fffbe6; }
td.status-ok { color: #176d22; } td.status-failed { color: #b00020; font-weight: bold; }
details pre { margin: .3em 0 0; font-size: 12px; white-space: pre-wrap; max-width: 40em; }
.hint { color: #777; font-size: 12px; }
"#;

const SCRIPT: &str = r#"
(function () {
  var table = document.getElementById('runs');
  var body = table.tBodies[0];
  var headers = table.tHead.rows[0].cells;
  function value(row, col) { var c = row.cells[col]; return c ? (c.getAttribute('data-v') || '') : ''; }
  Array.prototype.forEach.call(headers, function (th, col) {
    th.addEventListener('click', function () {
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
})();
"#;

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
         <title>{}</title>\n<style>{STYLE}</style>\n</head>\n<body>\n<h1>{}</h1>\n",
        escape(&title),
        escape(&title)
    );
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
    s.push_str(
        "<p class=\"hint\">Click a column header to sort (again to reverse). \
         Click a thumbnail for the full image, a run name for its folder. \
         summary.csv and summary.json hold the same table.</p>\n",
    );
    s.push_str("<div class=\"wrap\"><table id=\"runs\">\n<thead><tr>");
    let headers = ["run", "previews"]
        .into_iter()
        .chain(FIXED_COLUMNS[1..].iter().copied())
        .map(str::to_string)
        .chain(t.override_columns.iter().cloned())
        .chain(t.metric_columns.iter().cloned());
    for h in headers {
        let _ = write!(s, "<th>{}</th>", escape(&h));
    }
    s.push_str("</tr></thead>\n<tbody>\n");
    for (i, r) in rows.iter().enumerate() {
        let _ = write!(s, "<tr class=\"{}\" data-i=\"{i}\">", escape(&r.status));
        let _ = write!(
            s,
            "<td data-v=\"{n}\"><a href=\"{u}/\">{n}</a></td>",
            n = escape(&r.name),
            u = escape(&url_path(&r.name))
        );
        let _ = write!(s, "<td class=\"previews\" data-v=\"{}\">", r.previews.len());
        for p in &r.previews {
            let _ = write!(
                s,
                "<a href=\"{u}\"><img src=\"{u}\" loading=\"lazy\" alt=\"{a}\"></a>",
                u = escape(&url_path(p)),
                a = escape(p)
            );
        }
        s.push_str("</td>");
        let _ = write!(
            s,
            "<td class=\"status-{c}\" data-v=\"{c}\">{c}",
            c = escape(&r.status)
        );
        if !r.log_tail.is_empty() || r.status != "ok" {
            let _ = write!(
                s,
                "<details><summary>log</summary><pre>{}</pre><a href=\"{}\">log.txt</a></details>",
                escape(&r.log_tail.join("\n")),
                escape(&url_path(&format!("{}/log.txt", r.name)))
            );
        }
        s.push_str("</td>");
        cell(&mut s, r.exit_code.map(Value::from).as_ref());
        cell(&mut s, Some(&Value::String(r.reason.clone())));
        cell(&mut s, Some(&Value::String(r.error().to_string())));
        cell(&mut s, r.wall_seconds.map(Value::from).as_ref());
        for p in &t.override_columns {
            cell(&mut s, r.override_value(p).map(override_cell).as_ref());
        }
        for c in &t.metric_columns {
            cell(&mut s, r.metric(c));
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
}
