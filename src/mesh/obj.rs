//! Wavefront OBJ input and output that keep the file's vertex and face order.
//!
//! General OBJ loaders (e.g. `tobj`) renumber vertices in first-use order and drop unused ones.
//! Our output contract is "OUT.obj keeps the input's `v` and `f` order", so vertex `i` of the
//! [`TriMesh`] is always the `i`-th `v` record of the file, unreferenced vertices included, and
//! faces come in file order. Only `v` and `f` records carry meaning; every other record is skipped.
//!
//! Writers produce text; [`crate::files::Outputs`] commits it with the run's other outputs.

use std::io;
use std::path::Path;

use super::{MeshError, TriMesh};

/// What reading an OBJ file did besides producing the mesh.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ObjInfo {
    /// `f` records with more than 3 vertices; each was fan-triangulated into (n − 2) triangles
    /// `(a0, a_i, a_{i+1})`, so source faces then map one-to-many onto [`TriMesh::faces`].
    pub polygons_triangulated: usize,
    /// Non-comment records other than `v` and `f` (vt, vn, g, o, s, usemtl, mtllib, l, p, …).
    pub ignored_records: usize,
    /// Number of `f` records in the file (equals the triangle count when nothing was triangulated).
    pub source_face_count: usize,
}

/// Reads an OBJ file into a triangle mesh, keeping vertex order, face order and unused vertices
/// (at most [`crate::files::DEFAULT_MAX_ELEMENTS`] faces' worth of bytes).
pub fn read_obj(path: &Path) -> Result<TriMesh, MeshError> {
    read_obj_with_info(path, crate::files::DEFAULT_MAX_ELEMENTS).map(|(mesh, _)| mesh)
}

/// [`read_obj`] plus what was triangulated or skipped, for a file of at most `max_faces`
/// faces' worth of bytes ([`crate::files::BYTES_PER_ELEMENT`] each; the face count itself is
/// checked by validation).
pub fn read_obj_with_info(path: &Path, max_faces: usize) -> Result<(TriMesh, ObjInfo), MeshError> {
    // Other mesh formats would parse as an OBJ with no faces; name them instead.
    let format = super::formats::SurfaceFormat::from_path(path)?;
    if format != super::formats::SurfaceFormat::Obj {
        return Err(MeshError::Read {
            file: path.to_path_buf(),
            reason: format!(
                "a {} file, not OBJ (mesh::read_surface reads both)",
                format.name()
            ),
        });
    }
    let bytes = super::formats::read_input(path, max_faces, format)?;
    parse_obj_with_info(bytes, path)
}

/// Parses OBJ text already in memory; `file` is only used to name the source in errors.
pub fn parse_obj(text: impl AsRef<[u8]>, file: &Path) -> Result<TriMesh, MeshError> {
    parse_obj_with_info(text, file).map(|(mesh, _)| mesh)
}

/// [`parse_obj`] plus what was triangulated or skipped.
///
/// Errors: `Read` (with the 1-based line number in `reason`) for binary or non-UTF-8 data,
/// unparseable numbers, vertices with fewer than 3 coordinates, faces with fewer than 3 vertices
/// and index 0; `IndexOutOfRange` for indices past the vertex list (`face` is the 0-based index of
/// the first triangle the record produces, `index` the index as written in the file); `Empty`
/// when there are no faces. Non-finite coordinates are kept and left to validation, which names
/// the vertex.
pub fn parse_obj_with_info(
    text: impl AsRef<[u8]>,
    file: &Path,
) -> Result<(TriMesh, ObjInfo), MeshError> {
    let bytes = text.as_ref();
    let text = decode_text(bytes, file)?;
    let mut parser = Parser {
        file,
        mesh: TriMesh::default(),
        info: ObjInfo::default(),
        corners: Vec::new(),
        forward: Vec::new(),
    };

    // Records may continue over several physical lines with a trailing backslash.
    let mut joined = String::new();
    let mut record_line = 0usize;
    // Lines end in \n, \r\n or a lone \r (classic Mac OS files): normalise to \n.
    let text: std::borrow::Cow<'_, str> = if text.contains('\r') {
        std::borrow::Cow::Owned(text.replace("\r\n", "\n").replace('\r', "\n"))
    } else {
        std::borrow::Cow::Borrowed(text)
    };
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        if let Some(head) = line.trim_end().strip_suffix('\\') {
            if joined.is_empty() {
                record_line = line_no;
            }
            joined.push_str(head);
            joined.push(' ');
            continue;
        }
        if joined.is_empty() {
            parser.record(line, line_no)?;
        } else {
            joined.push_str(line);
            let record = std::mem::take(&mut joined);
            parser.record(&record, record_line)?;
        }
    }
    if !joined.is_empty() {
        let record = std::mem::take(&mut joined);
        parser.record(&record, record_line)?;
    }
    parser.finish()
}

