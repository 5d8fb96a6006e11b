//! The tangential vector field `T` on faces (Praun et al. 2000 §3.2): its
//! direction is the texture's "up", its length the local texture scale
//! (world units per patch unit, see the [module conventions](super)); the
//! "right" direction is `S = T × N`.
//!
//! - [`global_up_field`]: a global up direction projected onto each face.
//! - [`rbf_field`]: a few constraints (a face, a direction, a scale factor,
//!   a radius and a weight each) interpolated with Gaussian radial basis
//!   functions of the distance over the mesh (Dijkstra), blended with a
//!   background field; the interpolant reproduces every constraint exactly
//!   at its face.
//! - [`field_from_vertex_frames`]: the `t` axes of per-vertex frames
//!   (the `orientation` stage) averaged onto faces.
//!
//! For isotropic textures only the length matters: the orientation is
//! propagated during patch growth ([`super::grow`]).

use super::{LappedError, NO_FACE, TriMesh};
use crate::kernels::surface::frames::TangentFrame;
use crate::kernels::surface::geodesic::dijkstra;
use crate::mesh::Topology;
use glam::Vec3;

/// The unit up direction of face `f` for the world direction `up`
/// (projected; any tangent where `up` is parallel to the normal).
#[inline]
fn projected_up(mesh: &TriMesh, f: usize, up: Vec3) -> Vec3 {
    TangentFrame::from_up(mesh.normal(f), up).t
}

/// `up` projected onto every face plane, normalised and scaled by `scale`
/// (world units per patch unit). Where `up` is parallel to the normal (the
/// field's singular points) an arbitrary tangent is used.
pub fn global_up_field(mesh: &TriMesh, up: Vec3, scale: f32) -> Vec<Vec3> {
    (0..mesh.face_count())
        .map(|f| projected_up(mesh, f, up) * scale)
        .collect()
}

/// Per face, the mean of the `t` axes of its corners' frames, projected
/// onto the face and scaled by `scale`; `fallback_up` where they cancel.
///
/// # Panics
/// When `frames` has fewer entries than the mesh has vertices.
pub fn field_from_vertex_frames(
    mesh: &TriMesh,
    frames: &[TangentFrame],
    scale: f32,
    fallback_up: Vec3,
) -> Vec<Vec3> {
    (0..mesh.face_count())
        .map(|f| {
            let n = mesh.normal(f);
            let sum: Vec3 = mesh.tris[f].iter().map(|&v| frames[v as usize].t).sum();
            let t = sum - n * n.dot(sum);
            match t.try_normalize() {
                Some(t) if t.length_squared() > 0.5 => t * scale,
                _ => projected_up(mesh, f, fallback_up) * scale,
            }
        })
        .collect()
}

/// One user constraint of the field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldConstraint {
    /// The face it is attached to.
    pub face: u32,
    /// The texture up direction there (world space; projected onto the face).
    pub direction: Vec3,
    /// Multiplier of the base texture scale there (> 0).
    pub scale: f32,
    /// Radius of the Gaussian `exp(−(d / radius)²)`, world units (> 0).
    pub radius: f32,
    /// Weight of the basis function relative to the others and to the
    /// background (> 0).
    pub weight: f32,
}

/// The face whose centroid is nearest to `p` (lowest index on ties).
pub fn nearest_face(mesh: &TriMesh, p: Vec3) -> u32 {
    let mut best = (f32::INFINITY, 0u32);
    for f in 0..mesh.face_count() {
        let d = mesh.centroid(f).distance_squared(p);
        if d < best.0 {
            best = (d, f as u32);
        }
    }
    best.1
}

/// Solves the dense system `a x = b` for `m` right-hand sides by Gaussian
/// elimination with partial pivoting: `a` is row-major `n × n`, `b[i * m +
/// k]` is row `i` of right-hand side `k`, and so is the result. `None` when
/// `a` is (numerically) singular.
fn solve_dense(mut a: Vec<f64>, mut b: Vec<f64>, n: usize, m: usize) -> Option<Vec<f64>> {
    let norm = a.iter().fold(0.0f64, |x, v| x.max(v.abs())).max(1e-300);
    for col in 0..n {
        let pivot =
            (col..n).max_by(|&i, &j| a[i * n + col].abs().total_cmp(&a[j * n + col].abs()))?;
        if a[pivot * n + col].abs() <= 1e-10 * norm {
            return None;
        }
        if pivot != col {
            for k in 0..n {
                a.swap(col * n + k, pivot * n + k);
            }
            for k in 0..m {
                b.swap(col * m + k, pivot * m + k);
            }
        }
        for row in col + 1..n {
            let factor = a[row * n + col] / a[col * n + col];
            if factor == 0.0 {
                continue;
            }
            for k in col..n {
                a[row * n + k] -= factor * a[col * n + k];
            }
            for k in 0..m {
                b[row * m + k] -= factor * b[col * m + k];
            }
        }
    }
    let mut x = vec![0.0f64; n * m];
    for row in (0..n).rev() {
        for k in 0..m {
            let mut s = b[row * m + k];
            for j in row + 1..n {
                s -= a[row * n + j] * x[j * m + k];
            }
            x[row * m + k] = s / a[row * n + row];
        }
    }
    Some(x)
}

