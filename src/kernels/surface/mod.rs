//! Shared surface geometry: per-vertex tangent frames, local flattening of a
//! vertex's neighbourhood, resampling the surface around a point, geodesic
//! distances, occupancy grids, orientation fields and the per-component
//! fallback for meshes they cannot orient.

pub mod component_fallback;
pub mod flatten;
pub mod frames;
pub mod geodesic;
pub(crate) mod occupancy;
pub mod orientation_field;
pub mod surface_sample;
