//! Absorbing small charts into their neighbours (step 3 of the module
//! docs). Noisy scans leave single faces and small groups whose normal left
//! the cone of the chart around them, and small closed components (a
//! pebble, a noisy octahedron) whose every face bends more than the cone
//! from the next: each becomes a chart of its own, and each chart costs a
//! bounding rectangle and a gutter in the packing. A 400 k-vertex messy
//! scan gave 47 k charts, 21 k of them single faces.
//!
//! A chart of at most [`SMALL_CHART_FACES`] faces is moved, face by face,
//! into the neighbouring chart it shares the longest edges with (else the
//! next): breadth first from the shared edges, each face is laid out on its
//! already placed edge as a similar copy of its 3-D triangle (an unfolding:
//! no distortion), or, when its third corner is placed already, keeps that
//! corner if the face stays counter-clockwise and near-conformal. A face
//! that flips or overlaps the host or another moved face cancels the move,
//! and the next neighbour is tried. Moved charts keep the host's vertex
//! positions along the shared edges, so no seam is added inside a chart.
//! Every grown chart is rescaled to its surface area, so texel density
//! stays uniform across charts.

use super::raster::{FrozenTriangleGrid, TriangleHash, signed_area2};
use super::segment::{NO_FACE, Scratch, edge_components};
use super::{Charts, singular_values};
use glam::{Vec2, Vec3};
use std::collections::{HashMap, VecDeque};

/// Largest chart (faces) that is moved into a neighbour. Moves cost linear
/// time in the moved faces (plus one spatial hash per host), so the bound
/// only limits how far an unfolding may wander from its host.
pub const SMALL_CHART_FACES: usize = 64;

/// Largest conformal stretch σ₁/σ₂, and largest ratio of texel density to
/// the host's (either way), of a moved face whose three corners the host
/// already placed.
const MAX_CLOSING_STRETCH: f32 = 4.0;

/// A chart that small charts may move into: its vertices' flat positions
/// and a spatial hash of its faces. What it held when first needed is kept
/// in sorted arrays (faces by index into the charts' corner coordinates,
/// which do not change while the host exists): every chart of a scan may
/// become a host, and maps of vectors held ~130 bytes per face, the
/// largest part of the atlas' peak memory.
struct Host {
    /// Per vertex of its faces when it became a host, its position, sorted
    /// by vertex (the first face holding the vertex gives it).
    base_position: Vec<(u32, Vec2)>,
    /// Positions of vertices that moved faces added since.
    added_position: HashMap<u32, Vec2>,
    /// Its faces when it became a host (corner coordinates in
    /// `Charts::corner_st`).
    grid: FrozenTriangleGrid,
    /// Faces moved into it since.
    added: TriangleHash,
    /// Texels per world unit of the host, as laid out (area ratio, √).
    density: f32,
}

impl Host {
    /// The flat position of vertex `v`, if the host holds it.
    fn position(&self, v: u32) -> Option<Vec2> {
        match self.base_position.binary_search_by_key(&v, |e| e.0) {
            Ok(i) => Some(self.base_position[i].1),
            Err(_) => self.added_position.get(&v).copied(),
        }
    }

    /// Records `q` for `v` unless the host already places `v`.
    fn place(&mut self, v: u32, q: Vec2) {
        if self
            .base_position
            .binary_search_by_key(&v, |e| e.0)
            .is_err()
        {
            self.added_position.entry(v).or_insert(q);
        }
    }

    /// Whether `t` overlaps a face of the host (`corner_st`: the charts'
    /// corner coordinates).
    fn overlaps(&mut self, t: &[Vec2; 3], corner_st: &[[Vec2; 3]]) -> bool {
        self.grid.overlaps(t, corner_st) || self.added.overlaps(t)
    }
}

/// Passes over the small charts: a chart that grew in one pass may move
/// as a whole in the next.
const MERGE_PASSES: usize = 4;

