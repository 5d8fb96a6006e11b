//! Retiling: a pyramid of evenly tessellated triangle meshes over the input
//! surface, the mesh pyramid `G_s` of Wei & Levoy 2001, §3.1 (Table 3,
//! lines 2–3, Figure 2).
//!
//! [`retile`] turns any polygon mesh into [`RetiledPyramid::levels`]: level 0
//! has the requested vertex count (or edge length), and each coarser level has
//! a quarter of the vertices of the next finer one, so the sample spacing
//! doubles per level just as it does in the image pyramid. Every vertex of
//! every level lies on the input surface, and records the input triangle and
//! barycentric coordinates it lies at, so results can be mapped back.
//!
//! # Method, and why
//!
//! Wei & Levoy retile with Turk's point repulsion ("Re-tiling polygonal
//! surfaces", 1992): scatter points, let them repel within the surface, then
//! re-triangulate them against the old mesh. We use isotropic remeshing
//! instead (Botsch & Kobbelt 2004; the steps are in `remesh.rs`), which
//! reaches the same goal — near-equilateral triangles of one size, vertices
//! spread evenly — by local edits of the connectivity (split, collapse, flip,
//! tangential relaxation with projection). Each edit can be checked on its
//! own, so the genus, the boundary loops and the components of the input are
//! kept by construction, no triangle turns over, and boundary vertices stay on
//! the input boundary; a global re-triangulation offers no such handle.
//!
//! The first target edge length is that of an equilateral tessellation with
//! `V` vertices of area `A`, `L = sqrt(2·A / (√3·V))` (it has about `2·V`
//! triangles of area `√3/4·L²`). The vertex count is then steered by rescaling
//! `L` by `sqrt(V / V_target)` after every iteration, and matched at the end
//! by splitting the longest or collapsing the shortest edges. A last pass
//! (`repair.rs`) fixes the rare triangle that stands edge-on to one side of a
//! sharp ridge of the input, by a flip, a collapse or a split (changing the
//! count by at most 2%).
//!
//! Coarser levels are remeshed from the finer level, not from the input: the
//! paper also "progresses from higher to lower resolutions", the finer level
//! is already even, so the coarser one converges in the same number of
//! iterations, mostly by collapses; and every level is projected onto the
//! *input* surface, so no error accumulates from level to level.
//!
//! # Preconditions and errors
//!
//! Any [`PolyMesh`]: polygons are fan-triangulated, several components are
//! remeshed together (each keeps its share of vertices by area),
//! inconsistently oriented faces are turned over, non-manifold edges are
//! cut and non-manifold vertices split (see [`InputReport`]), vertices in
//! no face are left out. Non-orientable components, non-finite positions,
//! meshes without faces (or area) and settings out of range are
//! [`RetileError`]s naming what and where, as is a target below three
//! vertices per connected piece (checked before any remeshing).
//!
//! # Feasible counts
//!
//! Each level aims at its share of the target per connected piece, by area;
//! a piece whose share is below [`remesh::SMALL_PIECE`] vertices keeps the
//! few its topology needs instead, and the level's target becomes the large
//! pieces' shares plus what the small ones hold
//! ([`RetiledLevel::target_vertices`]), so a scan's chips do not make the
//! main surface coarser. Every level lands within 5% of that target, except
//! where the surface's thin parts need more vertices than the target leaves
//! them (a thin tube needs three vertices around whatever the target; a
//! perforated plate needs its hole walls): the level is then as coarse as
//! the surface allows, kept with a warning, not refused. On the test suite's
//! perforated plate (genus 100, walls a tenth of the hole size), 800 and more
//! land within 5 %; 400 and 600 give about 700. A coarser level remeshed
//! from its finer one stops higher than one remeshed from the input (600
//! from 2,400 gives about 740), and one that would not halve ends the
//! pyramid.
//!
//! What keeps thin parts coarse is that the remesher can collapse into
//! features: an edge from a wall to a rim collapses into the rim vertex when
//! the midpoint would cut the rim, and a triangle on one side of a crease
//! agrees with the input at a corner on the crease through the face on its
//! side (`remesh.rs`). Without these, a plate asked for 1,000 vertices kept
//! 1,203, and 1,500 kept 2,477: the walls' vertices could not go.
//!
//! Deterministic: the same input and settings (including
//! [`RetileSettings::seed`]) give the same output at any rayon thread count.

