//! STL reader, ASCII and binary.
//!
//! STL stores every triangle with its own three positions, so the reader welds
//! bit-identical positions into shared vertices (otherwise every triangle would
//! be its own component). Facet normals are ignored.
//!
//! A file is read as binary when its length is exactly `84 + 50 * count` for
//! the triangle count in bytes 80..84 (binary files may also start with
//! `solid`), as ASCII when it starts with `solid` in any case (after an
//! optional UTF-8 byte-order mark and whitespace) and holds no NUL byte, and
//! as binary otherwise. ASCII keywords are matched case-insensitively
//! (`SOLID` ... `ENDSOLID` is common from CAD exporters).

use super::{RawMesh, lines, parse_error, parse_xyz, show_token, strip_bom, tokens};
use crate::mesh::MeshError;
use crate::mesh::repair::weld_exact;
use glam::Vec3;
use std::path::Path;

/// Parses STL bytes into a welded raw mesh.
pub(super) fn parse_stl(bytes: &[u8], path: &Path) -> Result<RawMesh, MeshError> {
    let binary_count = bytes
        .get(80..84)
        .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as u64);
    let exact_binary = binary_count.is_some_and(|n| 84 + 50 * n == bytes.len() as u64);
    let text = strip_bom(bytes);
    let starts_solid = {
        let start = text
            .iter()
            .position(|b| !b.is_ascii_whitespace())
            .unwrap_or(0);
        text[start..]
            .get(..5)
            .is_some_and(|kw| kw.eq_ignore_ascii_case(b"solid"))
    };
    // ASCII STL is text: a NUL byte means binary with a `solid` header.
    let ascii = starts_solid && !exact_binary && !bytes.contains(&0);
    let soup = if !ascii {
        parse_binary(bytes, path)?
    } else {
        parse_ascii(text, path)?
    };
    // Check before welding, so the error names the vertex as the file lists it
    // (triangle t, corner c is vertex 3t + c), and NaN never reaches the weld.
    if let Some((v, p)) = soup
        .positions
        .iter()
        .enumerate()
        .find(|(_, p)| !p.is_finite())
    {
        return Err(MeshError::NonFinite {
            path: path.to_path_buf(),
            vertex: v,
            value: p.to_array(),
        });
    }
    let (positions, remap) = weld_exact(&soup.positions);
    let mut raw = RawMesh::with_capacity(positions.len(), soup.face_start.len(), bytes.len());
    raw.positions = positions;
    for w in soup.face_start.windows(2) {
        for c in w[0]..w[1] {
            raw.push_corner(remap[c as usize] as i64);
        }
        raw.end_face();
    }
    Ok(raw)
}

/// Unwelded triangles (or polygons): corner `c` has position `positions[c]`.
struct Soup {
    positions: Vec<Vec3>,
    face_start: Vec<u32>,
}

fn parse_binary(bytes: &[u8], path: &Path) -> Result<Soup, MeshError> {
    let Some(count) = bytes.get(80..84) else {
        return Err(parse_error(
            path,
            format!("byte {}", bytes.len()),
            format!(
                "binary STL needs an 84-byte header, the file has {} bytes (truncated?)",
                bytes.len()
            ),
        ));
    };
    let count = u32::from_le_bytes([count[0], count[1], count[2], count[3]]) as usize;
    let body = &bytes[84..];
    let available = body.len() / 50;
    if available < count {
        return Err(parse_error(
            path,
            format!("triangle {available} (byte {})", 84 + available * 50),
            format!(
                "binary STL header announces {count} triangles, the file holds {available} (truncated?)"
            ),
        ));
    }
    let mut soup = Soup {
        positions: Vec::with_capacity(count * 3),
        face_start: Vec::with_capacity(count + 1),
    };
    soup.face_start.push(0);
    for tri in body.chunks_exact(50).take(count) {
        // 12 bytes normal, 3 x 12 bytes vertices, 2 bytes attribute.
        for v in 0..3 {
            let o = 12 + 12 * v;
            let f = |k: usize| {
                let b = &tri[o + 4 * k..o + 4 * k + 4];
                f32::from_le_bytes([b[0], b[1], b[2], b[3]])
            };
            soup.positions.push(Vec3::new(f(0), f(1), f(2)));
        }
        soup.face_start.push(soup.positions.len() as u32);
    }
    Ok(soup)
}

