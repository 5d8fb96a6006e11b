//! The jump map (Zelinka & Garland 2004, §3, §4.5): per exemplar pixel a short
//! list of jumps (destination pixel and weight), integer and floating-point
//! look-ups (§6.4), and the byte format of the disk cache.
//!
//! Byte format, little endian, version [`FORMAT_VERSION`]:
//!
//! | bytes | content |
//! |---|---|
//! | 8 | magic `b"SSJMPMAP"` |
//! | 4 | format version |
//! | 32 | cache key ([`super::JumpMapSettings::cache_key`]) |
//! | 4 + 4 | exemplar width, height |
//! | 1 + 1 + 2 | boundary (0 toroidal, 1 inset), jumps per pixel `k`, zero |
//! | 16 + 16 | source region, destination region (x0, y0, x1, y1 as u32) |
//! | w·h | jump count per pixel (u8) |
//! | 4·w·h | accepted Poisson-disc diameter per pixel (f32) |
//! | 12·w·h·k | jump slots: destination x, y (u32) and weight (f32) |
//! | 32 | blake3 of all preceding bytes |

use super::{Boundary, JumpMapError};

/// Magic bytes at the start of a cached jump map.
pub const MAGIC: [u8; 8] = *b"SSJMPMAP";
/// Version of the byte format written by [`JumpMap::to_bytes`].
pub const FORMAT_VERSION: u32 = 1;
const HEADER_LEN: usize = 8 + 4 + 32 + 8 + 4 + 32;
const CHECKSUM_LEN: usize = 32;

/// Integer address of an exemplar pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct TexelCoord {
    /// Column, `0..width`.
    pub x: u32,
    /// Row, `0..height` (row 0 at the top).
    pub y: u32,
}

impl TexelCoord {
    /// The address `(x, y)`.
    #[inline]
    pub const fn new(x: u32, y: u32) -> Self {
        Self { x, y }
    }
}

/// A half-open rectangle of exemplar pixels `[x0, x1) × [y0, y1)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct TexelRect {
    /// First column inside.
    pub x0: u32,
    /// First row inside.
    pub y0: u32,
    /// One past the last column inside.
    pub x1: u32,
    /// One past the last row inside.
    pub y1: u32,
}

impl TexelRect {
    /// Whether `(x, y)` lies inside.
    #[inline]
    pub fn contains(&self, x: u32, y: u32) -> bool {
        x >= self.x0 && x < self.x1 && y >= self.y0 && y < self.y1
    }

    /// Width in pixels.
    #[inline]
    pub fn width(&self) -> u32 {
        self.x1.saturating_sub(self.x0)
    }

    /// Height in pixels.
    #[inline]
    pub fn height(&self) -> u32 {
        self.y1.saturating_sub(self.y0)
    }

    /// Whether the rectangle holds no pixel.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.width() == 0 || self.height() == 0
    }

    /// The rectangle shrunk by `n` pixels on every side (possibly empty).
    pub fn eroded(&self, n: u32) -> Self {
        Self {
            x0: self.x0 + n,
            y0: self.y0 + n,
            x1: self.x1.saturating_sub(n).max(self.x0 + n),
            y1: self.y1.saturating_sub(n).max(self.y0 + n),
        }
    }
}

/// One jump: where it leads and its weight (§4.5).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Jump {
    /// The destination pixel.
    pub to: TexelCoord,
    /// Probability weight in `[0, 1]`; a pixel's weights sum to at most 1.
    pub weight: f32,
}

/// A jump returned by a floating-point look-up (§6.4, Fig. 16).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FloatJump {
    /// Destination address in exemplar pixels (pixel centres at integers),
    /// already offset by the look-up address's subpixel offset.
    pub to: [f32; 2],
    /// The jump's weight scaled by its bilinear factor.
    pub weight: f32,
}

/// The jump map of one exemplar under one set of settings.
///
/// Architecture invariant: `counts`, `discs` have one entry per exemplar
/// pixel, `slots` has `k` per pixel; pixels outside `sources` have count 0;
/// every jump's destination lies in `destinations`; a pixel's jumps are sorted
/// best (most similar) first, so weights never increase along a list.
#[derive(Clone, Debug, PartialEq)]
pub struct JumpMap {
    width: u32,
    height: u32,
    boundary: Boundary,
    k: u32,
    sources: TexelRect,
    destinations: TexelRect,
    counts: Vec<u8>,
    discs: Vec<f32>,
    slots: Vec<Jump>,
    key: [u8; 32],
}

