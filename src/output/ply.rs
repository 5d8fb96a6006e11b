//! Binary little-endian PLY writer, by hand: the format is simple and this
//! keeps the output byte-deterministic (same mesh, same bytes).
//!
//! Layout: `vertex` with `float x y z`, `float nx ny nz` (the area-weighted
//! unit vertex normals of [`PolyMesh::vertex_normals`], the normals the OBJ
//! writer's `vn` lines carry: three.js' `PLYLoader` and Blender read them and
//! shade smooth, where without them three.js has no normals at all), then
//! optional `uchar red green blue` (and `alpha`), then optional extra `float`
//! properties; `face` with
//! `list uchar int vertex_indices`, or `list uint int vertex_indices` when a
//! face has 256 corners or more (so small meshes keep the common layout every
//! reader knows, and any polygon still fits).

use super::{OutputError, write_atomic};
use crate::mesh::PolyMesh;
use std::io::Write;
use std::path::Path;

/// Per-vertex colours: values in `[0, 1]`, `channels` per vertex.
/// 1 channel is grey (written as equal red, green, blue), 2 is grey and alpha,
/// 3 is RGB, 4 is RGBA.
pub type VertexColours<'a> = (&'a [f32], usize);

/// An extra per-vertex `float` property: its name and one value per vertex.
pub type ExtraProperty<'a> = (&'a str, &'a [f32]);

fn encode_error(message: String) -> OutputError {
    OutputError::Encode {
        what: "PLY".into(),
        message,
    }
}

