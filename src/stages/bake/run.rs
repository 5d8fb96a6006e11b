//! The bake itself: the source mesh's atlas ([`lay_out_with_progress`]),
//! then the result baked into it by what it holds (the order of the
//! stage's `//!`), then the asset and its metrics.

use super::{Bake, BakeBlend, BakeColours, BakeSettings, MeshData, MeshQuery, PasteQuery};
use crate::config::params::to_json;
use crate::image::Image;
use crate::image::sample::Wrap;
use crate::kernels::atlas::bake::{
    AtlasFrames, BakeTarget, BlendUvSource, ChannelKind, ChannelMap, ContributionSource,
    CoordinateSource, LappedSource, VertexColourSource, bake_channels_with_progress,
};
use crate::kernels::atlas::bake_layout::{
    AtlasLayout, blend_statistics, fan_triangles, lay_out_with_progress, merge_lookups,
    paste_triangles, patch_placements, progress_plan, single_layers,
};
use crate::kernels::atlas::triplanar::{TriplanarSource, crease_corner_normals};
use crate::kernels::atlas::{AtlasDistortion, AtlasSettings, UvAtlas};
use crate::kernels::jump_maps::jump_surface::Blend;
use crate::kernels::wei_levoy::retile::SurfaceProjector;
use crate::mesh::PolyMesh;
use crate::progress::Progress;
use crate::stage::Stage;
use crate::world::*;
use bevy_ecs::prelude::*;
use bevy_ecs::query::ROQueryItem;
use glam::{Vec2, Vec3};

/// One item of [`MeshQuery`].
type MeshItem<'a> = ROQueryItem<'a, 'a, MeshData>;

/// One item of a query of [`PasteQuery`].
type PasteItem<'a> = ROQueryItem<'a, 'a, PasteQuery>;

/// Metrics of the bake, by name.
pub(super) type MetricList = Vec<(&'static str, serde_json::Value)>;

/// The images a bake samples.
pub(super) struct BakeInputs<'a> {
    pub exemplar: &'a Exemplar,
    pub channels: Option<&'a ExemplarChannels>,
    pub patches: &'a [Image],
    /// Per patch, the exemplar pixel of its top-left pixel (lapped).
    pub origins: &'a [[i64; 2]],
    /// A triplanar projection (stage `triplanar`), baked before any other
    /// result.
    pub triplanar: Option<&'a TriplanarProjection>,
    /// The run's exemplar texels per world unit, for coordinates of a
    /// result that records no per-vertex scale.
    pub texels_per_unit: f32,
}

/// The exemplar maps baked beside the colour, with their roles.
struct ExemplarMaps<'a> {
    roles: Vec<&'static str>,
    maps: Vec<ChannelMap<'a>>,
}

impl<'a> ExemplarMaps<'a> {
    /// Every exemplar map present: each goes through the same
    /// contributions as the colour.
    fn of(channels: Option<&'a ExemplarChannels>) -> Self {
        let mut out = Self {
            roles: Vec::new(),
            maps: Vec::new(),
        };
        if let Some(ch) = channels {
            for (role, img, kind) in [
                ("normal", &ch.normal, ChannelKind::Normal),
                ("roughness", &ch.roughness, ChannelKind::Scalar),
                ("height", &ch.height, ChannelKind::Scalar),
            ] {
                if let Some(image) = img {
                    out.roles.push(role);
                    out.maps.push(ChannelMap { image, kind });
                }
            }
        }
        out
    }
}

/// A baked result: how it was read, its colour, its maps (those of
/// [`ExemplarMaps`], in order) and why maps are missing or flat.
struct Baked {
    method: &'static str,
    colour: Image,
    maps: Vec<Image>,
    note: &'static str,
}

