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
use crate::stages::world::BakedAsset;
use glam::{Vec2, Vec3};
use serde_json::{Value, json};
use std::collections::HashMap;

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
    let smooth = mesh.vertex_normals();
    let face_normals = mesh.face_normals();
    let mut index: HashMap<(u32, u32, u32), u32> = HashMap::with_capacity(mesh.corner_count());
    let (mut pos, mut nrm, mut tex, mut idx) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut tan_sum: Vec<Vec3> = Vec::new();
    for (f, face_normal) in face_normals.iter().enumerate() {
        // The face's atlas `u` gradient, weighted by its area.
        let r = mesh.face_corners(f);
        let p = [r.start, r.start + 1, r.start + 2]
            .map(|c| mesh.positions[mesh.corner_vertex[c] as usize]);
        let u = [r.start, r.start + 1, r.start + 2].map(|c| uvs[c].x);
        let area = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).length();
        let grad = crate::kernels::atlas::bake::gradient(p, u).normalize_or_zero() * area;
        for c in mesh.face_corners(f) {
            let v = mesh.corner_vertex[c];
            let uv = uvs[c];
            let key = (v, uv.x.to_bits(), uv.y.to_bits());
            let i = *index.entry(key).or_insert_with(|| {
                pos.push(mesh.positions[v as usize]);
                let n = smooth
                    .get(v as usize)
                    .copied()
                    .filter(|n| n.is_finite() && n.length_squared() > 0.5)
                    .or_else(|| face_normal.try_normalize())
                    .unwrap_or(Vec3::Z);
                nrm.push(n.normalize());
                tex.push(uv);
                tan_sum.push(Vec3::ZERO);
                (pos.len() - 1) as u32
            });
            tan_sum[i as usize] += grad;
            idx.push(i);
        }
    }
    let tangents = tan_sum
        .iter()
        .zip(&nrm)
        .map(|(t, n)| {
            let t = (*t - *n * t.dot(*n))
                .try_normalize()
                .unwrap_or_else(|| n.any_orthonormal_vector());
            [t.x, t.y, t.z, 1.0]
        })
        .collect();
    Ok(SplitMesh {
        positions: pos,
        normals: nrm,
        uvs: tex,
        tangents,
        indices: idx,
    })
}

/// Appends `bytes` to `bin` at a 4-byte boundary; returns (offset, length).
fn push_aligned(bin: &mut Vec<u8>, bytes: &[u8]) -> (usize, usize) {
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let offset = bin.len();
    bin.extend_from_slice(bytes);
    (offset, bytes.len())
}

/// Encodes the asset as GLB bytes.
pub fn encode_glb(asset: &BakedAsset) -> Result<Vec<u8>, OutputError> {
    let split = split_vertices(&asset.mesh, &asset.uvs)?;
    let (pos, nrm, tex, idx) = (&split.positions, &split.normals, &split.uvs, &split.indices);
    let has_normal_map = asset.maps.iter().any(|(role, _)| role == "normal");
    if pos.iter().any(|p| !p.is_finite()) {
        return Err(encode_error("a vertex position is not finite"));
    }
    let mut bin: Vec<u8> = Vec::new();
    let mut views: Vec<Value> = Vec::new();
    let mut view = |bin: &mut Vec<u8>, bytes: &[u8], target: Option<u32>| {
        let (offset, len) = push_aligned(bin, bytes);
        let mut v = json!({"buffer": 0, "byteOffset": offset, "byteLength": len});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        views.push(v);
        views.len() - 1
    };
    let f32s = |v: &mut Vec<u8>, xs: &[f32]| xs.iter().for_each(|x| v.extend(x.to_le_bytes()));
    let mut b = Vec::with_capacity(12 * pos.len());
    f32s(
        &mut b,
        &pos.iter().flat_map(|p| p.to_array()).collect::<Vec<_>>(),
    );
    let v_pos = view(&mut bin, &b, Some(ARRAY_BUFFER));
    b.clear();
    f32s(
        &mut b,
        &nrm.iter().flat_map(|p| p.to_array()).collect::<Vec<_>>(),
    );
    let v_nrm = view(&mut bin, &b, Some(ARRAY_BUFFER));
    b.clear();
    f32s(
        &mut b,
        &tex.iter().flat_map(|p| p.to_array()).collect::<Vec<_>>(),
    );
    let v_tex = view(&mut bin, &b, Some(ARRAY_BUFFER));
    b.clear();
    idx.iter().for_each(|i| b.extend(i.to_le_bytes()));
    let v_idx = view(&mut bin, &b, Some(ELEMENT_ARRAY_BUFFER));
    let v_tan = has_normal_map.then(|| {
        b.clear();
        f32s(
            &mut b,
            &split.tangents.iter().flatten().copied().collect::<Vec<_>>(),
        );
        view(&mut bin, &b, Some(ARRAY_BUFFER))
    });
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
    let mut add_image = |bin: &mut Vec<u8>, img: &Image| -> Result<usize, OutputError> {
        let png = encode_png(img)?;
        let v = view(bin, &png, None);
        images.push(json!({"bufferView": v, "mimeType": "image/png"}));
        Ok(images.len() - 1)
    };
    let base = add_image(&mut bin, &asset.colour)?;
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
                let i = add_image(&mut bin, img)?;
                material["normalTexture"] = json!({"index": i});
            }
            "roughness" => {
                let mr = metallic_roughness(img);
                let i = add_image(&mut bin, &mr)?;
                material["pbrMetallicRoughness"]["metallicRoughnessTexture"] = json!({"index": i});
            }
            _ => {}
        }
    }
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
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
        "buffers": [{"byteLength": bin.len()}],
    });
    let mut text = serde_json::to_vec(&doc).map_err(|e| encode_error(e.to_string()))?;
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let total32 = u32::try_from(total).map_err(|_| encode_error("the asset exceeds 4 GiB"))?;
    let mut out = Vec::with_capacity(total);
    out.extend(0x4654_6C67u32.to_le_bytes()); // "glTF"
    out.extend(2u32.to_le_bytes());
    out.extend(total32.to_le_bytes());
    out.extend((text.len() as u32).to_le_bytes());
    out.extend(0x4E4F_534Au32.to_le_bytes()); // "JSON"
    out.extend(&text);
    out.extend((bin.len() as u32).to_le_bytes());
    out.extend(0x004E_4942u32.to_le_bytes()); // "BIN\0"
    out.extend(&bin);
    Ok(out)
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
