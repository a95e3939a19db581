//! Packing several charts into the unit square without overlap.
//!
//! Every chart is first scaled so its UV area equals its 3D area (one texel density for the
//! whole atlas: a texture looks equally sharp on every chart), then turned so its bounding box
//! is the smallest over the directions of its convex hull's edges (the minimum-area enclosing
//! rectangle has a side on the hull; Freeman & Shapira 1975), laid flat (width ≥ height), and
//! the boxes are packed into shelves, tallest first (next-fit decreasing height). The strip
//! width is chosen among candidates to make the result as square as possible, and the margin
//! is kept between boxes and around the border, in the final `[0, 1]²` units. Boxes are disjoint,
//! so charts are too (each chart lies inside its box).
#![forbid(unsafe_code)]

/// Packing options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PackOptions {
    /// Gap between charts and to the square's border, as a fraction of the square's side.
    pub margin: f64,
}

impl Default for PackOptions {
    fn default() -> Self {
        PackOptions { margin: 0.005 }
    }
}

/// What [`pack`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct Packing {
    /// Σ chart UV area / area of the unit square, after packing.
    pub efficiency: f64,
    /// Lower-left corner and size of each chart's box in `[0, 1]²`.
    pub boxes: Vec<[f64; 4]>,
}

/// One chart to pack: its vertices (indices into the shared UV array), its faces (triangles
/// of those indices) and its 3D area.
pub struct ChartRef<'a> {
    pub vertices: &'a [u32],
    pub faces: &'a [[u32; 3]],
    pub area_3d: f64,
}

/// Packs the charts of `uv` in place into `[0, 1]²`. Each vertex must belong to one chart.
pub fn pack(uv: &mut [[f64; 2]], charts: &[ChartRef], opts: &PackOptions) -> Packing {
    let margin = opts.margin.clamp(0.0, 0.2);
    // Scale to 3D area, rotate to the minimal box, move the box's corner to the origin.
    let mut sizes = Vec::with_capacity(charts.len());
    for c in charts {
        let a_uv: f64 = c
            .faces
            .iter()
            .map(|f| crate::init::face_area_2d(uv, f))
            .sum();
        let s = if a_uv > 0.0 && c.area_3d > 0.0 {
            (c.area_3d / a_uv).sqrt()
        } else {
            1.0
        };
        let pts: Vec<[f64; 2]> = c
            .vertices
            .iter()
            .map(|&v| {
                let p = uv[v as usize];
                [p[0] * s, p[1] * s]
            })
            .collect();
        let angle = min_box_angle(&pts);
        let (sn, cs) = angle.sin_cos();
        let mut rotated: Vec<[f64; 2]> = pts
            .iter()
            .map(|p| [cs * p[0] + sn * p[1], -sn * p[0] + cs * p[1]])
            .collect();
        let (mut lo, mut hi) = bounds(&rotated);
        if hi[1] - lo[1] > hi[0] - lo[0] {
            // Lay the box flat: shelves pack wide, low boxes best.
            for p in rotated.iter_mut() {
                *p = [p[1], -p[0]];
            }
            (lo, hi) = bounds(&rotated);
        }
        for (p, &v) in rotated.iter().zip(c.vertices) {
            uv[v as usize] = [p[0] - lo[0], p[1] - lo[1]];
        }
        sizes.push([hi[0] - lo[0], hi[1] - lo[1]]);
    }
    let total_uv_area: f64 = charts.iter().map(|c| c.area_3d.max(0.0)).sum();

    // Order: tallest first, ties by index (deterministic).
    let mut order: Vec<usize> = (0..charts.len()).collect();
    order.sort_by(|&a, &b| sizes[b][1].total_cmp(&sizes[a][1]).then(a.cmp(&b)));
    let box_area: f64 = sizes.iter().map(|s| s[0] * s[1]).sum();
    let widest = sizes.iter().map(|s| s[0]).fold(0.0, f64::max);

    // The margin is relative to the final side, which grows with the gap: iterate the gap
    // g ← margin·side(g) (a contraction while margin × the number of gaps across is < 1) until
    // it covers the margin, slightly over-sized so the last round ends on the safe side.
    let mut gap = margin * box_area.sqrt().max(widest);
    let mut chosen: Option<(f64, Vec<[f64; 2]>)> = None;
    for _ in 0..50 {
        let mut best: Option<(f64, Vec<[f64; 2]>)> = None;
        for k in 0..24 {
            let width = (box_area.sqrt() * (0.7 + 0.05 * k as f64)).max(widest) + 2.0 * gap;
            let (corners, w, h) = shelves(&sizes, &order, width, gap);
            let s = w.max(h);
            if best.as_ref().map_or(true, |b| s < b.0) {
                best = Some((s, corners));
            }
        }
        let Some((s, corners)) = best else { break };
        let enough = gap >= margin * s;
        gap = margin * s * 1.001;
        chosen = Some((s, corners));
        if enough {
            break;
        }
    }
    let Some((side, corners)) = chosen.filter(|c| c.0 > 0.0) else {
        return Packing {
            efficiency: 0.0,
            boxes: Vec::new(),
        };
    };
    let inv = 1.0 / side;
    for (c, corner) in charts.iter().zip(&corners) {
        for &v in c.vertices {
            let p = uv[v as usize];
            uv[v as usize] = [(p[0] + corner[0]) * inv, (p[1] + corner[1]) * inv];
        }
    }
    Packing {
        efficiency: total_uv_area * inv * inv,
        boxes: corners
            .iter()
            .zip(&sizes)
            .map(|(c, s)| [c[0] * inv, c[1] * inv, s[0] * inv, s[1] * inv])
            .collect(),
    }
}

