//! Meshes that are not disks: `foldfree param` cuts them into disk charts, maps each chart and
//! packs the charts into [0,1]². Each written OBJ is checked from the file alone: the input's
//! `v` records unchanged, every chart (faces joined through shared `vt`) a disk with 0 flips,
//! charts pairwise disjoint inside the unit square, and the report's metrics equal to an
//! independent recomputation (tests/common/objcheck.rs).

use crate::common::objcheck;

use std::collections::HashMap;
use std::fs;
use std::path::Path;

use crate::common::{data_obj as data, TempDir};
use serde_json::Value;

fn foldfree(args: &[&str]) -> (Option<i32>, String) {
    let out = crate::common::foldfree(args);
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into(),
    )
}

/// Charts of an OBJ: faces joined when they share a `vt` index (seams split `vt`, not `v`).
/// Writes `[cut] overlap_splits = n` to a tuning file in `dir`; its path, for `--tuning`.
fn overlap_splits(dir: &TempDir, n: usize) -> String {
    let path = dir.join("tuning.toml");
    fs::write(&path, format!("[cut]\noverlap_splits = {n}\n")).expect("write tuning");
    path.to_str().expect("utf-8 path").to_string()
}

fn charts(obj: &objcheck::Obj) -> Vec<Vec<usize>> {
    let mut parent: Vec<usize> = (0..obj.f_v.len()).collect();
    fn root(p: &mut [usize], mut x: usize) -> usize {
        while p[x] != x {
            p[x] = p[p[x]];
            x = p[x];
        }
        x
    }
    let mut first: HashMap<usize, usize> = HashMap::new();
    for (f, t) in obj.f_vt.iter().enumerate() {
        for &t in t.as_ref().expect("every face has vt") {
            match first.get(&t) {
                Some(&g) => {
                    let (a, b) = (root(&mut parent, f), root(&mut parent, g));
                    parent[a] = b;
                }
                None => {
                    first.insert(t, f);
                }
            }
        }
    }
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for f in 0..obj.f_v.len() {
        let r = root(&mut parent, f);
        groups.entry(r).or_default().push(f);
    }
    let mut out: Vec<Vec<usize>> = groups.into_values().collect();
    out.sort();
    out
}