/// The parts a [`JumpMap`] is assembled from (see [`JumpMap::from_parts`]).
#[derive(Clone, Debug, PartialEq)]
pub struct JumpMapParts {
    /// Exemplar width in pixels.
    pub width: u32,
    /// Exemplar height in pixels.
    pub height: u32,
    /// Border handling the map was built with.
    pub boundary: Boundary,
    /// Jump slots per pixel.
    pub k: u32,
    /// Pixels that carry jump lists.
    pub sources: TexelRect,
    /// Region all destinations lie in.
    pub destinations: TexelRect,
    /// Number of jumps per pixel (`<= k`).
    pub counts: Vec<u8>,
    /// Accepted Poisson-disc diameter per pixel (pixels; 0 where no list).
    pub discs: Vec<f32>,
    /// `k` slots per pixel; slots past the count are ignored.
    pub slots: Vec<Jump>,
    /// The cache key of the exemplar and settings.
    pub key: [u8; 32],
}

impl JumpMap {
    /// Assembles a map, checking every invariant.
    ///
    /// # Errors
    /// [`JumpMapError::InvalidContent`] describing the first violation.
    pub fn from_parts(p: JumpMapParts) -> Result<Self, JumpMapError> {
        let bad = |m: String| Err(JumpMapError::InvalidContent(m));
        if p.width == 0 || p.height == 0 || p.width > 65535 || p.height > 65535 {
            return bad(format!("exemplar size {}x{}", p.width, p.height));
        }
        if p.k == 0 || p.k > 255 {
            return bad(format!("{} jumps per pixel", p.k));
        }
        let n = p.width as usize * p.height as usize;
        if p.counts.len() != n || p.discs.len() != n || p.slots.len() != n * p.k as usize {
            return bad("array lengths do not match the exemplar size".into());
        }
        for r in [p.sources, p.destinations] {
            if r.x1 > p.width || r.y1 > p.height || r.x0 > r.x1 || r.y0 > r.y1 {
                return bad(format!("region {r:?} outside the exemplar"));
            }
        }
        for y in 0..p.height {
            for x in 0..p.width {
                let i = (y * p.width + x) as usize;
                let c = p.counts[i] as u32;
                if c > p.k || (c > 0 && !p.sources.contains(x, y)) {
                    return bad(format!("pixel ({x}, {y}) has {c} jumps"));
                }
                if !(p.discs[i].is_finite() && p.discs[i] >= 0.0) {
                    return bad(format!("pixel ({x}, {y}) has disc diameter {}", p.discs[i]));
                }
                let list = &p.slots[i * p.k as usize..][..c as usize];
                let mut sum = 0.0f64;
                let mut prev = f32::INFINITY;
                for j in list {
                    if !p.destinations.contains(j.to.x, j.to.y) {
                        return bad(format!(
                            "pixel ({x}, {y}) jumps to {:?} outside the destinations",
                            j.to
                        ));
                    }
                    if !(j.weight.is_finite() && (0.0..=1.0).contains(&j.weight)) || j.weight > prev
                    {
                        return bad(format!("pixel ({x}, {y}) has jump weight {}", j.weight));
                    }
                    prev = j.weight;
                    sum += j.weight as f64;
                }
                if sum > 1.0 + 1e-4 {
                    return bad(format!("pixel ({x}, {y}) has weights summing to {sum}"));
                }
            }
        }
        Ok(Self {
            width: p.width,
            height: p.height,
            boundary: p.boundary,
            k: p.k,
            sources: p.sources,
            destinations: p.destinations,
            counts: p.counts,
            discs: p.discs,
            slots: p.slots,
            key: p.key,
        })
    }

    /// Exemplar width in pixels.
    #[inline]
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Exemplar height in pixels.
    #[inline]
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Border handling the map was built with.
    #[inline]
    pub fn boundary(&self) -> Boundary {
        self.boundary
    }

    /// Jump slots per pixel (the `k` of §4.4).
    #[inline]
    pub fn max_jumps(&self) -> u32 {
        self.k
    }

    /// Pixels that carry jump lists: the whole exemplar when toroidal, the
    /// inset region otherwise (§4.2). Synthesis keeps its addresses in here.
    #[inline]
    pub fn sources(&self) -> TexelRect {
        self.sources
    }

