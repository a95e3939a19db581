//! Pictures (`foldfree param --svg/--png/--plot` and the `viz` library calls):
//! the files exist, the SVG holds one subpath per face and no NaN, the PNGs decode to the
//! requested size, are not blank, keep the margins clear, and show pure red exactly when a
//! face is flipped. Uses only tests/data (plus an ignored timing run on a shared mesh).

mod common;

use std::fs;
use std::io::Cursor;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

use foldfree::mesh::TriMesh;
use foldfree::param::admm::History;
use foldfree::viz::{self, LayoutStyle};

use common::{data_obj as data, TempDir};

const RED: [u8; 3] = [255, 0, 0];

/// A decoded RGB8 picture.
struct Image {
    w: usize,
    h: usize,
    px: Vec<[u8; 3]>,
}

impl Image {
    fn decode(bytes: &[u8]) -> Image {
        let mut reader = png::Decoder::new(Cursor::new(bytes))
            .read_info()
            .expect("PNG header");
        let mut buf = vec![0; reader.output_buffer_size().expect("PNG buffer size")];
        let info = reader.next_frame(&mut buf).expect("PNG image data");
        assert_eq!(info.color_type, png::ColorType::Rgb);
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        let px = buf[..info.buffer_size()]
            .chunks_exact(3)
            .map(|c| [c[0], c[1], c[2]])
            .collect();
        Image {
            w: info.width as usize,
            h: info.height as usize,
            px,
        }
    }

    fn at(&self, x: usize, y: usize) -> [u8; 3] {
        self.px[y * self.w + x]
    }

    fn distinct(&self) -> usize {
        let mut c: Vec<[u8; 3]> = self.px.clone();
        c.sort_unstable();
        c.dedup();
        c.len()
    }

    fn count(&self, c: [u8; 3]) -> usize {
        self.px.iter().filter(|&&p| p == c).count()
    }

    /// Asserts every pixel within `band` of the border is `bg`.
    fn assert_border(&self, band: usize, bg: [u8; 3], what: &str) {
        for y in 0..self.h {
            for x in 0..self.w {
                let edge = x < band || y < band || x >= self.w - band || y >= self.h - band;
                if edge {
                    assert_eq!(self.at(x, y), bg, "{what}: pixel ({x}, {y}) in the margin");
                }
            }
        }
    }
}

/// Contents of every `d="..."` attribute of an SVG.
fn path_data(svg: &str) -> Vec<&str> {
    svg.split(" d=\"")
        .skip(1)
        .map(|rest| rest.split('"').next().unwrap_or(""))
        .collect()
}

/// Checks an SVG document is well-formed enough to trust: declaration, one root, balanced
/// groups and quotes, no NaN or infinity.
fn assert_svg_text(svg: &str, what: &str) {
    assert!(svg.starts_with("<?xml"), "{what}: no XML declaration");
    assert_eq!(svg.matches("<svg ").count(), 1, "{what}: one <svg> root");
    assert!(svg.trim_end().ends_with("</svg>"), "{what}: not closed");
    assert_eq!(
        svg.matches("<g ").count() + svg.matches("<g>").count(),
        svg.matches("</g>").count(),
        "{what}: unbalanced groups"
    );
    assert_eq!(
        svg.matches('"').count() % 2,
        0,
        "{what}: odd number of quotes"
    );
    for bad in ["NaN", "\"inf", " inf", "-inf", ",inf"] {
        assert!(!svg.contains(bad), "{what}: contains {bad}");
    }
}

/// Runs `foldfree param` on a test mesh with all four picture flags; returns the directory
/// and the face count of the report.
fn run_with_pictures(mesh: &str, extra: &[&str]) -> (TempDir, usize) {
    let dir = TempDir::new(mesh);
    let out = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .arg("param")
        .arg(data(mesh))
        .arg("-o")
        .arg(dir.join("out.obj"))
        .args(["--backend", "cpu", "-q", "--report"])
        .arg(dir.join("report.json"))
        .arg("--svg")
        .arg(dir.join("layout.svg"))
        .arg("--png")
        .arg(dir.join("layout.png"))
        .arg("--plot")
        .arg(dir.join("conv.svg"))
        .arg("--plot")
        .arg(dir.join("conv.png"))
        .args(extra)
        .output()
        .expect("run foldfree");
    // Pictures are written whether or not the run converged within its budget.
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success()
            || (out.status.code() == Some(3) && stderr.contains("best flip-free map was written")),
        "{mesh}: foldfree failed:\n{stderr}"
    );
    let report: serde_json::Value =
        serde_json::from_slice(&fs::read(dir.join("report.json")).expect("report written"))
            .expect("report is JSON");
    let faces = report["faces"].as_u64().expect("report.faces") as usize;
    assert_eq!(report["flips"].as_u64(), Some(0), "{mesh}: map has flips");
    (dir, faces)
}

