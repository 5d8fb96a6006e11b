//! A perspective camera placed on a sphere of view directions and pulled back
//! until the mesh fills a given fraction of the frame.

use super::View;
use glam::Vec3;

/// A pinhole camera looking along `forward`, with image rows growing downward.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Camera {
    /// The centre of projection.
    pub eye: Vec3,
    /// Unit vector that points to the right of the image.
    pub right: Vec3,
    /// Unit vector that points to the top of the image.
    pub up: Vec3,
    /// Unit viewing direction (into the screen).
    pub forward: Vec3,
    /// Focal length in pixels.
    pub focal: f32,
    /// Image centre in pixels.
    pub centre: (f32, f32),
}

/// The camera basis for `view`: azimuth 0, elevation 0 looks down −Z from the
/// +Z side; positive azimuth moves the camera toward +X, positive elevation
/// lifts it toward +Y. Returns `(right, up, forward)`.
///
/// `right` is taken from the azimuth alone so the basis stays well defined
/// when looking straight down or up.
pub(crate) fn basis(view: &View) -> (Vec3, Vec3, Vec3) {
    let (sa, ca) = view.azimuth_deg.to_radians().sin_cos();
    let (se, ce) = view.elevation_deg.to_radians().sin_cos();
    let forward = -Vec3::new(ce * sa, se, ce * ca);
    let right = Vec3::new(ca, 0.0, -sa);
    let up = right.cross(forward).normalize();
    (right, up, forward)
}

impl Camera {
    /// Fits a camera for `view` to `points` (non-finite points are ignored) so
    /// that their projection is roughly centred and its larger half-extent is
    /// `fill` of the frame's half-size, in a `width`×`height` pixel image with
    /// vertical field of view `fov_y_deg`.
    ///
    /// The distance is exact for the projected extent (not a bounding-sphere
    /// bound), so a flat or elongated mesh still fills the frame. Every point
    /// stays in front of the camera by at least 1% of the mesh radius.
    pub fn fit(
        points: &[Vec3],
        view: &View,
        fov_y_deg: f32,
        fill: f32,
        width: u32,
        height: u32,
    ) -> Self {
        let (right, up, forward) = basis(view);
        let fov = fov_y_deg.clamp(1.0, 170.0).to_radians();
        let tan_half = (0.5 * fov).tan();
        let focal = 0.5 * height as f32 / tan_half;
        let aspect = width as f32 / height.max(1) as f32;
        let centre = (0.5 * width as f32, 0.5 * height as f32);
        // Tangent of the half-angle that the mesh may fill, vertically and horizontally.
        let k_y = fill.clamp(0.05, 1.0) * tan_half;
        let k_x = k_y * aspect;

        let finite = || points.iter().copied().filter(|p| p.is_finite());
        let Some((lo, hi)) = finite().fold(None, |acc: Option<(Vec3, Vec3)>, p| {
            Some(acc.map_or((p, p), |(lo, hi)| (lo.min(p), hi.max(p))))
        }) else {
            return Self {
                eye: Vec3::new(0.0, 0.0, 3.0),
                right,
                up,
                forward,
                focal,
                centre,
            };
        };
        let mut target = 0.5 * (lo + hi);
        let radius = finite()
            .map(|p| (p - target).length())
            .fold(0.0f32, f32::max);
        // A single point (or coincident points) still gets a finite camera.
        let radius = if radius > 0.0 { radius } else { 1.0 };

        // The smallest distance along -forward from `target` that keeps every
        // point within the cone: |a| / (d + c) <= k  <=>  d >= |a| / k - c.
        let distance = |target: Vec3| {
            finite().fold(0.01 * radius, |d: f32, p| {
                let q = p - target;
                let (a, b, c) = (q.dot(right), q.dot(up), q.dot(forward));
                d.max((a.abs() / k_x).max(b.abs() / k_y) - c)
                    .max(0.01 * radius - c)
            })
        };
        let mut d = distance(target);
        // Two centring passes: shift the target so the projected extent is
        // symmetric about the image centre, then refit the distance.
        for _ in 0..2 {
            let (mut a_lo, mut a_hi, mut b_lo, mut b_hi) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
            for p in finite() {
                let q = p - target;
                let z = d + q.dot(forward);
                let (a, b) = (q.dot(right) / z, q.dot(up) / z);
                a_lo = a_lo.min(a);
                a_hi = a_hi.max(a);
                b_lo = b_lo.min(b);
                b_hi = b_hi.max(b);
            }
            target += right * (0.5 * (a_lo + a_hi) * d) + up * (0.5 * (b_lo + b_hi) * d);
            d = distance(target);
        }
        Self {
            eye: target - forward * d,
            right,
            up,
            forward,
            focal,
            centre,
        }
    }

    /// Projects `p` to pixel coordinates (x right, y down, pixel centres at
    /// integer + 0.5) and returns `(x, y, 1 / depth)`; `None` behind the
    /// camera or for a non-finite point.
    #[inline]
    pub fn project(&self, p: Vec3) -> Option<(f32, f32, f32)> {
        let q = p - self.eye;
        let z = q.dot(self.forward);
        if !p.is_finite() || z.is_nan() || z <= 1e-12 {
            return None;
        }
        let inv = 1.0 / z;
        let x = self.centre.0 + self.focal * q.dot(self.right) * inv;
        let y = self.centre.1 - self.focal * q.dot(self.up) * inv;
        Some((x, y, inv))
    }

    /// A unit key-light direction (pointing from the surface toward the
    /// light): from the camera, raised and moved to the left, so the
    /// silhouette keeps some shading and the front is lit.
    pub fn key_light(&self) -> Vec3 {
        (-self.forward + 0.35 * self.up - 0.25 * self.right).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn front_view_is_not_mirrored() {
        let cam = Camera::fit(
            &[Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, 1.0, 0.0)],
            &View {
                azimuth_deg: 0.0,
                elevation_deg: 0.0,
            },
            35.0,
            0.85,
            100,
            100,
        );
        let (xr, yr, _) = cam.project(Vec3::new(1.0, 0.0, 0.0)).unwrap();
        let (xt, yt, _) = cam.project(Vec3::new(0.0, 1.0, 0.0)).unwrap();
        assert!(
            xr > 50.0 && (yr - 50.0).abs() < 1e-3,
            "+X shows on the right"
        );
        assert!(yt < 50.0 && (xt - 50.0).abs() < 1e-3, "+Y shows at the top");
        assert!((xr - 50.0 - 0.85 * 50.0).abs() < 0.5, "fills 85%: {xr}");
    }

    #[test]
    fn straight_down_has_a_basis() {
        let (r, u, f) = basis(&View {
            azimuth_deg: 0.0,
            elevation_deg: 90.0,
        });
        assert!(r.is_finite() && u.is_finite() && f.is_finite());
        assert!(f.dot(Vec3::NEG_Y) > 0.999);
        assert!(
            u.dot(Vec3::NEG_Z) > 0.999,
            "top of the image is -Z (away from the front)"
        );
    }
}
