//! Stanford PLY reader (ASCII, binary little and big endian) on `ply_rs_bw`.
//!
//! Read: element `vertex` with scalar properties `x`, `y`, `z` of any numeric
//! type, and element `face` with a list property `vertex_indices` (or
//! `vertex_index`) of any integer type. Every other element and property is
//! skipped. Errors name the line (ASCII payload and header) or the element
//! (binary payload, `vertex 12`, `face 7`).

use super::{RawMesh, parse_error};
use crate::mesh::MeshError;
use ply_rs_bw::parser::{Parser, Reader};
use ply_rs_bw::ply::{
    ElementDef, Encoding, Property, PropertyAccess, PropertyAccessResult, PropertyType,
};
use std::io::Cursor;
use std::path::Path;

/// One PLY element as we need it: a position and/or an index list.
#[derive(Debug, Default)]
struct Element {
    xyz: [f64; 3],
    indices: IndexList,
}

/// A face's index list, kept in the file's integer type (no copy on read).
#[derive(Debug, Default)]
enum IndexList {
    #[default]
    None,
    Char(Vec<i8>),
    UChar(Vec<u8>),
    Short(Vec<i16>),
    UShort(Vec<u16>),
    Int(Vec<i32>),
    UInt(Vec<u32>),
}

impl IndexList {
    fn for_each(&self, mut f: impl FnMut(i64)) {
        match self {
            Self::None => {}
            Self::Char(v) => v.iter().for_each(|&i| f(i.into())),
            Self::UChar(v) => v.iter().for_each(|&i| f(i.into())),
            Self::Short(v) => v.iter().for_each(|&i| f(i.into())),
            Self::UShort(v) => v.iter().for_each(|&i| f(i.into())),
            Self::Int(v) => v.iter().for_each(|&i| f(i.into())),
            Self::UInt(v) => v.iter().for_each(|&i| f(i.into())),
        }
    }
}

fn is_index_list(name: &str) -> bool {
    name == "vertex_indices" || name == "vertex_index"
}

impl PropertyAccess for Element {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let axis = match name {
            "x" => Some(0),
            "y" => Some(1),
            "z" => Some(2),
            _ => None,
        };
        if let Some(axis) = axis {
            let value = match property {
                Property::Char(v) => v.into(),
                Property::UChar(v) => v.into(),
                Property::Short(v) => v.into(),
                Property::UShort(v) => v.into(),
                Property::Int(v) => v.into(),
                Property::UInt(v) => v.into(),
                Property::Float(v) => v.into(),
                Property::Double(v) => v,
                _ => return PropertyAccessResult::UnsupportedType,
            };
            self.xyz[axis] = value;
            return PropertyAccessResult::Set;
        }
        if is_index_list(name) {
            self.indices = match property {
                Property::ListChar(v) => IndexList::Char(v),
                Property::ListUChar(v) => IndexList::UChar(v),
                Property::ListShort(v) => IndexList::Short(v),
                Property::ListUShort(v) => IndexList::UShort(v),
                Property::ListInt(v) => IndexList::Int(v),
                Property::ListUInt(v) => IndexList::UInt(v),
                _ => return PropertyAccessResult::UnsupportedType,
            };
            return PropertyAccessResult::Set;
        }
        PropertyAccessResult::Ignored
    }
}

/// What an element of the file is for us.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Role {
    Vertex,
    Face,
    Skip,
}

/// Checks that the `vertex` and `face` elements have what we need.
fn role_of(def: &ElementDef, path: &Path) -> Result<Role, MeshError> {
    let header = "header";
    match def.name.as_str() {
        "vertex" => {
            for axis in ["x", "y", "z"] {
                match def.properties.get(axis).map(|p| &p.data_type) {
                    Some(PropertyType::Scalar(_)) => {}
                    Some(PropertyType::List(..)) => {
                        return Err(parse_error(
                            path,
                            header,
                            format!("vertex property {axis} is a list; it must be a number"),
                        ));
                    }
                    None => {
                        return Err(parse_error(
                            path,
                            header,
                            format!("element vertex has no property {axis}"),
                        ));
                    }
                }
            }
            Ok(Role::Vertex)
        }
        "face" => {
            let list = def.properties.iter().find(|(name, _)| is_index_list(name));
            match list.map(|(_, p)| &p.data_type) {
                Some(PropertyType::List(_, item)) if !is_float(item) => Ok(Role::Face),
                Some(_) => Err(parse_error(
                    path,
                    header,
                    "face property vertex_indices must be a list of integers",
                )),
                None => Err(parse_error(
                    path,
                    header,
                    "element face has no list property vertex_indices (or vertex_index)",
                )),
            }
        }
        _ => Ok(Role::Skip),
    }
}

