//! The byte format of an analysis-cache entry, without the disk: the key
//! every analysis hashes its exemplar into ([`key_hasher`]), the header
//! ([`entry_header`]), the checksum ([`seal`]) and the check of all three
//! when read ([`payload`]); and the [`AnalysisStore`] a kernel reads and
//! writes entries through. The disk side is `crate::cache`.

/// Where a kernel keeps its analyses between runs: entries of `kind` by
/// key (`crate::cache::DiskCache` on disk). A read entry is only a hint:
/// the kernel re-validates it ([`payload`]).
pub trait AnalysisStore: Sync {
    /// The entry's bytes, if there is one.
    fn read(&self, kind: &str, key: &[u8; 32]) -> Option<Vec<u8>>;
    /// Stores an entry (best effort: a failed write is a later miss).
    fn write(&self, kind: &str, key: &[u8; 32], bytes: &[u8]);
}

/// A key hasher started with `tag`, the analysis `version` and the whole
/// `image` (size, channels, value count, every value's bits, little-endian):
/// the part every analysis key shares. The caller adds its settings and
/// finalises.
pub fn key_hasher(tag: &[u8], version: u32, image: &crate::image::Image) -> blake3::Hasher {
    let mut h = blake3::Hasher::new();
    h.update(tag);
    h.update(&version.to_le_bytes());
    for v in [image.width, image.height, image.channels] {
        h.update(&v.to_le_bytes());
    }
    h.update(&(image.data.len() as u64).to_le_bytes());
    #[cfg(target_endian = "little")]
    h.update(bytemuck::cast_slice::<f32, u8>(&image.data));
    #[cfg(not(target_endian = "little"))]
    for v in &image.data {
        h.update(&v.to_bits().to_le_bytes());
    }
    h
}

/// Length of an entry's header written by [`entry_header`].
pub const HEADER_LEN: usize = 8 + 4 + 32;

/// The start of an entry: `magic`, the format `version`, the `key`. The
/// payload follows; [`seal`] appends the checksum.
pub fn entry_header(magic: &[u8; 8], version: u32, key: &[u8; 32]) -> Vec<u8> {
    let mut b = Vec::with_capacity(HEADER_LEN);
    b.extend_from_slice(magic);
    b.extend_from_slice(&version.to_le_bytes());
    b.extend_from_slice(key);
    b
}

/// Appends the BLAKE3 checksum of everything in `entry` to it.
pub fn seal(mut entry: Vec<u8>) -> Vec<u8> {
    let sum = blake3::hash(&entry);
    entry.extend_from_slice(sum.as_bytes());
    entry
}

/// The payload of an entry made by [`entry_header`] and [`seal`], if its
/// checksum, magic, version and key all match; `None` otherwise.
pub fn payload<'a>(
    bytes: &'a [u8],
    magic: &[u8; 8],
    version: u32,
    key: &[u8; 32],
) -> Option<&'a [u8]> {
    if bytes.len() < HEADER_LEN + 32 {
        return None;
    }
    let (body, sum) = bytes.split_at(bytes.len() - 32);
    (blake3::hash(body).as_bytes() == sum
        && body[..8] == magic[..]
        && body[8..12] == version.to_le_bytes()
        && &body[12..HEADER_LEN] == key)
        .then(|| &body[HEADER_LEN..])
}
