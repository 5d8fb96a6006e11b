//! What each column of the sweep summary means: its unit, which way is
//! better, its group on the page, and whether the page shows it by default.
//! The quality rows mirror the table of `docs/metrics.md`; a test checks that
//! every measure documented there has an entry here with the same direction.

use std::cmp::Ordering;

/// Which way a column's value is better.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Direction {
    /// Lower is better.
    Lower,
    /// Higher is better.
    Higher,
    /// Closest to this value is best.
    Near(f64),
    /// Fine up to this value, bad above.
    AtMost(f64),
    /// Neither: a description, not a score.
    Neither,
}

impl Direction {
    /// A compact mark for a header: `↓`, `↑`, `→1`, `≤2`, or empty.
    pub fn mark(self) -> String {
        match self {
            Direction::Lower => "\u{2193}".into(),
            Direction::Higher => "\u{2191}".into(),
            Direction::Near(v) => format!("\u{2192}{v}"),
            Direction::AtMost(v) => format!("\u{2264}{v}"),
            Direction::Neither => String::new(),
        }
    }

    /// The same in words, for a header's tooltip.
    pub fn phrase(self) -> String {
        match self {
            Direction::Lower => "lower is better".into(),
            Direction::Higher => "higher is better".into(),
            Direction::Near(v) => format!("best near {v}"),
            Direction::AtMost(v) => format!("fine up to {v}, bad above"),
            Direction::Neither => "neither way is better".into(),
        }
    }

    /// Orders two values so that the better one comes first (`Less`); `None`
    /// for [`Direction::Neither`] and [`Direction::AtMost`] (no single best).
    pub fn better(self, a: f64, b: f64) -> Option<Ordering> {
        match self {
            Direction::Lower => a.partial_cmp(&b),
            Direction::Higher => b.partial_cmp(&a),
            Direction::Near(t) => (a - t).abs().partial_cmp(&(b - t).abs()),
            Direction::AtMost(_) | Direction::Neither => None,
        }
    }
}

/// A column's meaning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ColumnMeta {
    /// Short unit for the header (`s`, `MiB`, `MSE`, `ratio`, ...).
    pub unit: &'static str,
    /// Which way is better.
    pub direction: Direction,
    /// One line on the unit and what the column catches, for the tooltip.
    pub about: &'static str,
    /// Shown on the page unless the reader chooses otherwise.
    pub shown: bool,
}

const fn meta(
    unit: &'static str,
    direction: Direction,
    shown: bool,
    about: &'static str,
) -> ColumnMeta {
    ColumnMeta {
        unit,
        direction,
        about,
        shown,
    }
}

