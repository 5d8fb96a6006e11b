//! Carrying per-vertex attributes down a √2 hierarchy through its
//! [`Parents`]: old vertices keep their values bit for bit (the scheme
//! keeps vertices, Bangay & Morkel §3.2.1 first bullet), face points get
//! their parents' weighted sum.

use super::Parents;
use crate::kernels::surface::frames::TangentFrame;
use glam::Vec3;
use std::ops::{Add, Mul};

/// Carries a per-vertex attribute to a refined level: identity parents copy
/// the value exactly, others take the weighted sum of their parents.
pub fn carry_attribute<T>(parents: &Parents, old: &[T]) -> Vec<T>
where
    T: Copy + Add<Output = T> + Mul<f32, Output = T>,
{
    (0..parents.len())
        .map(|v| {
            let (pv, pw) = parents.of(v);
            match (pv, pw) {
                // Identity entries copy the value: bit-exact, no `* 1.0`.
                ([s], [w]) if *w == 1.0 => old[*s as usize],
                _ => {
                    let mut acc = old[pv[0] as usize] * pw[0];
                    for (&s, &w) in pv.iter().zip(pw).skip(1) {
                        acc = acc + old[s as usize] * w;
                    }
                    acc
                }
            }
        })
        .collect()
}

/// [`carry_attribute`] for rows of `channels` values (colours).
pub fn carry_rows(parents: &Parents, old: &[f32], channels: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; parents.len() * channels];
    for (v, row) in out.chunks_exact_mut(channels.max(1)).enumerate() {
        let (pv, pw) = parents.of(v);
        match (pv, pw) {
            ([s], [w]) if *w == 1.0 => {
                let s = *s as usize;
                row.copy_from_slice(&old[s * channels..(s + 1) * channels]);
            }
            _ => {
                for (&s, &w) in pv.iter().zip(pw) {
                    let s = s as usize;
                    for (o, &x) in row.iter_mut().zip(&old[s * channels..(s + 1) * channels]) {
                        *o += x * w;
                    }
                }
            }
        }
    }
    out
}

/// Carries frames: old vertices keep theirs exactly; a new vertex takes its
/// parents' mean up direction on its own normal.
pub fn carry_frames(
    parents: &Parents,
    old: &[TangentFrame],
    normals: &[Vec3],
) -> Vec<TangentFrame> {
    let ups: Vec<Vec3> = old.iter().map(|f| f.t).collect();
    let carried = carry_attribute(parents, &ups);
    (0..parents.len())
        .map(|v| match parents.of(v) {
            ([s], [w]) if *w == 1.0 => old[*s as usize],
            _ => TangentFrame::from_up(normals[v], carried[v]),
        })
        .collect()
}
