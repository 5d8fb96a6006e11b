//! The exemplar as the matcher reads it: Gaussian stack (or pyramid) levels
//! laid out as padded channel planes, and the anti-aliasing level choice of
//! Bangay & Morkel 2006 §3.3.4.

use super::spectral::LevelSpectra;
use crate::image::pyramid::{gaussian_pyramid, gaussian_stack};
use crate::image::{Image, sample::Wrap};
use crate::kernels::coherent::appearance::{AppearanceLevel, AppearanceSpec, appearance_level};

/// Candidates are scored this many at a time (adjacent texels of one row).
pub(super) const TILE: usize = 32;

/// Which multi-resolution exemplar the matcher uses (§3.3.1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ImageLevels {
    /// Gaussian stack (Lefebvre & Hoppe 2005): every level the exemplar's
    /// size, blur doubling per level; `a = 1` in §3.3.2. Region vertices
    /// each read the level of their own density (§3.3.4).
    #[default]
    Stack,
    /// Gaussian pyramid: level `m` is `2ᵐ` times smaller; `a = 2`. A whole
    /// region is matched on the level of its centre.
    Pyramid,
}

/// One level laid out for matching: one plane per channel, extended so
/// that every candidate `x` plus any reduced offset (see
/// [`MatchImages::reduce_offset`]) is a plain index, and 32 candidates of a
/// row read 32 contiguous values.
#[derive(Clone, Debug)]
pub(super) struct Planes {
    /// Level width and height in texels.
    pub width: usize,
    pub height: usize,
    /// Padding before column 0 and row 0.
    left: usize,
    top: usize,
    stride: usize,
    plane: usize,
    pub data: Vec<f32>,
}

impl Planes {
    fn new(img: &Image, wrap: Wrap) -> Self {
        let (w, h) = (img.width as usize, img.height as usize);
        let c = img.channels as usize;
        let w_tiles = w.div_ceil(TILE) * TILE;
        let (left, top, stride, rows) = match wrap {
            // Offsets reduce to 0..w, so columns run to w_tiles + w − 1.
            Wrap::Repeat => (0, 0, w_tiles + w - 1, 2 * h - 1),
            // Offsets reduce to −(w−1)..=w−1.
            Wrap::Clamp => (w - 1, h - 1, (w - 1) + w_tiles + (w - 1), 3 * h - 2),
        };
        let plane = stride * rows;
        let mut data = vec![0.0f32; plane * c];
        for row in 0..rows {
            let y = row as i64 - top as i64;
            for col in 0..stride {
                let x = col as i64 - left as i64;
                let px = img.texel(x, y, wrap);
                for (ch, &v) in px.iter().enumerate() {
                    data[ch * plane + row * stride + col] = v;
                }
            }
        }
        Self {
            width: w,
            height: h,
            left,
            top,
            stride,
            plane,
            data,
        }
    }

    /// Index into `data` of channel `c` at candidate `(x, y)` plus the
    /// reduced offset `(ox, oy)`.
    #[inline(always)]
    pub fn index(&self, c: usize, x: usize, y: usize, ox: i32, oy: i32) -> usize {
        let row = (y as i64 + oy as i64 + self.top as i64) as usize;
        let col = (x as i64 + ox as i64 + self.left as i64) as usize;
        c * self.plane + row * self.stride + col
    }
}

/// The exemplar's levels, ready for region matching.
#[derive(Clone, Debug)]
pub struct MatchImages {
    kind: ImageLevels,
    wrap: Wrap,
    channels: usize,
    images: Vec<Image>,
    planes: Vec<Planes>,
    /// Per level, appearance vectors and k-coherence sets, where prepared
    /// ([`MatchImages::prepare_similar`]).
    similar: Vec<Option<AppearanceLevel>>,
    /// Per level, its spectra for the FFT search, computed on first use.
    spectra: Vec<std::sync::OnceLock<LevelSpectra>>,
}

impl MatchImages {
    /// Builds `levels` Gaussian stack or pyramid levels of `exemplar`
    /// (level 0 is the exemplar itself), addressed with `wrap`.
    ///
    /// Memory: about `4 × levels × pixels × channels` floats with
    /// `Wrap::Repeat` (9× with `Clamp`), since offsets are pre-reduced.
    ///
    /// Preconditions: the exemplar has at least one pixel; `levels >= 1`.
    pub fn new(exemplar: &Image, kind: ImageLevels, levels: usize, wrap: Wrap) -> Self {
        let levels = levels.max(1);
        let images = match kind {
            ImageLevels::Stack => gaussian_stack(exemplar, levels, wrap),
            ImageLevels::Pyramid => gaussian_pyramid(exemplar, levels, wrap),
        };
        let planes = images.iter().map(|i| Planes::new(i, wrap)).collect();
        Self {
            kind,
            wrap,
            channels: exemplar.channels as usize,
            similar: vec![None; images.len()],
            spectra: vec![std::sync::OnceLock::new(); images.len()],
            images,
            planes,
        }
    }

