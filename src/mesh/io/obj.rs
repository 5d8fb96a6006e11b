//! Wavefront OBJ reader: `v` positions and `f` polygon faces.
//!
//! We read OBJ with our own small line parser rather than `tobj`: `tobj`
//! re-indexes vertices per object (so vertices shared between groups are
//! duplicated and vertex order changes) and its errors carry no line number.
//! Here all objects and groups merge into one mesh, vertices keep their file
//! order, and every error names its line.
//!
//! Read: `v x y z [w | r g b]` (only x, y, z are used) and `f`/`fo` lines with
//! `v`, `v/vt`, `v//vn` or `v/vt/vn` references, absolute (1-based) or
//! relative (negative). Ignored: `vt`, `vn`, `l`, `p`, `g`, `o`, `s`,
//! materials, free-form geometry and unknown keywords. `#` starts a comment.
//! Line continuations (a trailing backslash) are not supported.

use super::{
    RawMesh, lines, parse_error, parse_token, parse_xyz, show_token, strip_comment, tokens,
};
use crate::mesh::MeshError;
use std::path::Path;

/// Parses OBJ bytes. Face references become 0-based but are not range-checked
/// here, since OBJ allows faces to refer to vertices defined later.
pub(super) fn parse_obj(bytes: &[u8], path: &Path) -> Result<RawMesh, MeshError> {
    // A vertex line takes at least 7 bytes, a triangle line at least 7.
    let mut raw = RawMesh::with_capacity(bytes.len() / 24, bytes.len() / 24, bytes.len());
    for (line_no, line) in lines(bytes) {
        let mut toks = tokens(strip_comment(line));
        match toks.next() {
            Some(b"v") => {
                let p = parse_xyz(&mut toks)
                    .map_err(|m| parse_error(path, format!("line {line_no}"), m))?;
                raw.push_vertex(p);
            }
            Some(b"f") | Some(b"fo") => {
                let nv = raw.positions.len() as i64;
                let mut corners = 0usize;
                for tok in toks {
                    let index = parse_reference(tok, nv)
                        .map_err(|m| parse_error(path, format!("line {line_no}"), m))?;
                    raw.push_corner(index);
                    corners += 1;
                }
                if corners < 3 {
                    return Err(parse_error(
                        path,
                        format!("line {line_no}"),
                        format!(
                            "a face needs at least 3 vertex references, this one has {corners} (a line cut short? a polyline is written `l`)"
                        ),
                    ));
                }
                raw.end_face_at(line_no);
            }
            _ => {}
        }
    }
    Ok(raw)
}

/// Rewrites the range error of face `face` (0-based, in file order) in the
/// user's terms: finds the face's line again and the first reference on it
/// that names no vertex, and reports it as written. Scanning again only when
/// something is wrong keeps the line numbers out of the parse itself. Returns
/// `None` when the face is not found (which the caller treats as "keep the
/// original error").
pub(super) fn reference_error(bytes: &[u8], path: &Path, face: usize) -> Option<MeshError> {
    let vertex_count = lines(bytes)
        .filter(|(_, l)| tokens(strip_comment(l)).next() == Some(b"v"))
        .count() as i64;
    let mut vertices_so_far = 0i64;
    let mut faces_so_far = 0usize;
    for (line_no, line) in lines(bytes) {
        let mut toks = tokens(strip_comment(line));
        match toks.next() {
            Some(b"v") => vertices_so_far += 1,
            Some(b"f") | Some(b"fo") => {
                if faces_so_far == face {
                    return toks.find_map(|tok| {
                        let index = parse_reference(tok, vertices_so_far).ok()?;
                        if (0..vertex_count).contains(&index) {
                            return None;
                        }
                        let written: i64 = parse_token(tok.split(|&b| b == b'/').next()?)?;
                        let detail = if vertex_count == 0 {
                            "the file defines no vertices (`v x y z` lines)".to_string()
                        } else if written > 0 {
                            format!(
                                "the file defines {vertex_count} vertices; allowed: 1..={vertex_count}, or -1..=-{vertices_so_far} counting back from this line"
                            )
                        } else {
                            format!(
                                "only {vertices_so_far} vertices are defined above this line; relative references allowed here: -1..=-{vertices_so_far} (absolute: 1..={vertex_count})"
                            )
                        };
                        Some(MeshError::ReferenceOutOfRange {
                            path: path.to_path_buf(),
                            line: line_no,
                            face,
                            written,
                            detail,
                        })
                    });
                }
                faces_so_far += 1;
            }
            _ => {}
        }
    }
    None
}

