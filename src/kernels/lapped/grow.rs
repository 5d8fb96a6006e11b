//! Growing a surface patch (Praun et al. 2000 §3.3).
//!
//! A paste starts at a point on a seed face: the point maps to the texture
//! patch centre and the face's basis `(S, T)` to the texture axes. Faces are
//! then added one at a time in order of increasing distance from the seed
//! (a Dijkstra over face centroids, in patch units), subject to three rules:
//!
//! 1. the patch stays homeomorphic to a disc: a face sharing one edge with
//!    the patch must bring a new vertex, a face sharing two edges fills a
//!    notch, and a face sharing three edges (which would close the surface)
//!    is refused;
//! 2. the patch only grows over an edge whose image still reaches into the
//!    texture patch's polygonal hull ([`super::hull`]);
//! 3. growth stops where the distortion becomes excessive: a face whose
//!    initial parametrisation disagrees with the field by more than
//!    [`GrowSettings::max_distortion`] is refused.
//!
//! Extension of rule 3: the distortion at the texel scale
//! ([`GrowSettings::distortion_radius`] > 0). The paper measures each face
//! on its own. On a dense scan the faces are rougher than the surface they
//! sample (scanner noise of a fixed amplitude tilts small faces more), and
//! the field projected onto each tilted face turns with the noise; the
//! per-face rule then refuses faces everywhere, patches fragment and the
//! paste count per face grows with the density (4.5 at 10 k vertices, 11
//! at 92 k on the messy-scan generator). The texture cannot show the tilt
//! of anything smaller than its texels, so the measure is taken at that
//! scale instead: the Jacobian `J = [φ(S), φ(T)]` of each face is low-pass
//! filtered along the growth front, `J̃_g = w J_g + (1 − w) J̃_f` with `f`
//! the patch face(s) `g` grows from and `w = min(1, step / radius)` (`step`
//! the centroid distance in patch units), so `J̃` averages the faces of
//! about one `radius` of growth path, and rule 3 compares
//! `‖J̃_g − I‖² / 2` with `max_distortion`. Zero-mean noise averages out
//! (the filtered measure converges as the mesh gets denser), a fold or a
//! field turn that persists over the radius still stops growth, and where
//! faces are larger than the radius (`w = 1`) it is exactly the paper's
//! per-face rule.
//!
//! A new vertex gets its texture coordinates by the prediction of Maillot et
//! al. 1993: for each face around it with an already mapped edge, the
//! triangle similar to the face in 3-D is laid on that edge; the vertex
//! takes the centroid of these predictions. For isotropic textures each new
//! face's direction is the mean of its patch neighbours' directions carried
//! across the shared edges (unfolding) — the propagation of §3.2.

use super::hull::Hull;
use super::{FaceField, NO_FACE, TriMesh};
use glam::{Vec2, Vec3};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Settings of patch growth.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GrowSettings {
    /// Largest accepted distortion of a new face: its share
    /// `(‖d_S‖² + ‖d_T‖²) / 2` of the §3.4 functional under the initial
    /// parametrisation (0 = perfectly aligned; a rotation by θ gives
    /// `2 − 2 cos θ`, a scale error by a factor k gives `(k − 1)²`).
    /// Default 0.6 (about 47°).
    pub max_distortion: f32,
    /// Scale at which rule 3 measures the distortion, patch units: 0 is
    /// the paper's per-face rule; above 0, the Jacobian is filtered along
    /// the growth front over this length (module docs). The paste loop
    /// sets it from [`crate::kernels::lapped::paste::PasteSettings::distortion_texels`].
    /// Default 0.
    pub distortion_radius: f32,
    /// Largest growth distance from the seed (patch units, along face
    /// centroids), as a multiple of the hull's largest radius. Where the
    /// field cannot be integrated (it turns around a thin tube, say) the
    /// optimised parametrisation shrinks, the hull then reaches ever
    /// farther over the surface, and regrowing would run away; this bounds
    /// it. Default 2.
    pub max_reach: f32,
    /// Safety bound on the faces of one patch. Default 100 000.
    pub max_faces: usize,
}

