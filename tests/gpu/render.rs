//! `foldfree render`: the offscreen checkerboard view of a UV map. Through the binary (PNG size,
//! foreground coverage, a visible checker) and in-process under the validation layer (with
//! synchronization validation when `FOLDFREE_SYNC_VALIDATION=1`). Skips without Vulkan unless
//! `REQUIRE_VULKAN=1`.

use crate::common::gpu as gpu_common;

use std::fs;
use std::io::Cursor;
use std::path::Path;

use foldfree::gpu::{render_checker, RenderDesc, BACKGROUND};

use crate::common::gpu::vulkan_available;
use crate::common::run::check_ok;
use crate::common::{data, foldfree, TempDir};

/// Whether Vulkan is usable here (panics under `REQUIRE_VULKAN=1` when it is not).
/// Success, or a run that stopped at its iteration cap and wrote its best map (exit 3).
fn check_kept(out: &std::process::Output, what: &str) {
    let stderr = String::from_utf8_lossy(&out.stderr);
    if out.status.code() == Some(3) && stderr.contains("best flip-free map was written") {
        return;
    }
    check_ok(out, what);
}

/// Decodes an RGBA8 PNG into (width, height, pixels).
fn decode(bytes: &[u8]) -> (u32, u32, Vec<[u8; 4]>) {
    let mut reader = png::Decoder::new(Cursor::new(bytes))
        .read_info()
        .expect("PNG header");
    let mut buf = vec![0; reader.output_buffer_size().expect("PNG buffer size")];
    let info = reader.next_frame(&mut buf).expect("PNG image data");
    assert_eq!(info.color_type, png::ColorType::Rgba);
    assert_eq!(info.bit_depth, png::BitDepth::Eight);
    let px = buf[..info.buffer_size()]
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    (info.width, info.height, px)
}

/// Foreground coverage, the shares of dark and light foreground pixels, and the number of
/// dark↔light transitions along scanlines.
struct Stats {
    foreground: f64,
    dark: f64,
    light: f64,
    transitions: usize,
}

fn luminance(p: [u8; 4]) -> f64 {
    0.2126 * f64::from(p[0]) + 0.7152 * f64::from(p[1]) + 0.0722 * f64::from(p[2])
}

fn stats(w: u32, h: u32, px: &[[u8; 4]]) -> Stats {
    let bg = BACKGROUND.map(|c| (c * 255.0).round() as i32);
    let is_fg = |p: [u8; 4]| (0..3).any(|k| (i32::from(p[k]) - bg[k]).abs() > 6);
    const DARK: f64 = 90.0;
    const LIGHT: f64 = 140.0;
    let (mut fg, mut dark, mut light, mut transitions) = (0usize, 0usize, 0usize, 0usize);
    for y in 0..h as usize {
        // The class of the last foreground pixel on this row: Some(true) light, Some(false) dark.
        let mut last: Option<bool> = None;
        for x in 0..w as usize {
            let p = px[y * w as usize + x];
            assert_eq!(p[3], 255, "opaque picture");
            if !is_fg(p) {
                last = None;
                continue;
            }
            fg += 1;
            let l = luminance(p);
            let class = if l < DARK {
                dark += 1;
                Some(false)
            } else if l > LIGHT {
                light += 1;
                Some(true)
            } else {
                None
            };
            if let Some(c) = class {
                if last.is_some_and(|prev| prev != c) {
                    transitions += 1;
                }
                last = Some(c);
            }
        }
    }
    let fgf = fg.max(1) as f64;
    Stats {
        foreground: fg as f64 / (w as f64 * h as f64),
        dark: dark as f64 / fgf,
        light: light as f64 / fgf,
        transitions,
    }
}

fn render_via_cli(dir: &TempDir, uv_obj: &Path, size: u32, checker: u32) -> Stats {
    let png_path = dir.join("view.png");
    let size_s = size.to_string();
    let checker_s = checker.to_string();
    let out = foldfree(&[
        "render",
        uv_obj.to_str().expect("utf-8 path"),
        "-o",
        png_path.to_str().expect("utf-8 path"),
        "--checker",
        &checker_s,
        "--size",
        &size_s,
        "--validation",
    ]);
    check_ok(&out, "foldfree render");
    let (w, h, px) = decode(&fs::read(&png_path).expect("PNG written"));
    assert_eq!((w, h), (size, size), "picture size");
    stats(w, h, &px)
}