/// Rejects binary data and non-UTF-8 text, naming the line of the first bad byte.
fn decode_text<'a>(bytes: &'a [u8], file: &Path) -> Result<&'a str, MeshError> {
    let line_of = |pos: usize| 1 + bytes[..pos].iter().filter(|&&b| b == b'\n').count();
    // Control characters other than tab, newline, vertical tab, form feed and carriage return
    // never occur in OBJ text; they mean the file is binary (e.g. a binary STL or PLY).
    let is_binary =
        |b: u8| b < 0x20 && !matches!(b, b'\t' | b'\n' | 0x0b | 0x0c | b'\r') || b == 0x7f;
    if let Some(pos) = bytes.iter().position(|&b| is_binary(b)) {
        return Err(read_error(
            file,
            line_of(pos),
            format!(
                "binary data (byte 0x{:02x}), not an OBJ text file",
                bytes[pos]
            ),
        ));
    }
    let text = std::str::from_utf8(bytes).map_err(|e| {
        read_error(
            file,
            line_of(e.valid_up_to()),
            "not UTF-8 text (binary file?)".to_string(),
        )
    })?;
    Ok(text.strip_prefix('\u{feff}').unwrap_or(text))
}

fn read_error(file: &Path, line: usize, what: String) -> MeshError {
    MeshError::Read {
        file: file.to_path_buf(),
        reason: format!("line {line}: {what}"),
    }
}

struct Parser<'a> {
    file: &'a Path,
    mesh: TriMesh,
    info: ObjInfo,
    /// Scratch: the 0-based vertex indices of the current `f` record.
    corners: Vec<u32>,
    /// (first triangle of the record, index as written) for positive indices past the vertices
    /// read so far; checked once the whole file is read.
    forward: Vec<(usize, i64)>,
}

impl Parser<'_> {
    fn record(&mut self, line: &str, line_no: usize) -> Result<(), MeshError> {
        // Everything after '#' is a comment (whole-line or trailing).
        let data = match line.find('#') {
            Some(pos) => &line[..pos],
            None => line,
        };
        let mut tokens = data.split_ascii_whitespace();
        match tokens.next() {
            None => Ok(()),
            Some("v") => self.vertex(tokens, line_no),
            Some("f") => self.face(tokens, line_no),
            Some(_) => {
                self.info.ignored_records += 1;
                Ok(())
            }
        }
    }

    /// `v x y z [w]` or `v x y z r g b`: the first three numbers are the position; extra
    /// components must still be numbers.
    fn vertex<'t>(
        &mut self,
        tokens: impl Iterator<Item = &'t str>,
        line_no: usize,
    ) -> Result<(), MeshError> {
        let mut xyz = [0.0f64; 3];
        let mut n = 0usize;
        for tok in tokens {
            let value: f64 = tok.parse().map_err(|_| {
                read_error(
                    self.file,
                    line_no,
                    format!("vertex coordinate {tok:?} is not a number"),
                )
            })?;
            if n < 3 {
                xyz[n] = value;
            }
            n += 1;
        }
        if n < 3 {
            return Err(read_error(
                self.file,
                line_no,
                format!("vertex has {n} coordinates, need 3"),
            ));
        }
        self.mesh.positions.push(xyz);
        Ok(())
    }

    /// `f a b c …` with `a`, `a/t`, `a/t/n` or `a//n` corners; negative indices count back from
    /// the last vertex defined so far. Positive indices are range-checked at the end of the file,
    /// so forward references (vertices after the face) are accepted.
    fn face<'t>(
        &mut self,
        tokens: impl Iterator<Item = &'t str>,
        line_no: usize,
    ) -> Result<(), MeshError> {
        let first_triangle = self.mesh.faces.len();
        let defined = self.mesh.positions.len();
        self.corners.clear();
        for tok in tokens {
            let head = tok.split('/').next().unwrap_or(tok);
            let written: i64 = head.parse().map_err(|e: std::num::ParseIntError| {
                let msg = match e.kind() {
                    // All digits, just too many of them: say so rather than "not an integer".
                    std::num::IntErrorKind::PosOverflow | std::num::IntErrorKind::NegOverflow => {
                        format!("face vertex index {head} is out of range (more than 64 bits)")
                    }
                    _ => format!("face vertex {tok:?} does not start with an integer index"),
                };
                read_error(self.file, line_no, msg)
            })?;
            let out_of_range = || MeshError::IndexOutOfRange {
                file: self.file.to_path_buf(),
                face: first_triangle,
                index: written,
                count: defined,
            };
            let zero_based = match written {
                0 => {
                    return Err(read_error(
                        self.file,
                        line_no,
                        "face vertex index 0 (OBJ indices start at 1)".to_string(),
                    ))
                }
                w if w > 0 => w - 1,
                // -1 is the last vertex defined so far.
                w => i64::try_from(defined).map_err(|_| out_of_range())? + w,
            };
            let index = u32::try_from(zero_based).map_err(|_| out_of_range())?;
            if index as usize >= defined {
                self.forward.push((first_triangle, written));
            }
            self.corners.push(index);
        }
        let n = self.corners.len();
        if n < 3 {
            return Err(read_error(
                self.file,
                line_no,
                format!(
                    "face has {n} {}, need at least 3",
                    if n == 1 { "vertex" } else { "vertices" }
                ),
            ));
        }
        self.info.source_face_count += 1;
        if n > 3 {
            self.info.polygons_triangulated += 1;
        }
        let a = self.corners[0];
        for w in self.corners[1..].windows(2) {
            self.mesh.faces.push([a, w[0], w[1]]);
        }
        Ok(())
    }

    fn finish(self) -> Result<(TriMesh, ObjInfo), MeshError> {
        let count = self.mesh.positions.len();
        if self.mesh.faces.is_empty() {
            return Err(MeshError::Empty {
                file: self.file.to_path_buf(),
            });
        }
        // Every other index was below the vertex count when it was read.
        if let Some(&(face, index)) = self.forward.iter().find(|&&(_, w)| w > count as i64) {
            return Err(MeshError::IndexOutOfRange {
                file: self.file.to_path_buf(),
                face,
                index,
                count,
            });
        }
        Ok((self.mesh, self.info))
    }
}