/// What [`rbf_field`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RbfReport {
    /// Whether the interpolation system was solved (constraints reproduced
    /// exactly); `false` means two constraints coincide and the plain
    /// normalised blend was used instead.
    pub exact: bool,
}

/// Gaussian RBF interpolation of `constraints` over the mesh (§3.2).
///
/// Distances are edge-path distances (Dijkstra, [`dijkstra`]) from the
/// constraint face's corners; a face's distance is the mean over its
/// corners, so the constraint face itself is at distance 0. With
/// `g_j = weight_j · exp(−(d_j / radius_j)²)` and the background
/// `background[f]` (unit vectors) of weight `background_weight`, the
/// direction at face `f` is
/// `(Σ_j g_j(f) a_j + w_b · background[f]) / (Σ_j g_j(f) + w_b)`, projected
/// onto the face and normalised; the coefficients `a_j` are solved so that
/// the direction at each constraint face equals that constraint's
/// (projected) direction. The log scale is interpolated the same way (the
/// background's is 0), and `T = direction · base_scale · exp(log scale)`.
///
/// # Errors
/// [`LappedError::ConstraintFace`] for a constraint on a face the mesh does
/// not have.
pub fn rbf_field(
    mesh: &TriMesh,
    topo: &Topology,
    constraints: &[FieldConstraint],
    background: &[Vec3],
    background_weight: f32,
    base_scale: f32,
) -> Result<(Vec<Vec3>, RbfReport), LappedError> {
    let fc = mesh.face_count();
    let n = constraints.len();
    for (index, c) in constraints.iter().enumerate() {
        if c.face as usize >= fc {
            return Err(LappedError::ConstraintFace {
                index,
                face: c.face,
                face_count: fc,
            });
        }
    }
    // g[j * fc + f]: the weighted basis function j at face f.
    let mut g = vec![0.0f32; n * fc];
    for (j, c) in constraints.iter().enumerate() {
        let radius = c.radius.max(1e-12);
        let d = dijkstra(
            &mesh.positions,
            topo,
            &mesh.tris[c.face as usize],
            4.0 * radius,
        );
        for f in 0..fc {
            let t = mesh.tris[f];
            let df = (d[t[0] as usize] + d[t[1] as usize] + d[t[2] as usize]) / 3.0;
            if df.is_finite() {
                let r = df / radius;
                g[j * fc + f] = c.weight * (-r * r).exp();
            }
        }
    }
    let wb = background_weight.max(0.0) as f64;
    // Values at the constraints: the projected unit direction and log scale.
    let values: Vec<[f64; 4]> = constraints
        .iter()
        .map(|c| {
            let f = c.face as usize;
            let nrm = mesh.normal(f);
            let projected = c.direction - nrm * nrm.dot(c.direction);
            let dir = projected
                .try_normalize()
                .unwrap_or_else(|| background[f].normalize_or_zero());
            [
                dir.x as f64,
                dir.y as f64,
                dir.z as f64,
                (c.scale.max(1e-12) as f64).ln(),
            ]
        })
        .collect();
    let log_lo = values.iter().map(|v| v[3]).fold(0.0f64, f64::min);
    let log_hi = values.iter().map(|v| v[3]).fold(0.0f64, f64::max);
    // Rows: constraint faces i; columns: basis j.
    let mut a = vec![0.0f64; n * n];
    let mut b = vec![0.0f64; n * 4];
    for (i, ci) in constraints.iter().enumerate() {
        let fi = ci.face as usize;
        let mut total = wb;
        for j in 0..n {
            let v = g[j * fc + fi] as f64;
            a[i * n + j] = v;
            total += v;
        }
        let bg = background[fi];
        let bg = [bg.x as f64, bg.y as f64, bg.z as f64, 0.0];
        for k in 0..4 {
            b[i * 4 + k] = values[i][k] * total - wb * bg[k];
        }
    }
    let (coef, exact) = match solve_dense(a, b, n, 4) {
        Some(x) => (x, true),
        None => (values.iter().flatten().copied().collect(), false),
    };
    let field = (0..fc)
        .map(|f| {
            let bg = background[f];
            let mut sum = [bg.x as f64 * wb, bg.y as f64 * wb, bg.z as f64 * wb, 0.0];
            let mut total = wb;
            for j in 0..n {
                let w = g[j * fc + f] as f64;
                if w != 0.0 {
                    total += w;
                    for k in 0..4 {
                        sum[k] += w * coef[j * 4 + k];
                    }
                }
            }
            if total <= 0.0 {
                return bg.normalize_or_zero() * base_scale;
            }
            let dir = Vec3::new(
                (sum[0] / total) as f32,
                (sum[1] / total) as f32,
                (sum[2] / total) as f32,
            );
            let nrm = mesh.normal(f);
            let dir = (dir - nrm * nrm.dot(dir))
                .try_normalize()
                .unwrap_or_else(|| bg.normalize_or_zero());
            // Clamp the log scale to the range of the values it blends, so
            // that nearby constraints with conflicting scales (a steep
            // interpolant) cannot overshoot to absurd scales.
            let log_scale = (sum[3] / total).clamp(log_lo, log_hi);
            let scale = base_scale * (log_scale as f32).exp();
            dir * scale
        })
        .collect();
    Ok((field, RbfReport { exact }))
}

