//! TetGen `.node` / `.ele` reading and writing. Indices may start at 0 or 1 (TetGen's `-z`):
//! the first record's index decides, as TetGen itself does.

use std::path::{Path, PathBuf};

use super::tet::TetMesh;
use super::VolError;

/// Non-empty, comment-stripped lines with their 1-based numbers.
fn records(text: &str) -> Vec<(usize, Vec<&str>)> {
    text.lines()
        .enumerate()
        .filter_map(|(i, l)| {
            let toks: Vec<&str> = l
                .split('#')
                .next()
                .unwrap_or("")
                .split_whitespace()
                .collect();
            (!toks.is_empty()).then_some((i + 1, toks))
        })
        .collect()
}

fn num<T: std::str::FromStr>(
    tok: Option<&&str>,
    file: &Path,
    line: usize,
    what: &str,
) -> Result<T, VolError> {
    let t = tok.ok_or_else(|| VolError::Parse {
        file: file.to_path_buf(),
        line,
        msg: format!("missing {what}"),
    })?;
    t.parse().map_err(|_| VolError::Parse {
        file: file.to_path_buf(),
        line,
        msg: format!("expected {what}, found `{t}`"),
    })
}

/// The `.node` and `.ele` paths for a path naming either file or their common stem.
pub fn tetgen_paths(path: &Path) -> (PathBuf, PathBuf) {
    let stem = match path.extension().and_then(|e| e.to_str()) {
        Some("node") | Some("ele") => path.with_extension(""),
        _ => path.to_path_buf(),
    };
    let mut n = stem.clone().into_os_string();
    n.push(".node");
    let mut e = stem.into_os_string();
    e.push(".ele");
    (PathBuf::from(n), PathBuf::from(e))
}

/// Positions, vertex references (boundary markers) and the first index of a `.node` file.
pub type NodeFile = (Vec<[f64; 3]>, Vec<i64>, i64);

/// Parses `.node` text: positions and boundary markers (as vertex references), and the index
/// base.
pub fn parse_node(text: &str, file: &Path) -> Result<NodeFile, VolError> {
    let recs = records(text);
    let (hl, head) = recs.first().ok_or_else(|| VolError::Truncated {
        file: file.to_path_buf(),
        line: 1,
        what: "empty .node file".into(),
    })?;
    let n: usize = num(head.first(), file, *hl, "the point count")?;
    let dim: usize = num(head.get(1), file, *hl, "the dimension")?;
    if dim != 3 {
        return Err(VolError::Parse {
            file: file.to_path_buf(),
            line: *hl,
            msg: format!("dimension {dim}: only 3 is supported"),
        });
    }
    let nattr: usize = head.get(2).map_or(Ok(0), |_| {
        num(head.get(2), file, *hl, "the attribute count")
    })?;
    let nmark: usize = head
        .get(3)
        .map_or(Ok(0), |_| num(head.get(3), file, *hl, "the marker count"))?;
    if recs.len() < n + 1 {
        return Err(VolError::Truncated {
            file: file.to_path_buf(),
            line: recs.last().map_or(1, |r| r.0),
            what: format!("{n} points announced, {} found", recs.len() - 1),
        });
    }
    // The header count is untrusted: reserve no more than the records present.
    let mut pos = Vec::with_capacity(n.min(recs.len()));
    let mut refs = Vec::with_capacity(n.min(recs.len()));
    let mut base = 0;
    for (i, (l, t)) in recs[1..=n].iter().enumerate() {
        let idx: i64 = num(t.first(), file, *l, "a point index")?;
        if i == 0 {
            base = idx;
        }
        if idx != base + i as i64 {
            return Err(VolError::Parse {
                file: file.to_path_buf(),
                line: *l,
                msg: format!("point index {idx}, expected {}", base + i as i64),
            });
        }
        let mut p = [0.0f64; 3];
        for k in 0..3 {
            p[k] = num(t.get(1 + k), file, *l, "a coordinate")?;
        }
        if p.iter().any(|c| !c.is_finite()) {
            return Err(VolError::NonFinite {
                file: file.to_path_buf(),
                line: *l,
                vertex: i,
            });
        }
        let r = if nmark > 0 {
            num(t.get(4 + nattr), file, *l, "a boundary marker")?
        } else {
            0
        };
        pos.push(p);
        refs.push(r);
    }
    Ok((pos, refs, base))
}