/// Next-fit decreasing-height shelves in a strip of `width`; returns each box's corner and the
/// used width and height (gaps included).
fn shelves(sizes: &[[f64; 2]], order: &[usize], width: f64, gap: f64) -> (Vec<[f64; 2]>, f64, f64) {
    let mut corners = vec![[0.0; 2]; sizes.len()];
    let (mut x, mut y, mut shelf_h) = (gap, gap, 0.0f64);
    let mut used_w = 0.0f64;
    for &i in order {
        let [w, h] = sizes[i];
        if x > gap && x + w + gap > width {
            y += shelf_h + gap;
            x = gap;
            shelf_h = 0.0;
        }
        corners[i] = [x, y];
        x += w + gap;
        used_w = used_w.max(x);
        shelf_h = shelf_h.max(h);
    }
    (corners, used_w, y + shelf_h + gap)
}

fn bounds(pts: &[[f64; 2]]) -> ([f64; 2], [f64; 2]) {
    let mut lo = [f64::INFINITY; 2];
    let mut hi = [f64::NEG_INFINITY; 2];
    for p in pts {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if pts.is_empty() {
        ([0.0; 2], [0.0; 2])
    } else {
        (lo, hi)
    }
}

/// The rotation angle (rotating points by −angle) whose axis-aligned box has the least area,
/// over the directions of the convex hull's edges.
fn min_box_angle(pts: &[[f64; 2]]) -> f64 {
    let hull = convex_hull(pts);
    if hull.len() < 3 {
        return 0.0;
    }
    let mut best = (f64::INFINITY, 0.0);
    for i in 0..hull.len() {
        let a = hull[i];
        let b = hull[(i + 1) % hull.len()];
        let t = (b[1] - a[1]).atan2(b[0] - a[0]);
        let (s, c) = t.sin_cos();
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for p in &hull {
            let q = [c * p[0] + s * p[1], -s * p[0] + c * p[1]];
            for k in 0..2 {
                lo[k] = lo[k].min(q[k]);
                hi[k] = hi[k].max(q[k]);
            }
        }
        let area = (hi[0] - lo[0]) * (hi[1] - lo[1]);
        if area < best.0 {
            best = (area, t);
        }
    }
    best.1
}

/// Andrew's monotone chain, counter-clockwise, collinear points dropped.
fn convex_hull(pts: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = pts.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(offset: u32, size: f64, angle: f64) -> (Vec<[f64; 2]>, Vec<[u32; 3]>) {
        let (s, c) = angle.sin_cos();
        let pts = [
            [0.0, 0.0],
            [size, 0.0],
            [size, size / 2.0],
            [0.0, size / 2.0],
        ]
        .map(|p: [f64; 2]| [c * p[0] - s * p[1] + 5.0, s * p[0] + c * p[1] - 3.0]);
        (
            pts.to_vec(),
            vec![
                [offset, offset + 1, offset + 2],
                [offset, offset + 2, offset + 3],
            ],
        )
    }

    #[test]
    fn packed_charts_are_disjoint_and_inside() {
        let mut uv = Vec::new();
        let mut faces = Vec::new();
        let mut verts = Vec::new();
        for i in 0..7u32 {
            let (p, f) = square(4 * i, 1.0 + i as f64, 0.3 * i as f64);
            uv.extend(p);
            faces.push(f);
            verts.push((4 * i..4 * i + 4).collect::<Vec<u32>>());
        }
        let charts: Vec<ChartRef> = (0..7)
            .map(|i| ChartRef {
                vertices: &verts[i],
                faces: &faces[i],
                area_3d: (1.0 + i as f64).powi(2) / 2.0,
            })
            .collect();
        let p = pack(&mut uv, &charts, &PackOptions { margin: 0.01 });
        for q in &uv {
            assert!(q[0] >= 0.01 - 1e-12 && q[0] <= 1.0 - 0.01 + 1e-12, "{q:?}");
            assert!(q[1] >= 0.01 - 1e-12 && q[1] <= 1.0 - 0.01 + 1e-12, "{q:?}");
        }
        for i in 0..7 {
            for j in 0..i {
                let (a, b) = (p.boxes[i], p.boxes[j]);
                let apart = a[0] + a[2] + 0.01 - 1e-12 <= b[0]
                    || b[0] + b[2] + 0.01 - 1e-12 <= a[0]
                    || a[1] + a[3] + 0.01 - 1e-12 <= b[1]
                    || b[1] + b[3] + 0.01 - 1e-12 <= a[1];
                assert!(apart, "boxes {i} {j}: {a:?} {b:?}");
            }
        }
        // Rectangles rotate to their own axes, so the boxes are tight.
        let used: f64 = p.boxes.iter().map(|b| b[2] * b[3]).sum();
        assert!(
            (used - p.efficiency).abs() < 1e-9,
            "{used} {}",
            p.efficiency
        );
        assert!(p.efficiency > 0.5, "{}", p.efficiency);
    }

    #[test]
    fn hull_of_square_with_inner_point() {
        let h = convex_hull(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]]);
        assert_eq!(h.len(), 4);
    }
}
