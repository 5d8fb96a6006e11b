//! Face coverage (Praun et al. 2000 §3.6) and the culling of occluded faces
//! for runtime pasting (§4).
//!
//! After each paste, every face of the new surface patch is rasterised in
//! texture space: each face carries a fixed set of samples at the texture
//! patch's pixel density (the centroids of a `k × k` subdivision of the
//! face, `k² ≈` the face's area in texture pixels, see [`sample_levels`]).
//! Each sample is mapped through every paste that holds the face
//! (barycentric coordinates carry it from one paste's texture space to
//! another's) and the alphas are accumulated, `1 − Π (1 − α)`. A sample is
//! covered when the accumulated alpha is opaque; a face is covered when the
//! fraction of covered samples reaches [`CoverageSettings::threshold`]. For
//! an uncovered face the least covered sample is remembered, to centre a
//! later paste there.
//!
//! Two departures from the paper's colour-coded face ids in an off-screen
//! buffer: samples are generated per face, which handles patches that
//! overlap themselves in texture space without extra passes; and they do
//! not depend on which paste is being tested, so coverage only ever grows
//! (with the pixel grid of the newest paste, a face found covered could
//! later be probed at a point that was missed before).

use super::mask::TexturePatch;
use glam::{Vec2, Vec3};
use rayon::prelude::*;

/// Settings of the coverage test.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoverageSettings {
    /// Fraction of a face's samples that must be covered, `(0, 1]`. Default 1.
    pub threshold: f32,
    /// Accumulated alpha from which a sample counts as covered. Default
    /// `1 − 0.5 / 255` (opaque in 8 bits).
    pub opaque: f32,
    /// Largest subdivision level `k` of a face (`k²` samples). Default 64.
    pub max_level: u16,
    /// Keep every layer in the lists, also those that can no longer be
    /// seen ([`Coverage::add_paste`]); for tests of that claim. Default
    /// false.
    pub keep_hidden: bool,
}

impl Default for CoverageSettings {
    fn default() -> Self {
        Self {
            threshold: 1.0,
            opaque: 1.0 - 0.5 / 255.0,
            max_level: 64,
            keep_hidden: false,
        }
    }
}

/// Per face, the subdivision level `k` of its coverage samples: `k²`
/// about the face's area in texture pixels, where a face of world area `A`
/// under the field `T` covers `A / ‖T‖² · unit_px²` pixels (`unit_px`:
/// pixels per patch unit of the finest texture patch). At least 1, at most
/// `max_level`.
pub fn sample_levels(
    area_and_field: impl Iterator<Item = (f32, Vec3)>,
    unit_px: f32,
    max_level: u16,
) -> Vec<u16> {
    area_and_field
        .map(|(a, t)| {
            let scale2 = t.length_squared().max(f32::MIN_POSITIVE);
            let px = (a / scale2) * unit_px * unit_px;
            (px.max(0.0).sqrt().ceil() as u16).clamp(1, max_level.max(1))
        })
        .collect()
}

/// The lattice level of a face of `area` sampled at about `per_area`
/// points per unit area: `k²` points, `k` in `1..=8`.
pub fn lattice_level(area: f32, per_area: f32) -> u16 {
    ((area * per_area).max(0.0).sqrt().round() as u16).clamp(1, 8)
}

/// The `k²` sample points of a face at level `k`: barycentric coordinates
/// of the centroids of the sub-triangles of its `k`-fold subdivision.
pub fn lattice_samples(k: u16) -> Vec<[f32; 3]> {
    let mut out = Vec::new();
    lattice_samples_into(k, &mut out);
    out
}

/// [`lattice_samples`] into `out` (cleared first), for loops that reuse
/// one buffer.
pub fn lattice_samples_into(k: u16, out: &mut Vec<[f32; 3]>) {
    out.clear();
    let k = k.max(1) as usize;
    let inv = 1.0 / k as f32;
    out.reserve(k * k);
    for j in 0..k {
        for i in 0..k - j {
            out.push(lattice_point(i, j, false, inv));
            if i + j + 2 <= k {
                out.push(lattice_point(i, j, true, inv));
            }
        }
    }
}

