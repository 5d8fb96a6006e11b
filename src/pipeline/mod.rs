//! Builds a `bevy_ecs` schedule from a validated config and runs it.
//!
//! One system set per stage, chained in config order; each set is bracketed
//! by a begin system (opens the stage's tracing span, starts its clock) and an
//! end system (records its wall time). The executor is single-threaded: the
//! stages parallelise inside their kernels with rayon, so two thread pools
//! never fight over the cores.

mod error;
mod input;
pub mod memory_budget;
pub mod memory_limit;
pub mod plane_check;
mod report;
mod run;
pub mod stage_check;

use crate::stage::{Datum, PlaneRole, StagePlan};
use crate::stages::registry;
pub use error::PipelineError;
pub use input::{
    INPUT_FILE_KEYS, LoadedInput, check_input_files, input_file, load_input, load_input_from,
};
pub use report::{describe_stages, format_report};
pub use run::{
    RunOptions, RunReport, StageSet, build_schedule, peak_rss_bytes, run, run_in_world, setup_world,
};

use crate::config::{ConfigError, ConfigSource, RawInput, RawOutput};
use std::collections::HashSet;

/// A validated pipeline: every stage parsed into typed settings, the order
/// of stages checked against what each needs.
pub struct Pipeline {
    /// Where the config came from (for messages).
    pub source: ConfigSource,
    /// Seed of every random stream.
    pub seed: u64,
    /// `[input]`.
    pub input: RawInput,
    /// `[output]`.
    pub output: RawOutput,
    /// The stages, in order.
    pub stages: Vec<Box<dyn StagePlan>>,
    /// The memory the run may use, detected (or read from
    /// `$SURFSYNTH_MEMORY_LIMIT`) at validation.
    pub memory_limit: memory_limit::MemoryLimit,
}

impl std::fmt::Debug for Pipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pipeline")
            .field("file", &self.source.file)
            .field("seed", &self.seed)
            .field(
                "stages",
                &self.stages.iter().map(|s| s.kind()).collect::<Vec<_>>(),
            )
            .finish()
    }
}

/// Most `[[stage]]` entries a config may have: far above any real
/// pipeline (the shipped ones have at most 7), far below the thousands at
/// which the schedule's memory became gigabytes (issue 43: 800 stages took
/// 0.78 GB, 3,000 took 11.4 GB).
pub const MAX_STAGES: usize = 256;

/// What `[input] height_map` may be, for messages.
const HEIGHT_MAP_ALLOWED: &str =
    "a file the exemplar's size, \"derive:luminance\" or \"derive:builtin\"";

/// Stage parameters that name a file, by stage kind: resolved by the path
/// rule of [`ConfigSource`] before the stage parses its settings.
const STAGE_PATH_PARAMS: &[(&str, &str)] =
    &[("lapped_paste", "mask_image"), ("triplanar", "image")];

/// Replaces each path-valued parameter of stage `index` (1-based) by the
/// path resolved against the config's folder (or the current directory for
/// a `--set` value); a missing file is a [`ConfigError::MissingFile`].
fn resolve_stage_paths(
    source: &ConfigSource,
    kind: &str,
    index: usize,
    table: &mut toml::Table,
) -> Result<(), ConfigError> {
    for (_, param) in STAGE_PATH_PARAMS.iter().filter(|(k, _)| *k == kind) {
        if let Some(toml::Value::String(spec)) = table.get_mut(*param)
            && !spec.trim().is_empty()
        {
            let key = format!("stage.{index}.{param}");
            *spec = input::input_file(source, &key, spec.trim())?
                .display()
                .to_string();
        }
    }
    Ok(())
}

