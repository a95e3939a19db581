//! PLY (Stanford polygon file), ASCII and binary little / big endian.
//!
//! The header (text, ending at `end_header`) declares elements in file order, each with a count
//! and typed properties (scalars, or lists with a count type and an item type). Positions are
//! the `x`, `y`, `z` properties of the `vertex` element (any numeric type, read into `f64`:
//! `double` exactly, ASCII as the decimal's nearest `f64`); faces are the `vertex_indices` (or
//! `vertex_index`) list of the `face` element, 0-based. Every other property (normals,
//! colours, texture coordinates) and element (edges, materials) is read past. Vertex and face
//! order are the file's.
//!
//! Counts are checked against the bytes left before anything is reserved: a binary element
//! needs its fixed-size part per record, an ASCII one at least 2 bytes per value. After the last
//! element only whitespace may follow (ASCII) or nothing (binary): more data means the header's
//! counts or types do not describe the file.

use std::path::Path;

use super::text::{parse_f64, parse_i64, shown, Lines, Tokens};
use super::{
    finish, located, push_fan, reserve_for, vertex_index, Encoding, SurfaceFormat, SurfaceInfo,
};
use crate::mesh::{MeshError, TriMesh};

/// A PLY scalar type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(name: &[u8]) -> Option<Scalar> {
        Some(match name {
            b"char" | b"int8" => Scalar::I8,
            b"uchar" | b"uint8" => Scalar::U8,
            b"short" | b"int16" => Scalar::I16,
            b"ushort" | b"uint16" => Scalar::U16,
            b"int" | b"int32" => Scalar::I32,
            b"uint" | b"uint32" => Scalar::U32,
            b"float" | b"float32" => Scalar::F32,
            b"double" | b"float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// The range of an integer type, for ASCII values.
    fn range(self) -> (i64, i64) {
        match self {
            Scalar::I8 => (i8::MIN.into(), i8::MAX.into()),
            Scalar::U8 => (0, u8::MAX.into()),
            Scalar::I16 => (i16::MIN.into(), i16::MAX.into()),
            Scalar::U16 => (0, u16::MAX.into()),
            Scalar::I32 => (i32::MIN.into(), i32::MAX.into()),
            Scalar::U32 => (0, u32::MAX.into()),
            Scalar::F32 | Scalar::F64 => (i64::MIN, i64::MAX),
        }
    }
}

#[derive(Clone, Debug)]
enum Kind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Clone, Debug)]
struct Property {
    name: String,
    kind: Kind,
}

#[derive(Clone, Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
    /// Header line of the `element` record (errors about its count point there).
    line: usize,
}

impl Element {
    fn scalar(&self, name: &str) -> Option<usize> {
        self.props
            .iter()
            .position(|p| p.name == name && matches!(p.kind, Kind::Scalar(_)))
    }

    /// Bytes of one binary record when every list is empty: the least a record can take.
    fn min_binary_bytes(&self) -> usize {
        self.props
            .iter()
            .map(|p| match p.kind {
                Kind::Scalar(s) => s.size(),
                Kind::List { count, .. } => count.size(),
            })
            .sum()
    }
}

struct Header {
    encoding: Encoding,
    elements: Vec<Element>,
    /// Offset of the first byte after `end_header`'s line.
    body: usize,
    /// Line number of the first body line (ASCII).
    body_line: usize,
}

