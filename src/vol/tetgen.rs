//! TetGen `.node` / `.ele` reading and writing. Indices may start at 0 or 1 (TetGen's `-z`):
//! the first record's index decides, as TetGen itself does.

use std::path::{Path, PathBuf};

use super::tet::TetMesh;
use super::VolError;
use crate::files::Outputs;

/// Non-empty, comment-stripped lines with their 1-based numbers, as a stream: nothing is held
/// but the current line, so memory does not grow with the file.
fn records(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines().enumerate().filter_map(|(i, l)| {
        let toks: Vec<&str> = l
            .split('#')
            .next()
            .unwrap_or("")
            .split_whitespace()
            .collect();
        (!toks.is_empty()).then_some((i + 1, toks))
    })
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

/// A record must have exactly the fields its header announces: a short record would read the
/// next column as the wrong quantity, a long one means the header is wrong.
fn fields(
    toks: &[&str],
    want: usize,
    file: &Path,
    line: usize,
    what: &str,
) -> Result<(), VolError> {
    if toks.len() == want {
        return Ok(());
    }
    Err(VolError::Parse {
        file: file.to_path_buf(),
        line,
        msg: format!(
            "{what} has {} fields, the header announces {want}",
            toks.len()
        ),
    })
}

/// The `n` records announced by a header, read one at a time: each must exist (else the file
/// is truncated) and have exactly `width` fields, and nothing may follow the last one.
struct Announced<'a, I> {
    recs: I,
    file: &'a Path,
    n: usize,
    width: usize,
    /// "point" or "tet".
    what: &'static str,
    last: usize,
}

