//! Random initial colours (Wei & Levoy 2001 §3.1, Table 2): every vertex
//! takes the colour of a random exemplar texel and remembers which texel.

use crate::image::Image;
use crate::kernels::mix;
use glam::Vec2;
use rayon::prelude::*;

/// Random texels of `exemplar` for `count` vertices: the colours
/// (`exemplar.channels` per vertex) and the texel centres they came from,
/// in the exemplar's pixels. Vertex `v` draws from its own stream
/// `mix(seed, v, 1)`, so the result does not depend on thread count.
pub fn random_texels(exemplar: &Image, count: usize, seed: u64) -> (Vec<f32>, Vec<Vec2>) {
    let c = exemplar.channels as usize;
    let (w, h) = (exemplar.width as u64, exemplar.height as u64);
    let mut values = vec![0.0f32; count * c];
    let mut texels = vec![Vec2::ZERO; count];
    values
        .par_chunks_mut(c)
        .zip(texels.par_iter_mut())
        .enumerate()
        .for_each(|(v, (out, texel))| {
            let r = mix(seed, v as u64, 1);
            let x = ((r >> 32) * w) >> 32;
            let y = ((r & 0xFFFF_FFFF) * h) >> 32;
            out.copy_from_slice(exemplar.pixel(x as u32, y as u32));
            *texel = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
        });
    (values, texels)
}

/// Texel centres of level `level` of a Gaussian pyramid (each level half
/// the size of the one below) turned into pixels of level 0.
pub fn texels_to_level_zero(texels: &mut [Vec2], level: usize) {
    let scale = 2f32.powi(level as i32);
    for t in texels {
        *t = (*t - Vec2::splat(0.5)) * scale + Vec2::splat(0.5);
    }
}