/// χ and boundary-loop count of a chart, counted on `vt` indices: a disk has χ = 1 and one loop.
fn chart_topology(obj: &objcheck::Obj, faces: &[usize]) -> (i64, usize) {
    let mut edges: HashMap<(usize, usize), usize> = HashMap::new();
    let mut verts = std::collections::HashSet::new();
    for &f in faces {
        let t = obj.f_vt[f].expect("vt");
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            verts.insert(a);
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let boundary: Vec<(usize, usize)> = edges
        .iter()
        .filter(|(_, &n)| n == 1)
        .map(|(&e, _)| e)
        .collect();
    // Loops = connected components of the boundary-edge graph.
    let mut adj: HashMap<usize, Vec<usize>> = HashMap::new();
    for &(a, b) in &boundary {
        adj.entry(a).or_default().push(b);
        adj.entry(b).or_default().push(a);
    }
    let mut seen = std::collections::HashSet::new();
    let mut loops = 0;
    for &start in adj.keys() {
        if !seen.insert(start) {
            continue;
        }
        loops += 1;
        let mut stack = vec![start];
        while let Some(v) = stack.pop() {
            for &w in &adj[&v] {
                if seen.insert(w) {
                    stack.push(w);
                }
            }
        }
    }
    assert!(edges.values().all(|&n| n <= 2), "a vt edge has 3 faces");
    let chi = verts.len() as i64 - edges.len() as i64 + faces.len() as i64;
    (chi, loops)
}

/// Runs `param` on `input` and checks the written atlas; returns the report.
/// Runs `foldfree param` with `extra` and checks the written atlas from the file; with
/// `expect_charts` = None any chart count is accepted (it is still checked against the report).
fn check_atlas(input: &Path, dir: &TempDir, extra: &[&str], expect_charts: Option<usize>) -> Value {
    let out = dir.join("out.obj");
    let rep = dir.join("out.json");
    let mut args = vec![
        "param",
        input.to_str().expect("utf-8 path"),
        "-o",
        out.to_str().expect("utf-8 path"),
        "--report",
        rep.to_str().expect("utf-8 path"),
        "-q",
    ];
    args.extend_from_slice(extra);
    let (code, stderr) = foldfree(&args);
    let kept = code == Some(3) && stderr.contains("best flip-free map was written");
    assert!(code == Some(0) || kept, "{stderr}");

    let src = objcheck::parse_obj(&fs::read_to_string(input).expect("read input")).expect("input");
    let obj = objcheck::parse_obj(&fs::read_to_string(&out).expect("read output")).expect("output");
    assert_eq!(obj.v, src.v, "v records must be the input's, in order");
    assert_eq!(obj.f_v, src.f_v, "faces must be the input's, in order");
    // Seams only add texture coordinates: at least one per referenced vertex.
    let referenced: std::collections::HashSet<usize> = src.f_v.iter().flatten().copied().collect();
    assert!(obj.vt.len() >= referenced.len(), "vt: {}", obj.vt.len());

    let report: Value =
        serde_json::from_str(&fs::read_to_string(&rep).expect("read report")).expect("json");
    let m = objcheck::metrics(&obj).expect("metrics");
    assert_eq!(m.flips, 0);
    assert_eq!(report["flips"], 0);
    for key in [
        "delta_con_mean",
        "mips_energy",
        "sd_energy",
        "delta_con_max",
    ] {
        let r = report[key].as_f64().expect(key);
        let x = match key {
            "delta_con_mean" => m.delta_con_mean,
            "mips_energy" => m.mips_energy,
            "sd_energy" => m.sd_energy,
            _ => m.delta_con_max,
        };
        assert!(
            (r - x).abs() <= 1e-6 * x.abs().max(1.0),
            "{key}: report {r} vs file {x}"
        );
    }

    let groups = charts(&obj);
    if let Some(n) = expect_charts {
        assert_eq!(groups.len(), n);
    }
    assert_eq!(report["atlas"]["charts"], groups.len());
    // Boundary crossings counted from the file alone (brute force over the vt boundary).
    assert_eq!(
        report["boundary_self_intersections"],
        objcheck::file_boundary_crossings(&obj),
        "report vs file: boundary crossings"
    );
    assert_eq!(
        report["atlas"]["texture_coordinates"].as_u64(),
        Some(obj.vt.len() as u64)
    );
    for g in &groups {
        assert_eq!(chart_topology(&obj, g), (1, 1), "chart is not a disk");
    }
    let resolution = report["atlas"]["resolution"].as_u64().expect("resolution") as usize;
    let padding = report["atlas"]["padding"].as_u64().expect("padding") as usize;
    check_texels(&obj, &groups, resolution, padding);
    let eff = report["atlas"]["packing_efficiency"].as_f64().expect("eff");
    assert!(eff > 0.05 && eff <= 1.0, "packing efficiency {eff}");
    report
}

/// Rasterizes every chart of the file at `n`² (a texel belongs to a chart when one of its
/// triangles covers the texel's centre or crosses the texel's edges — tested independently of
/// the packer: each triangle is sampled on a 4×4 grid per texel plus its own vertices and edge
/// midpoints), and checks that the charts lie inside `[0, 1]²`, keep their orientation (no
/// mirrored chart) and that no two charts' texels are within `padding` texels of each other.
fn check_texels(obj: &objcheck::Obj, groups: &[Vec<usize>], n: usize, padding: usize) {
    let mut owner = vec![usize::MAX; n * n];
    let nf = n as f64;
    let mut mark = |x: f64, y: f64, c: usize| {
        let (i, j) = ((x * nf).floor() as usize, (y * nf).floor() as usize);
        if i < n && j < n {
            let o = &mut owner[j * n + i];
            assert!(
                *o == usize::MAX || *o == c,
                "texel ({i}, {j}) holds charts {} and {c}",
                *o
            );
            *o = c;
        }
    };
    for (c, g) in groups.iter().enumerate() {
        for &f in g {
            let t = obj.f_vt[f].expect("vt").map(|k| obj.vt[k]);
            for q in &t {
                assert!(
                    (0.0..=1.0).contains(&q[0]) && (0.0..=1.0).contains(&q[1]),
                    "{q:?}"
                );
            }
            let signed = (t[1][0] - t[0][0]) * (t[2][1] - t[0][1])
                - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1]);
            assert!(signed > 0.0, "chart {c}: a face is mirrored or degenerate");
            // Barycentric samples dense enough to hit every texel the triangle covers by more
            // than a sliver (4 per texel along the longest edge).
            let len = (0..3)
                .map(|k| {
                    let (a, b) = (t[k], t[(k + 1) % 3]);
                    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
                })
                .fold(0.0, f64::max);
            let steps = ((len * nf * 4.0).ceil() as usize).max(1);
            for u in 0..=steps {
                for v in 0..=steps - u {
                    let (a, b) = (u as f64 / steps as f64, v as f64 / steps as f64);
                    let w = 1.0 - a - b;
                    mark(
                        w * t[0][0] + a * t[1][0] + b * t[2][0],
                        w * t[0][1] + a * t[1][1] + b * t[2][1],
                        c,
                    );
                }
            }
        }
    }
    for j in 0..n {
        for i in 0..n {
            let o = owner[j * n + i];
            if o == usize::MAX {
                continue;
            }
            for dj in j.saturating_sub(padding)..(j + padding + 1).min(n) {
                for di in i.saturating_sub(padding)..(i + padding + 1).min(n) {
                    let q = owner[dj * n + di];
                    assert!(
                        q == usize::MAX || q == o,
                        "charts {o} and {q} are closer than {padding} texels at ({i}, {j})"
                    );
                }
            }
        }
    }
}

