//! MEDIT ASCII `.mesh` reading and writing (Vertices and Tetrahedra; other sections skipped).
//!
//! Parsed as a stream of whitespace tokens that remember their line, because writers differ
//! on whether a section's count sits on the keyword's line or the next one. Sections of known
//! record size (Triangles, Edges, Corners, ...) are skipped by tokens; unknown ones by lines.

use std::path::Path;

use super::tet::TetMesh;
use super::VolError;

/// A stream of whitespace tokens with their 1-based lines: it holds one line at a time, so the
/// reader's memory is the mesh it builds, not a copy of the file's tokens.
struct Tokens<'a> {
    lines: std::iter::Enumerate<std::str::Lines<'a>>,
    current: std::str::SplitWhitespace<'a>,
    line: usize,
    peeked: Option<(&'a str, usize)>,
    /// The line of the last token seen (for errors at the end of the file).
    last: usize,
    file: &'a Path,
}

impl<'a> Tokens<'a> {
    fn new(text: &'a str, file: &'a Path) -> Tokens<'a> {
        Tokens {
            lines: text.lines().enumerate(),
            current: "".split_whitespace(),
            line: 0,
            peeked: None,
            last: 1,
            file,
        }
    }

    fn pull(&mut self) -> Option<(&'a str, usize)> {
        loop {
            if let Some(t) = self.current.next() {
                self.last = self.line;
                return Some((t, self.line));
            }
            let (i, l) = self.lines.next()?;
            self.line = i + 1;
            self.current = l.split('#').next().unwrap_or("").split_whitespace();
        }
    }

    fn peek(&mut self) -> Option<(&'a str, usize)> {
        if self.peeked.is_none() {
            self.peeked = self.pull();
        }
        self.peeked
    }

    fn advance(&mut self) -> Option<(&'a str, usize)> {
        self.peeked.take().or_else(|| self.pull())
    }

    fn last_line(&self) -> usize {
        self.last
    }

    fn next(&mut self, what: &str) -> Result<(&'a str, usize), VolError> {
        self.advance().ok_or_else(|| VolError::Truncated {
            file: self.file.to_path_buf(),
            line: self.last_line(),
            what: format!("expected {what}"),
        })
    }

    fn parse<T: std::str::FromStr>(&mut self, what: &str) -> Result<(T, usize), VolError> {
        let (t, line) = self.next(what)?;
        t.parse::<T>()
            .map(|v| (v, line))
            .map_err(|_| VolError::Parse {
                file: self.file.to_path_buf(),
                line,
                msg: format!("expected {what}, found `{t}`"),
            })
    }
}

/// Parses MEDIT text (`file` only names errors). Tets and vertices are validated for indices
/// and finite coordinates; orientation is the caller's business (rest vs map).
pub fn parse_medit(text: &str, file: &Path) -> Result<TetMesh, VolError> {
    let mut tk = Tokens::new(text, file);
    let mut mesh = TetMesh::default();
    let mut tet_lines = Vec::new();
    let mut have_vertices = false;
    let mut have_tets = false;
    while let Some((kw, line)) = tk.advance() {
        match kw {
            "MeshVersionFormatted" => {
                tk.parse::<i64>("a format version")?;
            }
            "Dimension" => {
                let (d, l) = tk.parse::<i64>("the dimension")?;
                if d != 3 {
                    return Err(VolError::Parse {
                        file: file.to_path_buf(),
                        line: l,
                        msg: format!("dimension {d}: only 3 is supported"),
                    });
                }
            }
            "Vertices" | "Tetrahedra"
                if (kw == "Vertices" && have_vertices) || (kw == "Tetrahedra" && have_tets) =>
            {
                return Err(VolError::Parse {
                    file: file.to_path_buf(),
                    line,
                    msg: format!("a second {kw} section (a mesh has one)"),
                });
            }
            "Vertices" => {
                let (n, _) = tk.parse::<usize>("the vertex count")?;
                // The count is untrusted (a fuzzer found 5e8): reserve at most what a file of
                // this size could hold; the vector grows past that only if records follow.
                mesh.positions.reserve(n.min(text.len() / 8));
                for i in 0..n {
                    let mut p = [0.0; 3];
                    let mut l = line;
                    for c in &mut p {
                        let (v, ll) = tk.parse::<f64>("a coordinate")?;
                        *c = v;
                        l = ll;
                    }
                    if p.iter().any(|c| !c.is_finite()) {
                        return Err(VolError::NonFinite {
                            file: file.to_path_buf(),
                            line: l,
                            vertex: i,
                        });
                    }
                    let (r, _) = tk.parse::<i64>("a vertex reference")?;
                    mesh.positions.push(p);
                    mesh.vertex_refs.push(r);
                }
                have_vertices = true;
            }
            "Tetrahedra" => {
                let (n, _) = tk.parse::<usize>("the tet count")?;
                mesh.tets.reserve(n.min(text.len() / 10));
                for _ in 0..n {
                    let mut t = [0i64; 4];
                    let mut l = line;
                    for c in &mut t {
                        let (v, ll) = tk.parse::<i64>("a vertex index")?;
                        *c = v;
                        l = ll;
                    }
                    let (r, _) = tk.parse::<i64>("a tet reference")?;
                    // Indices are checked once all vertices are known (sections may come in
                    // any order); keep the raw 1-based values and lines until then.
                    tet_lines.push((t, l));
                    mesh.tet_refs.push(r);
                }
                have_tets = true;
            }
            "End" => break,
            _ => {
                let size = match kw {
                    "Edges" => Some(3),
                    "Triangles" => Some(4),
                    "Quadrilaterals" => Some(5),
                    "Hexahedra" => Some(9),
                    "Prisms" => Some(7),
                    "Corners" | "Ridges" | "RequiredVertices" | "RequiredEdges"
                    | "RequiredTriangles" => Some(1),
                    "Normals" | "Tangents" => Some(3),
                    "NormalAtVertices" | "TangentAtVertices" => Some(2),
                    _ => None,
                };
                if kw.parse::<f64>().is_ok() {
                    return Err(VolError::Parse {
                        file: file.to_path_buf(),
                        line,
                        msg: format!("unexpected number `{kw}` outside a section (too many records before it?)"),
                    });
                }
                let (n, count_line) = tk.parse::<usize>(&format!("the record count of {kw}"))?;
                match size {
                    Some(k) => {
                        // A count near usize::MAX cannot be in the file: the loop ends at the
                        // first missing token, so saturating is enough (no overflow panic).
                        for _ in 0..n.saturating_mul(k) {
                            tk.next(&format!("a {kw} record"))?;
                        }
                    }
                    None => {
                        // Unknown section: one record per line.
                        let stop = count_line.saturating_add(n);
                        while tk.peek().is_some_and(|(_, l)| l <= stop) {
                            tk.advance();
                        }
                        if tk.peek().is_none() && tk.last_line() < stop {
                            return Err(VolError::Truncated {
                                file: file.to_path_buf(),
                                line: tk.last_line(),
                                what: format!("section {kw} announces {n} records"),
                            });
                        }
                    }
                }
            }
        }
    }
    if !have_vertices || !have_tets {
        return Err(VolError::Truncated {
            file: file.to_path_buf(),
            line: tk.last_line(),
            what: format!(
                "no {} section",
                if have_vertices {
                    "Tetrahedra"
                } else {
                    "Vertices"
                }
            ),
        });
    }
    let nv = mesh.positions.len();
    for (ti, (t, l)) in tet_lines.into_iter().enumerate() {
        let mut out = [0u32; 4];
        for k in 0..4 {
            if t[k] < 1 || t[k] as usize > nv {
                return Err(VolError::BadIndex {
                    file: file.to_path_buf(),
                    line: l,
                    tet: ti,
                    index: t[k],
                    count: nv,
                });
            }
            out[k] = (t[k] - 1) as u32;
        }
        mesh.tets.push(out);
    }
    Ok(mesh)
}