#[test]
fn render_square_grid_after_tutte() {
    if !vulkan_available() {
        return;
    }
    let dir = TempDir::new("square");
    let uv = dir.join("square_uv.obj");
    let out = foldfree(&[
        "param",
        data("square_grid_10x10.obj").to_str().expect("utf-8 path"),
        "-o",
        uv.to_str().expect("utf-8 path"),
        "--init",
        "tutte",
        "--solver",
        "none",
        "-q",
    ]);
    check_ok(&out, "foldfree param");
    let s = render_via_cli(&dir, &uv, 256, 8);
    // The flat square seen face-on fills the picture up to the 5% margin.
    assert!(s.foreground > 0.7, "foreground {:.3}", s.foreground);
    assert!(
        s.dark > 0.3 && s.light > 0.3,
        "dark {:.3} light {:.3}",
        s.dark,
        s.light
    );
    // 8 squares across (distorted by Tutte, so about 8 colour changes per row) on ~230 rows.
    assert!(s.transitions > 1000, "{} transitions", s.transitions);
}

#[test]
fn render_camel_after_admm() {
    if !vulkan_available() {
        return;
    }
    let dir = TempDir::new("camel");
    let uv = dir.join("camel_uv.obj");
    let out = foldfree(&[
        "param",
        data("camel_open.obj").to_str().expect("utf-8 path"),
        "-o",
        uv.to_str().expect("utf-8 path"),
        "--backend",
        "cpu",
        "--max-iters",
        "200",
        "-q",
    ]);
    check_kept(&out, "foldfree param");
    let s = render_via_cli(&dir, &uv, 384, 16);
    assert!(s.foreground > 0.05, "foreground {:.3}", s.foreground);
    assert!(
        s.dark > 0.15 && s.light > 0.15,
        "dark {:.3} light {:.3}",
        s.dark,
        s.light
    );
    assert!(s.transitions > 200, "{} transitions", s.transitions);
}

#[test]
fn render_without_vt_is_a_usage_error() {
    let dir = TempDir::new("novt");
    let png_path = dir.join("x.png");
    let out = foldfree(&[
        "render",
        data("square_grid_10x10.obj").to_str().expect("utf-8 path"),
        "-o",
        png_path.to_str().expect("utf-8 path"),
    ]);
    assert_eq!(out.status.code(), Some(2), "exit code");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("no texture coordinates"), "{stderr}");
    assert!(!png_path.exists(), "no picture on error");
}

/// A `n × n` grid on the unit square in the z = 0 plane, UV = xy, tilted out of plane a little
/// (so shading varies), with one vertex per grid point.
fn grid(n: u32) -> (Vec<[f32; 3]>, Vec<[f32; 2]>, Vec<u32>) {
    let mut p = Vec::new();
    let mut t = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
            p.push([u, v, 0.2 * u * v]);
            t.push([u, v]);
        }
    }
    let mut idx = Vec::new();
    let row = n + 1;
    for j in 0..n {
        for i in 0..n {
            let a = j * row + i;
            idx.extend_from_slice(&[a, a + 1, a + row + 1, a, a + row + 1, a + row]);
        }
    }
    (p, t, idx)
}

