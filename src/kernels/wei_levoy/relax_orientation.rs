//! Texture orientation over a mesh pyramid (Wei & Levoy 2001 §3.1, Fig. 3):
//! random `s` directions, a user direction, or relaxation towards n-way
//! symmetry.
//!
//! Relaxation starts from random directions on the coarsest level. Each finer
//! level is initialised by interpolating the next coarser level's directions
//! (at the parent point where the vertex normal meets the coarser surface,
//! the nearest surface point when it meets nothing) and then relaxed against
//! its one-ring neighbours and its parent-face vertices, minimising
//!
//! ```text
//! E = Σ_p Σ_{q near p} |φ_qp − round(φ_qp · n/360) · 360/n|²
//! ```
//!
//! where `φ_qp` is the angle (degrees) from `s_p` to `s_q` projected onto
//! `p`'s tangent plane and `n ∈ {1, 2, 4}` is the symmetry of the texture.
//! Angles that differ by a multiple of `360/n` cost nothing.
//!
//! Each iteration visits the vertices colour class by colour class (a greedy
//! colouring of the one-ring graph, so no two vertices of a class are
//! neighbours and their updates are independent) and rotates each `s_p` to
//! the exact minimiser of its own term `E_p` when that lowers every term `p`
//! takes part in (its own and its neighbours' terms on `s_p`); otherwise half
//! way, otherwise not at all. So `E` never increases, and the result does
//! not depend on the thread count.

use crate::kernels::mix;
use glam::Vec3;
use rayon::prelude::*;

use crate::kernels::surface::flatten::{TriangleAdjacency, template_spacing};
use crate::kernels::surface::frames::TangentFrame;
use crate::kernels::wei_levoy::wl_match::parents::{SurfacePoint, TriangleBvh};
use crate::mesh::{PolyMesh, Topology};
use crate::progress::{Progress, level_label};

/// How `s` directions are chosen.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum OrientationMode {
    /// Uniformly random on every level (isotropic textures).
    Random,
    /// `up` projected onto each tangent plane becomes `t` (a user field).
    User {
        /// The texture's up direction in world space.
        up: Vec3,
    },
    /// Random on the coarsest level, interpolated and relaxed on finer ones.
    Relax,
}

/// Settings of [`relax_orientation`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RelaxSettings {
    /// Random, user or relaxation.
    pub mode: OrientationMode,
    /// Rotational symmetry `n` of the texture: 1, 2 or 4 (others work too).
    pub symmetry: u32,
    /// Relaxation sweeps per level (the paper uses 30).
    pub iterations: u32,
    /// Seed of the random directions.
    pub seed: u64,
}

/// One level of the pyramid as the orientation kernel sees it.
#[derive(Clone, Copy, Debug)]
pub struct OrientationLevel<'a> {
    /// Vertex positions.
    pub positions: &'a [Vec3],
    /// Unit vertex normals.
    pub normals: &'a [Vec3],
    /// One-rings of the level.
    pub topology: &'a Topology,
    /// Fan triangles of the level (for parent lookups from finer levels).
    pub adjacency: &'a TriangleAdjacency,
}

/// Frames and energies per level, finest level first.
#[derive(Clone, Debug, Default)]
pub struct RelaxResult {
    /// Tangent frames of every vertex of every level.
    pub frames: Vec<Vec<TangentFrame>>,
    /// Per level: `E` in degrees² after initialisation, then after each
    /// iteration (only the first entry without relaxation).
    pub energy: Vec<Vec<f64>>,
}

/// Chooses tangent frames on every level of a pyramid (finest first) as
/// described in the module docs, and reports the energy `E`.
///
/// Preconditions: `levels[l]` arrays all have that level's vertex count;
/// normals are unit length; `settings.symmetry >= 1`.
pub fn relax_orientation(levels: &[OrientationLevel], settings: &RelaxSettings) -> RelaxResult {
    relax_orientation_with_progress(levels, settings, &Progress::hidden())
}