impl Default for GrowSettings {
    fn default() -> Self {
        Self {
            max_distortion: 0.6,
            distortion_radius: 0.0,
            max_reach: 2.0,
            max_faces: 100_000,
        }
    }
}

/// A surface patch and its parametrisation in patch units.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfacePatch {
    /// Mesh faces in the order they were added; `faces[0]` is the seed.
    pub faces: Vec<u32>,
    /// Per face, its corners as local vertex ids (the mesh's winding).
    pub tris: Vec<[u32; 3]>,
    /// Local vertex → mesh vertex.
    pub vertices: Vec<u32>,
    /// Per local vertex, `(s, t)` in patch units; the seed point maps to 0.
    pub st: Vec<Vec2>,
    /// Per face, the field vector `T` the parametrisation aligns to.
    pub face_t: Vec<Vec3>,
    /// Per face, its growth distance from the seed, patch units.
    pub face_dist: Vec<f32>,
    /// Barycentric coordinates of the seed point on `faces[0]`.
    pub seed_bary: [f32; 3],
}

impl SurfacePatch {
    /// `V − E + F` of the patch as a surface (1 for a disc).
    pub fn euler_characteristic(&self) -> i64 {
        let mut edges: Vec<(u32, u32)> = self
            .tris
            .iter()
            .flat_map(|t| (0..3).map(move |i| (t[i].min(t[(i + 1) % 3]), t[i].max(t[(i + 1) % 3]))))
            .collect();
        edges.sort_unstable();
        edges.dedup();
        self.vertices.len() as i64 - edges.len() as i64 + self.tris.len() as i64
    }

    /// Number of boundary loops of the patch (1 for a disc).
    pub fn boundary_loop_count(&self) -> usize {
        let mut directed: Vec<(u32, u32)> = self
            .tris
            .iter()
            .flat_map(|t| (0..3).map(move |i| (t[i], t[(i + 1) % 3])))
            .collect();
        directed.sort_unstable();
        let is_boundary = |&(a, b): &(u32, u32)| directed.binary_search(&(b, a)).is_err();
        let boundary: Vec<(u32, u32)> = directed.iter().copied().filter(is_boundary).collect();
        let mut next = std::collections::HashMap::new();
        for &(a, b) in &boundary {
            next.insert(a, b);
        }
        let mut seen = std::collections::HashSet::new();
        let mut loops = 0;
        for &(a, _) in &boundary {
            if seen.contains(&a) {
                continue;
            }
            loops += 1;
            let mut v = a;
            while seen.insert(v) {
                match next.get(&v) {
                    Some(&w) => v = w,
                    None => break,
                }
            }
        }
        loops
    }
}

#[derive(PartialEq)]
struct Candidate(f32, u32);
impl Eq for Candidate {}
impl PartialOrd for Candidate {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Candidate {
    fn cmp(&self, other: &Self) -> Ordering {
        // Min-heap on distance; ties by face id, for determinism.
        other
            .0
            .total_cmp(&self.0)
            .then_with(|| other.1.cmp(&self.1))
    }
}

/// Grows surface patches on one mesh, reusing its scratch arrays between
/// patches (global-size maps reset by a generation stamp).
pub struct Grower<'a> {
    mesh: &'a TriMesh,
    field: FaceField<'a>,
    settings: GrowSettings,
    stamp: u32,
    face_stamp: Vec<u32>,
    face_local: Vec<u32>,
    vertex_stamp: Vec<u32>,
    vertex_local: Vec<u32>,
    heap: BinaryHeap<Candidate>,
    /// Per patch face (local id), the filtered Jacobian `J̃` of the texel-
    /// scale distortion measure (empty with the per-face rule).
    smooth: Vec<[Vec2; 2]>,
}

