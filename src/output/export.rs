//! Writes what the `export` stage prepared.

use super::{OutputError, write_atomic, write_png};
use crate::mesh::PolyMesh;
use crate::progress::Progress;
use crate::world::{ExportJob, PasteExport};
use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Writes the job's files into `dir`; returns their paths. Progress (the
/// stage `export`) counts images and formats, the one being written the
/// part: a PLY or OBJ of a million vertices takes seconds.
///
/// [`write_export_titled`] with the job's stem as the title of `view.html`.
pub fn write_export(dir: &Path, job: &ExportJob) -> Result<Vec<PathBuf>, OutputError> {
    write_export_titled(dir, job, &job.stem)
}

/// [`write_export`]; `title` (the run's config, say) captions `view.html`,
/// the 3D view written beside the GLB (format `glb`).
pub fn write_export_titled(
    dir: &Path,
    job: &ExportJob,
    title: &str,
) -> Result<Vec<PathBuf>, OutputError> {
    let mut files = Vec::new();
    let items = job.images.len() + job.formats.len() + usize::from(job.original.is_some());
    let progress = Progress::new(items as u64, "export");
    let _finish = progress.finish_on_drop();
    for (name, image) in &job.images {
        progress.set_part(name);
        let path = dir.join(name);
        super::write_png(&path, image)?;
        files.push(path);
        progress.inc(1);
    }
    // The stem whose `.obj` holds the baked triangles, once written: formats
    // `obj` (blended) and `baked` write the same mesh, so the second copies.
    let mut baked_stem: Option<String> = None;
    let mut write_baked = |dir: &Path, stem: String, image: &crate::image::Image| {
        let files = match &baked_stem {
            Some(from) => super::obj::copy_obj(dir, from, &stem, image),
            None => write_baked_triangles(dir, &stem, &job.mesh, image),
        };
        baked_stem.get_or_insert(stem);
        files
    };
    for format in &job.formats {
        progress.set_part(format);
        let _span = tracing::debug_span!("write_format", format = format.as_str()).entered();
        match format.as_str() {
            "ply" => {
                let path = dir.join(format!("{}.ply", job.stem));
                let colours = job
                    .colours
                    .as_ref()
                    .or(job.corner_colours.as_ref())
                    .map(|c| (c.values.as_slice(), c.channels));
                super::ply::write_ply(&path, &job.mesh, colours, &[])?;
                files.push(path);
            }
            "obj" => {
                let (uvs, texture) = match &job.uvs {
                    Some((uv, tex)) => (Some(uv.as_slice()), Some(tex)),
                    None => (None, None),
                };
                let colours = job
                    .colours
                    .as_ref()
                    .map(|c| (c.values.as_slice(), c.channels));
                match (&job.baked, job.obj_blended) {
                    (Some(image), true) => {
                        // The blended result as `<stem>.obj`; the raw
                        // coordinates for a shader that blends itself.
                        files.extend(write_baked(dir, job.stem.clone(), image)?);
                        let stem = format!("{}_corner_uvs", job.stem);
                        files.extend(super::obj::write_obj(
                            dir, &stem, &job.mesh, uvs, texture, colours,
                        )?);
                    }
                    _ => files.extend(super::obj::write_obj(
                        dir, &job.stem, &job.mesh, uvs, texture, colours,
                    )?),
                }
            }
            "baked" => {
                if let Some(image) = &job.baked {
                    files.extend(write_baked(dir, format!("{}_baked", job.stem), image)?);
                }
            }
            "glb" => {
                if let Some(asset) = &job.baked_asset {
                    let path = dir.join(format!("{}.glb", job.stem));
                    super::gltf::write_glb(&path, asset)?;
                    let view = super::viewer::write_view(dir, &path, title)?;
                    files.push(path);
                    files.push(view);
                }
            }
            "baked_obj" => {
                if let Some(asset) = &job.baked_asset {
                    files.extend(write_baked_obj(dir, &format!("{}_atlas", job.stem), asset)?);
                }
            }
            "pastes" => {
                if let Some(pastes) = &job.pastes {
                    files.extend(write_pastes(dir, &job.stem, &job.mesh, pastes)?);
                }
            }
            "plane" => {
                if let Some(plane) = &job.plane {
                    let path = dir.join("plane.png");
                    write_png(&path, &plane.image)?;
                    files.push(path);
                    let path = dir.join("plane_sources.png");
                    let pixels = super::plane_source_pixels(plane);
                    let bytes =
                        super::encode_png_rgb16(plane.image.width, plane.image.height, &pixels)?;
                    super::write_bytes_atomic(&path, &bytes)?;
                    files.push(path);
                }
            }
            "preview" => {
                files.extend(super::render::write_previews(
                    dir,
                    "preview",
                    &job.previews,
                )?);
            }
            _ => {}
        }
        progress.inc(1);
    }
    // The result mapped back onto the original input mesh (`map_back`).
    if let Some((mesh, colours, previews)) = &job.original {
        progress.set_part("original");
        if job.formats.iter().any(|f| f == "ply") {
            let path = dir.join(format!("{}_original.ply", job.stem));
            let colours = (colours.values.as_slice(), colours.channels);
            super::ply::write_ply(&path, mesh, Some(colours), &[])?;
            files.push(path);
        }
        files.extend(super::render::write_previews(
            dir,
            "original_preview",
            previews,
        )?);
        progress.inc(1);
    }
    progress.finish();
    Ok(files)
}

