//! Chart segmentation with a bounded normal cone (step 1 of the module
//! docs), and the flatten-or-split loop that makes every chart a valid flat
//! layout.

use super::lscm::{flatten_chart, project_chart};
use super::merge::absorb_small_charts;
use super::raster::flat_and_disjoint;
use super::{AtlasSettings, Charts};
use crate::progress::Progress;
use glam::{Vec2, Vec3};
use std::collections::VecDeque;

/// No face across an edge.
pub const NO_FACE: u32 = u32::MAX;

/// Per face, the face across each of its edges (`k` joins corners `k` and
/// `k + 1`) when exactly two faces share that edge and traverse it in
/// opposite directions; [`NO_FACE`] at boundaries, non-manifold edges and
/// orientation flips.
pub fn manifold_neighbours(tris: &[[u32; 3]]) -> Vec<[u32; 3]> {
    // [min, max, face], sorted: equal edges are adjacent (12 bytes a
    // side: a million-vertex scan has 5.4 M of them).
    let mut sides: Vec<[u32; 3]> = Vec::with_capacity(3 * tris.len());
    for (f, t) in tris.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if a != b {
                sides.push([a.min(b), a.max(b), f as u32]);
            }
        }
    }
    sides.sort_unstable();
    // The edge's side in face `f` and whether it runs from min to max (a
    // pair of sides of two faces names each face's side once).
    let side = |s: [u32; 3]| {
        let t = tris[s[2] as usize];
        let k = (0..3)
            .find(|&k| t[k].min(t[(k + 1) % 3]) == s[0] && t[k].max(t[(k + 1) % 3]) == s[1])
            .unwrap_or(0);
        (s[2], k, t[k] < t[(k + 1) % 3])
    };
    let mut nb = vec![[NO_FACE; 3]; tris.len()];
    let mut i = 0;
    while i < sides.len() {
        let mut j = i + 1;
        while j < sides.len() && sides[j][0] == sides[i][0] && sides[j][1] == sides[i][1] {
            j += 1;
        }
        if j - i == 2 && sides[i][2] != sides[i + 1][2] {
            let (x, y) = (side(sides[i]), side(sides[i + 1]));
            if x.2 != y.2 {
                nb[x.0 as usize][x.1] = y.0;
                nb[y.0 as usize][y.1] = x.0;
            }
        }
        i = j;
    }
    nb
}

/// Most faces a chart grows to. Flattening a chart costs more than linear
/// time in its faces (conjugate gradients; halving when invalid), and the
/// charts of a flat region grow with the mesh's density: the cap keeps the
/// atlas linear in the faces (a 92 k-vertex scan's charts took 45× the
/// time of a 10 k one without it, though much of that was charts failing
/// the overlap test through f32 rounding, since fixed in `lscm`). 16 384
/// rather than 4 096: fewer, larger charts pack with less gutter (messy
/// scan, 2048²: fill 0.53 → 0.56 at 20 k vertices, 0.47 → 0.49 at 400 k)
/// at about the same atlas time. Breadth-first growth keeps a capped chart
/// a compact disc.
pub const MAX_CHART_FACES: usize = 16384;

/// Segments the triangles into flattened charts. Seeds are taken flattest
/// first (least bent to their neighbours), so charts spread widest before
/// the normal cone (or [`MAX_CHART_FACES`]) stops them.
pub fn segment_charts(positions: &[Vec3], tris: &[[u32; 3]], settings: &AtlasSettings) -> Charts {
    segment_charts_with_progress(positions, tris, settings, &Progress::hidden())
}

