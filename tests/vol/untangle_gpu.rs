//! The untangler's device kernel (`glsl/vol/untangle_tet.comp`) against its CPU f64 twin
//! (`vol::untangle::tet_terms`), then the whole untangling stage on the device, under the
//! validation layer (and synchronization validation in CI: `with_test_context` fails a test
//! that produced any message).
//!
//! Inputs: (a) random tets — random rest shapes and random maps, about a third of them inverted;
//! (b) a structured tet grid (5 × 5 × 5 cubes, 6 tets each) under a twist with every interior
//! vertex jittered, so some tets fold — the kind of map the untangler starts from. Every input is
//! rounded to f32 before the CPU twin sees it, so the comparison measures the kernel's
//! arithmetic only.

use crate::common::gpu as gpu_common;
use crate::common::Rng;

use foldfree::vol::newton::{corners_of, Corner};
use foldfree::vol::untangle::vulkan::DeviceTets;
use foldfree::vol::untangle::{
    tet_terms, untangle_sliding, untangle_sliding_protected, UntangleOptions,
};
use foldfree::vol::TetMesh;
use gpu_common::with_test_context;

/// Per-tet tolerance: |Δ| ≤ TOL · (|f| + 1) for the energy and TOL · (max |g| + 1) for each
/// gradient entry. The kernel is f32 (χ^{1/3} through `pow`, several divisions): on lavapipe the
/// worst measured difference is printed; a wrong formula or binding is off by O(1).
const TOL: f64 = 2e-4;

fn f32r(p: [f64; 3]) -> [f64; 3] {
    p.map(|c| f64::from(c as f32))
}

/// Corner weights of a rest tet, rounded to f32 like the upload.
fn weights_of(rest: &[[f64; 3]], t: &[u32; 4]) -> Option<Corner> {
    let (d, _) = corners_of(t.map(|v| rest[v as usize]))?;
    Some(d.map(|row| row.map(|v| f64::from(v as f32))))
}

/// Compares the kernel with the twin on `x` (positions), `tets`, `d`, `w`; returns the worst
/// relative differences (energy, gradient).
fn compare(
    ctx: &foldfree::gpu::Context,
    x: &[[f64; 3]],
    tets: &[[u32; 4]],
    d: &[Corner],
    w: &[f64],
    eps: f64,
) -> (f64, f64) {
    let x: Vec<[f64; 3]> = x.iter().map(|&p| f32r(p)).collect();
    let w: Vec<f64> = w.iter().map(|&v| f64::from(v as f32)).collect();
    let eps = f64::from(eps as f32);
    let mut dev = DeviceTets::new(ctx, tets, d, &w, x.len()).unwrap();
    let (fe, ge) = dev.evaluate(&x, eps, 0.5).unwrap();
    let (mut worst_f, mut worst_g) = (0.0f64, 0.0f64);
    for (t, tet) in tets.iter().enumerate() {
        let (f, g) = tet_terms(&x, tet, &d[t], w[t], eps, 0.5);
        let df = (f64::from(fe[t]) - f).abs() / (f.abs() + 1.0);
        let gmax = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut dg = 0.0f64;
        for c in 0..4 {
            for r in 0..3 {
                dg = dg.max((f64::from(ge[4 * t + c][r]) - g[3 * c + r]).abs() / (gmax + 1.0));
            }
        }
        assert!(
            df <= TOL && dg <= TOL,
            "tet {t} (ε {eps}): energy {} vs {f} (rel {df:.2e}), gradient rel {dg:.2e}",
            fe[t]
        );
        worst_f = worst_f.max(df);
        worst_g = worst_g.max(dg);
    }
    (worst_f, worst_g)
}

