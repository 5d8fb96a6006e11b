//! The run list of a sweep: `--grid` parsing (bracket- and quote-aware value
//! lists), the cartesian product in a fixed order, readable unique folder
//! names, and `--shard I/N` selection.

use super::SweepError;

/// One `--grid PATH=V1,V2,...` axis.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GridAxis {
    /// Dotted TOML path, as for `--set` (`seed`, `stage.2.iterations`).
    pub path: String,
    /// The values as TOML text (or bare strings), in the order given.
    pub values: Vec<String>,
}

/// One run of the sweep.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PlannedRun {
    /// Position in the full (unsharded) run list, from 0.
    pub index: usize,
    /// Folder name: `path=value` per axis joined by `__`, sanitised.
    pub name: String,
    /// `(path, value)` per axis, in axis order.
    pub overrides: Vec<(String, String)>,
}

impl PlannedRun {
    /// The overrides as `PATH=VALUE` assignments for `--set`.
    pub fn assignments(&self) -> Vec<String> {
        self.overrides
            .iter()
            .map(|(p, v)| format!("{p}={v}"))
            .collect()
    }
}

/// `--shard I/N`: the runs whose index is `I-1` modulo `N`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    /// 1-based shard number, `1..=count`.
    pub index: usize,
    /// Number of shards, at least 1.
    pub count: usize,
}

impl Shard {
    /// Parses `I/N` with `1 <= I <= N`.
    pub fn parse(text: &str) -> Result<Self, SweepError> {
        let err = |message: String| SweepError::Shard {
            arg: text.to_string(),
            message,
        };
        let (i, n) = text
            .split_once('/')
            .ok_or_else(|| err("expected I/N, e.g. --shard 2/4 (shards count from 1)".into()))?;
        let parse = |s: &str, what: &str| {
            s.trim().parse::<usize>().map_err(|_| {
                err(format!(
                    "{what} {s:?} is not a whole number; expected I/N with 1 <= I <= N"
                ))
            })
        };
        let index = parse(i, "I")?;
        let count = parse(n, "N")?;
        if count == 0 {
            return Err(err("N must be at least 1".into()));
        }
        if index == 0 || index > count {
            return Err(err(format!(
                "I = {index} is out of range; allowed: 1..={count} (shards count from 1)"
            )));
        }
        Ok(Self { index, count })
    }

    /// Whether run `index` (0-based, full list) belongs to this shard.
    pub fn contains(&self, index: usize) -> bool {
        index % self.count == self.index - 1
    }
}

/// Parses one `--grid PATH=V1,V2,...` argument.
///
/// Values are separated by commas outside brackets (`[...]`, `{...}`) and
/// quotes (`"..."`, `'...'`), so TOML arrays and strings may contain commas:
/// `stage.2.neighbourhoods=[9,5,3],[7,3]`. In a bare value, `\,` is a literal
/// comma and `\\` a backslash. Each value is then parsed exactly like a
/// `--set` value (TOML, else a string).
pub fn parse_grid(arg: &str) -> Result<GridAxis, SweepError> {
    let err = |message: String| SweepError::Grid {
        arg: arg.to_string(),
        message,
    };
    let (path, list) = arg.split_once('=').ok_or_else(|| {
        err(
            "expected PATH=V1,V2,..., e.g. --grid seed=1,2,3 or --grid stage.2.iterations=10,30"
                .into(),
        )
    })?;
    let path = path.trim();
    if path.is_empty() {
        return Err(err(
            "PATH is empty; expected a dotted config path such as seed or stage.2.iterations"
                .into(),
        ));
    }
    if path.split('.').any(|s| s.trim().is_empty()) {
        return Err(err(format!("PATH {path:?} has an empty segment")));
    }
    let values = split_values(list).map_err(err)?;
    for (i, v) in values.iter().enumerate() {
        if values[..i].contains(v) {
            return Err(err(format!("value {v:?} is given twice")));
        }
    }
    Ok(GridAxis {
        path: path.to_string(),
        values,
    })
}