/// Writes `mesh` with `image`, its per-triangle atlas ([`baked_mesh`]), as
/// `<stem>.obj/.mtl/.png`.
fn write_baked_triangles(
    dir: &Path,
    stem: &str,
    mesh: &PolyMesh,
    image: &crate::image::Image,
) -> Result<Vec<PathBuf>, OutputError> {
    let (mesh, uvs) = baked_mesh(mesh, image.width);
    super::obj::write_obj(dir, stem, &mesh, Some(uvs.as_slice()), Some(image), None)
}

/// The mesh of format `baked`: `mesh` fan-triangulated, with the atlas
/// coordinates of every triangle's cell in a `size`² atlas
/// ([`atlas_corner_uvs`](crate::kernels::atlas::bake_triangles::atlas_corner_uvs)).
pub fn baked_mesh(mesh: &PolyMesh, size: u32) -> (PolyMesh, Vec<glam::Vec2>) {
    let triangles = mesh.triangulated();
    let n = triangles.face_count();
    let uvs = (0..n)
        .flat_map(|t| crate::kernels::atlas::bake_triangles::atlas_corner_uvs(t, n, size))
        .collect();
    (triangles, uvs)
}

/// The `.obj` text of a lapped texture for runtime pasting (Praun et al.
/// 2000 §4): the mesh's vertices once, then one group per paste in paste
/// order, each with its own texture coordinates (`vt u (1 − v)`, OBJ's
/// bottom-up convention) and material `patch_K`. Drawn in file order with
/// alpha blending, later groups on top, the groups reproduce the lapped
/// texture.
pub fn encode_pastes_obj(
    mesh: &PolyMesh,
    pastes: &PasteExport,
    mtl: &str,
) -> Result<String, OutputError> {
    check_pastes(mesh, pastes)?;
    let mut bytes = Vec::new();
    stream_pastes_obj(&mut bytes, mesh, pastes, mtl).map_err(|e| OutputError::Encode {
        what: "pastes OBJ".into(),
        message: format!("writing into memory: {e}"),
    })?;
    String::from_utf8(bytes).map_err(|e| OutputError::Encode {
        what: "pastes OBJ".into(),
        message: e.to_string(),
    })
}

