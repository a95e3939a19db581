//! Position-constraint files (`vertex_index x y z` per line, 0-based, `#` comments) and the
//! twist generator behind `foldfree dev volmap-constraints`.

use std::fmt::Write;
use std::path::Path;

use super::tet::TetMesh;
use super::VolError;

/// Parses a constraints file for a mesh of `nv` vertices (a repeated vertex is an error).
pub fn parse_constraints(
    text: &str,
    file: &Path,
    nv: usize,
) -> Result<Vec<(u32, [f64; 3])>, VolError> {
    let mut out = Vec::new();
    let mut seen = vec![false; nv];
    for (i, line) in text.lines().enumerate() {
        let l = line.split('#').next().unwrap_or("");
        let toks: Vec<&str> = l.split_whitespace().collect();
        if toks.is_empty() {
            continue;
        }
        let err = |msg: String| VolError::Parse {
            file: file.to_path_buf(),
            line: i + 1,
            msg,
        };
        if toks.len() != 4 {
            return Err(err(format!(
                "expected `vertex x y z`, found {} fields",
                toks.len()
            )));
        }
        let v: i64 = toks[0]
            .parse()
            .map_err(|_| err(format!("bad vertex index `{}`", toks[0])))?;
        if v < 0 || v as usize >= nv {
            return Err(err(format!("vertex index {v} out of range (0..{nv})")));
        }
        if seen[v as usize] {
            return Err(err(format!("vertex {v} constrained twice")));
        }
        seen[v as usize] = true;
        let mut p = [0.0f64; 3];
        for k in 0..3 {
            p[k] = toks[1 + k]
                .parse()
                .map_err(|_| err(format!("bad coordinate `{}`", toks[1 + k])))?;
        }
        if p.iter().any(|c| !c.is_finite()) {
            return Err(err("non-finite coordinate".into()));
        }
        out.push((v as u32, p));
    }
    Ok(out)
}

/// Reads a constraints file.
pub fn read_constraints(path: &Path, nv: usize) -> Result<Vec<(u32, [f64; 3])>, VolError> {
    // At most one line per vertex is valid, so the vertex count bounds the file.
    let limit = crate::files::byte_limit(nv);
    let text = super::error::read_text(path, limit)?;
    parse_constraints(&text, path, nv)
}

/// Constraints text, coordinates in shortest round-trip form.
pub fn constraints_text(c: &[(u32, [f64; 3])], header: &str) -> String {
    let mut s = String::new();
    for l in header.lines() {
        let _ = writeln!(s, "# {l}");
    }
    for (v, p) in c {
        let _ = writeln!(s, "{v} {:?} {:?} {:?}", p[0], p[1], p[2]);
    }
    s
}

/// Checks the settings of [`twist_constraints`] (usage errors, exit 2): a finite angle, and
/// a held fraction in [0, 0.5) so the two ends do not overlap.
pub fn check_twist(degrees: f64, fraction: f64) -> Result<(), VolError> {
    let bad = |what: &str, value: f64, range: &str| {
        Err(VolError::Input(format!(
            "volmap-constraints option {what} = {value} is outside its range {range}"
        )))
    };
    if !degrees.is_finite() {
        return bad("twist", degrees, "(-∞, ∞), finite");
    }
    if !(0.0..0.5).contains(&fraction) {
        return bad("fraction", fraction, "[0, 0.5)");
    }
    Ok(())
}

/// A twist of part of the boundary: along the longest bounding-box axis, boundary vertices in
/// the first `fraction` of the length stay where they are, those in the last `fraction` are
/// rotated by `degrees` about the axis through the bounding-box centre, the rest are free.
/// A real deformation target for meshes with no natural one (a mechanical part).
pub fn twist_constraints(mesh: &TetMesh, degrees: f64, fraction: f64) -> Vec<(u32, [f64; 3])> {
    let p = &mesh.positions;
    let (lo, hi) = super::tet::bbox(p);
    let axis = (0..3)
        .max_by(|&a, &b| (hi[a] - lo[a]).total_cmp(&(hi[b] - lo[b])))
        .unwrap_or(0);
    let (u, w) = ((axis + 1) % 3, (axis + 2) % 3);
    let cu = 0.5 * (lo[u] + hi[u]);
    let cw = 0.5 * (lo[w] + hi[w]);
    let len = (hi[axis] - lo[axis]).max(f64::MIN_POSITIVE);
    let th = degrees.to_radians();
    let (sn, cs) = th.sin_cos();
    let mut out = Vec::new();
    for v in mesh.boundary_vertices() {
        let q = p[v as usize];
        let s = (q[axis] - lo[axis]) / len;
        if s <= fraction {
            out.push((v, q));
        } else if s >= 1.0 - fraction {
            let (a, b) = (q[u] - cu, q[w] - cw);
            let mut r = q;
            r[u] = cu + cs * a - sn * b;
            r[w] = cw + sn * a + cs * b;
            out.push((v, r));
        }
    }
    out
}
