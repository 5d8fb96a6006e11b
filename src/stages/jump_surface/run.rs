//! The phases of the `jump_surface` system around its kernels
//! ([`StageRun`]): the per-vertex scales and edge offsets, the synthesis
//! with its progress bar, the seam band and the refinement on it (with
//! their own bar and the analysis cache), the texture coordinates, and the
//! metrics.

use super::JumpSurfaceSettings;
use crate::kernels::coherent::CoherentSettings;
use crate::kernels::jump_maps::jump_map::{Boundary, JumpMap};
use crate::kernels::jump_maps::jump_surface::{
    BlendLayers, Matcher, REFINE_SETTINGS, SurfaceSynthOutput, SurfaceSynthSettings, corner_uvs,
    edge_offsets, height_scales, refine_band, refine_seams, refine_skipped,
    synthesize_surface_matched, texels_per_edge,
};
use crate::kernels::surface::frames::TangentFrame;
use crate::kernels::wei_levoy::wl_match::SynthesisLevel;
use crate::mesh::{PolyMesh, Topology};
use crate::progress::Progress;
use crate::world::{Exemplar, Metrics};
use glam::{Vec2, Vec3};
use std::time::Instant;

/// The topology of `mesh` and the texture-space offset of every edge at
/// the vertices' `scales`.
pub(super) fn offsets(
    mesh: &PolyMesh,
    frames: &[TangentFrame],
    scales: &[f32],
) -> (Topology, Vec<Vec2>) {
    let topo = {
        let _s = tracing::info_span!("topology").entered();
        Topology::build(mesh)
    };
    let offsets = {
        let _s = tracing::info_span!("edge_offsets").entered();
        edge_offsets(&mesh.positions, frames, scales, &topo)
    };
    (topo, offsets)
}

/// Per-corner texture coordinates and the blend layers; the side offsets
/// move into the compact blend layers.
pub(super) fn uvs(
    mesh: &PolyMesh,
    sides: Vec<Vec2>,
    texel: &[Vec2],
    map: &JumpMap,
) -> (Vec<Vec2>, BlendLayers) {
    let _s = tracing::info_span!("corner_uvs").entered();
    corner_uvs(mesh, sides, texel, (map.width(), map.height()))
}

/// One run of the stage: its settings, the exemplar, and the metrics it
/// records as stage `index`.
pub(super) struct StageRun<'a> {
    settings: &'a JumpSurfaceSettings,
    index: usize,
    exemplar: &'a Exemplar,
    metrics: &'a mut Metrics,
}

impl<'a> StageRun<'a> {
    /// A run of stage `index` with `settings`.
    pub fn new(
        settings: &'a JumpSurfaceSettings,
        index: usize,
        exemplar: &'a Exemplar,
        metrics: &'a mut Metrics,
    ) -> Self {
        Self {
            settings,
            index,
            exemplar,
            metrics,
        }
    }

    /// Per-vertex scale (pixels per world unit) on `mesh`: `scale`, or
    /// `texture_scale` (the run's) when it is 0, times the
    /// `scale_by_height` ramp.
    pub fn scales(&self, mesh: &PolyMesh, texture_scale: f32) -> Vec<f32> {
        let s = self.settings;
        let base = if s.scale > 0.0 {
            s.scale
        } else {
            texture_scale
        };
        let axis = Vec3::from(s.height_axis);
        height_scales(&mesh.positions, base, s.scale_by_height, axis)
    }

    /// The synthesis pass over the vertices (its own progress bar), with
    /// the matched choice when `choice` asks for it.
    pub fn synthesize(
        &self,
        topo: &Topology,
        offsets: &[Vec2],
        map: &JumpMap,
        seed: u64,
    ) -> SurfaceSynthOutput {
        let s = self.settings;
        let synth = SurfaceSynthSettings {
            patch_fraction: s.patch_fraction,
            boundary_fraction: s.boundary_fraction,
            tileable: map.boundary() == Boundary::Toroidal,
            order: s.order,
            seed,
            max_patch_area: s.max_patch_area,
            pixel_aligned: s.pixel_aligned,
        };
        let progress = Progress::new(topo.vertex_count() as u64, "jump_surface");
        let _finish = progress.finish_on_drop();
        let out = {
            let _s = tracing::info_span!("synthesize").entered();
            let matcher = (s.choice == "matched").then_some(Matcher {
                image: &self.exemplar.image,
                wrap: self.exemplar.wrap,
            });
            synthesize_surface_matched(topo, offsets, map, &synth, matcher, &progress)
        };
        progress.finish();
        out
    }

