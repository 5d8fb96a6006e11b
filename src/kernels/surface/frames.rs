//! Tangent frames (s, t, n) per vertex: the local texture axes on the surface.
//!
//! `s` is the texture's "right" direction, `t` its "up" direction, `n` the
//! surface normal; `(s, t, n)` is right-handed and orthonormal (`s × t = n`),
//! so a texture laid out along (s, t) reads unmirrored seen from outside.
//! A texture scale is kept apart (per-vertex scale arrays), so frames stay
//! unit length.
//!
//! Convention shared by every kernel: image pixel coordinates have x to the
//! right and y DOWN the rows, so a world displacement `d` moves
//! `(d·s, −d·t) × scale` pixels ([`TangentFrame::texel_offset`]).

use glam::Vec3;

/// An orthonormal, right-handed tangent frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TangentFrame {
    /// Texture x axis on the surface.
    pub s: Vec3,
    /// Texture y axis on the surface (`n × s`).
    pub t: Vec3,
    /// Unit surface normal.
    pub n: Vec3,
}

/// Vertex `v`'s exemplar coordinate (`sources`, pixels) continued through
/// its frame to the surface point `p`, at `texels_per_unit` (one value for
/// every vertex, or one per vertex): how a per-vertex result is read at the
/// exemplar's resolution (the coordinate bake, the previews and the plane
/// image drawn from sources all use it).
#[inline]
pub fn continued_source(
    sources: &[glam::Vec2],
    frames: &[TangentFrame],
    texels_per_unit: &[f32],
    positions: &[Vec3],
    v: usize,
    p: Vec3,
) -> glam::Vec2 {
    let scale = match texels_per_unit {
        [one] => *one,
        all => all[v],
    };
    sources[v] + frames[v].texel_offset(p - positions[v], scale)
}

impl TangentFrame {
    /// The frame whose `s` is `dir` projected onto the plane of `n`. When `dir`
    /// is (nearly) parallel to `n`, any perpendicular direction is used.
    #[inline]
    pub fn from_direction(n: Vec3, dir: Vec3) -> Self {
        let n = n.try_normalize().unwrap_or(Vec3::Z);
        let projected = dir - n * n.dot(dir);
        let s = projected
            .try_normalize()
            .filter(|_| projected.length_squared() > 1e-12)
            .unwrap_or_else(|| n.any_orthonormal_vector());
        let t = n.cross(s);
        Self { s, t, n }
    }

    /// The frame whose "up" axis `t` is `up` projected onto the plane of `n`
    /// (the orientation vector of Zelinka & Garland §6.1, Praun et al.'s
    /// "global up"). When `up` is (nearly) parallel to `n`, any perpendicular
    /// direction is used.
    #[inline]
    pub fn from_up(n: Vec3, up: Vec3) -> Self {
        let n = n.try_normalize().unwrap_or(Vec3::Z);
        let projected = up - n * n.dot(up);
        let t = projected
            .try_normalize()
            .filter(|_| projected.length_squared() > 1e-12)
            .unwrap_or_else(|| n.any_orthonormal_vector());
        let s = t.cross(n);
        Self { s, t, n }
    }

    /// Pixel offset (x right, y down) of the world displacement `d` at
    /// `scale` pixels per world unit.
    #[inline]
    pub fn texel_offset(&self, d: Vec3, scale: f32) -> glam::Vec2 {
        glam::Vec2::new(d.dot(self.s), -d.dot(self.t)) * scale
    }

    /// The frame rotated by `angle` radians about `n`.
    #[inline]
    pub fn rotated(&self, angle: f32) -> Self {
        let (sin, cos) = angle.sin_cos();
        let s = self.s * cos + self.t * sin;
        Self {
            s,
            t: self.n.cross(s),
            n: self.n,
        }
    }

    /// Angle of tangent vector `v` in this frame, radians from `s` toward `t`.
    #[inline]
    pub fn angle_of(&self, v: Vec3) -> f32 {
        v.dot(self.t).atan2(v.dot(self.s))
    }

    /// Tangent-plane coordinates of the offset `d`.
    #[inline]
    pub fn project(&self, d: Vec3) -> glam::Vec2 {
        glam::Vec2::new(d.dot(self.s), d.dot(self.t))
    }
}

/// Frames whose "up" axis `t` follows a global direction projected onto each
/// tangent plane (the "user field" of Wei & Levoy §3.1, Praun et al. §3.2,
/// Zelinka & Garland §6.1).
pub fn frames_from_global_direction(normals: &[Vec3], up: Vec3) -> Vec<TangentFrame> {
    normals
        .iter()
        .map(|&n| TangentFrame::from_up(n, up))
        .collect()
}

/// Frames with a uniformly random direction per vertex (isotropic textures,
/// Wei & Levoy §3.1). `angle_of(v)` supplies each vertex's angle in radians, so
/// the caller controls the random stream and results do not depend on threads.
pub fn frames_with_angles(normals: &[Vec3], angle_of: impl Fn(usize) -> f32) -> Vec<TangentFrame> {
    normals
        .iter()
        .enumerate()
        .map(|(i, &n)| {
            TangentFrame::from_direction(n, n.any_orthonormal_vector()).rotated(angle_of(i))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal_right_handed() {
        let f = TangentFrame::from_direction(Vec3::new(0.3, 0.2, 0.9), Vec3::X).rotated(0.7);
        assert!((f.s.length() - 1.0).abs() < 1e-5);
        assert!(f.s.dot(f.n).abs() < 1e-5 && f.t.dot(f.n).abs() < 1e-5);
        assert!((f.s.cross(f.t) - f.n).length() < 1e-5);
        let up = TangentFrame::from_up(Vec3::Z, Vec3::Y);
        assert!((up.s - Vec3::X).length() < 1e-6 && (up.t - Vec3::Y).length() < 1e-6);
        // Moving up the surface moves up the image (y decreases).
        assert!(up.texel_offset(Vec3::Y, 2.0).y < 0.0 && up.texel_offset(Vec3::X, 2.0).x > 0.0);
        let parallel = TangentFrame::from_direction(Vec3::Z, Vec3::Z);
        assert!(parallel.s.dot(Vec3::Z).abs() < 1e-6);
    }
}
