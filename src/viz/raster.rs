//! A small RGB canvas: flat-shaded triangles (scanline spans of edge functions), thick lines,
//! discs, rectangles and a 5×7 bitmap font, encoded as PNG by the `png` crate. No
//! anti-aliasing: every pixel is exactly one of the colours drawn, so a picture can be checked
//! pixel by pixel (a pure-red pixel in a layout *is* a flipped face).
#![forbid(unsafe_code)]

use std::io;

use super::{want_edges, Frame, LayoutStyle, FLIPPED_BIN};
use crate::mesh::TriMesh;

/// Largest side of a raster picture (8192² RGB is 192 MiB); larger requests are clamped.
pub const MAX_SIDE: u32 = 8192;

/// Width of a face outline inside the face, in pixels (two neighbours make a ~1 px line).
const EDGE_WIDTH: f64 = 0.5;

/// An RGB8 picture, row-major, y down.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Canvas {
    pub w: usize,
    pub h: usize,
    pub px: Vec<u8>,
}

impl Canvas {
    /// A `w`×`h` canvas filled with `bg` (sides clamped to 1..=[`MAX_SIDE`]).
    pub fn new(w: u32, h: u32, bg: [u8; 3]) -> Canvas {
        let (w, h) = (w.clamp(1, MAX_SIDE) as usize, h.clamp(1, MAX_SIDE) as usize);
        let mut px = Vec::with_capacity(w * h * 3);
        for _ in 0..w * h {
            px.extend_from_slice(&bg);
        }
        Canvas { w, h, px }
    }

