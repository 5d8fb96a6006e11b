//! Wavefront OBJ writer: `STEM.obj`, and with a texture `STEM.mtl` and
//! `STEM.png`, all written atomically.
//!
//! UV convention: our texture coordinates have `v = 0` at the **top** image
//! row (image convention, as [`crate::image::Image`] stores rows top-down).
//! OBJ's `vt` has `v = 0` at the **bottom**, so we write `vt u (1 - v)`.
//! Texture coordinates are per corner: corner `c` gets `vt` number `c + 1`,
//! so seams need no vertex splitting.
//!
//! Normals: one `vn` per vertex (the area-weighted vertex normal of
//! [`PolyMesh::vertex_normals`], `vn` number `v + 1`), referenced by every
//! face corner (`f v/vt/vn` or `f v//vn`), and smoothing group `s 1`: Blender
//! and MeshLab otherwise shade an OBJ without normals faceted.
//!
//! Numbers are written with Rust's shortest round-trip formatting (the
//! bytes of `Display`, by the faster [`super::decimal`]), so the output is
//! byte-deterministic and positions read back bit-exactly.

use super::decimal::{push_f32, push_u64};
use super::{OutputError, write_atomic, write_png};
use crate::image::Image;
use crate::mesh::PolyMesh;
use glam::Vec2;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Name of the one material the `.mtl` file defines.
pub const MATERIAL_NAME: &str = "surfsynth";

fn encode_error(message: String) -> OutputError {
    OutputError::Encode {
        what: "OBJ".into(),
        message,
    }
}

/// Encodes the `.obj` text.
///
/// - `corner_uvs`: one UV per corner (`mesh.corner_count()` entries), in our
///   top-row-is-`v = 0` convention; written flipped (see the module docs).
/// - `vertex_colours`: `(values in [0, 1], channels)` per vertex, written with
///   the common `v x y z r g b` extension (1 channel is grey; alpha dropped).
/// - `mtl`: the `.mtl` file name to reference with `mtllib`/`usemtl`.
///
/// The text of a million-vertex mesh is some 300 MB: files are streamed
/// with [`stream_obj`] instead; this is for tests and small meshes.
///
/// # Errors
/// [`OutputError::Encode`] when an attribute array has the wrong length or
/// the colours have a channel count outside `1..=4`.
pub fn encode_obj(
    mesh: &PolyMesh,
    corner_uvs: Option<&[Vec2]>,
    vertex_colours: Option<(&[f32], usize)>,
    mtl: Option<&str>,
) -> Result<String, OutputError> {
    check_obj(mesh, corner_uvs, vertex_colours)?;
    let mut bytes = Vec::with_capacity(64 * (mesh.vertex_count() + mesh.corner_count()) + 64);
    stream_obj(&mut bytes, mesh, corner_uvs, vertex_colours, mtl)
        .map_err(|e| encode_error(format!("writing into memory: {e}")))?;
    String::from_utf8(bytes).map_err(|e| encode_error(e.to_string()))
}

/// Checks the attribute arrays [`stream_obj`] writes (see [`encode_obj`]).
pub fn check_obj(
    mesh: &PolyMesh,
    corner_uvs: Option<&[Vec2]>,
    vertex_colours: Option<(&[f32], usize)>,
) -> Result<(), OutputError> {
    let nv = mesh.vertex_count();
    if let Some(uvs) = corner_uvs
        && uvs.len() != mesh.corner_count()
    {
        return Err(encode_error(format!(
            "{} corner UVs for a mesh with {} corners",
            uvs.len(),
            mesh.corner_count()
        )));
    }
    if let Some((values, channels)) = vertex_colours
        && (!(1..=4).contains(&channels) || values.len() != nv * channels)
    {
        return Err(encode_error(format!(
            "vertex colours: {} values with {channels} channels for {nv} vertices \
             (need 1..=4 channels and vertices x channels values)",
            values.len()
        )));
    }
    Ok(())
}

/// Writes the `.obj` text of [`encode_obj`] to `w` line by line, holding
/// no copy of it. Preconditions: [`check_obj`] accepted the arguments
/// (otherwise this may panic on an index).
pub fn stream_obj(
    w: &mut dyn Write,
    mesh: &PolyMesh,
    corner_uvs: Option<&[Vec2]>,
    vertex_colours: Option<(&[f32], usize)>,
    mtl: Option<&str>,
) -> std::io::Result<()> {
    w.write_all(&obj_header(mtl))?;
    write_positions(w, mesh, vertex_colours)?;
    write_vertex_normals(w, mesh)?;
    if let Some(uvs) = corner_uvs {
        write_items(w, uvs.len(), |c, buf| {
            buf.extend_from_slice(b"vt");
            push_floats(buf, [uvs[c].x, 1.0 - uvs[c].y]);
            buf.push(b'\n');
            Ok(())
        })?;
    }
    if mtl.is_some() {
        writeln!(w, "usemtl {MATERIAL_NAME}")?;
    }
    w.write_all(b"s 1\n")?;
    write_items(w, mesh.face_count(), |f, buf| {
        buf.push(b'f');
        for c in mesh.face_corners(f) {
            let v = u64::from(mesh.corner_vertex[c]) + 1;
            buf.push(b' ');
            push_u64(buf, v);
            buf.push(b'/');
            if corner_uvs.is_some() {
                push_u64(buf, c as u64 + 1);
            }
            buf.push(b'/');
            push_u64(buf, v);
        }
        buf.push(b'\n');
        Ok(())
    })
}