/// Reads a MEDIT `.mesh` file.
pub fn read_medit(path: &Path, limit: u64) -> Result<TetMesh, VolError> {
    let text = super::error::read_text(path, limit)?;
    parse_medit(&text, path)
}

/// MEDIT text of `mesh` with the vertex positions `positions` (the mesh's own or a map's).
/// Coordinates are written in shortest round-trip form so a re-read is bit-exact.
pub fn medit_text(mesh: &TetMesh, positions: &[[f64; 3]]) -> String {
    use std::fmt::Write;
    let mut s = String::with_capacity(positions.len() * 64 + mesh.tets.len() * 40);
    s.push_str("MeshVersionFormatted 1\nDimension 3\nVertices\n");
    let _ = writeln!(s, "{}", positions.len());
    for (i, p) in positions.iter().enumerate() {
        let r = mesh.vertex_refs.get(i).copied().unwrap_or(0);
        let _ = writeln!(s, "{:?} {:?} {:?} {}", p[0], p[1], p[2], r);
    }
    let _ = writeln!(s, "Tetrahedra\n{}", mesh.tets.len());
    for (i, t) in mesh.tets.iter().enumerate() {
        let r = mesh.tet_refs.get(i).copied().unwrap_or(0);
        let _ = writeln!(
            s,
            "{} {} {} {} {}",
            t[0] + 1,
            t[1] + 1,
            t[2] + 1,
            t[3] + 1,
            r
        );
    }
    s.push_str("End\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roundtrip_and_skip_triangles() {
        let text = "MeshVersionFormatted 1\nDimension 3\nVertices 4\n0 0 0 1\n1 0 0 0\n0 1 0 0\n0 0 1 0\nTriangles\n1\n1 2 3 0\nTetrahedra\n1\n1 2 3 4 7\nEnd\n";
        let m = parse_medit(text, Path::new("t.mesh")).unwrap();
        assert_eq!(m.tets, vec![[0, 1, 2, 3]]);
        assert_eq!(m.tet_refs, vec![7]);
        let again = parse_medit(&medit_text(&m, &m.positions), Path::new("u")).unwrap();
        assert_eq!(again, m);
    }

    #[test]
    fn located_errors() {
        let bad = "Dimension 3\nVertices\n2\n0 0 0 0\n1 nan 0 0\n";
        match parse_medit(bad, Path::new("x")) {
            Err(VolError::NonFinite { line, vertex, .. }) => assert_eq!((line, vertex), (5, 1)),
            other => panic!("{other:?}"),
        }
        let trunc = "Dimension 3\nVertices\n3\n0 0 0 0\n1 0 0 0\n";
        assert!(matches!(
            parse_medit(trunc, Path::new("x")),
            Err(VolError::Truncated { .. })
        ));
        let idx = "Vertices\n1\n0 0 0 0\nTetrahedra\n1\n1 1 1 9 0\nEnd\n";
        match parse_medit(idx, Path::new("x")) {
            Err(VolError::BadIndex {
                line, tet, index, ..
            }) => assert_eq!((line, tet, index), (6, 0, 9)),
            other => panic!("{other:?}"),
        }
    }
}