fn is_float(t: &ply_rs_bw::ply::ScalarType) -> bool {
    use ply_rs_bw::ply::ScalarType;
    matches!(t, ScalarType::Float | ScalarType::Double)
}

/// Scalar types a PLY property may have.
const PLY_TYPES: &str = "char, uchar, short, ushort, int, uint, float, double (or int8, uint8, int16, uint16, int32, uint32, float32, float64)";

/// A sentence for a header error of `ply_rs_bw`, whose messages embed the
/// parser's `Debug` state: says what is wrong with header line `line` (the
/// parser's 1-based count) and what is allowed, judged from the line itself.
fn header_problem(bytes: &[u8], line: Option<usize>, parser_message: &str) -> String {
    let Some(line_no) = line else {
        // No line: the parser ran out of input or could not read it at all.
        let first = parser_message.lines().next().unwrap_or_default().trim();
        return if bytes.windows(10).any(|w| w == b"end_header") {
            format!("unreadable header ({first})")
        } else {
            "the header has no `end_header` line (truncated, or not a PLY file?)".into()
        };
    };
    let text = bytes
        .split(|&b| b == b'\n')
        .nth(line_no.saturating_sub(1))
        .map(|l| String::from_utf8_lossy(l).trim().to_string())
        .unwrap_or_default();
    let shown = super::show_token(text.as_bytes());
    match text.split_whitespace().next().unwrap_or_default() {
        "" => "the header has no `end_header` line (truncated?)".into(),
        _ if line_no == 1 => {
            format!("the file starts with {shown:?}; a PLY file starts with the line `ply`")
        }
        "format" => format!(
            "bad format line {shown:?}; allowed: `format ascii 1.0`, `format binary_little_endian 1.0` or `format binary_big_endian 1.0`"
        ),
        "element" => format!("bad element line {shown:?}; allowed: `element NAME COUNT`"),
        "property" => format!(
            "bad property line {shown:?}; allowed: `property TYPE NAME` or `property list COUNT_TYPE TYPE NAME`, TYPE one of {PLY_TYPES}"
        ),
        _ => format!(
            "unexpected header line {shown:?}; allowed: `format`, `element`, `property`, `comment`, `obj_info` lines and `end_header`"
        ),
    }
}

/// Parses PLY bytes into a raw mesh (indices unchecked).
/// Names the first value of an ASCII element line that is not a finite
/// number (the PLY parser's own message shows only a character position).
fn ascii_value_message(line: &str) -> Option<String> {
    let bad = line
        .split_whitespace()
        .find(|t| t.parse::<f64>().map_or(true, |v| !v.is_finite()))?;
    Some(match bad.parse::<f64>() {
        Ok(_) => format!(
            "`{bad}` is not a finite number; allowed: finite decimal numbers (no NaN or infinity)"
        ),
        Err(_) => format!("`{bad}` is not a number; allowed: decimal numbers"),
    })
}