impl<'a> Grower<'a> {
    /// A grower for `mesh` and its `field`.
    pub fn new(mesh: &'a TriMesh, field: FaceField<'a>, settings: GrowSettings) -> Self {
        Self {
            mesh,
            field,
            settings,
            stamp: 0,
            face_stamp: vec![0; mesh.face_count()],
            face_local: vec![0; mesh.face_count()],
            vertex_stamp: vec![0; mesh.positions.len()],
            vertex_local: vec![0; mesh.positions.len()],
            heap: BinaryHeap::new(),
            smooth: Vec::new(),
        }
    }

    #[inline]
    fn in_patch(&self, f: u32) -> bool {
        self.face_stamp[f as usize] == self.stamp
    }

    #[inline]
    fn local_vertex(&self, v: u32) -> Option<u32> {
        (self.vertex_stamp[v as usize] == self.stamp).then(|| self.vertex_local[v as usize])
    }

    fn add_vertex(&mut self, patch: &mut SurfacePatch, v: u32, st: Vec2) -> u32 {
        let local = patch.vertices.len() as u32;
        self.vertex_stamp[v as usize] = self.stamp;
        self.vertex_local[v as usize] = local;
        patch.vertices.push(v);
        patch.st.push(st);
        local
    }

    fn add_face(&mut self, patch: &mut SurfacePatch, f: u32, t: Vec3, dist: f32) {
        self.face_stamp[f as usize] = self.stamp;
        self.face_local[f as usize] = patch.faces.len() as u32;
        let tri = self.mesh.tris[f as usize].map(|v| {
            self.local_vertex(v)
                .expect("grow: a face is added after its corners are mapped")
        });
        patch.faces.push(f);
        patch.tris.push(tri);
        patch.face_t.push(t);
        patch.face_dist.push(dist);
    }