/// Moves the faces of every chart of at most [`SMALL_CHART_FACES`] faces
/// that can be laid out without flips or overlaps into a neighbouring chart
/// (module docs), renumbers the charts in order of their first face and
/// rescales every changed chart to its surface area. `nb` is
/// [`super::segment::manifold_neighbours`] of `tris`. Deterministic: charts
/// are visited smallest first, ties by id.
pub fn absorb_small_charts(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    nb: &[[u32; 3]],
    charts: &mut Charts,
) {
    let _span = tracing::debug_span!("absorb_small_charts", charts = charts.count).entered();
    let mut faces_of: Vec<Vec<u32>> = vec![Vec::new(); charts.count];
    for (f, &c) in charts.chart_of_face.iter().enumerate() {
        faces_of[c as usize].push(f as u32);
    }
    let face_area = |f: u32| {
        let p = tris[f as usize].map(|v| positions[v as usize]);
        0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length()
    };
    let mut hosts: HashMap<u32, Host> = HashMap::new();
    // Charts whose faces changed, to rescale.
    let mut changed = vec![false; charts.count];
    let mut member = vec![false; tris.len()];
    let mut scratch = Scratch::new(positions.len(), tris.len());
    for _ in 0..MERGE_PASSES {
        let mut order: Vec<u32> = (0..faces_of.len() as u32)
            .filter(|&c| (1..=SMALL_CHART_FACES).contains(&faces_of[c as usize].len()))
            .collect();
        order.sort_by_key(|&c| (faces_of[c as usize].len(), c));
        let mut any = false;
        for s in order {
            let small = std::mem::take(&mut faces_of[s as usize]);
            if small.is_empty() || small.len() > SMALL_CHART_FACES {
                faces_of[s as usize] = small;
                continue;
            }
            let shared =
                neighbours_by_shared_length(positions, tris, nb, &charts.chart_of_face, &small);
            for &f in &small {
                member[f as usize] = true;
            }
            let mut layout = Vec::new();
            let mut target = None;
            for &h in &shared {
                let host = hosts.entry(h).or_insert_with(|| {
                    host_of(tris, &faces_of[h as usize], &charts.corner_st, face_area)
                });
                layout = unfold_into(
                    positions,
                    tris,
                    nb,
                    (&charts.chart_of_face, &charts.corner_st),
                    h,
                    &small,
                    &member,
                    host,
                );
                if layout.iter().any(Option::is_some) {
                    target = Some(h);
                    break;
                }
            }
            for &f in &small {
                member[f as usize] = false;
            }
            let Some(h) = target else {
                faces_of[s as usize] = small;
                continue;
            };
            any = true;
            let host = hosts.get_mut(&h).expect("the host was built");
            let mut rest = Vec::new();
            for (&f, st) in small.iter().zip(&layout) {
                let Some(st) = st else {
                    rest.push(f);
                    continue;
                };
                charts.chart_of_face[f as usize] = h;
                charts.corner_st[f as usize] = *st;
                for (&v, &q) in tris[f as usize].iter().zip(st) {
                    host.place(v, q);
                }
                if face_area(f) > 0.0 {
                    host.added.insert(*st);
                }
                faces_of[h as usize].push(f);
            }
            changed[h as usize] = true;
            hosts.remove(&s);
            // What stays is a subset of a valid layout, so valid; each of
            // its edge-connected pieces becomes a chart (the first keeps `s`).
            for (i, piece) in edge_components(&rest, nb, &mut scratch)
                .into_iter()
                .enumerate()
            {
                let c = if i == 0 {
                    s
                } else {
                    faces_of.push(Vec::new());
                    changed.push(false);
                    (faces_of.len() - 1) as u32
                };
                for &f in &piece {
                    charts.chart_of_face[f as usize] = c;
                }
                faces_of[c as usize] = piece;
                changed[c as usize] = true;
            }
        }
        if !any {
            break;
        }
    }
    // Rescale changed charts to their surface area; renumber by first face.
    for (c, faces) in faces_of.iter().enumerate() {
        if !changed[c] {
            continue;
        }
        let (mut a3, mut a2) = (0.0f64, 0.0f64);
        for &f in faces {
            a3 += face_area(f) as f64;
            a2 += 0.5 * signed_area2(&charts.corner_st[f as usize]).abs() as f64;
        }
        if a3 > 0.0 && a2 > 0.0 {
            let k = (a3 / a2).sqrt() as f32;
            for &f in faces {
                for p in &mut charts.corner_st[f as usize] {
                    *p *= k;
                }
            }
        }
    }
    let mut id = vec![u32::MAX; faces_of.len()];
    let mut count = 0u32;
    for c in charts.chart_of_face.iter_mut() {
        let slot = &mut id[*c as usize];
        if *slot == u32::MAX {
            *slot = count;
            count += 1;
        }
        *c = *slot;
    }
    charts.count = count as usize;
}

