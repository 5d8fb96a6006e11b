//! Lapped-texture pastes as the `export` format `pastes` writes them, for
//! runtime pasting (Praun et al. 2000 §4).

use crate::image::Image;
use glam::Vec2;

/// A lapped texture for runtime pasting (Praun et al. 2000 §4): the texture
/// patches and, in paste order, each paste's faces (those not hidden by
/// later pastes) with their corners' texture coordinates.
#[derive(Clone, Debug, Default)]
pub struct PasteExport {
    /// RGBA texture patches.
    pub textures: Vec<Image>,
    /// The pastes, in drawing order.
    pub pastes: Vec<PasteRecord>,
}

/// One paste of a [`PasteExport`].
#[derive(Clone, Debug, Default)]
pub struct PasteRecord {
    /// Index into [`PasteExport::textures`].
    pub texture: u32,
    /// Mesh faces to draw.
    pub faces: Vec<u32>,
    /// Texture coordinates of their corners, compactly (the corners of
    /// `faces[0]`, then of `faces[1]`, ...), `v = 0` at the top row.
    pub uvs: Vec<Vec2>,
}