/// Parses a PLY file; errors name `line N` (header, ASCII body) or `byte N` (binary body) and
/// the element and record.
pub fn parse_ply(bytes: &[u8], file: &Path) -> Result<(TriMesh, SurfaceInfo), MeshError> {
    let header = parse_header(bytes, file)?;
    let vertex = header.elements.iter().position(|e| e.name == "vertex");
    let Some(vertex) = vertex else {
        return Err(located(
            file,
            "line 1",
            "the header declares no `vertex` element",
        ));
    };
    let v_el = &header.elements[vertex];
    let vertex_count = v_el.count;
    let mut xyz = [0usize; 3];
    for (slot, axis) in xyz.iter_mut().zip(["x", "y", "z"]) {
        *slot = v_el.scalar(axis).ok_or_else(|| {
            located(
                file,
                format!("line {}", v_el.line),
                format!("element `vertex` has no scalar property `{axis}`"),
            )
        })?;
    }
    let face = header.elements.iter().position(|e| e.name == "face");
    let mut indices = None;
    if let Some(f) = face {
        let f_el = &header.elements[f];
        let list = f_el.props.iter().position(|p| {
            (p.name == "vertex_indices" || p.name == "vertex_index")
                && matches!(p.kind, Kind::List { .. })
        });
        let Some(list) = list else {
            return Err(located(
                file,
                format!("line {}", f_el.line),
                "element `face` has no `vertex_indices` list property",
            ));
        };
        if let Kind::List { count, item } = f_el.props[list].kind {
            if !count.is_integer() || !item.is_integer() {
                return Err(located(
                    file,
                    format!("line {}", f_el.line),
                    "the `vertex_indices` list must have integer count and index types",
                ));
            }
        }
        indices = Some(list);
    }
    let encoding = header.encoding;
    let mut reader = Reader {
        file,
        body: match encoding {
            Encoding::Text => Body::Text(Tokens::new(&bytes[header.body..], header.body_line)),
            _ => Body::Binary {
                bytes,
                pos: header.body,
                big_endian: encoding == Encoding::BinaryBigEndian,
            },
        },
    };
    let mut info = SurfaceInfo::new(SurfaceFormat::Ply, encoding);
    let mut mesh = TriMesh::default();
    let mut corners: Vec<u32> = Vec::new();
    let mut written: Vec<i64> = Vec::new();
    for (e, el) in header.elements.iter().enumerate() {
        reader.check_room(el)?;
        let left = reader.bytes_left();
        let is_vertex = e == vertex;
        let is_face = Some(e) == face;
        if is_vertex {
            mesh.positions = reserve_for(el.count, left, el.min_record_bytes(encoding));
        } else if is_face {
            // A triangle takes at least 8 bytes ("3 0 1 2\n", or 1 + 3 bytes … with u8 types).
            mesh.faces = reserve_for(el.count, left, el.min_record_bytes(encoding).max(8));
        } else {
            info.skipped = info.skipped.saturating_add(el.count);
        }
        if el.props.is_empty() {
            // Records of nothing: a count of 10^18 must not be looped over.
            continue;
        }
        for r in 0..el.count {
            let mut p = [0.0f64; 3];
            for (k, prop) in el.props.iter().enumerate() {
                let at = Where {
                    element: &el.name,
                    record: r,
                    property: &prop.name,
                };
                match prop.kind {
                    Kind::Scalar(ty) => {
                        if is_vertex {
                            if let Some(axis) = xyz.iter().position(|&i| i == k) {
                                p[axis] = reader.float(ty, &at)?;
                                continue;
                            }
                        }
                        reader.skip(ty, &at)?;
                    }
                    Kind::List { count, item } => {
                        let n = reader.list_len(count, item, &at)?;
                        if is_face && indices == Some(k) {
                            written.clear();
                            for _ in 0..n {
                                written.push(reader.int(item, &at)?);
                            }
                            if n < 3 {
                                return Err(reader.error(
                                    &at,
                                    format!("face has {n} vertices, need at least 3"),
                                ));
                            }
                            let first = mesh.faces.len();
                            corners.clear();
                            for &w in &written {
                                // Against the announced count: a `face` element may come
                                // before `vertex`, and a file that parses has that many.
                                corners.push(vertex_index(file, w, vertex_count, first)?);
                            }
                            push_fan(&mut mesh.faces, &corners, &mut info);
                        } else {
                            for _ in 0..n {
                                reader.skip(item, &at)?;
                            }
                        }
                    }
                }
            }
            if is_vertex {
                mesh.positions.push(p);
            }
        }
        if is_vertex || is_face {
            let used = if is_vertex { 3 } else { 1 };
            info.skipped = info
                .skipped
                .saturating_add(el.count.saturating_mul(el.props.len() - used));
        }
    }
    reader.finish()?;
    finish(mesh, info, file)
}