/// The global solver's single block chart, unconstrained, folds its boundary over itself
/// (checked from the file). By default the map is bijective: one chart, no crossing, no
/// splitting seam. With `--no-bijective` the overlapping chart is split by seams (the fallback).
#[test]
fn chart_that_would_overlap_itself_stays_one_bijective_chart() {
    let dir = TempDir::new("atlas_bijective");
    let args = ["--solver", "global", "--energy", "sd"];
    let r = check_atlas(&data("block"), &dir, &args, Some(1));
    assert_eq!(r["boundary_self_intersections"], 0);
    assert_eq!(r["atlas"]["overlap_splits"], 0);
    assert_eq!(r["atlas"]["injective_pieces"], 0);
    assert!(r["global"]["scaffold_iterations"].as_u64().expect("n") > 0);

    let dir = TempDir::new("atlas_split");
    let r = check_atlas(
        &data("block"),
        &dir,
        &[&args[..], &["--no-bijective"]].concat(),
        None,
    );
    assert_eq!(r["boundary_self_intersections"], 0);
    assert!(r["atlas"]["overlap_splits"].as_u64().expect("splits") >= 1);
    assert!(r["atlas"]["charts"].as_u64().expect("charts") > 1);

    let dir0 = TempDir::new("atlas_nosplit");
    let tuning = overlap_splits(&dir0, 0);
    let r0 = check_atlas(
        &data("block"),
        &dir0,
        &[&args[..], &["--no-bijective", "--tuning", &tuning]].concat(),
        Some(1),
    );
    assert!(r0["boundary_self_intersections"].as_u64().expect("n") > 0);
}