/// Sample `index` of [`lattice_samples`]`(k)`, the same bits.
pub fn lattice_sample(k: u16, index: u32) -> [f32; 3] {
    let k = k.max(1) as usize;
    let inv = 1.0 / k as f32;
    let mut rest = index as usize;
    for j in 0..k {
        // Row `j`: `k − j` lower sub-triangles, `k − j − 1` upper ones,
        // interleaved lower, upper, lower, …
        let row = 2 * (k - j) - 1;
        if rest < row {
            return lattice_point(rest / 2, j, rest % 2 == 1, inv);
        }
        rest -= row;
    }
    lattice_point(0, k - 1, false, inv)
}

/// Centroid of the lower (or `upper`) sub-triangle `(i, j)` of the
/// subdivision with cell size `inv`.
#[inline]
fn lattice_point(i: usize, j: usize, upper: bool, inv: f32) -> [f32; 3] {
    let third = if upper { 2.0 / 3.0 } else { 1.0 / 3.0 };
    let (u, v) = ((i as f32 + third) * inv, (j as f32 + third) * inv);
    [1.0 - u - v, u, v]
}

/// One paste holding a face.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaceLayer {
    /// The paste, in paste order.
    pub paste: u32,
    /// Its texture patch.
    pub texture: u32,
    /// Position of the face in the paste's face list.
    pub slot: u32,
    /// Texture coordinates of the face's corners in that paste.
    pub uv: [Vec2; 3],
}

/// "No layer" in the layer lists.
const NIL: u32 = u32::MAX;

/// Nodes per chunk of the layer pool: 40 MB, above the largest threshold
/// from which the system allocator maps blocks of their own (32 MB for
/// glibc), so a freed pool goes back to the system instead of leaving
/// holes in the heap; pages of a chunk not yet written are not resident.
const CHUNK: usize = 1 << 20;

/// Bytes of one chunk of the layer pool (36 MiB, allocated whole; a memory
/// estimate counts it as address space).
pub const POOL_CHUNK_BYTES: u64 = (CHUNK * std::mem::size_of::<Node>()) as u64;

/// Nodes per chunk of the layer pool.
pub const POOL_CHUNK_NODES: u64 = CHUNK as u64;

/// A layer in a face's list: the layer without its texture patch (which
/// the paste gives, [`Coverage::paste_texture`]) and the next one in paste
/// order; 36 bytes.
#[derive(Clone, Copy, Debug)]
struct Node {
    paste: u32,
    slot: u32,
    uv: [Vec2; 3],
    next: u32,
}

/// Coverage state of every face.
///
/// The pastes holding each face are a singly linked list per face in one
/// pool of nodes (36 bytes a layer, 4 bytes a face; freed nodes are
/// reused), in paste order. A `Vec` per face cost 24 bytes per face plus an
/// allocation of four layers (184 bytes per face) and, with every layer
/// ever pasted kept, ~9 layers per vertex on a scan.
#[derive(Clone, Debug, Default)]
pub struct Coverage {
    /// Whether the face is covered.
    pub covered: Vec<bool>,
    /// The least covered sample of the face's last test, as its index in
    /// [`lattice_samples`] of the face's level; [`NIL`] before the first
    /// test and once covered ([`Coverage::uncovered_point`]).
    worst: Vec<u32>,
    /// Subdivision level of each face's samples ([`sample_levels`]).
    pub levels: Vec<u16>,
    /// First layer of each face, [`NIL`] for none.
    head: Vec<u32>,
    /// The layer pool, in chunks of [`CHUNK`] nodes (no reallocation that
    /// would hold the old and the new pool at once).
    nodes: Vec<Vec<Node>>,
    /// First free node of the pool, [`NIL`] for none.
    free: u32,
    /// Each paste's texture patch, by paste index (the layers do not
    /// repeat it).
    paste_texture: Vec<u32>,
    /// Every layer ever added, hidden ones included.
    added: u64,
}

#[inline]
fn at(uv: &[Vec2; 3], b: [f32; 3]) -> Vec2 {
    uv[0] * b[0] + uv[1] * b[1] + uv[2] * b[2]
}

/// Accumulated alpha `1 − Π (1 − α)` of `layers` at barycentric point `b`.
#[inline]
fn accumulated_alpha(layers: &[FaceLayer], textures: &[TexturePatch], b: [f32; 3]) -> f32 {
    let mut clear = 1.0f32;
    for l in layers {
        clear *= 1.0 - textures[l.texture as usize].alpha_at(at(&l.uv, b));
        if clear <= 0.0 {
            break;
        }
    }
    1.0 - clear
}

