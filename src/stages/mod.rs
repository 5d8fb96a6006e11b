//! Stages: one folder per stage with its settings, systems and registration.
//! The world model (components and resources) is in [`world`].

pub mod export;
pub mod init_colours;
pub mod lapped_paste;
pub mod orientation;
pub mod result_metrics;
pub mod tangent_field;
pub mod world;
