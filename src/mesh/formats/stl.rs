//! STL, ASCII and binary.
//!
//! STL stores each triangle with its own three corners and no shared vertices. To get the
//! topology validation and the solvers need, corners at exactly equal positions (bit-equal
//! after `-0 → +0`; no tolerance, so nothing distinct is merged) are welded into one vertex.
//! Vertex `i` of the result is the `i`-th distinct position in order of first appearance, and
//! face `i` is the file's triangle `i` with its corners in the file's order (the stored normal
//! is ignored: the winding decides the orientation, as in OBJ).
//!
//! Binary: an 80-byte header, a little-endian `u32` triangle count, then 50 bytes per triangle
//! (normal and three corners as 12 `f32`, a `u16` attribute). The count must match the file's
//! size exactly. A file is read as ASCII when it starts with `solid`, its size does not match
//! the binary layout and it holds no NUL byte (binary files may start with `solid` too).
//!
//! ASCII: `solid NAME`, then `facet normal nx ny nz` / `outer loop` / `vertex x y z` … /
//! `endloop` / `endfacet` per triangle, `endsolid NAME`; several solids may follow each other.
//! A loop with more than 3 vertices is fan-triangulated. Coordinates are read as `f64`.

use std::collections::HashMap;
use std::path::Path;

use super::text::{parse_f64, shown, Tokens};
use super::{finish, located, push_fan, Encoding, SurfaceFormat, SurfaceInfo};
use crate::mesh::{MeshError, TriMesh};

const HEADER: usize = 80;
const RECORD: u64 = 50;

/// Parses an STL file (ASCII or binary, detected as described in the module doc).
pub fn parse_stl(bytes: &[u8], file: &Path) -> Result<(TriMesh, SurfaceInfo), MeshError> {
    let announced = binary_count(bytes);
    let size_matches = announced.is_some_and(|n| binary_size(n) == Some(bytes.len() as u64));
    let text_start = bytes.iter().position(|b| !b.is_ascii_whitespace());
    let starts_solid = text_start.is_some_and(|i| {
        let rest = &bytes[i..];
        rest.starts_with(b"solid") && rest.get(5).is_none_or(|b| b.is_ascii_whitespace())
    });
    // A NUL byte never occurs in ASCII STL; it marks a binary file whose count is wrong.
    if starts_solid && !size_matches && !bytes.contains(&0) {
        return parse_ascii(bytes, file);
    }
    parse_binary(bytes, file)
}