/// Builds the atlas of `mesh` (the source mesh) and bakes the result.
pub(super) fn bake_world(
    settings: &BakeSettings,
    source: Entity,
    active: Entity,
    inputs: &BakeInputs,
    mesh: &PolyMesh,
    meshes: &MeshQuery,
    pastes: &Query<PasteQuery>,
) -> Result<(BakedAsset, MetricList), String> {
    let _span = tracing::info_span!("bake", size = settings.size).entered();
    let tris = fan_triangles(mesh);
    let atlas_settings = AtlasSettings {
        size: settings.size,
        normal_cone_deg: settings.normal_cone as f32,
        padding_px: settings.padding,
    };
    let mut maps = ExemplarMaps::of(inputs.channels);
    let progress = Progress::new(0, Bake::KIND);
    let _finish = progress.finish_on_drop();
    progress.plan(progress_plan(tris.len(), settings.size, maps.maps.len()));
    let layout = lay_out_with_progress(&mesh.positions, &tris, &atlas_settings, &progress)
        .map_err(|e| e.to_string())?;
    let Ok(result) = meshes.get(active) else {
        return Err("the active mesh has no geometry".into());
    };
    let mut lapped: Vec<PasteItem> = pastes.iter().filter(|p| p.0.0 == active).collect();
    lapped.sort_by_key(|p| *p.1);
    let job = BakeJob {
        settings,
        inputs,
        mesh,
        tris: &tris,
        corner_uvs: &layout.atlas.corner_uvs,
        target: BakeTarget {
            corner_uvs: &layout.atlas.corner_uvs,
            texel_face: &layout.texel_face,
            size: settings.size,
            padding_px: settings.padding,
        },
        on_source: active == source,
        progress: &progress,
    };
    let baked = job.bake(result, &lapped, &mut maps)?;
    progress.finish();
    let AtlasLayout {
        atlas,
        distortion,
        texel_face,
    } = layout;
    drop(texel_face);
    let record = record(&baked, &atlas, &distortion, &maps.roles);
    Ok((asset(mesh, tris, atlas, baked, &maps.roles), record))
}