    /// The band the seam refinement corrects, when `refine = "seams"`
    /// applies to the mesh (uniform `scales`, about a pixel per edge);
    /// records the pixels per edge, and why the refinement was skipped.
    pub fn band(
        &mut self,
        scales: &[f32],
        offsets: &[Vec2],
        topo: &Topology,
        patch: &[u32],
    ) -> Option<Vec<bool>> {
        let uniform = scales.iter().all(|&s| s == scales[0]);
        // Exemplar pixels per edge, on average.
        let texels_per_edge = texels_per_edge(offsets);
        self.metrics
            .record(self.index, "texels_per_edge", texels_per_edge);
        if self.settings.refine != "seams" {
            return None;
        }
        if let Some(reason) = refine_skipped(uniform, texels_per_edge) {
            self.metrics.record(self.index, "refine_skipped", reason);
            return None;
        }
        (!scales.is_empty()).then(|| refine_band(topo, patch))
    }

    /// The seam refinement of `texel` on `band` at `scale` pixels per unit
    /// ([`refine_seams`], its appearance analysis in the analysis cache
    /// when `cache`), on its own progress bar: on a large fine mesh it can
    /// take longer than the synthesis. Records what it did.
    pub fn refine(
        &mut self,
        level: &SynthesisLevel,
        topo: &Topology,
        (scale, seed): (f32, u64),
        texel: &mut [Vec2],
        band: &[bool],
    ) -> Result<(), String> {
        let _s = tracing::info_span!("refine_seams").entered();
        let started = Instant::now();
        let kernel = CoherentSettings {
            scale,
            seed,
            wrap: self.exemplar.wrap,
            ..REFINE_SETTINGS
        };
        let store = crate::cache::DiskCache::if_enabled(self.settings.cache);
        let progress = Progress::new(0, "jump_surface seams");
        let _finish = progress.finish_on_drop();
        let refined = refine_seams(
            level,
            topo,
            &self.exemplar.image,
            &kernel,
            texel,
            band,
            store.as_ref().map(|s| s as _),
            &progress,
        )
        .map_err(|e| format!("refine: {e}"))?;
        let (metrics, index) = (&mut *self.metrics, self.index);
        metrics.record(index, "refine_band_vertices", refined.band_vertices);
        metrics.record(index, "refine_moved_vertices", refined.moved);
        metrics.record(index, "refine_energy", &refined.report.energy);
        metrics.record(index, "refine_visited", &refined.report.visited);
        let report = &refined.report;
        metrics.record(index, "refine_analysis_seconds", report.analysis_seconds);
        metrics.record(index, "refine_analysis_cached", report.analysis_cached);
        // With the appearance analysis (exemplar only) included.
        progress.finish();
        let seconds = started.elapsed().as_secs_f64();
        metrics.record(index, "refine_seconds", seconds);
        Ok(())
    }

    /// Records the synthesis's figures (`started` when the stage began);
    /// returns the mean scale (exemplar pixels per world unit).
    pub fn record(
        &mut self,
        out: &SurfaceSynthOutput,
        scales: &[f32],
        started: Instant,
        synthesis_seconds: f64,
    ) -> f32 {
        let (metrics, index) = (&mut *self.metrics, self.index);
        let secs = started.elapsed().as_secs_f64();
        let n = out.texel.len();
        metrics.record(index, "vertices", n);
        metrics.record(index, "vertices_per_second", n as f64 / secs.max(1e-9));
        metrics.record(index, "synthesis_seconds", synthesis_seconds);
        metrics.record(index, "jumps", out.jumps);
        metrics.record(index, "random_assignments", out.random_assignments);
        metrics.record(index, "matched_starts", out.matched_starts);
        metrics.record(index, "unfit_vertices", out.unfit);
        let mean_scale = scales.iter().sum::<f32>() / scales.len().max(1) as f32;
        metrics.record(index, "mean_scale_pixels_per_unit", mean_scale);
        mean_scale
    }
}
