//! glTF in and out through the `foldfree` binary: `.glb` files built here (normals and a
//! TEXCOORD_0) come back with every attribute intact, plus the map as a new TEXCOORD set
//! written with glTF's top-left UV origin (v' = 1 − v), vertices split where the map has seams;
//! `.gltf` output writes a `.bin` beside it. What is written is read back with the `gltf` crate
//! (not foldfree's reader) and checked against the glTF 2.0 rules foldfree relies on
//! ([`spec_problems`]). With `FOLDFREE_GLTF_VALIDATOR=1` the Khronos validator
//! (`ci/gltf_validate.sh`, from the npm registry) must accept the outputs too.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

use crate::common::glb;
use crate::common::glb::{Prim, ReadPrim};
use crate::common::run::check_ok;
use crate::common::{data, foldfree, TempDir};

fn obj(name: &str) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let m = foldfree::mesh::read_obj(&data(name)).expect("test mesh");
    (m.positions, m.faces)
}

/// The sphere's faces whose centroid has z > −0.3: a curved disk.
fn cap() -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let (p, f) = glb::sphere(3);
    let f: Vec<[u32; 3]> = f
        .into_iter()
        .filter(|t| t.iter().map(|&v| p[v as usize][2]).sum::<f64>() > -0.9)
        .collect();
    let mut used: Vec<u32> = f.iter().flatten().copied().collect();
    used.sort_unstable();
    used.dedup();
    let faces = f
        .iter()
        .map(|t| t.map(|v| used.binary_search(&v).unwrap() as u32))
        .collect();
    (used.iter().map(|&v| p[v as usize]).collect(), faces)
}

/// Signed area of a triangle in a UV plane.
fn area(a: [f32; 2], b: [f32; 2], c: [f32; 2]) -> f64 {
    let (a, b, c) = (a.map(f64::from), b.map(f64::from), c.map(f64::from));
    0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))
}

