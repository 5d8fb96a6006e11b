//! Wei & Levoy 2001: neighbourhood matching on a mesh pyramid (exhaustive and
//! tree search), Turk-style retiling into that pyramid, the orientation
//! relaxation of its tangent field, and the random initial colours.

pub mod random_texels;
pub mod relax_orientation;
pub mod retile;
pub mod wl_match;
