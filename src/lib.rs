//! # surfsynth
//!
//! Texture synthesis from a small exemplar image directly over an arbitrary 3D
//! mesh, with the four classic methods (Wei & Levoy 2001, Bangay & Morkel 2006,
//! Praun, Finkelstein & Hoppe 2000, Zelinka & Garland 2004) as schedulable
//! stages of one `bevy_ecs` world. See `ARCHITECTURE.md` for the map.

pub mod image;
pub mod kernels;
pub mod mesh;
pub mod output;