/// [`accumulated_alpha`] of layers whose alphas at the point are `alphas`
/// (the same operations in the same order, so the same value).
#[inline]
fn accumulated(alphas: &[f32]) -> f32 {
    let mut clear = 1.0f32;
    for &a in alphas {
        clear *= 1.0 - a;
        if clear <= 0.0 {
            break;
        }
    }
    1.0 - clear
}

/// The layers in a face's list.
pub struct FaceLayers<'a> {
    nodes: &'a [Vec<Node>],
    paste_texture: &'a [u32],
    at: u32,
}

impl Iterator for FaceLayers<'_> {
    type Item = FaceLayer;
    #[inline]
    fn next(&mut self) -> Option<FaceLayer> {
        if self.at == NIL {
            return None;
        }
        let node = node(self.nodes, self.at);
        self.at = node.next;
        Some(FaceLayer {
            paste: node.paste,
            texture: self.paste_texture[node.paste as usize],
            slot: node.slot,
            uv: node.uv,
        })
    }
}

#[inline]
fn node(nodes: &[Vec<Node>], id: u32) -> &Node {
    &nodes[id as usize / CHUNK][id as usize % CHUNK]
}

#[inline]
fn node_mut(nodes: &mut [Vec<Node>], id: u32) -> &mut Node {
    &mut nodes[id as usize / CHUNK][id as usize % CHUNK]
}

impl Coverage {
    /// Nothing covered yet; `levels` gives each face's sample level.
    pub fn new(levels: Vec<u16>) -> Self {
        let n = levels.len();
        Self {
            covered: vec![false; n],
            worst: vec![NIL; n],
            levels,
            head: vec![NIL; n],
            nodes: Vec::new(),
            free: NIL,
            paste_texture: Vec::new(),
            added: 0,
        }
    }

