//! Stages: one folder per stage with its settings, systems and registration,
//! and the list of them ([`registry`]). The contract every stage implements
//! is [`crate::stage`]; the world model they share is [`crate::world`].

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

use crate::stage::{Datum, StageInfo, entry};

/// Every stage, in the order `surfsynth stages` lists them.
pub fn registry() -> Vec<StageInfo> {
    vec![
        entry::<orientation::Orientation>(),
        entry::<init_colours::InitColours>(),
        entry::<retile::Retile>(),
        entry::<jump_map::JumpMapStage>(),
        entry::<jump_surface::JumpSurface>(),
        entry::<jump_image::JumpImage>(),
        entry::<builtin_pyramid::BuiltinPyramid>(),
        entry::<relax_orientation::RelaxOrientation>(),
        entry::<wl_match::Match>(),
        entry::<coherent::Coherent>(),
        entry::<tangent_field::TangentField>(),
        entry::<lapped_paste::LappedPaste>(),
        entry::<subdivide_sqrt2::SubdivideSqrt2>(),
        entry::<diffuse_orientation::DiffuseOrientation>(),
        entry::<graph_match::GraphMatch>(),
        entry::<map_back::MapBack>(),
        entry::<export::Export>(),
        entry::<displace::Displace>(),
        entry::<bake::Bake>(),
        entry::<triplanar::Triplanar>(),
    ]
}

/// Looks a stage kind up.
pub fn find(kind: &str) -> Option<StageInfo> {
    registry().into_iter().find(|s| s.kind == kind)
}

/// Which stages produce `datum` (for a mesh: the `[input]` section), for
/// hints.
pub fn producers(datum: Datum) -> Vec<&'static str> {
    match datum {
        Datum::Mesh => return vec!["input.mesh"],
        Datum::HeightMap => return vec!["input.height_map"],
        _ => {}
    }
    registry()
        .iter()
        .filter(|s| (s.produces_any)().contains(&datum))
        .map(|s| s.kind)
        .collect()
}