/// The bake's metrics: how the result was read, the atlas and its
/// distortion, the maps.
fn record(
    baked: &Baked,
    atlas: &UvAtlas,
    d: &AtlasDistortion,
    roles: &[&'static str],
) -> MetricList {
    let mut record = vec![
        ("bake_method", to_json(&baked.method)),
        ("atlas_charts", to_json(&atlas.charts.count)),
        ("atlas_fill", to_json(&atlas.fill)),
        ("atlas_texels_per_unit", to_json(&atlas.texels_per_unit)),
        ("atlas_mean_stretch", to_json(&d.mean_stretch)),
        ("atlas_density_ratio_p95", to_json(&d.density_ratio_p95)),
        ("baked_maps", to_json(&roles)),
    ];
    if !baked.note.is_empty() {
        record.push(("baked_maps_note", to_json(&baked.note)));
    }
    record
}

/// The asset: the source mesh's fan triangulation `tris` with the atlas
/// coordinates and the baked images.
fn asset(
    mesh: &PolyMesh,
    tris: Vec<[u32; 3]>,
    atlas: UvAtlas,
    baked: Baked,
    roles: &[&'static str],
) -> BakedAsset {
    // A triangle mesh is its own fan triangulation: the asset refers to
    // the world's (`BakedAsset::on_source`) instead of holding a copy.
    let (tri_mesh, on_source) = if mesh.is_triangle_mesh() {
        drop(tris);
        (PolyMesh::new(), true)
    } else {
        (
            PolyMesh::from_triangles(mesh.positions.clone(), &tris),
            false,
        )
    };
    BakedAsset {
        mesh: tri_mesh,
        on_source,
        // In place: the per-triangle array becomes the per-corner one.
        uvs: atlas.corner_uvs.into_flattened(),
        colour: baked.colour,
        maps: roles
            .iter()
            .zip(baked.maps)
            .map(|(role, img)| (role.to_string(), img))
            .collect(),
    }
}

/// One bake into the source mesh's atlas.
struct BakeJob<'a> {
    settings: &'a BakeSettings,
    inputs: &'a BakeInputs<'a>,
    /// The source mesh and its fan triangles.
    mesh: &'a PolyMesh,
    tris: &'a [[u32; 3]],
    /// Per triangle, its corners' atlas coordinates.
    corner_uvs: &'a [[Vec2; 3]],
    target: BakeTarget<'a>,
    /// Whether the result lies on the source mesh itself.
    on_source: bool,
    progress: &'a Progress,
}

impl BakeJob<'_> {
    /// The result, by what it holds (first match): a triplanar projection,
    /// lapped pastes, per-corner UVs, vertex colours.
    fn bake(
        &self,
        result: MeshItem,
        lapped: &[PasteItem],
        maps: &mut ExemplarMaps,
    ) -> Result<Baked, String> {
        let (_, colours, uvs, blend, ..) = result;
        if let Some(tp) = self.inputs.triplanar {
            Ok(self.triplanar(tp, maps))
        } else if !lapped.is_empty() {
            self.lapped(lapped, maps)
        } else if blend.is_some() || uvs.is_some() {
            self.corner_uvs(uvs, blend, maps)
        } else if let Some(c) = colours {
            self.vertex_colours(result, c, maps)
        } else {
            Err("the result has nothing to bake: no vertex colours, per-corner UVs, lapped pastes or triplanar projection; put `bake` after a synthesis stage or `triplanar`".into())
        }
    }

    /// Atlas frames (24 bytes per triangle): the angles of normal maps and
    /// the vertex-colour and lapped sources.
    fn frames(&self) -> AtlasFrames {
        AtlasFrames::new(&self.mesh.positions, self.tris, self.corner_uvs)
    }

    /// The exemplar, then the lapped patches: what contributions index.
    fn textures(&self) -> Vec<&Image> {
        std::iter::once(&self.inputs.exemplar.image)
            .chain(self.inputs.patches)
            .collect()
    }

    /// A projection evaluated per texel; the exemplar's maps follow only a
    /// projection of the exemplar itself (the same pixels).
    fn triplanar(&self, tp: &TriplanarProjection, maps: &mut ExemplarMaps) -> Baked {
        let exemplar = &self.inputs.exemplar.image;
        let frames = self.frames();
        let normals = crease_corner_normals(&self.mesh.positions, self.tris);
        let src = TriplanarSource {
            positions: &self.mesh.positions,
            normals: &normals,
            tris: self.tris,
            frames: &frames,
            texels_per_unit: tp.texels_per_unit,
            sharpness: tp.sharpness,
            image_size: Vec2::new(tp.image.width as f32, tp.image.height as f32),
        };
        let same_image = tp.image.width == exemplar.width
            && tp.image.height == exemplar.height
            && tp.image.data == exemplar.data;
        let mut note = "";
        if !maps.maps.is_empty() && !same_image {
            note = "the triplanar image is not the exemplar: maps are not baked";
            maps.maps.clear();
            maps.roles.clear();
        }
        let (colour, maps) = bake_channels_with_progress(
            &self.target,
            &src as &dyn ContributionSource,
            &[&tp.image],
            Wrap::Repeat,
            &maps.maps,
            &[],
            self.progress,
        );
        Baked {
            method: "triplanar",
            colour,
            maps,
            note,
        }
    }

    /// Lapped pastes on the source mesh, composited in paste order; maps
    /// follow the pastes where every patch records its exemplar origin.
    fn lapped(&self, lapped: &[PasteItem], maps: &ExemplarMaps) -> Result<Baked, String> {
        if !self.on_source {
            return Err("the lapped pastes lie on a mesh other than the loaded one; bake needs them on the original mesh (no retile before lapped_paste)".into());
        }
        if !self.mesh.is_triangle_mesh() {
            return Err("lapped pastes need a triangle mesh".into());
        }
        let mut records = Vec::with_capacity(lapped.len());
        for (_, _, texture, faces, puvs) in lapped {
            let list = paste_triangles(&faces.0, &puvs.0)
                .ok_or("a paste's texture coordinates do not match its faces")?;
            records.push((texture.0, list));
        }
        let (patches, exemplar) = (self.inputs.patches, self.inputs.exemplar);
        let frames = self.frames();
        let src = LappedSource::new(&self.mesh.positions, self.tris, &frames, &records, patches);
        let size = (exemplar.image.width, exemplar.image.height);
        let placements = patch_placements(patches, self.inputs.origins, size);
        let note = if !maps.maps.is_empty() && placements.is_empty() {
            "lapped patches record no exemplar origin: maps are flat/neutral"
        } else {
            ""
        };
        let (colour, maps) = bake_channels_with_progress(
            &self.target,
            &src as &dyn ContributionSource,
            &self.textures(),
            exemplar.wrap,
            &maps.maps,
            &placements,
            self.progress,
        );
        Ok(Baked {
            method: "lapped_pastes",
            colour,
            maps,
            note,
        })
    }

    /// Per-corner UVs on the source mesh, with the jump-map blend layers
    /// where `jump_surface` made them.
    fn corner_uvs(
        &self,
        uvs: Option<&CornerUvs>,
        blend: Option<&BlendUvs>,
        maps: &ExemplarMaps,
    ) -> Result<Baked, String> {
        if !self.on_source {
            return Err("the per-corner UVs lie on a mesh other than the loaded one; bake needs them on the original mesh".into());
        }
        let mesh = self.mesh;
        // Single-base UVs as three equal layers; the compact blend layers
        // are read in place (72 bytes per triangle expanded).
        let single: Vec<[[Vec2; 3]; 3]>;
        let (method, layers): (&'static str, Blend) = match (blend, uvs) {
            (Some(b), _) if b.0.fits(mesh) => {
                ("jump_map_blend", Blend::Compact { layers: &b.0, mesh })
            }
            (_, Some(u)) if u.0.len() == mesh.corner_count() => {
                single = single_layers(mesh, &u.0);
                ("corner_uvs", (&single).into())
            }
            _ => return Err("the result's UVs do not match the mesh's corners".into()),
        };
        // A blend baking no normal map reads no frames.
        let has_normal_map = self.inputs.channels.is_some_and(|ch| ch.normal.is_some());
        let src = if has_normal_map {
            BlendUvSource::new(&mesh.positions, self.tris, &self.frames(), layers)
        } else {
            BlendUvSource::without_angles(layers)
        };
        let (colour, maps) = self.bake_blended(&src, maps);
        Ok(Baked {
            method,
            colour,
            maps,
            note: "",
        })
    }

    /// Vertex colours on the active mesh (retiled, subdivided or the
    /// original): each texel's surface point projected onto the result,
    /// read through the exemplar coordinates where recorded
    /// (`colours = "coordinates"`/`"auto"`), else the colours
    /// interpolated.
    fn vertex_colours(
        &self,
        (result, _, _, _, source_texels, result_frames, vertex_scale): MeshItem,
        c: &VertexColours,
        maps: &ExemplarMaps,
    ) -> Result<Baked, String> {
        let n = result.0.vertex_count();
        if c.channels == 0 || c.values.len() != c.channels * n {
            return Err("the result's vertex colours do not match its vertices".into());
        }
        // Neighbouring texels project near one another: walk from the last.
        let projector = SurfaceProjector::with_adjacency(&result.0);
        let result_tris: Vec<[u32; 3]> = result
            .0
            .triangulated()
            .faces()
            .map(|f| [f[0], f[1], f[2]])
            .collect();
        let image = &self.inputs.exemplar.image;
        let size = Vec2::new(image.width as f32, image.height as f32);
        let source_uv: Option<Vec<Vec2>> = source_texels
            .filter(|t| t.0.len() == n)
            .map(|t| t.0.iter().map(|p| *p / size).collect());
        let frame_s: Option<Vec<Vec3>> = result_frames
            .filter(|f| f.0.len() == n)
            .map(|f| f.0.iter().map(|fr| fr.s).collect());
        let frames = self.frames();
        let src = VertexColourSource {
            positions: &self.mesh.positions,
            tris: self.tris,
            frames: &frames,
            projector: &projector,
            result_tris: &result_tris,
            colours: &c.values,
            channels: c.channels,
            source_uv: source_uv.as_deref(),
            frame_s: frame_s.as_deref(),
        };
        // The exemplar coordinates, continued per texel, where recorded.
        let coordinates = match (source_texels, result_frames) {
            (Some(t), Some(f)) if t.0.len() == n && f.0.len() == n => Some((&t.0, &f.0)),
            _ => None,
        };
        let one_scale = [self.inputs.texels_per_unit];
        let texels_per_unit: &[f32] = match vertex_scale {
            Some(s) if s.0.len() == n => &s.0,
            _ => &one_scale,
        };
        let mut note = "";
        let (method, source): (_, Box<dyn ContributionSource + '_>) = match (
            self.settings.colours,
            coordinates,
        ) {
            (BakeColours::Vertex, _) | (BakeColours::Auto, None) => {
                if !maps.maps.is_empty() && source_uv.is_none() {
                    note = "the result records no source texels: maps are flat/neutral";
                }
                ("vertex_colours", Box::new(src))
            }
            (BakeColours::Coordinates, None) => {
                return Err("colours = \"coordinates\" needs the exemplar coordinate and tangent frame of every result vertex, which this result does not record; allowed here: \"vertex\" or \"auto\"".into());
            }
            (_, Some((sources, synthesis_frames))) => (
                "coordinates",
                Box::new(CoordinateSource {
                    surface: src,
                    result_positions: &result.0.positions,
                    sources,
                    synthesis_frames,
                    texels_per_unit,
                    exemplar_size: size,
                }),
            ),
        };
        let (colour, maps) = self.bake_blended(source.as_ref(), maps);
        Ok(Baked {
            method,
            colour,
            maps,
            note,
        })
    }

    /// Bakes exemplar look-ups from `source`, those that agree merged and
    /// the others blended as `blend` and `merge_within` say.
    fn bake_blended(
        &self,
        source: &dyn ContributionSource,
        maps: &ExemplarMaps,
    ) -> (Image, Vec<Image>) {
        let exemplar = self.inputs.exemplar;
        let preserve = self.settings.blend == BakeBlend::PreserveVariance;
        let statistics = blend_statistics(preserve, &exemplar.image, exemplar.wrap);
        let merged = merge_lookups(
            source,
            self.settings.merge_within,
            statistics.as_ref(),
            (&exemplar.image, exemplar.wrap),
        );
        bake_channels_with_progress(
            &self.target,
            merged.as_ref().map_or(source, |m| m),
            &self.textures(),
            exemplar.wrap,
            &maps.maps,
            &[],
            self.progress,
        )
    }
}
