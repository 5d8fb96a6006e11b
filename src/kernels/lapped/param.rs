//! The parametrisation of a surface patch aligned to the field (Praun et
//! al. 2000 §3.4).
//!
//! For each face with field vector `T` (and `S = T × N`), write `T` and `S`
//! as zero-sum combinations of the corners, `T = Σ α_i x_i`,
//! `S = Σ β_i x_i` (with `α_i = ∇λ_i · T`, `β_i = ∇λ_i · S`). The map is
//! linear on the face, so `φ(T) = Σ α_i φ(x_i)`, and the functional
//!
//! ```text
//! E(φ) = Σ_f ‖φ(S) − ŝ‖² + ‖φ(T) − t̂‖²
//! ```
//!
//! is quadratic. It splits into the two texture coordinates, which share one
//! matrix: `M = Σ_f α αᵀ + β βᵀ` (a Laplacian-like, positive semi-definite
//! matrix whose null space is the constants), with right-hand sides
//! `Σ_f β` for `s` and `Σ_f α` for `t`. The minimum is unique up to a
//! translation, fixed by mapping the seed point to the patch centre.
//!
//! As in the paper, small systems are solved by (Jacobi-preconditioned)
//! conjugate gradients warm-started from the initial parametrisation of
//! §3.3. Large patches (hundreds to thousands of vertices, where a cold CG
//! needs hundreds of iterations) get a short CG budget first
//! ([`SolveSettings::cg_budget`]): where the growth's parametrisation is
//! already near the optimum (flat or developable regions) CG converges
//! within it, at a fraction of a factorisation's cost. Otherwise they are
//! factored: one vertex is pinned, which makes `M` positive definite, and
//! faer's sparse Cholesky solves both coordinates; should the factorisation
//! fail (a vertex held only by degenerate faces), CG takes over. Everything
//! is in `f64`.

use super::TriMesh;
use super::grow::SurfacePatch;
use glam::{DVec2, DVec3, Vec2, Vec3};

/// Settings of the least-squares solve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveSettings {
    /// CG: stop when `‖r‖ ≤ tolerance · ‖b‖`. Default 1e-6.
    pub tolerance: f64,
    /// CG: iteration cap per coordinate. Default 1000.
    pub max_iterations: usize,
    /// Patches with at least this many vertices are factored (sparse
    /// Cholesky) when CG does not converge within
    /// [`SolveSettings::cg_budget`]. Default 400; `usize::MAX` always
    /// uses CG.
    pub direct_from: usize,
    /// CG iterations per coordinate a large patch (`direct_from` or more
    /// vertices) whose warm start is near the optimum
    /// ([`SolveSettings::cg_first_below`]) gets before it is factored; 0
    /// always factors large patches (the behaviour before the budget).
    /// Default 24. Measured on the planar benchmark: the growth's
    /// parametrisation leaves a relative residual of 1e-6 to 1e-4, CG
    /// converges in 0 to 20 iterations, and the solves take a third of the
    /// time of the factorisations (ordering, symbolic and numeric).
    pub cg_budget: usize,
    /// Large patches try CG first only when the growth's parametrisation
    /// is this close to the optimum: relative residual `‖b − M x₀‖ / ‖b‖`
    /// of both coordinates at most this (dimensionless; default 1e-3, three
    /// orders above `tolerance`). Where the surface is curved or noisy the
    /// warm start is far off (0.1 to 2.5 on the messy-scan generator, where
    /// CG needs 200 to 400+ iterations), and those patches go straight to
    /// the factorisation, costing one matrix-vector product per coordinate.
    pub cg_first_below: f64,
}

impl Default for SolveSettings {
    fn default() -> Self {
        Self {
            tolerance: 1e-6,
            max_iterations: 1000,
            direct_from: 400,
            cg_budget: 24,
            cg_first_below: 1e-3,
        }
    }
}

/// What one optimisation did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ParamReport {
    /// CG iterations, both coordinates together (0 for a direct solve).
    pub iterations: usize,
    /// Whether the system was factored rather than iterated.
    pub direct: bool,
    /// Whether both solves reached the tolerance.
    pub converged: bool,
    /// The functional after the solve.
    pub energy: f64,
}

/// A symmetric sparse matrix in CSR form.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Csr {
    /// Row offsets, `n + 1` entries.
    pub start: Vec<u32>,
    /// Column of each entry.
    pub col: Vec<u32>,
    /// Value of each entry.
    pub val: Vec<f64>,
}

impl Csr {
    /// Number of rows.
    pub fn rows(&self) -> usize {
        self.start.len().saturating_sub(1)
    }