#[test]
fn render_in_process_is_validation_clean() {
    gpu_common::with_test_context(|ctx| {
        let (p, t, idx) = grid(12);
        let desc = RenderDesc {
            width: 200,
            height: 120,
            checker: 6,
            view_dir: [0.0, 0.0, 1.0],
            shade: Default::default(),
        };
        let rgba = render_checker(ctx, &p, &t, &idx, &desc).expect("render");
        assert_eq!(rgba.len(), 200 * 120 * 4);
        let px: Vec<[u8; 4]> = rgba
            .chunks_exact(4)
            .map(|c| [c[0], c[1], c[2], c[3]])
            .collect();
        let s = stats(200, 120, &px);
        assert!(s.foreground > 0.4, "foreground {:.3}", s.foreground);
        assert!(
            s.dark > 0.3 && s.light > 0.3,
            "dark {:.3} light {:.3}",
            s.dark,
            s.light
        );
        assert!(s.transitions > 300, "{} transitions", s.transitions);
        // Rendering twice gives the same pixels.
        let again = render_checker(ctx, &p, &t, &idx, &desc).expect("render again");
        assert_eq!(rgba, again, "deterministic");
        // Bad input is refused before any GPU work.
        assert!(render_checker(ctx, &p, &t, &[0, 1, 9999], &desc).is_err());
    });
}

/// Distinct colours among the pixels that are not background.
fn distinct_foreground(px: &[[u8; 4]]) -> usize {
    let bg = px[0];
    px.iter()
        .filter(|p| **p != bg)
        .collect::<std::collections::HashSet<_>>()
        .len()
}

/// `foldfree render INPUT -o PNG --shade normals --size SIZE VIEW --validation`.
fn render_normals(input: &Path, png: &Path, size: u32, view: &str) -> std::process::Output {
    let size = size.to_string();
    foldfree(&[
        "render",
        input.to_str().expect("utf-8 path"),
        "-o",
        png.to_str().expect("utf-8 path"),
        "--shade",
        "normals",
        "--size",
        &size,
        view,
        "--validation",
    ])
}

/// `--shade normals` renders any triangle mesh (no `vt` needed) with one colour per flat
/// normal: the planar approximation of the block (`foldfree approx -k 24`) shows at most as
/// many colours as it has planar regions, far fewer than the curved original.
#[test]
fn render_normals_of_an_approximation() {
    if !vulkan_available() {
        return;
    }
    let dir = TempDir::new("normals");
    let approx = dir.join("block24.obj");
    let report = dir.join("block24.json");
    let out = foldfree(&[
        "approx",
        data("block.obj").to_str().expect("utf-8 path"),
        "-k",
        "24",
        "-q",
        "-o",
        approx.to_str().expect("utf-8 path"),
        "--report",
        report.to_str().expect("utf-8 path"),
    ]);
    check_ok(&out, "foldfree approx");
    let regions = serde_json::from_slice::<serde_json::Value>(&fs::read(&report).expect("report"))
        .expect("json")["k_obtained"]
        .as_u64()
        .expect("report.k_obtained") as usize;
    let render = |input: &Path, name: &str| {
        let png = dir.join(name);
        let out = render_normals(input, &png, 256, "--view=1,1,1");
        check_ok(&out, "foldfree render --shade normals");
        let (w, h, px) = decode(&fs::read(&png).expect("PNG written"));
        assert_eq!((w, h), (256, 256));
        let s = stats(w, h, &px);
        assert!(s.foreground > 0.1, "foreground {:.3}", s.foreground);
        distinct_foreground(&px)
    };
    let flat = render(&approx, "approx.png");
    let original = render(&data("block.obj"), "original.png");
    assert!(
        flat <= regions,
        "{flat} colours for {regions} planar regions"
    );
    assert!(
        original > 4 * flat,
        "original {original} vs approximation {flat} colours"
    );
}

/// A tet mesh's boundary surface renders too (`.mesh`): the unit cube of 5 tets seen along
/// (1, 1, 1) shows exactly its three front faces, one flat colour each.
#[test]
fn render_normals_of_a_tet_boundary() {
    if !vulkan_available() {
        return;
    }
    let dir = TempDir::new("tet_boundary");
    let png = dir.join("cube.png");
    let input = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/cube_5tets.mesh");
    let out = render_normals(&input, &png, 128, "--view=1,1,1");
    check_ok(&out, "foldfree render cube_5tets.mesh");
    let (w, h, px) = decode(&fs::read(&png).expect("PNG written"));
    let s = stats(w, h, &px);
    assert!(s.foreground > 0.2, "foreground {:.3}", s.foreground);
    assert_eq!(
        distinct_foreground(&px),
        3,
        "three visible faces, one colour each"
    );
}