fn check_pictures(mesh: &str, extra: &[&str], png_side: usize) {
    let (dir, faces) = run_with_pictures(mesh, extra);

    let svg = fs::read_to_string(dir.join("layout.svg")).expect("layout.svg written");
    assert_svg_text(&svg, mesh);
    let d = path_data(&svg);
    assert!(!d.is_empty() && d.len() <= viz::DELTA_BINS + 1);
    let subpaths: usize = d.iter().map(|p| p.matches('z').count()).sum();
    let movetos: usize = d.iter().map(|p| p.matches('m').count()).sum();
    assert_eq!(subpaths, faces, "{mesh}: one closed subpath per face");
    assert_eq!(movetos, faces, "{mesh}: one moveto per face");
    assert!(!svg.contains(r#"id="flipped""#), "{mesh}: no flipped path");
    assert!(svg.contains("flipped: 0"), "{mesh}: legend counts no flips");

    let img = Image::decode(&fs::read(dir.join("layout.png")).expect("layout.png written"));
    assert_eq!((img.w, img.h), (png_side, png_side), "{mesh}: PNG size");
    assert!(img.distinct() >= 3, "{mesh}: PNG nearly uniform");
    img.assert_border(png_side / 50, viz::BACKGROUND, mesh);
    assert_eq!(
        img.count(RED),
        0,
        "{mesh}: red pixels in a flip-free layout"
    );
    let covered = img.px.len() - img.count(viz::BACKGROUND);
    assert!(
        covered * 20 > img.px.len(),
        "{mesh}: the layout covers only {covered} px"
    );

    let conv = fs::read_to_string(dir.join("conv.svg")).expect("conv.svg written");
    assert_svg_text(&conv, mesh);
    assert!(conv.matches("<polyline").count() >= 3, "{mesh}: plot lines");
    let plot = Image::decode(&fs::read(dir.join("conv.png")).expect("conv.png written"));
    let (pw, ph) = viz::ImageOutputs::default().plot_size;
    assert_eq!((plot.w, plot.h), (pw as usize, ph as usize));
    assert!(plot.distinct() >= 5, "{mesh}: plot nearly uniform");
    assert!(plot.count([255, 255, 255]) > plot.px.len() / 2);

    // Only the requested files, and no temporaries left by the atomic writes.
    let mut names: Vec<String> = fs::read_dir(&dir.0)
        .expect("list temp dir")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "conv.png",
            "conv.svg",
            "layout.png",
            "layout.svg",
            "out.obj",
            "report.json"
        ]
    );
}

#[test]
fn grid_pictures() {
    check_pictures("square_grid_10x10", &["--png-size", "300"], 300);
}

#[test]
fn camel_pictures() {
    check_pictures("camel_open", &["--max-iters", "400"], 1024);
}

/// A picture in a missing folder is found before any work (exit 2), and the map is not written
/// either: a run leaves all its outputs or none.
#[test]
fn unwritable_picture_is_refused_before_the_run_and_nothing_is_written() {
    let dir = TempDir::new("unwritable");
    let out = Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .arg("param")
        .arg(data("two_triangles"))
        .arg("-o")
        .arg(dir.join("out.obj"))
        .args(["--backend", "cpu", "-q", "--png"])
        .arg(dir.join("no-such-dir/layout.png"))
        .output()
        .expect("run foldfree");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("layout.png"), "error names the file: {err}");
    assert!(!dir.join("out.obj").exists(), "the map was written alone");
}

/// A unit square as two triangles; `mirrored` folds the second triangle over the diagonal.
fn two_triangles(mirrored: bool) -> (TriMesh, Vec<[f64; 2]>) {
    let mesh = TriMesh {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ],
        faces: vec![[0, 1, 2], [0, 2, 3]],
    };
    let mut uv = vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    if mirrored {
        uv[3] = [1.0, 0.0]; // (0,1) mirrored over the diagonal u = v
    }
    (mesh, uv)
}