/// [`relax_orientation`], reporting to `progress`: one step per vertex for
/// its initial frame and per relaxation iteration, each level a part
/// (`"level 1/3"`, coarsest first).
pub fn relax_orientation_with_progress(
    levels: &[OrientationLevel],
    settings: &RelaxSettings,
    progress: &Progress,
) -> RelaxResult {
    let n = settings.symmetry.max(1);
    let count = levels.len();
    let rounds = 1 + if settings.mode == OrientationMode::Relax {
        u64::from(settings.iterations)
    } else {
        0
    };
    progress.set_length(levels.iter().map(|l| l.normals.len() as u64 * rounds).sum());
    let mut result = RelaxResult {
        frames: vec![Vec::new(); count],
        energy: vec![Vec::new(); count],
    };
    for l in (0..count).rev() {
        let _span = tracing::info_span!("relax_level", level = l).entered();
        progress.set_part(&level_label(l, count));
        let level = &levels[l];
        let coarser = (l + 1 < count).then(|| {
            let c = &levels[l + 1];
            let parents = parent_points(level, c);
            (parents, l + 1)
        });
        let frames = match settings.mode {
            OrientationMode::User { up } => level
                .normals
                .iter()
                .map(|&nrm| TangentFrame::from_up(nrm, up))
                .collect(),
            OrientationMode::Random => random_frames(level.normals, settings.seed, l as u64),
            OrientationMode::Relax => match &coarser {
                None => random_frames(level.normals, settings.seed, l as u64),
                Some((parents, c)) => interpolate_frames(
                    level.normals,
                    parents,
                    levels[*c].adjacency,
                    &result.frames[*c],
                    n,
                ),
            },
        };
        let parent_frames: Vec<[TangentFrame; 3]> = match &coarser {
            Some((parents, c)) => parents
                .iter()
                .map(|p| {
                    levels[*c].adjacency.tris[p.tri as usize].map(|v| result.frames[*c][v as usize])
                })
                .collect(),
            None => Vec::new(),
        };
        let mut state = Relaxation {
            topology: level.topology,
            parents: &parent_frames,
            frames,
            n,
        };
        let mut energy = vec![state.total_energy()];
        let nv = state.frames.len() as u64;
        progress.inc(nv);
        if settings.mode == OrientationMode::Relax {
            let classes = colour_classes(level.topology);
            let mut dirty = vec![true; state.frames.len()];
            for it in 0..settings.iterations {
                let _span = tracing::debug_span!("relax_iteration", it).entered();
                let e = if state.sweep(&classes, &mut dirty) {
                    state.total_energy()
                } else {
                    *energy.last().unwrap_or(&0.0)
                };
                energy.push(e);
                progress.inc(nv);
            }
        }
        result.frames[l] = state.frames;
        result.energy[l] = energy;
    }
    result
}

/// Frames of `to` interpolated from the frames of `from` with `n`-way
/// symmetric averaging, at the parent point of each `to` vertex on `from`
/// (normal line, else nearest point). Used to give pyramid levels frames
/// from a level that has them.
///
/// Preconditions: as [`relax_orientation`]; `from_frames` has one frame per
/// `from` vertex.
pub fn transfer_frames(
    from: &OrientationLevel,
    from_frames: &[TangentFrame],
    to: &OrientationLevel,
    n: u32,
) -> Vec<TangentFrame> {
    let parents = parent_points(to, from);
    interpolate_frames(to.normals, &parents, from.adjacency, from_frames, n.max(1))
}

/// Parent points of every vertex of `fine` on `coarse`: where the normal
/// line meets it within four coarse template spacings, else the nearest
/// surface point.
fn parent_points(fine: &OrientationLevel, coarse: &OrientationLevel) -> Vec<SurfacePoint> {
    let bvh = TriangleBvh::new(coarse.adjacency, coarse.positions);
    let reach =
        4.0 * template_spacing(coarse.adjacency.mean_triangle_area(coarse.positions)).max(1e-12);
    fine.positions
        .par_iter()
        .zip(fine.normals.par_iter())
        .map(|(&p, &nrm)| {
            bvh.cast_line(p, nrm, reach)
                .or_else(|| bvh.nearest_point(p))
                .unwrap_or(SurfacePoint {
                    tri: 0,
                    weights: [1.0, 0.0, 0.0],
                    at: p,
                })
        })
        .collect()
}

/// Random frames for one level; vertex `v` draws from its own stream.
fn random_frames(normals: &[Vec3], seed: u64, level: u64) -> Vec<TangentFrame> {
    crate::kernels::surface::frames::frames_with_angles(normals, |v| {
        let r = mix(seed, level, v as u64);
        (r >> 40) as f32 / (1u64 << 24) as f32 * std::f32::consts::TAU
    })
}

/// Base frame of a normal: deterministic, from which angles are measured.
#[inline]
fn base_frame(normal: Vec3) -> TangentFrame {
    TangentFrame::from_direction(normal, normal.any_orthonormal_vector())
}

