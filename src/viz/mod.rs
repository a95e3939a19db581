//! Pictures a person can look at: the UV layout with faces coloured by conformal distortion
//! (SVG and PNG) and convergence plots of an ADMM run (SVG and PNG).
//!
//! Everything here is drawn by our own code (a scanline triangle rasterizer, a line plotter and
//! a 5×7 bitmap font); the only dependency is the pure-Rust `png` encoder. That keeps the CLI
//! free of system libraries and makes the output deterministic: the same map gives the same
//! bytes, so pictures can be diffed and cached.
//!
//! # Colour scale
//!
//! A face's colour encodes δ = σ1/σ2 (see [`crate::metrics`]), linearly in δ: δ = 1
//! (conformal) is blue, then light blue (δ = 1.35), pale yellow (1.6), orange (1.8), up to a
//! saturated dark orange at δ ≥ `delta_max` (default 2; the stops scale with it). The scale
//! is quantised into [`DELTA_BINS`] bins so that the SVG can hold one `<path>` per bin and the
//! PNG shows exactly the same colours. Flipped faces (signed UV area ≤ 0) are pure red,
//! [`FLIP_COLOR`], a colour the scale never produces, so a single red pixel means a fold.
#![forbid(unsafe_code)]

pub mod plot;
pub mod raster;
pub mod render;
pub mod svg;

use std::path::{Path, PathBuf};

use crate::files::Outputs;
use crate::mesh::TriMesh;
use crate::metrics::FaceDistortion;
use crate::param::admm::History;
use crate::{Error, Result};

pub use plot::{convergence_png, convergence_svg, try_convergence_png};
pub use raster::{layout_png, try_layout_png};
pub use svg::layout_svg;

/// Number of colour bins of the δ scale (bin 0 holds δ = 1, the last bin δ ≥ `delta_max`).
pub const DELTA_BINS: usize = 32;
/// The bin of flipped faces, after the δ bins.
pub const FLIPPED_BIN: u8 = DELTA_BINS as u8;
/// Flipped faces: pure red, never produced by the δ scale.
pub const FLIP_COLOR: [u8; 3] = [255, 0, 0];
/// Default background: white (not on the δ scale either, so margins are recognisable).
pub const BACKGROUND: [u8; 3] = [255, 255, 255];

/// Stops of the δ scale at t = (δ − 1)/(δmax − 1) ∈ [0, 1] (RGB, linearly interpolated).
const STOPS: [(f64, [u8; 3]); 5] = [
    (0.0, [44, 123, 182]),
    (0.35, [171, 217, 233]),
    (0.6, [255, 255, 191]),
    (0.8, [253, 174, 97]),
    (1.0, [230, 85, 13]),
];

/// Whether faces get a thin darker outline.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Edges {
    /// Outlines only when faces are large enough on the picture to still show their colour
    /// (mean face ≥ 48 px²): on a 250k-face mesh outlines would paint the picture dark.
    Auto,
    On,
    Off,
}

/// How a UV layout is drawn.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LayoutStyle {
    /// δ at which the colour saturates (default 2; values ≤ 1 are treated as 1 + 1e-9).
    pub delta_max: f64,
    pub background: [u8; 3],
    pub edges: Edges,
    /// Empty border around the UV bounding box, as a fraction of the picture's side
    /// (default 0.04; at least 2 px in a raster).
    pub margin: f64,
}

impl Default for LayoutStyle {
    fn default() -> LayoutStyle {
        LayoutStyle {
            delta_max: 2.0,
            background: BACKGROUND,
            edges: Edges::Auto,
            margin: 0.04,
        }
    }
}

/// Colour of distortion δ on the continuous scale (module docs): linear between colour stops
/// at t = (δ − 1)/(δmax − 1), clamped to [0, 1]; NaN or +∞ (a degenerate face) give the saturated end.
pub fn delta_color(delta: f64, delta_max: f64) -> [u8; 3] {
    color_at(delta_t(delta, delta_max))
}

fn delta_t(delta: f64, delta_max: f64) -> f64 {
    let span = (delta_max - 1.0).max(1e-9);
    let t = (delta - 1.0) / span;
    if t.is_nan() {
        1.0
    } else {
        t.clamp(0.0, 1.0)
    }
}

fn color_at(t: f64) -> [u8; 3] {
    for w in STOPS.windows(2) {
        let ((t0, c0), (t1, c1)) = (w[0], w[1]);
        if t <= t1 {
            let s = ((t - t0) / (t1 - t0)).clamp(0.0, 1.0);
            let mut c = [0u8; 3];
            for k in 0..3 {
                c[k] = (c0[k] as f64 + s * (c1[k] as f64 - c0[k] as f64)).round() as u8;
            }
            return c;
        }
    }
    STOPS[STOPS.len() - 1].1
}

/// Colour bin of distortion δ: ⌊t·[`DELTA_BINS`]⌋ clamped to the last bin.
pub fn delta_bin(delta: f64, delta_max: f64) -> u8 {
    let t = delta_t(delta, delta_max);
    ((t * DELTA_BINS as f64) as usize).min(DELTA_BINS - 1) as u8
}