    /// Row `r` of `A x`.
    #[inline]
    pub fn row_dot(&self, r: usize, x: &[f64]) -> f64 {
        let (a, b) = (self.start[r] as usize, self.start[r + 1] as usize);
        self.col[a..b]
            .iter()
            .zip(&self.val[a..b])
            .map(|(&c, &v)| v * x[c as usize])
            .sum()
    }

    /// `y = A x`.
    pub fn mul(&self, x: &[f64], y: &mut [f64]) {
        for (r, out) in y.iter_mut().enumerate() {
            *out = self.row_dot(r, x);
        }
    }

    /// The diagonal.
    pub fn diagonal(&self) -> Vec<f64> {
        (0..self.rows())
            .map(|r| {
                let (a, b) = (self.start[r] as usize, self.start[r + 1] as usize);
                (a..b)
                    .find(|&k| self.col[k] as usize == r)
                    .map_or(0.0, |k| self.val[k])
            })
            .collect()
    }
}

/// The per-face coefficients `(α, β)` of §3.4 for face `f` with field `t`,
/// computed in `f64` and made to sum to exactly zero (the functional's null
/// space must be exactly the constants, or CG picks up a spurious
/// near-constant mode).
pub fn face_coefficients(mesh: &TriMesh, f: usize, t: Vec3) -> ([f64; 3], [f64; 3]) {
    let x = mesh.corners(f).map(|p| p.as_dvec3());
    let n2 = (x[1] - x[0]).cross(x[2] - x[0]);
    let twice_area = n2.length();
    if twice_area <= f64::MIN_POSITIVE {
        return ([0.0; 3], [0.0; 3]);
    }
    let n = n2 / twice_area;
    let t = t.as_dvec3();
    let s = t.cross(n);
    let grad: [DVec3; 3] = [0, 1, 2].map(|i| n.cross(x[(i + 2) % 3] - x[(i + 1) % 3]) / twice_area);
    let mut alpha = grad.map(|g| g.dot(t));
    let mut beta = grad.map(|g| g.dot(s));
    alpha[2] = -alpha[0] - alpha[1];
    beta[2] = -beta[0] - beta[1];
    (alpha, beta)
}

/// The normal equations of §3.4 for a patch: `(M, b_s, b_t)` over its local
/// vertices.
pub fn alignment_system(mesh: &TriMesh, patch: &SurfacePatch) -> (Csr, Vec<f64>, Vec<f64>) {
    let n = patch.vertices.len();
    let mut bs = vec![0.0f64; n];
    let mut bt = vec![0.0f64; n];
    // Per face its 3 × 3 block, bucketed by row (counting sort, faces in
    // order), then each row's entries ordered by column (stable: equal
    // columns are summed in face order) and merged.
    let mut count = vec![0u32; n + 1];
    for tri in patch.tris.iter().take(patch.faces.len()) {
        for &r in tri {
            count[r as usize + 1] += 3;
        }
    }
    for r in 0..n {
        count[r + 1] += count[r];
    }
    let mut fill = count.clone();
    let mut entries: Vec<(u32, f64)> = vec![(0, 0.0); count[n] as usize];
    for (lf, &f) in patch.faces.iter().enumerate() {
        let (alpha, beta) = face_coefficients(mesh, f as usize, patch.face_t[lf]);
        let tri = patch.tris[lf];
        for i in 0..3 {
            let r = tri[i] as usize;
            bs[r] += beta[i];
            bt[r] += alpha[i];
            for j in 0..3 {
                entries[fill[r] as usize] = (tri[j], alpha[i] * alpha[j] + beta[i] * beta[j]);
                fill[r] += 1;
            }
        }
    }
    let mut m = Csr {
        start: vec![0; n + 1],
        col: Vec::with_capacity(entries.len() / 2),
        val: Vec::with_capacity(entries.len() / 2),
    };
    for r in 0..n {
        let row = &mut entries[count[r] as usize..count[r + 1] as usize];
        // Rows hold a few dozen entries: insertion sort, stable.
        for i in 1..row.len() {
            let mut k = i;
            while k > 0 && row[k - 1].0 > row[k].0 {
                row.swap(k - 1, k);
                k -= 1;
            }
        }
        let mut last = u32::MAX;
        for &(c, v) in row.iter() {
            if c == last {
                if let Some(x) = m.val.last_mut() {
                    *x += v;
                }
            } else {
                m.col.push(c);
                m.val.push(v);
                last = c;
            }
        }
        m.start[r + 1] = m.col.len() as u32;
    }
    (m, bs, bt)
}

