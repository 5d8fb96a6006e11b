//! User orientation fields on vertices (Zelinka & Garland 2004 §6.1; Praun et
//! al. 2000 §3.2): interpolation of a few anchor "up" vectors, and sources and
//! sinks (singular points the field flows out of or into).

use crate::kernels::surface::component_fallback::{
    Components, fallback_keys, spread_over_components,
};
use crate::kernels::surface::frames::TangentFrame;
use crate::kernels::surface::geodesic::{dijkstra, nearest_vertex};
use crate::mesh::Topology;
use glam::Vec3;

/// An "up" vector prescribed near a point.
#[derive(Clone, Copy, Debug)]
pub struct Anchor {
    /// Where (the nearest vertex takes it).
    pub at: Vec3,
    /// The texture's up direction there (world space, projected).
    pub up: Vec3,
}

/// A singular point of the field.
#[derive(Clone, Copy, Debug)]
pub struct Singularity {
    /// Where.
    pub at: Vec3,
    /// +1 for a source (up points away), −1 for a sink (up points toward it).
    pub sign: f32,
    /// Relative strength: at `strength` bounding-box diagonals from it, its
    /// pull has the length of one anchor's vector.
    pub strength: f32,
}

/// The up field from anchors and singularities, one unit tangent frame per
/// vertex.
///
/// Anchors blend by inverse squared edge-path distance (Dijkstra from each
/// anchor's nearest vertex), so each anchor dominates near itself and the
/// field varies smoothly between them. Singularities add
/// `sign · strength · D · (x − p) / |x − p|²` (a 2-D point-charge field,
/// decaying with distance; `D` the bounding-box diagonal of `positions`, so
/// the balance of anchors and singularities does not depend on the mesh's
/// units). Each vertex's sum is projected onto its tangent plane; where it
/// vanishes, `fallback_up` is used.
///
/// An anchor reaches only the connected component it is on. A vertex no
/// anchor reaches takes `unreached[v]` in place of the blend (when given;
/// e.g. the direction of an automatic key spread over its component,
/// `component_fallback::spread_over_components`, which is what one anchor
/// alone on that component would give without a search per component).
///
/// Preconditions: `topo` was built for the mesh; `normals` and `unreached`
/// (if given) have one entry per vertex.
pub fn up_field(
    positions: &[Vec3],
    normals: &[Vec3],
    topo: &Topology,
    anchors: &[Anchor],
    unreached: Option<&[Vec3]>,
    singularities: &[Singularity],
    fallback_up: Vec3,
) -> Vec<TangentFrame> {
    let n = positions.len();
    let mut field = vec![Vec3::ZERO; n];
    let scale = bbox_diagonal(positions).max(1e-12);
    let mut total = vec![0.0f32; n];
    if !anchors.is_empty() {
        let mut weighted = vec![Vec3::ZERO; n];
        for a in anchors {
            let Some(src) = nearest_vertex(positions, a.at) else {
                continue;
            };
            let d = dijkstra(positions, topo, &[src], f32::INFINITY);
            for v in 0..n {
                if d[v].is_finite() {
                    let rel = d[v] / scale;
                    let w = 1.0 / (rel * rel + 1e-6);
                    weighted[v] += a.up * w;
                    total[v] += w;
                }
            }
        }
        for v in 0..n {
            if total[v] > 0.0 {
                field[v] += weighted[v] / total[v];
            }
        }
    }
    if let Some(unreached) = unreached {
        for ((f, &t), &u) in field.iter_mut().zip(&total).zip(unreached) {
            if t == 0.0 {
                *f += u;
            }
        }
    }
    for s in singularities {
        for (v, f) in field.iter_mut().enumerate() {
            let r = positions[v] - s.at;
            let d2 = r.length_squared().max(1e-12);
            *f += r * (s.sign * s.strength * scale / d2);
        }
    }
    field
        .iter()
        .zip(normals)
        .map(|(&f, &nrm)| {
            let projected = f - nrm * nrm.dot(f);
            if projected.length_squared() > 1e-20 {
                TangentFrame::from_up(nrm, projected)
            } else {
                TangentFrame::from_up(nrm, fallback_up)
            }
        })
        .collect()
}