/// Shortest text that parses back to exactly `x`; exponent form only where plain decimals
/// would be long (|x| < 1e-5 or ≥ 1e16).
fn push_f64(out: &mut String, x: f64) {
    use std::fmt::Write as _;
    let a = x.abs();
    // Writing into a String cannot fail.
    let _ = if a != 0.0 && a.is_finite() && !(1e-5..1e16).contains(&a) {
        write!(out, "{x:e}")
    } else {
        write!(out, "{x}")
    };
}

fn invalid_input(what: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, what)
}

fn push_header_and_vertices(out: &mut String, mesh: &TriMesh, uv: &[[f64; 2]]) {
    out.push_str("# written by foldfree\n");
    for p in &mesh.positions {
        out.push('v');
        for &c in p {
            out.push(' ');
            push_f64(out, c);
        }
        out.push('\n');
    }
    for t in uv {
        out.push_str("vt");
        for &c in t {
            out.push(' ');
            push_f64(out, c);
        }
        out.push('\n');
    }
}

/// OBJ text of the mesh with one texture coordinate per vertex (`uv` is #V×2): `v`, `vt`, then
/// `f a/a b/b c/c` (1-based) in the mesh's vertex and face order. Unreferenced vertices get a
/// `vt` too, so `v` and `vt` indices coincide.
pub fn obj_text_with_uv(mesh: &TriMesh, uv: &[[f64; 2]]) -> io::Result<String> {
    if uv.len() != mesh.positions.len() {
        return Err(invalid_input(format!(
            "{} texture coordinates for {} vertices",
            uv.len(),
            mesh.positions.len()
        )));
    }
    obj_text_with_corner_uv(mesh, uv, &mesh.faces)
}

/// OBJ text of the mesh with texture coordinates indexed per face corner, as needed once seams
/// are cut: `uv` is #T×2, `corner_uv` is #F×3 0-based indices into `uv`; face `f` is written as
/// `f a/t0 b/t1 c/t2`. Non-finite numbers are refused: nothing non-finite is ever written.
pub fn obj_text_with_corner_uv(
    mesh: &TriMesh,
    uv: &[[f64; 2]],
    corner_uv: &[[u32; 3]],
) -> io::Result<String> {
    if corner_uv.len() != mesh.faces.len() {
        return Err(invalid_input(format!(
            "{} corner texture indices for {} faces",
            corner_uv.len(),
            mesh.faces.len()
        )));
    }
    if let Some((f, _)) = corner_uv
        .iter()
        .enumerate()
        .find(|(_, c)| c.iter().any(|&t| t as usize >= uv.len()))
    {
        return Err(invalid_input(format!(
            "face {f} refers to a texture coordinate past the {} given",
            uv.len()
        )));
    }
    if let Some((f, _)) = mesh
        .faces
        .iter()
        .enumerate()
        .find(|(_, c)| c.iter().any(|&v| v as usize >= mesh.positions.len()))
    {
        return Err(invalid_input(format!(
            "face {f} refers to a vertex past the {} given",
            mesh.positions.len()
        )));
    }

    let finite = |c: &[f64]| c.iter().all(|x| x.is_finite());
    if let Some(v) = mesh.positions.iter().position(|p| !finite(p)) {
        return Err(invalid_input(format!(
            "vertex {v} has a non-finite coordinate"
        )));
    }
    if let Some(t) = uv.iter().position(|p| !finite(p)) {
        return Err(invalid_input(format!(
            "texture coordinate {t} is not finite"
        )));
    }
    use std::fmt::Write as _;
    // ~30 bytes per v/vt line, ~25 per face line.
    let mut out =
        String::with_capacity(32 * (mesh.positions.len() + uv.len()) + 28 * mesh.faces.len() + 32);
    push_header_and_vertices(&mut out, mesh, uv);
    for (f, t) in mesh.faces.iter().zip(corner_uv) {
        // Writing into a String cannot fail.
        let _ = writeln!(
            out,
            "f {}/{} {}/{} {}/{}",
            u64::from(f[0]) + 1,
            u64::from(t[0]) + 1,
            u64::from(f[1]) + 1,
            u64::from(t[1]) + 1,
            u64::from(f[2]) + 1,
            u64::from(t[2]) + 1
        );
    }
    Ok(out)
}
