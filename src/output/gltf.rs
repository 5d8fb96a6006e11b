//! glTF 2.0 binary (`.glb`) writer for a baked asset: one mesh, one
//! material, textures embedded as PNG in the BIN chunk. Written by hand with
//! serde_json (the format is small; the `gltf` crate re-reads it in tests).
//!
//! Layout: vertices are split where a mesh vertex has more than one atlas
//! coordinate (chart seams); POSITION (with min/max), NORMAL (smooth,
//! area-weighted), TEXCOORD_0 (glTF's `v = 0` is the top row, as ours),
//! u32 indices; TANGENT (atlas `u` axis, handedness +1) when a normal map
//! is present. Material: `baseColorTexture`; a baked `normal` map becomes
//! `normalTexture`; `roughness` becomes `metallicRoughnessTexture` (G =
//! roughness, B = metallic 0).

use super::{OutputError, encode_png};
use crate::image::Image;
use crate::mesh::PolyMesh;
use crate::world::BakedAsset;
use glam::{Vec2, Vec3};
use serde_json::{Value, json};
use std::io::Write;
use std::path::Path;

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;

fn encode_error(message: impl Into<String>) -> OutputError {
    OutputError::Encode {
        what: "glTF binary".into(),
        message: message.into(),
    }
}

/// The glTF vertex arrays of a mesh.
#[derive(Clone, Debug, Default)]
pub struct SplitMesh {
    /// Positions.
    pub positions: Vec<Vec3>,
    /// Unit normals (smooth, area-weighted).
    pub normals: Vec<Vec3>,
    /// Texture coordinates.
    pub uvs: Vec<Vec2>,
    /// Unit tangents along the atlas `u` axis, orthogonal to the normal,
    /// with handedness +1 (bitangent = normal × tangent points up the
    /// texture, glTF's normal-map +Y).
    pub tangents: Vec<[f32; 4]>,
    /// Triangle indices.
    pub indices: Vec<u32>,
}

/// Splits `mesh` (triangles) into glTF vertices: one per distinct (vertex,
/// atlas coordinate).
pub fn split_vertices(mesh: &PolyMesh, uvs: &[Vec2]) -> Result<SplitMesh, OutputError> {
    split_vertices_with(mesh, uvs, true)
}

