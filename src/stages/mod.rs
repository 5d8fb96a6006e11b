//! Stages: one folder per stage with its settings, systems and registration.
//! The world model (components and resources) is in [`world`].

pub mod diffuse_orientation;
pub mod export;
pub mod graph_match;
pub mod init_colours;
pub mod orientation;
pub mod result_metrics;
pub mod subdivide_sqrt2;
pub mod world;