/// [`up_field`] where every connected component that no anchor is on gets
/// one automatic anchor ([`fallback_keys`]: at its vertex nearest its
/// centroid, `up` projected there), since the anchors blend by edge-path
/// distance and never reach it. The automatic anchor is spread over its
/// component directly (one anchor alone gives its own vector everywhere;
/// no search per component, however many there are). Without anchors the
/// field is the singularities', which reach every component. Returns the
/// frames and the number of components that got an automatic anchor.
///
/// Preconditions: as [`up_field`].
pub fn up_field_with_fallback(
    positions: &[Vec3],
    normals: &[Vec3],
    topo: &Topology,
    anchors: &[Anchor],
    singularities: &[Singularity],
    up: Vec3,
) -> (Vec<TangentFrame>, usize) {
    let mut fallback_components = 0;
    let mut unreached = None;
    if !anchors.is_empty() {
        let anchored: Vec<u32> = anchors
            .iter()
            .filter_map(|a| nearest_vertex(positions, a.at))
            .collect();
        let (count, of_vertex) = topo.components();
        let components = Components {
            count,
            of_vertex: &of_vertex,
        };
        let automatic = fallback_keys(positions, normals, components, &anchored, up);
        fallback_components = automatic.len();
        if !automatic.is_empty() {
            unreached = Some(spread_over_components(components, &automatic));
        }
    }
    let frames = up_field(
        positions,
        normals,
        topo,
        anchors,
        unreached.as_deref(),
        singularities,
        up,
    );
    (frames, fallback_components)
}

fn bbox_diagonal(positions: &[Vec3]) -> f32 {
    let Some(first) = positions.first() else {
        return 0.0;
    };
    let (lo, hi) = positions
        .iter()
        .fold((*first, *first), |(lo, hi), &p| (lo.min(p), hi.max(p)));
    (hi - lo).length()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::PolyMesh;

    fn grid(n: usize) -> PolyMesh {
        let p = (0..n * n)
            .map(|i| Vec3::new((i % n) as f32, (i / n) as f32, 0.0))
            .collect();
        let mut faces = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = (y * n + x) as u32;
                faces.push([i, i + 1, i + n as u32 + 1, i + n as u32]);
            }
        }
        PolyMesh::from_polygons(p, faces.iter().map(|f| &f[..]))
    }

    #[test]
    fn anchor_is_reproduced_at_its_vertex() {
        let m = grid(8);
        let t = Topology::build(&m);
        let normals = m.vertex_normals();
        let anchors = [
            Anchor {
                at: Vec3::ZERO,
                up: Vec3::X,
            },
            Anchor {
                at: Vec3::new(7.0, 7.0, 0.0),
                up: Vec3::Y,
            },
        ];
        let f = up_field(&m.positions, &normals, &t, &anchors, None, &[], Vec3::Y);
        assert!((f[0].t - Vec3::X).length() < 1e-2, "{:?}", f[0].t);
        assert!((f[63].t - Vec3::Y).length() < 1e-2, "{:?}", f[63].t);
        // Halfway, a blend of the two.
        let mid = f[7 * 8].t; // corner (0, 7): equidistant
        assert!(mid.x > 0.3 && mid.y > 0.3, "{mid:?}");
    }

    #[test]
    fn source_points_away_and_sink_toward() {
        let m = grid(9);
        let t = Topology::build(&m);
        let normals = m.vertex_normals();
        let centre = Vec3::new(4.0, 4.0, 0.0);
        let src = [Singularity {
            at: centre,
            sign: 1.0,
            strength: 1.0,
        }];
        let f = up_field(&m.positions, &normals, &t, &[], None, &src, Vec3::Y);
        let v = 4 * 9 + 8; // (8, 4): to the right of the centre
        assert!(f[v].t.x > 0.99, "{:?}", f[v].t);
        let sink = [Singularity {
            at: centre,
            sign: -1.0,
            strength: 1.0,
        }];
        let f = up_field(&m.positions, &normals, &t, &[], None, &sink, Vec3::Y);
        assert!(f[v].t.x < -0.99, "{:?}", f[v].t);
    }
}