#[test]
fn kernel_matches_cpu_twin_on_random_tets() {
    with_test_context(|ctx| {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let n = 4096;
        let mut rest = Vec::new();
        let mut x = Vec::new();
        let mut tets = Vec::new();
        let mut d = Vec::new();
        let mut w = Vec::new();
        let mut inverted = 0;
        while tets.len() < n {
            let base = rest.len() as u32;
            let r: Vec<[f64; 3]> = (0..4)
                .map(|_| [0; 3].map(|_| rng.range(-1.0, 1.0)))
                .collect();
            let t = [base, base + 1, base + 2, base + 3];
            // Positive, well-shaped rest tets: the f32 error of J = Σ x_j ⊗ D_j grows with the
            // rest tet's condition number (the D_j of a sliver are large and cancel), which is
            // the upload's conditioning, not the kernel's arithmetic.
            let det = |p: &[[f64; 3]]| {
                let e = |k: usize| [0, 1, 2].map(|c| p[k][c] - p[0][c]);
                let (a, b, c) = (e(1), e(2), e(3));
                a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                    + a[2] * (b[0] * c[1] - b[1] * c[0])
            };
            if det(&r) < 0.5 {
                continue;
            }
            let Some(dw) = weights_of(&r, &[0, 1, 2, 3]) else {
                continue;
            };
            let m: Vec<[f64; 3]> = (0..4)
                .map(|_| [0; 3].map(|_| rng.range(-1.0, 1.0)))
                .collect();
            inverted += usize::from(det(&m) <= 0.0);
            rest.extend(r);
            x.extend(m);
            tets.push(t);
            d.push(dw);
            w.push(rng.range(0.1, 1.0) / n as f64);
        }
        assert!(
            inverted > n / 5,
            "the random maps must include inverted tets"
        );
        for eps in [1.0, 1e-1, 1e-2] {
            let (f, g) = compare(ctx, &x, &tets, &d, &w, eps);
            println!(
                "random tets, ε {eps}: worst relative difference energy {f:.2e}, gradient {g:.2e}"
            );
        }
    });
}

/// A 5×5×5 grid of unit cubes, 6 positive tets per cube (Kuhn subdivision).
fn grid(n: usize) -> TetMesh {
    let id = |i: usize, j: usize, k: usize| (i + (n + 1) * (j + (n + 1) * k)) as u32;
    let mut positions = Vec::new();
    for k in 0..=n {
        for j in 0..=n {
            for i in 0..=n {
                positions.push([i as f64, j as f64, k as f64]);
            }
        }
    }
    let mut tets = Vec::new();
    for k in 0..n {
        for j in 0..n {
            for i in 0..n {
                let c = |a: usize, b: usize, e: usize| id(i + a, j + b, k + e);
                // The six paths from (0,0,0) to (1,1,1) along the axes.
                for p in [
                    [0, 1, 2],
                    [0, 2, 1],
                    [1, 0, 2],
                    [1, 2, 0],
                    [2, 0, 1],
                    [2, 1, 0],
                ] {
                    let mut v = [0usize; 3];
                    let mut corners = vec![c(0, 0, 0)];
                    for axis in p {
                        v[axis] = 1;
                        corners.push(c(v[0], v[1], v[2]));
                    }
                    tets.push([corners[0], corners[1], corners[2], corners[3]]);
                }
            }
        }
    }
    let mut m = TetMesh::new(positions, tets);
    // Orient every tet positively.
    for t in 0..m.tets.len() {
        if m.volume_at(&m.positions, t) < 0.0 {
            m.tets[t].swap(2, 3);
        }
    }
    m
}

/// The twisted, jittered grid: boundary exactly twisted (a fold-free map with that boundary
/// exists), interior vertices jittered enough to fold some tets.
fn tangled_grid() -> (TetMesh, Vec<[f64; 3]>, Vec<bool>) {
    let m = grid(5);
    let bnd = m.boundary_vertices();
    let mut fixed = vec![false; m.positions.len()];
    for &v in &bnd {
        fixed[v as usize] = true;
    }
    let mut rng = Rng(42);
    let x: Vec<[f64; 3]> = m
        .positions
        .iter()
        .enumerate()
        .map(|(v, p)| {
            let a = 0.25 * p[2];
            let (c, s) = (a.cos(), a.sin());
            let q = [
                2.5 + c * (p[0] - 2.5) - s * (p[1] - 2.5),
                2.5 + s * (p[0] - 2.5) + c * (p[1] - 2.5),
                p[2],
            ];
            if fixed[v] {
                q
            } else {
                [0, 1, 2].map(|r| q[r] + rng.range(-0.9, 0.9))
            }
        })
        .collect();
    (m, x, fixed)
}

