//! Pure algorithms over slices and `u32` indices. Nothing here imports `bevy_ecs`.

pub mod frames;
pub mod jump_map;
pub mod metrics;