/// Colour of a bin: bin 0 is exactly the δ = 1 colour, the last δ bin exactly the saturated
/// one, [`FLIPPED_BIN`] (or anything larger) is [`FLIP_COLOR`].
pub fn bin_color(bin: u8) -> [u8; 3] {
    if bin as usize >= DELTA_BINS {
        FLIP_COLOR
    } else {
        color_at(bin as f64 / (DELTA_BINS - 1) as f64)
    }
}

/// The outline colour of a fill: 60 % of it (darker, same hue).
pub(crate) fn edge_color(c: [u8; 3]) -> [u8; 3] {
    c.map(|x| (x as f64 * 0.6).round() as u8)
}

/// Bin of one face: [`FLIPPED_BIN`] when its signed UV area is ≤ 0 (or NaN), else the bin of
/// its δ (+∞ for a zero-area 3D triangle, which lands in the saturated bin).
pub fn face_bin(d: &FaceDistortion, delta_max: f64) -> u8 {
    if d.uv_area > 0.0 {
        delta_bin(d.delta_con(), delta_max)
    } else {
        FLIPPED_BIN
    }
}

/// Per-face bins of a map, from [`crate::metrics::face_distortions`].
pub fn face_bins(mesh: &TriMesh, uv: &[[f64; 2]], delta_max: f64) -> Vec<u8> {
    crate::metrics::face_distortions(&mesh.positions, &mesh.faces, uv)
        .iter()
        .map(|d| face_bin(d, delta_max))
        .collect()
}

/// The summary printed on the SVG legend.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct LayoutStats {
    pub faces: usize,
    pub flips: usize,
    /// Mean and max of δ over the non-flipped faces with a finite δ (NaN when none).
    pub delta_mean: f64,
    pub delta_max: f64,
}

/// Bins and legend numbers of a map in one pass over [`crate::metrics::face_distortions`].
pub(crate) fn classify(mesh: &TriMesh, uv: &[[f64; 2]], delta_max: f64) -> (Vec<u8>, LayoutStats) {
    let d = crate::metrics::face_distortions(&mesh.positions, &mesh.faces, uv);
    let bins: Vec<u8> = d.iter().map(|f| face_bin(f, delta_max)).collect();
    let flips = bins.iter().filter(|&&b| b == FLIPPED_BIN).count();
    let (mut sum, mut n, mut max) = (0.0, 0usize, f64::NAN);
    for f in &d {
        let x = f.delta_con();
        if f.uv_area > 0.0 && x.is_finite() {
            sum += x;
            n += 1;
            max = if max.is_nan() { x } else { max.max(x) };
        }
    }
    let stats = LayoutStats {
        faces: d.len(),
        flips,
        delta_mean: if n > 0 { sum / n as f64 } else { f64::NAN },
        delta_max: max,
    };
    (bins, stats)
}

/// The similarity that fits the UV bounding box of the faces' corners into a `w`×`h` picture
/// with `margin` units on each side, centred, y up (picture y grows downwards).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Frame {
    pub scale: f64,
    pub tx: f64,
    pub ty: f64,
}

impl Frame {
    pub fn fit(faces: &[[u32; 3]], uv: &[[f64; 2]], w: f64, h: f64, margin: f64) -> Frame {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for f in faces {
            for &v in f {
                if let Some(p) = uv.get(v as usize) {
                    if p[0].is_finite() && p[1].is_finite() {
                        for k in 0..2 {
                            lo[k] = lo[k].min(p[k]);
                            hi[k] = hi[k].max(p[k]);
                        }
                    }
                }
            }
        }
        if lo[0] > hi[0] {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        let (du, dv) = (hi[0] - lo[0], hi[1] - lo[1]);
        let (aw, ah) = ((w - 2.0 * margin).max(1.0), (h - 2.0 * margin).max(1.0));
        let mut scale = match (du > 0.0, dv > 0.0) {
            (true, true) => (aw / du).min(ah / dv),
            (true, false) => aw / du,
            (false, true) => ah / dv,
            (false, false) => 1.0,
        };
        if !(scale.is_finite() && scale > 0.0) {
            scale = 1.0;
        }
        let (cu, cv) = (0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]));
        Frame {
            scale,
            tx: 0.5 * w - scale * cu,
            ty: 0.5 * h + scale * cv,
        }
    }

    #[inline]
    pub fn map(&self, p: [f64; 2]) -> [f64; 2] {
        [self.tx + self.scale * p[0], self.ty - self.scale * p[1]]
    }
}

/// Whether faces are outlined on a picture where the map covers `frame`: [`Edges::Auto`]
/// outlines when the mean face is at least 48 px² (in the picture's units × `px_per_unit`).
pub(crate) fn want_edges(
    style: &LayoutStyle,
    mesh: &TriMesh,
    uv: &[[f64; 2]],
    frame: &Frame,
    px_per_unit: f64,
) -> bool {
    match style.edges {
        Edges::On => true,
        Edges::Off => false,
        Edges::Auto => {
            if mesh.faces.is_empty() {
                return false;
            }
            let a: f64 = mesh
                .faces
                .iter()
                .filter_map(|f| {
                    let [a, b, c] = f.map(|v| uv.get(v as usize).copied());
                    let (a, b, c) = (a?, b?, c?);
                    let x =
                        0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])).abs();
                    x.is_finite().then_some(x)
                })
                .sum();
            let s = frame.scale / px_per_unit;
            let mean_px = a * s * s / mesh.faces.len() as f64;
            mean_px.is_finite() && mean_px >= 48.0
        }
    }
}

