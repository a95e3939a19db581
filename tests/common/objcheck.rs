//! An independent f64 re-implementation of the map metrics that `foldfree param` reports,
//! computed from the OBJ files alone (no library code), so the CLI tests can check the report
//! against the file that was actually written.
//!
//! Deliberately different routes from the library: the 3D triangle is laid in its plane by
//! Gram–Schmidt (not by the cross product), X is inverted by the generic 2×2 adjugate formula,
//! and the singular values come from the eigenvalues of JᵀJ (not from a closed-form SVD).

use std::collections::{HashMap, HashSet};

/// The records of an OBJ file that matter here, 0-based.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Obj {
    /// `v x y z`, in file order.
    pub v: Vec<[f64; 3]>,
    /// `vt u v`, in file order.
    pub vt: Vec<[f64; 2]>,
    /// Position indices of each `f` (triangles only), in file order.
    pub f_v: Vec<[usize; 3]>,
    /// Texture indices of each `f`, `None` when the face has none (`f a b c`).
    pub f_vt: Vec<Option<[usize; 3]>>,
}

fn number(tok: Option<&str>, line_no: usize) -> Result<f64, String> {
    let tok = tok.ok_or_else(|| format!("line {line_no}: missing number"))?;
    tok.parse()
        .map_err(|_| format!("line {line_no}: {tok:?} is not a number"))
}

fn index(tok: &str, count: usize, line_no: usize) -> Result<usize, String> {
    let i: usize = tok
        .parse()
        .map_err(|_| format!("line {line_no}: {tok:?} is not a positive index"))?;
    if i == 0 || i > count {
        return Err(format!("line {line_no}: index {i} outside 1..={count}"));
    }
    Ok(i - 1)
}

/// Parses `v`, `vt` and triangular `f` records (`a`, `a/t`, `a/t/n`, `a//n` corners, positive
/// indices); skips comments, blank lines and every other record.
pub fn parse_obj(text: &str) -> Result<Obj, String> {
    let mut obj = Obj::default();
    let mut faces: Vec<(Vec<&str>, usize)> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let data = line.split('#').next().unwrap_or("");
        let mut tok = data.split_whitespace();
        match tok.next() {
            Some("v") => {
                let p = [
                    number(tok.next(), line_no)?,
                    number(tok.next(), line_no)?,
                    number(tok.next(), line_no)?,
                ];
                obj.v.push(p);
            }
            Some("vt") => {
                let t = [number(tok.next(), line_no)?, number(tok.next(), line_no)?];
                obj.vt.push(t);
            }
            Some("f") => faces.push((tok.collect(), line_no)),
            _ => {}
        }
    }
    // Indices are checked once every v and vt record is known.
    for (corners, line_no) in faces {
        if corners.len() != 3 {
            return Err(format!(
                "line {line_no}: face has {} corners, expected a triangle",
                corners.len()
            ));
        }
        let mut fv = [0usize; 3];
        let mut ft = [0usize; 3];
        let mut textured = 0;
        for (k, c) in corners.iter().enumerate() {
            let mut parts = c.split('/');
            fv[k] = index(parts.next().unwrap_or(""), obj.v.len(), line_no)?;
            match parts.next() {
                Some(t) if !t.is_empty() => {
                    ft[k] = index(t, obj.vt.len(), line_no)?;
                    textured += 1;
                }
                _ => {}
            }
        }
        obj.f_v.push(fv);
        obj.f_vt.push(match textured {
            0 => None,
            3 => Some(ft),
            _ => return Err(format!("line {line_no}: only some corners have a vt index")),
        });
    }
    Ok(obj)
}

/// The report's measured fields, recomputed.
#[derive(Clone, Debug, PartialEq)]
pub struct Metrics {
    pub vertices: usize,
    pub faces: usize,
    pub interior_edges: usize,
    pub boundary_loops: usize,
    /// Faces with signed UV area ≤ 0.
    pub flips: usize,
    /// Unweighted mean of σ1/σ2.
    pub delta_con_mean: f64,
    /// 3D-area-weighted mean of σ1/σ2.
    pub delta_con_area_mean: f64,
    pub delta_con_max: f64,
    /// Area-weighted mean of σ1/σ2 + σ2/σ1.
    pub mips_energy: f64,
    /// Area-weighted mean of σ1² + σ1⁻² + σ2² + σ2⁻² with the UV scaled to the 3D area.
    pub sd_energy: f64,
}

