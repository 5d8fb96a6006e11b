//! TEMPORARY STUB (replaced by helper-a's merge).
use super::{MeshError, PolyMesh};
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    pub merge_duplicates: bool,
}
#[derive(Clone, Debug, Default)]
pub struct LoadReport;
impl LoadReport {
    pub fn summary(&self) -> String {
        String::new()
    }
}
pub fn load_mesh(
    path: &std::path::Path,
    _o: &LoadOptions,
) -> Result<(PolyMesh, LoadReport), MeshError> {
    Err(MeshError::NoFaces {
        path: path.into(),
        detail: String::new(),
    })
}