/// The first lines of an `.obj` referencing material file `mtl`: all that
/// depends on the file's name ([`copy_obj`]).
fn obj_header(mtl: Option<&str>) -> Vec<u8> {
    let mut h = b"# written by surfsynth\n".to_vec();
    if let Some(mtl) = mtl {
        h.extend_from_slice(format!("mtllib {mtl}\n").as_bytes());
    }
    h
}

/// Appends each value of `values` after a space, as `Display` writes it
/// ([`push_f32`]: the same bytes as `write!(buf, " {}", x)`, faster).
#[inline]
pub(crate) fn push_floats<const N: usize>(buf: &mut Vec<u8>, values: [f32; N]) {
    for x in values {
        buf.push(b' ');
        push_f32(buf, x);
    }
}

/// Lines written per block of [`write_items`].
const ITEM_BLOCK: usize = 16_384;
/// Blocks formatted at once by [`write_items`] (their text is held until
/// written: some 16 MB for `v` lines).
const BLOCK_GROUP: usize = 16;

/// Writes the text of items `0..count` to `w` in order, `item(i, buf)`
/// appending item `i`'s: blocks of [`ITEM_BLOCK`] items are formatted in
/// parallel into buffers, then written one after another, so the bytes are
/// those of writing them one by one (float formatting is most of a large
/// OBJ's writing time).
fn write_items(
    w: &mut dyn Write,
    count: usize,
    item: impl Fn(usize, &mut Vec<u8>) -> std::io::Result<()> + Sync,
) -> std::io::Result<()> {
    use rayon::prelude::*;
    let blocks = count.div_ceil(ITEM_BLOCK);
    for group in (0..blocks).step_by(BLOCK_GROUP) {
        let texts: Vec<std::io::Result<Vec<u8>>> = (group..(group + BLOCK_GROUP).min(blocks))
            .into_par_iter()
            .map(|b| {
                let mut buf = Vec::with_capacity(ITEM_BLOCK * 40);
                for i in b * ITEM_BLOCK..((b + 1) * ITEM_BLOCK).min(count) {
                    item(i, &mut buf)?;
                }
                Ok(buf)
            })
            .collect();
        for text in texts {
            w.write_all(&text?)?;
        }
    }
    Ok(())
}

/// Writes one `v` line per vertex, with its RGB when `vertex_colours` are
/// given (see [`encode_obj`]).
pub(crate) fn write_positions(
    w: &mut dyn Write,
    mesh: &PolyMesh,
    vertex_colours: Option<(&[f32], usize)>,
) -> std::io::Result<()> {
    write_items(w, mesh.vertex_count(), |v, buf| {
        buf.push(b'v');
        push_floats(buf, mesh.positions[v].to_array());
        if let Some((values, channels)) = vertex_colours {
            push_floats(
                buf,
                crate::image::pixel_rgb(&values[v * channels..(v + 1) * channels]),
            );
        }
        buf.push(b'\n');
        Ok(())
    })
}

/// Writes one `vn` line per vertex: the mesh's area-weighted unit vertex
/// normals, so `vn` number `v + 1` belongs to vertex `v + 1` and a face
/// corner references the same index for both.
pub(crate) fn write_vertex_normals(w: &mut dyn Write, mesh: &PolyMesh) -> std::io::Result<()> {
    let normals = mesh.vertex_normals();
    write_items(w, normals.len(), |v, buf| {
        buf.extend_from_slice(b"vn");
        push_floats(buf, normals[v].to_array());
        buf.push(b'\n');
        Ok(())
    })
}

/// The `.mtl` text: one white diffuse material textured with `png`.
pub fn encode_mtl(png: &str) -> String {
    format!(
        "# written by surfsynth\nnewmtl {MATERIAL_NAME}\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\nmap_Kd {png}\n"
    )
}