impl<'a, 't, I: Iterator<Item = (usize, Vec<&'t str>)>> Announced<'a, I> {
    /// Record `i` (0-based) with its line.
    fn get(&mut self, i: usize) -> Result<(usize, Vec<&'t str>), VolError> {
        let Some((l, t)) = self.recs.next() else {
            return Err(VolError::Truncated {
                file: self.file.to_path_buf(),
                line: self.last,
                what: format!("{} {}s announced, {i} found", self.n, self.what),
            });
        };
        self.last = l;
        fields(&t, self.width, self.file, l, &format!("a {}", self.what))?;
        Ok((l, t))
    }

    /// Nothing after the announced records (a record more means the header is wrong).
    fn end(mut self) -> Result<(), VolError> {
        match self.recs.next() {
            Some((l, _)) => Err(VolError::Parse {
                file: self.file.to_path_buf(),
                line: l,
                msg: format!(
                    "a record after the {} {}s the header announces",
                    self.n, self.what
                ),
            }),
            None => Ok(()),
        }
    }
}

/// The header counts of `.node` / `.ele` are untrusted: sums are checked, and a count larger
/// than the lines of the file is found to be truncated by reading, never by arithmetic.
fn count_plus(a: usize, b: usize, file: &Path, line: usize) -> Result<usize, VolError> {
    a.checked_add(b).ok_or_else(|| VolError::Parse {
        file: file.to_path_buf(),
        line,
        msg: format!("field counts {a} + {b} overflow"),
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
/// base. Records past the announced count are an error (a wrong header).
pub fn parse_node(text: &str, file: &Path) -> Result<NodeFile, VolError> {
    let mut recs = records(text);
    let (hl, head) = recs.next().ok_or_else(|| VolError::Truncated {
        file: file.to_path_buf(),
        line: 1,
        what: "empty .node file".into(),
    })?;
    fields(&head, head.len().clamp(2, 4), file, hl, "the header")?;
    let n: usize = num(head.first(), file, hl, "the point count")?;
    let dim: usize = num(head.get(1), file, hl, "the dimension")?;
    if dim != 3 {
        return Err(VolError::Parse {
            file: file.to_path_buf(),
            line: hl,
            msg: format!("dimension {dim}: only 3 is supported"),
        });
    }
    let nattr: usize = head
        .get(2)
        .map_or(Ok(0), |_| num(head.get(2), file, hl, "the attribute count"))?;
    let nmark: usize = head
        .get(3)
        .map_or(Ok(0), |_| num(head.get(3), file, hl, "the marker count"))?;
    if nmark > 1 {
        return Err(VolError::Parse {
            file: file.to_path_buf(),
            line: hl,
            msg: format!("{nmark} boundary markers per point: TetGen writes 0 or 1"),
        });
    }
    let width = count_plus(4, count_plus(nattr, nmark, file, hl)?, file, hl)?;
    // The header count is untrusted: reserve no more than the text could hold (a point takes
    // at least 8 bytes: four one-character fields and their separators).
    let mut pos = Vec::with_capacity(n.min(text.len() / 8));
    let mut refs = Vec::with_capacity(n.min(text.len() / 8));
    let mut base = 0;
    let mut records = Announced {
        recs,
        file,
        n,
        width,
        what: "point",
        last: hl,
    };
    for i in 0..n {
        let (l, t) = records.get(i)?;
        let idx: i64 = num(t.first(), file, l, "a point index")?;
        if i == 0 {
            base = idx;
            if base != 0 && base != 1 {
                return Err(VolError::Parse {
                    file: file.to_path_buf(),
                    line: l,
                    msg: format!("first point index {idx}: TetGen numbers from 0 or 1"),
                });
            }
        }
        if idx != base + i as i64 {
            return Err(VolError::Parse {
                file: file.to_path_buf(),
                line: l,
                msg: format!("point index {idx}, expected {}", base + i as i64),
            });
        }
        let mut p = [0.0f64; 3];
        for k in 0..3 {
            p[k] = num(t.get(1 + k), file, l, "a coordinate")?;
        }
        if p.iter().any(|c| !c.is_finite()) {
            return Err(VolError::NonFinite {
                file: file.to_path_buf(),
                line: l,
                vertex: i,
            });
        }
        // Attributes are not used, but a field that is not a number means the record is not
        // what the header says it is.
        for k in 0..nattr {
            num::<f64>(t.get(4 + k), file, l, "a point attribute")?;
        }
        let r = if nmark > 0 {
            num(t.get(4 + nattr), file, l, "a boundary marker")?
        } else {
            0
        };
        pos.push(p);
        refs.push(r);
    }
    records.end()?;
    Ok((pos, refs, base))
}

/// Parses `.ele` text against `nv` vertices whose first index is `base`. A 10-node tet's
/// corners are its first four nodes; every record must have all announced fields.
pub fn parse_ele(
    text: &str,
    file: &Path,
    nv: usize,
    base: i64,
) -> Result<(Vec<[u32; 4]>, Vec<i64>), VolError> {
    let mut recs = records(text);
    let (hl, head) = recs.next().ok_or_else(|| VolError::Truncated {
        file: file.to_path_buf(),
        line: 1,
        what: "empty .ele file".into(),
    })?;
    fields(&head, head.len().clamp(2, 3), file, hl, "the header")?;
    let n: usize = num(head.first(), file, hl, "the tet count")?;
    let npt: usize = num(head.get(1), file, hl, "the nodes per tet")?;
    if npt != 4 && npt != 10 {
        return Err(VolError::Parse {
            file: file.to_path_buf(),
            line: hl,
            msg: format!("{npt} nodes per tet: only 4 (or 10, corners used) are supported"),
        });
    }
    let nattr: usize = head
        .get(2)
        .map_or(Ok(0), |_| num(head.get(2), file, hl, "the attribute count"))?;
    let width = count_plus(1 + npt, nattr, file, hl)?;
    let mut tets = Vec::with_capacity(n.min(text.len() / 10));
    let mut refs = Vec::with_capacity(n.min(text.len() / 10));
    let mut tbase = 0i64;
    let mut records = Announced {
        recs,
        file,
        n,
        width,
        what: "tet",
        last: hl,
    };
    for ti in 0..n {
        let (l, t) = records.get(ti)?;
        let idx: i64 = num(t.first(), file, l, "a tet index")?;
        if ti == 0 {
            tbase = idx;
        }
        if (tbase != 0 && tbase != 1) || idx != tbase + ti as i64 {
            return Err(VolError::Parse {
                file: file.to_path_buf(),
                line: l,
                msg: format!("tet index {idx}: TetGen numbers tets in sequence from 0 or 1"),
            });
        }
        let mut tet = [0u32; 4];
        let mut nodes = Vec::with_capacity(npt);
        for k in 0..npt {
            let v: i64 = num(t.get(1 + k), file, l, "a vertex index")?;
            let z = v
                .checked_sub(base)
                .filter(|&z| z >= 0 && (z as u64) < nv as u64);
            let Some(z) = z else {
                return Err(VolError::BadIndex {
                    file: file.to_path_buf(),
                    line: l,
                    tet: ti,
                    index: v,
                    count: nv,
                });
            };
            nodes.push(z as u32);
        }
        tet.copy_from_slice(&nodes[..4]);
        let r = if nattr > 0 {
            let a: f64 = num(t.get(1 + npt), file, l, "a region attribute")?;
            if !a.is_finite() {
                return Err(VolError::Parse {
                    file: file.to_path_buf(),
                    line: l,
                    msg: "non-finite region attribute".into(),
                });
            }
            a as i64
        } else {
            0
        };
        tets.push(tet);
        refs.push(r);
    }
    records.end()?;
    Ok((tets, refs))
}

/// Reads `.node` + `.ele` (`path` names either, or their stem), each at most `limit` bytes.
pub fn read_tetgen(path: &Path, limit: u64) -> Result<TetMesh, VolError> {
    let (np, ep) = tetgen_paths(path);
    let read = |p: &Path| super::error::read_text(p, limit);
    let (positions, vertex_refs, base) = parse_node(&read(&np)?, &np)?;
    let (tets, tet_refs) = parse_ele(&read(&ep)?, &ep, positions.len(), base)?;
    Ok(TetMesh {
        positions,
        tets,
        vertex_refs,
        tet_refs,
    })
}

/// `.node` and `.ele` text (1-based, one boundary marker = the vertex reference, one region
/// attribute = the tet reference).
pub fn tetgen_text(mesh: &TetMesh, positions: &[[f64; 3]]) -> (String, String) {
    use std::fmt::Write;
    let mut node = String::new();
    let _ = writeln!(node, "{} 3 0 1", positions.len());
    for (i, p) in positions.iter().enumerate() {
        let r = mesh.vertex_refs.get(i).copied().unwrap_or(0);
        let _ = writeln!(node, "{} {:?} {:?} {:?} {}", i + 1, p[0], p[1], p[2], r);
    }
    let mut ele = String::new();
    let _ = writeln!(ele, "{} 4 1", mesh.tets.len());
    for (i, t) in mesh.tets.iter().enumerate() {
        let r = mesh.tet_refs.get(i).copied().unwrap_or(0);
        let _ = writeln!(
            ele,
            "{} {} {} {} {} {}",
            i + 1,
            t[0] + 1,
            t[1] + 1,
            t[2] + 1,
            t[3] + 1,
            r
        );
    }
    (node, ele)
}

/// The tet formats by extension: `.mesh` MEDIT, `.node` / `.ele` TetGen.
enum Format {
    Medit,
    TetGen,
}

fn format_of(path: &Path) -> Result<Format, VolError> {
    match path
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .as_deref()
    {
        Some("node") | Some("ele") => Ok(Format::TetGen),
        Some("mesh") => Ok(Format::Medit),
        _ => Err(VolError::Input(format!(
            "{}: unknown tet mesh format (use .mesh, .node or .ele)",
            path.display()
        ))),
    }
}

/// Reads a tet mesh by extension (`.mesh` MEDIT, `.node` / `.ele` TetGen) with the default
/// size limit ([`crate::files::DEFAULT_MAX_ELEMENTS`] tets), and checks its structure.
pub fn read_any(path: &Path) -> Result<TetMesh, VolError> {
    read_any_with_limit(path, crate::files::DEFAULT_MAX_ELEMENTS)
}

/// Reads a tet mesh by extension (`.mesh` MEDIT, `.node` / `.ele` TetGen) of at most
/// `max_tets` tets (and files of at most that many tets' worth of bytes), and checks its
/// structure ([`TetMesh::check_structure`]).
pub fn read_any_with_limit(path: &Path, max_tets: usize) -> Result<TetMesh, VolError> {
    let limit = crate::files::byte_limit(max_tets);
    let m = match format_of(path)? {
        Format::TetGen => read_tetgen(path, limit)?,
        Format::Medit => super::medit::read_medit(path, limit)?,
    };
    if m.tets.len() > max_tets {
        return Err(VolError::Input(format!(
            "{}: {} tets, more than the limit of {max_tets} (--max-tets)",
            path.display(),
            m.tets.len()
        )));
    }
    m.check_structure(path)?;
    Ok(m)
}

/// The files a tet mesh at `path` consists of (TetGen: the `.node` and `.ele` pair).
pub fn files_of(path: &Path) -> Result<Vec<PathBuf>, VolError> {
    Ok(match format_of(path)? {
        Format::TetGen => {
            let (n, e) = tetgen_paths(path);
            vec![n, e]
        }
        Format::Medit => vec![path.to_path_buf()],
    })
}

/// Records a tet mesh input (both files of a TetGen pair) in a run's outputs; a path of no
/// tet format is recorded as it is (its reader reports the format).
pub fn tet_input(outputs: &mut Outputs, path: &Path) {
    for f in files_of(path).unwrap_or_else(|_| vec![path.to_path_buf()]) {
        outputs.input(&f);
    }
}

/// Plans a tet mesh output (both files of a TetGen pair) in a run's outputs.
pub fn tet_output(outputs: &mut Outputs, path: &Path, what: &str) -> Result<(), VolError> {
    // An unknown extension is an output path problem: the policy's message, not the reader's.
    if format_of(path).is_err() {
        outputs.output(path, what, &["mesh", "node", "ele"])?;
    }
    for f in files_of(path)? {
        outputs.output(&f, what, &["mesh", "node", "ele"])?;
    }
    Ok(())
}

/// The contents of the files of [`files_of`], in the same order.
pub fn output_texts(
    path: &Path,
    mesh: &TetMesh,
    positions: &[[f64; 3]],
) -> Result<Vec<String>, VolError> {
    if let Some(v) = positions
        .iter()
        .position(|p| p.iter().any(|c| !c.is_finite()))
    {
        return Err(VolError::BadResult(format!(
            "{}: vertex {v} of the map is not finite; nothing written",
            path.display()
        )));
    }
    Ok(match format_of(path)? {
        Format::TetGen => {
            let (n, e) = tetgen_text(mesh, positions);
            vec![n, e]
        }
        Format::Medit => vec![super::medit::medit_text(mesh, positions)],
    })
}

/// Writes a tet mesh (both files of a TetGen pair together, see [`crate::files::Outputs`]),
/// never over an existing file of another kind.
pub fn write_any(path: &Path, mesh: &TetMesh, positions: &[[f64; 3]]) -> Result<(), VolError> {
    let mut outputs = Outputs::new();
    tet_output(&mut outputs, path, "tet mesh")?;
    for (f, t) in files_of(path)?
        .iter()
        .zip(output_texts(path, mesh, positions)?)
    {
        outputs.set(f, t.into_bytes());
    }
    outputs.commit()?;
    Ok(())
}

/// Parses the contents of [`output_texts`] back (the independent check of what is written).
pub fn parse_output(path: &Path, texts: &[String]) -> Result<TetMesh, VolError> {
    match (format_of(path)?, texts) {
        (Format::TetGen, [n, e]) => {
            let (np, ep) = tetgen_paths(path);
            let (positions, vertex_refs, base) = parse_node(n, &np)?;
            let (tets, tet_refs) = parse_ele(e, &ep, positions.len(), base)?;
            Ok(TetMesh {
                positions,
                tets,
                vertex_refs,
                tet_refs,
            })
        }
        (Format::Medit, [m]) => super::medit::parse_medit(m, path),
        _ => Err(VolError::BadResult(
            "output texts do not match the format".into(),
        )),
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