impl Element {
    /// The least bytes one record takes in the body: a bound for reserving.
    fn min_record_bytes(&self, encoding: Encoding) -> usize {
        match encoding {
            // A value and a separator.
            Encoding::Text => 2 * self.props.len(),
            _ => self.min_binary_bytes(),
        }
    }
}

fn parse_header(bytes: &[u8], file: &Path) -> Result<Header, MeshError> {
    let mut lines = Lines::new(bytes, 1);
    let at = |n: usize| format!("line {n}");
    match lines.next() {
        Some((_, line)) if line.trim_ascii_end() == b"ply" => {}
        _ => {
            return Err(located(
                file,
                at(1),
                "not a PLY file: the first line is not `ply`",
            ))
        }
    }
    let mut encoding = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some((n, line)) = lines.next() else {
            return Err(located(
                file,
                at(lines.line()),
                "the header has no `end_header` line",
            ));
        };
        let text = std::str::from_utf8(line).map_err(|_| {
            located(
                file,
                at(n),
                "the header is not text (binary data before `end_header`)",
            )
        })?;
        let words: Vec<&str> = text.split_ascii_whitespace().collect();
        let bad = |what: String| located(file, at(n), what);
        match words.as_slice() {
            [] => {}
            ["comment" | "obj_info", ..] => {}
            ["format", kind, _version] => {
                encoding = Some(match *kind {
                    "ascii" => Encoding::Text,
                    "binary_little_endian" => Encoding::BinaryLittleEndian,
                    "binary_big_endian" => Encoding::BinaryBigEndian,
                    other => {
                        return Err(bad(format!(
                            "unknown PLY format {}",
                            shown(other.as_bytes())
                        )))
                    }
                });
            }
            ["element", name, count] => {
                let count = parse_i64(count.as_bytes())
                    .ok()
                    .and_then(|c| usize::try_from(c).ok())
                    .ok_or_else(|| {
                        bad(format!(
                            "element `{name}` count {} is not a non-negative integer",
                            shown(count.as_bytes())
                        ))
                    })?;
                if elements.iter().any(|e| e.name == *name) {
                    return Err(bad(format!("element `{name}` is declared twice")));
                }
                elements.push(Element {
                    name: name.to_string(),
                    count,
                    props: Vec::new(),
                    line: n,
                });
            }
            ["property", rest @ ..] => {
                let Some(el) = elements.last_mut() else {
                    return Err(bad("`property` before any `element`".to_string()));
                };
                let ty = |name: &str| {
                    Scalar::parse(name.as_bytes()).ok_or_else(|| {
                        bad(format!("unknown property type {}", shown(name.as_bytes())))
                    })
                };
                let prop = match rest {
                    ["list", count, item, name] => Property {
                        name: name.to_string(),
                        kind: Kind::List {
                            count: ty(count)?,
                            item: ty(item)?,
                        },
                    },
                    [scalar, name] if *scalar != "list" => Property {
                        name: name.to_string(),
                        kind: Kind::Scalar(ty(scalar)?),
                    },
                    _ => {
                        return Err(bad(
                            "a property is `property TYPE NAME` or `property list COUNT_TYPE ITEM_TYPE NAME`"
                                .to_string(),
                        ))
                    }
                };
                if el.props.iter().any(|p| p.name == prop.name) {
                    return Err(bad(format!(
                        "element `{}` declares property `{}` twice",
                        el.name, prop.name
                    )));
                }
                el.props.push(prop);
            }
            ["end_header"] => break,
            [word, ..] => {
                return Err(bad(format!(
                    "unknown header line starting with {}",
                    shown(word.as_bytes())
                )))
            }
        }
    }
    let Some(encoding) = encoding else {
        return Err(located(file, at(2), "the header has no `format` line"));
    };
    Ok(Header {
        encoding,
        elements,
        body: bytes.len() - lines.rest(),
        body_line: lines.line(),
    })
}