fn sub3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// One face: (σ1, σ2 ≥ 0, 3D area, signed UV area).
fn face(p: [[f64; 3]; 3], t: [[f64; 2]; 3]) -> (f64, f64, f64, f64) {
    // Isometric layout: x0 = 0, x1 = (|e1|, 0), x2 = (e2·ê1, |e2 − (e2·ê1) ê1|).
    let e1 = sub3(p[1], p[0]);
    let e2 = sub3(p[2], p[0]);
    let l1 = dot3(e1, e1).sqrt();
    let ex = [e1[0] / l1, e1[1] / l1, e1[2] / l1];
    let a = dot3(e2, ex);
    let w = [e2[0] - a * ex[0], e2[1] - a * ex[1], e2[2] - a * ex[2]];
    let h = dot3(w, w).sqrt();
    // X = [x1 − x0, x2 − x0] = [[l1, a], [0, h]]; X⁻¹ = adj(X) / det(X).
    let x = [[l1, a], [0.0, h]];
    let det_x = x[0][0] * x[1][1] - x[0][1] * x[1][0];
    let xi = [
        [x[1][1] / det_x, -x[0][1] / det_x],
        [-x[1][0] / det_x, x[0][0] / det_x],
    ];
    // U = [uv1 − uv0, uv2 − uv0]; J = U·X⁻¹.
    let u = [
        [t[1][0] - t[0][0], t[2][0] - t[0][0]],
        [t[1][1] - t[0][1], t[2][1] - t[0][1]],
    ];
    let mut j = [[0.0; 2]; 2];
    for r in 0..2 {
        for c in 0..2 {
            j[r][c] = u[r][0] * xi[0][c] + u[r][1] * xi[1][c];
        }
    }
    let uv_area = 0.5 * (u[0][0] * u[1][1] - u[0][1] * u[1][0]);
    // JᵀJ = [[m, q], [q, n]]: eigenvalues (m + n ± √((m − n)² + 4q²)) / 2; the small one as
    // det(JᵀJ)/λ1 = det(J)²/λ1, which keeps its relative accuracy when σ2 ≪ σ1.
    let m = j[0][0] * j[0][0] + j[1][0] * j[1][0];
    let n = j[0][1] * j[0][1] + j[1][1] * j[1][1];
    let q = j[0][0] * j[0][1] + j[1][0] * j[1][1];
    let lambda1 = 0.5 * (m + n + ((m - n) * (m - n) + 4.0 * q * q).sqrt());
    let det_j = j[0][0] * j[1][1] - j[0][1] * j[1][0];
    let lambda2 = det_j * det_j / lambda1;
    (lambda1.sqrt(), lambda2.sqrt(), 0.5 * det_x.abs(), uv_area)
}

