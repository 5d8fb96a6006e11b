//! Jump maps (Zelinka & Garland 2004, "Jump Map-Based Interactive Texture
//! Synthesis", ACM TOG): an analysis pass that links every exemplar pixel to a
//! few pixels with similar neighbourhoods, and fast synthesis passes that copy
//! exemplar pixels and occasionally follow a link.
//!
//! Analysis (§4), one file per step:
//! - [`settings`]: [`JumpMapSettings`], every parameter with default, unit and range,
//!   and the cache key.
//! - [`neighbourhoods`]: multi-resolution neighbourhood vectors over a Gaussian
//!   pyramid, each level weighted equally (§4.1, §4.3), toroidal or inset (§4.2).
//! - [`pca`]: principal components of a random sample of neighbourhoods (§4.2).
//! - [`ann`]: (1+ε)-approximate k nearest neighbours in PCA space (§4.2): a
//!   kiddo kd-tree on the leading components with exact refinement, or a
//!   blocked exhaustive search where that is faster.
//! - [`poisson`]: Poisson-disc filtering of the candidates with halving (§4.4).
//! - [`normalise`]: jump weights in `[α, 1]` per pixel (§4.5).
//! - [`analysis`]: the whole analysis, [`analyse`] (and
//!   [`analysis::analyse_with_stats`] for PCA and Poisson statistics).
//! - [`map`]: the [`JumpMap`] itself, integer and floating-point look-ups (§6.4),
//!   and its byte format for the disk cache.
//!
//! Synthesis:
//! - [`order`]: scanline, serpentine and Hilbert pixel orders for any size (§5.3).
//! - [`sources`]: the per-output-pixel source map, colour gathering and the
//!   patch visualisation of Fig. 5.
//! - [`synth_pixel`]: pixel-based image synthesis with boundary avoidance (§5).
//! - [`synth_patch`]: patch-based image synthesis with selection tables (§7.1).
//! - [`control`]: image synthesis under orientation and scale fields (§7.2).
//!
//! Surface synthesis (§6) lives elsewhere; it needs only [`JumpMap`] and
//! [`JumpMap::jumps_at_float`].

pub mod analysis;
pub mod ann;
pub mod control;
mod error;
pub mod map;
pub mod neighbourhoods;
pub mod normalise;
pub mod order;
pub mod pca;
pub mod poisson;
pub mod refine;
pub mod settings;
pub mod sources;
pub mod synth_patch;
pub mod synth_pixel;

pub use analysis::analyse;
pub use ann::AnnSearch;
pub use control::{
    ControlField, ControlledOutput, ControlledSynthesisSettings, synthesize_controlled,
    synthesize_controlled_with_progress,
};
pub use error::JumpMapError;
pub use map::{FloatJump, Jump, JumpMap, TexelCoord, TexelRect};
pub use order::{PixelOrder, PixelOrderIter};
pub use settings::{Boundary, JumpMapSettings};
pub use sources::{SourceMap, SynthesisOutput};
pub use synth_patch::{
    PatchSeams, PatchSynthesisSettings, synthesize_patch_sources_with_progress, synthesize_patches,
    synthesize_patches_with_progress,
};
pub use synth_pixel::{
    MATCH_RADIUS, PixelChoice, PixelSynthesisSettings, synthesize_pixels,
    synthesize_pixels_with_progress, synthesize_sources, synthesize_sources_with_progress,
};
