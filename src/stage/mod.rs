//! The stage contract: what a stage kind declares ([`Stage`]: its typed
//! settings, the data it needs and makes, its systems, its plane role, its
//! memory estimates), the type-erased configured stage ([`StagePlan`]), the
//! registry entry ([`StageInfo`]) and a stage's failure ([`StageError`]).
//! Every stage implements it; the list of stages is `stages::registry`.

pub mod memory;

use crate::config::params::{ParamDoc, StageSettings, check_range, defaults_table};
use crate::image::{Image, sample::Wrap};
use crate::world::{StageFailure, fail};
use bevy_ecs::prelude::*;
use bevy_ecs::schedule::ScheduleConfigs;
use bevy_ecs::system::ScheduleSystem;
use memory::{InputSizes, MemoryEstimate};

/// Data a stage reads or writes, for validating the order of stages.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Datum {
    /// A mesh (`[input] mesh`).
    Mesh,
    /// Per-vertex tangent frames on the active mesh.
    Frames,
    /// Per-vertex colours on the active mesh.
    Colours,
    /// A multi-level mesh pyramid (retile, √2 subdivision).
    MeshPyramid,
    /// Per-corner texture coordinates on the active mesh.
    CornerUvs,
    /// The jump map of the exemplar.
    JumpMap,
    /// Lapped-texture pastes.
    Patches,
    /// A per-face tangent field (lapped textures).
    FaceField,
    /// A synthesised image (`jump_image`).
    Image,
    /// The `bake` stage's UV atlas of the original mesh (export formats
    /// `glb`, `baked_obj`).
    BakedAtlas,
    /// A triplanar projection of an image (`triplanar`), evaluated per
    /// texel by `bake`.
    Triplanar,
    /// A height map of the exemplar (`[input] height_map`).
    HeightMap,
}

impl Datum {
    /// What it is, for messages.
    pub fn describe(self) -> &'static str {
        match self {
            Datum::Mesh => "a mesh",
            Datum::Frames => "tangent frames",
            Datum::Colours => "vertex colours",
            Datum::MeshPyramid => "a mesh pyramid",
            Datum::CornerUvs => "per-corner texture coordinates",
            Datum::JumpMap => "a jump map",
            Datum::Patches => "lapped-texture pastes",
            Datum::FaceField => "a per-face tangent field",
            Datum::Image => "a synthesised image",
            Datum::Triplanar => "a triplanar projection",
            Datum::HeightMap => "a height map",
            Datum::BakedAtlas => "the `bake` stage's atlas (export formats `glb`, `baked_obj`)",
        }
    }
}

/// What a stage means for the planar image output (`export` format
/// `plane`), so that a request it cannot satisfy is refused before the run.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PlaneRole {
    /// Leaves the active mesh's shape alone (most stages).
    Keeps,
    /// Makes a new active mesh: `planar` when it is flat in xy; `what` names it.
    ReplacesMesh {
        /// Whether the new mesh lies flat in the xy plane.
        planar: bool,
        /// The mesh, for messages (`builtin plane`).
        what: String,
    },
    /// Moves vertices out of their plane (displacement).
    DeformsMesh,
    /// Synthesises an image of this size directly (`jump_image`).
    Image {
        /// Pixels.
        width: u32,
        /// Pixels.
        height: u32,
    },
    /// Asks for a plane image of this size (`export` with format `plane`).
    Request {
        /// Pixels.
        width: u32,
        /// Pixels.
        height: u32,
    },
}

/// Context handed to a stage when it builds its systems.
#[derive(Clone, Copy, Debug)]
pub struct StageCtx {
    /// 0-based position in the pipeline (metrics and RNG streams use it).
    pub index: usize,
}

/// What a fallible stage system returns: `Err(message)` fails the stage,
/// the message saying what is wrong and what is allowed.
pub type SystemResult = Result<(), String>;

impl StageCtx {
    /// `system` of stage `kind`, whose `Err(message)` is recorded as the
    /// stage's failure ([`StageError`]; the first one wins). It runs only
    /// while nothing has failed, so the systems after a failed one, in its
    /// stage and in later stages, do not run; the pipeline returns the
    /// error.
    pub fn fallible<M>(
        self,
        kind: &'static str,
        system: impl IntoSystem<(), SystemResult, M>,
    ) -> ScheduleConfigs<ScheduleSystem> {
        let index = self.index;
        let record = move |In(result): In<SystemResult>, mut failure: ResMut<StageFailure>| {
            if let Err(message) = result {
                fail(&mut failure, index, kind, message);
            }
        };
        system
            .pipe(record)
            .run_if(|failure: Res<StageFailure>| failure.0.is_none())
            .into_configs()
    }
}