/// Unconstrained, with a budget of one seam the block's chart still overlaps after it; the last resort cuts
/// what overlaps into pieces that keep their map: no crossing, no flip, the same energy
/// as without any split (pieces are not re-mapped).
#[test]
fn a_chart_still_overlapping_after_its_seams_is_cut_into_pieces() {
    let dir = TempDir::new("atlas_pieces");
    let tuning = overlap_splits(&dir, 1);
    let args = [
        "--solver",
        "global",
        "--energy",
        "sd",
        "--no-bijective",
        "--tuning",
        tuning.as_str(),
    ];
    let r = check_atlas(&data("block"), &dir, &args, None);
    assert_eq!(r["boundary_self_intersections"], 0);
    assert_eq!(r["flips"], 0);
    assert_eq!(r["atlas"]["overlap_splits"], 1);
    let pieces = r["atlas"]["injective_pieces"].as_u64().expect("pieces");
    assert!(pieces >= 1, "{}", r["atlas"]);
    assert_eq!(
        r["atlas"]["charts"].as_u64().expect("charts"),
        2 + pieces,
        "one chart, one seam, then pieces"
    );
}

#[test]
fn closed_genus0_bunny_becomes_one_disk() {
    let dir = TempDir::new("atlas_bunny");
    let r = check_atlas(
        &data("bunny_npm"),
        &dir,
        &["--max-iters", "200", "--tuning", &overlap_splits(&dir, 0)],
        Some(1),
    );
    assert_eq!(r["atlas"]["genus"], 0);
    assert!(r["atlas"]["seam_edges"].as_u64().expect("seams") >= 2);
}

#[test]
fn genus3_block_becomes_one_disk() {
    let dir = TempDir::new("atlas_block");
    let r = check_atlas(
        &data("block"),
        &dir,
        &[
            "--max-iters",
            "100",
            "--energy",
            "sd",
            "--tuning",
            &overlap_splits(&dir, 0),
        ],
        Some(1),
    );
    assert_eq!(r["atlas"]["genus"], 3);
}

#[test]
fn several_components_are_packed_apart() {
    let dir = TempDir::new("atlas_components");
    // Three disjoint copies of a closed mesh, scaled differently: three charts.
    let text = fs::read_to_string(data("bunny_npm")).expect("read");
    let src = objcheck::parse_obj(&text).expect("parse");
    let mut out = String::from("# three scaled copies of bunny_npm\n");
    for (i, s) in [1.0, 0.5, 0.25].iter().enumerate() {
        for p in &src.v {
            out += &format!(
                "v {} {} {}\n",
                p[0] * s + 10.0 * i as f64,
                p[1] * s,
                p[2] * s
            );
        }
    }
    let n = src.v.len();
    for i in 0..3 {
        for f in &src.f_v {
            out += &format!(
                "f {} {} {}\n",
                f[0] + 1 + i * n,
                f[1] + 1 + i * n,
                f[2] + 1 + i * n
            );
        }
    }
    let input = dir.join("three.obj");
    fs::write(&input, out).expect("write");
    let r = check_atlas(
        &input,
        &dir,
        &[
            "--solver",
            "none",
            "--padding",
            "4",
            "--tuning",
            &overlap_splits(&dir, 0),
        ],
        Some(3),
    );
    let faces: Vec<u64> = r["atlas"]["chart_faces"]
        .as_array()
        .expect("array")
        .iter()
        .map(|v| v.as_u64().expect("n"))
        .collect();
    assert_eq!(faces, vec![src.f_v.len() as u64; 3]);
}

#[test]
fn disk_with_cut_always_is_packed_into_the_unit_square() {
    let dir = TempDir::new("atlas_disk");
    let r = check_atlas(
        &data("square_grid_10x10"),
        &dir,
        &["--cut", "always", "--solver", "none", "--init", "lscm"],
        Some(1),
    );
    assert_eq!(r["atlas"]["seam_edges"], 0);
    // A flat square maps to a square: the packing fills the texture up to the padding.
    let eff = r["atlas"]["packing_efficiency"].as_f64().expect("eff");
    assert!(eff > 0.97, "{eff}");
}