fn interpolate_frames(
    normals: &[Vec3],
    parents: &[SurfacePoint],
    coarse: &TriangleAdjacency,
    coarse_frames: &[TangentFrame],
    n: u32,
) -> Vec<TangentFrame> {
    let nf = n as f32;
    normals
        .par_iter()
        .zip(parents.par_iter())
        .map(|(&nrm, parent)| {
            let base = base_frame(nrm);
            let tri = if coarse.is_empty() {
                return base;
            } else {
                coarse.tris[parent.tri as usize]
            };
            // n-fold symmetric mean: average the unit vectors at n·angle.
            let (mut cx, mut cy) = (0.0f32, 0.0f32);
            let mut first = None;
            for k in 0..3 {
                let s = coarse_frames[tri[k] as usize].s;
                let a = base.angle_of(s);
                first.get_or_insert(a);
                let w = parent.weights[k].max(0.0) + 1e-6;
                cx += w * (nf * a).cos();
                cy += w * (nf * a).sin();
            }
            let angle = if cx * cx + cy * cy > 1e-12 {
                cy.atan2(cx) / nf
            } else {
                first.unwrap_or(0.0)
            };
            base.rotated(angle)
        })
        .collect()
}

/// Greedy colouring of the one-ring graph in vertex order; returns the
/// vertices of each colour class.
fn colour_classes(topology: &Topology) -> Vec<Vec<u32>> {
    let nv = topology.vertex_count();
    let mut colour = vec![u32::MAX; nv];
    let mut classes: Vec<Vec<u32>> = Vec::new();
    let mut used: Vec<bool> = Vec::new();
    for v in 0..nv as u32 {
        used.clear();
        for &w in topology.neighbours(v) {
            let c = colour[w as usize];
            if c != u32::MAX {
                if used.len() <= c as usize {
                    used.resize(c as usize + 1, false);
                }
                used[c as usize] = true;
            }
        }
        let c = used.iter().position(|&u| !u).unwrap_or(used.len());
        colour[v as usize] = c as u32;
        if classes.len() <= c {
            classes.resize_with(c + 1, Vec::new);
        }
        classes[c].push(v);
    }
    classes
}

/// The angular residual of `phi` (radians) modulo `2π/n`, in degrees.
#[inline]
fn residual_degrees(phi: f32, n: u32) -> f32 {
    let period = std::f32::consts::TAU / n as f32;
    let r = phi - round(phi / period) * period;
    r.to_degrees()
}

/// Rounds half away from zero like `f32::round`, by a truncating cast (one
/// instruction; `round` is a library call on baseline x86-64). Exact for
/// `|x| < 2²³`, far beyond any angle ratio here.
#[inline]
fn round(x: f32) -> f32 {
    (x + 0.5f32.copysign(x)) as i32 as f32
}

struct Relaxation<'a> {
    topology: &'a Topology,
    /// Per vertex, the frames of its parent-face vertices (empty on the
    /// coarsest level).
    parents: &'a [[TangentFrame; 3]],
    frames: Vec<TangentFrame>,
    n: u32,
}

