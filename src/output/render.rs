//! TEMPORARY STUB (replaced by helper-c's merge).
use crate::image::{Image, sample::Wrap};
#[derive(Default)]
pub struct RenderOptions;
pub enum Shading<'a> {
    Plain,
    VertexColours {
        values: &'a [f32],
        channels: usize,
    },
    CornerUvs {
        uvs: &'a [glam::Vec2],
        texture: &'a Image,
        wrap: Wrap,
    },
}
pub fn render_views(
    _m: &crate::mesh::PolyMesh,
    _s: &Shading,
    size: u32,
    _o: &RenderOptions,
) -> Vec<Image> {
    vec![Image::new(size, size, 3)]
}
pub fn write_previews(
    dir: &std::path::Path,
    prefix: &str,
    images: &[Image],
) -> Result<Vec<std::path::PathBuf>, super::OutputError> {
    let mut v = vec![];
    for (i, im) in images.iter().enumerate() {
        let p = dir.join(format!("{prefix}_{i}.png"));
        super::write_png(&p, im)?;
        v.push(p);
    }
    Ok(v)
}