    #[inline]
    fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as usize) < self.w && (y as usize) < self.h {
            let i = 3 * (y as usize * self.w + x as usize);
            self.px[i..i + 3].copy_from_slice(&c);
        }
    }

    /// Fills the pixels whose centres lie in [x0, x1) × [y0, y1).
    pub fn fill_rect(&mut self, x0: f64, y0: f64, x1: f64, y1: f64, c: [u8; 3]) {
        let xs = (x0 - 0.5).ceil().max(0.0) as i64;
        let ys = (y0 - 0.5).ceil().max(0.0) as i64;
        let xe = ((x1 - 0.5).ceil() as i64).min(self.w as i64);
        let ye = ((y1 - 0.5).ceil() as i64).min(self.h as i64);
        for y in ys..ye {
            for x in xs..xe {
                self.put(x, y, c);
            }
        }
    }

    /// Fills the pixels whose centres lie within `r` of (cx, cy).
    pub fn disc(&mut self, cx: f64, cy: f64, r: f64, c: [u8; 3]) {
        let r2 = r * r;
        let (ys, ye) = ((cy - r - 0.5).ceil() as i64, (cy + r - 0.5).floor() as i64);
        let (xs, xe) = ((cx - r - 0.5).ceil() as i64, (cx + r - 0.5).floor() as i64);
        for y in ys..=ye {
            let dy = y as f64 + 0.5 - cy;
            for x in xs..=xe {
                let dx = x as f64 + 0.5 - cx;
                if dx * dx + dy * dy <= r2 {
                    self.put(x, y, c);
                }
            }
        }
    }

    /// A line `width` pixels wide with round ends (discs stamped every half pixel).
    pub fn line(&mut self, a: [f64; 2], b: [f64; 2], width: f64, c: [u8; 3]) {
        if !(a.iter().chain(&b).all(|x| x.is_finite())) {
            return;
        }
        let r = (0.5 * width).max(0.71);
        let len = ((b[0] - a[0]).powi(2) + (b[1] - a[1]).powi(2)).sqrt();
        let n = (2.0 * len).ceil().clamp(1.0, 1e6) as usize;
        for i in 0..=n {
            let t = i as f64 / n as f64;
            self.disc(a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), r, c);
        }
    }

    /// Fills the triangle `p` (either orientation): every pixel whose centre is inside or on
    /// an edge, so neighbours leave no gaps. With `edge = Some((colour, width))` the pixels
    /// closer than `width` to an edge get that colour. Returns the number of pixels set
    /// (0 for a triangle between pixel centres or with a non-finite corner).
    pub fn fill_triangle(
        &mut self,
        p: [[f64; 2]; 3],
        fill: [u8; 3],
        edge: Option<([u8; 3], f64)>,
    ) -> usize {
        const EPS: f64 = 1e-7;
        let area2 =
            (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
        if !(area2.is_finite() && area2 != 0.0) {
            return 0;
        }
        let sgn = area2.signum();
        // Edge i (p[i] → p[i+1]) as a·x + b·y + c: the signed distance, positive inside.
        let mut e = [[0.0f64; 3]; 3];
        for i in 0..3 {
            let (p0, p1) = (p[i], p[(i + 1) % 3]);
            let (dx, dy) = (p1[0] - p0[0], p1[1] - p0[1]);
            let k = sgn / (dx * dx + dy * dy).sqrt();
            e[i] = [-dy * k, dx * k, (dy * p0[0] - dx * p0[1]) * k];
        }
        let xmin = p[0][0].min(p[1][0]).min(p[2][0]);
        let xmax = p[0][0].max(p[1][0]).max(p[2][0]);
        let ymin = p[0][1].min(p[1][1]).min(p[2][1]);
        let ymax = p[0][1].max(p[1][1]).max(p[2][1]);
        let x0 = ((xmin - 0.5).ceil() as i64).max(0);
        let x1 = ((xmax - 0.5).floor() as i64).min(self.w as i64 - 1);
        let y0 = ((ymin - 0.5).ceil() as i64).max(0);
        let y1 = ((ymax - 0.5).floor() as i64).min(self.h as i64 - 1);
        let mut count = 0;
        for y in y0..=y1 {
            let yc = y as f64 + 0.5;
            let (mut lo, mut hi) = (x0 as f64 + 0.5, x1 as f64 + 0.5);
            let mut k = [0.0; 3];
            for i in 0..3 {
                k[i] = e[i][1] * yc + e[i][2];
                let a = e[i][0];
                if a > 0.0 {
                    lo = lo.max(-k[i] / a - EPS);
                } else if a < 0.0 {
                    hi = hi.min(-k[i] / a + EPS);
                } else if k[i] < -EPS {
                    hi = f64::NEG_INFINITY;
                }
            }
            if lo.is_nan() || hi.is_nan() || lo > hi {
                continue;
            }
            let xs = ((lo - 0.5).ceil() as i64).max(x0);
            let xe = ((hi - 0.5).floor() as i64).min(x1);
            if xs > xe {
                continue;
            }
            let row = 3 * y as usize * self.w;
            for x in xs..=xe {
                let c = match edge {
                    Some((ec, width)) => {
                        let xc = x as f64 + 0.5;
                        let d = (e[0][0] * xc + k[0])
                            .min(e[1][0] * xc + k[1])
                            .min(e[2][0] * xc + k[2]);
                        if d < width {
                            ec
                        } else {
                            fill
                        }
                    }
                    None => fill,
                };
                let i = row + 3 * x as usize;
                self.px[i..i + 3].copy_from_slice(&c);
            }
            count += (xe - xs + 1) as usize;
        }
        count
    }

    /// Width in pixels of `s` drawn at glyph `scale`.
    pub fn text_width(s: &str, scale: usize) -> usize {
        (6 * s.chars().count() * scale).saturating_sub(scale)
    }

    /// Draws `s` in the 5×7 font, each font pixel `scale`² pixels, top-left corner at (x, y).
    /// Characters the font lacks are left blank.
    pub fn text(&mut self, x: f64, y: f64, s: &str, scale: usize, c: [u8; 3]) {
        let sc = scale.max(1) as f64;
        for (n, ch) in s.chars().enumerate() {
            let Some(rows) = glyph(ch) else { continue };
            let gx = x + 6.0 * sc * n as f64;
            for (r, bits) in rows.iter().enumerate() {
                for col in 0..5 {
                    if bits & (0x10 >> col) != 0 {
                        let (px, py) = (gx + col as f64 * sc, y + r as f64 * sc);
                        self.fill_rect(px, py, px + sc, py + sc, c);
                    }
                }
            }
        }
    }

    /// The picture as PNG (RGB8, fast deflate: flat colours compress well anyway). Writing to
    /// memory cannot fail for the clamped sizes, but the encoder's `Result` is passed on.
    pub fn encode_png(&self) -> io::Result<Vec<u8>> {
        let mut out = Vec::new();
        let mut enc = png::Encoder::new(&mut out, self.w as u32, self.h as u32);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        enc.set_compression(png::Compression::Fast);
        let mut writer = enc.write_header().map_err(io::Error::other)?;
        writer
            .write_image_data(&self.px)
            .map_err(io::Error::other)?;
        writer.finish().map_err(io::Error::other)?;
        Ok(out)
    }
}

