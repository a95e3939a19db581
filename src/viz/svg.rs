//! The UV layout as SVG: one `<path>` per colour bin (32 δ bins + the flipped faces, drawn
//! last), which keeps a 250k-face layout to a few MB and lets an editor recolour a bin at once.
//!
//! Coordinates are integers in 1/64 px of the nominal 1024 px picture (exact to well below a
//! pixel at any zoom a viewer offers), written relatively (`m`/`l`) from integer positions, so
//! there is no accumulated rounding and no float formatting: numbers are short and never NaN.
#![forbid(unsafe_code)]

use std::fmt::Write;

use super::{
    bin_color, want_edges, Frame, LayoutStats, LayoutStyle, DELTA_BINS, FLIPPED_BIN, FLIP_COLOR,
};
use crate::mesh::TriMesh;

/// Nominal picture side in px.
const SIDE_PX: f64 = 1024.0;
/// SVG user units per px.
const UNITS: f64 = 64.0;
/// Height of the legend strip under the layout, px.
const LEGEND_PX: f64 = 64.0;

/// SVG of the UV layout: faces filled by δ on the scale documented in [`super`] (binned into
/// [`DELTA_BINS`] colours), flipped faces pure red on top, a legend strip (colour bar, flip
/// count, mean and max δ) under the layout. The UV bounding box is fitted into a 1024 px
/// square with `opts.margin`, y up. `uv` has one entry per vertex of `mesh`; faces with a
/// non-finite corner are left out.
pub fn layout_svg(mesh: &TriMesh, uv: &[[f64; 2]], opts: &LayoutStyle) -> String {
    let (bins, stats) = super::classify(mesh, uv, opts.delta_max);
    render_layout(mesh, uv, &bins, &stats, opts)
}