/// The config's single values: the output folder, the metric settings, the
/// texture scale and the stage count.
fn check_scalars(raw: &crate::config::RawConfig, file: &str) -> Result<(), ConfigError> {
    let value_err = |key: &str, message: String| ConfigError::Value {
        file: file.to_string(),
        key: key.to_string(),
        message,
    };
    if raw.output.dir.trim().is_empty() {
        return Err(value_err("output.dir", "must name a folder".into()));
    }
    let n = raw.output.metric_neighbourhood;
    if !(3..=15).contains(&n) || n.is_multiple_of(2) {
        return Err(value_err(
            "output.metric_neighbourhood",
            format!("{n} is not allowed; allowed: odd, 3..=15"),
        ));
    }
    if !(10..=100_000).contains(&raw.output.metric_samples) {
        return Err(value_err(
            "output.metric_samples",
            format!(
                "{} is out of range; allowed: 10..=100000",
                raw.output.metric_samples
            ),
        ));
    }
    let scale = raw.input.texture_scale;
    let limit = crate::config::TEXTURE_SCALE_LIMIT;
    if !(scale.is_finite() && (1.0 / limit..=limit).contains(&scale)) {
        return Err(value_err(
            "input.texture_scale",
            format!(
                "{scale} is out of range; allowed: {}..={limit:e} (in texture_scale_unit = {:?}: {})",
                1.0 / limit,
                raw.input.texture_scale_unit,
                crate::config::TextureScaleUnit::ALLOWED
            ),
        ));
    }
    if raw.stage.len() > MAX_STAGES {
        return Err(value_err(
            "stage",
            format!(
                "{} stages; allowed: at most {MAX_STAGES} (a pipeline's world holds every stage's systems, and its memory grows faster than the stage count)",
                raw.stage.len()
            ),
        ));
    }
    Ok(())
}

/// The `index`-th (1-based) `[[stage]]` table parsed into its plan: its
/// kind looked up in `all`, its paths resolved, its settings typed and
/// checked. Returns the plan and the line of its `kind`.
fn parse_stage_table(
    source: &ConfigSource,
    all: &[crate::stage::StageInfo],
    index: usize,
    spanned: &toml::Spanned<std::collections::BTreeMap<toml::Spanned<String>, toml::Value>>,
) -> Result<(Box<dyn StagePlan>, usize), ConfigError> {
    let file = &source.file;
    let allowed_kinds = || all.iter().map(|s| s.kind).collect::<Vec<_>>().join(", ");
    let table_line = source.line_of(spanned.span().start);
    let entries = spanned.get_ref();
    let kind_value = entries.iter().find(|(k, _)| k.get_ref() == "kind");
    let Some((kind_key, kind_value)) = kind_value else {
        return Err(ConfigError::UnknownStage {
            file: file.clone(),
            line: table_line,
            index,
            kind: String::new(),
            allowed: format!("a `kind = \"...\"` line with one of: {}", allowed_kinds()),
        });
    };
    let kind_line = source.line_of(kind_key.span().start);
    let kind = kind_value.as_str().unwrap_or_default().to_string();
    let Some(info) = all.iter().find(|s| s.kind == kind) else {
        return Err(ConfigError::UnknownStage {
            file: file.clone(),
            line: kind_line,
            index,
            kind,
            allowed: allowed_kinds(),
        });
    };
    let mut table = toml::Table::new();
    for (k, v) in entries {
        if k.get_ref() != "kind" {
            table.insert(k.get_ref().clone(), v.clone());
        }
    }
    resolve_stage_paths(source, &kind, index, &mut table)?;
    let plan = (info.parse)(table).map_err(|(param, message)| {
        let line = entries
            .iter()
            .find(|(k, _)| k.get_ref() == &param)
            .map(|(k, _)| source.line_of(k.span().start))
            .unwrap_or(table_line);
        ConfigError::Param {
            file: file.clone(),
            line,
            index,
            kind: kind.clone(),
            param,
            message,
        }
    })?;
    Ok((plan, kind_line))
}

/// Checks that what `plan` needs is `available` from `[input]` and the
/// stages before it, and that a `plane` request has a result to draw.
fn check_order(
    plan: &dyn StagePlan,
    available: &HashSet<Datum>,
    file: &str,
    kind_line: usize,
    index: usize,
) -> Result<(), ConfigError> {
    let kind = plan.kind().to_string();
    for need in plan.requires() {
        if !available.contains(&need) {
            let producers = crate::stages::producers(need);
            return Err(ConfigError::MissingInput {
                file: file.to_string(),
                line: kind_line,
                index,
                kind,
                needs: need.describe().to_string(),
                hint: if need == Datum::Mesh {
                    "set `mesh` in [input]".to_string()
                } else if need == Datum::HeightMap {
                    format!("set input.height_map ({HEIGHT_MAP_ALLOWED})")
                } else {
                    format!(
                        "add {} before it",
                        producers
                            .iter()
                            .map(|p| format!("`{p}`"))
                            .collect::<Vec<_>>()
                            .join(" or ")
                    )
                },
            });
        }
    }
    if matches!(plan.plane_role(), PlaneRole::Request { .. })
        && !plane_check::PLANE_RESULTS
            .iter()
            .any(|d| available.contains(d))
    {
        return Err(ConfigError::MissingInput {
            file: file.to_string(),
            line: kind_line,
            index,
            kind,
            needs: "a result to draw for format `plane` (vertex colours, per-corner texture coordinates, lapped pastes or a synthesised image)".into(),
            hint: "add a synthesis stage (`init_colours`, `match`, `graph_match`, `jump_surface`, `lapped_paste` or `jump_image`) before it".into(),
        });
    }
    Ok(())
}

