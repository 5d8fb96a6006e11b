//! TEMPORARY STUB (replaced by helper-a's merge).
pub fn write_obj(
    dir: &std::path::Path,
    stem: &str,
    _m: &crate::mesh::PolyMesh,
    _u: Option<&[glam::Vec2]>,
    _t: Option<&crate::image::Image>,
    _c: Option<(&[f32], usize)>,
) -> Result<Vec<std::path::PathBuf>, super::OutputError> {
    let p = dir.join(format!("{stem}.obj"));
    super::write_bytes_atomic(&p, b"")?;
    Ok(vec![p])
}
