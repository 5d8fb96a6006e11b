//! Per-component fallbacks for fields grown from user keys: a field that
//! spreads over edges from a few key vertices (diffusion, edge-path
//! blending, a sweep front) never reaches a connected component without a
//! key. [`fallback_keys`] places one automatic key on each such component
//! so that the field there is grown the same way, and smooth, instead of
//! being filled vertex by vertex; [`one_per_component`] picks one start
//! vertex per component for a front; [`chain_components`] offsets a scalar
//! so that it continues from one component to the next.
//!
//! The connected components are [`Topology::components`] (over edges;
//! an isolated vertex is a component of its own).
//!
//! [`Topology::components`]: crate::mesh::Topology::components

use glam::{Mat3, Vec3};

/// The connected components of a mesh: how many, and the component id of
/// every vertex (`0..count`), as [`crate::mesh::Topology::components`]
/// returns them.
#[derive(Clone, Copy, Debug)]
pub struct Components<'a> {
    /// Number of components.
    pub count: usize,
    /// Component id per vertex.
    pub of_vertex: &'a [u32],
}

/// An automatic key: a vertex and the direction the field takes there.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FallbackKey {
    /// The component it stands for.
    pub component: u32,
    /// The component's vertex nearest its centroid (lowest id on ties).
    pub vertex: u32,
    /// Unit tangent direction at `vertex`.
    pub direction: Vec3,
}

/// Below this `|projected| / |up|` (the sine of the angle between `up` and
/// the normal, about 0.6°) a projected direction is taken as degenerate:
/// the direction would be decided by rounding.
const DEGENERATE_SINE: f32 = 1e-2;

/// `v` projected onto the tangent plane of `n` and normalised, or `None`
/// when less than [`DEGENERATE_SINE`] of it is left.
fn tangent(v: Vec3, n: Vec3) -> Option<Vec3> {
    let len = v.length();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    let n = n.try_normalize().unwrap_or(Vec3::ZERO);
    let p = v - n * n.dot(v);
    (p.length() > DEGENERATE_SINE * len).then(|| p.normalize())
}