/// [`split_vertices`]; `tangents` false leaves [`SplitMesh::tangents`]
/// empty (only a normal map needs them).
///
/// Vertices are numbered in order of their first corner. Each mesh
/// vertex's corners are sorted by atlas coordinate (a list of the corners
/// of every vertex, 4 bytes a corner, instead of a map of every distinct
/// pair: ~140 MB at a million vertices); the first corner of each run of
/// equal coordinates names the glTF vertex of the run.
pub fn split_vertices_with(
    mesh: &PolyMesh,
    uvs: &[Vec2],
    tangents: bool,
) -> Result<SplitMesh, OutputError> {
    if !mesh.is_triangle_mesh() {
        return Err(encode_error("the mesh is not triangulated"));
    }
    if uvs.len() != mesh.corner_count() {
        return Err(encode_error(format!(
            "{} texture coordinates for {} corners",
            uvs.len(),
            mesh.corner_count()
        )));
    }
    if mesh.face_count() == 0 {
        return Err(encode_error("the mesh has no faces"));
    }
    let corners = mesh.corner_count();
    let vc = mesh.vertex_count();
    if u32::try_from(corners).is_err() || mesh.corner_vertex.iter().any(|&v| v as usize >= vc) {
        return Err(encode_error("corner indices out of range"));
    }
    // Corners of each vertex, ascending (CSR).
    let mut start = vec![0u32; vc + 1];
    for &v in &mesh.corner_vertex {
        start[v as usize + 1] += 1;
    }
    for v in 0..vc {
        start[v + 1] += start[v];
    }
    let mut list = vec![0u32; corners];
    {
        let mut fill = start.clone();
        for (c, &v) in mesh.corner_vertex.iter().enumerate() {
            list[fill[v as usize] as usize] = c as u32;
            fill[v as usize] += 1;
        }
    }
    // Per corner, first the first corner with its vertex and coordinate.
    let bits = |c: u32| (uvs[c as usize].x.to_bits(), uvs[c as usize].y.to_bits());
    let mut idx = vec![0u32; corners];
    for v in 0..vc {
        let group = &mut list[start[v] as usize..start[v + 1] as usize];
        group.sort_unstable_by_key(|&c| (bits(c), c));
        let mut first = None;
        for &c in group.iter() {
            let k = bits(c);
            let r = match first {
                Some((key, r)) if key == k => r,
                _ => {
                    first = Some((k, c));
                    c
                }
            };
            idx[c as usize] = r;
        }
    }
    drop((list, start));
    let count = idx
        .iter()
        .enumerate()
        .filter(|&(c, &r)| r as usize == c)
        .count();
    let smooth = mesh.vertex_normals();
    let (mut pos, mut nrm, mut tex) = (
        Vec::with_capacity(count),
        Vec::with_capacity(count),
        Vec::with_capacity(count),
    );
    for f in 0..mesh.face_count() {
        for c in mesh.face_corners(f) {
            let r = idx[c] as usize;
            if r != c {
                // `r < c`: already numbered.
                idx[c] = idx[r];
                continue;
            }
            let v = mesh.corner_vertex[c];
            pos.push(mesh.positions[v as usize]);
            let n = smooth
                .get(v as usize)
                .copied()
                .filter(|n| n.is_finite() && n.length_squared() > 0.5)
                .or_else(|| mesh.face_normal(f).try_normalize())
                .unwrap_or(Vec3::Z);
            nrm.push(n.normalize());
            tex.push(uvs[c]);
            idx[c] = (pos.len() - 1) as u32;
        }
    }
    drop(smooth);
    let tangents = if tangents {
        let mut tan_sum = vec![Vec3::ZERO; pos.len()];
        for f in 0..mesh.face_count() {
            // The face's atlas `u` gradient, weighted by its area.
            let r = mesh.face_corners(f);
            let p = [r.start, r.start + 1, r.start + 2]
                .map(|c| mesh.positions[mesh.corner_vertex[c] as usize]);
            let u = [r.start, r.start + 1, r.start + 2].map(|c| uvs[c].x);
            let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
            let grad = crate::kernels::atlas::bake::gradient(p, u).normalize_or_zero() * area;
            for c in r {
                tan_sum[idx[c] as usize] += grad;
            }
        }
        tan_sum
            .iter()
            .zip(&nrm)
            .map(|(t, n)| {
                let t = (*t - *n * t.dot(*n))
                    .try_normalize()
                    .unwrap_or_else(|| n.any_orthonormal_vector());
                [t.x, t.y, t.z, 1.0]
            })
            .collect()
    } else {
        Vec::new()
    };
    Ok(SplitMesh {
        positions: pos,
        normals: nrm,
        uvs: tex,
        tangents,
        indices: idx,
    })
}

/// A GLB ready to be written: its JSON chunk, and the arrays and PNG files
/// of its BIN chunk, in order.
struct GlbParts {
    json: Vec<u8>,
    split: SplitMesh,
    pngs: Vec<Vec<u8>>,
    bin_len: usize,
}

/// Bytes of zero padding after `len` bytes to a 4-byte boundary.
fn pad4(len: usize) -> usize {
    (4 - len % 4) % 4
}