/// Per face, the largest angle (radians, `[0, π]`) between its field
/// direction and a neighbour's carried across their shared edge: where the
/// field is discontinuous, parametrisations are hard (§3.3 seeds there
/// first).
pub fn field_discontinuity(mesh: &TriMesh, t: impl Fn(usize) -> Vec3) -> Vec<f32> {
    (0..mesh.face_count())
        .map(|f| {
            let own = t(f).normalize_or_zero();
            mesh.neighbours[f]
                .iter()
                .filter(|&&g| g != NO_FACE)
                .map(|&g| {
                    let other = mesh
                        .transport(t(g as usize), g as usize, f)
                        .normalize_or_zero();
                    own.dot(other).clamp(-1.0, 1.0).acos()
                })
                .fold(0.0f32, f32::max)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::lapped::test_meshes::{grid, sphere};

    #[test]
    fn global_up_is_projected_and_scaled() {
        let m = TriMesh::new(&grid(4, 1.0)).unwrap();
        let t = global_up_field(&m, Vec3::new(0.0, 1.0, 1.0), 2.0);
        for v in &t {
            assert!((*v - Vec3::new(0.0, 2.0, 0.0)).length() < 1e-5, "{v:?}");
        }
    }

    #[test]
    fn rbf_reproduces_each_constraint_at_its_face() {
        let mesh = sphere(3);
        let m = TriMesh::new(&mesh).unwrap();
        let topo = Topology::build(&mesh);
        let background = global_up_field(&m, Vec3::Y, 1.0);
        let constraints = [
            FieldConstraint {
                face: 10,
                direction: Vec3::new(1.0, 0.2, 0.3),
                scale: 2.0,
                radius: 0.8,
                weight: 1.0,
            },
            FieldConstraint {
                face: 300,
                direction: Vec3::new(-0.3, 0.1, 1.0),
                scale: 0.5,
                radius: 0.8,
                weight: 3.0,
            },
            FieldConstraint {
                face: 301,
                direction: Vec3::new(0.0, 0.0, 1.0),
                scale: 1.0,
                radius: 0.3,
                weight: 0.5,
            },
        ];
        let (field, report) = rbf_field(&m, &topo, &constraints, &background, 0.05, 1.5).unwrap();
        assert!(report.exact);
        for c in &constraints {
            let f = c.face as usize;
            let nrm = m.normal(f);
            let expected = (c.direction - nrm * nrm.dot(c.direction)).normalize() * 1.5 * c.scale;
            let got = field[f];
            assert!(
                (got - expected).length() < 1e-3 * expected.length(),
                "face {f}: {got:?} vs {expected:?}"
            );
        }
        // Every vector lies in its face plane and is non-zero.
        for (f, t) in field.iter().enumerate() {
            assert!(t.dot(m.normal(f)).abs() < 1e-4 && t.length() > 0.1);
        }
        // Far away from all constraints, the background takes over.
        let far = (0..m.face_count())
            .max_by(|&a, &b| {
                let da = m
                    .centroid(a)
                    .distance(m.centroid(10))
                    .min(m.centroid(a).distance(m.centroid(300)));
                let db = m
                    .centroid(b)
                    .distance(m.centroid(10))
                    .min(m.centroid(b).distance(m.centroid(300)));
                da.total_cmp(&db)
            })
            .unwrap();
        assert!(field[far].normalize().dot(background[far]) > 0.9);
        // A bad face is an error naming it.
        let bad = [FieldConstraint {
            face: 999_999,
            ..constraints[0]
        }];
        assert!(matches!(
            rbf_field(&m, &topo, &bad, &background, 0.05, 1.0),
            Err(LappedError::ConstraintFace { face: 999_999, .. })
        ));
    }

    #[test]
    fn discontinuity_is_zero_for_a_constant_flat_field() {
        let m = TriMesh::new(&grid(5, 1.0)).unwrap();
        let t = global_up_field(&m, Vec3::Y, 1.0);
        assert!(field_discontinuity(&m, |f| t[f]).iter().all(|&a| a < 1e-3));
    }
}
