//! Pure algorithms over slices and `u32` indices. Nothing here imports `bevy_ecs`.

pub mod diffuse_orientation;
pub mod frames;
pub mod geodesic;
pub mod graph_cut_transfer;
pub mod graph_match;
pub mod jump_surface;
pub mod max_flow;
pub mod metrics;
pub mod orientation_field;
pub mod sqrt2;
pub mod surface_sample;
pub mod sweep;
pub mod vertex_order;