/// [`segment_charts`], advancing `progress` by the faces of each chart once
/// it is flattened.
pub fn segment_charts_with_progress(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    settings: &AtlasSettings,
    progress: &Progress,
) -> Charts {
    let _span = tracing::debug_span!("segment_charts", faces = tris.len()).entered();
    let fc = tris.len();
    let normals: Vec<Vec3> = tris
        .iter()
        .map(|t| {
            let p = t.map(|v| positions[v as usize]);
            (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero()
        })
        .collect();
    let nb = manifold_neighbours(tris);
    let cos_cone = settings.normal_cone_deg.clamp(0.0, 89.0).to_radians().cos();
    let bend: Vec<f32> = (0..fc)
        .map(|f| {
            nb[f]
                .iter()
                .map(|&g| {
                    if g == NO_FACE {
                        1.0
                    } else {
                        1.0 - normals[f].dot(normals[g as usize])
                    }
                })
                .sum()
        })
        .collect();
    let mut seeds: Vec<u32> = (0..fc as u32).collect();
    seeds.sort_by(|&a, &b| {
        bend[a as usize]
            .total_cmp(&bend[b as usize])
            .then(a.cmp(&b))
    });
    drop(bend);

    let mut chart_of_face = vec![u32::MAX; fc];
    let mut corner_st = vec![[Vec2::ZERO; 3]; fc];
    let mut count = 0u32;
    let mut scratch = Scratch::new(positions.len(), fc);
    let mut queue = VecDeque::new();
    for seed in seeds {
        if chart_of_face[seed as usize] != u32::MAX {
            continue;
        }
        // Grow in breadth-first order; `faces` keeps that order.
        let n0 = normals[seed as usize];
        let mut faces = vec![seed];
        chart_of_face[seed as usize] = count;
        queue.clear();
        queue.push_back(seed);
        while let Some(f) = queue.pop_front() {
            for &g in &nb[f as usize] {
                if g == NO_FACE || chart_of_face[g as usize] != u32::MAX {
                    continue;
                }
                let ng = normals[g as usize];
                let degenerate = ng == Vec3::ZERO;
                if faces.len() < MAX_CHART_FACES
                    && n0 != Vec3::ZERO
                    && (degenerate || ng.dot(n0) >= cos_cone)
                {
                    chart_of_face[g as usize] = count;
                    faces.push(g);
                    queue.push_back(g);
                }
            }
        }
        // Flatten, splitting until every part is valid.
        let grown = faces.len() as u64;
        let mut stack = vec![faces];
        let mut first = true;
        while let Some(part) = stack.pop() {
            let normal = if n0 != Vec3::ZERO {
                n0
            } else {
                part.iter()
                    .map(|&f| normals[f as usize])
                    .sum::<Vec3>()
                    .normalize_or(Vec3::Z)
            };
            match flatten_valid(positions, tris, &normals, &part, normal, &mut scratch) {
                Some(st) => {
                    // The first valid part keeps the chart's id; every
                    // further part of a split chart gets a new one.
                    let id = if first {
                        first = false;
                        count
                    } else {
                        count += 1;
                        count
                    };
                    for (&f, s) in part.iter().zip(st) {
                        chart_of_face[f as usize] = id;
                        corner_st[f as usize] = s;
                    }
                }
                None => {
                    let half = part.len() / 2;
                    for piece in [&part[..half], &part[half..]] {
                        stack.extend(edge_components(piece, &nb, &mut scratch));
                    }
                }
            }
        }
        count += 1;
        progress.inc(grown);
    }
    // The small charts' move needs none of the growth's arrays.
    drop((normals, scratch, queue));
    let mut charts = Charts {
        count: count as usize,
        chart_of_face,
        corner_st,
    };
    absorb_small_charts(positions, tris, &nb, &mut charts);
    charts
}

/// Reusable per-vertex and per-face marks.
pub(crate) struct Scratch {
    /// Local index of each mesh vertex in the current chart (`u32::MAX`).
    pub local: Vec<u32>,
    /// Per face, a stamp marking membership of the current set.
    pub face_mark: Vec<u32>,
    pub stamp: u32,
}

impl Scratch {
    pub(crate) fn new(vertices: usize, faces: usize) -> Self {
        Self {
            local: vec![u32::MAX; vertices],
            face_mark: vec![0; faces],
            stamp: 0,
        }
    }
}

/// The edge-connected components of `faces`, each in breadth-first order.
pub(crate) fn edge_components(
    faces: &[u32],
    nb: &[[u32; 3]],
    scratch: &mut Scratch,
) -> Vec<Vec<u32>> {
    scratch.stamp += 2;
    let (member, done) = (scratch.stamp - 1, scratch.stamp);
    for &f in faces {
        scratch.face_mark[f as usize] = member;
    }
    let mut out = Vec::new();
    for &s in faces {
        if scratch.face_mark[s as usize] != member {
            continue;
        }
        scratch.face_mark[s as usize] = done;
        let mut comp = vec![s];
        let mut i = 0;
        while i < comp.len() {
            let f = comp[i];
            i += 1;
            for &g in &nb[f as usize] {
                if g != NO_FACE && scratch.face_mark[g as usize] == member {
                    scratch.face_mark[g as usize] = done;
                    comp.push(g);
                }
            }
        }
        out.push(comp);
    }
    out
}

/// Flattens the chart `faces` by least-squares conformal maps, else by
/// projection; `None` when both flip or overlap a face. Coordinates are
/// scaled so the chart's flat area equals its surface area.
fn flatten_valid(
    positions: &[Vec3],
    tris: &[[u32; 3]],
    normals: &[Vec3],
    faces: &[u32],
    normal: Vec3,
    scratch: &mut Scratch,
) -> Option<Vec<[Vec2; 3]>> {
    let skip: Vec<bool> = faces
        .iter()
        .map(|&f| normals[f as usize] == Vec3::ZERO)
        .collect();
    let area3: f32 = faces
        .iter()
        .map(|&f| {
            let p = tris[f as usize].map(|v| positions[v as usize]);
            0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length()
        })
        .sum();
    let cell = (2.0 * area3 / faces.len().max(1) as f32).sqrt();
    let candidates: [Option<Vec<[Vec2; 3]>>; 2] = [
        (faces.len() > 1)
            .then(|| flatten_chart(positions, tris, faces, normal, &mut scratch.local))
            .flatten(),
        Some(project_chart(
            positions,
            tris,
            faces,
            normal,
            &mut scratch.local,
        )),
    ];
    for mut st in candidates.into_iter().flatten() {
        if faces.len() == 1 {
            // One triangle: lay it out exactly in its own plane.
            st[0] = exact_triangle(tris[faces[0] as usize].map(|v| positions[v as usize]));
        }
        let area2: f32 = st
            .iter()
            .map(|t| 0.5 * super::raster::signed_area2(t).abs())
            .sum();
        if area2 > 0.0 && area3 > 0.0 {
            let k = (area3 / area2).sqrt();
            for t in &mut st {
                for p in t.iter_mut() {
                    *p *= k;
                }
            }
        }
        if faces.len() == 1 || flat_and_disjoint(&st, &skip, cell) {
            return Some(st);
        }
    }
    None
}

/// A triangle laid out isometrically, counter-clockwise.
fn exact_triangle(p: [Vec3; 3]) -> [Vec2; 3] {
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let l = e1.length();
    if l <= 0.0 {
        return [Vec2::ZERO, Vec2::X * e2.length(), Vec2::ZERO];
    }
    let x = e1 / l;
    let y = (e2 - x * e2.dot(x)).length();
    [Vec2::ZERO, Vec2::new(l, 0.0), Vec2::new(e2.dot(x), y)]
}