mod prepare;
mod project;
mod remesh;
mod repair;
mod trimesh;

pub use prepare::InputReport;
pub use project::{
    MapBackError, MappedBack, ResultAttributes, SurfacePoint, SurfaceProjector,
    closest_point_on_triangle, map_back, map_back_with_progress,
};

use crate::mesh::PolyMesh;
use crate::progress::{Progress, level_label};
use glam::Vec3;
use remesh::{LevelPlan, LevelWork, Pieces, remesh_level, snap_to_surface};

/// How fine level 0 should be.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RetileTarget {
    /// Vertex count of level 0; range
    /// [`RetileSettings::MIN_LEVEL_VERTICES`]`..=`[`RetileSettings::MAX_VERTICES`]
    /// for every level.
    Vertices(u32),
    /// Edge length of level 0 in model units (finite, > 0). It is turned into
    /// a vertex count `V = 2·A / (√3·L²)` for total area `A` (the count of an
    /// equilateral tessellation), which must then be in range as above.
    EdgeLength(f32),
}

/// Settings of [`retile`].
#[derive(Clone, Debug, PartialEq)]
pub struct RetileSettings {
    /// Level 0's vertex count or edge length. Default 24,576 vertices (the
    /// sphere of Wei & Levoy's Figure 7).
    pub target: RetileTarget,
    /// Number of pyramid levels, level 0 finest, each coarser one with a
    /// quarter of the vertices. Range `1..=8`. Default 4 (the paper's).
    pub levels: u32,
    /// Remeshing iterations per level (split, collapse, flip, relax).
    /// Range `1..=100`. Default 10.
    pub iterations: u32,
    /// Seed of the edge orders (any value); different seeds give different,
    /// equally even tilings. Default 0.
    pub seed: u64,
}

impl Default for RetileSettings {
    fn default() -> Self {
        Self {
            target: RetileTarget::Vertices(24_576),
            levels: 4,
            iterations: 10,
            seed: 0,
        }
    }
}

impl RetileSettings {
    /// Fewest vertices any level may ask for.
    pub const MIN_LEVEL_VERTICES: u32 = 12;
    /// Most vertices level 0 may ask for.
    pub const MAX_VERTICES: u32 = 20_000_000;
    /// Most pyramid levels.
    pub const MAX_LEVELS: u32 = 8;
    /// Most iterations per level.
    pub const MAX_ITERATIONS: u32 = 100;
    /// Largest relative difference between a level's vertex count and its target.
    pub const COUNT_TOLERANCE: f64 = 0.05;

    /// Settings for `vertices` vertices at level 0, other fields default.
    pub fn with_vertices(vertices: u32) -> Self {
        Self {
            target: RetileTarget::Vertices(vertices),
            ..Self::default()
        }
    }

    /// Checks the ranges that do not depend on the mesh.
    ///
    /// # Errors
    /// [`RetileError::InvalidSetting`] naming the setting and its range.
    pub fn validate(&self) -> Result<(), RetileError> {
        let bad = |name: &'static str, value: String, allowed: String| {
            Err(RetileError::InvalidSetting {
                name,
                value,
                allowed,
            })
        };
        if !(1..=Self::MAX_LEVELS).contains(&self.levels) {
            return bad(
                "levels",
                self.levels.to_string(),
                format!("1..={}", Self::MAX_LEVELS),
            );
        }
        if !(1..=Self::MAX_ITERATIONS).contains(&self.iterations) {
            return bad(
                "iterations",
                self.iterations.to_string(),
                format!("1..={}", Self::MAX_ITERATIONS),
            );
        }
        match self.target {
            RetileTarget::Vertices(v) => self.check_vertices(v, "vertices"),
            RetileTarget::EdgeLength(l) if !(l.is_finite() && l > 0.0) => bad(
                "edge_length",
                l.to_string(),
                "a finite length > 0 (model units)".into(),
            ),
            RetileTarget::EdgeLength(_) => Ok(()),
        }
    }

    fn check_vertices(&self, v: u32, name: &'static str) -> Result<(), RetileError> {
        let coarsest = level_target(v as usize, self.levels - 1);
        let min = Self::MIN_LEVEL_VERTICES as usize;
        if v > Self::MAX_VERTICES || coarsest < min {
            let lo = min as u64 * 4u64.pow(self.levels - 1);
            return Err(RetileError::InvalidSetting {
                name,
                value: format!("{v} vertices at level 0"),
                allowed: format!(
                    "{lo}..={} vertices for {} levels (each level has a quarter of the \
                     vertices of the next finer one, and the coarsest needs at least {min})",
                    Self::MAX_VERTICES,
                    self.levels
                ),
            });
        }
        Ok(())
    }

    /// Level 0's vertex count for a surface of area `area`.
    fn level0_vertices(&self, area: f64) -> Result<usize, RetileError> {
        let v = match self.target {
            RetileTarget::Vertices(v) => v,
            RetileTarget::EdgeLength(l) => {
                let v = (2.0 * area / (3f64.sqrt() * (l as f64).powi(2))).round();
                v.min(u32::MAX as f64) as u32
            }
        };
        self.check_vertices(v, "edge_length")?;
        Ok(v as usize)
    }
}