/// Draws the layout with precomputed face `bins` (see [`super::classify`]) on a `size`²
/// canvas. Flipped faces are drawn last, without outline, so that they show in pure red on
/// top of the faces they overlap, and one that covers fewer than 9 pixels also gets a 3×3
/// red mark at its centroid: a fold must be visible at any resolution.
pub(crate) fn render_layout(
    mesh: &TriMesh,
    uv: &[[f64; 2]],
    bins: &[u8],
    size: u32,
    style: &LayoutStyle,
) -> Canvas {
    let mut cv = Canvas::new(size, size, style.background);
    let side = cv.w as f64;
    let margin = (style.margin * side).max(2.0).min(0.25 * side);
    let frame = Frame::fit(&mesh.faces, uv, side, side, margin);
    let edges = want_edges(style, mesh, uv, &frame, 1.0);
    let corners = |f: &[u32; 3]| -> Option<[[f64; 2]; 3]> {
        let mut p = [[0.0; 2]; 3];
        for k in 0..3 {
            p[k] = frame.map(*uv.get(f[k] as usize)?);
        }
        Some(p)
    };
    for flipped_pass in [false, true] {
        for (fi, f) in mesh.faces.iter().enumerate() {
            let bin = bins.get(fi).copied().unwrap_or(FLIPPED_BIN - 1);
            if (bin == FLIPPED_BIN) != flipped_pass {
                continue;
            }
            let Some(p) = corners(f) else { continue };
            let fill = super::bin_color(bin);
            // Folds are all pure red, outline included, so that a thin one shows as red.
            let edge = (edges && !flipped_pass).then(|| (super::edge_color(fill), EDGE_WIDTH));
            let n = cv.fill_triangle(p, fill, edge);
            if flipped_pass && n < 9 {
                let c = [
                    (p[0][0] + p[1][0] + p[2][0]) / 3.0,
                    (p[0][1] + p[1][1] + p[2][1]) / 3.0,
                ];
                if c[0].is_finite() && c[1].is_finite() {
                    cv.fill_rect(c[0] - 1.5, c[1] - 1.5, c[0] + 1.5, c[1] + 1.5, fill);
                }
            }
        }
    }
    cv
}

/// PNG of the UV layout, `size_px`² pixels (clamped to 1..=[`MAX_SIDE`]): faces flat-coloured
/// by δ on the scale of [`super`], flipped faces pure red, `opts.background` around the
/// UV bounding box (fitted with `opts.margin`, y up). Outlines follow `opts.edges`. `uv` has
/// one entry per vertex of `mesh`. An empty vector only if the encoder fails, which it does
/// not for in-memory output; [`try_layout_png`] passes such an error on.
pub fn layout_png(mesh: &TriMesh, uv: &[[f64; 2]], size_px: u32, opts: &LayoutStyle) -> Vec<u8> {
    try_layout_png(mesh, uv, size_px, opts).unwrap_or_default()
}

/// [`layout_png`] with the encoder's error.
pub fn try_layout_png(
    mesh: &TriMesh,
    uv: &[[f64; 2]],
    size_px: u32,
    opts: &LayoutStyle,
) -> io::Result<Vec<u8>> {
    let (bins, _) = super::classify(mesh, uv, opts.delta_max);
    render_layout(mesh, uv, &bins, size_px, opts).encode_png()
}