    /// The pastes still holding face `f`, in paste order (hidden layers are
    /// dropped, see [`Coverage::add_paste`]).
    #[inline]
    pub fn layers(&self, f: usize) -> FaceLayers<'_> {
        FaceLayers {
            nodes: &self.nodes,
            paste_texture: &self.paste_texture,
            at: self.head[f],
        }
    }

    /// Number of faces.
    #[inline]
    pub fn face_count(&self) -> usize {
        self.head.len()
    }

    /// Barycentric coordinates of the least covered sample of face `f`'s
    /// last test; `None` before the first test and once covered.
    #[inline]
    pub fn uncovered_point(&self, f: usize) -> Option<[f32; 3]> {
        let w = self.worst[f];
        (w != NIL).then(|| lattice_sample(self.levels[f], w))
    }

    /// Appends the layer of paste `paste` (at `slot` in its face list,
    /// corners at `uv`) to face `f`'s list.
    fn push(&mut self, f: usize, paste: u32, slot: u32, uv: [Vec2; 3]) {
        let new = Node {
            paste,
            slot,
            uv,
            next: NIL,
        };
        let id = if self.free == NIL {
            if self.nodes.last().is_none_or(|c| c.len() == CHUNK) {
                self.nodes.push(Vec::with_capacity(CHUNK));
            }
            let full = (self.nodes.len() - 1) * CHUNK;
            let last = self.nodes.last_mut().expect("a chunk was just made");
            last.push(new);
            (full + last.len() - 1) as u32
        } else {
            let id = self.free;
            let slot = node_mut(&mut self.nodes, id);
            self.free = slot.next;
            *slot = new;
            id
        };
        match self.head[f] {
            NIL => self.head[f] = id,
            mut at => {
                while node(&self.nodes, at).next != NIL {
                    at = node(&self.nodes, at).next;
                }
                node_mut(&mut self.nodes, at).next = id;
            }
        }
    }

    /// Unlinks the layers of face `f` whose positions in its list are
    /// flagged in `drop` (bit `k` for the `k`-th layer) and frees them.
    fn remove(&mut self, f: usize, drop: u64) {
        let (mut prev, mut at, mut k) = (NIL, self.head[f], 0u32);
        while at != NIL {
            let next = node(&self.nodes, at).next;
            if k < 64 && drop & (1 << k) != 0 {
                match prev {
                    NIL => self.head[f] = next,
                    p => node_mut(&mut self.nodes, p).next = next,
                }
                node_mut(&mut self.nodes, at).next = self.free;
                self.free = at;
            } else {
                prev = at;
            }
            at = next;
            k += 1;
        }
    }

    /// Records paste `paste` (texture patch `texture`, its `faces` with
    /// per-corner texture coordinates `uvs`) and re-tests its faces.
    ///
    /// Layers the face can no longer show are dropped from its list: a
    /// layer whose alpha is exactly 0 at every sample of the face, or
    /// where it is not, the layers above it are opaque (the test of
    /// [`drawn_faces`] with "transparent" meaning exactly 0). Dropping such
    /// a layer changes no later coverage test (at each sample either its
    /// factor `1 − α` is exactly 1, or the sample stays opaque whatever
    /// lies below, products of factors in `[0, 1]` being monotone in
    /// floating point too), and no later [`drawn_faces`] flag of the
    /// layers kept, so the paste loop is the same with or without it; it
    /// keeps the lists at the layers that can still be seen instead of
    /// every layer ever pasted (~1.5 instead of ~4.5 per face).
    pub fn add_paste(
        &mut self,
        paste: u32,
        texture: u32,
        faces: &[u32],
        uvs: &[[Vec2; 3]],
        textures: &[TexturePatch],
        settings: &CoverageSettings,
    ) {
        let _span = tracing::trace_span!("coverage", faces = faces.len()).entered();
        let p = paste as usize;
        if self.paste_texture.len() <= p {
            self.paste_texture.resize(p + 1, 0);
        }
        self.paste_texture[p] = texture;
        for (slot, (&f, uv)) in faces.iter().zip(uvs).enumerate() {
            self.push(f as usize, paste, slot as u32, *uv);
            self.added += 1;
        }
        let this = &*self;
        // Per worker: the face's layers, samples and alphas (no allocation
        // per face).
        let scratch = || (Vec::<FaceLayer>::new(), Vec::new(), Vec::new());
        let results: Vec<(f32, Option<u32>, u64)> = faces
            .par_iter()
            .map_init(scratch, |(layers, samples, alphas), &f| {
                layers.clear();
                layers.extend(this.layers(f as usize));
                let n = layers.len();
                lattice_samples_into(this.levels[f as usize], samples);
                let mut covered = 0usize;
                let mut worst: Option<(f32, u32)> = None;
                alphas.clear();
                alphas.resize(n, 0.0f32);
                // Bit k: layer k was seen (not transparent, not hidden) at
                // some sample; only the first 64 layers are candidates.
                let m = n.min(64);
                let all: u64 = if m == 64 { u64::MAX } else { (1u64 << m) - 1 };
                let mut seen = 0u64;
                for (index, b) in samples.iter().enumerate() {
                    for (a, l) in alphas.iter_mut().zip(layers.iter()) {
                        *a = textures[l.texture as usize].alpha_at(at(&l.uv, *b));
                    }
                    let a = accumulated(alphas);
                    if a >= settings.opaque {
                        covered += 1;
                    } else if worst.is_none_or(|(w, _)| a < w) {
                        worst = Some((a, index as u32));
                    }
                    for k in 0..m {
                        if seen & (1 << k) == 0
                            && alphas[k] != 0.0
                            && accumulated(&alphas[k + 1..]) < settings.opaque
                        {
                            seen |= 1 << k;
                        }
                    }
                }
                (
                    covered as f32 / samples.len() as f32,
                    worst.map(|w| w.1),
                    all & !seen,
                )
            })
            .collect();
        for (&f, (fraction, worst, hidden)) in faces.iter().zip(results) {
            let f = f as usize;
            self.covered[f] = fraction >= settings.threshold || worst.is_none();
            self.worst[f] = worst.unwrap_or(NIL);
            if hidden != 0 && !settings.keep_hidden {
                self.remove(f, hidden);
            }
        }
    }

    /// Mean number of pastes that held a face (hidden layers included).
    pub fn mean_layers(&self) -> f64 {
        self.added as f64 / self.head.len().max(1) as f64
    }

    /// Most layers held at once (the pool's size).
    pub fn pool_size(&self) -> usize {
        self.nodes.iter().map(Vec::len).sum()
    }

    /// Layers still held, over all faces.
    pub fn held_layers(&self) -> usize {
        (0..self.face_count()).map(|f| self.layers(f).count()).sum()
    }

    /// Per paste (`paste_count` of them), the faces it still holds, in
    /// face order, with their corners' texture coordinates; the layers'
    /// `slot`s are renumbered to the positions in these lists.
    ///
    /// Filled in one sweep over the faces into lists of the counted
    /// lengths: no index of all held layers beside the pool and the
    /// lists (12 bytes a layer, the loop's peak on a scan).
    pub fn paste_lists(&mut self, paste_count: usize) -> Vec<(Vec<u32>, Vec<[Vec2; 3]>)> {
        let mut count = vec![0usize; paste_count];
        for f in 0..self.face_count() {
            for l in self.layers(f) {
                count[l.paste as usize] += 1;
            }
        }
        let mut lists: Vec<(Vec<u32>, Vec<[Vec2; 3]>)> = count
            .iter()
            .map(|&n| (Vec::with_capacity(n), Vec::with_capacity(n)))
            .collect();
        drop(count);
        for f in 0..self.face_count() {
            let mut at = self.head[f];
            while at != NIL {
                let n = node_mut(&mut self.nodes, at);
                let (faces, uvs) = &mut lists[n.paste as usize];
                n.slot = faces.len() as u32;
                faces.push(f as u32);
                uvs.push(n.uv);
                at = n.next;
            }
        }
        lists
    }
}