    /// Computes, for each of `levels` (out-of-range ones are ignored), every
    /// texel's `k` most similar texels of that level
    /// ([`crate::kernels::coherent::appearance`]: leading principal
    /// components of Gaussian-weighted 5 × 5 neighbourhoods, points spaced
    /// like the level's texels, `2ˡ` level-0 texels on a stack, capped at a
    /// fifth of the exemplar), for [`super::Candidates::Coherent`].
    /// Deterministic; `seed` picks the sample the components are fitted on.
    pub fn prepare_similar(&mut self, levels: &[usize], k: usize, seed: u64) {
        for &l in levels {
            if l >= self.images.len() || self.similar[l].is_some() {
                continue;
            }
            let img = &self.images[l];
            let cap = (img.width.min(img.height) as f32 / 5.0).max(1.0);
            let spacing = match self.kind {
                ImageLevels::Stack => ((1u64 << l.min(62)) as f32).min(cap),
                ImageLevels::Pyramid => 1.0,
            };
            let spec = AppearanceSpec {
                window: 5,
                spacing,
                dims: 8,
                k,
                seed: crate::kernels::mix(seed, l as u64, 0xC0DE),
                wrap: self.wrap,
            };
            self.similar[l] = Some(appearance_level(img, &spec));
        }
    }

    /// The similarity sets of level `l`, if prepared.
    pub fn similar(&self, l: usize) -> Option<&AppearanceLevel> {
        self.similar.get(l)?.as_ref()
    }

    /// Bytes the FFT search takes at most for an exemplar of `width ×
    /// height × channels` with `levels` levels searched by `threads`
    /// threads: every level's spectra (each computed on first use) and each
    /// thread's buffers; none above [`super::spectral::MAX_TEXELS`].
    pub fn spectral_bytes(
        width: u32,
        height: u32,
        channels: u32,
        levels: usize,
        threads: usize,
    ) -> u64 {
        let (w, h) = (width as usize, height as usize);
        if w * h > super::spectral::MAX_TEXELS {
            return 0;
        }
        levels as u64 * LevelSpectra::bytes(w, h, channels as usize)
            + threads as u64 * LevelSpectra::scratch_bytes(w, h)
    }

    /// The largest useful level count: levels until the blur (or the
    /// pyramid level) spans the exemplar's smaller side.
    pub fn default_levels(exemplar: &Image) -> usize {
        Self::default_levels_for(exemplar.width, exemplar.height)
    }

    /// [`Self::default_levels`] of a `width × height` exemplar.
    pub fn default_levels_for(width: u32, height: u32) -> usize {
        let side = width.min(height).max(1);
        (32 - side.leading_zeros()) as usize
    }

    /// Stack or pyramid.
    pub fn kind(&self) -> ImageLevels {
        self.kind
    }

    /// Addressing outside the exemplar.
    pub fn wrap(&self) -> Wrap {
        self.wrap
    }

    /// Values per texel.
    pub fn channels(&self) -> usize {
        self.channels
    }

    /// Number of levels.
    pub fn levels(&self) -> usize {
        self.images.len()
    }

    /// The image of level `l`.
    pub fn image(&self, l: usize) -> &Image {
        &self.images[l]
    }

    pub(super) fn planes(&self, l: usize) -> &Planes {
        &self.planes[l]
    }

    /// The spectra of level `l` ([`super::spectral`]), computed on first
    /// use.
    pub(super) fn spectra(&self, l: usize) -> &LevelSpectra {
        self.spectra[l].get_or_init(|| LevelSpectra::new(&self.images[l]))
    }

    /// Texels of level 0 per texel of level `l`: `aˡ` of §3.3.2.
    pub fn level_factor(&self, l: usize) -> f32 {
        match self.kind {
            ImageLevels::Stack => 1.0,
            ImageLevels::Pyramid => (1u64 << l.min(62)) as f32,
        }
    }

    /// The anti-aliasing level of §3.3.4: a vertex whose edges span
    /// `texels_per_edge = r_scale · ē` texels of level 0 stands for a square
    /// of that side, so it is matched and coloured from level
    /// `log2(r_scale · ē)`, taken as its integer part: the deepest level
    /// whose texels (`2ˡ` level-0 texels wide) still fit in the square.
    /// Clamped to the levels there are; level 0 when a texel spans several
    /// vertices. (Rounding to the nearest level instead blurs coarse mesh
    /// levels so much that thin structures, such as mortar lines, never
    /// reach the coarse pattern.)
    pub fn level_for(&self, texels_per_edge: f32) -> usize {
        if texels_per_edge.is_nan() || texels_per_edge <= 1.0 {
            return 0;
        }
        let l = texels_per_edge.log2().floor();
        if l.is_finite() {
            (l as usize).min(self.levels() - 1)
        } else {
            self.levels() - 1
        }
    }

    /// Reduces an integer texel offset on level `l` to the range the padded
    /// planes cover, without changing the texel it addresses from any
    /// candidate: modulo the size for `Repeat`, clamped to `±(size − 1)`
    /// for `Clamp`.
    pub fn reduce_offset(&self, l: usize, offset: [i32; 2]) -> [i32; 2] {
        let p = &self.planes[l];
        let (w, h) = (p.width as i32, p.height as i32);
        match self.wrap {
            Wrap::Repeat => [offset[0].rem_euclid(w), offset[1].rem_euclid(h)],
            Wrap::Clamp => [
                offset[0].clamp(-(w - 1), w - 1),
                offset[1].clamp(-(h - 1), h - 1),
            ],
        }
    }
}