/// Rows of a 5×7 glyph plus a descender row (bit 4 is the leftmost column); `None` for
/// characters not in the font (digits, lowercase letters and a little punctuation: enough for
/// axis labels).
fn glyph(c: char) -> Option<[u8; 8]> {
    Some(match c {
        ' ' => [0; 8],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E, 0],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E, 0],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F, 0],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E, 0],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02, 0],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E, 0],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E, 0],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08, 0],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E, 0],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C, 0],
        '.' => [0, 0, 0, 0, 0, 0x0C, 0x0C, 0],
        ',' => [0, 0, 0, 0, 0, 0x0C, 0x04, 0x08],
        ':' => [0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0, 0],
        '-' => [0, 0, 0, 0x1F, 0, 0, 0, 0],
        '+' => [0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0, 0],
        '=' => [0, 0, 0x1F, 0, 0x1F, 0, 0, 0],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02, 0],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08, 0],
        '/' => [0, 0x01, 0x02, 0x04, 0x08, 0x10, 0, 0],
        '|' => [0x04; 8],
        'a' => [0, 0, 0x0E, 0x01, 0x0F, 0x11, 0x0F, 0],
        'b' => [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E, 0],
        'c' => [0, 0, 0x0E, 0x10, 0x10, 0x11, 0x0E, 0],
        'd' => [0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F, 0],
        'e' => [0, 0, 0x0E, 0x11, 0x1F, 0x10, 0x0E, 0],
        'f' => [0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08, 0],
        'g' => [0, 0, 0x0F, 0x11, 0x11, 0x0F, 0x01, 0x0E],
        'h' => [0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11, 0],
        'i' => [0x04, 0, 0x0C, 0x04, 0x04, 0x04, 0x0E, 0],
        'j' => [0x02, 0, 0x06, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'k' => [0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12, 0],
        'l' => [0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E, 0],
        'm' => [0, 0, 0x1A, 0x15, 0x15, 0x11, 0x11, 0],
        'n' => [0, 0, 0x16, 0x19, 0x11, 0x11, 0x11, 0],
        'o' => [0, 0, 0x0E, 0x11, 0x11, 0x11, 0x0E, 0],
        'p' => [0, 0, 0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10],
        'q' => [0, 0, 0x0F, 0x11, 0x11, 0x0F, 0x01, 0x01],
        'r' => [0, 0, 0x16, 0x19, 0x10, 0x10, 0x10, 0],
        's' => [0, 0, 0x0E, 0x10, 0x0E, 0x01, 0x1E, 0],
        't' => [0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06, 0],
        'u' => [0, 0, 0x11, 0x11, 0x11, 0x13, 0x0D, 0],
        'v' => [0, 0, 0x11, 0x11, 0x11, 0x0A, 0x04, 0],
        'w' => [0, 0, 0x11, 0x11, 0x15, 0x15, 0x0A, 0],
        'x' => [0, 0, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0],
        'y' => [0, 0, 0x11, 0x11, 0x11, 0x0F, 0x01, 0x0E],
        'z' => [0, 0, 0x1F, 0x02, 0x04, 0x08, 0x1F, 0],
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn count(cv: &Canvas, c: [u8; 3]) -> usize {
        cv.px.chunks_exact(3).filter(|p| *p == c).count()
    }

    #[test]
    fn two_triangles_tile_a_square_without_gaps_or_spill() {
        let mut cv = Canvas::new(20, 20, [255; 3]);
        let (a, b, c, d) = ([2.0, 2.0], [18.0, 2.0], [18.0, 18.0], [2.0, 18.0]);
        let n1 = cv.fill_triangle([a, b, c], [0, 0, 255], None);
        let n2 = cv.fill_triangle([a, d, c], [0, 0, 255], None); // clockwise: also filled
        assert!(n1 > 0 && n2 > 0);
        assert_eq!(count(&cv, [0, 0, 255]), 16 * 16);
        assert_eq!(count(&cv, [255; 3]), 400 - 256);
    }

    #[test]
    fn outlines_are_drawn_inside() {
        let mut cv = Canvas::new(40, 40, [255; 3]);
        cv.fill_triangle(
            [[0.0, 0.0], [40.0, 0.0], [0.0, 40.0]],
            [0, 0, 255],
            Some(([0, 0, 0], 1.0)),
        );
        assert!(count(&cv, [0, 0, 0]) > 0);
        assert!(count(&cv, [0, 0, 255]) > 0);
    }

    #[test]
    fn degenerate_triangles_draw_nothing() {
        let mut cv = Canvas::new(10, 10, [255; 3]);
        assert_eq!(
            cv.fill_triangle([[1.0, 1.0], [5.0, 5.0], [9.0, 9.0]], [0; 3], None),
            0
        );
        assert_eq!(
            cv.fill_triangle([[f64::NAN, 1.0], [5.0, 5.0], [9.0, 1.0]], [0; 3], None),
            0
        );
        assert_eq!(count(&cv, [255; 3]), 100);
    }
}
