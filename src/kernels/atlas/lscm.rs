//! Flattening a chart: projection onto a plane, and least-squares conformal
//! maps (Lévy, Petitjean, Ray & Maillot 2002) solved by Jacobi-preconditioned
//! conjugate gradients on the normal equations, started from the projection
//! with the two vertices farthest apart along the chart's longer axis pinned
//! where the projection puts them.

use glam::{DVec2, Vec2, Vec3};

/// Gives the chart's vertices local indices (in first-seen order) in
/// `local` (all `u32::MAX` on entry and on return); returns the mesh vertex
/// of each local index and the chart's corners as local indices.
fn local_indices(tris: &[[u32; 3]], faces: &[u32], local: &mut [u32]) -> (Vec<u32>, Vec<[u32; 3]>) {
    let mut verts = Vec::new();
    let corners = faces
        .iter()
        .map(|&f| {
            tris[f as usize].map(|v| {
                if local[v as usize] == u32::MAX {
                    local[v as usize] = verts.len() as u32;
                    verts.push(v);
                }
                local[v as usize]
            })
        })
        .collect();
    for &v in &verts {
        local[v as usize] = u32::MAX;
    }
    (verts, corners)
}

/// A corner of the chart, subtracted from its positions before they are
/// projected: f32 coordinates of a scan far from the origin (a 0.1-unit
/// face 200 units out) would otherwise round shared edges apart by more
/// than the overlap test's margin, and every large chart would fail.
fn chart_origin(positions: &[Vec3], tris: &[[u32; 3]], faces: &[u32]) -> Vec3 {
    faces
        .first()
        .map_or(Vec3::ZERO, |&f| positions[tris[f as usize][0] as usize])
}

/// An orthonormal basis (a, b) of the plane normal to `n`, with a × b = n.
fn plane_basis(n: Vec3) -> (Vec3, Vec3) {
    let a = n.any_orthonormal_vector();
    (a, n.cross(a))
}

/// The chart projected onto the plane normal to `normal`: per face, its
/// corners' coordinates (counter-clockwise faces stay counter-clockwise).
pub fn project_chart(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    faces: &[u32],
    normal: Vec3,
    _local: &mut [u32],
) -> Vec<[Vec2; 3]> {
    let (a, b) = plane_basis(normal);
    let origin = chart_origin(positions, tris, faces);
    faces
        .iter()
        .map(|&f| {
            tris[f as usize].map(|v| {
                let p = positions[v as usize] - origin;
                Vec2::new(p.dot(a), p.dot(b))
            })
        })
        .collect()
}