impl Pipeline {
    /// Parses and validates a config: unknown stages, keys, types and ranges,
    /// and stages whose inputs no earlier stage produces, are errors naming
    /// the file, the line and what is allowed.
    pub fn from_source(source: ConfigSource) -> Result<Self, ConfigError> {
        let raw = source.parse()?;
        let file = source.file.clone();
        check_scalars(&raw, &file)?;
        let all = registry();
        let mut stages = Vec::with_capacity(raw.stage.len());
        let mut available: HashSet<Datum> = HashSet::new();
        if raw.input.mesh.is_some() {
            available.insert(Datum::Mesh);
        }
        if raw.input.height_map.is_some() {
            available.insert(Datum::HeightMap);
        }
        for (i, spanned) in raw.stage.iter().enumerate() {
            let (plan, kind_line) = parse_stage_table(&source, &all, i + 1, spanned)?;
            check_order(&*plan, &available, &file, kind_line, i + 1)?;
            available.extend(plan.produces());
            stages.push(plan);
        }
        let memory_limit =
            memory_limit::MemoryLimit::detect().map_err(|message| ConfigError::Value {
                file: "environment".into(),
                key: memory_limit::LIMIT_VAR.into(),
                message,
            })?;
        memory_budget::check_input(&raw.input, &memory_limit, &file)?;
        // Before loading: what the settings alone decide. The estimates are
        // lower bounds, so a refusal stands; but the largest value it
        // offers must leave room for the input, which only loading it
        // tells (issue 43: an offer was refused once the input was
        // loaded). So a refusal loads the input and says what the check
        // before the first stage will say.
        memory_budget::check_stages(&stages, &Default::default(), &memory_limit, &[]).map_err(
            |r| {
                let r = load_input_from(&raw.input, &source)
                    .ok()
                    .and_then(|input| {
                        memory_budget::check_loaded(
                            &stages,
                            &input,
                            &crate::stage::memory::InputSizes::of(&input, &raw.input),
                            &raw.input,
                            raw.seed,
                            &memory_limit,
                        )
                        .err()
                    })
                    .unwrap_or(r);
                ConfigError::Value {
                    file: file.clone(),
                    key: format!("stage {} ({}) {}", r.index, r.kind, r.param),
                    message: r.message,
                }
            },
        )?;
        Ok(Self {
            seed: raw.seed,
            input: raw.input,
            output: raw.output,
            stages,
            source,
            memory_limit,
        })
    }

    /// The config with every default filled in, as written to `<out>/config.toml`.
    pub fn resolved_toml(&self) -> String {
        let mut root = toml::Table::new();
        root.insert("seed".into(), toml::Value::Integer(self.seed as i64));
        root.insert(
            "input".into(),
            toml::Value::Table(crate::config::params::to_table(&self.input)),
        );
        let stages = self
            .stages
            .iter()
            .map(|s| {
                let mut t = toml::Table::new();
                t.insert("kind".into(), toml::Value::String(s.kind().into()));
                t.extend(s.resolved());
                toml::Value::Table(t)
            })
            .collect();
        root.insert("stage".into(), toml::Value::Array(stages));
        root.insert(
            "output".into(),
            toml::Value::Table(crate::config::params::to_table(&self.output)),
        );
        format!(
            "# Resolved configuration of this run (defaults filled in).\n# Source: {}\n\n{}",
            self.source.file,
            toml::to_string(&root).unwrap_or_default()
        )
    }
}