fn hex(c: [u8; 3]) -> String {
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

/// Integer SVG coordinates of a face's corners, `None` if one is missing or not finite.
fn face_coords(f: &[u32; 3], uv: &[[f64; 2]], frame: &Frame) -> Option<[[i64; 2]; 3]> {
    const LIMIT: f64 = 1e12;
    let mut q = [[0i64; 2]; 3];
    for k in 0..3 {
        let p = frame.map(*uv.get(f[k] as usize)?);
        if !(p[0].abs() < LIMIT && p[1].abs() < LIMIT) {
            return None;
        }
        q[k] = [p[0].round() as i64, p[1].round() as i64];
    }
    Some(q)
}

pub(crate) fn render_layout(
    mesh: &TriMesh,
    uv: &[[f64; 2]],
    bins: &[u8],
    stats: &LayoutStats,
    style: &LayoutStyle,
) -> String {
    let side = SIDE_PX * UNITS;
    let margin = if style.margin.is_finite() {
        style.margin.clamp(0.0, 0.25) * side
    } else {
        0.0
    };
    let frame = Frame::fit(&mesh.faces, uv, side, side, margin);
    let edges = want_edges(style, mesh, uv, &frame, UNITS);

    // Path data per bin; `start` is the first corner of the bin's previous face (where `z`
    // leaves the current point), so every face begins with a relative `m`.
    let nbins = DELTA_BINS + 1;
    let mut d = vec![String::new(); nbins];
    let mut start = vec![[0i64; 2]; nbins];
    let mut drawn = 0usize;
    for (fi, f) in mesh.faces.iter().enumerate() {
        let bin = bins.get(fi).copied().unwrap_or(FLIPPED_BIN - 1) as usize;
        let Some(q) = face_coords(f, uv, &frame) else {
            continue;
        };
        let s = &mut d[bin];
        let [x0, y0] = start[bin];
        // Writing to a String cannot fail.
        let _ = write!(
            s,
            "m{} {}l{} {} {} {}z",
            q[0][0] - x0,
            q[0][1] - y0,
            q[1][0] - q[0][0],
            q[1][1] - q[0][1],
            q[2][0] - q[1][0],
            q[2][1] - q[1][1]
        );
        start[bin] = q[0];
        drawn += 1;
    }

    let total_h = SIDE_PX + LEGEND_PX;
    let mut out = String::with_capacity(d.iter().map(String::len).sum::<usize>() + 8192);
    let _ = writeln!(out, r#"<?xml version="1.0" encoding="UTF-8"?>"#);
    let _ = writeln!(
        out,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {vw} {vh}">"#,
        w = SIDE_PX,
        h = total_h,
        vw = side,
        vh = total_h * UNITS,
    );
    let _ = writeln!(
        out,
        "<title>UV layout: {} faces ({} drawn), {} flipped; colour = conformal distortion σ1/σ2</title>",
        stats.faces, drawn, stats.flips
    );
    let _ = writeln!(
        out,
        r#"<rect width="{}" height="{}" fill="{}"/>"#,
        side,
        total_h * UNITS,
        hex(style.background)
    );
    let stroke_w = 0.5 * UNITS;
    let _ = writeln!(
        out,
        r#"<g id="faces" stroke-linejoin="round" stroke-width="{stroke_w}">"#
    );
    for (bin, path) in d.iter().enumerate() {
        if path.is_empty() {
            continue;
        }
        let fill = bin_color(bin as u8);
        let stroke = if bin == FLIPPED_BIN as usize {
            // Folds get a red 1 px outline: even a zero-area one shows.
            format!(r#" stroke="{}" stroke-width="{}""#, hex(fill), UNITS)
        } else if edges {
            format!(r#" stroke="{}""#, hex(super::edge_color(fill)))
        } else {
            String::new()
        };
        let id = if bin == FLIPPED_BIN as usize {
            "flipped".to_string()
        } else {
            format!("delta-bin-{bin}")
        };
        let _ = writeln!(
            out,
            r#"<path id="{id}" fill="{}"{stroke} d="{path}"/>"#,
            hex(fill)
        );
    }
    let _ = writeln!(out, "</g>");
    legend(&mut out, stats, style);
    let _ = writeln!(out, "</svg>");
    out
}

/// Colour bar with δ labels, the flipped swatch and count, and mean / max δ, in px units.
fn legend(out: &mut String, stats: &LayoutStats, style: &LayoutStyle) {
    let y0 = SIDE_PX;
    let _ = writeln!(
        out,
        r##"<g id="legend" transform="translate(0 {}) scale({UNITS})" font-family="sans-serif" font-size="12" fill="#333333">"##,
        y0 * UNITS
    );
    let (bx, by, bw, bh) = (24.0, 10.0, 8.0, 14.0);
    for b in 0..DELTA_BINS {
        let _ = writeln!(
            out,
            r#"<rect x="{}" y="{by}" width="{}" height="{bh}" fill="{}"/>"#,
            bx + b as f64 * bw,
            bw + 0.25,
            hex(bin_color(b as u8))
        );
    }
    let dmax = style.delta_max.max(1.0);
    let bar_w = bw * DELTA_BINS as f64;
    let ty = by + bh + 14.0;
    let _ = writeln!(out, r#"<text x="{bx}" y="{ty}">δ = 1</text>"#);
    let _ = writeln!(
        out,
        r#"<text x="{}" y="{ty}" text-anchor="middle">{}</text>"#,
        bx + 0.5 * bar_w,
        fmt_num(0.5 * (1.0 + dmax))
    );
    let _ = writeln!(
        out,
        r#"<text x="{}" y="{ty}" text-anchor="end">≥ {}</text>"#,
        bx + bar_w,
        fmt_num(dmax)
    );
    let fx = bx + bar_w + 32.0;
    let _ = writeln!(
        out,
        r#"<rect x="{fx}" y="{by}" width="{bh}" height="{bh}" fill="{}"/>"#,
        hex(FLIP_COLOR)
    );
    let _ = writeln!(
        out,
        r#"<text x="{}" y="{}">flipped: {}</text>"#,
        fx + bh + 6.0,
        by + bh - 2.0,
        stats.flips
    );
    let summary = if stats.delta_mean.is_finite() {
        format!(
            "δ = σ1/σ2 over {} faces: mean {:.4}, max {:.3}",
            stats.faces, stats.delta_mean, stats.delta_max
        )
    } else {
        format!("{} faces, no valid face", stats.faces)
    };
    let _ = writeln!(out, r#"<text x="{fx}" y="{ty}">{summary}</text>"#);
    let _ = writeln!(out, "</g>");
}

/// A short decimal: at most 3 decimals, trailing zeros dropped.
fn fmt_num(x: f64) -> String {
    let s = format!("{x:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_path_per_used_bin_and_one_subpath_per_face() {
        let mesh = TriMesh {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            faces: vec![[0, 1, 2], [0, 2, 3]],
        };
        let uv = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
        let s = layout_svg(&mesh, &uv, &LayoutStyle::default());
        assert_eq!(s.matches("<path ").count(), 1);
        assert!(s.contains(r#"id="delta-bin-0""#));
        let subpaths: usize = s
            .split(" d=\"")
            .skip(1)
            .map(|rest| rest.split('"').next().unwrap_or("").matches('z').count())
            .sum();
        assert_eq!(subpaths, 2);
        assert!(!s.contains("NaN"));
        // Mirror the second triangle over the diagonal: it is flipped and drawn in red.
        let uv = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [1.0, 0.0]];
        let s = layout_svg(&mesh, &uv, &LayoutStyle::default());
        assert!(s.contains(r##"id="flipped" fill="#ff0000""##));
    }

    #[test]
    fn numbers_are_short() {
        assert_eq!(fmt_num(1.5), "1.5");
        assert_eq!(fmt_num(2.0), "2");
    }
}