/// Edge and boundary-loop counts of a triangle list: (interior edges, boundary loops), where a
/// boundary loop is a connected component of the graph of edges used by exactly one face.
fn topology(faces: &[[usize; 3]]) -> (usize, usize) {
    let mut uses: HashMap<(usize, usize), usize> = HashMap::new();
    for f in faces {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            *uses.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let interior = uses.values().filter(|&&c| c == 2).count();
    // Union-find over the boundary vertices.
    let mut parent: HashMap<usize, usize> = HashMap::new();
    fn root(parent: &mut HashMap<usize, usize>, v: usize) -> usize {
        let mut r = v;
        while let Some(&p) = parent.get(&r) {
            if p == r {
                break;
            }
            r = p;
        }
        parent.insert(v, r);
        r
    }
    for (&(a, b), _) in uses.iter().filter(|(_, &c)| c == 1) {
        parent.entry(a).or_insert(a);
        parent.entry(b).or_insert(b);
        let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
        parent.insert(ra, rb);
    }
    let vertices: Vec<usize> = parent.keys().copied().collect();
    let roots: HashSet<usize> = vertices.into_iter().map(|v| root(&mut parent, v)).collect();
    (interior, roots.len())
}

/// Recomputes the metrics of `obj`'s UV map: positions through the `f` position indices, UVs
/// through the `f` texture indices (faces without them are an error).
pub fn metrics(obj: &Obj) -> Result<Metrics, String> {
    let nf = obj.f_v.len();
    let mut per_face = Vec::with_capacity(nf);
    for (i, (fv, ft)) in obj.f_v.iter().zip(&obj.f_vt).enumerate() {
        let ft = ft.ok_or_else(|| format!("face {i} has no vt indices"))?;
        let p = [obj.v[fv[0]], obj.v[fv[1]], obj.v[fv[2]]];
        let t = [obj.vt[ft[0]], obj.vt[ft[1]], obj.vt[ft[2]]];
        per_face.push(face(p, t));
    }
    let flips = per_face
        .iter()
        .filter(|f| f.3.is_nan() || f.3 <= 0.0)
        .count();
    let area_3d: f64 = per_face.iter().map(|f| f.2).sum();
    let area_uv: f64 = per_face.iter().map(|f| f.3).sum();
    let weighted = |g: &dyn Fn(f64, f64) -> f64| {
        per_face.iter().map(|f| f.2 * g(f.0, f.1)).sum::<f64>() / area_3d
    };
    // σ scales linearly with the UV: s²·(UV area) = 3D area.
    let s = (area_3d / area_uv).sqrt();
    let (interior_edges, boundary_loops) = topology(&obj.f_v);
    Ok(Metrics {
        vertices: obj.v.len(),
        faces: nf,
        interior_edges,
        boundary_loops,
        flips,
        delta_con_mean: per_face.iter().map(|f| f.0 / f.1).sum::<f64>() / nf as f64,
        delta_con_area_mean: weighted(&|s1, s2| s1 / s2),
        delta_con_max: per_face
            .iter()
            .map(|f| f.0 / f.1)
            .fold(f64::NEG_INFINITY, f64::max),
        mips_energy: weighted(&|s1, s2| s1 / s2 + s2 / s1),
        sd_energy: weighted(&|s1, s2| {
            let (a, b) = (s * s1, s * s2);
            a * a + 1.0 / (a * a) + b * b + 1.0 / (b * b)
        }),
    })
}

/// Pairs of boundary segments of a UV layout that cross (sharing no vertex), by brute force
/// over all pairs: the boundary is every UV edge used by one face. Independent of the
/// library's grid-accelerated count (`metrics::boundary_self_intersections`).
pub fn boundary_crossings(faces: &[[usize; 3]], uv: &[[f64; 2]]) -> usize {
    let mut count = HashMap::<[usize; 2], usize>::new();
    for t in faces {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry([a.min(b), a.max(b)]).or_default() += 1;
        }
    }
    let segs: Vec<[usize; 2]> = count
        .into_iter()
        .filter(|&(_, n)| n == 1)
        .map(|(e, _)| e)
        .collect();
    let p = |i: usize| uv[i];
    let orient = |a: [f64; 2], b: [f64; 2], c: [f64; 2]| {
        (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    };
    let mut n = 0;
    for i in 0..segs.len() {
        for j in i + 1..segs.len() {
            let ([a, b], [c, d]) = (segs[i], segs[j]);
            if a == c || a == d || b == c || b == d {
                continue;
            }
            let (d1, d2) = (orient(p(c), p(d), p(a)), orient(p(c), p(d), p(b)));
            let (d3, d4) = (orient(p(a), p(b), p(c)), orient(p(a), p(b), p(d)));
            if d1 * d2 < 0.0 && d3 * d4 < 0.0 {
                n += 1;
            }
        }
    }
    n
}

/// [`boundary_crossings`] of an OBJ's `vt` layout.
pub fn file_boundary_crossings(obj: &Obj) -> usize {
    let faces: Vec<[usize; 3]> = obj.f_vt.iter().flatten().copied().collect();
    boundary_crossings(&faces, &obj.vt)
}