/// Fewest vertices any connected piece keeps through remeshing: a
/// triangle (a closed piece keeps at least a tetrahedron's 4; 3 is the
/// bound that holds for every piece, so a target refused by it is truly
/// out of reach).
pub const MIN_VERTICES_PER_COMPONENT: usize = 3;

/// Target vertex count of `level` given level 0's.
fn level_target(level0: usize, level: u32) -> usize {
    ((level0 as f64) / 4f64.powi(level as i32)).round() as usize
}

/// Edge length of an equilateral tessellation of `area` with `vertices` vertices.
fn equilateral_edge_length(area: f64, vertices: usize) -> f32 {
    (2.0 * area / (3f64.sqrt() * vertices.max(1) as f64)).sqrt() as f32
}

/// One level of the pyramid.
#[derive(Clone, Debug, PartialEq)]
pub struct RetiledLevel {
    /// The retiled surface: triangles, consistently oriented like the input.
    pub mesh: PolyMesh,
    /// For each vertex: the input triangle it lies on, indexing the faces of
    /// `input.triangulated()` (the input's own faces when it is all
    /// triangles; [`RetiledPyramid::triangle_polygon`] maps them back to
    /// input polygons).
    pub source_face: Vec<u32>,
    /// For each vertex: its barycentric coordinates in `source_face`, in the
    /// corner order of that triangle; they sum to 1.
    pub source_bary: Vec<Vec3>,
    /// The vertex count this level aimed at: the asked count, with each
    /// small piece's share replaced by the vertices it holds.
    pub target_vertices: usize,
    /// The target edge length the remesher ended with (model units).
    pub edge_length: f32,
}

/// The retiled mesh pyramid; level 0 is the finest.
#[derive(Clone, Debug, PartialEq)]
pub struct RetiledPyramid {
    pub levels: Vec<RetiledLevel>,
    /// For each triangle of `input.triangulated()`: the input face it came from.
    pub triangle_polygon: Vec<u32>,
    /// What preparing the input changed.
    pub input: InputReport,
}

/// Why [`retile`] could not run.
#[derive(Debug, thiserror::Error)]
pub enum RetileError {
    /// A setting is out of its range.
    #[error("retile setting `{name}` = {value} is out of range; allowed: {allowed}")]
    InvalidSetting {
        name: &'static str,
        value: String,
        allowed: String,
    },
    /// Nothing to retile.
    #[error(
        "retile: the input mesh has no faces{detail}; it needs at least one triangle or polygon"
    )]
    NoFaces { detail: String },
    /// A vertex position is NaN or infinite.
    #[error("retile: input vertex {vertex} has a non-finite position {position:?}")]
    NonFinite { vertex: u32, position: [f32; 3] },
    /// More than two faces share an edge.
    #[error(
        "retile: non-manifold edge between vertices {a} and {b} ({faces} faces meet there; \
         {total} such edge(s) in all); every edge must have at most two faces — \
         split the mesh there or remove the extra faces"
    )]
    NonManifoldEdge {
        a: u32,
        b: u32,
        faces: usize,
        total: usize,
    },
    /// The input has more connected pieces than the level can hold.
    #[error(
        "retile: the input has {components} connected pieces and each keeps at least \
         {per_component} vertices, so level 0 cannot have {target} vertices (at least \
         {floor}); ask for more vertices (a smaller `[input] texture_scale` value, or \
         `retile.vertices`), or remove the small pieces from the mesh"
    )]
    TooManyComponents {
        components: usize,
        per_component: usize,
        target: usize,
        floor: usize,
    },
    /// A component cannot be oriented consistently (a Möbius strip, say).
    #[error(
        "retile: the surface containing input triangle {face} (of the triangulated input) \
         is not orientable, so its triangles cannot all face one way"
    )]
    NonOrientable { face: u32 },
}

