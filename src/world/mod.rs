//! The world model: the components of mesh levels, image levels and
//! patches, and the run-wide resources, shared by every stage, the writer
//! (`output`) and the pipeline. It sits below the stages: it names only the
//! stage contract, the kernels (their data types, and a kernel function where
//! a shared query completes its data: `Pyramid::input`) and the mesh and
//! image layers.
//! Everything is structure-of-arrays: a vertex is a row (`u32` id) in each
//! per-vertex array.
//!
//! - `mesh`: mesh levels and pyramids;
//! - `image`: the exemplar, its levels and maps, images stages make;
//! - `run`: the seed, the texture scale, metrics, timings, failures;
//! - `export`: what the export stage asks the writer to write;
//! - `lapped`: lapped-texture pastes for runtime pasting.

mod export;
mod image;
mod lapped;
mod mesh;
mod run;

pub use export::*;
pub use image::*;
pub use lapped::*;
pub use mesh::*;
pub use run::*;