/// The charts across manifold edges from the faces `small` (all of one
/// chart), longest shared length first, ties by id.
fn neighbours_by_shared_length(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    nb: &[[u32; 3]],
    chart_of_face: &[u32],
    small: &[u32],
) -> Vec<u32> {
    let own = chart_of_face[small[0] as usize];
    let mut shared: Vec<(u32, f32)> = Vec::new();
    for &f in small {
        let t = tris[f as usize];
        for k in 0..3 {
            let g = nb[f as usize][k];
            if g == NO_FACE || chart_of_face[g as usize] == own {
                continue;
            }
            let h = chart_of_face[g as usize];
            let len = (positions[t[(k + 1) % 3] as usize] - positions[t[k] as usize]).length();
            match shared.iter_mut().find(|e| e.0 == h) {
                Some(e) => e.1 += len,
                None => shared.push((h, len)),
            }
        }
    }
    shared.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
    shared.into_iter().map(|e| e.0).collect()
}

/// The host state of the chart made of `faces`.
fn host_of(
    tris: &[[u32; 3]],
    faces: &[u32],
    corner_st: &[[Vec2; 3]],
    face_area: impl Fn(u32) -> f32,
) -> Host {
    let (mut a3, mut a2) = (0.0f64, 0.0f64);
    let mut position: Vec<(u32, Vec2)> = Vec::with_capacity(3 * faces.len());
    for &f in faces {
        let st = &corner_st[f as usize];
        for (&v, &q) in tris[f as usize].iter().zip(st) {
            position.push((v, q));
        }
        a3 += face_area(f) as f64;
        a2 += 0.5 * signed_area2(st).abs() as f64;
    }
    // Stable: the first face holding a vertex gives its position.
    position.sort_by_key(|e| e.0);
    position.dedup_by_key(|e| e.0);
    position.shrink_to_fit();
    let density = if a3 > 0.0 && a2 > 0.0 {
        (a2 / a3).sqrt() as f32
    } else {
        1.0
    };
    // Cells about one mean edge long, as in the flatten-or-split check.
    let cell = density * (2.0 * a3 as f32 / faces.len().max(1) as f32).sqrt();
    // Degenerate faces cover no texel and are never tested.
    let grid = FrozenTriangleGrid::new(
        cell,
        corner_st,
        faces.iter().copied().filter(|&f| face_area(f) > 0.0),
    );
    let added = TriangleHash::new(grid.cell());
    Host {
        base_position: position,
        added_position: HashMap::new(),
        grid,
        added,
        density,
    }
}