/// The triangle count of a binary STL header.
fn binary_count(bytes: &[u8]) -> Option<u32> {
    let b = bytes.get(HEADER..HEADER + 4)?;
    Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

/// 84 + 50·n bytes.
fn binary_size(n: u32) -> Option<u64> {
    u64::from(n)
        .checked_mul(RECORD)?
        .checked_add(HEADER as u64 + 4)
}

/// Corners welded by exact position: `-0.0` and `0.0` are one position (they compare equal).
struct Welder {
    index: HashMap<[u64; 3], u32>,
    positions: Vec<[f64; 3]>,
}

impl Welder {
    fn new(capacity: usize) -> Welder {
        Welder {
            index: HashMap::with_capacity(capacity),
            positions: Vec::with_capacity(capacity),
        }
    }

    /// The vertex at `p`, added if new; `None` past the 32-bit index range.
    fn vertex(&mut self, p: [f64; 3]) -> Option<u32> {
        // x + 0.0 turns -0.0 into +0.0 and changes nothing else (NaNs stay NaN).
        let key = p.map(|c| (c + 0.0).to_bits());
        if let Some(&v) = self.index.get(&key) {
            return Some(v);
        }
        let v = u32::try_from(self.positions.len()).ok()?;
        self.index.insert(key, v);
        self.positions.push(p);
        Some(v)
    }

    /// The mesh of the welded vertices, counting the `corners` read that were merged.
    fn finish(
        self,
        faces: Vec<[u32; 3]>,
        corners: usize,
        mut info: SurfaceInfo,
        file: &Path,
    ) -> Result<(TriMesh, SurfaceInfo), MeshError> {
        info.skipped = corners.saturating_sub(self.positions.len());
        let mesh = TriMesh {
            positions: self.positions,
            faces,
        };
        finish(mesh, info, file)
    }
}

fn too_many(file: &Path, at: String) -> MeshError {
    located(
        file,
        at,
        "more distinct vertices than 32-bit indices can address",
    )
}

fn parse_binary(bytes: &[u8], file: &Path) -> Result<(TriMesh, SurfaceInfo), MeshError> {
    let Some(n) = binary_count(bytes) else {
        return Err(located(
            file,
            "byte 0",
            format!(
                "{} bytes: not an ASCII STL (no `solid`) and too short for a binary STL (80-byte \
                 header and a triangle count)",
                bytes.len()
            ),
        ));
    };
    // Checked before anything is reserved: the count then bounds every allocation by the size.
    let needed = binary_size(n);
    if needed != Some(bytes.len() as u64) {
        return Err(located(
            file,
            format!("byte {HEADER}"),
            format!(
                "the header announces {n} triangles (84 + 50·{n} = {} bytes), the file has {} bytes",
                needed.map_or("more than 2^64".to_string(), |b| b.to_string()),
                bytes.len()
            ),
        ));
    }
    let mut info = SurfaceInfo::new(SurfaceFormat::Stl, Encoding::BinaryLittleEndian);
    let count = n as usize;
    let mut welder = Welder::new(count.min(1 << 20));
    let mut faces = Vec::with_capacity(count);
    let records = bytes[HEADER + 4..].chunks_exact(RECORD as usize);
    for (t, record) in records.enumerate() {
        let f32_at = |i: usize| {
            let b = &record[4 * i..4 * i + 4];
            f64::from(f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        };
        let mut tri = [0u32; 3];
        for (k, v) in tri.iter_mut().enumerate() {
            // Corners follow the normal (floats 0..3).
            let p = [f32_at(3 + 3 * k), f32_at(4 + 3 * k), f32_at(5 + 3 * k)];
            let at = || format!("byte {}", HEADER + 4 + t * RECORD as usize);
            *v = welder.vertex(p).ok_or_else(|| too_many(file, at()))?;
        }
        push_fan(&mut faces, &tri, &mut info);
    }
    welder.finish(faces, 3 * count, info, file)
}

fn parse_ascii(bytes: &[u8], file: &Path) -> Result<(TriMesh, SurfaceInfo), MeshError> {
    let mut info = SurfaceInfo::new(SurfaceFormat::Stl, Encoding::Text);
    let mut toks = Tokens::new(bytes, 1);
    let mut welder = Welder::new(0);
    let mut faces = Vec::new();
    let mut corners = Vec::new();
    let mut corner_count = 0usize;

    // `expect("facet")`: the next token must be `word` (case-insensitive, as exporters vary).
    let expect = |toks: &mut Tokens<'_>, word: &str, face: usize| -> Result<(), MeshError> {
        match toks.next_token() {
            Some((_, t)) if t.eq_ignore_ascii_case(word.as_bytes()) => Ok(()),
            Some((n, t)) => Err(located(
                file,
                format!("line {n}"),
                format!("facet {face}: expected `{word}`, found {}", shown(t)),
            )),
            None => Err(located(
                file,
                format!("line {}", toks.line()),
                format!("file ends inside facet {face} (expected `{word}`)"),
            )),
        }
    };

    let mut in_solid = false;
    loop {
        let Some((n, word)) = toks.next_token() else {
            if in_solid {
                return Err(located(
                    file,
                    format!("line {}", toks.line()),
                    format!(
                        "file ends after {} facets without `endsolid` (truncated?)",
                        info.source_face_count
                    ),
                ));
            }
            break;
        };
        let at = format!("line {n}");
        let lower = word.to_ascii_lowercase();
        match (in_solid, lower.as_slice()) {
            (false, b"solid") => {
                // The rest of the line is the solid's name.
                toks.skip_line();
                in_solid = true;
            }
            (true, b"endsolid") => {
                toks.skip_line();
                in_solid = false;
            }
            (true, b"facet") => {
                let face = info.source_face_count;
                expect(&mut toks, "normal", face)?;
                // The normal is not used (and some exporters write NaN there).
                for _ in 0..3 {
                    if toks.next_token().is_none() {
                        return Err(located(
                            file,
                            format!("line {}", toks.line()),
                            format!("file ends inside facet {face} (in its normal)"),
                        ));
                    }
                }
                expect(&mut toks, "outer", face)?;
                expect(&mut toks, "loop", face)?;
                corners.clear();
                loop {
                    let Some((m, t)) = toks.next_token() else {
                        return Err(located(
                            file,
                            format!("line {}", toks.line()),
                            format!(
                                "file ends inside facet {face} (expected `vertex` or `endloop`)"
                            ),
                        ));
                    };
                    if t.eq_ignore_ascii_case(b"endloop") {
                        break;
                    }
                    if !t.eq_ignore_ascii_case(b"vertex") {
                        return Err(located(
                            file,
                            format!("line {m}"),
                            format!(
                                "facet {face}: expected `vertex` or `endloop`, found {}",
                                shown(t)
                            ),
                        ));
                    }
                    let mut p = [0.0; 3];
                    for c in &mut p {
                        let Some((m, t)) = toks.next_token() else {
                            return Err(located(
                                file,
                                format!("line {}", toks.line()),
                                format!("file ends inside a vertex of facet {face}"),
                            ));
                        };
                        *c = parse_f64(t).ok_or_else(|| {
                            located(
                                file,
                                format!("line {m}"),
                                format!(
                                    "facet {face}: vertex coordinate {} is not a number",
                                    shown(t)
                                ),
                            )
                        })?;
                    }
                    let v = welder
                        .vertex(p)
                        .ok_or_else(|| too_many(file, format!("line {m}")))?;
                    corners.push(v);
                }
                if corners.len() < 3 {
                    return Err(located(
                        file,
                        at,
                        format!(
                            "facet {face} has {} vertices, need at least 3",
                            corners.len()
                        ),
                    ));
                }
                corner_count += corners.len();
                push_fan(&mut faces, &corners, &mut info);
                expect(&mut toks, "endfacet", face)?;
            }
            (false, _) => {
                return Err(located(
                    file,
                    at,
                    format!("expected `solid`, found {}", shown(word)),
                ))
            }
            (true, _) => {
                return Err(located(
                    file,
                    at,
                    format!("expected `facet` or `endsolid`, found {}", shown(word)),
                ))
            }
        }
    }
    welder.finish(faces, corner_count, info, file)
}
