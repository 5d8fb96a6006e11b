//! The texture patches' entries in the analysis cache (kind `patches`):
//! their key, their byte format (a `cache_format` header around what
//! cutting computes: alpha, centre, hull, origin; the colours are copied
//! from the exemplar again when read) and [`texture_patches_cached`], which
//! reads and writes them through the [`AnalysisStore`] its stage hands it.

use super::cut::{CutSettings, MaskKind, texture_patches};
use super::hull::Hull;
use super::mask::{TexturePatch, patch_image};
use crate::cache_format::AnalysisStore;
use crate::image::Image;
use crate::image::sample::Wrap;
use glam::Vec2;

/// The cache's kind of texture-patch entries.
pub const PATCH_CACHE_KIND: &str = "patches";

/// Version of the texture patches' cache entries: bump it whenever
/// [`texture_patches`] would cut anything else for the same inputs.
const PATCH_CACHE_VERSION: u32 = 1;

/// First bytes of a texture-patch cache entry.
const PATCH_CACHE_MAGIC: [u8; 8] = *b"SSPATCHS";

/// [`texture_patches`] through an analysis `store` (the on-disk cache;
/// `None`: none; a user mask image is never cached): a valid entry for the
/// same exemplar, settings and seed is read instead of cutting (the same
/// values, bit for bit); a missing, stale or corrupt one is rebuilt and
/// written.
///
/// # Errors
/// As [`texture_patches`].
pub fn texture_patches_cached(
    exemplar: &Image,
    wrap: Wrap,
    settings: &CutSettings,
    mask: Option<&Image>,
    seed: u64,
    store: Option<&dyn AnalysisStore>,
) -> Result<Vec<TexturePatch>, String> {
    let store = match store {
        Some(s) if settings.mask != MaskKind::Image => s,
        _ => return texture_patches(exemplar, wrap, settings, mask, seed),
    };
    let key = patch_cache_key(exemplar, wrap, settings, seed);
    if let Some(patches) = store
        .read(PATCH_CACHE_KIND, &key)
        .and_then(|bytes| patches_from_bytes(&bytes, &key, exemplar, wrap))
    {
        return Ok(patches);
    }
    let patches = texture_patches(exemplar, wrap, settings, mask, seed)?;
    store.write(PATCH_CACHE_KIND, &key, &patches_to_bytes(&patches, &key));
    Ok(patches)
}

/// The cache key of the texture patches: a BLAKE3 hash of the version, the
/// exemplar (size, channels, every value's bits), its addressing, every
/// setting [`texture_patches`] reads and the seed.
pub fn patch_cache_key(
    exemplar: &Image,
    wrap: Wrap,
    settings: &CutSettings,
    seed: u64,
) -> [u8; 32] {
    let mut h = crate::cache_format::key_hasher(&PATCH_CACHE_MAGIC, PATCH_CACHE_VERSION, exemplar);
    h.update(&[
        match wrap {
            Wrap::Repeat => 0u8,
            Wrap::Clamp => 1,
        },
        match settings.mask {
            MaskKind::Splotch => 0u8,
            MaskKind::Circle => 1,
            MaskKind::Image => 2,
        },
    ]);
    for v in [
        settings.patches,
        settings.patch_pixels,
        settings.hull_vertices,
    ] {
        h.update(&v.to_le_bytes());
    }
    h.update(&settings.falloff.to_bits().to_le_bytes());
    h.update(&seed.to_le_bytes());
    *h.finalize().as_bytes()
}

/// A cache entry of `patches`: what cutting computes (alpha, centre, hull,
/// origin); the colours are copied from the exemplar again when read.
pub fn patches_to_bytes(patches: &[TexturePatch], key: &[u8; 32]) -> Vec<u8> {
    let mut b = crate::cache_format::entry_header(&PATCH_CACHE_MAGIC, PATCH_CACHE_VERSION, key);
    b.extend_from_slice(&(patches.len() as u32).to_le_bytes());
    let f32s = |b: &mut Vec<u8>, v: &[f32]| {
        for x in v {
            b.extend_from_slice(&x.to_le_bytes());
        }
    };
    for p in patches {
        for v in [p.image.width, p.image.height] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        b.extend_from_slice(&(p.hull.vertices.len() as u32).to_le_bytes());
        f32s(&mut b, &p.alpha);
        f32s(&mut b, &[p.centre_px.x, p.centre_px.y]);
        for v in &p.hull.vertices {
            f32s(&mut b, &[v.x, v.y]);
        }
        for o in p.origin {
            b.extend_from_slice(&o.to_le_bytes());
        }
    }
    crate::cache_format::seal(b)
}