/// Lays the faces `small` (flagged in `member`) out in the plane of chart
/// `h`, breadth first from the edges they share with it: per face, its
/// corners, or `None` when it would flip, overlap, or close onto the host
/// too distorted (nothing grows from such a face).
#[allow(clippy::too_many_arguments)]
fn unfold_into(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    nb: &[[u32; 3]],
    (chart_of_face, corner_st): (&[u32], &[[Vec2; 3]]),
    h: u32,
    small: &[u32],
    member: &[bool],
    host: &mut Host,
) -> Vec<Option<[Vec2; 3]>> {
    let local: HashMap<u32, usize> = small.iter().enumerate().map(|(i, &f)| (f, i)).collect();
    let mut layout: Vec<Option<[Vec2; 3]>> = vec![None; small.len()];
    let mut placed: HashMap<u32, Vec2> = HashMap::new();
    let mut queued = vec![false; small.len()];
    let mut queue: VecDeque<(u32, usize)> = VecDeque::new();
    for (i, &f) in small.iter().enumerate() {
        if let Some(k) = (0..3).find(|&k| {
            let g = nb[f as usize][k];
            g != NO_FACE && chart_of_face[g as usize] == h
        }) {
            queued[i] = true;
            queue.push_back((f, k));
        }
    }
    let mut fresh = TriangleHash::new(host.grid.cell());
    while let Some((f, k)) = queue.pop_front() {
        let Some((q, new_corner)) = lay_face(
            positions,
            tris[f as usize],
            k,
            &placed,
            (host, corner_st),
            &mut fresh,
        ) else {
            continue;
        };
        if let Some((v, c)) = new_corner {
            placed.insert(v, c);
        }
        layout[local[&f]] = Some(q);
        for &g in &nb[f as usize] {
            if g == NO_FACE || !member[g as usize] {
                continue;
            }
            let gi = local[&g];
            if queued[gi] {
                continue;
            }
            if let Some(back) = (0..3).find(|&m| nb[g as usize][m] == f) {
                queued[gi] = true;
                queue.push_back((g, back));
            }
        }
    }
    layout
}

/// A face laid out: its corners and, when it placed its third corner, that
/// vertex and where.
type LaidFace = ([Vec2; 3], Option<(u32, Vec2)>);

/// Lays the face `t` out on its edge `k` (corners `k`, `k + 1`, placed per
/// the host's or the freshly placed positions `placed`): its corners and,
/// when its third corner was not placed yet, that vertex and where it went.
/// `None` when it flips, overlaps a face of the host (with the charts'
/// corner coordinates its grid indexes) or of `fresh` (the faces laid out
/// so far, which it joins), or closes onto placed corners too distorted.
fn lay_face(
    positions: &[Vec3],
    t: [u32; 3],
    k: usize,
    placed: &HashMap<u32, Vec2>,
    (host, corner_st): (&mut Host, &[[Vec2; 3]]),
    fresh: &mut TriangleHash,
) -> Option<LaidFace> {
    let at = |v: u32| host.position(v).or_else(|| placed.get(&v).copied());
    let density = host.density;
    let p = t.map(|v| positions[v as usize]);
    let (a, b) = (at(t[k])?, at(t[(k + 1) % 3])?);
    let j = (k + 2) % 3;
    let closing = at(t[j]);
    let c = match closing {
        Some(c) => c,
        None => {
            // A similar copy of the 3-D triangle on the placed edge.
            let (e, d) = (p[(k + 1) % 3] - p[k], p[j] - p[k]);
            let l2 = e.length_squared();
            if l2.is_nan() || l2 <= 0.0 {
                return None;
            }
            let (x, y) = (e.dot(d) / l2, e.cross(d).length() / l2);
            a + (b - a) * x + (b - a).perp() * y
        }
    };
    let mut q = [Vec2::ZERO; 3];
    q[k] = a;
    q[(k + 1) % 3] = b;
    q[j] = c;
    if !q.iter().all(|v| v.is_finite()) {
        return None;
    }
    // Degenerate 3-D faces cover no texel and are not tested.
    if let Some((s1, s2)) = singular_values(p, &q) {
        if signed_area2(&q) <= 0.0 {
            return None;
        }
        if closing.is_some() {
            let r = (s1 * s2).sqrt() / density;
            let bound = MAX_CLOSING_STRETCH;
            if s1 > bound * s2 || r > bound || r * bound < 1.0 {
                return None;
            }
        }
        if host.overlaps(&q, corner_st) || fresh.overlaps(&q) {
            return None;
        }
        fresh.insert(q);
    }
    Some((q, closing.is_none().then_some((t[j], c))))
}
