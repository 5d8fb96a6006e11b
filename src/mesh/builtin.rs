//! TEMPORARY STUB (replaced by helper-a's merge).
use super::{MeshError, PolyMesh};
#[derive(Clone, Debug, Default, serde::Deserialize)]
#[serde(default)]
pub struct BuiltinOptions {
    pub subdivisions: u32,
}
pub fn builtin_mesh(name: &str, _o: &BuiltinOptions) -> Result<PolyMesh, MeshError> {
    let t = 1.0f32;
    let p = vec![
        glam::Vec3::new(t, t, t),
        glam::Vec3::new(t, -t, -t),
        glam::Vec3::new(-t, t, -t),
        glam::Vec3::new(-t, -t, t),
    ];
    if name != "icosphere" {
        return Err(MeshError::Builtin {
            name: name.into(),
            message: "stub".into(),
        });
    }
    Ok(PolyMesh::from_triangles(
        p,
        &[[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]],
    ))
}