/// Writes `dir/STEM.obj`, and with a `texture` also `dir/STEM.mtl` (material
/// with `map_Kd STEM.png`) and `dir/STEM.png`. Returns the written paths, the
/// `.obj` first. The texture files are written before the `.obj`, so a
/// present `.obj` always finds them.
///
/// See [`encode_obj`] for `corner_uvs` (our `v = 0` is the top row; the file
/// gets `1 - v`) and `vertex_colours`.
///
/// # Errors
/// [`OutputError::Encode`] for a `stem` that is empty or holds a path
/// separator or whitespace, or attribute arrays of the wrong size;
/// [`OutputError::Io`] when a file cannot be written.
pub fn write_obj(
    dir: &Path,
    stem: &str,
    mesh: &PolyMesh,
    corner_uvs: Option<&[Vec2]>,
    texture: Option<&Image>,
    vertex_colours: Option<(&[f32], usize)>,
) -> Result<Vec<PathBuf>, OutputError> {
    if stem.is_empty()
        || stem
            .chars()
            .any(|c| c == '/' || c == '\\' || c.is_whitespace())
    {
        return Err(encode_error(format!(
            "file stem {stem:?} must be non-empty, without path separators or whitespace"
        )));
    }
    let obj_path = dir.join(format!("{stem}.obj"));
    let mut written = vec![obj_path.clone()];
    let mtl_name = texture.map(|_| format!("{stem}.mtl"));
    check_obj(mesh, corner_uvs, vertex_colours)?;
    if let (Some(img), Some(mtl_name)) = (texture, &mtl_name) {
        let png_name = format!("{stem}.png");
        let png_path = dir.join(&png_name);
        write_png(&png_path, img)?;
        let mtl_path = dir.join(mtl_name);
        let mtl = encode_mtl(&png_name);
        write_atomic(&mtl_path, |w| w.write_all(mtl.as_bytes()))?;
        written.push(mtl_path);
        written.push(png_path);
    }
    write_atomic(&obj_path, |w| {
        stream_obj(w, mesh, corner_uvs, vertex_colours, mtl_name.as_deref())
    })?;
    Ok(written)
}