/// Which pictures to write after a run; `None` skips one.
#[derive(Clone, Debug, PartialEq)]
pub struct ImageOutputs {
    /// UV layout, SVG.
    pub layout_svg: Option<PathBuf>,
    /// UV layout, PNG of `png_size`² pixels.
    pub layout_png: Option<PathBuf>,
    pub png_size: u32,
    /// Convergence plot, SVG.
    pub plot_svg: Option<PathBuf>,
    /// Convergence plot, PNG of `plot_size` pixels.
    pub plot_png: Option<PathBuf>,
    pub plot_size: (u32, u32),
    pub style: LayoutStyle,
}

impl Default for ImageOutputs {
    fn default() -> ImageOutputs {
        ImageOutputs {
            layout_svg: None,
            layout_png: None,
            png_size: 1024,
            plot_svg: None,
            plot_png: None,
            plot_size: (1024, 720),
            style: LayoutStyle::default(),
        }
    }
}

impl ImageOutputs {
    /// Nothing to write.
    pub fn is_empty(&self) -> bool {
        self.layout_svg.is_none()
            && self.layout_png.is_none()
            && self.plot_svg.is_none()
            && self.plot_png.is_none()
    }
}

impl ImageOutputs {
    /// Reserves the requested pictures' paths in the run's outputs (checked before the run).
    pub fn plan(&self, outputs: &mut Outputs) -> Result<()> {
        for (p, what, ext) in [
            (&self.layout_svg, "layout picture", "svg"),
            (&self.layout_png, "layout picture", "png"),
            (&self.plot_svg, "convergence plot", "svg"),
            (&self.plot_png, "convergence plot", "png"),
        ] {
            if let Some(p) = p {
                outputs.output(p, what, &[ext])?;
            }
        }
        Ok(())
    }

    /// Renders the requested pictures of a map and its run history into the run's outputs
    /// (planned with [`ImageOutputs::plan`]; committed with the map). The face distortions are
    /// computed once for both layout pictures.
    pub fn render(
        &self,
        mesh: &TriMesh,
        uv: &[[f64; 2]],
        history: &[History],
        outputs: &mut Outputs,
    ) -> Result<()> {
        if self.layout_svg.is_some() || self.layout_png.is_some() {
            let (bins, stats) = classify(mesh, uv, self.style.delta_max);
            if let Some(path) = &self.layout_svg {
                let text = svg::render_layout(mesh, uv, &bins, &stats, &self.style);
                outputs.set(path, text.into_bytes());
            }
            if let Some(path) = &self.layout_png {
                let bytes = raster::render_layout(mesh, uv, &bins, self.png_size, &self.style)
                    .encode_png()
                    .map_err(|e| io_error(path, e))?;
                outputs.set(path, bytes);
            }
        }
        if let Some(path) = &self.plot_svg {
            outputs.set(path, convergence_svg(history).into_bytes());
        }
        if let Some(path) = &self.plot_png {
            let (w, h) = self.plot_size;
            let bytes = plot::render_png(history, w, h).map_err(|e| io_error(path, e))?;
            outputs.set(path, bytes);
        }
        Ok(())
    }
}

fn io_error(path: &Path, source: std::io::Error) -> Error {
    Error::Io {
        path: path.to_path_buf(),
        source,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scale_endpoints_and_flip_colour() {
        assert_eq!(delta_color(1.0, 2.0), STOPS[0].1);
        assert_eq!(delta_color(0.5, 2.0), STOPS[0].1);
        assert_eq!(delta_color(2.0, 2.0), STOPS[4].1);
        assert_eq!(delta_color(50.0, 2.0), STOPS[4].1);
        assert_eq!(delta_color(f64::INFINITY, 2.0), STOPS[4].1);
        assert_eq!(bin_color(0), STOPS[0].1);
        assert_eq!(bin_color(DELTA_BINS as u8 - 1), STOPS[4].1);
        assert_eq!(bin_color(FLIPPED_BIN), FLIP_COLOR);
        for b in 0..DELTA_BINS as u8 {
            assert_ne!(bin_color(b), FLIP_COLOR);
            assert_ne!(bin_color(b), BACKGROUND);
            assert_ne!(edge_color(bin_color(b)), FLIP_COLOR);
        }
    }

    #[test]
    fn frame_fits_and_flips_y() {
        let faces = [[0, 1, 2]];
        let uv = [[0.0, 0.0], [2.0, 0.0], [0.0, 1.0]];
        let f = Frame::fit(&faces, &uv, 100.0, 100.0, 10.0);
        assert_eq!(f.map([0.0, 0.0]), [10.0, 70.0]);
        assert_eq!(f.map([2.0, 1.0]), [90.0, 30.0]);
    }
}