/// PLY, OFF and STL surfaces render like OBJ: the unit square as a quad OBJ, ASCII and binary
/// PLY, COFF and binary STL (tests/data/bad, all valid) gives the same picture byte for byte.
/// The checker needs `vt`, which only an OBJ carries: other formats are refused by name.
#[test]
fn render_normals_reads_every_surface_format() {
    let bad = |name: &str| data("bad").join(name);
    let dir = TempDir::new("formats");
    let stl = bad("stl_binary_square_valid.stl");
    let png = dir.join("checker.png");
    let out = foldfree(&[
        "render",
        stl.to_str().expect("utf-8 path"),
        "-o",
        png.to_str().expect("utf-8 path"),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("no texture coordinates") && stderr.contains("this STL surface"),
        "{stderr}"
    );
    if !vulkan_available() {
        return;
    }
    let render = |input: &Path| {
        let png = dir.join("normals.png");
        let out = render_normals(input, &png, 64, "--view=0.3,0.2,1");
        check_ok(&out, &format!("foldfree render {}", input.display()));
        fs::read(&png).expect("PNG written")
    };
    let reference = render(&bad("quad_valid.obj"));
    for name in [
        "ply_quad_with_normals_valid.ply",
        "ply_binary_big_endian_valid.ply",
        "coff_quad_valid.off",
        "stl_binary_square_valid.stl",
    ] {
        assert!(render(&bad(name)) == reference, "{name}: another picture");
    }
}

use crate::common::glb;

/// The glTF path draws the checker like the OBJ path: a sphere (an atlas, so seams split
/// glTF vertices) mapped once into a `.glb` and once into an OBJ renders (near-)identically —
/// the glTF's UVs are f32 with v flipped (v' = 1 − v), read back as (u, 1 − v'), so only
/// checker edges may move by a rounding. The checker through a glTF without a TEXCOORD set is
/// refused.
#[test]
fn render_checker_of_gltf_matches_the_obj_of_the_same_map() {
    let dir = TempDir::new("gltf");
    let (p, f) = glb::sphere(3);
    let input = dir.join("sphere.glb");
    fs::write(&input, glb::glb(&[glb::Prim::smooth(&p, &f)])).expect("write the glb");
    let (g, o) = (dir.join("map.glb"), dir.join("map.obj"));
    for out in [&g, &o] {
        let run = foldfree(&[
            "param",
            input.to_str().expect("utf-8 path"),
            "-o",
            out.to_str().expect("utf-8 path"),
            "-q",
        ]);
        check_ok(&run, "foldfree param sphere.glb");
    }
    // TEXCOORD_0 (the planar one the file came with) is not the map: --uv-set picks.
    let png = dir.join("x.png");
    let run = foldfree(&[
        "render",
        g.to_str().expect("utf-8 path"),
        "-o",
        png.to_str().expect("utf-8 path"),
        "--uv-set",
        "7",
    ]);
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("has no TEXCOORD_7"));
    if !vulkan_available() {
        return;
    }
    let render = |input: &Path| {
        let png = dir.join("view.png");
        let out = foldfree(&[
            "render",
            input.to_str().expect("utf-8 path"),
            "-o",
            png.to_str().expect("utf-8 path"),
            "--checker",
            "16",
            "--size",
            "256",
            "--view=0.3,0.5,1",
            "--validation",
        ]);
        check_ok(&out, &format!("foldfree render {}", input.display()));
        decode(&fs::read(&png).expect("PNG written"))
    };
    let (w, h, from_gltf) = render(&g);
    let (_, _, from_obj) = render(&o);
    let s = stats(w, h, &from_gltf);
    assert!(s.dark > 0.15 && s.light > 0.15, "a visible checker");
    let differ = from_gltf
        .iter()
        .zip(&from_obj)
        .filter(|(a, b)| a != b)
        .count();
    eprintln!(
        "glTF vs OBJ render: {differ} of {} pixels differ",
        from_gltf.len()
    );
    assert!(
        differ * 1000 < from_gltf.len(),
        "{differ} of {} pixels differ between the glTF and the OBJ render",
        from_gltf.len()
    );
}