/// Retiles `input` into a pyramid of `settings.levels` even triangle meshes
/// on its surface (Wei & Levoy 2001, §3.1); see the module docs.
///
/// Cost: O(iterations · V · log n) per level for `V` vertices over an input
/// of `n` triangles (the log from the BVH projection), plus O(n log n) to
/// index the input; the bunny to 24,576 vertices with 4 levels takes about
/// two CPU-seconds.
///
/// # Errors
/// See [`RetileError`]: bad settings, unusable input, or a target below
/// three vertices per connected piece. Levels that the surface's thin parts
/// keep above their target are kept (a warning is logged; see "Feasible
/// counts" in the module docs); the pyramid ends early, with fewer levels
/// than asked, at a level that would not shrink below half the finer one.
pub fn retile(input: &PolyMesh, settings: &RetileSettings) -> Result<RetiledPyramid, RetileError> {
    retile_with_progress(input, settings, &Progress::hidden())
}

/// [`retile`], reporting to `progress`: the levels are planned as parts
/// weighed by their remeshing work (`LevelWork`), each labelled by
/// [`level_label`] (`"level 0 of 4 (0 = finest)"` first).
///
/// # Errors
/// As [`retile`].
pub fn retile_with_progress(
    input: &PolyMesh,
    settings: &RetileSettings,
    progress: &Progress,
) -> Result<RetiledPyramid, RetileError> {
    settings.validate()?;
    let prep = prepare::prepare(input)?;
    let proj = SurfaceProjector::from_trimesh(&prep.mesh);
    let area: f64 = (0..prep.mesh.halfedge_slots() as u32 / 3)
        .map(|f| 0.5 * prep.mesh.face_normal_scaled(3 * f).length() as f64)
        .sum();
    if !(area.is_finite() && area > 0.0) {
        return Err(RetileError::NoFaces {
            detail: " with area (every triangle is degenerate)".into(),
        });
    }
    let v0 = settings.level0_vertices(area)?;
    // Every connected piece keeps a few vertices whatever the target (a
    // triangle at least): a finest level asking for fewer than that leaves
    // nothing for the surface. Checked before any remeshing.
    let floor = MIN_VERTICES_PER_COMPONENT * prep.report.components;
    if (v0 as f64) * (1.0 + RetileSettings::COUNT_TOLERANCE) < floor as f64 {
        return Err(RetileError::TooManyComponents {
            components: prep.report.components,
            per_component: MIN_VERTICES_PER_COMPONENT,
            target: v0,
            floor,
        });
    }
    let pieces = Pieces::of(&prep.mesh);
    let mut counts = Vec::new();
    let mut mesh = prep.mesh.clone();
    remesh::attach_to_input(&mut mesh, &proj);
    // One part per level, weighed by its remeshing work: the finest level,
    // grown from the input, is most of it.
    let label = |level: u32| level_label(level as usize, settings.levels as usize);
    progress.plan((0..settings.levels).map(|level| {
        let start = if level == 0 {
            mesh.live_vertices
        } else {
            level_target(v0, level - 1)
        };
        let work = LevelWork::of(level_target(v0, level), start, settings.iterations);
        (label(level), work.total() as f64)
    }));
    let mut len = equilateral_edge_length(area, v0);
    let mut levels = Vec::with_capacity(settings.levels as usize);
    for level in 0..settings.levels {
        let target = level_target(v0, level);
        // Coarser levels coarsen the large pieces; once every piece is
        // small at this level's density there is nothing left to coarsen.
        if level > 0 && pieces.large_share(target) == 0.0 {
            tracing::warn!(
                level,
                target,
                components = prep.report.components,
                "retile: every connected piece is below {} vertices at this level's density; the pyramid ends at {level} levels",
                remesh::SMALL_PIECE
            );
            break;
        }
        let _span = tracing::info_span!("retile_level", level, target).entered();
        let plan = LevelPlan {
            target_vertices: target,
            edge_length: len,
            iterations: settings.iterations,
            seed: splitmix(settings.seed ^ splitmix(level as u64 + 1)),
        };
        let work = LevelWork::of(target, mesh.live_vertices, settings.iterations);
        progress.start_part(&label(level), work.total());
        let (l, target) = remesh_level(&mut mesh, &proj, &pieces, &plan, progress);
        len = l;
        if target > plan.target_vertices {
            tracing::info!(
                level,
                asked = plan.target_vertices,
                target,
                "retile: small pieces of the input keep more vertices than their share of the level; the rest keeps the density asked for"
            );
        }
        mesh.compact();
        snap_to_surface(&mut mesh, &proj);
        let max_change = (repair::MAX_COUNT_CHANGE * target as f64) as usize;
        let left = repair::repair_flipped_faces(&mut mesh, &proj, 0.5 * len, 2.0 * len, max_change);
        if left > 0 {
            tracing::debug!(
                level,
                left,
                "triangles still face away from the input at their centroid"
            );
        }
        mesh.compact();
        let reached = mesh.live_vertices;
        let off = (reached as f64 - target as f64).abs()
            > RetileSettings::COUNT_TOLERANCE * target as f64;
        // A level the surface keeps above its target (thin walls and
        // handles need a minimum of vertices: no collapse there keeps the
        // topology and the triangles facing the way the input does) is kept
        // as it is, as dense as the surface allows: a level between its
        // neighbours is still a pyramid level. One that no longer shrinks
        // ends the pyramid early.
        if off {
            tracing::warn!(
                level,
                target,
                reached,
                "retile: the surface's thin parts keep this level above its target vertex count (the fewest vertices that keep its shape and topology)"
            );
        }
        // The large pieces (by this level's shares) must shrink to at most
        // half of what they had on the finer level; small ones keep theirs.
        let previous_free = (level > 0).then(|| pieces.split(plan.target_vertices, &counts).0);
        pieces.counts(&mesh, &mut counts);
        let free = pieces.split(plan.target_vertices, &counts).0;
        if let Some(p) = previous_free
            && 2 * free > p
        {
            tracing::warn!(
                level,
                free,
                previous = p,
                "retile: the level's large pieces do not shrink below half the finer level; the pyramid ends here"
            );
            break;
        }
        levels.push(export_level(&mesh, &prep, target, len));
        len *= 2.0;
    }
    let (_, triangle_polygon) = input.triangulate_corners();
    Ok(RetiledPyramid {
        levels,
        triangle_polygon,
        input: prep.report,
    })
}

