//! TEMPORARY STUB (replaced by helper-a's merge).
pub fn write_ply(
    path: &std::path::Path,
    _m: &crate::mesh::PolyMesh,
    _c: Option<(&[f32], usize)>,
) -> Result<(), super::OutputError> {
    super::write_bytes_atomic(path, b"ply\n")
}