/// The direction of largest spread of `points` (the principal axis of
/// their covariance, by power iteration started from the covariance's
/// longest column; the sign is made to have a non-negative largest
/// coordinate so the result is deterministic). `None` for fewer than two
/// distinct points.
pub fn principal_axis(points: &[Vec3]) -> Option<Vec3> {
    if points.len() < 2 {
        return None;
    }
    let mean = points.iter().copied().sum::<Vec3>() / points.len() as f32;
    let mut cov = Mat3::ZERO;
    for &p in points {
        let d = p - mean;
        cov += Mat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    let mut v = [cov.x_axis, cov.y_axis, cov.z_axis]
        .into_iter()
        .max_by(|a, b| a.length_squared().total_cmp(&b.length_squared()))?
        .try_normalize()?;
    for _ in 0..64 {
        v = (cov * v).try_normalize()?;
    }
    let largest = if v.x.abs() >= v.y.abs() && v.x.abs() >= v.z.abs() {
        v.x
    } else if v.y.abs() >= v.z.abs() {
        v.y
    } else {
        v.z
    };
    Some(if largest < 0.0 { -v } else { v })
}

/// The component ids that hold none of `seeded` (vertex ids; ids out of
/// range are ignored), ascending.
pub fn unseeded_components(components: Components, seeded: &[u32]) -> Vec<u32> {
    let mut has = vec![false; components.count];
    for &v in seeded {
        if let Some(&c) = components.of_vertex.get(v as usize) {
            has[c as usize] = true;
        }
    }
    (0..components.count as u32)
        .filter(|&c| !has[c as usize])
        .collect()
}

/// One automatic key per component that holds none of the `seeded`
/// vertices (ascending component id).
///
/// The key sits at the component's vertex nearest its centroid (the mean
/// of its vertex positions; lowest id on ties). Its direction is
/// `fallback_up` projected onto that vertex's tangent plane (`normals`);
/// where that is degenerate (`fallback_up` within about 0.6° of the
/// normal, or zero), the component's [`principal_axis`] projected, and
/// failing that any unit vector perpendicular to the normal.
///
/// Preconditions: `positions`, `normals` and `components.of_vertex` have
/// one entry per vertex; component ids are below `components.count`.
/// Linear in the vertex count, however many components there are.
pub fn fallback_keys(
    positions: &[Vec3],
    normals: &[Vec3],
    components: Components,
    seeded: &[u32],
    fallback_up: Vec3,
) -> Vec<FallbackKey> {
    let missing = unseeded_components(components, seeded);
    if missing.is_empty() {
        return Vec::new();
    }
    let of = components.of_vertex;
    // Centroids in f64: a large component far from the origin would lose
    // the centroid's low bits in an f32 sum.
    let mut sum = vec![[0.0f64; 3]; components.count];
    let mut count = vec![0u32; components.count];
    for (v, p) in positions.iter().enumerate() {
        let c = of[v] as usize;
        sum[c][0] += p.x as f64;
        sum[c][1] += p.y as f64;
        sum[c][2] += p.z as f64;
        count[c] += 1;
    }
    let centroid = |c: usize| {
        let k = count[c].max(1) as f64;
        Vec3::new(
            (sum[c][0] / k) as f32,
            (sum[c][1] / k) as f32,
            (sum[c][2] / k) as f32,
        )
    };
    let mut nearest: Vec<Option<(f32, u32)>> = vec![None; components.count];
    for (v, p) in positions.iter().enumerate() {
        let c = of[v] as usize;
        let d = p.distance_squared(centroid(c));
        if nearest[c].is_none_or(|(best, _)| d < best) {
            nearest[c] = Some((d, v as u32));
        }
    }
    // Vertices per component (counting sort), built only if a component
    // needs its principal axis, so that many components cost one pass.
    let mut members: Option<(Vec<u32>, Vec<u32>)> = None;
    let mut members_of = |c: u32| -> Vec<Vec3> {
        let (start, order) = members.get_or_insert_with(|| {
            let mut start = vec![0u32; components.count + 1];
            for &k in of {
                start[k as usize + 1] += 1;
            }
            for k in 0..components.count {
                start[k + 1] += start[k];
            }
            let mut next = start.clone();
            let mut order = vec![0u32; of.len()];
            for (v, &k) in of.iter().enumerate() {
                order[next[k as usize] as usize] = v as u32;
                next[k as usize] += 1;
            }
            (start, order)
        });
        let range = start[c as usize] as usize..start[c as usize + 1] as usize;
        order[range]
            .iter()
            .map(|&v| positions[v as usize])
            .collect()
    };
    missing
        .into_iter()
        .filter_map(|c| {
            let (_, vertex) = nearest[c as usize]?;
            let n = normals[vertex as usize];
            let direction = tangent(fallback_up, n)
                .or_else(|| principal_axis(&members_of(c)).and_then(|a| tangent(a, n)))
                .unwrap_or_else(|| {
                    n.try_normalize()
                        .map_or(Vec3::X, |n| n.any_orthonormal_vector())
                });
            Some(FallbackKey {
                component: c,
                vertex,
                direction,
            })
        })
        .collect()
}

/// Spreads each key's direction over its whole component: one vector per
/// vertex, the direction of the key on its component, zero on components
/// without one. A component with a single key and nothing else acting on
/// it has that key's direction everywhere (before projection), so this is
/// what blending the key with itself would give, in one pass instead of a
/// search from the key.
///
/// Preconditions: `components.of_vertex` has one entry per vertex.
pub fn spread_over_components(components: Components, keys: &[FallbackKey]) -> Vec<Vec3> {
    let mut by_component = vec![Vec3::ZERO; components.count];
    for k in keys {
        if let Some(slot) = by_component.get_mut(k.component as usize) {
            *slot = k.direction;
        }
    }
    components
        .of_vertex
        .iter()
        .map(|&c| by_component.get(c as usize).copied().unwrap_or(Vec3::ZERO))
        .collect()
}

/// The first of `candidates` (vertex ids, in order of preference; ids out
/// of range are ignored) in each component that has one, in the order
/// chosen: a front started from these starts once per component.
pub fn one_per_component(components: Components, candidates: &[u32]) -> Vec<u32> {
    let mut taken = vec![false; components.count];
    let mut out = Vec::new();
    for &v in candidates {
        if let Some(&c) = components.of_vertex.get(v as usize)
            && !taken[c as usize]
        {
            taken[c as usize] = true;
            out.push(v);
        }
    }
    out
}

/// Offsets `values` per component so that they continue from one
/// component to the next: `first` (a component id) keeps its values, then
/// every other component in ascending id is shifted so that its smallest
/// value equals the largest value so far. Sorting by the result visits the
/// components one after the other, each in its own order. With one
/// component nothing changes.
///
/// Preconditions: `values` and `components.of_vertex` have one entry per
/// vertex. Non-finite values are left as they are and ignored.
pub fn chain_components(values: &mut [f32], components: Components, first: Option<u32>) {
    if components.count < 2 {
        return;
    }
    let mut lo = vec![f32::INFINITY; components.count];
    let mut hi = vec![f32::NEG_INFINITY; components.count];
    for (&v, &c) in values.iter().zip(components.of_vertex) {
        if v.is_finite() {
            lo[c as usize] = lo[c as usize].min(v);
            hi[c as usize] = hi[c as usize].max(v);
        }
    }
    let first = first.filter(|&c| (c as usize) < components.count);
    let order = first
        .into_iter()
        .chain((0..components.count as u32).filter(|&c| Some(c) != first));
    let mut shift = vec![0.0f32; components.count];
    let mut end: Option<f32> = None;
    for c in order {
        let c = c as usize;
        if !lo[c].is_finite() {
            continue;
        }
        shift[c] = end.map_or(0.0, |e| e - lo[c]);
        end = Some(hi[c] + shift[c]);
    }
    for (v, &c) in values.iter_mut().zip(components.of_vertex) {
        if v.is_finite() {
            *v += shift[c as usize];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_go_to_unseeded_components_at_their_central_vertex() {
        // Two segments of three points along x; component 1 has no key.
        let positions = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(10.0, 0.0, 0.0),
            Vec3::new(11.0, 0.0, 0.0),
            Vec3::new(12.0, 0.0, 0.0),
        ];
        let normals = [Vec3::Z; 6];
        let of = [0, 0, 0, 1, 1, 1];
        let comps = Components {
            count: 2,
            of_vertex: &of,
        };
        let keys = fallback_keys(&positions, &normals, comps, &[0], Vec3::new(0.0, 2.0, 1.0));
        assert_eq!(keys.len(), 1);
        assert_eq!((keys[0].component, keys[0].vertex), (1, 4));
        assert!((keys[0].direction - Vec3::Y).length() < 1e-6);
        // `up` along the normal: the principal axis (x) instead.
        let keys = fallback_keys(&positions, &normals, comps, &[1], Vec3::Z);
        assert!((keys[0].direction - Vec3::X).length() < 1e-5, "{keys:?}");
        assert!(fallback_keys(&positions, &normals, comps, &[2, 5], Vec3::Y).is_empty());
    }

    #[test]
    fn many_components_with_degenerate_up_take_their_own_axes() {
        // 1000 two-point components, alternately along x and y, `up` along
        // every normal: each needs its principal axis (one pass in all).
        let mut positions = Vec::new();
        let mut of = Vec::new();
        for c in 0..1000u32 {
            let base = Vec3::new(0.0, 0.0, c as f32 * 10.0);
            let axis = if c % 2 == 0 { Vec3::X } else { Vec3::Y };
            positions.extend([base, base + axis]);
            of.extend([c, c]);
        }
        let normals = vec![Vec3::Z; positions.len()];
        let comps = Components {
            count: 1000,
            of_vertex: &of,
        };
        let keys = fallback_keys(&positions, &normals, comps, &[], Vec3::Z);
        assert_eq!(keys.len(), 1000);
        for k in &keys {
            let want = if k.component % 2 == 0 {
                Vec3::X
            } else {
                Vec3::Y
            };
            assert!((k.direction - want).length() < 1e-5, "{k:?}");
        }
        let spread = spread_over_components(comps, &keys[..2]);
        assert_eq!(&spread[..4], &[Vec3::X, Vec3::X, Vec3::Y, Vec3::Y]);
        assert!(spread[4..].iter().all(|v| *v == Vec3::ZERO));
    }

    #[test]
    fn one_start_per_component_in_order_of_preference() {
        let of = [0, 0, 1, 1, 2];
        let comps = Components {
            count: 3,
            of_vertex: &of,
        };
        assert_eq!(one_per_component(comps, &[1, 0, 3, 2, 9, 4]), vec![1, 3, 4]);
    }

    #[test]
    fn chained_values_continue_from_the_first_component() {
        let of = [0, 0, 1, 1, 2];
        let comps = Components {
            count: 3,
            of_vertex: &of,
        };
        let mut v = [0.0, 1.0, -2.0, 3.0, 0.5];
        chain_components(&mut v, comps, Some(1));
        // Component 1 first (unchanged), then 0 from 3, then 2 from 4.
        assert_eq!(v, [3.0, 4.0, -2.0, 3.0, 4.0]);
    }
}