/// A stage kind: its settings and its systems.
pub trait Stage: 'static {
    /// The `kind` in `[[stage]]`.
    const KIND: &'static str;
    /// One line: what it does.
    const SUMMARY: &'static str;
    /// Paper and section it implements.
    const PAPER: &'static str;
    /// Its typed settings.
    type Settings: StageSettings;
    /// Data it needs from earlier stages.
    fn requires(settings: &Self::Settings) -> Vec<Datum>;
    /// Data it produces (for any settings, used in hints).
    fn produces(settings: &Self::Settings) -> Vec<Datum>;
    /// Its systems, run in order inside the stage's system set.
    fn systems(settings: Self::Settings, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem>;
    /// What it means for the planar image output (default: keeps the mesh).
    fn plane_role(_settings: &Self::Settings) -> PlaneRole {
        PlaneRole::Keeps
    }
    /// Its large allocations, estimated from its settings and the input's
    /// sizes before any work (default: none). Each estimate names the
    /// parameter it grows with; the run is refused when one is over the
    /// memory limit (`pipeline::memory_budget`).
    fn memory_estimate(_settings: &Self::Settings, _sizes: &InputSizes) -> Vec<MemoryEstimate> {
        Vec::new()
    }
    /// The sizes the stages after it see: a stage that makes a new active
    /// mesh (retiling, subdivision, a builtin pyramid) gives its vertex,
    /// face and triangle counts, so the later stages' estimates scale with
    /// the mesh they will work on (default: unchanged).
    fn sizes_after(_settings: &Self::Settings, sizes: &InputSizes) -> InputSizes {
        *sizes
    }
    /// Checks its settings against the loaded input, as this stage will
    /// see it (`input.sizes`: the exemplar's size and wrap, the mesh's
    /// vertex ids), once the input is loaded and before any stage runs
    /// (default: nothing to check). `Err` is what is wrong, naming the
    /// parameter, the input and what is allowed; the run is refused with
    /// exit 2 before the first stage (issue 43: a neighbourhood wider than
    /// the exemplar, a key on a vertex that does not exist).
    fn check_input(_settings: &Self::Settings, _input: &InputView) -> Result<(), String> {
        Ok(())
    }
    /// Whether the mesh whose vertex ids later stages' settings name (the
    /// active mesh, or the coarsest level of a √2 hierarchy) is still the
    /// one this stage saw, with the same vertices and ids, for an input of
    /// `sizes` (default: yes). A stage that makes another mesh (a
    /// retiling, a builtin pyramid, a remeshed or refined coarsest level)
    /// says no, so a later key vertex is then checked when its stage runs.
    fn keeps_vertex_ids(_settings: &Self::Settings, _sizes: &InputSizes) -> bool {
        true
    }
    /// Whether the analysis this stage would make of `exemplar` (addressed
    /// with `wrap`, in a run of seed `seed`, at position `ctx`) is in the
    /// analysis cache already: its estimates are then not checked, since
    /// reading the entry holds only the result (default: no cache).
    fn analysis_cached(
        _settings: &Self::Settings,
        _exemplar: &Image,
        _wrap: Wrap,
        _seed: u64,
        _ctx: StageCtx,
    ) -> bool {
        false
    }
}

/// A configured stage, type-erased.
pub trait StagePlan: Send + Sync {
    /// Stage kind.
    fn kind(&self) -> &'static str;
    /// Data it needs.
    fn requires(&self) -> Vec<Datum>;
    /// Data it makes.
    fn produces(&self) -> Vec<Datum>;
    /// The resolved settings (defaults filled in), for `config.toml` in the output.
    fn resolved(&self) -> toml::Table;
    /// Its systems.
    fn systems(&self, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem>;
    /// What it means for the planar image output.
    fn plane_role(&self) -> PlaneRole;
    /// Its memory estimates for an input of `sizes`.
    fn memory_estimate(&self, sizes: &InputSizes) -> Vec<MemoryEstimate>;
    /// The sizes the stages after it see.
    fn sizes_after(&self, sizes: &InputSizes) -> InputSizes;
    /// Whether its analysis of `exemplar` is cached already.
    fn analysis_cached(&self, exemplar: &Image, wrap: Wrap, seed: u64, ctx: StageCtx) -> bool;
    /// Its settings checked against the loaded input.
    fn check_input(&self, input: &InputView) -> Result<(), String>;
    /// Whether it keeps the mesh whose vertex ids later settings name.
    fn keeps_vertex_ids(&self, sizes: &InputSizes) -> bool;
}

/// What [`Stage::check_input`] sees of the loaded input.
#[derive(Clone, Copy, Debug)]
pub struct InputView<'a> {
    /// The sizes this stage sees: the input's, or those of the mesh a
    /// stage before it makes (`pipeline::memory_budget::stage_sizes`).
    pub sizes: &'a InputSizes,
    /// The exemplar's display name (its file as written, or `builtin:NAME`).
    pub exemplar: &'a str,
    /// Vertices of the mesh whose ids this stage's settings name (the
    /// coarsest level of a √2 hierarchy, else the active mesh), when known
    /// before the run: the input mesh's, while every stage before keeps
    /// that mesh's vertices ([`Stage::keeps_vertex_ids`]); `None` after a
    /// stage that makes another mesh.
    pub key_vertices: Option<u64>,
}