/// Turns a face reference `v[/vt[/vn]]` into a 0-based vertex index, given the
/// number of vertices read so far (for relative references).
fn parse_reference(token: &[u8], vertices_so_far: i64) -> Result<i64, String> {
    let v = token.split(|&b| b == b'/').next().unwrap_or(token);
    let i: i64 = parse_token(v).ok_or_else(|| {
        format!(
            "bad vertex reference {:?} in face (expected an integer like 12, 12/3 or 12//7)",
            show_token(token)
        )
    })?;
    match i {
        0 => Err(
            "vertex reference 0 in face; OBJ indices start at 1 (or -1 for the last vertex)"
                .to_string(),
        ),
        i if i > 0 => Ok(i - 1),
        // Relative: -1 is the last vertex read so far. Out-of-range results stay
        // negative and are reported by the range check.
        i => Ok(vertices_so_far.saturating_add(i)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<crate::mesh::PolyMesh, MeshError> {
        super::super::parse_mesh(
            text.as_bytes(),
            super::super::MeshFormat::Obj,
            Path::new("t.obj"),
        )
    }

    /// Issue 43: a face line cut short is an error naming the line, not a
    /// face dropped without a word.
    #[test]
    fn a_face_with_fewer_than_three_references_names_its_line() {
        for (face, found) in [("f 1 2", 2), ("f 3", 1), ("f", 0)] {
            let text = format!("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n{face}\n");
            let e = parse(&text).expect_err(face).to_string();
            assert!(e.contains("line 5"), "{face}: {e}");
            assert!(
                e.contains("at least 3") && e.contains(&format!("{found}")),
                "{face}: {e}"
            );
        }
    }

    #[test]
    fn polygons_groups_and_relative_indices() {
        let text = "# comment\nmtllib x.mtl\no a\nv 0 0 0\nv 1 0 0 1\nv 1 1 0 0.5 0.5 0.5\nv 0 1 0\n\
                    vt 0 0\nvn 0 0 1\ng one\nf 1/1/1 2/1/1 3//1 4\ng two\nv 2 0 0\nf -4 -1 -3 # tri\nl 1 2\n";
        let m = parse(text).unwrap();
        assert_eq!(m.vertex_count(), 5);
        assert_eq!(m.face_count(), 2);
        assert_eq!(m.face(0), &[0, 1, 2, 3]);
        assert_eq!(m.face(1), &[1, 4, 2]);
    }

    #[test]
    fn crlf_and_tabs_are_accepted() {
        let m = parse("v\t0 0 0\r\nv 1 0 0\r\nv 0 1 0\r\nf 1 2 3\r\n").unwrap();
        assert_eq!(m.face(0), &[0, 1, 2]);
    }

    #[test]
    fn errors_name_the_line() {
        let err = parse("v 0 0 0\nv 1 0\n").unwrap_err();
        assert!(err.to_string().contains("line 2"), "{err}");
        let err = parse("v 0 0 0\nv 1 0 x\n").unwrap_err();
        assert!(err.to_string().contains("bad z coordinate"), "{err}");
        let err = parse("v 0 0 0\nf 1 a 2\n").unwrap_err();
        assert!(err.to_string().contains("line 2"), "{err}");
        let err = parse("v 0 0 0\nf 0 1 1\n").unwrap_err();
        assert!(err.to_string().contains("start at 1"), "{err}");
    }

    #[test]
    fn out_of_range_references() {
        let err = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n# c\nf 1 2/5/1 4\n").unwrap_err();
        match &err {
            MeshError::ReferenceOutOfRange {
                line,
                face,
                written,
                ..
            } => assert_eq!((*line, *face, *written), (6, 1, 4)),
            e => panic!("{e}"),
        }
        let text = err.to_string();
        assert!(
            text.contains("line 6") && text.contains("vertex 4"),
            "{text}"
        );
        assert!(text.contains("1..=3"), "{text}");
        let err = parse("v 0 0 0\nv 1 0 0\nf -1 -2 -3\nv 0 1 0\n").unwrap_err();
        match &err {
            MeshError::ReferenceOutOfRange {
                line,
                face,
                written,
                ..
            } => assert_eq!((*line, *face, *written), (3, 0, -3)),
            e => panic!("{e}"),
        }
        assert!(err.to_string().contains("-1..=-2"), "{err}");
        // A forward reference to a vertex defined later is fine.
        assert!(parse("v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n").is_ok());
    }

    #[test]
    fn non_finite_vertex() {
        let err = parse("v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n").unwrap_err();
        assert!(
            matches!(err, MeshError::NonFinite { vertex: 1, .. }),
            "{err}"
        );
    }
}