/// Converts a colour value in `[0, 1]` to a byte, the way PNG output does.
#[inline]
pub(crate) fn colour_byte(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Checks the attributes and builds the header (see [`encode_ply`]).
fn ply_header(
    mesh: &PolyMesh,
    colours: Option<VertexColours>,
    extra: &[ExtraProperty],
) -> Result<PlyHeader, OutputError> {
    let nv = mesh.vertex_count();
    let nf = mesh.face_count();
    let mut header =
        String::from("ply\nformat binary_little_endian 1.0\ncomment written by surfsynth\n");
    header.push_str(&format!(
        "element vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n"
    ));
    if let Some((values, channels)) = colours {
        if !(1..=4).contains(&channels) {
            return Err(encode_error(format!(
                "vertex colours have {channels} channels; allowed 1 (grey), 2 (grey, alpha), 3 (RGB) or 4 (RGBA)"
            )));
        }
        if values.len() != nv * channels {
            return Err(encode_error(format!(
                "vertex colours hold {} values, expected {nv} vertices x {channels} channels = {}",
                values.len(),
                nv * channels
            )));
        }
        header.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
        if channels % 2 == 0 {
            header.push_str("property uchar alpha\n");
        }
    }
    let mut names: Vec<&str> = vec![
        "x", "y", "z", "nx", "ny", "nz", "red", "green", "blue", "alpha",
    ];
    for (name, values) in extra {
        let ok = !name.is_empty()
            && name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
            && !names.contains(name);
        if !ok {
            return Err(encode_error(format!(
                "extra vertex property name {name:?} must be a new identifier of letters, digits and '_'"
            )));
        }
        if values.len() != nv {
            return Err(encode_error(format!(
                "extra vertex property {name} holds {} values, expected one per vertex ({nv})",
                values.len()
            )));
        }
        names.push(name);
        header.push_str(&format!("property float {name}\n"));
    }
    // A `uchar` count holds up to 255 corners; wider faces need `uint`.
    let wide_counts = mesh.faces().any(|f| f.len() > u8::MAX as usize);
    let count_type = if wide_counts { "uint" } else { "uchar" };
    header.push_str(&format!(
        "element face {nf}\nproperty list {count_type} int vertex_indices\nend_header\n"
    ));
    Ok(PlyHeader {
        text: header,
        wide_counts,
    })
}

/// The checked header of a PLY file and the face-count type it declares.
struct PlyHeader {
    text: String,
    wide_counts: bool,
}

/// Encodes `mesh` as binary little-endian PLY bytes (in memory: for tests
/// and small meshes; [`write_ply`] streams to the file).
///
/// # Errors
/// [`OutputError::Encode`] when `colours` has a channel count outside `1..=4`
/// or a length other than `vertices × channels`, an extra property has a
/// length other than the vertex count or a name that is not a plain
/// identifier (or clashes with another property).
pub fn encode_ply(
    mesh: &PolyMesh,
    colours: Option<VertexColours>,
    extra: &[ExtraProperty],
) -> Result<Vec<u8>, OutputError> {
    let header = ply_header(mesh, colours, extra)?;
    let mut out = Vec::with_capacity(
        header.text.len() + mesh.vertex_count() * 32 + mesh.face_count() + 4 * mesh.corner_count(),
    );
    stream_ply(&mut out, &header, mesh, colours, extra)
        .map_err(|e| encode_error(format!("writing into memory: {e}")))?;
    Ok(out)
}

/// Writes the header and the elements to `w`, a vertex or a face at a time.
fn stream_ply(
    w: &mut dyn Write,
    header: &PlyHeader,
    mesh: &PolyMesh,
    colours: Option<VertexColours>,
    extra: &[ExtraProperty],
) -> std::io::Result<()> {
    w.write_all(header.text.as_bytes())?;
    let colour_bytes = colours.map_or(0, |(_, c)| if c % 2 == 0 { 4 } else { 3 });
    let normals = mesh.vertex_normals();
    let mut row: Vec<u8> = Vec::with_capacity(28 + 4 * extra.len());
    for (v, (p, n)) in mesh.positions.iter().zip(&normals).enumerate() {
        row.clear();
        for x in p.to_array().into_iter().chain(n.to_array()) {
            row.extend_from_slice(&x.to_le_bytes());
        }
        if let Some((values, channels)) = colours {
            let c = &values[v * channels..(v + 1) * channels];
            let rgba = match channels {
                1 => [c[0], c[0], c[0], 1.0],
                2 => [c[0], c[0], c[0], c[1]],
                3 => [c[0], c[1], c[2], 1.0],
                _ => [c[0], c[1], c[2], c[3]],
            };
            row.extend(rgba[..colour_bytes].iter().map(|&x| colour_byte(x)));
        }
        for (_, values) in extra {
            row.extend_from_slice(&values[v].to_le_bytes());
        }
        w.write_all(&row)?;
    }
    for face in mesh.faces() {
        row.clear();
        // Corner counts fit `u32`: `PolyMesh` offsets are `u32`.
        let degree = face.len() as u32;
        if header.wide_counts {
            row.extend_from_slice(&degree.to_le_bytes());
        } else {
            row.push(degree as u8);
        }
        for &v in face {
            row.extend_from_slice(&(v as i32).to_le_bytes());
        }
        w.write_all(&row)?;
    }
    Ok(())
}

/// Writes `mesh` as binary little-endian PLY to `path`, atomically,
/// streaming it (no copy of the file in memory). See [`encode_ply`] for the
/// layout and errors.
pub fn write_ply(
    path: &Path,
    mesh: &PolyMesh,
    colours: Option<VertexColours>,
    extra: &[ExtraProperty],
) -> Result<(), OutputError> {
    let header = ply_header(mesh, colours, extra)?;
    write_atomic(path, |w| stream_ply(w, &header, mesh, colours, extra))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::io::{LoadOptions, MeshFormat, load_mesh_from_bytes};
    use glam::Vec3;

    fn quad_and_triangle() -> PolyMesh {
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.5, 2.0, 0.25),
        ];
        PolyMesh::from_polygons(p, [&[0u32, 1, 2, 3][..], &[3, 2, 4][..]])
    }

    #[test]
    fn round_trip_through_the_loader() {
        let m = quad_and_triangle();
        let grey = [0.0, 0.25, 0.5, 0.75, 1.0];
        let extra = [("curvature", &grey[..])];
        let bytes = encode_ply(&m, Some((&grey, 1)), &extra).unwrap();
        let (back, report) = load_mesh_from_bytes(
            &bytes,
            MeshFormat::Ply,
            Path::new("rt.ply"),
            &LoadOptions::default(),
        )
        .unwrap();
        assert!(report.is_clean());
        assert_eq!(back, m);
    }

    #[test]
    fn deterministic_bytes_and_layout() {
        let m = quad_and_triangle();
        let rgba = vec![0.5f32; 20];
        let a = encode_ply(&m, Some((&rgba, 4)), &[]).unwrap();
        let b = encode_ply(&m, Some((&rgba, 4)), &[]).unwrap();
        assert_eq!(a, b);
        let text = String::from_utf8_lossy(&a);
        assert!(text.contains("property uchar alpha\n"));
        let header_len = text.find("end_header\n").unwrap() + "end_header\n".len();
        assert!(text.contains("property float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty uchar red\n"));
        assert_eq!(a.len(), header_len + 5 * 28 + (1 + 16) + (1 + 12));
        assert_eq!(a[header_len + 24], 128);
        // The normal of vertex 0 (in the xy-plane quad only) is +z.
        let nz = f32::from_le_bytes(a[header_len + 20..header_len + 24].try_into().unwrap());
        assert_eq!(nz, 1.0);
    }

    #[test]
    fn bad_attributes_are_errors() {
        let m = quad_and_triangle();
        assert!(encode_ply(&m, Some((&[0.0; 5], 5)), &[]).is_err());
        assert!(encode_ply(&m, Some((&[0.0; 4], 1)), &[]).is_err());
        assert!(encode_ply(&m, None, &[("red", &[0.0; 5])]).is_err());
        assert!(encode_ply(&m, None, &[("a b", &[0.0; 5])]).is_err());
        assert!(encode_ply(&m, None, &[("k", &[0.0; 4])]).is_err());
    }

    #[test]
    fn faces_of_256_corners_get_uint_list_counts() {
        let n = 300u32;
        let positions = (0..n)
            .map(|i| {
                let a = i as f32 / n as f32 * std::f32::consts::TAU;
                glam::Vec3::new(a.cos(), a.sin(), 0.0)
            })
            .collect();
        let m = PolyMesh::from_polygons(positions, [&(0..n).collect::<Vec<u32>>()[..]]);
        let bytes = encode_ply(&m, None, &[]).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        assert!(
            text.contains("property list uint int vertex_indices"),
            "{text}"
        );
        let back = crate::mesh::io::parse_mesh(
            &bytes,
            crate::mesh::io::MeshFormat::Ply,
            Path::new("big.ply"),
        )
        .unwrap();
        assert_eq!(back.face(0).len(), n as usize);
        assert_eq!(back.face(0)[299], 299);
    }
}