/// Least-squares conformal map of the chart; `None` when the solve does not
/// give finite coordinates. Coordinates are in world units only up to the
/// pins' spacing; the caller rescales.
pub fn flatten_chart(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    faces: &[u32],
    normal: Vec3,
    local: &mut [u32],
) -> Option<Vec<[Vec2; 3]>> {
    let (verts, corners) = local_indices(tris, faces, local);
    let n = verts.len();
    let (a, b) = plane_basis(normal);
    let origin = chart_origin(positions, tris, faces);
    let (a, b) = (a.as_dvec3(), b.as_dvec3());
    let mut x: Vec<DVec2> = verts
        .iter()
        .map(|&v| {
            let p = (positions[v as usize] - origin).as_dvec3();
            DVec2::new(p.dot(a), p.dot(b))
        })
        .collect();
    // Per triangle: √area × gradients of the three hat functions.
    let mut grads: Vec<(usize, [DVec2; 3])> = Vec::with_capacity(faces.len());
    for (i, &f) in faces.iter().enumerate() {
        let p = tris[f as usize].map(|v| positions[v as usize].as_dvec3());
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let l = e1.length();
        let cross = e1.cross(e2);
        let area = 0.5 * cross.length();
        if l <= 0.0 || area <= 1e-18 * (l * l).max(1e-300) || !area.is_finite() {
            continue;
        }
        let ex = e1 / l;
        let ey = cross.cross(e1).normalize();
        let q = [
            DVec2::ZERO,
            DVec2::new(l, 0.0),
            DVec2::new(e2.dot(ex), e2.dot(ey)),
        ];
        let w = area.sqrt() / (2.0 * area);
        let g = [0, 1, 2].map(|k| (q[(k + 2) % 3] - q[(k + 1) % 3]).perp() * w);
        grads.push((i, g));
    }
    if grads.is_empty() || n < 3 {
        return None;
    }
    // Pins: extreme vertices along the projection's longer axis.
    let (mut lo, mut hi) = (DVec2::splat(f64::INFINITY), DVec2::splat(f64::NEG_INFINITY));
    for p in &x {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    let axis = if hi.x - lo.x >= hi.y - lo.y {
        DVec2::X
    } else {
        DVec2::Y
    };
    let pin0 = (0..n).min_by(|&i, &j| x[i].dot(axis).total_cmp(&x[j].dot(axis)))?;
    let pin1 = (0..n).max_by(|&i, &j| x[i].dot(axis).total_cmp(&x[j].dot(axis)))?;
    if pin0 == pin1 {
        return None;
    }
    let pinned = |i: usize| i == pin0 || i == pin1;
    // Residual of one triangle: r = Σ_k v_k g_k − u_k R g_k, R = +90°.
    let apply = |x: &[DVec2], out: &mut [DVec2]| {
        out.fill(DVec2::ZERO);
        for (i, g) in &grads {
            let c = corners[*i];
            let mut r = DVec2::ZERO;
            for k in 0..3 {
                let xv = x[c[k] as usize];
                r += g[k] * xv.y - g[k].perp() * xv.x;
            }
            // Transpose: ∂r/∂u_k = −R g_k, ∂r/∂v_k = g_k.
            for k in 0..3 {
                let o = &mut out[c[k] as usize];
                o.x += -g[k].perp().dot(r);
                o.y += g[k].dot(r);
            }
        }
    };
    let mut diag = vec![DVec2::ZERO; n];
    for (i, g) in &grads {
        let c = corners[*i];
        for k in 0..3 {
            let d = g[k].length_squared();
            diag[c[k] as usize] += DVec2::splat(d);
        }
    }
    let precond = |r: &[DVec2], z: &mut [DVec2]| {
        for i in 0..n {
            z[i] = if pinned(i) || diag[i].x <= 0.0 {
                DVec2::ZERO
            } else {
                r[i] / diag[i]
            };
        }
    };
    let dot = |p: &[DVec2], q: &[DVec2]| -> f64 { p.iter().zip(q).map(|(a, b)| a.dot(*b)).sum() };
    let mut r = vec![DVec2::ZERO; n];
    apply(&x, &mut r);
    for (i, ri) in r.iter_mut().enumerate() {
        *ri = if pinned(i) { DVec2::ZERO } else { -*ri };
    }
    let mut z = vec![DVec2::ZERO; n];
    precond(&r, &mut z);
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let r0 = dot(&r, &r).sqrt();
    let scale: f64 = grads
        .iter()
        .map(|(_, g)| g[0].length_squared())
        .sum::<f64>()
        .sqrt()
        * (hi - lo).length().max(1e-300);
    let mut ap = vec![DVec2::ZERO; n];
    // A residual 10⁵ times below the projection's is far below what a
    // texel can show; the cap bounds the worst case on huge charts.
    let max_iter = (2 * n).clamp(100, 1500);
    for _ in 0..max_iter {
        if dot(&r, &r).sqrt() <= (1e-5 * r0).max(1e-12 * scale) || rz <= 0.0 {
            break;
        }
        apply(&p, &mut ap);
        for (i, v) in ap.iter_mut().enumerate() {
            if pinned(i) {
                *v = DVec2::ZERO;
            }
        }
        let pap = dot(&p, &ap);
        if pap.is_nan() || pap <= 0.0 {
            break;
        }
        let alpha = rz / pap;
        for i in 0..n {
            x[i] += p[i] * alpha;
            r[i] -= ap[i] * alpha;
        }
        precond(&r, &mut z);
        let rz_new = dot(&r, &z);
        let beta = rz_new / rz;
        rz = rz_new;
        for i in 0..n {
            p[i] = z[i] + p[i] * beta;
        }
    }
    if !x.iter().all(|p| p.is_finite()) {
        return None;
    }
    // Centred before rounding to f32, so precision follows the chart's
    // size, not its distance from the origin.
    let centre = x.iter().copied().sum::<DVec2>() / n as f64;
    Some(
        corners
            .iter()
            .map(|c| c.map(|v| (x[v as usize] - centre).as_vec2()))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A bent strip of quads (two planes at 40°): LSCM unfolds it with far
    /// less angle distortion than the projection.
    #[test]
    fn lscm_unfolds_a_bent_strip_conformally() {
        let mut positions = Vec::new();
        let (nx, ny) = (8usize, 4usize);
        for j in 0..=ny {
            for i in 0..=nx {
                let x = i as f32 / nx as f32;
                let y = j as f32 / ny as f32;
                // Fold along x = 0.5.
                let (px, pz) = if x <= 0.5 {
                    (x, 0.0)
                } else {
                    let a = 40f32.to_radians();
                    (0.5 + (x - 0.5) * a.cos(), (x - 0.5) * a.sin())
                };
                positions.push(Vec3::new(px, y, pz));
            }
        }
        let mut tris = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let v = (j * (nx + 1) + i) as u32;
                let w = (nx + 1) as u32;
                tris.push([v, v + 1, v + w + 1]);
                tris.push([v, v + w + 1, v + w]);
            }
        }
        let faces: Vec<u32> = (0..tris.len() as u32).collect();
        let mut local = vec![u32::MAX; positions.len()];
        let normal = Vec3::Z;
        let st = flatten_chart(&positions, &tris, &faces, normal, &mut local).unwrap();
        assert!(local.iter().all(|&l| l == u32::MAX));
        // Flattened edge lengths match 3-D ones up to one common scale.
        let ratio = |st: &[[Vec2; 3]]| {
            let mut r: Vec<f32> = Vec::new();
            for (t, s) in tris.iter().zip(st) {
                for k in 0..3 {
                    let l3 =
                        (positions[t[k] as usize] - positions[t[(k + 1) % 3] as usize]).length();
                    r.push((s[k] - s[(k + 1) % 3]).length() / l3);
                }
            }
            let max = r.iter().copied().fold(0.0, f32::max);
            let min = r.iter().copied().fold(f32::INFINITY, f32::min);
            max / min
        };
        let projected = project_chart(&positions, &tris, &faces, normal, &mut local);
        let (rl, rp) = (ratio(&st), ratio(&projected));
        assert!(rl < 1.01, "LSCM edge-length spread {rl}");
        assert!(rp > 1.2, "projection edge-length spread {rp}");
    }
}