    /// Starts a patch at the point with barycentric coordinates `bary` on
    /// face `seed`. The point maps to the origin and the face's `(S, T)` to
    /// the texture axes. For an isotropic field, `T` is an arbitrary
    /// tangent rotated by `angle` radians (the field's length is kept).
    ///
    /// # Panics
    /// When `seed` is not a face of the mesh.
    pub fn start(&mut self, seed: u32, bary: [f32; 3], angle: f32) -> SurfacePatch {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            // The stamp wrapped: clear the maps once.
            self.face_stamp.fill(0);
            self.vertex_stamp.fill(0);
            self.stamp = 1;
        }
        let mesh = self.mesh;
        let f = seed as usize;
        let n = mesh.normal(f);
        let field_t = self.field.at(f);
        let scale = field_t.length().max(f32::MIN_POSITIVE);
        let dir = if self.field.isotropic || field_t.length_squared() == 0.0 {
            let x = mesh.corners(f);
            let e = (x[1] - x[0]).normalize_or(n.any_orthonormal_vector());
            let (sin, cos) = angle.sin_cos();
            e * cos + n.cross(e) * sin
        } else {
            field_t / scale
        };
        let t = dir * scale;
        let s = t.cross(n);
        let p0 = mesh.point(f, bary);
        let inv = 1.0 / (scale * scale);
        let mut patch = SurfacePatch {
            seed_bary: bary,
            ..Default::default()
        };
        for v in mesh.tris[f] {
            let d = mesh.positions[v as usize] - p0;
            self.add_vertex(&mut patch, v, Vec2::new(d.dot(s), d.dot(t)) * inv);
        }
        self.add_face(&mut patch, seed, t, 0.0);
        patch
    }

    /// Grows `patch` over every boundary edge that still reaches into
    /// `hull`, under the rules of the module docs; returns the number of
    /// faces added. Call again after the parametrisation changed (§3.4: the
    /// optimisation may uncover parts of the texture patch).
    pub fn grow(&mut self, patch: &mut SurfacePatch, hull: &Hull) -> usize {
        let radius = hull
            .vertices
            .iter()
            .map(|v| v.length())
            .fold(0.0f32, f32::max);
        self.grow_filtered(
            patch,
            self.settings.max_reach * radius,
            &|a: Vec2, b: Vec2| hull.segment_intersects(a, b),
            &mut |_: u32, _: [Vec2; 3]| true,
        )
    }

    /// [`Grower::grow`] with the growth distance bounded by `max_dist`
    /// (patch units), the hull test replaced by `reaches(a, b)` (does the
    /// edge with images `a b` still need covering?) and a last veto:
    /// `admit(face, st)` is asked once every other rule accepted the face
    /// with corner coordinates `st`; the face is added exactly when it
    /// returns true. The texture atlas (§4) uses this for its normal-cone and
    /// overlap constraints.
    pub fn grow_with(
        &mut self,
        patch: &mut SurfacePatch,
        max_dist: f32,
        reaches: &dyn Fn(Vec2, Vec2) -> bool,
        admit: &mut dyn FnMut(u32, [Vec2; 3]) -> bool,
    ) -> usize {
        self.grow_filtered(patch, max_dist, reaches, admit)
    }

    /// [`Grower::grow_with`], the patch's filtered Jacobians computed anew
    /// first.
    fn grow_filtered(
        &mut self,
        patch: &mut SurfacePatch,
        max_dist: f32,
        reaches: &dyn Fn(Vec2, Vec2) -> bool,
        admit: &mut dyn FnMut(u32, [Vec2; 3]) -> bool,
    ) -> usize {
        let mesh = self.mesh;
        if self.settings.distortion_radius > 0.0 {
            self.refilter(patch);
        }
        self.heap.clear();
        for (lf, &f) in patch.faces.iter().enumerate() {
            for &g in &mesh.neighbours[f as usize] {
                if g != NO_FACE && !self.in_patch(g) {
                    let d = patch.face_dist[lf] + self.step(patch.face_t[lf], f, g);
                    self.heap.push(Candidate(d, g));
                }
            }
        }
        let mut added = 0;
        while let Some(Candidate(dist, g)) = self.heap.pop() {
            if self.in_patch(g) || dist > max_dist {
                continue;
            }
            if patch.faces.len() >= self.settings.max_faces {
                break;
            }
            if self.try_add(patch, g, dist, reaches, admit) {
                added += 1;
                let lf = patch.faces.len() - 1;
                for &h in &mesh.neighbours[g as usize] {
                    if h != NO_FACE && !self.in_patch(h) {
                        let d = dist + self.step(patch.face_t[lf], g, h);
                        self.heap.push(Candidate(d, h));
                    }
                }
            }
        }
        added
    }

    /// Distance from face `f` to its neighbour `g` in patch units.
    #[inline]
    fn step(&self, t: Vec3, f: u32, g: u32) -> f32 {
        let m = self.mesh;
        m.centroid(f as usize).distance(m.centroid(g as usize)) / t.length().max(f32::MIN_POSITIVE)
    }

    /// The field vector of face `g` joining the patch.
    fn face_tangent(&self, patch: &SurfacePatch, g: u32) -> Vec3 {
        let mesh = self.mesh;
        let own = self.field.at(g as usize);
        if !self.field.isotropic && own.length_squared() > 0.0 {
            return own;
        }
        let mut sum = Vec3::ZERO;
        let mut scale = 0.0f32;
        let mut count = 0.0f32;
        for &f in &mesh.neighbours[g as usize] {
            if f != NO_FACE && self.in_patch(f) {
                let tf = patch.face_t[self.face_local[f as usize] as usize];
                sum += mesh
                    .transport(tf, f as usize, g as usize)
                    .normalize_or_zero();
                scale += tf.length();
                count += 1.0;
            }
        }
        let n = mesh.normal(g as usize);
        let dir = (sum - n * n.dot(sum))
            .try_normalize()
            .unwrap_or_else(|| n.any_orthonormal_vector());
        let len = if own.length_squared() > 0.0 {
            own.length()
        } else {
            scale / count.max(1.0)
        };
        dir * len
    }

    /// The Maillot et al. prediction of mesh vertex `w`'s coordinates from
    /// the faces around it with both other corners mapped.
    fn predict(&self, patch: &SurfacePatch, w: u32) -> Option<Vec2> {
        let mesh = self.mesh;
        let p = &mesh.positions;
        let mut sum = Vec2::ZERO;
        let mut count = 0.0f32;
        for &h in mesh.vertex_faces(w) {
            let t = mesh.tris[h as usize];
            let Some(k) = t.iter().position(|&v| v == w) else {
                continue;
            };
            // The face as (a, b, w), counter-clockwise.
            let (a, b) = (t[(k + 1) % 3], t[(k + 2) % 3]);
            let (Some(la), Some(lb)) = (self.local_vertex(a), self.local_vertex(b)) else {
                continue;
            };
            let (pa, pb, pw) = (p[a as usize], p[b as usize], p[w as usize]);
            let e = pb - pa;
            let len2 = e.length_squared();
            if len2 <= f32::MIN_POSITIVE {
                continue;
            }
            let x = (pw - pa).dot(e) / len2;
            let y = ((pw - pa) - e * x).length() / len2.sqrt();
            let (sa, sb) = (patch.st[la as usize], patch.st[lb as usize]);
            let edge = sb - sa;
            sum += sa + edge * x + edge.perp() * y;
            count += 1.0;
        }
        (count > 0.0).then(|| sum / count)
    }

    fn try_add(
        &mut self,
        patch: &mut SurfacePatch,
        g: u32,
        dist: f32,
        reaches: &dyn Fn(Vec2, Vec2) -> bool,
        admit: &mut dyn FnMut(u32, [Vec2; 3]) -> bool,
    ) -> bool {
        let mesh = self.mesh;
        let tri = mesh.tris[g as usize];
        let nb = mesh.neighbours[g as usize];
        let shared = nb.map(|f| f != NO_FACE && self.in_patch(f));
        let k = shared.iter().filter(|&&s| s).count();
        if k == 0 || k == 3 {
            return false;
        }
        // Rule 2: some shared edge still reaches into the texture patch.
        let reaches = (0..3).filter(|&i| shared[i]).any(|i| {
            match (
                self.local_vertex(tri[i]),
                self.local_vertex(tri[(i + 1) % 3]),
            ) {
                (Some(a), Some(b)) => reaches(patch.st[a as usize], patch.st[b as usize]),
                _ => false,
            }
        });
        if !reaches {
            return false;
        }
        // Rule 1: a disc stays a disc.
        let new_vertex = if k == 1 {
            let i = (0..3).find(|&i| shared[i]).unwrap_or(0);
            let w = tri[(i + 2) % 3];
            if self.local_vertex(w).is_some() {
                return false;
            }
            Some(w)
        } else {
            None
        };
        let t = self.face_tangent(patch, g);
        let predicted = match new_vertex {
            Some(w) => match self.predict(patch, w) {
                Some(st) => Some((w, st)),
                None => return false,
            },
            None => None,
        };
        // Rule 3: bounded distortion.
        let st = tri.map(|v| match (self.local_vertex(v), predicted) {
            (Some(l), _) => patch.st[l as usize],
            (None, Some((w, st))) if w == v => st,
            _ => Vec2::ZERO,
        });
        let (distortion, smooth) = if self.settings.distortion_radius > 0.0 {
            let (j, degenerate) = self.filtered_jacobian(patch, g, t, st);
            // Degenerate faces show nothing: accepted, as by the per-face rule.
            let d = if degenerate {
                0.0
            } else {
                jacobian_distortion(j)
            };
            (d, Some(j))
        } else {
            (face_distortion(mesh, g as usize, t, st), None)
        };
        if distortion > self.settings.max_distortion || !admit(g, st) {
            return false;
        }
        if let Some((w, st)) = predicted {
            self.add_vertex(patch, w, st);
        }
        self.add_face(patch, g, t, dist);
        if let Some(j) = smooth {
            self.smooth.push(j);
        }
        true
    }

    /// The filtered Jacobian `J̃` of face `g` (field `t`, corners at `st`)
    /// joining the patch: its own Jacobian blended with the mean `J̃` of its
    /// patch neighbours by `w = min(1, step / radius)` (module docs), and
    /// whether `g` is degenerate (it then carries its neighbours' mean on).
    fn filtered_jacobian(
        &self,
        patch: &SurfacePatch,
        g: u32,
        t: Vec3,
        st: [Vec2; 3],
    ) -> ([Vec2; 2], bool) {
        let own = face_jacobian(self.mesh, g as usize, t, st);
        let radius = self.settings.distortion_radius;
        let m = self.mesh;
        let mut sum = [Vec2::ZERO; 2];
        let mut count = 0.0f32;
        for &f in &self.mesh.neighbours[g as usize] {
            if f == NO_FACE || !self.in_patch(f) {
                continue;
            }
            let lf = self.face_local[f as usize] as usize;
            // Only faces already filtered (earlier in the patch) count.
            let Some(prev) = self.smooth.get(lf) else {
                continue;
            };
            let step = m.centroid(f as usize).distance(m.centroid(g as usize))
                / patch.face_t[lf].length().max(f32::MIN_POSITIVE);
            let w = (step / radius).min(1.0);
            let blended = match own {
                Some(j) if w >= 1.0 => j,
                Some(j) => [0, 1].map(|k| j[k] * w + prev[k] * (1.0 - w)),
                None => *prev,
            };
            sum[0] += blended[0];
            sum[1] += blended[1];
            count += 1.0;
        }
        let degenerate = own.is_none();
        if count == 0.0 {
            return (own.unwrap_or([Vec2::X, Vec2::Y]), degenerate);
        }
        ([sum[0] / count, sum[1] / count], degenerate)
    }

    /// Recomputes `J̃` of every patch face in patch order (the coordinates
    /// changed since: an optimisation, or a new patch).
    fn refilter(&mut self, patch: &SurfacePatch) {
        self.smooth.clear();
        for (lf, (&f, tri)) in patch.faces.iter().zip(&patch.tris).enumerate() {
            let st = tri.map(|v| patch.st[v as usize]);
            // Neighbours with a smaller local id joined before `f`; later
            // ones have no entry in `smooth` yet and are skipped.
            let (j, _) = self.filtered_jacobian(patch, f, patch.face_t[lf], st);
            self.smooth.push(j);
        }
    }
}

