//! Pure algorithms over slices and `u32` indices. Nothing here imports `bevy_ecs`.

pub mod atlas;
pub mod bake_triangles;
pub mod channels;
pub mod coherent;
pub mod diffuse_orientation;
pub mod flatten;
pub mod frames;
pub mod geodesic;
pub mod graph_cut_transfer;
pub mod graph_match;
pub mod jump_map;
pub mod jump_surface;
pub mod lapped;
pub mod max_flow;
pub mod metrics;
pub mod orientation_field;
pub mod plane_raster;
pub mod relax_orientation;
pub mod retile;
pub mod sqrt2;
pub mod surface_sample;
pub mod sweep;
pub mod vertex_colours_from_uvs;
pub mod vertex_order;
pub mod wl_match;
