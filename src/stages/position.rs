//! Positions in stage configs. A point is written either in world
//! coordinates, `at = [x, y, z]`, or relative to the bounding box of the
//! mesh it refers to, `at_bbox = [u, v, w]` with each coordinate in `[0, 1]`
//! (0 = the box's minimum, 1 = its maximum on that axis). A bounding-box
//! position survives scaling and moving the mesh, so one config fits a
//! mesh in any units.
//!
//! Used by `orientation` (anchors, singularities), `diffuse_orientation`
//! (keys, sweep anchor) and `tangent_field` (constraints). Which mesh the
//! box is taken from is the stage's choice and is written in its docs: the
//! active mesh, or the coarsest level of a hierarchy.

use glam::Vec3;

/// Checks a position pair as written in a config, without a mesh: at most
/// one of `at` and `at_bbox`, every coordinate finite, `at_bbox` in
/// `[0, 1]`. Whether one of them is required depends on the spec (a
/// `vertex` or `face` may stand in for both), so the caller checks that.
///
/// # Errors
/// A message naming the offending key (`at` or `at_bbox`) and what is
/// allowed.
pub fn check(at: Option<[f32; 3]>, at_bbox: Option<[f32; 3]>) -> Result<(), String> {
    if at.is_some() && at_bbox.is_some() {
        return Err("give either `at` (world coordinates) or `at_bbox` (fractions of the bounding box), not both".into());
    }
    if let Some(p) = at
        && p.iter().any(|c| !c.is_finite())
    {
        return Err(format!("`at` = {p:?} must be finite"));
    }
    if let Some(p) = at_bbox
        && p.iter()
            .any(|c| !(c.is_finite() && (0.0..=1.0).contains(c)))
    {
        return Err(format!(
            "`at_bbox` = {p:?} must have every coordinate in [0, 1] (0 = bounding-box minimum, 1 = maximum)"
        ));
    }
    Ok(())
}

/// The world point of `at` or `at_bbox` on a mesh whose bounding box is
/// `bbox` (`(min, max)`, `None` for a mesh without vertices); `Ok(None)`
/// when neither is given (the spec names a vertex or face instead).
///
/// `at_bbox = [u, v, w]` maps to `min + (max − min) · (u, v, w)`, so a flat
/// axis (min = max) gives its one value whatever the fraction.
///
/// # Errors
/// Everything [`check`] refuses, and `at_bbox` on a mesh without vertices.
pub fn resolve(
    at: Option<[f32; 3]>,
    at_bbox: Option<[f32; 3]>,
    bbox: Option<(Vec3, Vec3)>,
) -> Result<Option<Vec3>, String> {
    check(at, at_bbox)?;
    match (at, at_bbox) {
        (Some(p), _) => Ok(Some(Vec3::from(p))),
        (None, Some(f)) => {
            let (lo, hi) = bbox.ok_or("`at_bbox` needs a mesh with vertices")?;
            Ok(Some(lo + (hi - lo) * Vec3::from(f)))
        }
        (None, None) => Ok(None),
    }
}

/// How a position was written, for messages: `at [x, y, z]` or
/// `at_bbox [u, v, w]`.
pub fn describe(at: Option<[f32; 3]>, at_bbox: Option<[f32; 3]>) -> String {
    match (at, at_bbox) {
        (Some(p), _) => format!("at {p:?}"),
        (None, Some(f)) => format!("at_bbox {f:?}"),
        (None, None) => "with no position".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bbox_fractions_map_onto_the_box() {
        let bbox = Some((Vec3::new(-1.0, 0.0, 10.0), Vec3::new(1.0, 4.0, 10.0)));
        let p = resolve(None, Some([0.5, 0.25, 1.0]), bbox).unwrap();
        assert_eq!(p, Some(Vec3::new(0.0, 1.0, 10.0)));
        let p = resolve(Some([7.0, 8.0, 9.0]), None, bbox).unwrap();
        assert_eq!(p, Some(Vec3::new(7.0, 8.0, 9.0)));
        assert_eq!(resolve(None, None, bbox).unwrap(), None);
    }

    #[test]
    fn bad_positions_name_the_key() {
        let both = check(Some([0.0; 3]), Some([0.0; 3])).unwrap_err();
        assert!(
            both.contains("`at`") && both.contains("`at_bbox`"),
            "{both}"
        );
        let out = check(None, Some([2.0, 0.0, 0.0])).unwrap_err();
        assert!(out.contains("`at_bbox`") && out.contains("[0, 1]"), "{out}");
        let nan = check(None, Some([f32::NAN, 0.0, 0.0])).unwrap_err();
        assert!(nan.contains("`at_bbox`"), "{nan}");
        let inf = check(Some([f32::INFINITY, 0.0, 0.0]), None).unwrap_err();
        assert!(inf.contains("`at`"), "{inf}");
        assert!(resolve(None, Some([0.5; 3]), None).is_err());
    }
}