/// Checks that every paste names faces of `mesh` and holds one texture
/// coordinate per corner of them, as [`stream_pastes_obj`] needs.
pub fn check_pastes(mesh: &PolyMesh, pastes: &PasteExport) -> Result<(), OutputError> {
    for (i, paste) in pastes.pastes.iter().enumerate() {
        let mut used = 0usize;
        for &f in &paste.faces {
            if f as usize >= mesh.face_count() {
                return Err(OutputError::Encode {
                    what: "pastes OBJ".into(),
                    message: format!(
                        "paste {i} names face {f}, but the mesh has {} faces",
                        mesh.face_count()
                    ),
                });
            }
            used += mesh.face_corners(f as usize).len();
        }
        if used != paste.uvs.len() {
            return Err(OutputError::Encode {
                what: "pastes OBJ".into(),
                message: format!(
                    "paste {i} has {} texture coordinates for {used} corners",
                    paste.uvs.len()
                ),
            });
        }
    }
    Ok(())
}

/// Writes the text of [`encode_pastes_obj`] to `w` line by line.
/// Preconditions: [`check_pastes`] accepted `pastes` (else this may panic).
pub fn stream_pastes_obj(
    w: &mut dyn Write,
    mesh: &PolyMesh,
    pastes: &PasteExport,
    mtl: &str,
) -> std::io::Result<()> {
    let faces: usize = pastes.pastes.iter().map(|p| p.faces.len()).sum();
    let draws = faces as f64 / mesh.face_count().max(1) as f64;
    writeln!(
        w,
        "# written by surfsynth: a lapped texture for runtime pasting\n\
         # {} pastes; draw the groups in order with alpha blending (each face is drawn {draws:.2} times on average)\n\
         mtllib {mtl}",
        pastes.pastes.len()
    )?;
    super::obj::write_positions(w, mesh, None)?;
    super::obj::write_vertex_normals(w, mesh)?;
    let mut line = Vec::new();
    for paste in &pastes.pastes {
        for uv in &paste.uvs {
            line.clear();
            line.extend_from_slice(b"vt");
            super::obj::push_floats(&mut line, [uv.x, 1.0 - uv.y]);
            line.push(b'\n');
            w.write_all(&line)?;
        }
    }
    let mut vt = 1usize;
    for (i, paste) in pastes.pastes.iter().enumerate() {
        writeln!(w, "g paste_{i:05}\nusemtl patch_{}\ns 1", paste.texture)?;
        for &f in &paste.faces {
            w.write_all(b"f")?;
            for &v in mesh.face(f as usize) {
                write!(w, " {}/{}/{}", v + 1, vt, v + 1)?;
                vt += 1;
            }
            w.write_all(b"\n")?;
        }
    }
    Ok(())
}

/// Writes `dir/STEM_pastes.obj`, `dir/STEM_pastes.mtl` (materials
/// `patch_K` with colour and alpha maps) and `dir/STEM_patch_K.png` (RGBA
/// texture patches); returns the paths, the `.obj` first (written last).
pub fn write_pastes(
    dir: &Path,
    stem: &str,
    mesh: &PolyMesh,
    pastes: &PasteExport,
) -> Result<Vec<PathBuf>, OutputError> {
    let obj_path = dir.join(format!("{stem}_pastes.obj"));
    let mtl_name = format!("{stem}_pastes.mtl");
    check_pastes(mesh, pastes)?;
    let mut files = vec![obj_path.clone()];
    let mut mtl = String::from("# written by surfsynth: lapped-texture patches (straight alpha)\n");
    for (k, img) in pastes.textures.iter().enumerate() {
        let png = format!("{stem}_patch_{k}.png");
        let path = dir.join(&png);
        write_png(&path, img)?;
        files.push(path);
        let _ = writeln!(
            mtl,
            "newmtl patch_{k}\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\nmap_Kd {png}\nmap_d {png}"
        );
    }
    let mtl_path = dir.join(&mtl_name);
    write_atomic(&mtl_path, |w| w.write_all(mtl.as_bytes()))?;
    files.push(mtl_path);
    write_atomic(&obj_path, |w| stream_pastes_obj(w, mesh, pastes, &mtl_name))?;
    Ok(files)
}