/// The compacted, snapped mesh as a level, with its map back to the input.
fn export_level(
    mesh: &trimesh::TriMesh,
    prep: &prepare::Prepared,
    target: usize,
    len: f32,
) -> RetiledLevel {
    let tris = mesh.triangles();
    let source_face = mesh
        .src_face
        .iter()
        .map(|&f| prep.tri_source[f as usize])
        .collect();
    let source_bary = mesh
        .src_face
        .iter()
        .zip(&mesh.src_bary)
        .map(|(&f, &b)| {
            if prep.tri_flipped[f as usize] {
                Vec3::new(b.x, b.z, b.y)
            } else {
                b
            }
        })
        .collect();
    RetiledLevel {
        mesh: PolyMesh::from_triangles(mesh.pos.clone(), &tris),
        source_face,
        source_bary,
        target_vertices: target,
        edge_length: len,
    }
}

/// SplitMix64 finaliser, to derive per-level seeds.
fn splitmix(x: u64) -> u64 {
    let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Edge-length coefficient of variation (std / mean) of a mesh: how evenly
/// a level is tiled.
pub fn edge_length_cv(mesh: &PolyMesh) -> f32 {
    let topo = crate::mesh::Topology::build(mesh);
    let lens: Vec<f64> = topo
        .edges
        .iter()
        .map(|e| (mesh.positions[e[0] as usize] - mesh.positions[e[1] as usize]).length() as f64)
        .collect();
    let n = lens.len().max(1) as f64;
    let mean = lens.iter().sum::<f64>() / n;
    let var = lens.iter().map(|l| (l - mean) * (l - mean)).sum::<f64>() / n;
    (var.sqrt() / mean.max(1e-30)) as f32
}