/// For runtime pasting (§4): per paste, per face of it, whether the face
/// must be drawn. A face is dropped from a paste when, at every one of the
/// face's coverage samples, the paste is transparent or the later pastes
/// holding the face are together opaque. `paste_sizes` are the lengths of
/// the pastes' face lists the layers' `slot`s index
/// ([`Coverage::paste_lists`]).
pub fn drawn_faces(
    coverage: &Coverage,
    paste_sizes: &[usize],
    textures: &[TexturePatch],
    settings: &CoverageSettings,
) -> Vec<Vec<bool>> {
    let _span = tracing::debug_span!("cull_occluded_faces").entered();
    let mut drawn: Vec<Vec<bool>> = paste_sizes.iter().map(|&n| vec![false; n]).collect();
    // In blocks of faces: the flags of all faces at once were a
    // `Vec<Vec<bool>>` of 24 bytes per face plus an allocation each.
    const BLOCK: usize = 1 << 14;
    for lo in (0..coverage.face_count()).step_by(BLOCK) {
        let hi = (lo + BLOCK).min(coverage.face_count());
        let per_face: Vec<Vec<bool>> = (lo..hi)
            .into_par_iter()
            .map(|f| {
                let layers: Vec<FaceLayer> = coverage.layers(f).collect();
                let samples = lattice_samples(coverage.levels[f]);
                (0..layers.len())
                    .map(|k| {
                        let own = &layers[k];
                        let tex = &textures[own.texture as usize];
                        let later = &layers[k + 1..];
                        samples.iter().any(|&b| {
                            tex.alpha_at(at(&own.uv, b)) > 1.0 - settings.opaque
                                && accumulated_alpha(later, textures, b) < settings.opaque
                        })
                    })
                    .collect()
            })
            .collect();
        for (f, flags) in (lo..hi).zip(per_face) {
            for (l, d) in coverage.layers(f).zip(flags) {
                drawn[l.paste as usize][l.slot as usize] = d;
            }
        }
    }
    drawn
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lattice_sample_by_index_is_the_listed_one_bit_for_bit() {
        for k in 1u16..=20 {
            for (i, b) in lattice_samples(k).iter().enumerate() {
                let one = lattice_sample(k, i as u32);
                assert_eq!(
                    one.map(f32::to_bits),
                    b.map(f32::to_bits),
                    "k {k}, sample {i}"
                );
            }
        }
    }

    #[test]
    fn lattice_samples_fill_the_face_evenly() {
        for k in [1u16, 2, 5, 17] {
            let s = lattice_samples(k);
            assert_eq!(s.len(), k as usize * k as usize);
            for b in &s {
                assert!(b.iter().all(|&v| v > 0.0) && (b.iter().sum::<f32>() - 1.0).abs() < 1e-5);
            }
            // The mean is the centroid.
            let mean: f32 = s.iter().map(|b| b[1]).sum::<f32>() / s.len() as f32;
            assert!((mean - 1.0 / 3.0).abs() < 1e-5, "{k}: {mean}");
        }
        // A face of 100 square texture pixels gets level 10.
        let levels = sample_levels([(4.0, Vec3::new(0.0, 2.0, 0.0))].into_iter(), 10.0, 64);
        assert_eq!(levels, vec![10]);
    }
}