/// The glTF 2.0 rules foldfree's output relies on, checked on the JSON and the binary buffer
/// (`None` problems = the output satisfies them): GLB chunk layout and 4-byte padding; one
/// buffer whose byteLength fits its data; every bufferView inside the buffer; every accessor
/// inside its view (offset + stride·(count−1) + element size), aligned to its component size;
/// vertex-attribute byteStride a multiple of 4 in [4, 252]; POSITION with min/max equal to its
/// data's bounds; TEXCOORD FLOAT VEC2 (or normalized UNSIGNED_BYTE/SHORT); all attributes of a
/// primitive with one count; indices below that count and never the restart value; TEXCOORD
/// sets numbered 0, 1, … without gaps.
fn spec_problems(main: &[u8], bin: Option<&[u8]>) -> Vec<String> {
    let mut problems = Vec::new();
    let (json_bytes, blob): (&[u8], Vec<u8>) = if main.starts_with(b"glTF") {
        let word = |at: usize| u32::from_le_bytes(main[at..at + 4].try_into().unwrap()) as usize;
        if word(4) != 2 || word(8) != main.len() {
            problems.push("GLB header version/length".into());
        }
        let jl = word(12);
        if &main[16..20] != b"JSON" || jl % 4 != 0 {
            problems.push("GLB JSON chunk type or padding".into());
        }
        let b = 20 + jl;
        let bl = word(b);
        if &main[b + 4..b + 8] != b"BIN\0" || bl % 4 != 0 || b + 8 + bl != main.len() {
            problems.push("GLB BIN chunk type, padding or length".into());
        }
        (&main[20..20 + jl], main[b + 8..b + 8 + bl].to_vec())
    } else {
        (main, bin.expect(".gltf output has a .bin").to_vec())
    };
    let doc: Value = serde_json::from_slice(json_bytes).expect("JSON");
    let buffers = doc["buffers"].as_array().expect("buffers");
    if buffers.len() != 1 {
        problems.push(format!("{} buffers, expected 1", buffers.len()));
    }
    let blen = buffers[0]["byteLength"].as_u64().unwrap() as usize;
    if blen > blob.len() || blob.len() - blen > 3 {
        problems.push(format!("buffer byteLength {blen}, data {}", blob.len()));
    }
    let u = |v: &Value| v.as_u64().unwrap_or(0) as usize;
    let views = doc["bufferViews"].as_array().unwrap();
    for (i, v) in views.iter().enumerate() {
        if u(&v["byteOffset"]) + u(&v["byteLength"]) > blen {
            problems.push(format!("bufferViews[{i}] runs past the buffer"));
        }
        if let Some(s) = v["byteStride"].as_u64() {
            if s % 4 != 0 || !(4..=252).contains(&s) {
                problems.push(format!("bufferViews[{i}].byteStride {s}"));
            }
        }
    }
    let accessors = doc["accessors"].as_array().unwrap();
    let comp_size = |c: u64| match c {
        5120 | 5121 => 1,
        5122 | 5123 => 2,
        _ => 4,
    };
    let dims = |t: &str| match t {
        "SCALAR" => 1,
        "VEC2" => 2,
        "VEC3" => 3,
        "VEC4" | "MAT2" => 4,
        "MAT3" => 9,
        _ => 16,
    };
    for (i, a) in accessors.iter().enumerate() {
        let v = &views[u(&a["bufferView"])];
        let cs = comp_size(a["componentType"].as_u64().unwrap());
        let size = cs * dims(a["type"].as_str().unwrap());
        let stride = v["byteStride"].as_u64().map_or(size, |s| s as usize);
        let count = u(&a["count"]);
        let end = u(&a["byteOffset"]) + stride * count.saturating_sub(1) + size;
        if count > 0 && end > u(&v["byteLength"]) {
            problems.push(format!("accessors[{i}] runs past its bufferView"));
        }
        if (u(&v["byteOffset"]) + u(&a["byteOffset"])) % cs != 0 {
            problems.push(format!(
                "accessors[{i}] is not aligned to its component size"
            ));
        }
    }
    let read_f32 = |a: &Value, i: usize, k: usize| -> f32 {
        let v = &views[u(&a["bufferView"])];
        let size = 4 * dims(a["type"].as_str().unwrap());
        let stride = v["byteStride"].as_u64().map_or(size, |s| s as usize);
        let at = u(&v["byteOffset"]) + u(&a["byteOffset"]) + i * stride + 4 * k;
        f32::from_le_bytes(blob[at..at + 4].try_into().unwrap())
    };
    for (m, mesh) in doc["meshes"].as_array().unwrap().iter().enumerate() {
        for (p, prim) in mesh["primitives"].as_array().unwrap().iter().enumerate() {
            let at = format!("meshes[{m}].primitives[{p}]");
            let attrs = prim["attributes"].as_object().unwrap();
            let pos = &accessors[u(&attrs["POSITION"])];
            let n = u(&pos["count"]);
            for (name, idx) in attrs {
                let a = &accessors[u(idx)];
                if u(&a["count"]) != n {
                    problems.push(format!("{at}.{name}: count differs from POSITION"));
                }
                if name.starts_with("TEXCOORD_") {
                    let ok = a["type"] == "VEC2"
                        && (a["componentType"] == 5126
                            || (a["normalized"] == true
                                && matches!(a["componentType"].as_u64(), Some(5121 | 5123))));
                    if !ok {
                        problems.push(format!("{at}.{name}: not FLOAT VEC2"));
                    }
                }
            }
            let sets = attrs.keys().filter(|k| k.starts_with("TEXCOORD_")).count();
            for s in 0..sets {
                if !attrs.contains_key(&format!("TEXCOORD_{s}")) {
                    problems.push(format!("{at}: TEXCOORD sets have a gap at {s}"));
                }
            }
            let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
            for i in 0..n {
                for k in 0..3 {
                    let x = read_f32(pos, i, k);
                    lo[k] = lo[k].min(x);
                    hi[k] = hi[k].max(x);
                }
            }
            let as_f32 = |v: &Value| -> Option<Vec<f32>> {
                v.as_array()
                    .map(|a| a.iter().map(|x| x.as_f64().unwrap() as f32).collect())
            };
            if as_f32(&pos["min"]) != Some(lo.to_vec()) || as_f32(&pos["max"]) != Some(hi.to_vec())
            {
                problems.push(format!("{at}: POSITION min/max are not its bounds"));
            }
            if let Some(ix) = prim["indices"].as_u64() {
                let a = &accessors[ix as usize];
                let v = &views[u(&a["bufferView"])];
                let cs = comp_size(a["componentType"].as_u64().unwrap());
                let restart = (1u64 << (8 * cs)) - 1;
                for i in 0..u(&a["count"]) {
                    let at_b = u(&v["byteOffset"]) + u(&a["byteOffset"]) + i * cs;
                    let x = match cs {
                        1 => u64::from(blob[at_b]),
                        2 => u64::from(u16::from_le_bytes([blob[at_b], blob[at_b + 1]])),
                        _ => {
                            u64::from(u32::from_le_bytes(blob[at_b..at_b + 4].try_into().unwrap()))
                        }
                    };
                    if x >= n as u64 || x == restart {
                        problems.push(format!("{at}: index {x} of {n} vertices"));
                        break;
                    }
                }
            }
        }
    }
    problems
}