/// Writes the `bake` stage's asset as `dir/STEM.obj` (the original mesh,
/// triangulated, with atlas coordinates), `STEM.mtl` and `STEM.png` (colour),
/// plus `STEM_normal.png`, `STEM_roughness.png` and `STEM_height.png` when
/// those maps were baked (their MTL lines: [`non_colour_map_lines`]). Returns
/// the paths, the `.obj` first (written last).
pub fn write_baked_obj(
    dir: &Path,
    stem: &str,
    asset: &crate::world::BakedAsset,
) -> Result<Vec<PathBuf>, OutputError> {
    let obj_path = dir.join(format!("{stem}.obj"));
    let mtl_name = format!("{stem}.mtl");
    super::obj::check_obj(&asset.mesh, Some(&asset.uvs), None)?;
    let mut files = vec![obj_path.clone()];
    let png = format!("{stem}.png");
    write_png(&dir.join(&png), &asset.colour)?;
    files.push(dir.join(&png));
    let mut mtl = super::obj::encode_mtl(&png);
    for (role, img) in &asset.maps {
        let name = format!("{stem}_{role}.png");
        let Some(line) = non_colour_map_lines(role, &name) else {
            continue;
        };
        write_png(&dir.join(&name), img)?;
        files.push(dir.join(&name));
        mtl.push_str(&line);
    }
    let mtl_path = dir.join(&mtl_name);
    write_atomic(&mtl_path, |w| w.write_all(mtl.as_bytes()))?;
    files.push(mtl_path);
    write_atomic(&obj_path, |w| {
        super::obj::stream_obj(w, &asset.mesh, Some(&asset.uvs), None, Some(&mtl_name))
    })?;
    Ok(files)
}

/// The MTL lines of a non-colour map (`role` = `normal`, `roughness` or
/// `height`; `None` for any other role), written so that readers which can
/// tell keep the map's values as data instead of decoding them as sRGB.
///
/// MTL has no colour-space option (`-colorspace` is no reader's keyword, and
/// three.js would take an unknown option as part of the file name), so the
/// statement itself must say what the map is:
///
/// - normal: `norm NAME` (the PBR extension; three.js' `MTLLoader` reads it as
///   `normalMap`, assimp as its normals texture) and `map_Bump -bm 1 NAME`,
///   which Blender's OBJ importer (3.x and 4.x) reads as a tangent-space
///   Normal Map node of strength `-bm` with a Non-Color image. three.js also
///   takes `map_Bump` as a `bumpMap`, but its shaders use the normal map
///   when a material has both, so the bump map goes unused there.
/// - roughness: `map_Pr NAME` (Blender: Roughness input, Non-Color;
///   three.js' stock loader ignores it).
/// - height: `disp -mm 0 0 NAME`: the map with a displacement range of zero
///   (`-mm base gain`). three.js reads it as a linear `displacementMap` with
///   `displacementBias` 0 and `displacementScale` 0; without `-mm` its scale
///   would be 1 model unit, pushing every vertex out by up to a model unit
///   (10 % of the bunny's height), where the preview and the GLB show the
///   mesh undisplaced. Set `displacementScale` to use it; Blender reads no
///   displacement from MTL.
///
/// three.js marks only `map_Kd` and `map_Ke` as sRGB, so the maps above are
/// linear there; MeshLab reads `map_Kd` only.
pub fn non_colour_map_lines(role: &str, name: &str) -> Option<String> {
    match role {
        "normal" => Some(format!("norm {name}\nmap_Bump -bm 1 {name}\n")),
        "roughness" => Some(format!("map_Pr {name}\n")),
        "height" => Some(format!("disp -mm 0 0 {name}\n")),
        _ => None,
    }
}
