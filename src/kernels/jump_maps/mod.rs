//! Zelinka & Garland 2004: the jump map of an exemplar (analysis, refinement),
//! image synthesis from it (pixels, patches; [`jump_image`] as the stage runs
//! it), and its synthesis on surfaces
//! with the vertex order it walks.

pub mod jump_image;
pub mod jump_map;
pub mod jump_surface;
pub mod vertex_order;