/// Every output vertex is an input vertex (same position, normal and TEXCOORD_0, bit for bit),
/// every input vertex that a triangle uses is still there, and the triangles are the input's
/// (same positions per corner, in order).
fn attributes_kept(input: &Prim, out: &ReadPrim) -> Vec<String> {
    let mut problems = Vec::new();
    let key = |p: [f32; 3], n: [f32; 3], t: [f32; 2]| {
        let mut k: Vec<u32> = p.iter().chain(&n).chain(&t).map(|x| x.to_bits()).collect();
        k.shrink_to_fit();
        k
    };
    let inputs: std::collections::HashSet<Vec<u32>> = (0..input.positions.len())
        .map(|i| key(input.positions[i], input.normals[i], input.uv0[i]))
        .collect();
    for i in 0..out.positions.len() {
        if !inputs.contains(&key(out.positions[i], out.normals[i], out.uvs[0][i])) {
            problems.push(format!("output vertex {i} is no input vertex"));
            break;
        }
    }
    if input.target.is_some() && out.target.len() != out.positions.len() {
        problems.push("the morph target lost its count".to_string());
    }
    let in_ix: Vec<u32> = input
        .indices
        .clone()
        .unwrap_or_else(|| (0..input.positions.len() as u32).collect());
    if in_ix.len() != out.indices.len() {
        problems.push(format!(
            "{} corners in, {} out",
            in_ix.len(),
            out.indices.len()
        ));
        return problems;
    }
    for (c, (&a, &b)) in in_ix.iter().zip(&out.indices).enumerate() {
        let (a, b) = (a as usize, b as usize);
        let target_moved = input
            .target
            .as_ref()
            .is_some_and(|t| out.target.get(b) != Some(&t[a]));
        if input.positions[a] != out.positions[b]
            || input.normals[a] != out.normals[b]
            || target_moved
        {
            problems.push(format!("corner {c}: another vertex"));
            break;
        }
    }
    problems
}

/// The new set (index `set`) has no flipped triangle in foldfree's orientation, i.e. every
/// triangle is clockwise in glTF's top-left-origin UV plane; returns the number of triangles
/// checked.
fn assert_flip_free_in_gltf_convention(out: &ReadPrim, set: usize) -> usize {
    let uv = &out.uvs[set];
    let mut n = 0;
    for t in out.indices.chunks_exact(3) {
        let [a, b, c] = [0, 1, 2].map(|k| uv[t[k] as usize]);
        let in_gltf = area(a, b, c);
        let flip = |p: [f32; 2]| [p[0], 1.0 - p[1]];
        let in_foldfree = area(flip(a), flip(b), flip(c));
        assert!(
            in_gltf < 0.0 && in_foldfree > 0.0,
            "triangle {n}: area {in_gltf} in glTF's UV plane (expected < 0: v is flipped)"
        );
        n += 1;
    }
    n
}