/// Where a value is, for messages: `element vertex 12, property y`.
struct Where<'a> {
    element: &'a str,
    record: usize,
    property: &'a str,
}

impl std::fmt::Display for Where<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} {}, property `{}`",
            self.element, self.record, self.property
        )
    }
}

enum Body<'a> {
    Text(Tokens<'a>),
    Binary {
        bytes: &'a [u8],
        pos: usize,
        big_endian: bool,
    },
}

struct Reader<'a> {
    file: &'a Path,
    body: Body<'a>,
}

/// A binary value before conversion: integers exactly, floats as `f64`.
enum Value {
    Int(i64),
    Float(f64),
}

impl<'a> Reader<'a> {
    fn bytes_left(&self) -> usize {
        match &self.body {
            Body::Text(t) => t.rest(),
            Body::Binary { bytes, pos, .. } => bytes.len() - pos,
        }
    }

    /// `line N` or `byte N` of the next value.
    fn position(&self) -> String {
        match &self.body {
            Body::Text(t) => format!("line {}", t.line()),
            Body::Binary { pos, .. } => format!("byte {pos}"),
        }
    }

    fn error(&self, at: &Where<'_>, what: String) -> MeshError {
        located(self.file, self.position(), format!("{at}: {what}"))
    }

    /// Refuses an element whose announced count cannot fit in the bytes left.
    fn check_room(&self, el: &Element) -> Result<(), MeshError> {
        let per = el.min_record_bytes(match self.body {
            Body::Text(_) => Encoding::Text,
            Body::Binary { .. } => Encoding::BinaryLittleEndian,
        });
        let left = self.bytes_left();
        // + 1: the last value of a text body may end the file without a separator.
        let fits = el
            .count
            .checked_mul(per)
            .is_some_and(|need| need <= left.saturating_add(1));
        if fits || per == 0 {
            return Ok(());
        }
        Err(located(
            self.file,
            format!("line {}", el.line),
            format!(
                "the header announces {} `{}` elements of at least {per} bytes each, but only {left} \
                 bytes follow (truncated file or wrong count)",
                el.count, el.name
            ),
        ))
    }

    /// The next text token, or an error naming the value that is missing.
    fn token(&mut self, at: &Where<'_>) -> Result<(usize, &'a [u8]), MeshError> {
        let Body::Text(t) = &mut self.body else {
            return Err(located(
                self.file,
                "byte 0",
                "internal: text read of a binary body",
            ));
        };
        match t.next_token() {
            Some(tok) => Ok(tok),
            None => {
                let line = t.line();
                Err(located(
                    self.file,
                    format!("line {line}"),
                    format!(
                        "{at}: the file ends here (truncated, or the header's counts are wrong)"
                    ),
                ))
            }
        }
    }

    fn binary(&mut self, ty: Scalar, at: &Where<'_>) -> Result<Value, MeshError> {
        let file = self.file;
        let Body::Binary {
            bytes,
            pos,
            big_endian,
        } = &mut self.body
        else {
            return Err(located(
                file,
                "byte 0",
                "internal: binary read of a text body",
            ));
        };
        let size = ty.size();
        let Some(b) = pos.checked_add(size).and_then(|end| bytes.get(*pos..end)) else {
            return Err(located(
                file,
                format!("byte {pos}"),
                format!(
                    "{at}: the file ends inside this value ({} of {size} bytes; truncated)",
                    bytes.len() - *pos
                ),
            ));
        };
        *pos += size;
        let mut buf = [0u8; 8];
        buf[..size].copy_from_slice(b);
        if *big_endian {
            buf[..size].reverse();
        }
        let [b0, b1, b2, b3, ..] = buf;
        Ok(match ty {
            Scalar::I8 => Value::Int(i8::from_le_bytes([b0]).into()),
            Scalar::U8 => Value::Int(b0.into()),
            Scalar::I16 => Value::Int(i16::from_le_bytes([b0, b1]).into()),
            Scalar::U16 => Value::Int(u16::from_le_bytes([b0, b1]).into()),
            Scalar::I32 => Value::Int(i32::from_le_bytes([b0, b1, b2, b3]).into()),
            Scalar::U32 => Value::Int(u32::from_le_bytes([b0, b1, b2, b3]).into()),
            Scalar::F32 => Value::Float(f32::from_le_bytes([b0, b1, b2, b3]).into()),
            Scalar::F64 => Value::Float(f64::from_le_bytes(buf)),
        })
    }