/// Writes `dir/TO.obj` (with `TO.mtl` and `TO.png` of `texture`) as a copy
/// of `dir/FROM.obj`, which [`write_obj`] wrote with the same mesh, texture
/// coordinates and `texture`: the same bytes but the `mtllib` line, copied
/// instead of formatted again (the text of a million-vertex mesh is some
/// 300 MB). Returns the written paths, the `.obj` first.
///
/// # Errors
/// As [`write_obj`]; [`OutputError::Io`] naming `TO.obj` when `FROM.obj`
/// cannot be read.
pub fn copy_obj(
    dir: &Path,
    from: &str,
    to: &str,
    texture: &Image,
) -> Result<Vec<PathBuf>, OutputError> {
    let obj_path = dir.join(format!("{to}.obj"));
    let png_name = format!("{to}.png");
    let png_path = dir.join(&png_name);
    write_png(&png_path, texture)?;
    let mtl_name = format!("{to}.mtl");
    let mtl_path = dir.join(&mtl_name);
    write_atomic(&mtl_path, |w| w.write_all(encode_mtl(&png_name).as_bytes()))?;
    let skip = obj_header(Some(&format!("{from}.mtl"))).len() as u64;
    write_atomic(&obj_path, |w| {
        use std::io::{Read, Seek};
        let mut source = std::fs::File::open(dir.join(format!("{from}.obj")))?;
        source.seek(std::io::SeekFrom::Start(skip))?;
        w.write_all(&obj_header(Some(&mtl_name)))?;
        let mut block = vec![0u8; 1 << 20];
        loop {
            let n = source.read(&mut block)?;
            if n == 0 {
                return Ok(());
            }
            w.write_all(&block[..n])?;
        }
    })?;
    Ok(vec![obj_path, mtl_path, png_path])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::{LoadOptions, load_mesh};
    use glam::Vec3;

    fn quad_and_triangle() -> PolyMesh {
        let p = vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.1, 2.3, 0.7),
        ];
        PolyMesh::from_polygons(p, [&[0u32, 1, 2, 3][..], &[3, 2, 4][..]])
    }

    #[test]
    fn uvs_are_per_corner_and_flipped() {
        let m = quad_and_triangle();
        let uvs: Vec<Vec2> = (0..m.corner_count())
            .map(|c| Vec2::new(c as f32 / 8.0, 0.25))
            .collect();
        let s = encode_obj(&m, Some(&uvs), None, Some("a.mtl")).unwrap();
        assert!(s.contains("mtllib a.mtl\n"));
        assert!(s.contains("vt 0.125 0.75\n"), "{s}");
        assert!(
            s.contains("s 1\nf 1/1/1 2/2/2 3/3/3 4/4/4\nf 4/5/4 3/6/3 5/7/5\n"),
            "{s}"
        );
        assert_eq!(s.matches("\nvn ").count(), 5);
        assert_eq!(s.matches("\nvt ").count(), 7);
    }

    #[test]
    fn writes_obj_mtl_png_and_reads_back() {
        let dir = tempfile::tempdir().unwrap();
        let m = quad_and_triangle();
        let uvs = vec![Vec2::new(0.5, 0.5); m.corner_count()];
        let tex = Image::new(4, 2, 3);
        let grey = [0.0, 0.2, 0.4, 0.6, 1.0];
        let paths = write_obj(
            dir.path(),
            "out",
            &m,
            Some(&uvs),
            Some(&tex),
            Some((&grey, 1)),
        )
        .unwrap();
        assert_eq!(paths.len(), 3);
        for p in &paths {
            assert!(p.exists(), "{}", p.display());
        }
        let mtl = std::fs::read_to_string(dir.path().join("out.mtl")).unwrap();
        assert!(mtl.contains("map_Kd out.png"));
        let obj = std::fs::read_to_string(&paths[0]).unwrap();
        assert!(obj.contains("v 0.1 2.3 0.7 1 1 1\n"), "{obj}");
        let (back, _) = load_mesh(&paths[0], &LoadOptions::default()).unwrap();
        assert_eq!(back, m);
        // Without a texture only the .obj is written.
        let paths = write_obj(dir.path(), "plain", &m, None, None, None).unwrap();
        assert_eq!(paths.len(), 1);
        assert!(!dir.path().join("plain.mtl").exists());
    }

    /// A copy is the bytes `write_obj` writes under the new name, and the
    /// text is `Display`'s: each line as `write!` formats it.
    #[test]
    fn a_copy_equals_writing_again_and_lines_equal_display() {
        let dir = tempfile::tempdir().unwrap();
        let other = tempfile::tempdir().unwrap();
        let m = quad_and_triangle();
        let uvs: Vec<Vec2> = (0..m.corner_count())
            .map(|c| Vec2::new(c as f32 / 7.0, 0.3 + c as f32 * 1e-7))
            .collect();
        let tex = Image::new(4, 2, 3);
        write_obj(dir.path(), "first", &m, Some(&uvs), Some(&tex), None).unwrap();
        let copied = copy_obj(dir.path(), "first", "second", &tex).unwrap();
        let written = write_obj(other.path(), "second", &m, Some(&uvs), Some(&tex), None).unwrap();
        assert_eq!(copied.len(), written.len());
        for (a, b) in copied.iter().zip(&written) {
            assert_eq!(a.file_name(), b.file_name());
            assert_eq!(std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
        }
        let text = std::fs::read_to_string(&copied[0]).unwrap();
        let mut expected = String::from("# written by surfsynth\nmtllib second.mtl\n");
        use std::fmt::Write as _;
        for p in &m.positions {
            writeln!(expected, "v {} {} {}", p.x, p.y, p.z).unwrap();
        }
        for n in m.vertex_normals() {
            writeln!(expected, "vn {} {} {}", n.x, n.y, n.z).unwrap();
        }
        for uv in &uvs {
            writeln!(expected, "vt {} {}", uv.x, 1.0 - uv.y).unwrap();
        }
        writeln!(expected, "usemtl {MATERIAL_NAME}\ns 1").unwrap();
        for f in 0..m.face_count() {
            expected.push('f');
            for c in m.face_corners(f) {
                let v = m.corner_vertex[c] + 1;
                write!(expected, " {v}/{}/{v}", c + 1).unwrap();
            }
            expected.push('\n');
        }
        assert_eq!(text, expected);
    }

    #[test]
    fn items_written_in_parallel_blocks_equal_one_by_one() {
        // More than one group of blocks, and a last block cut short.
        let count = ITEM_BLOCK * BLOCK_GROUP + 3 * ITEM_BLOCK + 17;
        let line = |i: usize, buf: &mut Vec<u8>| writeln!(buf, "v {} {}", i as f32 * 0.37, i);
        let mut blocks = Vec::new();
        write_items(&mut blocks, count, line).unwrap();
        let mut serial = Vec::new();
        for i in 0..count {
            line(i, &mut serial).unwrap();
        }
        assert_eq!(blocks, serial);
    }

    #[test]
    fn bad_inputs_are_errors() {
        let dir = tempfile::tempdir().unwrap();
        let m = quad_and_triangle();
        assert!(write_obj(dir.path(), "a/b", &m, None, None, None).is_err());
        assert!(write_obj(dir.path(), "", &m, None, None, None).is_err());
        let uvs = vec![Vec2::ZERO; 3];
        assert!(write_obj(dir.path(), "a", &m, Some(&uvs), None, None).is_err());
    }
}