/// Writes `prim` as `in.glb` in `dir`, runs `foldfree param in.glb -o out.glb --report r.json`
/// with `args`, and returns the output's path and the report.
fn map_glb(dir: &TempDir, prim: &Prim, args: &[&str]) -> (PathBuf, Value) {
    let input = dir.join("in.glb");
    fs::write(&input, glb::glb(std::slice::from_ref(prim))).unwrap();
    let (out, report) = (dir.join("out.glb"), dir.join("r.json"));
    let mut all = vec![
        Path::new("param"),
        &input,
        Path::new("-o"),
        &out,
        Path::new("--report"),
        &report,
    ];
    all.extend(args.iter().map(Path::new));
    check_ok(&foldfree(&all), "param in.glb");
    let r = serde_json::from_slice(&fs::read(&report).unwrap()).unwrap();
    (out, r)
}

fn validate_with_khronos(files: &[&Path]) {
    if std::env::var("FOLDFREE_GLTF_VALIDATOR").as_deref() != Ok("1") {
        eprintln!("Khronos glTF validator: skipped (set FOLDFREE_GLTF_VALIDATOR=1)");
        return;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("ci/gltf_validate.sh");
    let out = Command::new("bash")
        .arg(script)
        .args(files)
        .output()
        .expect("run ci/gltf_validate.sh");
    eprintln!("{}", String::from_utf8_lossy(&out.stdout));
    check_ok(&out, "the Khronos glTF validator");
}

#[test]
fn disk_glb_round_trip_keeps_attributes_and_adds_a_flipped_v_set() {
    // Not camel_open.obj: it is a closed camel cut open, the cut's vertices duplicated at
    // equal positions, which glTF reading welds back (an atlas).
    let dir = TempDir::new("gltf-disk");
    let (p, f) = cap();
    let prim = Prim::smooth(&p, &f);
    let (out, r) = map_glb(&dir, &prim, &["--init", "tutte", "--solver", "none"]);
    assert_eq!(r["faces"], f.len(), "every triangle read");
    assert!(r["atlas"].is_null(), "a disk: no atlas");
    // The report states the convention the flip test below checks.
    assert_eq!(r["uv_output"]["format"], "gltf");
    assert_eq!(r["uv_output"]["v_origin"], "top-left");
    assert_eq!(r["uv_output"]["texcoord_sets"], serde_json::json!([1]));
    let bytes = fs::read(&out).unwrap();
    assert_eq!(spec_problems(&bytes, None), Vec::<String>::new());
    let (json, prims) = glb::read_back(&bytes, None);
    assert_eq!(
        json["nodes"][0]["name"], "kept",
        "the rest of the document is kept"
    );
    assert_eq!(prims.len(), 1);
    let o = &prims[0];
    assert_eq!(o.uvs.len(), 2, "TEXCOORD_0 kept, TEXCOORD_1 added");
    assert_eq!(
        o.positions.len(),
        prim.positions.len(),
        "a disk splits nothing"
    );
    assert_eq!(attributes_kept(&prim, o), Vec::<String>::new());
    assert_eq!(o.uvs[0], prim.uv0, "TEXCOORD_0 unchanged");
    assert_eq!(assert_flip_free_in_gltf_convention(o, 1), f.len());
    validate_with_khronos(&[&out]);
}

#[test]
fn flat_shaded_primitive_is_welded_into_one_disk() {
    let dir = TempDir::new("gltf-flat");
    let (p, f) = obj("square_grid_10x10.obj");
    let prim = Prim::flat(&p, &f);
    let (out, r) = map_glb(&dir, &prim, &[]);
    assert_eq!(
        r["vertices"],
        p.len(),
        "split glTF vertices welded by position"
    );
    assert!(r["atlas"].is_null(), "welded, the grid is one disk");
    let bytes = fs::read(&out).unwrap();
    assert_eq!(spec_problems(&bytes, None), Vec::<String>::new());
    let (_, prims) = glb::read_back(&bytes, None);
    let o = &prims[0];
    assert_eq!(attributes_kept(&prim, o), Vec::<String>::new());
    assert_eq!(assert_flip_free_in_gltf_convention(o, 1), f.len());
    // Corners at one welded position get one UV: the seams of the glTF are not cuts.
    let mut by_pos = std::collections::HashMap::new();
    for i in 0..o.positions.len() {
        let k = o.positions[i].map(f32::to_bits);
        let t = *by_pos.entry(k).or_insert(o.uvs[1][i]);
        assert_eq!(t, o.uvs[1][i], "one UV per welded vertex");
    }
}

#[test]
fn closed_mesh_atlas_splits_vertices_on_seams_and_writes_gltf_with_bin() {
    let dir = TempDir::new("gltf-atlas");
    let (p, f) = glb::sphere(2);
    let mut prim = Prim::smooth(&p, &f);
    // A morph target (inflate along the normal): its displacements are split with the vertices.
    prim.target = Some(prim.normals.iter().map(|n| n.map(|c| 0.1 * c)).collect());
    let input = dir.join("sphere.glb");
    fs::write(&input, glb::glb(std::slice::from_ref(&prim))).unwrap();
    let out = dir.join("sphere_uv.gltf");
    let run = foldfree(&[Path::new("param"), &input, Path::new("-o"), &out]);
    check_ok(&run, "param sphere.glb -o sphere_uv.gltf");
    let bin_path = dir.join("sphere_uv.bin");
    let (main, bin) = (fs::read(&out).unwrap(), fs::read(&bin_path).unwrap());
    assert_eq!(spec_problems(&main, Some(&bin)), Vec::<String>::new());
    let (json, prims) = glb::read_back(&main, Some(&bin));
    assert_eq!(json["buffers"][0]["uri"], "sphere_uv.bin");
    let o = &prims[0];
    assert!(
        o.positions.len() > prim.positions.len(),
        "seams split vertices: {} → {}",
        prim.positions.len(),
        o.positions.len()
    );
    assert_eq!(attributes_kept(&prim, o), Vec::<String>::new());
    assert_eq!(assert_flip_free_in_gltf_convention(o, 1), f.len());
    for t in &o.uvs[1] {
        assert!(
            t.iter().all(|c| (0.0..=1.0).contains(c)),
            "atlas UV {t:?} in [0,1]²"
        );
    }
    let files: Vec<String> = dir.entries().into_iter().collect();
    assert_eq!(files, ["sphere.glb", "sphere_uv.bin", "sphere_uv.gltf"]);
    validate_with_khronos(&[&out]);
    // The .gltf reads again, its buffer from the .bin beside it, and takes a third set.
    let again = dir.join("again.glb");
    check_ok(
        &foldfree(&[Path::new("param"), &out, Path::new("-o"), &again]),
        "param sphere_uv.gltf",
    );
    let (_, prims) = glb::read_back(&fs::read(&again).unwrap(), None);
    assert_eq!(prims[0].uvs.len(), 3);
    assert_eq!(assert_flip_free_in_gltf_convention(&prims[0], 2), f.len());
    // A .bin that an input reads is an input too: an output .gltf whose .bin would replace it
    // is refused, and nothing is written.
    let copy = dir.join("copy.gltf");
    fs::copy(&out, &copy).unwrap();
    let run = foldfree(&[Path::new("param"), &copy, Path::new("-o"), &out]);
    let err = String::from_utf8_lossy(&run.stderr);
    assert_eq!(run.status.code(), Some(2), "{err}");
    assert!(err.contains("refusing to overwrite the input"), "{err}");
    assert_eq!(fs::read(&bin_path).unwrap(), bin, "the input .bin is kept");
}

#[test]
fn uv_set_that_exists_or_leaves_a_gap_is_refused_before_any_work() {
    let dir = TempDir::new("gltf-set");
    let (p, f) = obj("square_grid_10x10.obj");
    let input = dir.join("grid.glb");
    fs::write(&input, glb::glb(&[Prim::smooth(&p, &f)])).unwrap();
    let out = dir.join("out.glb");
    let with_set = |set: &str| {
        let set = Path::new(set);
        foldfree(&[
            Path::new("param"),
            &input,
            Path::new("-o"),
            &out,
            Path::new("--uv-set"),
            set,
        ])
    };
    for (set, says) in [("0", "already has TEXCOORD_0"), ("2", "would leave a gap")] {
        let run = with_set(set);
        let err = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "--uv-set {set}: {err}");
        assert!(err.contains(says), "--uv-set {set}: {err}");
        assert!(!out.exists());
    }
    check_ok(&with_set("1"), "--uv-set 1");
    // A glTF output needs a glTF input.
    let run = foldfree(&[
        Path::new("param"),
        &data("square_grid_10x10.obj"),
        Path::new("-o"),
        &dir.join("x.glb"),
    ]);
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("needs a glTF input"));
}

