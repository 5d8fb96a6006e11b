//! Wei & Levoy 2001: neighbourhood matching on a mesh pyramid (exhaustive and
//! tree search), Turk-style retiling into that pyramid, and the orientation
//! relaxation of its tangent field.

pub mod relax_orientation;
pub mod retile;
pub mod wl_match;
