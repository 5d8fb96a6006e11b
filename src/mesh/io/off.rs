//! Object File Format (OFF) reader, ASCII.
//!
//! Layout: an optional header keyword (`OFF`, or a variant such as `COFF`,
//! `NOFF`, `STOFF`), the counts `vertices faces [edges]` (on the header line or
//! the next one), one vertex per line (`x y z`, extra values such as colours
//! and normals ignored), then one face per line (`n i1 .. in`, trailing colour
//! values ignored). `#` starts a comment; blank lines are skipped.
//! Four-dimensional (`4OFF`, `nOFF`) and binary OFF are rejected.

use super::{
    RawMesh, lines, parse_error, parse_token, parse_xyz, show_token, strip_comment, tokens,
};
use crate::mesh::MeshError;
use std::path::Path;

/// Parses OFF bytes into a raw mesh (indices unchecked).
pub(super) fn parse_off(bytes: &[u8], path: &Path) -> Result<RawMesh, MeshError> {
    let at = |line: usize| format!("line {line}");
    // Non-empty, comment-stripped lines.
    let mut content = lines(bytes).filter_map(|(n, l)| {
        let l = strip_comment(l);
        tokens(l).next().is_some().then_some((n, l))
    });
    let last_line = lines(bytes).count();
    let eof = || format!("line {last_line} (end of file)");

    let Some((first_no, first)) = content.next() else {
        return Err(parse_error(
            path,
            eof(),
            "empty file; expected an OFF header or counts",
        ));
    };
    // Header keyword, and counts either on the same line or on the next one.
    let mut toks = tokens(first).peekable();
    let counts_line: (usize, Vec<&[u8]>) = match toks.peek() {
        Some(kw) if kw.ends_with(b"OFF") || kw.ends_with(b"off") => {
            let prefix = &kw[..kw.len() - 3];
            if prefix.contains(&b'4') || prefix.contains(&b'n') {
                return Err(parse_error(
                    path,
                    at(first_no),
                    format!(
                        "{:?}: only three-dimensional OFF is supported",
                        show_token(kw)
                    ),
                ));
            }
            if !prefix
                .iter()
                .all(|b| matches!(b, b'S' | b'T' | b'C' | b'N'))
            {
                return Err(parse_error(
                    path,
                    at(first_no),
                    format!("unknown header keyword {:?}", show_token(kw)),
                ));
            }
            toks.next();
            let rest: Vec<&[u8]> = toks.collect();
            if rest
                .first()
                .is_some_and(|t| t.eq_ignore_ascii_case(b"BINARY"))
            {
                return Err(parse_error(
                    path,
                    at(first_no),
                    "binary OFF is not supported; convert it to ASCII OFF, PLY or OBJ",
                ));
            }
            if rest.is_empty() {
                match content.next() {
                    Some((n, l)) => (n, tokens(l).collect()),
                    None => return Err(parse_error(path, eof(), "missing vertex and face counts")),
                }
            } else {
                (first_no, rest)
            }
        }
        _ => (first_no, tokens(first).collect()),
    };
    let (counts_no, counts) = counts_line;
    let count = |k: usize, what: &str| -> Result<usize, MeshError> {
        let tok = counts.get(k).ok_or_else(|| {
            parse_error(
                path,
                at(counts_no),
                format!("missing {what} count; expected `vertices faces [edges]`"),
            )
        })?;
        parse_token(tok).ok_or_else(|| {
            parse_error(
                path,
                at(counts_no),
                format!("bad {what} count {:?}", show_token(tok)),
            )
        })
    };
    let nv = count(0, "vertex")?;
    let nf = count(1, "face")?;

    let mut raw = RawMesh::with_capacity(nv, nf, bytes.len());
    for k in 0..nv {
        let Some((n, l)) = content.next() else {
            return Err(parse_error(
                path,
                eof(),
                format!("expected {nv} vertices, the file ends after {k} (truncated?)"),
            ));
        };
        let p = parse_xyz(&mut tokens(l))
            .map_err(|m| parse_error(path, at(n), format!("vertex {k}: {m}")))?;
        raw.push_vertex(p);
    }
    for f in 0..nf {
        let Some((n, l)) = content.next() else {
            return Err(parse_error(
                path,
                eof(),
                format!("expected {nf} faces, the file ends after {f} (truncated?)"),
            ));
        };
        let mut toks = tokens(l);
        let degree_tok = toks.next().unwrap_or_default();
        let degree: usize = parse_token(degree_tok).ok_or_else(|| {
            parse_error(
                path,
                at(n),
                format!("face {f}: bad corner count {:?}", show_token(degree_tok)),
            )
        })?;
        if degree < 3 {
            return Err(parse_error(
                path,
                at(n),
                format!(
                    "face {f}: a face needs at least 3 corners, this one has {degree} (a line cut short? OFF has no polylines)"
                ),
            ));
        }
        for c in 0..degree {
            let Some(tok) = toks.next() else {
                return Err(parse_error(
                    path,
                    at(n),
                    format!("face {f}: expected {degree} vertex indices, found {c}"),
                ));
            };
            let i: i64 = parse_token(tok).ok_or_else(|| {
                parse_error(
                    path,
                    at(n),
                    format!("face {f}: bad vertex index {:?}", show_token(tok)),
                )
            })?;
            raw.push_corner(i);
        }
        raw.end_face_at(n);
    }
    Ok(raw)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<crate::mesh::PolyMesh, MeshError> {
        parse_off(text.as_bytes(), Path::new("t.off"))?
            .finish(Path::new("t.off"))
            .map(|(m, _)| m)
    }

    #[test]
    fn header_variants() {
        let body = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n4 0 1 2 3 255 0 0\n";
        for head in [
            "OFF\n4 1 0\n",
            "OFF 4 1 0\n",
            "4 1\n",
            "# c\nOFF # x\n\n4 1 0 # y\n",
        ] {
            let m = parse(&format!("{head}{body}")).unwrap();
            assert_eq!(m.vertex_count(), 4, "{head}");
            assert_eq!(m.face(0), &[0, 1, 2, 3], "{head}");
        }
        let m =
            parse("COFF\n3 1 0\n0 0 0 1 1 1 1\n1 0 0 1 1 1 1\n0 1 0 1 1 1 1\n3 0 1 2\n").unwrap();
        assert_eq!(m.face_count(), 1);
    }

    /// Issue 43: a face of fewer than 3 corners is an error naming its
    /// line, as in OBJ, not a face dropped as degenerate.
    #[test]
    fn a_face_of_fewer_than_three_corners_names_its_line() {
        for (face, found) in [("2 0 1", 2), ("1 0", 1), ("0", 0)] {
            let text = format!("OFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n{face}\n");
            let e = parse(&text).expect_err(face).to_string();
            assert!(e.contains("line 7"), "{face}: {e}");
            assert!(
                e.contains("at least 3") && e.contains(&format!("has {found}")),
                "{face}: {e}"
            );
        }
    }

    #[test]
    fn errors() {
        let err = parse("OFF\n3 1 0\n0 0 0\n1 0 0\n").unwrap_err();
        assert!(err.to_string().contains("expected 3 vertices"), "{err}");
        let err = parse("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n").unwrap_err();
        assert!(err.to_string().contains("line 6"), "{err}");
        let err = parse("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 -1\n").unwrap_err();
        assert!(
            matches!(err, MeshError::IndexOutOfRange { index: -1, .. }),
            "{err}"
        );
        let err = parse("OFF\n3 1 0\n0 0 0\n1 inf 0\n0 1 0\n3 0 1 2\n").unwrap_err();
        assert!(
            matches!(err, MeshError::NonFinite { vertex: 1, .. }),
            "{err}"
        );
        let err = parse("4OFF\n3 1 0\n").unwrap_err();
        assert!(err.to_string().contains("three-dimensional"), "{err}");
        let err = parse("OFF BINARY\n").unwrap_err();
        assert!(err.to_string().contains("binary"), "{err}");
        let err = parse("").unwrap_err();
        assert!(err.to_string().contains("empty"), "{err}");
    }
}