/// The patches of an entry written by [`patches_to_bytes`] with `key`, their
/// colours copied from `exemplar` (the key's); `None` for any other bytes.
pub fn patches_from_bytes(
    bytes: &[u8],
    key: &[u8; 32],
    exemplar: &Image,
    wrap: Wrap,
) -> Option<Vec<TexturePatch>> {
    let body = crate::cache_format::payload(bytes, &PATCH_CACHE_MAGIC, PATCH_CACHE_VERSION, key)?;
    let mut at = 0usize;
    let mut take = |n: usize| -> Option<&[u8]> {
        let s = body.get(at..at.checked_add(n)?)?;
        at += n;
        Some(s)
    };
    let u32_of = |s: &[u8]| u32::from_le_bytes([s[0], s[1], s[2], s[3]]);
    let f32s_of = |s: &[u8]| -> Vec<f32> {
        s.chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect()
    };
    let count = u32_of(take(4)?) as usize;
    let mut patches = Vec::with_capacity(count.min(1024));
    for _ in 0..count {
        let (w, h) = (u32_of(take(4)?), u32_of(take(4)?));
        let hull_n = u32_of(take(4)?) as usize;
        let pixels = (w as usize).checked_mul(h as usize)?;
        let alpha = f32s_of(take(pixels.checked_mul(4)?)?);
        let centre = f32s_of(take(8)?);
        let hull = f32s_of(take(hull_n.checked_mul(8)?)?);
        let mut origin = [0i64; 2];
        for o in origin.iter_mut() {
            let s = take(8)?;
            *o = i64::from_le_bytes(s.try_into().ok()?);
        }
        if w == 0 || h == 0 {
            return None;
        }
        patches.push(TexturePatch {
            image: patch_image(exemplar, wrap, origin, w, h, &alpha),
            alpha,
            centre_px: Vec2::new(centre[0], centre[1]),
            hull: Hull::new(
                hull.chunks_exact(2)
                    .map(|v| Vec2::new(v[0], v[1]))
                    .collect(),
            ),
            origin,
        });
    }
    (at == body.len()).then_some(patches)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exemplar() -> Image {
        let data = (0..48 * 40 * 3)
            .map(|i| ((i * 37) % 101) as f32 / 100.0)
            .collect();
        Image::from_data(48, 40, 3, data).expect("size matches")
    }

    /// An entry of [`Memory`]: kind, key, bytes.
    type Entry = (String, [u8; 32], Vec<u8>);

    /// An in-memory store.
    #[derive(Default)]
    struct Memory(std::sync::Mutex<Vec<Entry>>);

    impl AnalysisStore for Memory {
        fn read(&self, kind: &str, key: &[u8; 32]) -> Option<Vec<u8>> {
            let entries = self.0.lock().expect("lock");
            let found = entries.iter().find(|(k, e, _)| k == kind && e == key);
            found.map(|(_, _, b)| b.clone())
        }
        fn write(&self, kind: &str, key: &[u8; 32], bytes: &[u8]) {
            let mut entries = self.0.lock().expect("lock");
            entries.push((kind.into(), *key, bytes.to_vec()));
        }
    }

    #[test]
    fn texture_patch_cache_round_trips_and_rejects_other_keys_and_damage() {
        let ex = exemplar();
        let settings = CutSettings {
            mask: MaskKind::Splotch,
            patches: 3,
            patch_pixels: 24,
            falloff: 3.0,
            hull_vertices: 16,
        };
        let cut = texture_patches(&ex, Wrap::Clamp, &settings, None, 7).expect("cut");
        let key = patch_cache_key(&ex, Wrap::Clamp, &settings, 7);
        let bytes = patches_to_bytes(&cut, &key);
        let back = patches_from_bytes(&bytes, &key, &ex, Wrap::Clamp).expect("round trip");
        assert_eq!(back.len(), cut.len());
        for (a, b) in cut.iter().zip(&back) {
            assert_eq!(a.image, b.image);
            assert_eq!(a.alpha, b.alpha);
            assert_eq!(a.centre_px, b.centre_px);
            assert_eq!(a.hull.vertices, b.hull.vertices);
            assert_eq!(a.hull.bounds, b.hull.bounds);
            assert_eq!(a.origin, b.origin);
        }
        // Another seed or setting is another key.
        assert_ne!(key, patch_cache_key(&ex, Wrap::Clamp, &settings, 8));
        let other = CutSettings {
            falloff: 2.0,
            ..settings
        };
        assert_ne!(key, patch_cache_key(&ex, Wrap::Clamp, &other, 7));
        let mut bad = bytes.clone();
        bad[60] ^= 1;
        assert!(patches_from_bytes(&bad, &key, &ex, Wrap::Clamp).is_none());
        assert!(patches_from_bytes(&bytes[..bytes.len() - 3], &key, &ex, Wrap::Clamp).is_none());
        // Through a store: cut and written first, read second.
        let store = Memory::default();
        let first = texture_patches_cached(&ex, Wrap::Clamp, &settings, None, 7, Some(&store))
            .expect("cut");
        assert_eq!(store.0.lock().expect("lock").len(), 1);
        let second = texture_patches_cached(&ex, Wrap::Clamp, &settings, None, 7, Some(&store))
            .expect("read");
        assert_eq!(store.0.lock().expect("lock").len(), 1);
        assert_eq!(first.len(), second.len());
        for (a, b) in first.iter().zip(&second) {
            assert_eq!(a.image, b.image);
            assert_eq!(a.hull.vertices, b.hull.vertices);
        }
    }
}