    /// Region every jump destination lies in: the source region when
    /// toroidal, the source region shrunk by one pixel when inset, so that a
    /// destination moved by one pixel in any direction is still a source (§6.6:
    /// with images the offsets are known in advance).
    #[inline]
    pub fn destinations(&self) -> TexelRect {
        self.destinations
    }

    /// The cache key this map was built under.
    #[inline]
    pub fn key(&self) -> &[u8; 32] {
        &self.key
    }

    /// The jumps at pixel `(x, y)`, best first; empty outside the source region
    /// or outside the exemplar.
    #[inline]
    pub fn jumps_at(&self, x: u32, y: u32) -> &[Jump] {
        if x >= self.width || y >= self.height {
            return &[];
        }
        let i = (y * self.width + x) as usize;
        &self.slots[i * self.k as usize..][..self.counts[i] as usize]
    }

    /// The Poisson-disc diameter (pixels) accepted at `(x, y)` after halving
    /// (§4.4): every jump of the pixel ends at least this far from the pixel
    /// and from the pixel's other jumps (toroidal distance when toroidal).
    /// Never below the settings' `min_disc_diameter`; 0 for pixels without list.
    #[inline]
    pub fn disc_diameter_at(&self, x: u32, y: u32) -> f32 {
        if x >= self.width || y >= self.height {
            return 0.0;
        }
        self.discs[(y * self.width + x) as usize]
    }

    /// Sum of the jump weights at `(x, y)`: the probability mass of jumping
    /// from there (§4.5).
    pub fn weight_sum_at(&self, x: u32, y: u32) -> f32 {
        self.jumps_at(x, y).iter().map(|j| j.weight).sum()
    }

    /// Floating-point look-up (§6.4, Fig. 16): the jump lists of the four
    /// pixels around address `(x, y)` (exemplar pixels, pixel centres at
    /// integers), each weight scaled by its bilinear factor and each destination
    /// moved by the address's offset from that pixel. Appends to `out` (cleared
    /// first). Neighbours wrap when toroidal; when inset, neighbours outside
    /// the source region contribute nothing. The weights in `out` sum to at
    /// most 1.
    pub fn jumps_at_float(&self, x: f32, y: f32, out: &mut Vec<FloatJump>) {
        out.clear();
        if !(x.is_finite() && y.is_finite()) {
            return;
        }
        let fx = x.floor();
        let fy = y.floor();
        let (ax, ay) = (x - fx, y - fy);
        for (dx, dy, wb) in [
            (0i64, 0i64, (1.0 - ax) * (1.0 - ay)),
            (1, 0, ax * (1.0 - ay)),
            (0, 1, (1.0 - ax) * ay),
            (1, 1, ax * ay),
        ] {
            if wb <= 0.0 {
                continue;
            }
            let nx = fx as i64 + dx;
            let ny = fy as i64 + dy;
            let (px, py) = match self.boundary {
                Boundary::Toroidal => (
                    nx.rem_euclid(self.width as i64) as u32,
                    ny.rem_euclid(self.height as i64) as u32,
                ),
                Boundary::Inset => {
                    if nx < 0 || ny < 0 || nx >= self.width as i64 || ny >= self.height as i64 {
                        continue;
                    }
                    (nx as u32, ny as u32)
                }
            };
            // The address's offset from this neighbour, in pixels.
            let ox = x - nx as f32;
            let oy = y - ny as f32;
            for j in self.jumps_at(px, py) {
                out.push(FloatJump {
                    to: [j.to.x as f32 + ox, j.to.y as f32 + oy],
                    weight: j.weight * wb,
                });
            }
        }
    }

    /// The map as bytes for the disk cache (format in the module docs).
    pub fn to_bytes(&self) -> Vec<u8> {
        let n = self.counts.len();
        let mut b = Vec::with_capacity(HEADER_LEN + n * 5 + self.slots.len() * 12 + CHECKSUM_LEN);
        b.extend_from_slice(&MAGIC);
        b.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        b.extend_from_slice(&self.key);
        b.extend_from_slice(&self.width.to_le_bytes());
        b.extend_from_slice(&self.height.to_le_bytes());
        b.push(match self.boundary {
            Boundary::Toroidal => 0,
            Boundary::Inset => 1,
        });
        b.push(self.k as u8);
        b.extend_from_slice(&[0, 0]);
        for r in [self.sources, self.destinations] {
            for v in [r.x0, r.y0, r.x1, r.y1] {
                b.extend_from_slice(&v.to_le_bytes());
            }
        }
        b.extend_from_slice(&self.counts);
        for d in &self.discs {
            b.extend_from_slice(&d.to_le_bytes());
        }
        for j in &self.slots {
            b.extend_from_slice(&j.to.x.to_le_bytes());
            b.extend_from_slice(&j.to.y.to_le_bytes());
            b.extend_from_slice(&j.weight.to_le_bytes());
        }
        let sum = blake3::hash(&b);
        b.extend_from_slice(sum.as_bytes());
        b
    }