/// Everything of the GLB of `asset` but its arrays' bytes.
fn prepare_glb(asset: &BakedAsset) -> Result<GlbParts, OutputError> {
    let has_normal_map = asset.maps.iter().any(|(role, _)| role == "normal");
    let split = split_vertices_with(&asset.mesh, &asset.uvs, has_normal_map)?;
    let (pos, nrm, tex, idx) = (&split.positions, &split.normals, &split.uvs, &split.indices);
    if pos.iter().any(|p| !p.is_finite()) {
        return Err(encode_error("a vertex position is not finite"));
    }
    // The BIN chunk's layout: each view at a 4-byte boundary.
    let mut bin_len = 0usize;
    let mut views: Vec<Value> = Vec::new();
    let mut view = |bin_len: &mut usize, len: usize, target: Option<u32>| {
        *bin_len += pad4(*bin_len);
        let offset = *bin_len;
        *bin_len += len;
        let mut v = json!({"buffer": 0, "byteOffset": offset, "byteLength": len});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        views.push(v);
        views.len() - 1
    };
    let v_pos = view(&mut bin_len, 12 * pos.len(), Some(ARRAY_BUFFER));
    let v_nrm = view(&mut bin_len, 12 * nrm.len(), Some(ARRAY_BUFFER));
    let v_tex = view(&mut bin_len, 8 * tex.len(), Some(ARRAY_BUFFER));
    let v_idx = view(&mut bin_len, 4 * idx.len(), Some(ELEMENT_ARRAY_BUFFER));
    let v_tan =
        has_normal_map.then(|| view(&mut bin_len, 16 * split.tangents.len(), Some(ARRAY_BUFFER)));
    let (lo, hi) = pos.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    );
    let mut accessors = json!([
        {"bufferView": v_pos, "componentType": FLOAT, "count": pos.len(), "type": "VEC3",
         "min": lo.to_array(), "max": hi.to_array()},
        {"bufferView": v_nrm, "componentType": FLOAT, "count": nrm.len(), "type": "VEC3"},
        {"bufferView": v_tex, "componentType": FLOAT, "count": tex.len(), "type": "VEC2"},
        {"bufferView": v_idx, "componentType": UNSIGNED_INT, "count": idx.len(), "type": "SCALAR"},
    ]);
    let mut attributes = json!({"POSITION": 0, "NORMAL": 1, "TEXCOORD_0": 2});
    if let (Some(v), Some(list)) = (v_tan, accessors.as_array_mut()) {
        list.push(
            json!({"bufferView": v, "componentType": FLOAT, "count": pos.len(), "type": "VEC4"}),
        );
        attributes["TANGENT"] = json!(4);
    }
    // Images: colour first, then the maps glTF has a slot for.
    let mut images: Vec<Value> = Vec::new();
    let mut pngs: Vec<Vec<u8>> = Vec::new();
    let mut add_image = |bin_len: &mut usize, img: &Image| -> Result<usize, OutputError> {
        let png = encode_png(img)?;
        let v = view(bin_len, png.len(), None);
        pngs.push(png);
        images.push(json!({"bufferView": v, "mimeType": "image/png"}));
        Ok(images.len() - 1)
    };
    let base = add_image(&mut bin_len, &asset.colour)?;
    let mut material = json!({
        "name": "baked",
        "pbrMetallicRoughness": {
            "baseColorTexture": {"index": base},
            "metallicFactor": 0.0,
            "roughnessFactor": 1.0
        },
        "doubleSided": true
    });
    for (role, img) in &asset.maps {
        match role.as_str() {
            "normal" => {
                let i = add_image(&mut bin_len, img)?;
                material["normalTexture"] = json!({"index": i});
            }
            "roughness" => {
                let mr = metallic_roughness(img);
                let i = add_image(&mut bin_len, &mr)?;
                material["pbrMetallicRoughness"]["metallicRoughnessTexture"] = json!({"index": i});
            }
            _ => {}
        }
    }
    bin_len += pad4(bin_len);
    let textures: Vec<Value> = (0..images.len())
        .map(|i| json!({"sampler": 0, "source": i}))
        .collect();
    let doc = json!({
        "asset": {"version": "2.0", "generator": concat!("surfsynth ", env!("CARGO_PKG_VERSION"))},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "baked"}],
        "meshes": [{"primitives": [{
            "attributes": attributes,
            "indices": 3,
            "material": 0,
            "mode": 4
        }]}],
        "materials": [material],
        "textures": textures,
        "images": images,
        "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 33071, "wrapT": 33071}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin_len}],
    });
    let mut json = serde_json::to_vec(&doc).map_err(|e| encode_error(e.to_string()))?;
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin_len;
    if u32::try_from(total).is_err() {
        return Err(encode_error("the asset exceeds 4 GiB"));
    }
    Ok(GlbParts {
        json,
        split,
        pngs,
        bin_len,
    })
}