/// Solves `A x = b` by Jacobi-preconditioned conjugate gradients from the
/// initial `x`; returns `(iterations, converged)`. `A` must be symmetric
/// positive semi-definite and `b` in its range.
pub fn conjugate_gradient(
    a: &Csr,
    b: &[f64],
    x: &mut [f64],
    settings: &SolveSettings,
) -> (usize, bool) {
    let n = b.len();
    let inv_diag: Vec<f64> = a
        .diagonal()
        .iter()
        .map(|&d| if d > 0.0 { 1.0 / d } else { 1.0 })
        .collect();
    let dot = |u: &[f64], v: &[f64]| u.iter().zip(v).map(|(a, b)| a * b).sum::<f64>();
    let b_norm = dot(b, b).sqrt();
    let goal = settings.tolerance * b_norm;
    let mut r = vec![0.0f64; n];
    a.mul(x, &mut r);
    for i in 0..n {
        r[i] = b[i] - r[i];
    }
    if b_norm == 0.0 || dot(&r, &r).sqrt() <= goal {
        return (0, true);
    }
    let mut z: Vec<f64> = r.iter().zip(&inv_diag).map(|(r, d)| r * d).collect();
    let mut p = z.clone();
    let mut rz = dot(&r, &z);
    let mut ap = vec![0.0f64; n];
    for it in 1..=settings.max_iterations {
        a.mul(&p, &mut ap);
        let pap = dot(&p, &ap);
        if pap <= 0.0 {
            return (it, dot(&r, &r).sqrt() <= goal);
        }
        let step = rz / pap;
        for i in 0..n {
            x[i] += step * p[i];
            r[i] -= step * ap[i];
        }
        if dot(&r, &r).sqrt() <= goal {
            return (it, true);
        }
        for i in 0..n {
            z[i] = r[i] * inv_diag[i];
        }
        let rz_next = dot(&r, &z);
        let beta = rz_next / rz;
        rz = rz_next;
        for i in 0..n {
            p[i] = z[i] + beta * p[i];
        }
    }
    (settings.max_iterations, false)
}

/// `‖b − A x‖ / ‖b‖` (0 for `b = 0`).
pub fn relative_residual(a: &Csr, b: &[f64], x: &[f64]) -> f64 {
    let (mut rr, mut bb) = (0.0f64, 0.0f64);
    for (r, &br) in b.iter().enumerate() {
        let ax = a.row_dot(r, x);
        rr += (br - ax) * (br - ax);
        bb += br * br;
    }
    if bb == 0.0 { 0.0 } else { (rr / bb).sqrt() }
}

/// The functional `Σ_f ‖d_S‖² + ‖d_T‖²` of the patch's current
/// parametrisation.
pub fn alignment_energy(mesh: &TriMesh, patch: &SurfacePatch) -> f64 {
    patch
        .faces
        .iter()
        .enumerate()
        .map(|(lf, &f)| {
            let (alpha, beta) = face_coefficients(mesh, f as usize, patch.face_t[lf]);
            if alpha == [0.0; 3] && beta == [0.0; 3] {
                return 0.0;
            }
            let st = patch.tris[lf].map(|v| patch.st[v as usize].as_dvec2());
            let phi_t: DVec2 = (0..3).map(|i| st[i] * alpha[i]).sum();
            let phi_s: DVec2 = (0..3).map(|i| st[i] * beta[i]).sum();
            (phi_s - DVec2::X).length_squared() + (phi_t - DVec2::Y).length_squared()
        })
        .sum()
}

/// Solves `M s = b_s` and `M t = b_t` directly: pins vertex 0 at 0 (the
/// solution is unique up to a translation) and factors the rest with
/// faer's sparse Cholesky. `None` when the pinned matrix is not positive
/// definite.
pub fn solve_direct(m: &Csr, bs: &[f64], bt: &[f64]) -> Option<(Vec<f64>, Vec<f64>)> {
    use faer::linalg::solvers::Solve;
    use faer::sparse::{SparseColMat, Triplet};
    let n = m.rows();
    if n == 0 {
        return Some((Vec::new(), Vec::new()));
    }
    // 32-bit indices (a patch has fewer than 2³² vertices): the factor's
    // row indices take half the memory of `usize` ones.
    let mut triplets: Vec<Triplet<u32, u32, f64>> = Vec::with_capacity(m.val.len());
    for r in 0..n {
        for k in m.start[r] as usize..m.start[r + 1] as usize {
            let c = m.col[k];
            if r != 0 && c != 0 {
                triplets.push(Triplet::new(r as u32, c, m.val[k]));
            }
        }
    }
    triplets.push(Triplet::new(0, 0, 1.0));
    let a = SparseColMat::<u32, f64>::try_new_from_triplets(n, n, &triplets).ok()?;
    drop(triplets);
    let llt = a.sp_cholesky(faer::Side::Lower);
    crate::kernels::simd_state::after_faer();
    let llt = llt.ok()?;
    let mut rhs = faer::Mat::<f64>::zeros(n, 2);
    for i in 1..n {
        rhs[(i, 0)] = bs[i];
        rhs[(i, 1)] = bt[i];
    }
    llt.solve_in_place(&mut rhs);
    crate::kernels::simd_state::after_faer();
    let s: Vec<f64> = (0..n).map(|i| rhs[(i, 0)]).collect();
    let t: Vec<f64> = (0..n).map(|i| rhs[(i, 1)]).collect();
    (s.iter().chain(&t).all(|v| v.is_finite())).then_some((s, t))
}