pub(super) fn parse_ply(bytes: &[u8], path: &Path) -> Result<RawMesh, MeshError> {
    let parser = Parser::<Element>::new();
    let mut reader = Reader::new(Cursor::new(bytes));
    let header = parser.read_header(&mut reader).map_err(|e| {
        let location = e
            .line()
            .map_or_else(|| "header".to_string(), |l| format!("line {l} (header)"));
        parse_error(
            path,
            location,
            header_problem(bytes, e.line(), &e.to_string()),
        )
    })?;
    let mut roles = Vec::with_capacity(header.elements.len());
    for def in header.elements.values() {
        roles.push(role_of(def, path)?);
    }
    let count_of = |role: Role| {
        header
            .elements
            .values()
            .zip(&roles)
            .find(|(_, r)| **r == role)
            .map_or(0, |(d, _)| d.count)
    };
    let mut raw = RawMesh::with_capacity(count_of(Role::Vertex), count_of(Role::Face), bytes.len());
    let mut cursor = reader.into_inner();
    let payload_start = cursor.position() as usize;
    // ASCII payload: we read lines ourselves to know their numbers.
    let mut line_no = bytes[..payload_start.min(bytes.len())]
        .iter()
        .filter(|&&b| b == b'\n')
        .count();
    let mut ascii_lines = bytes[payload_start.min(bytes.len())..].split(|&b| b == b'\n');
    let mut remaining = roles.iter().filter(|r| **r != Role::Skip).count();

    for (def, &role) in header.elements.values().zip(&roles) {
        if remaining == 0 {
            // Trailing elements (edges, materials, ...) are not needed.
            break;
        }
        if def.properties.is_empty() {
            // Nothing to read (and a huge count must not make us spin).
            continue;
        }
        for k in 0..def.count {
            let element = match header.encoding {
                Encoding::Ascii => {
                    // Skip blank lines; a missing line means the file is truncated.
                    let line = loop {
                        let Some(l) = ascii_lines.next() else {
                            return Err(parse_error(
                                path,
                                format!("line {} (end of file)", line_no + 1),
                                format!(
                                    "expected {} {} elements, the file ends after {k} (truncated?)",
                                    def.count, def.name
                                ),
                            ));
                        };
                        line_no += 1;
                        if l.iter().any(|b| !b.is_ascii_whitespace()) {
                            break l;
                        }
                    };
                    let text = std::str::from_utf8(line).map_err(|_| {
                        parse_error(path, format!("line {line_no}"), "not ASCII text")
                    })?;
                    parser.read_ascii_element(text, def).map_err(|e| {
                        parse_error(
                            path,
                            format!("line {line_no} ({} {k})", def.name),
                            ascii_value_message(text).unwrap_or_else(|| e.to_string()),
                        )
                    })?
                }
                Encoding::BinaryLittleEndian | Encoding::BinaryBigEndian => {
                    let read = if header.encoding == Encoding::BinaryLittleEndian {
                        parser.read_little_endian_element(&mut cursor, def)
                    } else {
                        parser.read_big_endian_element(&mut cursor, def)
                    };
                    read.map_err(|e| {
                        let message = if e.kind() == std::io::ErrorKind::UnexpectedEof {
                            format!(
                                "the file ends inside {} {k} of {} (truncated?)",
                                def.name, def.count
                            )
                        } else {
                            e.to_string()
                        };
                        parse_error(
                            path,
                            format!("{} {k} (byte {})", def.name, cursor.position()),
                            message,
                        )
                    })?
                }
            };
            match role {
                Role::Vertex => raw.push_vertex(element.xyz.map(|v| v as f32)),
                Role::Face => {
                    let mut corners = 0usize;
                    element.indices.for_each(|_| corners += 1);
                    if corners < 3 {
                        let location = match header.encoding {
                            Encoding::Ascii => format!("line {line_no} ({} {k})", def.name),
                            _ => format!("{} {k}", def.name),
                        };
                        return Err(parse_error(
                            path,
                            location,
                            format!(
                                "a face needs at least 3 corners, this one has {corners} (cut short? a polyline is an edge element)"
                            ),
                        ));
                    }
                    element.indices.for_each(|i| raw.push_corner(i));
                    if header.encoding == Encoding::Ascii {
                        raw.end_face_at(line_no);
                    } else {
                        raw.end_face();
                    }
                }
                Role::Skip => {}
            }
        }
        if role != Role::Skip {
            remaining -= 1;
        }
    }
    Ok(raw)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(bytes: &[u8]) -> Result<crate::mesh::PolyMesh, MeshError> {
        parse_ply(bytes, Path::new("t.ply"))?
            .finish(Path::new("t.ply"))
            .map(|(m, _)| m)
    }

    const ASCII: &str = "ply\nformat ascii 1.0\ncomment hi\nelement vertex 4\nproperty double x\nproperty double y\n\
        property double z\nproperty uchar red\nelement face 1\nproperty list uchar uint vertex_index\nproperty int flags\n\
        end_header\n0 0 0 1\n1 0 0 2\n1 1 0 3\n0 1 0 4\n4 0 1 2 3 7\n";

    fn binary(big: bool) -> Vec<u8> {
        let fmt = if big {
            "binary_big_endian"
        } else {
            "binary_little_endian"
        };
        let mut b = format!(
            "ply\nformat {fmt} 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
             element face 1\nproperty list uchar short vertex_indices\nelement edge 1\nproperty int a\nend_header\n"
        )
        .into_bytes();
        for p in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
            for x in p {
                b.extend_from_slice(&if big {
                    x.to_be_bytes()
                } else {
                    x.to_le_bytes()
                });
            }
        }
        b.push(3);
        for i in [0i16, 1, 2] {
            b.extend_from_slice(&if big {
                i.to_be_bytes()
            } else {
                i.to_le_bytes()
            });
        }
        b
    }

    /// Issue 43: NaN or infinity in an ASCII PLY names the value, not only
    /// "Couldn't parse element line".
    #[test]
    fn a_non_finite_ascii_value_is_named() {
        for bad in ["nan", "inf", "-Infinity"] {
            let text = ASCII.replace("1 0 0 2", &format!("1 {bad} 0 2"));
            let e = parse(text.as_bytes()).expect_err(bad).to_string();
            assert!(e.contains("line 14"), "{bad}: {e}");
            assert!(
                e.contains(&format!("`{bad}`")) && e.contains("finite"),
                "{bad}: {e}"
            );
        }
    }

    #[test]
    fn ascii_with_extra_properties() {
        let m = parse(ASCII.as_bytes()).unwrap();
        assert_eq!(m.vertex_count(), 4);
        assert_eq!(m.face(0), &[0, 1, 2, 3]);
        assert_eq!(m.positions[2], glam::Vec3::new(1.0, 1.0, 0.0));
    }

    #[test]
    fn binary_both_endians() {
        for big in [false, true] {
            let m = parse(&binary(big)).unwrap();
            assert_eq!(m.face(0), &[0, 1, 2]);
            assert_eq!(m.positions[1], glam::Vec3::X);
        }
    }

    /// Issue 43: a face of fewer than 3 corners is an error naming its
    /// line, as in OBJ and OFF, not a face dropped as degenerate.
    #[test]
    fn a_face_of_fewer_than_three_corners_names_its_line() {
        let bad = ASCII.replace("4 0 1 2 3 7", "2 0 1 7");
        let err = parse(bad.as_bytes()).unwrap_err().to_string();
        assert!(
            err.contains("line 17") && err.contains("at least 3") && err.contains("has 2"),
            "{err}"
        );
    }

    #[test]
    fn errors_name_line_or_element() {
        let cut = &ASCII[..ASCII.len() - 4];
        let err = parse(cut.as_bytes()).unwrap_err();
        assert!(err.to_string().contains("line 17"), "{err}");
        let b = binary(false);
        let err = parse(&b[..b.len() - 1]).unwrap_err();
        assert!(err.to_string().contains("face 0"), "{err}");
        let bad = ASCII.replace("4 0 1 2 3 7", "4 0 1 2 9 7");
        let err = parse(bad.as_bytes()).unwrap_err();
        assert!(
            matches!(err, MeshError::IndexOutOfRange { index: 9, .. }),
            "{err}"
        );
        let bad = ASCII.replace("property double z", "property doubel z");
        let err = parse(bad.as_bytes()).unwrap_err().to_string();
        assert!(
            err.contains("line 7") && err.contains("bad property line"),
            "{err}"
        );
        assert!(
            err.contains("uchar") && !err.contains("ParseError"),
            "{err}"
        );
        let bad = ASCII.replace("property double z\n", "");
        let err = parse(bad.as_bytes()).unwrap_err();
        assert!(err.to_string().contains("no property z"), "{err}");
    }
}