/// Splits a value list at top-level commas (see [`parse_grid`]).
fn split_values(list: &str) -> Result<Vec<String>, String> {
    let mut values = Vec::new();
    let mut cur = String::new();
    let mut depth: Vec<char> = Vec::new();
    let mut quote: Option<char> = None;
    let mut chars = list.chars().peekable();
    let push = |cur: &mut String, values: &mut Vec<String>| -> Result<(), String> {
        let v = cur.trim().to_string();
        if v.is_empty() {
            return Err(format!(
                "value {} is empty (two commas in a row, or a comma at either end); \
                 write an empty string as \"\"",
                values.len() + 1
            ));
        }
        values.push(v);
        cur.clear();
        Ok(())
    };
    while let Some(c) = chars.next() {
        if let Some(q) = quote {
            cur.push(c);
            if c == '\\' && q == '"' {
                if let Some(n) = chars.next() {
                    cur.push(n);
                }
            } else if c == q {
                quote = None;
            }
            continue;
        }
        match c {
            '"' | '\'' => {
                quote = Some(c);
                cur.push(c);
            }
            '[' | '{' => {
                depth.push(c);
                cur.push(c);
            }
            ']' | '}' => {
                let open = if c == ']' { '[' } else { '{' };
                if depth.pop() != Some(open) {
                    return Err(format!("unbalanced {c:?} in value {}", values.len() + 1));
                }
                cur.push(c);
            }
            '\\' if depth.is_empty() => match chars.peek() {
                Some(&n) if n == ',' || n == '\\' => {
                    cur.push(n);
                    chars.next();
                }
                _ => cur.push(c),
            },
            ',' if depth.is_empty() => push(&mut cur, &mut values)?,
            _ => cur.push(c),
        }
    }
    if let Some(q) = quote {
        return Err(format!(
            "unclosed quote {q:?} in value {}",
            values.len() + 1
        ));
    }
    if let Some(open) = depth.last() {
        return Err(format!("unclosed {open:?} in value {}", values.len() + 1));
    }
    push(&mut cur, &mut values)?;
    Ok(values)
}

/// Longest value part of a folder name before it is shortened.
const MAX_VALUE_CHARS: usize = 40;
/// Longest folder name.
const MAX_NAME_CHARS: usize = 180;

fn short_hash(text: &str) -> String {
    blake3::hash(text.as_bytes()).to_hex()[..6].to_string()
}

/// A value as it appears in a folder name: letters, digits and `. + -`
/// kept, brackets and quotes dropped, anything else `_`. When that changed
/// the text or it is long, a short hash of the exact value is appended
/// (`-1a2b3c`), so different values never share a name.
pub fn sanitise_value(value: &str) -> String {
    let mut out = String::new();
    for c in value.chars() {
        match c {
            'a'..='z' | 'A'..='Z' | '0'..='9' | '.' | '+' | '-' => out.push(c),
            '[' | ']' | '{' | '}' | '"' | '\'' | ' ' => {}
            _ => out.push('_'),
        }
    }
    if out == value && out.chars().count() <= MAX_VALUE_CHARS && !out.starts_with('.') {
        return out;
    }
    let kept: String = out.chars().take(MAX_VALUE_CHARS).collect();
    format!("{kept}-{}", short_hash(value))
}

fn sanitise_path(path: &str) -> String {
    path.chars()
        .map(|c| match c {
            'a'..='z' | 'A'..='Z' | '0'..='9' | '.' | '_' | '-' => c,
            _ => '_',
        })
        .collect()
}

/// The folder name of a run: `path=value` per override, joined by `__`.
pub fn run_name(overrides: &[(String, String)]) -> String {
    let name = overrides
        .iter()
        .map(|(p, v)| format!("{}={}", sanitise_path(p), sanitise_value(v)))
        .collect::<Vec<_>>()
        .join("__");
    if name.chars().count() <= MAX_NAME_CHARS {
        return name;
    }
    let kept: String = name.chars().take(MAX_NAME_CHARS).collect();
    format!("{kept}-{}", short_hash(&name))
}