    /// A coordinate of any numeric type.
    fn float(&mut self, ty: Scalar, at: &Where<'_>) -> Result<f64, MeshError> {
        if matches!(self.body, Body::Binary { .. }) {
            return Ok(match self.binary(ty, at)? {
                // Integers of at most 32 bits are exact in f64.
                Value::Int(i) => i as f64,
                Value::Float(x) => x,
            });
        }
        let (line, tok) = self.token(at)?;
        parse_f64(tok).ok_or_else(|| {
            located(
                self.file,
                format!("line {line}"),
                format!("{at}: {} is not a number", shown(tok)),
            )
        })
    }

    /// An integer of an integer type (checked by the header), range-checked in ASCII.
    fn int(&mut self, ty: Scalar, at: &Where<'_>) -> Result<i64, MeshError> {
        if matches!(self.body, Body::Binary { .. }) {
            return Ok(match self.binary(ty, at)? {
                Value::Int(i) => i,
                // Not reached: list types are checked to be integers.
                Value::Float(x) => x as i64,
            });
        }
        let (line, tok) = self.token(at)?;
        let (lo, hi) = ty.range();
        match parse_i64(tok) {
            Ok(i) if (lo..=hi).contains(&i) => Ok(i),
            _ => Err(located(
                self.file,
                format!("line {line}"),
                format!(
                    "{at}: {} is not an integer of its type ({lo}..={hi})",
                    shown(tok)
                ),
            )),
        }
    }

    /// A list's length; in binary, checked against the bytes left before its items are read.
    fn list_len(
        &mut self,
        count: Scalar,
        item: Scalar,
        at: &Where<'_>,
    ) -> Result<usize, MeshError> {
        let n = if count.is_integer() {
            self.int(count, at)?
        } else {
            let x = self.float(count, at)?;
            if x.fract() != 0.0 || !(0.0..=u32::MAX as f64).contains(&x) {
                return Err(self.error(at, format!("list length {x} is not a count")));
            }
            x as i64
        };
        let n = usize::try_from(n)
            .map_err(|_| self.error(at, format!("list length {n} is negative")))?;
        if let Body::Binary { .. } = self.body {
            let left = self.bytes_left();
            if n.checked_mul(item.size()).is_none_or(|need| need > left) {
                return Err(self.error(
                    at,
                    format!(
                        "a list of {n} items does not fit in the {left} bytes left (truncated?)"
                    ),
                ));
            }
        }
        Ok(n)
    }

    /// Reads past a value that is not used; in text any token will do (colours written as
    /// floats for a `uchar` property are not worth refusing a file for).
    fn skip(&mut self, ty: Scalar, at: &Where<'_>) -> Result<(), MeshError> {
        match self.body {
            Body::Binary { .. } => self.binary(ty, at).map(|_| ()),
            Body::Text(_) => self.token(at).map(|_| ()),
        }
    }

    /// Nothing but whitespace (ASCII) or nothing (binary) after the last element.
    fn finish(mut self) -> Result<(), MeshError> {
        match &mut self.body {
            Body::Text(t) => match t.next_token() {
                None => Ok(()),
                Some((line, tok)) => Err(located(
                    self.file,
                    format!("line {line}"),
                    format!(
                        "{} after the last element the header announces (wrong counts?)",
                        shown(tok)
                    ),
                )),
            },
            Body::Binary { bytes, pos, .. } if *pos < bytes.len() => Err(located(
                self.file,
                format!("byte {pos}"),
                format!(
                    "{} bytes after the last element the header announces (wrong counts or types?)",
                    bytes.len() - *pos
                ),
            )),
            Body::Binary { .. } => Ok(()),
        }
    }
}