#[test]
fn gltf_input_writes_the_same_map_as_obj() {
    // The OBJ output of a glTF input is the welded mesh with its map: same UVs as the glTF's
    // new set, v flipped back.
    let dir = TempDir::new("gltf-obj");
    let (p, f) = obj("square_grid_10x10.obj");
    let prim = Prim::smooth(&p, &f);
    let input = dir.join("grid.glb");
    fs::write(&input, glb::glb(std::slice::from_ref(&prim))).unwrap();
    let (g, o) = (dir.join("g.glb"), dir.join("o.obj"));
    for out in [&g, &o] {
        check_ok(
            &foldfree(&[Path::new("param"), &input, Path::new("-o"), out]),
            "param",
        );
    }
    let (_, prims) = glb::read_back(&fs::read(&g).unwrap(), None);
    let text = fs::read_to_string(&o).unwrap();
    let vt: Vec<[f64; 2]> = text
        .lines()
        .filter_map(|l| l.strip_prefix("vt "))
        .map(|l| {
            let c: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [c[0], c[1]]
        })
        .collect();
    assert_eq!(vt.len(), prims[0].uvs[1].len());
    for (a, b) in vt.iter().zip(&prims[0].uvs[1]) {
        assert_eq!(a[0] as f32, b[0]);
        assert_eq!((1.0 - a[1]) as f32, b[1]);
    }
}

