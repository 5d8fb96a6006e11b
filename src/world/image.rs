//! Image levels and the exemplar: the exemplar and its material maps, its
//! pyramid or stack levels, its jump map, and the images stages make
//! (`jump_image`'s result, `triplanar`'s projection).

use crate::image::{Image, sample::Wrap};
use bevy_ecs::prelude::*;

/// Whether an image level belongs to the halving pyramid or the same-size stack.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageLevelKind {
    /// Gaussian pyramid: each level half the size of the previous.
    Pyramid,
    /// Gaussian stack: every level the exemplar's size, blur doubling.
    Stack,
}

/// An exemplar pyramid or stack level; 0 is the exemplar itself.
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq)]
pub struct ImageLevel {
    /// Level index, 0 = finest.
    pub level: u8,
    /// Pyramid or stack.
    pub kind: ImageLevelKind,
}

/// The pixels of an image level.
#[derive(Component, Clone, Debug, Default)]
pub struct Pixels(pub Image);

/// The exemplar image and how it is addressed.
#[derive(Resource, Clone, Debug)]
pub struct Exemplar {
    /// Pixels, f32, the file's channel count.
    pub image: Image,
    /// Display name (`builtin:bricks`, a file path).
    pub name: String,
    /// Toroidal (`Repeat`) for tileable exemplars, `Clamp` otherwise.
    pub wrap: Wrap,
}

/// Extra exemplar maps that follow the colour synthesis (issue 7): each the
/// colour exemplar's size, addressed with the exemplar's wrap, so a vertex's
/// [`SourceTexels`] or a corner's [`CornerUvs`] read them as they read the
/// colours. Always present (all `None` when the config gives no maps).
#[derive(Resource, Clone, Debug, Default)]
pub struct ExemplarChannels {
    /// Tangent-space normal map, RGB (`kernels::atlas::channels` convention).
    pub normal: Option<Image>,
    /// Roughness, one channel in `[0, 1]`.
    pub roughness: Option<Image>,
    /// Height (displacement), one channel in `[0, 1]`.
    pub height: Option<Image>,
    /// The exemplar's wrap.
    pub wrap: Wrap,
}

/// The exemplar's jump map (Zelinka & Garland 2004 §4), made by `jump_map`.
#[derive(Resource, Clone, Debug)]
pub struct ExemplarJumpMap(pub std::sync::Arc<crate::kernels::jump_maps::jump_map::JumpMap>);

/// A synthesised image (`jump_image`): the image at one exemplar pixel per
/// pixel and, per pixel, its source in exemplar pixel coordinates (as the
/// method returns them: integer indices for pixel and patch synthesis,
/// continuous for controlled synthesis). The `export` format `plane` writes
/// it when the active mesh carries no result.
#[derive(Resource, Clone, Debug)]
pub struct SynthesisedImage {
    /// The image, the exemplar's channel count.
    pub image: Image,
    /// Row-major per-pixel source coordinates.
    pub sources: Vec<[f32; 2]>,
}

/// A triplanar projection (stage `triplanar`): `image` repeated along the
/// three world axes at `texels_per_unit`, blended by `|n_axis|^sharpness`
/// ([`crate::kernels::atlas::triplanar`]). `bake` evaluates it per texel.
#[derive(Resource, Clone, Debug)]
pub struct TriplanarProjection {
    /// The projected image (a tile).
    pub image: Image,
    /// Image pixels per world unit.
    pub texels_per_unit: f32,
    /// The blend exponent.
    pub sharpness: f32,
}
