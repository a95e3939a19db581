//! ASCII OFF (Geomview Object File Format).
//!
//! ```text
//! OFF              (or COFF, NOFF, CNOFF, STOFF, …; optional: a file may start at the counts)
//! nv nf [ne]       (may follow the keyword on its line; ne is ignored)
//! x y z [extra]    nv vertex lines; normals, colours, texture coordinates after xyz ignored
//! n i0 … in-1 [c]  nf face lines, 0-based indices; a colour after the indices ignored
//! ```
//! `#` starts a comment anywhere; blank lines are skipped. One vertex or face per line, as every
//! writer produces: the trailing values a prefix letter adds (C: 3 or 4 colour values) cannot be
//! told from the next record otherwise. Binary OFF and 4D/nD OFF are refused by name.

use std::path::Path;

use super::text::{parse_f64, parse_i64, shown, tokens, uncommented, Lines};
use super::{
    finish, located, push_fan, reserve_for, vertex_index, Encoding, SurfaceFormat, SurfaceInfo,
};
use crate::mesh::{MeshError, TriMesh};

/// Parses an ASCII OFF file; `file` names the source in errors (`line N: …`, 1-based).
pub fn parse_off(bytes: &[u8], file: &Path) -> Result<(TriMesh, SurfaceInfo), MeshError> {
    let mut info = SurfaceInfo::new(SurfaceFormat::Off, Encoding::Text);
    let bytes = bytes.strip_prefix(b"\xef\xbb\xbf").unwrap_or(bytes);
    let mut lines = Lines::new(bytes, 1);
    let mut records = std::iter::from_fn(|| {
        for (n, line) in lines.by_ref() {
            let data = uncommented(line);
            if tokens(data).next().is_some() {
                return Some((n, data));
            }
        }
        None
    });
    let at = |n: usize| format!("line {n}");

    // The keyword, and the counts on its line or the next.
    let Some((first_line, first)) = records.next() else {
        return Err(located(file, at(1), "empty file: no OFF header"));
    };
    let mut head = tokens(first);
    let keyword = head.next().unwrap_or_default();
    let (counts_line, counts): (usize, Vec<&[u8]>) = if parse_i64(keyword).is_ok() {
        // No keyword: the file starts at the counts.
        (first_line, tokens(first).collect())
    } else {
        check_keyword(keyword, file, first_line)?;
        let rest: Vec<&[u8]> = head.collect();
        if rest
            .first()
            .is_some_and(|t| t.eq_ignore_ascii_case(b"BINARY"))
        {
            return Err(located(
                file,
                at(first_line),
                "binary OFF is not read; write it as ASCII OFF, PLY or OBJ",
            ));
        }
        if rest.is_empty() {
            match records.next() {
                Some((n, line)) => (n, tokens(line).collect()),
                None => return Err(located(file, at(first_line), "file ends before the counts")),
            }
        } else {
            (first_line, rest)
        }
    };
    let count = |i: usize, what: &str| -> Result<usize, MeshError> {
        let Some(&t) = counts.get(i) else {
            return Err(located(
                file,
                at(counts_line),
                format!("no {what} count (the counts line is `vertices faces [edges]`)"),
            ));
        };
        parse_i64(t)
            .ok()
            .and_then(|c| usize::try_from(c).ok())
            .ok_or_else(|| {
                located(
                    file,
                    at(counts_line),
                    format!("{what} count {} is not a non-negative integer", shown(t)),
                )
            })
    };
    let nv = count(0, "vertex")?;
    let nf = count(1, "face")?;

    // Every record takes at least 6 bytes ("0 0 0\n", "3 0 1 2" is more): bound the reserves.
    let left = bytes.len();
    let mut mesh = TriMesh {
        positions: reserve_for(nv, left, 6),
        faces: reserve_for(nf, left, 8),
    };
    // The next record, or where the file ends short of the counts.
    let mut last_line = counts_line;
    let mut record = |i: usize, of: usize, what: &str| {
        let (n, line) = records.next().ok_or_else(|| {
            located(
                file,
                at(last_line),
                format!("file ends after {i} of the {of} {what} announced"),
            )
        })?;
        last_line = n;
        Ok::<_, MeshError>((n, line))
    };
    for v in 0..nv {
        let (n, line) = record(v, nv, "vertices")?;
        let mut xyz = [0.0; 3];
        let mut toks = tokens(line);
        for (k, c) in xyz.iter_mut().enumerate() {
            let Some(t) = toks.next() else {
                return Err(located(
                    file,
                    at(n),
                    format!("vertex {v} has {k} coordinates, need 3"),
                ));
            };
            *c = parse_f64(t).ok_or_else(|| {
                located(
                    file,
                    at(n),
                    format!("vertex {v} coordinate {} is not a number", shown(t)),
                )
            })?;
        }
        mesh.positions.push(xyz);
    }

    let mut corners = Vec::new();
    for f in 0..nf {
        let (n, line) = record(f, nf, "faces")?;
        let mut toks = tokens(line);
        let head = toks.next().unwrap_or_default();
        let k = parse_i64(head)
            .ok()
            .and_then(|k| usize::try_from(k).ok())
            .ok_or_else(|| {
                located(
                    file,
                    at(n),
                    format!(
                        "face {f} vertex count {} is not a non-negative integer",
                        shown(head)
                    ),
                )
            })?;
        if k < 3 {
            return Err(located(
                file,
                at(n),
                format!("face {f} has {k} vertices, need at least 3"),
            ));
        }
        corners.clear();
        let first_triangle = mesh.faces.len();
        for t in toks.by_ref().take(k) {
            let written = parse_i64(t).map_err(|too_long| {
                let what = if too_long {
                    format!(
                        "face {f} vertex index {} is out of range (more than 64 bits)",
                        shown(t)
                    )
                } else {
                    format!("face {f} vertex index {} is not an integer", shown(t))
                };
                located(file, at(n), what)
            })?;
            corners.push(vertex_index(file, written, nv, first_triangle)?);
        }
        if corners.len() < k {
            return Err(located(
                file,
                at(n),
                format!(
                    "face {f} announces {k} vertices, the line gives {}",
                    corners.len()
                ),
            ));
        }
        push_fan(&mut mesh.faces, &corners, &mut info);
    }
    if let Some((n, _)) = records.next() {
        return Err(located(
            file,
            at(n),
            format!("a record past the counts of line {counts_line} (vertices {nv}, faces {nf})"),
        ));
    }
    finish(mesh, info, file)
}

/// `[ST][C][N]OFF` in any order of C and N; 4D and nD variants are refused by name.
fn check_keyword(keyword: &[u8], file: &Path, line: usize) -> Result<(), MeshError> {
    let bad = |what: String| Err(located(file, format!("line {line}"), what));
    let Some(prefix) = keyword.strip_suffix(b"OFF") else {
        return bad(format!(
            "not an OFF file: the first word is {}, not OFF (or COFF, NOFF, …)",
            shown(keyword)
        ));
    };
    let prefix = prefix.strip_prefix(b"ST").unwrap_or(prefix);
    if prefix.iter().any(|&b| b == b'4' || b == b'n') {
        return bad(format!(
            "{} is a 4D or nD OFF; only 3D surfaces are read",
            shown(keyword)
        ));
    }
    let known = prefix.len() <= 2
        && prefix.iter().all(|&b| b == b'C' || b == b'N')
        && !(prefix.len() == 2 && prefix[0] == prefix[1]);
    if !known {
        return bad(format!(
            "unknown OFF keyword {} (expected OFF, COFF, NOFF, CNOFF or STOFF)",
            shown(keyword)
        ));
    }
    Ok(())
}
