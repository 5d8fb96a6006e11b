//! Stages: one folder per stage with its settings, systems and registration.
//! The world model (components and resources) is in [`world`].

pub mod bake;
pub mod builtin_pyramid;
pub mod coherent;
pub mod diffuse_orientation;
pub mod displace;
pub mod export;
pub mod graph_match;
pub mod init_colours;
pub mod jump_image;
pub mod jump_map;
pub mod jump_surface;
pub mod lapped_paste;
pub mod map_back;
pub mod orientation;
pub mod position;
pub mod relax_orientation;
pub mod result_metrics;
pub mod retile;
pub mod subdivide_sqrt2;
pub mod tangent_field;
pub mod triplanar;
pub mod wl_match;
pub mod world;