    /// Reads a map written by [`Self::to_bytes`], accepting it only if it was
    /// built under `expected_key` (the exemplar and settings of this run).
    /// Never panics on any input.
    ///
    /// # Errors
    /// [`JumpMapError::Truncated`], [`JumpMapError::BadMagic`],
    /// [`JumpMapError::UnsupportedVersion`], [`JumpMapError::ChecksumMismatch`]
    /// (any corrupt byte), [`JumpMapError::StaleCache`] (other exemplar or
    /// settings) or [`JumpMapError::InvalidContent`].
    pub fn from_bytes(bytes: &[u8], expected_key: &[u8; 32]) -> Result<Self, JumpMapError> {
        let min = HEADER_LEN + CHECKSUM_LEN;
        if bytes.len() < 8 {
            return Err(JumpMapError::Truncated {
                len: bytes.len(),
                needed: min,
            });
        }
        if bytes[..8] != MAGIC {
            return Err(JumpMapError::BadMagic);
        }
        if bytes.len() < min {
            return Err(JumpMapError::Truncated {
                len: bytes.len(),
                needed: min,
            });
        }
        let (body, sum) = bytes.split_at(bytes.len() - CHECKSUM_LEN);
        if blake3::hash(body).as_bytes() != sum {
            return Err(JumpMapError::ChecksumMismatch);
        }
        let mut r = Reader { b: body, at: 8 };
        let version = r.u32()?;
        if version != FORMAT_VERSION {
            return Err(JumpMapError::UnsupportedVersion {
                found: version,
                expected: FORMAT_VERSION,
            });
        }
        let key: [u8; 32] = r.take(32)?.try_into().map_err(|_| r.short())?;
        if &key != expected_key {
            return Err(JumpMapError::StaleCache);
        }
        let width = r.u32()?;
        let height = r.u32()?;
        let boundary = match r.take(1)?[0] {
            0 => Boundary::Toroidal,
            1 => Boundary::Inset,
            v => return Err(JumpMapError::InvalidContent(format!("boundary code {v}"))),
        };
        let k = r.take(1)?[0] as u32;
        r.take(2)?;
        let mut rect = || -> Result<TexelRect, JumpMapError> {
            Ok(TexelRect {
                x0: r.u32()?,
                y0: r.u32()?,
                x1: r.u32()?,
                y1: r.u32()?,
            })
        };
        let sources = rect()?;
        let destinations = rect()?;
        if width > 65535 || height > 65535 {
            return Err(JumpMapError::InvalidContent(format!(
                "exemplar size {width}x{height}"
            )));
        }
        let n = width as usize * height as usize;
        let needed = HEADER_LEN + n * 5 + n * k as usize * 12;
        if body.len() != needed {
            return Err(JumpMapError::InvalidContent(format!(
                "{} body bytes for a {width}x{height} map with {k} jumps per pixel, expected {needed}",
                body.len()
            )));
        }
        let counts = r.take(n)?.to_vec();
        let discs = r
            .take(4 * n)?
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let slots = r
            .take(12 * n * k as usize)?
            .chunks_exact(12)
            .map(|c| {
                let u = |o: usize| u32::from_le_bytes([c[o], c[o + 1], c[o + 2], c[o + 3]]);
                Jump {
                    to: TexelCoord::new(u(0), u(4)),
                    weight: f32::from_bits(u(8)),
                }
            })
            .collect();
        Self::from_parts(JumpMapParts {
            width,
            height,
            boundary,
            k,
            sources,
            destinations,
            counts,
            discs,
            slots,
            key,
        })
    }
}

/// A bounds-checked little-endian reader.
struct Reader<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn short(&self) -> JumpMapError {
        JumpMapError::Truncated {
            len: self.b.len() + CHECKSUM_LEN,
            needed: self.at + CHECKSUM_LEN + 1,
        }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], JumpMapError> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.b.len())
            .ok_or_else(|| self.short())?;
        let s = &self.b[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn u32(&mut self) -> Result<u32, JumpMapError> {
        let s = self.take(4)?;
        Ok(u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
    }
}
