//! # surfsynth
//!
//! Texture synthesis from a small exemplar image directly over an arbitrary 3D
//! mesh, with the four classic methods (Wei & Levoy 2001, Bangay & Morkel 2006,
//! Praun, Finkelstein & Hoppe 2000, Zelinka & Garland 2004) as schedulable
//! stages of one `bevy_ecs` world. See `ARCHITECTURE.md` for the map.
//!
//! * [`mesh`], [`image`]: data models, loaders, procedural inputs.
//! * [`kernels`]: the algorithms, pure functions over slices (no bevy).
//! * [`stages`]: the world model and one folder per stage (settings, systems).
//! * [`config`], [`pipeline`]: TOML configs into a validated schedule; running it.
//! * [`output`]: exporters, preview renderer, atomic writes.

pub mod cache;
pub mod cache_format;
pub mod config;
pub mod image;
pub mod kernels;
pub mod mesh;
pub mod output;
pub mod pipeline;
pub mod preflight;
pub mod progress;
pub mod stage;
pub mod stages;
pub mod sweep;
pub mod telemetry;
pub mod world;

#[cfg(test)]
mod layer_check;