/// Writes the prepared GLB to `w`, the arrays in chunks (no copy of the
/// file in memory).
fn write_glb_parts(w: &mut dyn Write, parts: &GlbParts) -> std::io::Result<()> {
    let (json, split) = (&parts.json, &parts.split);
    let total = (12 + 8 + json.len() + 8 + parts.bin_len) as u32;
    w.write_all(&0x4654_6C67u32.to_le_bytes())?; // "glTF"
    w.write_all(&2u32.to_le_bytes())?;
    w.write_all(&total.to_le_bytes())?;
    w.write_all(&(json.len() as u32).to_le_bytes())?;
    w.write_all(&0x4E4F_534Au32.to_le_bytes())?; // "JSON"
    w.write_all(json)?;
    w.write_all(&(parts.bin_len as u32).to_le_bytes())?;
    w.write_all(&0x004E_4942u32.to_le_bytes())?; // "BIN\0"
    let mut written = 0usize;
    let mut buf: Vec<u8> = Vec::with_capacity(1 << 16);
    let mut put =
        |w: &mut dyn Write, xs: &mut dyn Iterator<Item = [u8; 4]>| -> std::io::Result<()> {
            buf.clear();
            for x in xs {
                buf.extend(x);
                if buf.len() >= 1 << 16 {
                    w.write_all(&buf)?;
                    written += buf.len();
                    buf.clear();
                }
            }
            w.write_all(&buf)?;
            written += buf.len();
            Ok(())
        };
    let le = |x: f32| x.to_le_bytes();
    put(
        w,
        &mut split.positions.iter().flat_map(|p| p.to_array().map(le)),
    )?;
    put(
        w,
        &mut split.normals.iter().flat_map(|p| p.to_array().map(le)),
    )?;
    put(w, &mut split.uvs.iter().flat_map(|p| p.to_array().map(le)))?;
    put(w, &mut split.indices.iter().map(|i| i.to_le_bytes()))?;
    put(w, &mut split.tangents.iter().flat_map(|t| t.map(le)))?;
    for png in &parts.pngs {
        let pad = pad4(written);
        w.write_all(&[0u8; 3][..pad])?;
        w.write_all(png)?;
        written += pad + png.len();
    }
    w.write_all(&[0u8; 3][..pad4(written)])?;
    Ok(())
}

/// Encodes the asset as GLB bytes.
pub fn encode_glb(asset: &BakedAsset) -> Result<Vec<u8>, OutputError> {
    let parts = prepare_glb(asset)?;
    let mut out = Vec::with_capacity(12 + 8 + parts.json.len() + 8 + parts.bin_len);
    write_glb_parts(&mut out, &parts).map_err(|e| encode_error(e.to_string()))?;
    Ok(out)
}

/// Writes the GLB of `asset` to `path` (atomically), streaming its arrays.
pub fn write_glb(path: &Path, asset: &BakedAsset) -> Result<(), OutputError> {
    let parts = prepare_glb(asset)?;
    super::write_atomic(path, |w| write_glb_parts(w, &parts))
}

/// A glTF metallic-roughness texture from a one-channel roughness map:
/// G = roughness, B = metallic (0), R unused (1).
pub fn metallic_roughness(roughness: &Image) -> Image {
    let mut out = Image::new(roughness.width, roughness.height, 3);
    let c = roughness.channels.max(1) as usize;
    for (o, px) in out
        .data
        .chunks_exact_mut(3)
        .zip(roughness.data.chunks_exact(c))
    {
        o.copy_from_slice(&[1.0, px[0], 0.0]);
    }
    out
}