struct Plan<S: Stage>(S::Settings);

impl<S: Stage> StagePlan for Plan<S> {
    fn kind(&self) -> &'static str {
        S::KIND
    }
    fn requires(&self) -> Vec<Datum> {
        S::requires(&self.0)
    }
    fn produces(&self) -> Vec<Datum> {
        S::produces(&self.0)
    }
    fn resolved(&self) -> toml::Table {
        crate::config::params::to_table(&self.0)
    }
    fn systems(&self, ctx: StageCtx) -> ScheduleConfigs<ScheduleSystem> {
        S::systems(self.0.clone(), ctx)
    }
    fn plane_role(&self) -> PlaneRole {
        S::plane_role(&self.0)
    }
    fn memory_estimate(&self, sizes: &InputSizes) -> Vec<MemoryEstimate> {
        S::memory_estimate(&self.0, sizes)
    }
    fn sizes_after(&self, sizes: &InputSizes) -> InputSizes {
        S::sizes_after(&self.0, sizes)
    }
    fn analysis_cached(&self, exemplar: &Image, wrap: Wrap, seed: u64, ctx: StageCtx) -> bool {
        S::analysis_cached(&self.0, exemplar, wrap, seed, ctx)
    }
    fn check_input(&self, input: &InputView) -> Result<(), String> {
        S::check_input(&self.0, input)
    }
    fn keeps_vertex_ids(&self, sizes: &InputSizes) -> bool {
        S::keeps_vertex_ids(&self.0, sizes)
    }
}

/// A parameter error: `(parameter, message)`.
pub type ParamError = (String, String);

/// Everything the registry knows about a stage kind.
pub struct StageInfo {
    /// The `kind` string.
    pub kind: &'static str,
    /// One line: what it does.
    pub summary: &'static str,
    /// Paper and section.
    pub paper: &'static str,
    /// Parameter documentation.
    pub params: &'static [ParamDoc],
    /// Default settings as TOML.
    pub defaults: fn() -> toml::Table,
    /// Data produced with default settings.
    pub produces_any: fn() -> Vec<Datum>,
    /// Parses and checks settings from the stage's table (without `kind`).
    pub parse: fn(toml::Table) -> Result<Box<dyn StagePlan>, ParamError>,
}

fn parse_stage<S: Stage>(table: toml::Table) -> Result<Box<dyn StagePlan>, ParamError> {
    for (key, value) in &table {
        let Some(doc) = S::Settings::PARAMS.iter().find(|p| p.name == key) else {
            let allowed: Vec<&str> = S::Settings::PARAMS.iter().map(|p| p.name).collect();
            return Err((
                key.clone(),
                format!(
                    "unknown parameter; allowed: {}",
                    if allowed.is_empty() {
                        "none".to_string()
                    } else {
                        allowed.join(", ")
                    }
                ),
            ));
        };
        check_range(value, &doc.range).map_err(|m| (key.clone(), m))?;
    }
    let settings: S::Settings = table.clone().try_into().map_err(|e: toml::de::Error| {
        // serde names the type but not always the key: find the key that
        // fails on its own over the defaults.
        let culprit = table.iter().find(|(k, v)| {
            let mut alone = defaults_table::<S::Settings>();
            alone.insert((*k).clone(), (*v).clone());
            alone.try_into::<S::Settings>().is_err()
        });
        let param = culprit
            .map(|(k, _)| k.clone())
            .unwrap_or_else(|| "?".into());
        (param, e.message().trim_end().to_string())
    })?;
    settings.check()?;
    Ok(Box::new(Plan::<S>(settings)))
}

fn produces_default<S: Stage>() -> Vec<Datum> {
    S::produces(&S::Settings::default())
}

/// The registry entry of stage `S`.
pub fn entry<S: Stage>() -> StageInfo {
    StageInfo {
        kind: S::KIND,
        summary: S::SUMMARY,
        paper: S::PAPER,
        params: S::Settings::PARAMS,
        defaults: defaults_table::<S::Settings>,
        produces_any: produces_default::<S>,
        parse: parse_stage::<S>,
    }
}

/// A stage refused its input or failed: which stage and why. The pipeline
/// reports it as exit 2 (`PipelineError::Stage`).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("stage {index} ({kind}): {message}")]
pub struct StageError {
    /// 1-based position in the pipeline.
    pub index: usize,
    /// Stage kind.
    pub kind: String,
    /// What is wrong, and what is allowed.
    pub message: String,
}

impl StageError {
    /// The failure of the stage at 0-based position `index`.
    pub fn new(index: usize, kind: &str, message: impl Into<String>) -> Self {
        Self {
            index: index + 1,
            kind: kind.to_string(),
            message: message.into(),
        }
    }
}