/// The Jacobian `[φ(S), φ(T)]` of face `f` when its corners map to `st` and
/// its field vector is `t` (the identity when the parametrisation maps
/// `(S, T)` exactly onto the texture axes); `None` for a degenerate face.
pub fn face_jacobian(mesh: &TriMesh, f: usize, t: Vec3, st: [Vec2; 3]) -> Option<[Vec2; 2]> {
    let (grad, n) = mesh.gradients_and_normal(f);
    if grad[0] == Vec3::ZERO {
        return None;
    }
    let s = t.cross(n);
    let mut phi_t = Vec2::ZERO;
    let mut phi_s = Vec2::ZERO;
    for i in 0..3 {
        phi_t += st[i] * grad[i].dot(t);
        phi_s += st[i] * grad[i].dot(s);
    }
    Some([phi_s, phi_t])
}

/// `‖J − I‖² / 2` of a Jacobian `[φ(S), φ(T)]`: the share of a face in
/// the functional of §3.4.
#[inline]
pub fn jacobian_distortion(j: [Vec2; 2]) -> f32 {
    0.5 * ((j[0] - Vec2::X).length_squared() + (j[1] - Vec2::Y).length_squared())
}

/// The share `(‖d_S‖² + ‖d_T‖²) / 2` of face `f` in the functional of §3.4
/// when its corners map to `st` and its field vector is `t`: 0 when the
/// parametrisation maps `(S, T)` exactly onto the texture axes. Degenerate
/// faces count as undistorted.
pub fn face_distortion(mesh: &TriMesh, f: usize, t: Vec3, st: [Vec2; 3]) -> f32 {
    face_jacobian(mesh, f, t, st).map_or(0.0, jacobian_distortion)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::lapped::hull::mask_hull;
    use crate::kernels::lapped::mask::{circle_mask, splotch_mask};
    use crate::kernels::lapped::tangent_field::global_up_field;
    use crate::kernels::lapped::test_meshes::{grid, sphere};

    fn hull_of(mask: &crate::kernels::lapped::mask::Mask) -> Hull {
        let c = Vec2::new(mask.width as f32 / 2.0, mask.height as f32 / 2.0);
        mask_hull(mask, c, mask.width as f32, 16)
    }

    #[test]
    fn flat_grid_patch_is_the_similarity_and_stays_near_the_hull() {
        let m = TriMesh::new(&grid(30, 0.1)).unwrap();
        let t = global_up_field(&m, Vec3::Y, 1.0);
        let field = FaceField {
            t: &t,
            isotropic: false,
            scale: 1.0,
        };
        let hull = hull_of(&circle_mask(64));
        let mut g = Grower::new(&m, field, GrowSettings::default());
        let seed = 2 * (15 * 29 + 15);
        let mut p = g.start(seed, [1.0 / 3.0; 3], 0.0);
        g.grow(&mut p, &hull);
        assert!(p.faces.len() > 100, "{}", p.faces.len());
        assert_eq!(p.euler_characteristic(), 1);
        assert_eq!(p.boundary_loop_count(), 1);
        // On a flat mesh with a constant field, st is the world offset.
        let c = m.point(seed as usize, [1.0 / 3.0; 3]);
        for (l, &v) in p.vertices.iter().enumerate() {
            let d = m.positions[v as usize] - c;
            assert!((p.st[l] - Vec2::new(d.x, d.y)).length() < 1e-4);
        }
        // Every face has an edge reaching into the hull (the grown band is
        // at most one face wide beyond it).
        for (lf, tri) in p.tris.iter().enumerate() {
            let reaches = (0..3).any(|i| {
                hull.segment_intersects(p.st[tri[i] as usize], p.st[tri[(i + 1) % 3] as usize])
            });
            assert!(reaches, "face {lf} lies outside the hull");
        }
    }

    #[test]
    fn patches_on_closed_meshes_are_discs() {
        let mesh = sphere(3);
        let m = TriMesh::new(&mesh).unwrap();
        // Large texture scale: the hull covers the whole sphere, so only the
        // disc rule stops growth.
        let t = global_up_field(&m, Vec3::Y, 4.0);
        for isotropic in [false, true] {
            let field = FaceField {
                t: &t,
                isotropic,
                scale: 1.0,
            };
            let settings = GrowSettings {
                max_distortion: f32::INFINITY,
                ..Default::default()
            };
            let mut g = Grower::new(&m, field, settings);
            let hull = hull_of(&splotch_mask(64, 5));
            for seed in [0u32, 17, 600] {
                let mut p = g.start(seed, [0.2, 0.3, 0.5], 1.0);
                g.grow(&mut p, &hull);
                assert_eq!(p.euler_characteristic(), 1, "seed {seed}");
                assert_eq!(p.boundary_loop_count(), 1, "seed {seed}");
                assert!(p.faces.len() > 500, "{}", p.faces.len());
            }
        }
    }

    #[test]
    fn distortion_stops_growth() {
        let mesh = sphere(3);
        let m = TriMesh::new(&mesh).unwrap();
        let t = global_up_field(&m, Vec3::Y, 4.0);
        let field = FaceField {
            t: &t,
            isotropic: false,
            scale: 1.0,
        };
        let hull = hull_of(&circle_mask(64));
        let mut loose = Grower::new(
            &m,
            field,
            GrowSettings {
                max_distortion: f32::INFINITY,
                ..Default::default()
            },
        );
        let mut strict = Grower::new(
            &m,
            field,
            GrowSettings {
                max_distortion: 0.05,
                ..Default::default()
            },
        );
        let mut a = loose.start(40, [1.0 / 3.0; 3], 0.0);
        loose.grow(&mut a, &hull);
        let mut b = strict.start(40, [1.0 / 3.0; 3], 0.0);
        strict.grow(&mut b, &hull);
        assert!(
            b.faces.len() < a.faces.len() / 2,
            "{} vs {}",
            b.faces.len(),
            a.faces.len()
        );
        assert_eq!(b.euler_characteristic(), 1);
    }
}