#[test]
fn kernel_matches_cpu_twin_on_a_tangled_grid() {
    with_test_context(|ctx| {
        let (m, x, _) = tangled_grid();
        assert!(!m.inverted(&x).is_empty(), "the jitter must fold some tets");
        let d: Vec<Corner> = m
            .tets
            .iter()
            .map(|t| weights_of(&m.positions, t).unwrap())
            .collect();
        let w = vec![1.0 / m.tets.len() as f64; m.tets.len()];
        for eps in [1e-1, 1e-2] {
            let (f, g) = compare(ctx, &x, &m.tets, &d, &w, eps);
            println!(
                "tangled grid, ε {eps}: worst relative difference energy {f:.2e}, gradient {g:.2e}"
            );
        }
    });
}

#[test]
fn device_untangler_untangles_the_tangled_grid() {
    with_test_context(|ctx| {
        let (m, x0, fixed) = tangled_grid();
        let start = m.inverted(&x0).len();
        let mut x = x0.clone();
        let s = untangle_sliding(
            &m,
            &mut x,
            &fixed,
            &[],
            &UntangleOptions::default(),
            Some(ctx),
        )
        .unwrap();
        assert!(start > 0);
        assert_eq!(
            s.inverted, 0,
            "device untangler left {} of {start} inverted",
            s.inverted
        );
        assert!(m.inverted(&x).is_empty());
        for (v, &f) in fixed.iter().enumerate() {
            if f {
                assert_eq!(x[v], x0[v], "fixed vertex {v} moved");
            }
        }
        // The CPU path untangles the same start too.
        let mut y = x0.clone();
        let c =
            untangle_sliding(&m, &mut y, &fixed, &[], &UntangleOptions::default(), None).unwrap();
        assert_eq!(c.inverted, 0);
        println!(
            "tangled grid: {start} inverted; device {} L-BFGS steps, CPU {}",
            s.iterations, c.iterations
        );
    });
}

/// The protected untangling (the ball target's default: flagged tets keep the ε → 0 barrier,
/// recomputed on the host after the device's per-tet terms) on the device and on the CPU:
/// here the tets with a fixed corner are flagged; both untangle the grid, and no flagged tet
/// that was positive at the start is inverted at the end.
#[test]
fn device_protected_untangler_keeps_flagged_tets_positive() {
    with_test_context(|ctx| {
        let (m, x0, fixed) = tangled_grid();
        let flag: Vec<bool> = m
            .tets
            .iter()
            .map(|t| t.iter().any(|&v| fixed[v as usize]))
            .collect();
        let positive: Vec<bool> = (0..m.tets.len())
            .map(|t| !m.inverted(&x0).contains(&t))
            .collect();
        assert!(flag.iter().zip(&positive).any(|(&f, &p)| f && p));
        for device in [Some(ctx), None] {
            let mut x = x0.clone();
            let s = untangle_sliding_protected(
                &m,
                &mut x,
                &fixed,
                &[],
                &flag,
                &UntangleOptions::default(),
                device,
            )
            .unwrap();
            let after = m.inverted(&x);
            assert_eq!(s.inverted, after.len());
            assert_eq!(
                s.inverted,
                0,
                "{} left {} inverted",
                if device.is_some() { "device" } else { "CPU" },
                s.inverted
            );
            for t in 0..m.tets.len() {
                assert!(
                    !(flag[t] && positive[t] && after.contains(&t)),
                    "protected tet {t} inverted"
                );
            }
        }
    });
}