/// A stand-in for `fuzz/fuzz_targets/gltf_reader.rs` in the normal suite: every prefix of the
/// glTF square of tests/data/bad (`.glb` and `.gltf`) and every byte replaced by a few values
/// reads to a mesh with in-range indices or to an error naming the file, and whatever reads is
/// written back as a `.glb` that reads again with one more TEXCOORD set; never a panic.
#[test]
fn every_prefix_and_byte_mutation_reads_and_writes_back_or_is_a_located_error() {
    use foldfree::mesh::formats::gltf::{parse_gltf, write_gltf, GltfTarget};
    let file = Path::new("m.glb");
    let mut none = |_: &str| Err("no external buffers".to_string());
    let mut check = |bytes: &[u8]| match parse_gltf(bytes, file, &mut none) {
        Ok(scene) => {
            let n = scene.mesh.positions.len();
            assert!(scene.mesh.faces.iter().flatten().all(|&v| (v as usize) < n));
            let uv: Vec<[f64; 2]> = scene.mesh.positions.iter().map(|p| [p[0], p[1]]).collect();
            if uv.iter().flatten().all(|c| c.is_finite()) {
                let w = write_gltf(&scene, &uv, &scene.mesh.faces, None, &GltfTarget::Glb)
                    .expect("a read file writes back");
                let mut none = |_: &str| Err("no external buffers".to_string());
                let again = parse_gltf(&w.main, file, &mut none).expect("reads back");
                for (a, b) in scene.primitives.iter().zip(&again.primitives) {
                    assert_eq!(a.texcoord_sets.len() + 1, b.texcoord_sets.len());
                }
            }
        }
        Err(e) => assert!(e.to_string().starts_with("m.glb: "), "{e}"),
    };
    for name in ["glb_square_valid.glb", "gltf_square_valid.gltf"] {
        let bytes = fs::read(data("bad").join(name)).unwrap();
        for cut in 0..bytes.len() {
            check(&bytes[..cut]);
        }
        let mut mutated = bytes.clone();
        for i in 0..bytes.len() {
            for b in [0u8, b'0', b'5', b'9', b'"', b'-', b',', 0xff] {
                mutated[i] = b;
                check(&mutated);
            }
            mutated[i] = bytes[i];
        }
    }
}