#[test]
fn flipped_faces_are_red() {
    let style = LayoutStyle::default();
    let (mesh, uv) = two_triangles(false);
    let ok = Image::decode(&viz::layout_png(&mesh, &uv, 64, &style));
    assert_eq!((ok.w, ok.h), (64, 64));
    assert_eq!(ok.count(RED), 0);
    assert!(ok.count(viz::bin_color(0)) > 0, "isometric faces use bin 0");

    let (mesh, uv) = two_triangles(true);
    let bad = Image::decode(&viz::layout_png(&mesh, &uv, 64, &style));
    assert!(bad.count(RED) > 100, "the folded triangle is red");
    bad.assert_border(2, viz::BACKGROUND, "folded");
    let svg = viz::layout_svg(&mesh, &uv, &style);
    assert_svg_text(&svg, "folded");
    assert!(svg.contains(r##"id="flipped" fill="#ff0000""##));
    assert!(svg.contains("flipped: 1"));

    // A zero-area fold still shows: at least a red mark.
    let mut uv = uv;
    uv[3] = [0.5, 0.5];
    let thin = Image::decode(&viz::layout_png(&mesh, &uv, 64, &style));
    assert!(thin.count(RED) > 0, "a degenerate fold is marked");
}

#[test]
fn colour_scale_endpoints() {
    let cool = viz::delta_color(1.0, 2.0);
    let warm = viz::delta_color(2.0, 2.0);
    assert!(cool[2] > cool[0], "δ = 1 is blue-ish: {cool:?}");
    assert!(
        warm[0] > warm[2] && warm[0] >= 200,
        "δ ≥ 2 is warm: {warm:?}"
    );
    assert_eq!(viz::delta_color(10.0, 2.0), warm, "saturates above δmax");
    assert_eq!(viz::delta_color(0.9, 2.0), cool, "clamped below 1");
    assert_eq!(viz::delta_color(f64::INFINITY, 2.0), warm);
    assert_eq!(viz::bin_color(0), cool);
    assert_eq!(viz::bin_color(viz::DELTA_BINS as u8 - 1), warm);
    assert_eq!(viz::bin_color(viz::FLIPPED_BIN), RED);
    assert_eq!(viz::FLIP_COLOR, RED);
    assert_eq!(viz::delta_bin(1.0, 2.0), 0);
    assert_eq!(viz::delta_bin(2.0, 2.0) as usize, viz::DELTA_BINS - 1);
    for b in 0..viz::DELTA_BINS as u8 {
        assert_ne!(viz::bin_color(b), RED, "bin {b} looks like a flip");
    }
}

#[test]
fn convergence_plots_of_synthetic_history() {
    let history: Vec<History> = (1..=40)
        .map(|k| History {
            iteration: 10 * k,
            mu_rel: 100.0,
            primal: 10f64.powf(-(k as f64) / 8.0),
            dual: 10f64.powf(-(k as f64) / 10.0),
            energy: 2.0 + 1.0 / k as f64,
            energy_change: 1.0 / (k * k) as f64,
            recovered_flips: (k % 10 == 0).then_some(0),
            recovered_energy: (k % 10 == 0).then_some(2.0 + 1.1 / k as f64),
            accel_accepted: None,
            accel_rejected: None,
            rolled_back: false,
        })
        .collect();
    let svg = viz::convergence_svg(&history);
    assert_svg_text(&svg, "synthetic");
    assert_eq!(
        svg.matches("<polyline").count(),
        3 + 3,
        "3 series + 3 legend swatches"
    );
    assert_eq!(
        svg.matches("<circle").count(),
        4 + 1,
        "4 recoveries + legend dot"
    );
    let img = Image::decode(&viz::convergence_png(&history, 640, 480));
    assert_eq!((img.w, img.h), (640, 480));
    assert!(img.distinct() >= 5);

    // No history (solver none): empty axes, still valid pictures.
    let svg = viz::convergence_svg(&[]);
    assert_svg_text(&svg, "empty");
    assert!(svg.contains("no iterations"));
    let img = Image::decode(&viz::convergence_png(&[], 300, 200));
    assert_eq!((img.w, img.h), (300, 200));
    assert!(img.distinct() >= 2);
}

/// Timing on a 249k-face mesh (if the shared copy exists): `cargo test --release --test viz
/// -- --ignored --nocapture`.
#[test]
#[ignore]
fn time_large_layout() {
    let path = Path::new("/work/shared/meshes/disk/igea_open_249k.obj");
    if !path.exists() {
        eprintln!("skipped: {} not found", path.display());
        return;
    }
    let (mesh, topo, _) =
        foldfree::mesh::load(path, &foldfree::mesh::ValidateOptions::default()).expect("load");
    let uv = foldfree::init::initial_map(
        &mesh,
        &topo,
        foldfree::init::InitMethod::Tutte(foldfree::init::tutte::TutteWeights::Uniform),
    )
    .expect("tutte");
    let style = LayoutStyle::default();
    let t = Instant::now();
    let png = viz::layout_png(&mesh, &uv, 2048, &style);
    let t_png = t.elapsed();
    let t = Instant::now();
    let svg = viz::layout_svg(&mesh, &uv, &style);
    let t_svg = t.elapsed();
    eprintln!(
        "{} faces: PNG 2048² {:.0} ms ({} bytes), SVG {:.0} ms ({} bytes)",
        mesh.faces.len(),
        t_png.as_secs_f64() * 1e3,
        png.len(),
        t_svg.as_secs_f64() * 1e3,
        svg.len()
    );
    let img = Image::decode(&png);
    assert_eq!(img.count(RED), 0);
}