/// The result quality measures (`quality.<key>`, and `quality.plane.<key>`
/// for the planar image), in page order. See docs/metrics.md.
const QUALITY: &[(&str, ColumnMeta)] = &[
    (
        "coherence.mean",
        meta(
            "MSE",
            Direction::Lower,
            true,
            "texture energy, mean over result windows of the MSE to the nearest exemplar window (values in [0, 1]); catches garbage, blind to blur and flat colour",
        ),
    ),
    (
        "coherence.p90",
        meta(
            "MSE",
            Direction::Lower,
            true,
            "90th percentile of the texture energy (MSE per value, values in [0, 1]); catches seams, tears, speckle",
        ),
    ),
    (
        "completeness",
        meta(
            "MSE",
            Direction::Lower,
            true,
            "mean over exemplar windows of the MSE to the nearest result window (values in [0, 1]); catches missing content: blur, flat colour, one patch repeated",
        ),
    ),
    (
        "sharpness",
        meta(
            "ratio",
            Direction::Near(1.0),
            true,
            "Sobel gradient magnitude over the exemplar's (ratio, 1 = as sharp as the exemplar); below 1 blur, well above 1 noise",
        ),
    ),
    (
        "structure",
        meta(
            "TV dist.",
            Direction::Lower,
            true,
            "total-variation distance of the orientation histograms, in [0, 1]; catches wrong orientation or scale, lost structure; 1 for a flat result",
        ),
    ),
    (
        "histogram",
        meta(
            "W\u{2081}",
            Direction::Lower,
            true,
            "mean per-channel Wasserstein-1 distance, value units [0, 1]; catches colour drift, washed-out or inverted contrast",
        ),
    ),
    (
        "verbatim.source_coverage",
        meta(
            "fraction",
            Direction::Higher,
            true,
            "fraction of exemplar pixels used as a source, [0, 1]; catches tiling or repetition of a small part",
        ),
    ),
    (
        "verbatim.large_region_repeats",
        meta(
            "count",
            Direction::AtMost(2.0),
            true,
            "times one large piece (over a third of the exemplar) is repeated verbatim",
        ),
    ),
    (
        "verbatim.mean_region_area",
        meta(
            "px",
            Direction::Neither,
            false,
            "pixel-weighted mean area of copied regions, in result pixels: 1 = per-pixel synthesis",
        ),
    ),
    (
        "verbatim.mean_region_fraction",
        meta(
            "fraction",
            Direction::Neither,
            false,
            "mean copied-region area over the exemplar's area",
        ),
    ),
    (
        "verbatim.largest_region",
        meta(
            "px",
            Direction::Neither,
            false,
            "area of the largest verbatim copy, in result pixels",
        ),
    ),
    (
        "texture_energy.mean",
        meta(
            "MSE",
            Direction::Lower,
            false,
            "the same as coherence mean (mean squared error per value, values in [0, 1])",
        ),
    ),
    (
        "texture_energy.p90",
        meta(
            "MSE",
            Direction::Lower,
            false,
            "the same as coherence p90 (mean squared error per value, values in [0, 1])",
        ),
    ),
    (
        "texture_energy.samples",
        meta(
            "count",
            Direction::Neither,
            false,
            "result windows measured for the texture energy",
        ),
    ),
    (
        "texture_energy.neighbourhood",
        meta(
            "px",
            Direction::Neither,
            false,
            "side of the metric windows",
        ),
    ),
    (
        "texture_energy.spacing_world_units",
        meta(
            "world units",
            Direction::Neither,
            false,
            "world size of one exemplar pixel in the metric windows",
        ),
    ),
    (
        "templates.small",
        meta(
            "count",
            Direction::Neither,
            false,
            "surface templates measured for completeness and sharpness",
        ),
    ),
    (
        "templates.structure",
        meta(
            "count",
            Direction::Neither,
            false,
            "32x32 surface templates measured for structure",
        ),
    ),
];

/// Run time and memory columns, in page order.
const TIME_MEMORY: &[(&str, ColumnMeta)] = &[
    (
        "run_seconds",
        meta(
            "s",
            Direction::Lower,
            true,
            "the run's own total time (metrics.json total_seconds)",
        ),
    ),
    (
        "peak_rss_mib",
        meta(
            "MiB",
            Direction::Lower,
            true,
            "peak resident memory of the run",
        ),
    ),
    (
        "wall_seconds",
        meta(
            "s",
            Direction::Lower,
            false,
            "wall time of the child process as the sweep measured it (start-up included)",
        ),
    ),
];

/// Everything else the sweep writes itself.
const OTHER: &[(&str, ColumnMeta)] = &[
    (
        "status",
        meta("", Direction::Neither, false, "ok, failed or incomplete"),
    ),
    (
        "exit_code",
        meta(
            "",
            Direction::Neither,
            false,
            "exit code of the run's process",
        ),
    ),
    (
        "reason",
        meta("", Direction::Neither, false, "how the run ended"),
    ),
    (
        "error",
        meta(
            "",
            Direction::Neither,
            false,
            "last log line of a failed run",
        ),
    ),
    (
        "input.vertices",
        meta(
            "count",
            Direction::Neither,
            false,
            "vertices of the input mesh",
        ),
    ),
    (
        "input.faces",
        meta(
            "count",
            Direction::Neither,
            false,
            "faces of the input mesh",
        ),
    ),
    (
        "result.vertices",
        meta(
            "count",
            Direction::Neither,
            false,
            "vertices of the result mesh",
        ),
    ),
    (
        "result.faces",
        meta(
            "count",
            Direction::Neither,
            false,
            "faces of the result mesh",
        ),
    ),
];

/// A column's group on the page (the column chooser's sections).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Group {
    /// The run's previews.
    Run,
    /// Swept parameters (grid axes).
    Parameter,
    /// Result quality measures (`quality.*`).
    Quality,
    /// Times and memory.
    TimeMemory,
    /// Counts, status, per-stage metrics.
    Other,
}