#[test]
fn cut_none_refuses_a_closed_mesh() {
    let dir = TempDir::new("atlas_none");
    let out = dir.join("out.obj");
    let (code, stderr) = foldfree(&[
        "param",
        data("bunny_npm").to_str().expect("utf-8"),
        "-o",
        out.to_str().expect("utf-8"),
        "--cut",
        "none",
    ]);
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("closed surface of genus 0"), "{stderr}");
    assert!(!out.exists());
}

/// The acceptance sweep over the shared meshes that are not disks (closed, open with several
/// holes, CAD). Not part of `cargo test` (tests must not need `../shared`): run it with
/// `FOLDFREE_SHARED_MESHES=../shared/meshes cargo test --release --test param shared_meshes_sweep -- --ignored --nocapture`.
#[test]
#[ignore]
fn shared_meshes_sweep() {
    let Ok(root) = std::env::var("FOLDFREE_SHARED_MESHES") else {
        panic!("set FOLDFREE_SHARED_MESHES to the shared meshes folder");
    };
    let iters = std::env::var("FOLDFREE_SWEEP_ITERS").unwrap_or_else(|_| "2000".into());
    // FOLDFREE_SWEEP_SOLVER=global sweeps the global solver (it has its own stop rule).
    let solver = std::env::var("FOLDFREE_SWEEP_SOLVER").unwrap_or_else(|_| "admm".into());
    for name in [
        "closed/bunny_npm",
        "closed/cheburashka",
        "closed/fertility",
        "closed/spot",
        "open/stanford_bunny_scan",
        "cad/block",
        "cad/fandisk",
        "cad/rocker_arm",
    ] {
        let input = Path::new(&root).join(format!("{name}.obj"));
        let dir = TempDir::new(&format!("sweep_{}", name.replace('/', "_")));
        for energy in ["mips", "sd"] {
            let mut args = vec!["--energy", energy, "--solver", solver.as_str()];
            if solver == "admm" {
                args.extend(["--max-iters", iters.as_str()]);
            }
            let r = check_atlas(&input, &dir, &args, None);
            println!(
                "| {name} | {solver} {energy} | {} | {} | {:.4} | {:.1}% | {} | {:.4} | {:.4} | {} | {} | {:.1} | {} |",
                r["faces"],
                r["atlas"]["seam_edges"],
                r["atlas"]["seam_length"].as_f64().unwrap_or(f64::NAN),
                100.0 * r["atlas"]["packing_efficiency"].as_f64().unwrap_or(f64::NAN),
                r["flips"],
                r["delta_con_mean"].as_f64().unwrap_or(f64::NAN),
                r["sd_energy"].as_f64().unwrap_or(f64::NAN),
                r["iterations"],
                r["converged"],
                r["seconds"].as_f64().unwrap_or(f64::NAN),
                r["boundary_self_intersections"],
            );
        }
    }
}

/// `--texel-density`: the scale is the one asked for, the texture the smallest square that
/// holds the atlas (a multiple of 4), and the layout passes the texel check at that size.
#[test]
fn texel_density_sets_the_scale_and_finds_the_resolution() {
    let dir = TempDir::new("atlas_density");
    let r = check_atlas(
        &data("bunny_npm"),
        &dir,
        &["--texel-density", "150", "--padding", "3"],
        None,
    );
    let a = &r["atlas"];
    assert_eq!(a["texels_per_unit"].as_f64(), Some(150.0));
    assert_eq!(a["padding"].as_u64(), Some(3));
    let res = a["resolution"].as_u64().expect("resolution");
    assert!(res % 4 == 0 && (16..1024).contains(&res), "{res}");
}
