//! Lapped-texture pastes: their components and resources, and the record
//! the `export` format `pastes` writes for runtime pasting (Praun et al.
//! 2000 §4).
//!
//! Every paste is an entity with [`PasteOf`] (the mesh entity it is pasted
//! on), [`PasteOrder`], [`TexturePatchIndex`], [`PatchFaces`],
//! [`PatchUvs`] and [`PatchDrawn`]: the record of one paste operation of
//! Praun et al. 2000 §3.5 ("texture patch index, list of surface patch
//! faces, and texture coordinates"), in paste order. The texture patches
//! themselves are the [`TexturePatches`] resource; an atlas, when built, is
//! an [`AtlasTexture`] on the mesh entity.

use crate::image::Image;
use bevy_ecs::prelude::*;
use glam::Vec2;

/// The mesh entity a paste belongs to.
#[derive(Component, Clone, Copy, Debug)]
pub struct PasteOf(pub Entity);

/// Position of the paste in paste order: later pastes are drawn on top.
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct PasteOrder(pub u32);

/// Which texture patch ([`TexturePatches`]) the paste uses.
#[derive(Component, Clone, Copy, Debug, PartialEq, Eq)]
pub struct TexturePatchIndex(pub u32);

/// The mesh faces of the surface patch, seed face first.
#[derive(Component, Clone, Debug, Default)]
pub struct PatchFaces(pub Vec<u32>);

/// Texture coordinates of the corners of [`PatchFaces`], compactly: the
/// corners of `faces[0]` in the face's corner order, then `faces[1]`'s, …
/// (the layout of `output::render::Layer::uvs`); `[0, 1]` over the texture
/// patch image, `v = 0` at its top row.
#[derive(Component, Clone, Debug, Default)]
pub struct PatchUvs(pub Vec<Vec2>);

/// Per face of [`PatchFaces`], whether runtime pasting must draw it: false
/// when later pastes hide it completely or the paste is transparent there
/// (Praun et al. §4).
#[derive(Component, Clone, Debug, Default)]
pub struct PatchDrawn(pub Vec<bool>);

/// The texture patches: RGBA images (straight alpha) with a transparent
/// border, addressed with clamping.
#[derive(Resource, Clone, Debug, Default)]
pub struct TexturePatches(pub Vec<Image>);

/// Per texture patch of [`TexturePatches`], the exemplar pixel of its
/// top-left pixel (`TexturePatch::origin`): a paste's patch coordinate
/// `uv` (in `[0, 1]` of the patch) is exemplar pixel
/// `origin + uv · (width, height)`, so other exemplar channels follow.
#[derive(Resource, Clone, Debug, Default)]
pub struct TexturePatchOrigins(pub Vec<[i64; 2]>);

/// A texture atlas of the lapped texture on a mesh entity (Praun et al.
/// §4): per-corner coordinates into the composited atlas image.
#[derive(Component, Clone, Debug, Default)]
pub struct AtlasTexture {
    /// One coordinate per mesh corner, `[0, 1]`, `v = 0` at the top row.
    pub uvs: Vec<Vec2>,
    /// The atlas (RGB).
    pub image: Image,
}

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