impl Group {
    /// Section title in the chooser.
    pub fn title(self) -> &'static str {
        match self {
            Group::Run => "run",
            Group::Parameter => "parameters",
            Group::Quality => "quality",
            Group::TimeMemory => "time & memory",
            Group::Other => "other",
        }
    }

    /// A CSS-friendly name.
    pub fn slug(self) -> &'static str {
        match self {
            Group::Run => "run",
            Group::Parameter => "param",
            Group::Quality => "quality",
            Group::TimeMemory => "time",
            Group::Other => "other",
        }
    }
}

/// `quality.plane.coherence_mean` → (`true`, `coherence.mean`);
/// `quality.sharpness` → (`false`, `sharpness`); `None` outside `quality.`.
fn quality_key(key: &str) -> Option<(bool, String)> {
    let rest = key.strip_prefix("quality.")?;
    let (plane, rest) = match rest.strip_prefix("plane.") {
        Some(r) => (true, r),
        None => (false, rest),
    };
    // The planar image's measures are the fields of `ImageQuality`.
    Some((plane, rest.replacen("coherence_", "coherence.", 1)))
}

fn lookup(table: &[(&str, ColumnMeta)], key: &str) -> Option<(usize, ColumnMeta)> {
    table
        .iter()
        .position(|(k, _)| *k == key)
        .map(|i| (i, table[i].1))
}

/// The unit, direction and description of a summary column (a metric column
/// name, a fixed column, `time.s<i>.<kind>`); `None` when unknown (a
/// stage's own metrics, swept parameters).
pub fn column_meta(key: &str) -> Option<ColumnMeta> {
    if let Some((_, k)) = quality_key(key) {
        return lookup(QUALITY, &k).map(|(_, m)| m);
    }
    if key.starts_with("time.s") {
        return Some(meta(
            "s",
            Direction::Lower,
            false,
            "time of this stage of the run",
        ));
    }
    lookup(TIME_MEMORY, key)
        .or_else(|| lookup(OTHER, key))
        .map(|(_, m)| m)
}

/// The group of a metric or fixed column (parameters are the caller's).
pub fn group(key: &str) -> Group {
    if key.starts_with("quality.") {
        Group::Quality
    } else if key.starts_with("time.") || lookup(TIME_MEMORY, key).is_some() {
        Group::TimeMemory
    } else {
        Group::Other
    }
}

/// Page order of metric and fixed columns: by group; quality measures in
/// the order of the table above (the surface's, then the planar image's,
/// then unknown ones); times and memory likewise. Ties keep `keys`' order.
pub fn page_order(keys: &[String]) -> Vec<String> {
    let rank = |key: &str| -> (Group, usize, usize) {
        let g = group(key);
        let far = usize::MAX;
        match g {
            Group::Quality => match quality_key(key) {
                Some((plane, k)) => match lookup(QUALITY, &k) {
                    Some((i, _)) => (g, usize::from(plane), i),
                    None => (g, 2, far),
                },
                None => (g, 2, far),
            },
            Group::TimeMemory => (g, 0, lookup(TIME_MEMORY, key).map_or(far, |(i, _)| i)),
            _ => (g, 0, lookup(OTHER, key).map_or(far, |(i, _)| i)),
        }
    };
    let mut out = keys.to_vec();
    out.sort_by_key(|k| rank(k));
    out
}

/// Whether the page shows a metric or fixed column by default, given every
/// column present: the scoring quality measures (of the planar image when a
/// run measured one, else of the surface), total seconds, peak memory.
pub fn shown_by_default(key: &str, present: &[String]) -> bool {
    let Some(m) = column_meta(key) else {
        return false;
    };
    if let Some((plane, _)) = quality_key(key) {
        let any_plane = present.iter().any(|k| k.starts_with("quality.plane."));
        return m.shown && plane == any_plane;
    }
    m.shown
}