/// The cartesian product of the axes: the first axis varies slowest (as
/// nested loops written in `--grid` order). Errors when an axis repeats a
/// path, or a path is also fixed by `--set`.
pub fn plan(axes: &[GridAxis], fixed: &[String]) -> Result<Vec<PlannedRun>, SweepError> {
    if axes.is_empty() {
        return Err(SweepError::Grid {
            arg: String::new(),
            message: "a sweep needs at least one --grid PATH=V1,V2,...".into(),
        });
    }
    for (i, a) in axes.iter().enumerate() {
        if axes[..i].iter().any(|b| b.path == a.path) {
            return Err(SweepError::Grid {
                arg: format!("{}=...", a.path),
                message: format!(
                    "PATH {} is given by two --grid options; merge their values",
                    a.path
                ),
            });
        }
        let fixed_here = fixed
            .iter()
            .any(|s| s.split_once('=').is_some_and(|(p, _)| p.trim() == a.path));
        if fixed_here {
            return Err(SweepError::Grid {
                arg: format!("{}=...", a.path),
                message: format!(
                    "PATH {} is also fixed by --set; give it in one place",
                    a.path
                ),
            });
        }
    }
    let total: usize = axes
        .iter()
        .try_fold(1usize, |acc, a| acc.checked_mul(a.values.len()))
        .filter(|&n| n <= 1_000_000)
        .ok_or_else(|| SweepError::Grid {
            arg: String::new(),
            message: "the grid has more than 1000000 runs".into(),
        })?;
    let mut runs = Vec::with_capacity(total);
    for index in 0..total {
        let mut rest = index;
        let mut overrides = vec![(String::new(), String::new()); axes.len()];
        for (k, axis) in axes.iter().enumerate().rev() {
            let n = axis.values.len();
            overrides[k] = (axis.path.clone(), axis.values[rest % n].clone());
            rest /= n;
        }
        runs.push(PlannedRun {
            index,
            name: run_name(&overrides),
            overrides,
        });
    }
    let mut names: Vec<&str> = runs.iter().map(|r| r.name.as_str()).collect();
    names.sort_unstable();
    if let Some(w) = names.windows(2).find(|w| w[0] == w[1]) {
        return Err(SweepError::Grid {
            arg: String::new(),
            message: format!("two runs would share the folder {:?}", w[0]),
        });
    }
    Ok(runs)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn axis(s: &str) -> GridAxis {
        parse_grid(s).unwrap()
    }

    #[test]
    fn values_split_outside_brackets_and_quotes_with_escapes() {
        assert_eq!(axis("seed=1, 2,3").values, ["1", "2", "3"]);
        assert_eq!(
            axis("stage.2.neighbourhoods=[9,5,3],[7, 3]").values,
            ["[9,5,3]", "[7, 3]"]
        );
        assert_eq!(
            axis(r#"input.mesh="a,b.obj",'c,d',e\,f"#).values,
            [r#""a,b.obj""#, "'c,d'", "e,f"]
        );
        assert_eq!(axis("x={a = [1,2]},{}").values, ["{a = [1,2]}", "{}"]);
        assert_eq!(axis(r#"x="q\",r",s"#).values, [r#""q\",r""#, "s"]);
    }

    #[test]
    fn bad_grids_name_the_problem() {
        let msg = |s: &str| parse_grid(s).unwrap_err().to_string();
        assert!(msg("seed").contains("PATH=V1,V2"), "{}", msg("seed"));
        assert!(msg("=1,2").contains("PATH is empty"));
        assert!(msg("stage..x=1").contains("empty segment"));
        assert!(
            msg("seed=1,,2").contains("value 2 is empty"),
            "{}",
            msg("seed=1,,2")
        );
        assert!(msg("seed=1,").contains("empty"));
        assert!(msg("x=[1,2").contains("unclosed '['"));
        assert!(msg("x=1],2").contains("unbalanced"));
        assert!(msg("x=\"a,b").contains("unclosed quote"));
        assert!(msg("seed=1,2,1").contains("given twice"));
    }

    #[test]
    fn product_runs_first_axis_slowest_with_readable_names() {
        let runs = plan(
            &[axis("seed=1,2"), axis("stage.2.iterations=10,30,50")],
            &[],
        )
        .unwrap();
        let names: Vec<_> = runs.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "seed=1__stage.2.iterations=10",
                "seed=1__stage.2.iterations=30",
                "seed=1__stage.2.iterations=50",
                "seed=2__stage.2.iterations=10",
                "seed=2__stage.2.iterations=30",
                "seed=2__stage.2.iterations=50",
            ]
        );
        assert_eq!(runs[4].assignments(), ["seed=2", "stage.2.iterations=30"]);
        assert!(runs.iter().enumerate().all(|(i, r)| r.index == i));
    }

    #[test]
    fn names_are_safe_and_unique_for_values_that_sanitise_alike() {
        let runs = plan(
            &[axis(r#"input.mesh="a/b.obj","a_b.obj",../x/y.off,[1,2]"#)],
            &[],
        )
        .unwrap();
        for r in &runs {
            assert!(
                r.name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || "._+-=".contains(c)),
                "{}",
                r.name
            );
            assert!(!r.name.starts_with('.'));
        }
        assert_eq!(
            runs[1].name,
            "input.mesh=a_b.obj-".to_string() + &short_hash("\"a_b.obj\"")
        );
        assert_ne!(runs[0].name, runs[1].name);
        let long = "x".repeat(300);
        let name = run_name(&[("p".into(), long.clone()), ("q".into(), long)]);
        assert!(name.len() < 255, "{}", name.len());
    }

    #[test]
    fn repeated_or_fixed_paths_are_refused() {
        let e = plan(&[axis("seed=1"), axis("seed=2")], &[]).unwrap_err();
        assert!(e.to_string().contains("two --grid"), "{e}");
        let e = plan(&[axis("seed=1,2")], &["seed=3".into()]).unwrap_err();
        assert!(e.to_string().contains("also fixed by --set"), "{e}");
        let e = plan(&[], &[]).unwrap_err();
        assert!(e.to_string().contains("at least one --grid"), "{e}");
    }

    #[test]
    fn shards_partition_the_run_list() {
        let n = 7;
        let shards: Vec<Shard> = (1..=3)
            .map(|i| Shard::parse(&format!("{i}/3")).unwrap())
            .collect();
        for idx in 0..n {
            assert_eq!(shards.iter().filter(|s| s.contains(idx)).count(), 1);
        }
        assert_eq!(
            (0..n)
                .filter(|&i| shards[1].contains(i))
                .collect::<Vec<_>>(),
            [1, 4]
        );
        for bad in ["0/2", "3/2", "1/0", "a/2", "2", "1/-1"] {
            let e = Shard::parse(bad).unwrap_err().to_string();
            assert!(e.contains("--shard") && e.contains(bad), "{e}");
        }
    }
}