impl Relaxation<'_> {
    /// `E` over all vertices, in degrees², summed in vertex order.
    fn total_energy(&self) -> f64 {
        let per_vertex: Vec<f64> = (0..self.frames.len())
            .into_par_iter()
            .map(|p| {
                let f = &self.frames[p];
                let mut e = 0.0f64;
                for &q in self.topology.neighbours(p as u32) {
                    let r = residual_degrees(f.angle_of(self.frames[q as usize].s), self.n);
                    e += (r * r) as f64;
                }
                if let Some(par) = self.parents.get(p) {
                    for c in par {
                        let r = residual_degrees(f.angle_of(c.s), self.n);
                        e += (r * r) as f64;
                    }
                }
                e
            })
            .collect();
        per_vertex.iter().sum()
    }

    /// Every term `p`'s direction takes part in, with `s_p` rotated by `theta`.
    fn local_energy(&self, p: u32, theta: f32, own: &[f32]) -> f32 {
        let f = self.frames[p as usize].rotated(theta);
        let mut e = 0.0f32;
        for &a in own {
            let r = residual_degrees(a - theta, self.n);
            e += r * r;
        }
        for &q in self.topology.neighbours(p) {
            let r = residual_degrees(self.frames[q as usize].angle_of(f.s), self.n);
            e += r * r;
        }
        e
    }

    /// The rotation of `s_p` that best lowers its terms (0 when none does).
    fn best_rotation(&self, p: u32, own: &mut Vec<f32>) -> f32 {
        let f = &self.frames[p as usize];
        own.clear();
        for &q in self.topology.neighbours(p) {
            own.push(f.angle_of(self.frames[q as usize].s));
        }
        if let Some(par) = self.parents.get(p as usize) {
            for c in par {
                own.push(f.angle_of(c.s));
            }
        }
        if own.is_empty() {
            return 0.0;
        }
        let target = circular_minimiser(own, self.n);
        let current = self.local_energy(p, 0.0, own);
        let mut best = (current, 0.0f32);
        for theta in [target, 0.5 * target] {
            let e = self.local_energy(p, theta, own);
            if e < best.0 {
                best = (e, theta);
            }
        }
        best.1
    }

    /// One Gauss–Seidel sweep, class by class. Only vertices marked `dirty`
    /// are evaluated: a vertex whose direction and neighbours' directions did
    /// not change since it last found no better rotation would find none
    /// again, so skipping it changes nothing. Returns whether any direction
    /// rotated.
    fn sweep(&mut self, classes: &[Vec<u32>], dirty: &mut [bool]) -> bool {
        let mut any = false;
        for class in classes {
            let rotations: Vec<f32> = class
                .par_iter()
                .map_init(Vec::new, |own, &p| {
                    if dirty[p as usize] {
                        self.best_rotation(p, own)
                    } else {
                        0.0
                    }
                })
                .collect();
            for &p in class {
                dirty[p as usize] = false;
            }
            for (&p, &theta) in class.iter().zip(&rotations) {
                if theta != 0.0 {
                    any = true;
                    let f = &mut self.frames[p as usize];
                    *f = f.rotated(theta);
                    dirty[p as usize] = true;
                    for &q in self.topology.neighbours(p) {
                        dirty[q as usize] = true;
                    }
                }
            }
        }
        any
    }
}

/// The angle `θ` minimising `Σ_k r(a_k − θ)²`, `r` the residual modulo
/// `2π/n`: the squared-arc circular mean. The minimiser is the plain mean
/// of the values unwrapped at one of the `K` cuts between sorted residues, so
/// every cut is tried (O(K²), K is a one-ring).
fn circular_minimiser(angles: &[f32], n: u32) -> f32 {
    let period = std::f32::consts::TAU / n as f32;
    let mut b: Vec<f32> = angles.iter().map(|a| a.rem_euclid(period)).collect();
    b.sort_by(f32::total_cmp);
    let k = b.len() as f32;
    let total: f32 = b.iter().sum();
    let mut best = (f32::INFINITY, 0.0f32);
    let mut shifted = 0.0f32;
    for _ in 0..b.len() {
        // Values before the cut move up one period.
        let mean = (total + shifted) / k;
        let cost: f32 = b
            .iter()
            .map(|&x| {
                let r = residual_degrees(x - mean, n);
                r * r
            })
            .sum();
        if cost < best.0 {
            best = (cost, mean);
        }
        shifted += period;
    }
    // Express as the smallest rotation.
    let m = best.1;
    m - round(m / period) * period
}

/// Frames of `to` interpolated from `from`'s `frames` ([`transfer_frames`],
/// no symmetry assumed).
pub fn transfer_frames_between(
    from: &PolyMesh,
    frames: &[TangentFrame],
    to: &PolyMesh,
) -> Vec<TangentFrame> {
    let level = |m: &PolyMesh| {
        (
            m.vertex_normals(),
            Topology::build(m),
            TriangleAdjacency::new(m),
        )
    };
    let (fnorm, ftopo, fadj) = level(from);
    let (tnorm, ttopo, tadj) = level(to);
    transfer_frames(
        &OrientationLevel {
            positions: &from.positions,
            normals: &fnorm,
            topology: &ftopo,
            adjacency: &fadj,
        },
        frames,
        &OrientationLevel {
            positions: &to.positions,
            normals: &tnorm,
            topology: &ttopo,
            adjacency: &tadj,
        },
        1,
    )
}