/// Optimises the patch's parametrisation in place (§3.4): solves both
/// coordinates (directly for large patches, else by CG from the current
/// values), then translates so that the seed point maps to the origin (the
/// patch centre).
pub fn optimise_parametrisation(
    mesh: &TriMesh,
    patch: &mut SurfacePatch,
    settings: &SolveSettings,
) -> ParamReport {
    let _span =
        tracing::trace_span!("optimise_parametrisation", faces = patch.faces.len()).entered();
    let (m, bs, bt) = alignment_system(mesh, patch);
    let mut s: Vec<f64> = patch.st.iter().map(|p| p.x as f64).collect();
    let mut t: Vec<f64> = patch.st.iter().map(|p| p.y as f64).collect();
    let mut report = ParamReport {
        converged: true,
        ..Default::default()
    };
    // Large patches: a CG budget first, then the factorisation.
    let mut solved = false;
    if patch.vertices.len() >= settings.direct_from {
        let budget = SolveSettings {
            max_iterations: settings.cg_budget.min(settings.max_iterations),
            ..*settings
        };
        let near = settings.cg_budget > 0
            && relative_residual(&m, &bs, &s) <= settings.cg_first_below
            && relative_residual(&m, &bt, &t) <= settings.cg_first_below;
        let (is, cs) = if near {
            conjugate_gradient(&m, &bs, &mut s, &budget)
        } else {
            (0, false)
        };
        report.iterations += is;
        if cs {
            let (it, ct) = conjugate_gradient(&m, &bt, &mut t, &budget);
            report.iterations += it;
            solved = ct;
        }
        if !solved && let Some((ds, dt)) = solve_direct(&m, &bs, &bt) {
            (s, t) = (ds, dt);
            report.direct = true;
            solved = true;
        }
    }
    if !solved {
        let (is, cs) = conjugate_gradient(&m, &bs, &mut s, settings);
        let (it, ct) = conjugate_gradient(&m, &bt, &mut t, settings);
        report.iterations += is + it;
        report.converged = cs && ct;
    }
    let seed = patch.tris[0];
    let b = patch.seed_bary;
    let centre = DVec2::new(
        (0..3).map(|i| s[seed[i] as usize] * b[i] as f64).sum(),
        (0..3).map(|i| t[seed[i] as usize] * b[i] as f64).sum(),
    );
    for (i, st) in patch.st.iter_mut().enumerate() {
        *st = Vec2::new((s[i] - centre.x) as f32, (t[i] - centre.y) as f32);
    }
    report.energy = alignment_energy(mesh, patch);
    report
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::lapped::FaceField;
    use crate::kernels::lapped::grow::{GrowSettings, Grower};
    use crate::kernels::lapped::hull::Hull;
    use crate::kernels::lapped::tangent_field::global_up_field;
    use crate::kernels::lapped::test_meshes::{grid, sphere};

    fn square_hull(r: f32) -> Hull {
        Hull::new(vec![
            Vec2::new(-r, -r),
            Vec2::new(r, -r),
            Vec2::new(r, r),
            Vec2::new(-r, r),
        ])
    }

    #[test]
    fn flat_grid_with_constant_field_gives_the_exact_similarity() {
        // A jittered grid, a rotated and scaled constant field, and a
        // perturbed start: the optimum is the similarity (zero residual).
        let mut mesh = grid(12, 0.25);
        for (i, p) in mesh.positions.iter_mut().enumerate() {
            let h = crate::kernels::mix(3, i as u64, 0);
            p.x += ((h & 0xFFFF) as f32 / 65535.0 - 0.5) * 0.08;
            p.y += (((h >> 16) & 0xFFFF) as f32 / 65535.0 - 0.5) * 0.08;
        }
        let m = TriMesh::new(&mesh).unwrap();
        let up = Vec3::new(0.6, 0.8, 0.0);
        let scale = 1.7;
        let t = global_up_field(&m, up, scale);
        let field = FaceField {
            t: &t,
            isotropic: false,
            scale: 1.0,
        };
        let mut g = Grower::new(&m, field, GrowSettings::default());
        let seed = 2 * (5 * 11 + 5);
        let bary = [0.2, 0.5, 0.3];
        let mut p = g.start(seed, bary, 0.0);
        g.grow(&mut p, &square_hull(0.8));
        assert!(p.faces.len() > 50);
        for (i, st) in p.st.iter_mut().enumerate() {
            *st += Vec2::new((i % 7) as f32 * 0.01, (i % 5) as f32 * -0.02);
        }
        let report = optimise_parametrisation(
            &m,
            &mut p,
            &SolveSettings {
                tolerance: 1e-12,
                max_iterations: 10_000,
                ..Default::default()
            },
        );
        assert!(report.converged && report.energy < 1e-8, "{report:?}");
        let c = m.point(seed as usize, bary);
        let right = up.normalize().cross(Vec3::Z);
        for (l, &v) in p.vertices.iter().enumerate() {
            let d = m.positions[v as usize] - c;
            let expected = Vec2::new(d.dot(right), d.dot(up.normalize())) / scale;
            assert!(
                (p.st[l] - expected).length() < 1e-5,
                "{:?} vs {expected:?}",
                p.st[l]
            );
        }
    }

    #[test]
    fn cg_and_cholesky_match_a_dense_least_squares_solve() {
        let mesh = sphere(2);
        let m = TriMesh::new(&mesh).unwrap();
        let t = global_up_field(&m, Vec3::new(0.3, 1.0, 0.2), 0.8);
        for (isotropic, direct_from) in [
            (false, usize::MAX),
            (true, usize::MAX),
            (false, 0),
            (true, 0),
        ] {
            let field = FaceField {
                t: &t,
                isotropic,
                scale: 1.0,
            };
            let mut g = Grower::new(
                &m,
                field,
                GrowSettings {
                    max_distortion: 2.0,
                    ..Default::default()
                },
            );
            let mut p = g.start(7, [0.5, 0.25, 0.25], 0.3);
            g.grow(&mut p, &square_hull(0.6));
            let nv = p.vertices.len();
            assert!(nv > 10 && nv < 200, "{nv}");
            let report = optimise_parametrisation(
                &m,
                &mut p,
                &SolveSettings {
                    tolerance: 1e-13,
                    max_iterations: 10_000,
                    direct_from,
                    cg_budget: 0,
                    ..SolveSettings::default()
                },
            );
            assert_eq!(report.direct, direct_from == 0);
            // Dense least squares: rows (per face) β·s − 1, α·s, β·t, α·t − 1,
            // plus one row pinning the seed point at the origin.
            let rows = 2 * p.faces.len() + 1;
            let mut a = faer::Mat::<f64>::zeros(rows, nv);
            let mut bs = faer::Mat::<f64>::zeros(rows, 1);
            let mut bt = faer::Mat::<f64>::zeros(rows, 1);
            for (lf, &f) in p.faces.iter().enumerate() {
                let (alpha, beta) = face_coefficients(&m, f as usize, p.face_t[lf]);
                for i in 0..3 {
                    let v = p.tris[lf][i] as usize;
                    a[(2 * lf, v)] += beta[i];
                    a[(2 * lf + 1, v)] += alpha[i];
                }
                bs[(2 * lf, 0)] = 1.0;
                bt[(2 * lf + 1, 0)] = 1.0;
            }
            for i in 0..3 {
                a[(rows - 1, p.tris[0][i] as usize)] += p.seed_bary[i] as f64 * 100.0;
            }
            let qr = a.col_piv_qr();
            use faer::linalg::solvers::SolveLstsq;
            let xs = qr.solve_lstsq(&bs);
            let xt = qr.solve_lstsq(&bt);
            for l in 0..nv {
                let dense = Vec2::new(xs[(l, 0)] as f32, xt[(l, 0)] as f32);
                assert!(
                    (p.st[l] - dense).length() < 1e-4,
                    "isotropic {isotropic}, direct {}, vertex {l}: {:?} vs dense {dense:?}",
                    report.direct,
                    p.st[l]
                );
            }
        }
    }
}
