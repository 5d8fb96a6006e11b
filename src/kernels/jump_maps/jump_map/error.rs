//! Errors of jump map analysis, synthesis and the cache format.

/// Everything that can go wrong building, loading or using a jump map.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum JumpMapError {
    /// A setting is outside its allowed range.
    #[error("jump map setting `{name}` = {value} is invalid: expected {expected}")]
    InvalidSetting {
        /// The setting's field name.
        name: &'static str,
        /// The value given.
        value: String,
        /// What is allowed.
        expected: &'static str,
    },
    /// The exemplar has no pixels, no channels, or data of the wrong length.
    #[error("exemplar is {width}x{height} with {channels} channels and {len} values: {message}")]
    BadExemplar {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// Channels per pixel.
        channels: u32,
        /// Length of the data buffer.
        len: usize,
        /// What is wrong.
        message: &'static str,
    },
    /// The exemplar is too small for the neighbourhoods when inset (§4.2).
    #[error(
        "exemplar is {width}x{height} pixels, too small for inset neighbourhoods that need a border of {margin} pixels on every side; allowed: an exemplar of at least {min_side}x{min_side} pixels, smaller neighbourhoods or toroidal boundaries"
    )]
    ExemplarTooSmall {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
        /// The inset border (pixels) the neighbourhoods need.
        margin: u32,
        /// The smallest side that leaves the neighbourhoods room.
        min_side: u32,
    },
    /// The exemplar is larger than the 65535×65535 pixels addresses are packed into.
    #[error("exemplar is {width}x{height} pixels; jump maps support at most 65535 pixels per side")]
    ExemplarTooLarge {
        /// Width in pixels.
        width: u32,
        /// Height in pixels.
        height: u32,
    },
    /// The PCA decomposition failed (the SVD did not converge).
    #[error("principal component analysis failed: {0}")]
    Pca(String),
    /// The exemplar given to synthesis is not the one the map was built for.
    #[error(
        "jump map is for a {map_width}x{map_height} exemplar but the exemplar is {width}x{height}"
    )]
    ExemplarMismatch {
        /// Exemplar width the map was built for.
        map_width: u32,
        /// Exemplar height the map was built for.
        map_height: u32,
        /// Width of the exemplar given.
        width: u32,
        /// Height of the exemplar given.
        height: u32,
    },
    /// A control field does not cover the output image.
    #[error("control field is {field_width}x{field_height} but the output is {width}x{height}")]
    FieldMismatch {
        /// Field width.
        field_width: u32,
        /// Field height.
        field_height: u32,
        /// Output width.
        width: u32,
        /// Output height.
        height: u32,
    },
    /// The cache bytes do not start with the jump map magic.
    #[error("not a jump map cache file (bad magic bytes)")]
    BadMagic,
    /// The cache was written by another format version.
    #[error("jump map cache has format version {found}, this build reads version {expected}")]
    UnsupportedVersion {
        /// Version in the file.
        found: u32,
        /// Version this build writes and reads.
        expected: u32,
    },
    /// The cache is shorter than its header says.
    #[error("jump map cache is truncated: {len} bytes, at least {needed} needed")]
    Truncated {
        /// Bytes given.
        len: usize,
        /// Bytes needed.
        needed: usize,
    },
    /// The checksum over the cache bytes does not match: the file is corrupt.
    #[error("jump map cache is corrupt (checksum mismatch)")]
    ChecksumMismatch,
    /// The cache was built from another exemplar or other settings.
    #[error("jump map cache is stale: it was built from another exemplar or other settings")]
    StaleCache,
    /// The cache passed its checksum but its content is inconsistent.
    #[error("jump map content is invalid: {0}")]
    InvalidContent(String),
}