/// A compact header label: `quality.` dropped, `_` as spaces, the last
/// part of the key as the name and the rest as a prefix (`plane verbatim`).
pub fn label(key: &str) -> (String, String) {
    let k = match quality_key(key) {
        Some((plane, k)) if plane => format!("plane.{k}"),
        Some((_, k)) => k,
        None => key.to_string(),
    };
    let k = k.replace('_', " ");
    let parts: Vec<&str> = k.split('.').collect();
    match parts.as_slice() {
        [.., "mean" | "p90"] if parts.len() >= 2 => {
            let n = parts.len();
            (parts[..n - 2].join(" "), parts[n - 2..].join(" "))
        }
        [rest @ .., last] => (rest.join(" "), (*last).to_string()),
        [] => (String::new(), String::new()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `better` column of docs/metrics.md in this module's terms.
    fn documented_direction(text: &str) -> Direction {
        match text.trim() {
            "lower" => Direction::Lower,
            "higher" => Direction::Higher,
            "—" => Direction::Neither,
            t => {
                if let Some(v) = t.strip_prefix("near ") {
                    Direction::Near(v.trim().parse().expect("near <number>"))
                } else if let Some(v) = t.strip_prefix("≤ ") {
                    Direction::AtMost(v.trim().parse().expect("≤ <number>"))
                } else {
                    panic!("docs/metrics.md: unknown direction {t:?}; teach src/sweep/columns.rs")
                }
            }
        }
    }

    #[test]
    fn every_quality_measure_in_docs_metrics_md_has_its_unit_and_direction() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/metrics.md");
        let text = std::fs::read_to_string(path).expect("docs/metrics.md");
        let mut checked = 0;
        for line in text.lines().filter(|l| l.starts_with("| `")) {
            let cells: Vec<&str> = line.split('|').map(str::trim).collect();
            // "", key(s), unit, better, what it catches, ""
            assert!(cells.len() >= 5, "{line}");
            let direction = documented_direction(cells[3]);
            let keys: Vec<&str> = cells[1].split('`').skip(1).step_by(2).collect();
            assert!(!keys.is_empty(), "{line}");
            for key in keys {
                for column in [
                    format!("quality.{key}"),
                    format!(
                        "quality.plane.{}",
                        key.replacen("coherence.", "coherence_", 1)
                    ),
                ] {
                    let m = column_meta(&column)
                        .unwrap_or_else(|| panic!("{column} (docs/metrics.md) has no entry"));
                    assert_eq!(m.direction, direction, "{column}");
                    assert!(!m.unit.is_empty() && !m.about.is_empty(), "{column}");
                    assert_eq!(group(&column), Group::Quality);
                    checked += 1;
                }
            }
        }
        assert!(checked >= 20, "read {checked} columns from docs/metrics.md");
    }

    #[test]
    fn columns_are_ordered_quality_then_time_then_the_rest() {
        let keys: Vec<String> = [
            "run_seconds",
            "input.vertices",
            "quality.texture_energy.mean",
            "quality.sharpness",
            "time.s2.jump_map",
            "s2.jump_map.boundary",
            "peak_rss_mib",
            "quality.plane.coherence_mean",
            "quality.coherence.mean",
            "status",
        ]
        .map(String::from)
        .to_vec();
        assert_eq!(
            page_order(&keys),
            [
                "quality.coherence.mean",
                "quality.sharpness",
                "quality.texture_energy.mean",
                "quality.plane.coherence_mean",
                "run_seconds",
                "peak_rss_mib",
                "time.s2.jump_map",
                "status",
                "input.vertices",
                "s2.jump_map.boundary",
            ]
        );
        assert!(shown_by_default("quality.plane.coherence_mean", &keys));
        assert!(!shown_by_default("quality.coherence.mean", &keys));
        assert!(shown_by_default("quality.coherence.mean", &keys[..3]));
        assert!(!shown_by_default("quality.texture_energy.mean", &keys[..3]));
        assert!(shown_by_default("peak_rss_mib", &keys));
        assert!(!shown_by_default("s2.jump_map.boundary", &keys));
    }

    #[test]
    fn labels_and_marks_are_compact() {
        assert_eq!(
            label("quality.coherence.p90"),
            (String::new(), "coherence p90".into())
        );
        assert_eq!(
            label("quality.plane.coherence_mean"),
            ("plane".into(), "coherence mean".into())
        );
        assert_eq!(
            label("quality.verbatim.source_coverage"),
            ("verbatim".into(), "source coverage".into())
        );
        assert_eq!(label("run_seconds"), (String::new(), "run seconds".into()));
        assert_eq!(Direction::Near(1.0).mark(), "→1");
        assert_eq!(Direction::AtMost(2.0).mark(), "≤2");
        assert_eq!(Direction::Near(1.0).better(0.9, 1.2), Some(Ordering::Less));
    }
}