/// Parses `.ele` text against `nv` vertices whose first index is `base`.
pub fn parse_ele(
    text: &str,
    file: &Path,
    nv: usize,
    base: i64,
) -> Result<(Vec<[u32; 4]>, Vec<i64>), VolError> {
    let recs = records(text);
    let (hl, head) = recs.first().ok_or_else(|| VolError::Truncated {
        file: file.to_path_buf(),
        line: 1,
        what: "empty .ele file".into(),
    })?;
    let n: usize = num(head.first(), file, *hl, "the tet count")?;
    let npt: usize = num(head.get(1), file, *hl, "the nodes per tet")?;
    if npt != 4 && npt != 10 {
        return Err(VolError::Parse {
            file: file.to_path_buf(),
            line: *hl,
            msg: format!("{npt} nodes per tet: only 4 (or 10, corners used) are supported"),
        });
    }
    let nattr: usize = head.get(2).map_or(Ok(0), |_| {
        num(head.get(2), file, *hl, "the attribute count")
    })?;
    if recs.len() < n + 1 {
        return Err(VolError::Truncated {
            file: file.to_path_buf(),
            line: recs.last().map_or(1, |r| r.0),
            what: format!("{n} tets announced, {} found", recs.len() - 1),
        });
    }
    let mut tets = Vec::with_capacity(n.min(recs.len()));
    let mut refs = Vec::with_capacity(n.min(recs.len()));
    for (ti, (l, t)) in recs[1..=n].iter().enumerate() {
        let mut tet = [0u32; 4];
        for k in 0..4 {
            let v: i64 = num(t.get(1 + k), file, *l, "a vertex index")?;
            let z = v - base;
            if z < 0 || z as usize >= nv {
                return Err(VolError::BadIndex {
                    file: file.to_path_buf(),
                    line: *l,
                    tet: ti,
                    index: v,
                    count: nv,
                });
            }
            tet[k] = z as u32;
        }
        let r = if nattr > 0 {
            let a: f64 = num(t.get(1 + npt), file, *l, "a region attribute")?;
            a as i64
        } else {
            0
        };
        tets.push(tet);
        refs.push(r);
    }
    Ok((tets, refs))
}

/// Reads `.node` + `.ele` (`path` names either, or their stem).
pub fn read_tetgen(path: &Path) -> Result<TetMesh, VolError> {
    let (np, ep) = tetgen_paths(path);
    let read = |p: &Path| super::error::read_text(p);
    let (positions, vertex_refs, base) = parse_node(&read(&np)?, &np)?;
    let (tets, tet_refs) = parse_ele(&read(&ep)?, &ep, positions.len(), base)?;
    Ok(TetMesh {
        positions,
        tets,
        vertex_refs,
        tet_refs,
    })
}

/// Writes `.node` + `.ele` (1-based, one boundary marker = the vertex reference, one region
/// attribute = the tet reference).
pub fn write_tetgen(path: &Path, mesh: &TetMesh, positions: &[[f64; 3]]) -> Result<(), VolError> {
    use std::fmt::Write;
    let (np, ep) = tetgen_paths(path);
    let mut s = String::new();
    let _ = writeln!(s, "{} 3 0 1", positions.len());
    for (i, p) in positions.iter().enumerate() {
        let r = mesh.vertex_refs.get(i).copied().unwrap_or(0);
        let _ = writeln!(s, "{} {:?} {:?} {:?} {}", i + 1, p[0], p[1], p[2], r);
    }
    let io = |p: &Path, source| VolError::Io {
        path: p.to_path_buf(),
        source,
    };
    crate::mesh::write_atomic(&np, s.as_bytes()).map_err(|e| io(&np, e))?;
    let mut s = String::new();
    let _ = writeln!(s, "{} 4 1", mesh.tets.len());
    for (i, t) in mesh.tets.iter().enumerate() {
        let r = mesh.tet_refs.get(i).copied().unwrap_or(0);
        let _ = writeln!(
            s,
            "{} {} {} {} {} {}",
            i + 1,
            t[0] + 1,
            t[1] + 1,
            t[2] + 1,
            t[3] + 1,
            r
        );
    }
    crate::mesh::write_atomic(&ep, s.as_bytes()).map_err(|e| io(&ep, e))
}

/// Reads a tet mesh by extension: `.mesh` MEDIT, `.node` / `.ele` TetGen.
pub fn read_any(path: &Path) -> Result<TetMesh, VolError> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("node") | Some("ele") => read_tetgen(path),
        Some("mesh") => super::medit::read_medit(path),
        _ => Err(VolError::Input(format!(
            "{}: unknown tet mesh format (use .mesh, .node or .ele)",
            path.display()
        ))),
    }
}

/// Writes a tet mesh by extension (as [`read_any`]).
pub fn write_any(path: &Path, mesh: &TetMesh, positions: &[[f64; 3]]) -> Result<(), VolError> {
    match path.extension().and_then(|e| e.to_str()) {
        Some("node") | Some("ele") => write_tetgen(path, mesh, positions),
        Some("mesh") => super::medit::write_medit(path, mesh, positions),
        _ => Err(VolError::Input(format!(
            "{}: unknown tet mesh format (use .mesh, .node or .ele)",
            path.display()
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_based_and_errors() {
        let node = "4 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n";
        let (p, _, base) = parse_node(node, Path::new("a.node")).unwrap();
        assert_eq!((p.len(), base), (4, 0));
        let (t, _) = parse_ele("1 4 0\n0 0 1 2 3\n", Path::new("a.ele"), 4, 0).unwrap();
        assert_eq!(t, vec![[0, 1, 2, 3]]);
        match parse_ele("1 4 0\n0 0 1 2 4\n", Path::new("a.ele"), 4, 0) {
            Err(VolError::BadIndex { line, index, .. }) => assert_eq!((line, index), (2, 4)),
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            parse_node("5 3 0 0\n0 0 0 0\n", Path::new("a.node")),
            Err(VolError::Truncated { .. })
        ));
    }
}
