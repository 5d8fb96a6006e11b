//! Running a pipeline: inputs into a fresh `World`, the schedule, the result
//! metrics, then the files.

use super::{LoadedInput, Pipeline, PipelineError, load_input_from};
use crate::stage::{StageCtx, StageError};
use crate::world::FaceField;
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::SingleThreadedExecutor;
use std::path::PathBuf;
use std::time::Instant;

/// The system set of stage `i` (0-based).
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct StageSet(pub usize);

/// The set of the result-metrics system that follows every stage.
#[derive(SystemSet, Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ResultMetricsSet;

/// Options of one run.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Output folder (`--out`); `[output].dir` when `None`. It is checked
    /// before any work, written as a whole into a sibling temporary folder
    /// and renamed into place at the end (`output::staging`).
    pub out_dir: Option<PathBuf>,
}

/// What a run did.
#[derive(Clone, Debug)]
pub struct RunReport {
    /// Where the files went.
    pub out_dir: PathBuf,
    /// Files written, in order.
    pub files: Vec<PathBuf>,
    /// Per-stage wall times.
    pub timings: Vec<StageTiming>,
    /// Everything written to `metrics.json`.
    pub metrics: serde_json::Value,
}

struct StageSpan(#[allow(dead_code)] tracing::span::EnteredSpan);

#[derive(Resource)]
struct StageClock(Instant);

fn no_failure(failure: Res<StageFailure>) -> bool {
    failure.0.is_none()
}

/// Adds the world's resources and the source mesh entity.
pub fn setup_world(pipeline: &Pipeline, world: &mut World, input: LoadedInput) {
    let spacing = input.mesh.average_edge_length().max(f32::MIN_POSITIVE);
    let scale = TextureScale::resolve(
        pipeline.input.texture_scale,
        pipeline.input.texture_scale_unit,
        input.exemplar.width,
        crate::mesh::repair::bounding_box_diagonal(&input.mesh.positions),
    );
    world.insert_resource(scale);
    world.insert_resource(Exemplar {
        image: input.exemplar,
        name: input.exemplar_name,
        wrap: pipeline.input.exemplar_wrap,
    });
    world.insert_resource(input.channels);
    world.insert_resource(RunSeed(pipeline.seed));
    world.insert_resource(TexelSpacing(spacing));
    world.insert_resource(Metrics::default());
    world.insert_resource(StageTimings::default());
    world.insert_resource(StageFailure::default());
    world.insert_resource(ExportJob::default());
    let source = world
        .spawn((SourceMesh, MeshLevel(0), Geometry(input.mesh)))
        .id();
    world.insert_resource(ActiveMesh(source));
}

/// The schedule of a pipeline: one chained system set per stage, then the
/// result metrics.
pub fn build_schedule(pipeline: &Pipeline) -> Schedule {
    let mut schedule = Schedule::default();
    schedule.set_executor(SingleThreadedExecutor::new());
    let n = pipeline.stages.len();
    for (i, stage) in pipeline.stages.iter().enumerate() {
        let kind = stage.kind();
        let begin = move |world: &mut World| {
            // The start line is logged outside the span, whose fields would
            // repeat the index and kind on it; events inside the stage carry them.
            tracing::info!("stage {} ({kind}) started", i + 1);
            let span =
                tracing::info_span!(crate::telemetry::STAGE_SPAN, index = i + 1, kind).entered();
            world.insert_non_send(StageSpan(span));
            world.insert_resource(StageClock(Instant::now()));
        };
        let end = move |world: &mut World| {
            let seconds = world
                .get_resource::<StageClock>()
                .map(|c| c.0.elapsed().as_secs_f64())
                .unwrap_or(0.0);
            world.resource_mut::<StageTimings>().0.push(StageTiming {
                index: i + 1,
                kind: kind.to_string(),
                seconds,
            });
            world.remove_non_send::<StageSpan>();
            tracing::info!("stage {} ({kind}) done in {seconds:.3} s", i + 1);
        };
        schedule.add_systems(
            (begin, stage.systems(StageCtx { index: i }), end)
                .chain()
                .in_set(StageSet(i)),
        );
        schedule.configure_sets(StageSet(i).run_if(no_failure));
        if i > 0 {
            schedule.configure_sets(StageSet(i).after(StageSet(i - 1)));
        }
    }
    let metrics = schedule_result_metrics(pipeline);
    if n > 0 {
        schedule.configure_sets(ResultMetricsSet.after(StageSet(n - 1)));
    }
    schedule.configure_sets(ResultMetricsSet.run_if(no_failure));
    schedule.add_systems(metrics.in_set(ResultMetricsSet));
    schedule
}

fn schedule_result_metrics(
    pipeline: &Pipeline,
) -> bevy_ecs::schedule::ScheduleConfigs<bevy_ecs::system::ScheduleSystem> {
    let settings = crate::kernels::metrics::EnergySettings {
        neighbourhood: pipeline.output.metric_neighbourhood,
        samples: pipeline.output.metric_samples,
        seed: pipeline.seed,
        ..Default::default()
    };
    crate::stages::result_metrics::system(settings)
}

/// Sets the world up from `input`, runs the whole schedule, and returns the
/// first stage failure, if any.
pub fn run_in_world(
    pipeline: &Pipeline,
    world: &mut World,
    input: LoadedInput,
) -> Result<(), PipelineError> {
    run_schedule(pipeline, world, input, Keep::All)?;
    crate::stages::export::finish_export_job(world, crate::stages::export::Transfer::Copy)
        .map_err(Into::into)
}

/// What the world keeps once the stages are done.
#[derive(Clone, Copy, PartialEq)]
enum Keep {
    /// Everything, for callers that inspect the world ([`run_in_world`]).
    All,
    /// Only what the result metrics and the export job read: the jump-map
    /// blend layers (144 bytes per vertex), per-vertex scales and lapped
    /// textures' tangent field (24 bytes per vertex) go before the result
    /// metrics build their topology.
    Read,
}

/// Removes the components no step after the last stage reads (see
/// [`Keep::Read`]).
fn release_unread(world: &mut World) {
    let entities: Vec<Entity> = world
        .query_filtered::<Entity, Or<(With<BlendUvs>, With<VertexScale>, With<FaceField>)>>()
        .iter(world)
        .collect();
    for e in entities {
        world
            .entity_mut(e)
            .remove::<(BlendUvs, VertexScale, FaceField)>();
    }
}

/// [`run_in_world`] without filling the export job's arrays.
fn run_schedule(
    pipeline: &Pipeline,
    world: &mut World,
    input: LoadedInput,
    keep: Keep,
) -> Result<(), PipelineError> {
    super::plane_check::check_plane_requests(pipeline, &input.mesh)?;
    // The loaded input's sizes, which the checks below all read.
    let sizes = crate::stage::memory::InputSizes::of(&input, &pipeline.input);
    super::stage_check::check_stage_inputs(pipeline, &input, &sizes)?;
    // Every stage's memory estimate for the loaded input, before any work.
    let estimates = super::memory_budget::check_loaded(
        &pipeline.stages,
        &input,
        &sizes,
        &pipeline.input,
        pipeline.seed,
        &pipeline.memory_limit,
    )
    .map_err(|r| StageError {
        index: r.index,
        kind: r.kind.into(),
        message: r.message,
    })?;
    super::memory_budget::check_metrics(
        &pipeline.output,
        &pipeline.stages,
        &sizes,
        &pipeline.memory_limit,
        &pipeline.source.file,
    )?;
    setup_world(pipeline, world, input);
    let mut metrics = world.resource_mut::<Metrics>();
    for e in estimates {
        let mut all = metrics
            .stages
            .get(e.index - 1)
            .and_then(|m| m.get("memory_estimate_bytes"))
            .and_then(|v| v.as_object().cloned())
            .unwrap_or_default();
        all.insert(e.param.into(), e.bytes.into());
        metrics.record(e.index - 1, "memory_estimate_bytes", all);
    }

    let mut schedule = build_schedule(pipeline);
    if keep == Keep::Read {
        let n = pipeline.stages.len();
        let release = release_unread.before(ResultMetricsSet);
        if n > 0 {
            schedule.add_systems(release.after(StageSet(n - 1)));
        } else {
            schedule.add_systems(release);
        }
    }
    schedule.run(world);
    if let Some(err) = world.resource_mut::<StageFailure>().0.take() {
        return Err(err.into());
    }
    Ok(())
}

/// Peak resident set size of this process in bytes (Linux; `None` elsewhere).
pub fn peak_rss_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// Runs a pipeline end to end and writes its outputs. The output folder is
/// checked first (not a file, writable parent, empty or an earlier run's:
/// exit 2); the outputs appear all at once, replacing an earlier run's
/// folder, or not at all.
pub fn run(pipeline: &Pipeline, options: &RunOptions) -> Result<RunReport, PipelineError> {
    let started = Instant::now();
    let requested = options
        .out_dir
        .clone()
        .unwrap_or_else(|| PathBuf::from(&pipeline.output.dir));
    // A set-aside earlier result goes back before anything can refuse the
    // run (`output::staging::recover`).
    crate::output::staging::recover(&requested);
    let (file, key) = match options.out_dir {
        Some(_) => ("command line".to_string(), "--out"),
        None => (pipeline.source.file.clone(), "output.dir"),
    };
    let out_dir = crate::preflight::resolve_output_folder(&requested)
        .and_then(|dir| {
            crate::preflight::check_folder_target(&dir)?;
            crate::output::staging::check_replaceable(&dir)?;
            Ok(dir)
        })
        .map_err(|message| crate::config::ConfigError::Value {
            file,
            key: key.into(),
            message,
        })?;
    // Every file goes into a sibling temporary folder, renamed to `out_dir`
    // at the end: a failed or killed run leaves no partial result.
    let folder = crate::output::staging::RunFolder::begin(&out_dir)?;
    let staged = folder.path().to_path_buf();
    let input = load_input_from(&pipeline.input, &pipeline.source)?;
    tracing::info!(
        "input: {} vertices, {} faces ({}); exemplar {} {}x{}x{}",
        input.mesh.vertex_count(),
        input.mesh.face_count(),
        input.load_report,
        input.exemplar_name,
        input.exemplar.width,
        input.exemplar.height,
        input.exemplar.channels
    );
    let memory = serde_json::json!({
        "limit_bytes": pipeline.memory_limit.bytes,
        "limit_source": pipeline.memory_limit.source.to_string(),
        "input_bytes": crate::stage::memory::InputSizes::of(&input, &pipeline.input).resident_bytes(),
    });
    let input_counts = serde_json::json!({
        "vertices": input.mesh.vertex_count(),
        "faces": input.mesh.face_count(),
        "repairs": input.load_report,
        "exemplar": input.exemplar_name,
        "exemplar_size": [input.exemplar.width, input.exemplar.height, input.exemplar.channels],
    });
    let mut world = World::new();
    run_schedule(pipeline, &mut world, input, Keep::Read)?;

    let _span = tracing::info_span!("write_outputs").entered();
    let mut files = Vec::new();
    let config_path = staged.join("config.toml");
    crate::output::write_bytes_atomic(&config_path, pipeline.resolved_toml().as_bytes())?;
    files.push(config_path);
    let timings = world.resource::<StageTimings>().0.clone();
    let active = world.resource::<ActiveMesh>().0;
    let result_counts = world
        .get::<Geometry>(active)
        .map(|g| serde_json::json!({"vertices": g.0.vertex_count(), "faces": g.0.face_count()}))
        .unwrap_or(serde_json::Value::Null);
    // The texture scale the method used (issue 14): exemplar texels per world
    // unit (the `TexelSpacing` the synthesis stages set) and per bounding-box
    // diagonal of the result mesh, so two methods or two mesh sizes compare.
    let texels_per_unit = 1.0 / world.resource::<TexelSpacing>().0.max(f32::MIN_POSITIVE);
    // Beside it, what `[input] texture_scale` asked for, in the same units.
    let requested = *world.resource::<TextureScale>();
    let scale = world
        .get::<Geometry>(active)
        .and_then(|g| g.0.bounding_box())
        .map(|(lo, hi)| {
            use crate::config::params::to_json;
            serde_json::json!({
                "texels_per_world_unit": to_json(&texels_per_unit),
                "texels_per_bbox_diagonal": to_json(&(texels_per_unit * (hi - lo).length())),
                "requested_texels_per_world_unit": to_json(&requested.texels_per_unit),
                "requested_texels_per_bbox_diagonal": to_json(&requested.texels_per_diagonal()),
                "effective_over_requested":
                    to_json(&(texels_per_unit / requested.texels_per_unit.max(f32::MIN_POSITIVE))),
            })
        })
        .unwrap_or(serde_json::Value::Null);
    let metrics_res = std::mem::take(&mut *world.resource_mut::<Metrics>());
    // Everything metrics.json needs is read: the world's arrays (mesh,
    // frames, texture coordinates: about half the peak memory at a million
    // vertices) go before the files are written.
    crate::stages::export::finish_export_job(&mut world, crate::stages::export::Transfer::Move)?;
    let job = std::mem::take(&mut *world.resource_mut::<ExportJob>());
    drop(world);
    files.extend(crate::output::export::write_export_titled(
        &staged,
        &job,
        &pipeline.source.file,
    )?);
    drop(job);
    let stages: Vec<serde_json::Value> = pipeline
        .stages
        .iter()
        .enumerate()
        .map(|(i, s)| {
            serde_json::json!({
                "index": i + 1,
                "kind": s.kind(),
                "seconds": timings.iter().find(|t| t.index == i + 1).map(|t| t.seconds),
                "metrics": metrics_res.stages.get(i).cloned().unwrap_or_default(),
            })
        })
        .collect();
    let metrics = serde_json::json!({
        "config": pipeline.source.file,
        "seed": pipeline.seed,
        "threads": rayon::current_num_threads(),
        "input": input_counts,
        "result": {
            "mesh": result_counts,
            "scale": scale,
            "quality": metrics_res.result,
        },
        "stages": stages,
        "total_seconds": started.elapsed().as_secs_f64(),
        "peak_rss_bytes": peak_rss_bytes(),
        "memory": memory,
    });
    let metrics_path = staged.join("metrics.json");
    let text = serde_json::to_string_pretty(&metrics)
        .map_err(|e| PipelineError::Internal(format!("metrics.json: {e}")))?;
    crate::output::write_bytes_atomic(&metrics_path, text.as_bytes())?;
    files.push(metrics_path);
    // Last: the marker that makes the folder provably a run's, so that the
    // next run may replace it (`staging::check_replaceable`).
    files.push(crate::output::staging::write_run_marker(&staged, &files)?);
    folder.commit()?;
    let files = files
        .into_iter()
        .map(|f| match f.strip_prefix(&staged) {
            Ok(rel) => out_dir.join(rel),
            Err(_) => f,
        })
        .collect();
    Ok(RunReport {
        out_dir,
        files,
        timings,
        metrics,
    })
}
