//! TEMPORARY STUB (replaced by helper-b's merge).
use crate::image::{Image, sample::Wrap};
pub struct EnergySettings {
    pub neighbourhood: u32,
    pub samples: usize,
    pub seed: u64,
}
pub struct EnergyStats {
    pub mean: f32,
    pub p90: f32,
    pub samples: usize,
}
pub enum SurfaceSignal<'a> {
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
pub fn histogram_wasserstein(_a: &Image, _b: &Image) -> Vec<f32> {
    vec![]
}
pub fn surface_texture_energy(
    _m: &crate::mesh::PolyMesh,
    _t: &crate::mesh::Topology,
    _f: &[crate::kernels::frames::TangentFrame],
    _s: f32,
    _sig: &SurfaceSignal,
    _e: &Image,
    _st: &EnergySettings,
) -> EnergyStats {
    EnergyStats {
        mean: 0.0,
        p90: 0.0,
        samples: 0,
    }
}