/// Frames for every level of a pyramid (`meshes`, finest first): the
/// `given` ones; levels without frames (or with the wrong count) take
/// frames transferred from the nearest level that has them, else from
/// `external` (a mesh outside the pyramid with its frames).
///
/// # Errors
/// No level and no external mesh has frames.
pub fn complete_frames(
    meshes: &[&PolyMesh],
    given: &[Option<&[TangentFrame]>],
    external: Option<(&PolyMesh, &[TangentFrame])>,
) -> Result<Vec<Vec<TangentFrame>>, String> {
    let ok = |l: usize| given[l].filter(|f| f.len() == meshes[l].vertex_count());
    let mut out = Vec::with_capacity(meshes.len());
    for l in 0..meshes.len() {
        if let Some(f) = ok(l) {
            out.push(f.to_vec());
            continue;
        }
        let nearest = (0..meshes.len())
            .filter(|&k| ok(k).is_some())
            .min_by_key(|&k| k.abs_diff(l));
        let (from_mesh, from_frames) = match (nearest, external) {
            (Some(k), _) => (meshes[k], ok(k).unwrap_or(&[])),
            (None, Some(e)) => e,
            (None, None) => {
                return Err(
                    "needs tangent frames on the mesh: add `orientation` or `relax_orientation` before it"
                        .into(),
                );
            }
        };
        out.push(transfer_frames_between(from_mesh, from_frames, meshes[l]));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::PolyMesh;
    use crate::mesh::builtin::{BuiltinOptions, builtin_mesh};

    struct Owned {
        mesh: PolyMesh,
        normals: Vec<Vec3>,
        topo: Topology,
        adj: TriangleAdjacency,
    }

    fn sphere_pyramid(finest: u32, levels: u32) -> Vec<Owned> {
        (0..levels)
            .map(|l| {
                let mesh = builtin_mesh(
                    "icosphere",
                    &BuiltinOptions {
                        subdivisions: finest - l,
                        ..Default::default()
                    },
                )
                .unwrap();
                Owned {
                    normals: mesh.vertex_normals(),
                    topo: Topology::build(&mesh),
                    adj: TriangleAdjacency::new(&mesh),
                    mesh,
                }
            })
            .collect()
    }

    fn view(o: &[Owned]) -> Vec<OrientationLevel<'_>> {
        o.iter()
            .map(|o| OrientationLevel {
                positions: &o.mesh.positions,
                normals: &o.normals,
                topology: &o.topo,
                adjacency: &o.adj,
            })
            .collect()
    }

    #[test]
    fn circular_minimiser_is_exact_on_small_sets() {
        for n in [1u32, 2, 4] {
            let angles = [0.1f32, 0.3, 2.9, -1.2, 1.7];
            let m = circular_minimiser(&angles, n);
            let f = |t: f32| -> f32 {
                angles
                    .iter()
                    .map(|&a| residual_degrees(a - t, n).powi(2))
                    .sum()
            };
            let brute = (0..36000)
                .map(|i| f(i as f32 * std::f32::consts::TAU / 36000.0))
                .fold(f32::INFINITY, f32::min);
            assert!(
                f(m) <= brute + 1e-2 * brute.max(1.0),
                "n {n}: {} vs {brute}",
                f(m)
            );
        }
    }

    #[test]
    fn energy_never_increases_and_threads_do_not_matter() {
        let owned = sphere_pyramid(3, 3);
        let levels = view(&owned);
        for n in [2u32, 4] {
            let settings = RelaxSettings {
                mode: OrientationMode::Relax,
                symmetry: n,
                iterations: 10,
                seed: 3,
            };
            let r = relax_orientation(&levels, &settings);
            for (l, e) in r.energy.iter().enumerate() {
                assert_eq!(e.len(), 11);
                for w in e.windows(2) {
                    assert!(w[1] <= w[0] * (1.0 + 1e-6), "n {n} level {l}: {e:?}");
                }
            }
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap();
            let one = pool.install(|| relax_orientation(&levels, &settings));
            assert_eq!(one.energy, r.energy);
            assert!(one.frames[0] == r.frames[0]);
        }
    }

    #[test]
    fn user_mode_follows_up_and_transfer_keeps_a_smooth_field() {
        let owned = sphere_pyramid(3, 2);
        let levels = view(&owned);
        let r = relax_orientation(
            &levels,
            &RelaxSettings {
                mode: OrientationMode::User { up: Vec3::Z },
                symmetry: 1,
                iterations: 5,
                seed: 0,
            },
        );
        assert_eq!(r.energy[0].len(), 1);
        for f in &r.frames[0] {
            assert!(f.t.z >= -1e-4);
        }
        let moved = transfer_frames(&levels[1], &r.frames[1], &levels[0], 1);
        let mut agree = 0;
        for (a, b) in moved.iter().zip(&r.frames[0]) {
            if a.s.dot(b.s) > 0.9 {
                agree += 1;
            }
        }
        assert!(agree as f32 > 0.9 * moved.len() as f32, "{agree}");
    }
}
