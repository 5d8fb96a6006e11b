//! TEMPORARY STUB (replaced by helper-a's merge).
pub struct MeshInfo;
impl MeshInfo {
    pub fn compute(_m: &super::PolyMesh) -> Self {
        MeshInfo
    }
}
impl std::fmt::Display for MeshInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "stub")
    }
}