fn parse_ascii(bytes: &[u8], path: &Path) -> Result<Soup, MeshError> {
    let mut soup = Soup {
        positions: Vec::with_capacity(bytes.len() / 100),
        face_start: vec![0],
    };
    let mut in_loop: Option<usize> = None;
    let mut ended = false;
    let mut last_line = 0;
    for (n, line) in lines(bytes) {
        last_line = n;
        let mut toks = tokens(line);
        let Some(kw) = toks.next() else { continue };
        // Keywords in any case, lowered on the stack (the longest is 8 bytes).
        let mut lowered = [0u8; 8];
        let kw_lower = match lowered.get_mut(..kw.len()) {
            Some(buf) => {
                buf.copy_from_slice(kw);
                buf.make_ascii_lowercase();
                &*buf
            }
            None => kw,
        };
        match kw_lower {
            b"solid" | b"facet" | b"endfacet" => {}
            b"outer" => {
                if in_loop.is_some() {
                    return Err(parse_error(
                        path,
                        format!("line {n}"),
                        "`outer loop` inside an unfinished loop",
                    ));
                }
                in_loop = Some(n);
            }
            b"vertex" => {
                if in_loop.is_none() {
                    return Err(parse_error(
                        path,
                        format!("line {n}"),
                        "`vertex` outside an `outer loop`",
                    ));
                }
                let p =
                    parse_xyz(&mut toks).map_err(|m| parse_error(path, format!("line {n}"), m))?;
                soup.positions.push(Vec3::from_array(p));
            }
            b"endloop" => {
                if in_loop.take().is_none() {
                    return Err(parse_error(
                        path,
                        format!("line {n}"),
                        "`endloop` without `outer loop`",
                    ));
                }
                soup.face_start.push(soup.positions.len() as u32);
            }
            b"endsolid" => {
                ended = true;
                break;
            }
            other => {
                return Err(parse_error(
                    path,
                    format!("line {n}"),
                    format!("unexpected keyword {:?} in ASCII STL", show_token(other)),
                ));
            }
        }
    }
    if let Some(start) = in_loop {
        return Err(parse_error(
            path,
            format!("line {last_line} (end of file)"),
            format!("the loop opened at line {start} is not closed (truncated?)"),
        ));
    }
    if !ended {
        return Err(parse_error(
            path,
            format!("line {last_line} (end of file)"),
            "missing `endsolid` (truncated?)",
        ));
    }
    if soup.positions.len() > u32::MAX as usize {
        return Err(parse_error(path, "end of file", "too many triangles"));
    }
    Ok(soup)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(bytes: &[u8]) -> Result<crate::mesh::PolyMesh, MeshError> {
        parse_stl(bytes, Path::new("t.stl"))?
            .finish(Path::new("t.stl"))
            .map(|(m, _)| m)
    }

    const ASCII: &str = "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 0 1 0\n  endloop\n endfacet\n\
                         facet normal 0 0 1\n outer loop\n vertex 1 0 0\n vertex 1 1 0\n vertex 0 1 0\n endloop\n endfacet\nendsolid t\n";

    fn binary(tris: &[[[f32; 3]; 3]]) -> Vec<u8> {
        let mut b = vec![0u8; 80];
        b[..5].copy_from_slice(b"solid");
        b.extend_from_slice(&(tris.len() as u32).to_le_bytes());
        for t in tris {
            b.extend_from_slice(&[0u8; 12]);
            for v in t {
                for x in v {
                    b.extend_from_slice(&x.to_le_bytes());
                }
            }
            b.extend_from_slice(&[0u8; 2]);
        }
        b
    }

    #[test]
    fn ascii_welds_shared_positions() {
        let m = parse(ASCII.as_bytes()).unwrap();
        assert_eq!(m.vertex_count(), 4);
        assert_eq!(m.face_count(), 2);
        assert_eq!(m.face(0), &[0, 1, 2]);
        assert_eq!(m.face(1), &[1, 3, 2]);
    }

    #[test]
    fn binary_starting_with_solid_is_binary() {
        let b = binary(&[
            [[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]],
            [[1., 0., 0.], [1., 1., 0.], [0., 1., 0.]],
        ]);
        let m = parse(&b).unwrap();
        assert_eq!((m.vertex_count(), m.face_count()), (4, 2));
        let err = parse(&b[..b.len() - 1]).unwrap_err();
        assert!(err.to_string().contains("triangle 1"), "{err}");
    }

    #[test]
    fn upper_case_ascii_and_bom_are_ascii() {
        let upper = ASCII.to_ascii_uppercase();
        let m = parse(upper.as_bytes()).unwrap();
        assert_eq!((m.vertex_count(), m.face_count()), (4, 2));
        let with_bom = [b"\xEF\xBB\xBF".as_slice(), ASCII.as_bytes()].concat();
        assert_eq!(parse(&with_bom).unwrap(), parse(ASCII.as_bytes()).unwrap());
        // A binary file whose header says SOLID stays binary (the size matches).
        let mut b = binary(&[[[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]]]);
        b[..5].copy_from_slice(b"SOLID");
        assert_eq!(parse(&b).unwrap().face_count(), 1);
    }

    #[test]
    fn ascii_errors() {
        let cut = &ASCII[..ASCII.find("endloop").unwrap()];
        let err = parse(cut.as_bytes()).unwrap_err();
        assert!(err.to_string().contains("not closed"), "{err}");
        let cut = &ASCII[..ASCII.find("endsolid").unwrap()];
        let err = parse(cut.as_bytes()).unwrap_err();
        assert!(err.to_string().contains("endsolid"), "{err}");
        let bad = ASCII.replacen("vertex 1 0 0", "vertex 1 nan 0", 1);
        let err = parse(bad.as_bytes()).unwrap_err();
        assert!(
            matches!(err, MeshError::NonFinite { vertex: 1, .. }),
            "{err}"
        );
    }
}
