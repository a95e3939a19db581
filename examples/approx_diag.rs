//! Diagnostic (not shipped): where do the bad faces of `approx` sit?
use foldfree::approx::{self, cluster::vertex_clusters, geom, untangle, ApproxOptions};
use foldfree::mesh::{self, Topology, NO_FACE};
use std::path::Path;

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let path = Path::new(&a[1]);
    let k: usize = a[2].parse().unwrap();
    let m = mesh::read_obj(path).unwrap();
    let topo = Topology::build(&m, path).unwrap();
    // Optional 4th argument: one run with this seed (no restarts).
    let mut opts = ApproxOptions::new(k);
    if let Some(s) = a.get(4) {
        opts.seed = s.parse().unwrap();
        opts.restarts = 0;
    }
    let out = approx::approximate(&m, &topo, &opts, &mut |_| {}).unwrap();
    let diag = geom::bbox_diagonal(&m);
    let bad = untangle::bad_faces(
        &out.positions,
        &m.faces,
        &out.face_cluster,
        &out.planes,
        1e-12 * diag * diag,
    );
    let vc = vertex_clusters(&topo, &out.face_cluster);
    let nreg = out.planes.len();
    let mut per = vec![0usize; nreg];
    let mut size = vec![0usize; nreg];
    for &c in &out.face_cluster {
        size[c as usize] += 1;
    }
    for &f in &bad {
        per[out.face_cluster[f] as usize] += 1;
    }
    println!("bad {} regions {}", bad.len(), nreg);
    if let Some(dump) = a.get(3) {
        // Raw state for offline analysis: positions, faces, regions, planes, bad faces.
        let planes: Vec<[f64; 4]> = out
            .planes
            .iter()
            .map(|p| p.map_or([0.0; 4], |p| [p.n[0], p.n[1], p.n[2], p.d]))
            .collect();
        let j = format!(
            "{{\"pos\":{:?},\"input\":{:?},\"faces\":{:?},\"fc\":{:?},\"planes\":{:?},\"bad\":{:?}}}",
            out.positions, m.positions, m.faces, out.face_cluster, planes, bad
        );
        std::fs::write(dump, j).unwrap();
    }
    for r in 0..nreg {
        if per[r] == 0 {
            continue;
        }
        let p = out.planes[r].unwrap();
        // region boundary edges in 2D
        let (u, v) = frame(p.n);
        let mut segs = vec![];
        let mut nbrs = std::collections::BTreeSet::new();
        for (e, ef) in topo.edge_faces.iter().enumerate() {
            let c0 = out.face_cluster[ef[0] as usize] as usize;
            let c1 = if ef[1] == NO_FACE {
                usize::MAX
            } else {
                out.face_cluster[ef[1] as usize] as usize
            };
            if (c0 == r) != (c1 == r) {
                let [x, y] = topo.edges[e];
                let q = |w: u32| {
                    let s = out.positions[w as usize];
                    [geom::dot(s, u), geom::dot(s, v)]
                };
                segs.push((x, y, q(x), q(y)));
                nbrs.insert(if c0 == r { c1 } else { c0 });
            }
        }
        let mut cross = 0;
        for i in 0..segs.len() {
            for j in i + 1..segs.len() {
                let (a0, a1, p0, p1) = segs[i];
                let (b0, b1, q0, q1) = segs[j];
                if a0 == b0 || a0 == b1 || a1 == b0 || a1 == b1 {
                    continue;
                }
                if inter(p0, p1, q0, q1) {
                    cross += 1;
                }
            }
        }
        let bf: Vec<usize> = bad
            .iter()
            .copied()
            .filter(|&f| out.face_cluster[f] as usize == r)
            .collect();
        let cls: Vec<String> = bf
            .iter()
            .take(12)
            .map(|&f| {
                let c: Vec<usize> = m.faces[f].iter().map(|&w| vc[w as usize].len()).collect();
                format!("{c:?}")
            })
            .collect();
        // area of region faces in plane (signed) vs total abs
        let (mut sa, mut aa) = (0.0, 0.0);
        for (f, &c) in out.face_cluster.iter().enumerate() {
            if c as usize != r {
                continue;
            }
            let [i, j, l] = m.faces[f].map(|w| out.positions[w as usize]);
            let nn = geom::cross(geom::sub(j, i), geom::sub(l, i));
            sa += geom::dot(nn, p.n) / 2.0;
            aa += geom::norm(nn) / 2.0;
        }
        println!(
            "region {r}: faces {} bad {} nbrs {} outline-crossings {} signed/abs area {:.3} | {}",
            size[r],
            per[r],
            nbrs.len(),
            cross,
            sa / aa,
            cls.join(" ")
        );
    }
}
fn frame(n: [f64; 3]) -> ([f64; 3], [f64; 3]) {
    let t = if n[0].abs() < 0.9 {
        [1.0, 0.0, 0.0]
    } else {
        [0.0, 1.0, 0.0]
    };
    let u = geom::normalize(geom::cross(n, t)).unwrap();
    (u, geom::cross(n, u))
}
fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}
fn inter(p0: [f64; 2], p1: [f64; 2], q0: [f64; 2], q1: [f64; 2]) -> bool {
    orient(p0, p1, q0) * orient(p0, p1, q1) < 0.0 && orient(q0, q1, p0) * orient(q0, q1, p1) < 0.0
}
