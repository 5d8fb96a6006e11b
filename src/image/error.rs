use std::path::PathBuf;

/// Everything that can be wrong with an exemplar image a user gives us.
#[derive(Debug, thiserror::Error)]
pub enum ImageError {
    /// The file could not be read or decoded.
    #[error("cannot load image {path}: {message}")]
    Load { path: PathBuf, message: String },
    /// The file declares more pixels than an exemplar or map may have
    /// (checked from its header, before decoding).
    #[error(
        "image {path} declares {width}x{height} pixels, over the limit of {max_side} pixels per side and {max_pixels} pixels in all ({why}); use a smaller image"
    )]
    TooLarge {
        path: PathBuf,
        width: u32,
        height: u32,
        max_side: u32,
        max_pixels: u64,
        why: String,
    },
    /// The image has no pixels or an unsupported layout.
    #[error("image {path}: {message}")]
    Invalid { path: PathBuf, message: String },
    /// The exemplar is smaller than a configured neighbourhood or patch.
    #[error(
        "exemplar {name} is {width}x{height} pixels, smaller than the {what} of {needed}x{needed} pixels; use a larger exemplar or a smaller {what}"
    )]
    TooSmall {
        name: String,
        width: u32,
        height: u32,
        what: String,
        needed: u32,
    },
    /// A builtin exemplar name or option is wrong.
    #[error("builtin exemplar {name:?}: {message}")]
    Builtin { name: String, message: String },
    /// A material channel map (height, normal, roughness) is not the size
    /// of the colour exemplar it follows.
    #[error(
        "{key} {path} is {width}x{height} pixels but the exemplar {exemplar} is {exemplar_width}x{exemplar_height}; channel maps must be the same size as the exemplar"
    )]
    ChannelSize {
        key: String,
        path: String,
        width: u32,
        height: u32,
        exemplar: String,
        exemplar_width: u32,
        exemplar_height: u32,
    },
}
