//! Packing the charts of an atlas into one texture of `resolution`² texels.
//!
//! Every chart is scaled so its UV area equals its 3D area (one texel density for the whole
//! atlas: a texture looks equally sharp on every chart) and turned so its bounding box is the
//! smallest over the directions of its convex hull's edges (the minimum-area enclosing
//! rectangle has a side on the hull; Freeman & Shapira 1975). Then, at a candidate scale
//! (texels per unit), each chart is rasterized **conservatively** — every texel a triangle
//! touches is the chart's — and placed, largest first, into an occupancy bitmap of the texture:
//! at each of the four right-angle rotations (never mirrored: a rotation keeps every triangle's
//! orientation), the first free position in row-major order where the chart's footprint grown
//! by `padding` texels touches no other chart and stays inside the border, keeping the
//! rotation whose footprint ends lowest (then leftmost). The scale is the largest one for which
//! every chart fits, found by bisection; positions are whole texels, so a chart's final
//! footprint is exactly the one placed. This is the packer xatlas and Blender use (bitmap
//! occupancy, rotations, scale search); the bitmap rows are 64-bit words and a blocked
//! position skips to the end of the blocking run.
//!
//! **Pages.** With `max_pages` above 1, a chart that fits no earlier page goes to the next one
//! (up to `max_pages`), and the scale search targets the pages together: the atlas is page `k`
//! in `[k, k+1] × [0, 1]` of UV space (the UDIM convention: tile 1001 + k), each page its own
//! `resolution`² texture. A mesh whose charts fill one page uses one page: pages are used only
//! where the charts are larger together at one page's scale bound.
//!
//! Two numbers say how full the result is, and they differ: the **efficiency** is Σ chart UV
//! area / atlas area; the **texel coverage** is the share of texels some chart touches (what
//! xatlas calls utilization), larger because edge texels count whole.
#![forbid(unsafe_code)]

/// Packing options.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PackOptions {
    /// Texture side in texels.
    pub resolution: u32,
    /// Empty texels between charts and between a chart and the border.
    pub padding: u32,
    /// Texels per unit of 3D length: when set, the scale is this and the resolution is the
    /// smallest square (a multiple of 4) that holds the charts, instead of the reverse.
    pub texels_per_unit: Option<f64>,
    /// Texture pages the charts may use (1: one texture).
    pub max_pages: u32,
}

impl Default for PackOptions {
    fn default() -> Self {
        PackOptions {
            resolution: 1024,
            padding: 2,
            texels_per_unit: None,
            max_pages: 1,
        }
    }
}

impl PackOptions {
    /// Checks the ranges (`resolution` 16..=16384, `padding` below a quarter of it, `max_pages`
    /// 1..=1000).
    pub fn validate(&self) -> Result<(), crate::OptionError> {
        if !(1..=1000).contains(&self.max_pages) {
            return crate::OptionError::reject("pack", "max_pages", self.max_pages, "[1, 1000]");
        }
        if !(16..=16384).contains(&self.resolution) {
            return crate::OptionError::reject(
                "pack",
                "resolution",
                self.resolution,
                "[16, 16384]",
            );
        }
        if let Some(d) = self.texels_per_unit {
            if !(d.is_finite() && d > 0.0) {
                return crate::OptionError::reject("pack", "texel_density", d, "(0, ∞), finite");
            }
        }
        if self.padding >= self.resolution / 4 {
            return crate::OptionError::reject(
                "pack",
                "padding",
                self.padding,
                &format!("[0, {}) (a quarter of the resolution)", self.resolution / 4),
            );
        }
        Ok(())
    }
}

/// What [`pack`] did.
#[derive(Clone, Debug, PartialEq)]
pub struct Packing {
    /// Σ chart UV area / atlas area.
    pub efficiency: f64,
    /// Texels touched by some chart / all texels.
    pub coverage: f64,
    /// Texels per unit of 3D length.
    pub texels_per_unit: f64,
    /// Texture side in texels (the requested one, or the one found for a texel density).
    pub resolution: u32,
    /// Pages used (page `k` is `[k, k+1] × [0, 1]` in UV).
    pub pages: u32,
    /// Per chart: lower-left texel of its footprint and its orientation (0–3: quarter turns
    /// of the minimum-area box; 4–7: of the smallest enclosing square, when they differ).
    pub placements: Vec<([u32; 2], u8)>,
    /// Per chart: its page.
    pub chart_pages: Vec<u32>,
}

/// One chart to pack: its vertices (indices into the shared UV array), its faces (triangles
/// of those indices) and its 3D area.
pub struct ChartRef<'a> {
    pub vertices: &'a [u32],
    pub faces: &'a [[u32; 3]],
    pub area_3d: f64,
}

/// Packs the charts of `uv` in place into `[0, 1]²` (texel `(i, j)` covers
/// `[i, i+1] × [j, j+1] / resolution`), or into pages `[k, k+1] × [0, 1]` with
/// `opts.max_pages` > 1. Each vertex must belong to one chart. Fails when the charts cannot
/// all get a footprint with their padding at this resolution (too many charts).
pub fn pack(
    uv: &mut [[f64; 2]],
    charts: &[ChartRef],
    opts: &PackOptions,
) -> crate::Result<Packing> {
    opts.validate()?;
    // Scale to 3D area; the orientations each chart may be placed in: its minimum-area box
    // and its smallest enclosing square (what bounds a large chart in a square texture), each
    // at four right angles — rotations only, never a reflection.
    let mut shapes: Vec<Vec<Vec<[f64; 2]>>> = Vec::with_capacity(charts.len());
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
        let hull = convex_hull(&pts);
        let mut bases = vec![min_box_angle(&hull)];
        let square = min_square_angle(&hull);
        let quarter = std::f64::consts::FRAC_PI_2;
        let apart = (square - bases[0]).rem_euclid(quarter);
        if apart.min(quarter - apart) > 1e-6 {
            bases.push(square);
        }
        let mut orientations = Vec::with_capacity(4 * bases.len());
        for angle in bases {
            let rotated = rotate(&pts, angle);
            for k in 0..4 {
                orientations.push(quarter_turns(&rotated, k));
            }
        }
        shapes.push(orientations);
    }
    // Each chart's triangles in its local vertex numbering.
    let tris: Vec<Vec<[usize; 3]>> = charts
        .iter()
        .map(|c| {
            let index: std::collections::HashMap<u32, usize> = c
                .vertices
                .iter()
                .enumerate()
                .map(|(i, &v)| (v, i))
                .collect();
            c.faces
                .iter()
                .filter_map(|f| Some([*index.get(&f[0])?, *index.get(&f[1])?, *index.get(&f[2])?]))
                .collect()
        })
        .collect();
    let total_area: f64 = charts.iter().map(|c| c.area_3d.max(0.0)).sum();
    if charts.is_empty() || !(total_area > 0.0 && total_area.is_finite()) {
        return Ok(Packing {
            efficiency: 0.0,
            coverage: 0.0,
            texels_per_unit: 0.0,
            resolution: opts.resolution,
            pages: 0,
            placements: Vec::new(),
            chart_pages: Vec::new(),
        });
    }
    let (resolution, s_ok, a_ok) = match opts.texels_per_unit {
        None => {
            let (s, a) = search_scale(&shapes, &tris, total_area, opts)?;
            (opts.resolution, s, a)
        }
        Some(density) => {
            let (res, a) = search_resolution(&shapes, &tris, total_area, density, opts)?;
            (res, density, a)
        }
    };
    let r = f64::from(resolution);
    // Final UVs: rotate the scaled footprint, move it to its texel, divide by the resolution,
    // shift to its page.
    for (((c, o), (at, which)), &page) in charts
        .iter()
        .zip(&shapes)
        .zip(&a_ok.placements)
        .zip(&a_ok.pages)
    {
        let turned: Vec<[f64; 2]> = o[*which as usize]
            .iter()
            .map(|p| [p[0] * s_ok, p[1] * s_ok])
            .collect();
        for (q, &v) in turned.iter().zip(c.vertices) {
            uv[v as usize] = [
                (q[0] + 0.5 + f64::from(at[0])) / r + f64::from(page),
                (q[1] + 0.5 + f64::from(at[1])) / r,
            ];
        }
    }
    let pages = a_ok.pages.iter().copied().max().map_or(0, |p| p + 1);
    let area = r * r * f64::from(pages.max(1));
    Ok(Packing {
        efficiency: total_area * s_ok * s_ok / area,
        coverage: a_ok.covered as f64 / area,
        texels_per_unit: s_ok,
        resolution,
        pages,
        placements: a_ok.placements,
        chart_pages: a_ok.pages,
    })
}

/// The largest scale (texels per unit) at which every chart fits `opts.resolution`².
fn search_scale(
    shapes: &[Vec<Vec<[f64; 2]>>],
    tris: &[Vec<[usize; 3]>],
    total_area: f64,
    opts: &PackOptions,
) -> crate::Result<(f64, Attempt)> {
    let r = f64::from(opts.resolution);
    // No scale beats 100 % efficiency, and each chart's smallest side over its orientations
    // must fit inside the padding (less the texel its footprint can straddle at each end).
    let room = r - 2.0 * f64::from(opts.padding) - 2.0;
    let widest = shapes
        .iter()
        .map(|o| {
            o.iter()
                .map(|p| {
                    let (_, hi) = bounds(p);
                    hi[0].max(hi[1])
                })
                .fold(f64::INFINITY, f64::min)
        })
        .fold(0.0, f64::max);
    let pages = f64::from(opts.max_pages.max(1));
    let bound = (r * pages.sqrt() / total_area.sqrt()).min(if widest > 0.0 && room > 0.0 {
        room / widest
    } else {
        f64::INFINITY
    });
    // The bound itself often fits (one dominant chart); otherwise step down until a packing
    // exists, then bisect (in log) between it and the last failure, to 0.2 %.
    let mut found: Option<(f64, Attempt)> = None;
    let mut failed: Option<f64> = None;
    let mut factor = 1.0;
    for _ in 0..60 {
        let s = bound * factor;
        match attempt(shapes, tris, s, opts) {
            Some(a) => {
                found = Some((s, a));
                break;
            }
            None => {
                failed = Some(s);
                factor = next_factor(factor);
            }
        }
    }
    let Some((mut s_ok, mut a_ok)) = found else {
        return Err(crate::Error::Usage(format!(
            "{} charts do not fit {} page(s) of {}² texels with {} texels of padding; raise \
             --resolution or --max-pages",
            shapes.len(),
            opts.max_pages,
            opts.resolution,
            opts.padding
        )));
    };
    let mut hi = failed.unwrap_or(s_ok);
    while hi / s_ok > 1.002 {
        let mid = (s_ok * hi).sqrt();
        match attempt(shapes, tris, mid, opts) {
            Some(a) => {
                s_ok = mid;
                a_ok = a;
            }
            None => hi = mid,
        }
    }
    Ok((s_ok, a_ok))
}

/// The smallest square texture (a multiple of 4 texels, at most 16384) holding every chart at
/// `density` texels per unit: from the area bound, doubling until it fits, then bisection.
fn search_resolution(
    shapes: &[Vec<Vec<[f64; 2]>>],
    tris: &[Vec<[usize; 3]>],
    total_area: f64,
    density: f64,
    opts: &PackOptions,
) -> crate::Result<(u32, Attempt)> {
    const MAX: u32 = 16384;
    let at = |res: u32| {
        attempt(
            shapes,
            tris,
            density,
            &PackOptions {
                resolution: res,
                ..*opts
            },
        )
    };
    // Below one texel for the largest chart, the texel offsets swamp the chart's coordinates
    // in f64 and its faces collapse: a density that small is a usage error, not a failed run.
    let largest = shapes
        .iter()
        .flat_map(|o| o.iter().map(|p| span(p)))
        .fold(0.0f64, f64::max);
    if largest * density < 1.0 || (largest * density).is_nan() {
        return Err(crate::Error::Usage(format!(
            "--texel-density {density:e}: the largest chart ({largest:.3e} units across) would \
             be under one texel; raise --texel-density"
        )));
    }
    let round4 = |x: f64| ((x / 4.0).ceil() as u32).saturating_mul(4);
    let pages = f64::from(opts.max_pages.max(1));
    let mut lo = round4((total_area.sqrt() * density / pages.sqrt()).max(16.0)).min(MAX);
    let mut found = None;
    let mut hi = lo;
    loop {
        if let Some(a) = at(hi) {
            found = Some(a);
            break;
        }
        if hi >= MAX {
            break;
        }
        lo = hi;
        hi = (hi * 2).min(MAX);
    }
    let Some(mut a_ok) = found else {
        return Err(crate::Error::Usage(format!(
            "at {density:e} texels per unit the charts need more than {MAX}² texels; lower \
             --texel-density"
        )));
    };
    // `lo` failed (or is the area bound), `hi` fits.
    while hi - lo > 4 {
        let mid = lo + ((hi - lo) / 8) * 4;
        match at(mid) {
            Some(a) => {
                hi = mid;
                a_ok = a;
            }
            None => lo = mid,
        }
    }
    Ok((hi, a_ok))
}

/// A successful placement of every chart at one scale.
struct Attempt {
    placements: Vec<([u32; 2], u8)>,
    /// Per chart, its page.
    pages: Vec<u32>,
    covered: u64,
}

/// Places every chart at `scale` texels per unit, or `None` when one does not fit.
/// The larger side of the bounding box of a chart footprint.
fn span(pts: &[[f64; 2]]) -> f64 {
    let (lo, hi) = bounds(pts);
    (hi[0] - lo[0]).max(hi[1] - lo[1]).max(0.0)
}

fn attempt(
    shapes: &[Vec<Vec<[f64; 2]>>],
    tris: &[Vec<[usize; 3]>],
    scale: f64,
    opts: &PackOptions,
) -> Option<Attempt> {
    let n = opts.resolution as usize;
    let pad = opts.padding as usize;
    // A chart wider than the texture cannot fit: refuse it before rasterizing, whose bitmap
    // would be as large as the scaled chart (a density of 1e300 asked for an impossible
    // allocation and panicked).
    if shapes.iter().any(|o| {
        let side = o.iter().map(|p| span(p)).fold(0.0, f64::max) * scale;
        side > n as f64 || side.is_nan()
    }) {
        return None;
    }
    // Footprints of each orientation.
    let masks: Vec<Vec<Mask>> = shapes
        .iter()
        .zip(tris)
        .map(|(o, t)| {
            o.iter()
                .map(|pts| {
                    let scaled: Vec<[f64; 2]> =
                        pts.iter().map(|p| [p[0] * scale, p[1] * scale]).collect();
                    Mask::rasterize(&scaled, t)
                })
                .collect()
        })
        .collect();
    let mut order: Vec<usize> = (0..shapes.len()).collect();
    order.sort_by(|&a, &b| masks[b][0].count.cmp(&masks[a][0].count).then(a.cmp(&b)));
    let mut atlas: Vec<Bitmap> = vec![Bitmap::new(n, n)];
    let mut placements = vec![([0u32; 2], 0u8); shapes.len()];
    let mut pages = vec![0u32; shapes.len()];
    let mut covered = 0u64;
    for &i in &order {
        // The first page (opening a new one while allowed) where some orientation fits.
        let mut placed = None;
        for page in 0..opts.max_pages.max(1) as usize {
            if page == atlas.len() {
                atlas.push(Bitmap::new(n, n));
            }
            let mut chosen: Option<(usize, usize, u8)> = None;
            for rot in 0..masks[i].len() as u8 {
                let m = &masks[i][rot as usize];
                let grown = m.grown(pad);
                let top_limit = chosen.map(|(x, y, r)| (y + masks[i][r as usize].h, x));
                if let Some((x, y)) = atlas[page].first_fit(&grown, top_limit.map(|t| t.0), m.h) {
                    let key = (y + m.h, x);
                    if top_limit.is_none_or(|t| key < t) {
                        chosen = Some((x, y, rot));
                    }
                }
            }
            if let Some(c) = chosen {
                placed = Some((page, c));
                break;
            }
        }
        let (page, (x, y, rot)) = placed?;
        let m = &masks[i][rot as usize];
        // The grown footprint sits at (x, y); the chart's own is `pad` texels in.
        atlas[page].set(m, x + pad, y + pad);
        covered += m.count as u64;
        placements[i] = ([(x + pad) as u32, (y + pad) as u32], rot);
        pages[i] = page as u32;
    }
    Some(Attempt {
        placements,
        pages,
        covered,
    })
}

/// The scale ladder below the bound: 1, 0.99, 0.97, 0.93, 0.85, 0.7, then halving.
fn next_factor(f: f64) -> f64 {
    const LADDER: [f64; 6] = [1.0, 0.99, 0.97, 0.93, 0.85, 0.7];
    match LADDER.iter().position(|&x| (x - f).abs() < 1e-12) {
        Some(i) if i + 1 < LADDER.len() => LADDER[i + 1],
        _ => f * 0.5,
    }
}

/// `pts` rotated by −`angle`.
fn rotate(pts: &[[f64; 2]], angle: f64) -> Vec<[f64; 2]> {
    let (sn, cs) = angle.sin_cos();
    pts.iter()
        .map(|p| [cs * p[0] + sn * p[1], -sn * p[0] + cs * p[1]])
        .collect()
}

/// The rotation angle (rotating by −angle) whose axis-aligned box has the smallest larger
/// side: the chart's smallest enclosing square, searched on a 1° grid and refined by
/// golden-section search around the best sample.
fn min_square_angle(hull: &[[f64; 2]]) -> f64 {
    if hull.len() < 3 {
        return 0.0;
    }
    let side = |t: f64| {
        let (lo, hi) = bounds(&rotate(hull, t));
        (hi[0] - lo[0]).max(hi[1] - lo[1])
    };
    let step = std::f64::consts::FRAC_PI_2 / 90.0;
    let (mut best, mut best_side) = (0.0, f64::INFINITY);
    for k in 0..90 {
        let t = k as f64 * step;
        let s = side(t);
        if s < best_side {
            (best, best_side) = (t, s);
        }
    }
    let (mut a, mut b) = (best - step, best + step);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..30 {
        let (c, d) = (b - g * (b - a), a + g * (b - a));
        if side(c) < side(d) {
            b = d;
        } else {
            a = c;
        }
    }
    let t = 0.5 * (a + b);
    if side(t) < best_side {
        t
    } else {
        best
    }
}

/// `pts` turned by `k` quarter turns counter-clockwise and moved back to the positive
/// quadrant with its box at the origin (a rotation: orientation is kept).
fn quarter_turns(pts: &[[f64; 2]], k: u8) -> Vec<[f64; 2]> {
    let turned: Vec<[f64; 2]> = pts
        .iter()
        .map(|&[x, y]| match k % 4 {
            0 => [x, y],
            1 => [-y, x],
            2 => [-x, -y],
            _ => [y, -x],
        })
        .collect();
    let (lo, _) = bounds(&turned);
    turned
        .iter()
        .map(|p| [p[0] - lo[0], p[1] - lo[1]])
        .collect()
}

/// Rows of bits, 64 per word.
#[derive(Clone, Debug)]
struct Bitmap {
    w: usize,
    h: usize,
    words: usize,
    bits: Vec<u64>,
}

impl Bitmap {
    fn new(w: usize, h: usize) -> Bitmap {
        let words = w.div_ceil(64).max(1);
        Bitmap {
            w,
            h,
            words,
            bits: vec![0; words * h],
        }
    }

    fn get(&self, x: usize, y: usize) -> bool {
        self.bits[y * self.words + x / 64] >> (x % 64) & 1 == 1
    }

    /// Sets bits `x0..=x1` of row `y`.
    fn set_run(&mut self, y: usize, x0: usize, x1: usize) {
        let row = &mut self.bits[y * self.words..(y + 1) * self.words];
        let (k0, k1) = (x0 / 64, x1 / 64);
        for (k, word) in row.iter_mut().enumerate().take(k1 + 1).skip(k0) {
            let lo = if k == k0 { x0 % 64 } else { 0 };
            let hi = if k == k1 { x1 % 64 } else { 63 };
            let mask = (u64::MAX >> (63 - hi)) & (u64::MAX << lo);
            *word |= mask;
        }
    }

    fn put(&mut self, x: usize, y: usize) {
        self.bits[y * self.words + x / 64] |= 1 << (x % 64);
    }

    /// Bits `x .. x + 64` of row `y` (zeros past the end).
    fn window(&self, x: usize, y: usize) -> u64 {
        let row = &self.bits[y * self.words..(y + 1) * self.words];
        let (k, sh) = (x / 64, x % 64);
        let lo = row.get(k).copied().unwrap_or(0) >> sh;
        let hi = if sh == 0 {
            0
        } else {
            row.get(k + 1).copied().unwrap_or(0) << (64 - sh)
        };
        lo | hi
    }

    /// Whether `m` placed with its origin at `(x, y)` hits a set bit; on a hit, the row of
    /// the mask that hit.
    /// Rows are tried from `hint` on (the row that hit last time: at the next position it
    /// usually hits again).
    fn hits(&self, m: &Mask, x: usize, y: usize, hint: usize) -> Option<usize> {
        let hit = |r: usize| {
            let row = &m.bits.bits[r * m.bits.words..(r + 1) * m.bits.words];
            row.iter()
                .enumerate()
                .any(|(k, &word)| word != 0 && self.window(x + 64 * k, y + r) & word != 0)
        };
        let hint = hint.min(m.h.saturating_sub(1));
        (hint..m.h).chain(0..hint).find(|&r| hit(r))
    }

    /// The first free texel of row `y` at or after `x` (`w` when none).
    fn free_from(&self, mut x: usize, y: usize) -> usize {
        while x < self.w {
            let word = !self.window(x, y);
            if word != 0 {
                return (x + word.trailing_zeros() as usize).min(self.w);
            }
            x += 64;
        }
        self.w
    }

    /// The first position (row-major) where `m` fits inside the bitmap without hitting a set
    /// bit. With `top_limit`, rows `y` with `y + h > top_limit` are not searched (`h`: the
    /// height the caller ranks positions by).
    fn first_fit(&self, m: &Mask, top_limit: Option<usize>, h: usize) -> Option<(usize, usize)> {
        if m.w > self.w || m.h > self.h {
            return None;
        }
        for y in 0..=self.h - m.h {
            if top_limit.is_some_and(|t| y + h > t) {
                return None;
            }
            let mut x = 0;
            let mut hint = 0;
            while x + m.w <= self.w {
                match self.hits(m, x, y, hint) {
                    None => return Some((x, y)),
                    Some(r) => {
                        // The row's first and last set texels must both land on free texels:
                        // skip past the occupied runs under either.
                        hint = r;
                        let (first, last) = (m.first[r], m.last[r]);
                        let a = self.free_from(x + first, y + r) - first;
                        let b = self.free_from(x + last, y + r) - last;
                        x = a.max(b).max(x + 1);
                    }
                }
            }
        }
        None
    }

    /// Sets the bits of `m` placed at `(x, y)`.
    fn set(&mut self, m: &Mask, x: usize, y: usize) {
        for r in 0..m.h {
            for c in 0..m.w {
                if m.bits.get(c, r) {
                    self.put(x + c, y + r);
                }
            }
        }
    }
}

/// How far outside a texel a triangle still counts as touching it when rasterizing (in
/// texels): final UVs are recomputed in floating point, and a footprint must contain every
/// texel the written chart touches, whatever the rounding.
const TOUCH_EPS: f64 = 1e-6;

/// A chart's footprint: the texels its triangles touch, with its box at the origin.
#[derive(Clone, Debug)]
struct Mask {
    w: usize,
    h: usize,
    bits: Bitmap,
    /// Per row, the first and last set column (`w` and 0 when empty).
    first: Vec<usize>,
    last: Vec<usize>,
    count: usize,
}

impl Mask {
    /// Conservative rasterization: texel `(i, j)` = `[i, i+1] × [j, j+1]` is set when it
    /// intersects a triangle (separating-axis test: the box's two axes, the triangle's three
    /// edge normals; a degenerate triangle counts as its box).
    fn rasterize(pts: &[[f64; 2]], tris: &[[usize; 3]]) -> Mask {
        // Half a texel in from the box's corner: no vertex sits on the grid line the mask's
        // first row and column start at (the final UVs are moved the same way).
        let pts: Vec<[f64; 2]> = pts.iter().map(|p| [p[0] + 0.5, p[1] + 0.5]).collect();
        let pts = &pts[..];
        let (_, hi) = bounds(pts);
        let w = (hi[0].ceil() as usize).max(1);
        let h = (hi[1].ceil() as usize).max(1);
        let mut bits = Bitmap::new(w, h);
        for t in tris {
            let p = t.map(|i| pts[i]);
            let (lo, hi) = bounds(&p);
            let y0 = ((lo[1] - TOUCH_EPS).floor().max(0.0) as usize).min(h - 1);
            let y1 = ((hi[1] + TOUCH_EPS).floor().max(0.0) as usize).min(h - 1);
            for j in y0..=y1 {
                // The triangle clipped to the closed row [j, j+1] (grown by TOUCH_EPS) is convex
                // and spans the row's height only where it lies, so a texel of the row touches
                // it exactly when their x-ranges overlap.
                let (b0, b1) = (j as f64 - TOUCH_EPS, j as f64 + 1.0 + TOUCH_EPS);
                let (mut x_lo, mut x_hi) = (f64::INFINITY, f64::NEG_INFINITY);
                for k in 0..3 {
                    let (a, b) = (p[k], p[(k + 1) % 3]);
                    if (b0..=b1).contains(&a[1]) {
                        x_lo = x_lo.min(a[0]);
                        x_hi = x_hi.max(a[0]);
                    }
                    for y in [b0, b1] {
                        if (a[1] - y) * (b[1] - y) < 0.0 {
                            let x = a[0] + (b[0] - a[0]) * (y - a[1]) / (b[1] - a[1]);
                            x_lo = x_lo.min(x);
                            x_hi = x_hi.max(x);
                        }
                    }
                }
                if x_lo > x_hi {
                    continue;
                }
                let i0 = ((x_lo - TOUCH_EPS).ceil() - 1.0).max(0.0) as usize;
                let i1 = ((x_hi + TOUCH_EPS).floor().max(0.0) as usize).min(w - 1);
                if i0 <= i1 {
                    bits.set_run(j, i0, i1);
                }
            }
        }
        Mask::from_bits(bits)
    }

    fn from_bits(bits: Bitmap) -> Mask {
        let (w, h) = (bits.w, bits.h);
        let first = (0..h)
            .map(|r| (0..w).find(|&c| bits.get(c, r)).unwrap_or(w))
            .collect();
        let last = (0..h)
            .map(|r| (0..w).rev().find(|&c| bits.get(c, r)).unwrap_or(0))
            .collect();
        let count = bits.bits.iter().map(|b| b.count_ones() as usize).sum();
        Mask {
            w,
            h,
            bits,
            first,
            last,
            count,
        }
    }

    /// The footprint grown by `pad` texels in every direction (a square neighbourhood), so a
    /// grown footprint that touches no other chart keeps `pad` empty texels between them.
    fn grown(&self, pad: usize) -> Mask {
        let (w, h) = (self.w + 2 * pad, self.h + 2 * pad);
        let mut bits = Bitmap::new(w, h);
        let words = bits.words;
        // Horizontal: each row ORed with itself shifted by 1..=2·pad texels (word carries);
        // vertical: each grown row is the OR of 2·pad + 1 of those.
        let mut wide = vec![0u64; words * self.h];
        for r in 0..self.h {
            let src = &self.bits.bits[r * self.bits.words..(r + 1) * self.bits.words];
            let dst = &mut wide[r * words..(r + 1) * words];
            for shift in 0..=2 * pad {
                let (k, sh) = (shift / 64, shift % 64);
                for (i, &word) in src.iter().enumerate() {
                    if word == 0 {
                        continue;
                    }
                    if let Some(d) = dst.get_mut(i + k) {
                        *d |= word << sh;
                    }
                    if sh > 0 {
                        if let Some(d) = dst.get_mut(i + k + 1) {
                            *d |= word >> (64 - sh);
                        }
                    }
                }
            }
        }
        for r in 0..self.h {
            for dy in 0..=2 * pad {
                let (src, dst) = (r * words, (r + dy) * words);
                for i in 0..words {
                    bits.bits[dst + i] |= wide[src + i];
                }
            }
        }
        Mask::from_bits(bits)
    }
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
fn min_box_angle(hull: &[[f64; 2]]) -> f64 {
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
        for p in hull {
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

    /// Whether the closed triangle `p` and the closed texel `[i, i+1] × [j, j+1]`, grown by
    /// `eps` on every side, intersect.
    fn triangle_touches_cell(p: &[[f64; 2]; 3], i: f64, j: f64, eps: f64) -> bool {
        let (a0, a1, b0, b1) = (i - eps, i + 1.0 + eps, j - eps, j + 1.0 + eps);
        let corners = [[a0, b0], [a1, b0], [a1, b1], [a0, b1]];
        let (lo, hi) = bounds(p);
        if hi[0] < a0 || lo[0] > a1 || hi[1] < b0 || lo[1] > b1 {
            return false;
        }
        for k in 0..3 {
            let a = p[k];
            let b = p[(k + 1) % 3];
            let c = p[(k + 2) % 3];
            let n = [a[1] - b[1], b[0] - a[0]];
            if n[0] == 0.0 && n[1] == 0.0 {
                continue;
            }
            let side = |q: [f64; 2]| n[0] * (q[0] - a[0]) + n[1] * (q[1] - a[1]);
            let inner = side(c);
            if inner == 0.0 {
                continue; // degenerate: the box test above decides
            }
            // The cell is entirely on the far side of this edge.
            if corners.iter().all(|&q| side(q) * inner < 0.0) {
                return false;
            }
        }
        true
    }

    /// The scanline rasterizer sets exactly the texels the separating-axis test says a
    /// triangle touches (random triangles, grown by the same epsilon).
    #[test]
    fn scanline_raster_matches_the_separating_axis_test() {
        let mut rng = crate::linalg::rng::SplitMix(0x9e3779b97f4a7c15);
        let mut rnd = || rng.unit();
        for _ in 0..200 {
            let p: Vec<[f64; 2]> = (0..3).map(|_| [rnd() * 12.0, rnd() * 9.0]).collect();
            let m = Mask::rasterize(&p, &[[0, 1, 2]]);
            let q: [[f64; 2]; 3] = [0, 1, 2].map(|k| [p[k][0] + 0.5, p[k][1] + 0.5]);
            for j in 0..m.h {
                for i in 0..m.w {
                    assert_eq!(
                        m.bits.get(i, j),
                        triangle_touches_cell(&q, i as f64, j as f64, TOUCH_EPS),
                        "texel ({i}, {j}) of {q:?}"
                    );
                }
            }
        }
    }

    fn rect(offset: u32, w: f64, h: f64, angle: f64) -> (Vec<[f64; 2]>, Vec<[u32; 3]>) {
        let (s, c) = angle.sin_cos();
        let pts = [[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]]
            .map(|p: [f64; 2]| [c * p[0] - s * p[1] + 5.0, s * p[0] + c * p[1] - 3.0]);
        (
            pts.to_vec(),
            vec![
                [offset, offset + 1, offset + 2],
                [offset, offset + 2, offset + 3],
            ],
        )
    }

    /// `n` rectangles (`dims(i)` = width, height, angle) as charts of one UV array: the UVs,
    /// each chart's faces and vertices.
    #[allow(clippy::type_complexity)]
    fn rects(
        n: u32,
        dims: impl Fn(u32) -> (f64, f64, f64),
    ) -> (Vec<[f64; 2]>, Vec<Vec<[u32; 3]>>, Vec<Vec<u32>>) {
        let (mut uv, mut faces, mut verts) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..n {
            let (w, h, angle) = dims(i);
            let (p, f) = rect(4 * i, w, h, angle);
            uv.extend(p);
            faces.push(f);
            verts.push((4 * i..4 * i + 4).collect::<Vec<u32>>());
        }
        (uv, faces, verts)
    }

    /// The charts of [`rects`], chart `i` of 3D area `area(i)`.
    fn chart_refs<'a>(
        faces: &'a [Vec<[u32; 3]>],
        verts: &'a [Vec<u32>],
        area: impl Fn(usize) -> f64,
    ) -> Vec<ChartRef<'a>> {
        (0..faces.len())
            .map(|i| ChartRef {
                vertices: &verts[i],
                faces: &faces[i],
                area_3d: area(i),
            })
            .collect()
    }

    /// Charts packed at 256² with 2 texels padding: inside the square, counter-clockwise
    /// still, and their conservative footprints (recomputed from the final UVs) 2 texels apart.
    #[test]
    fn packed_charts_keep_their_padding_and_orientation() {
        let size = |i: f64| (1.0 + i, 0.5 + 0.3 * i);
        let (mut uv, faces, verts) = rects(9, |i| {
            let (w, h) = size(f64::from(i));
            (w, h, 0.3 * f64::from(i))
        });
        let charts = chart_refs(&faces, &verts, |i| {
            let (w, h) = size(i as f64);
            w * h
        });
        let opts = PackOptions {
            resolution: 256,
            padding: 2,
            texels_per_unit: None,
            max_pages: 1,
        };
        let p = pack(&mut uv, &charts, &opts).expect("packs");
        let n = 256.0;
        let mut owner = vec![usize::MAX; 256 * 256];
        for (ci, fs) in faces.iter().enumerate() {
            for f in fs {
                let t = f.map(|v| [uv[v as usize][0] * n, uv[v as usize][1] * n]);
                let signed = (t[1][0] - t[0][0]) * (t[2][1] - t[0][1])
                    - (t[2][0] - t[0][0]) * (t[1][1] - t[0][1]);
                assert!(signed > 0.0, "chart {ci} was mirrored");
                for q in &t {
                    assert!(q[0] >= 2.0 && q[0] <= n - 2.0 && q[1] >= 2.0 && q[1] <= n - 2.0);
                }
                for j in 0..256 {
                    for i in 0..256 {
                        if triangle_touches_cell(&t, i as f64, j as f64, 0.0) {
                            let o = &mut owner[j * 256 + i];
                            assert!(*o == usize::MAX || *o == ci, "texel ({i}, {j}) shared");
                            *o = ci;
                        }
                    }
                }
            }
        }
        for j in 0..256usize {
            for i in 0..256usize {
                let o = owner[j * 256 + i];
                if o == usize::MAX {
                    continue;
                }
                for dj in j.saturating_sub(2)..(j + 3).min(256) {
                    for di in i.saturating_sub(2)..(i + 3).min(256) {
                        let q = owner[dj * 256 + di];
                        assert!(
                            q == usize::MAX || q == o,
                            "charts {o} and {q} closer than 2"
                        );
                    }
                }
            }
        }
        assert!(p.efficiency > 0.6 && p.efficiency < p.coverage, "{p:?}");
    }

    /// Four equal squares with four pages allowed: one per page at about twice the texel
    /// density of one page holding all four; each chart inside its page's tile `[k, k+1]`,
    /// counter-clockwise; with one page allowed, the old single texture.
    #[test]
    fn pages_hold_what_one_texture_cannot_at_that_density() {
        let (uv0, faces, verts) = rects(4, |i| (1.0, 1.0, 0.1 * f64::from(i)));
        let charts = chart_refs(&faces, &verts, |_| 1.0);
        let run = |max_pages| {
            let mut uv = uv0.clone();
            let opts = PackOptions {
                resolution: 64,
                max_pages,
                ..PackOptions::default()
            };
            (pack(&mut uv, &charts, &opts).expect("packs"), uv)
        };
        let (one, uv1) = run(1);
        assert_eq!((one.pages, one.chart_pages.clone()), (1, vec![0; 4]));
        assert!(uv1.iter().all(|p| (0.0..=1.0).contains(&p[0])));
        let (four, uv4) = run(4);
        assert_eq!(four.pages, 4, "{four:?}");
        assert!(
            four.texels_per_unit > 1.8 * one.texels_per_unit,
            "{four:?} vs {one:?}"
        );
        assert!(four.efficiency > 0.8, "{four:?}");
        for (c, f) in faces.iter().enumerate() {
            let k = f64::from(four.chart_pages[c]);
            for t in f {
                let q = t.map(|v| uv4[v as usize]);
                assert!(q
                    .iter()
                    .all(|p| p[0] > k && p[0] < k + 1.0 && p[1] > 0.0 && p[1] < 1.0));
                let signed = (q[1][0] - q[0][0]) * (q[2][1] - q[0][1])
                    - (q[2][0] - q[0][0]) * (q[1][1] - q[0][1]);
                assert!(signed > 0.0, "chart {c} was mirrored");
            }
        }
        let mut used = four.chart_pages.clone();
        used.sort();
        assert_eq!(used, vec![0, 1, 2, 3]);
    }

    /// A single square fills the texture up to its padding.
    #[test]
    fn one_square_fills_the_texture() {
        let (mut uv, f) = rect(0, 1.0, 1.0, 0.2);
        let verts = [0, 1, 2, 3];
        let charts = [ChartRef {
            vertices: &verts,
            faces: &f,
            area_3d: 1.0,
        }];
        let p = pack(&mut uv, &charts, &PackOptions::default()).expect("packs");
        assert!(p.efficiency > 0.985, "{p:?}");
    }

    /// With a texel density the scale is fixed and the texture is the smallest that holds
    /// the chart: a unit square at 100 texels per unit needs 100 texels, its padding and the
    /// texel its footprint straddles — 108 rounded to a multiple of 4.
    #[test]
    fn a_texel_density_picks_the_smallest_texture() {
        let (mut uv, f) = rect(0, 1.0, 1.0, 0.0);
        let verts = [0, 1, 2, 3];
        let charts = [ChartRef {
            vertices: &verts,
            faces: &f,
            area_3d: 1.0,
        }];
        let opts = PackOptions {
            texels_per_unit: Some(100.0),
            ..PackOptions::default()
        };
        let p = pack(&mut uv, &charts, &opts).expect("packs");
        assert_eq!(p.texels_per_unit, 100.0);
        assert!((104..=108).contains(&p.resolution), "{p:?}");
        let side = uv.iter().map(|q| q[0]).fold(0.0, f64::max)
            - uv.iter().map(|q| q[0]).fold(1.0, f64::min);
        assert!(
            (side * f64::from(p.resolution) - 100.0).abs() < 1e-9,
            "{side}"
        );
    }

    #[test]
    fn too_many_charts_for_the_resolution_is_an_error() {
        let (mut uv, faces, verts) = rects(200, |_| (1.0, 1.0, 0.0));
        let charts = chart_refs(&faces, &verts, |_| 1.0);
        let opts = PackOptions {
            resolution: 16,
            padding: 2,
            texels_per_unit: None,
            max_pages: 1,
        };
        assert!(pack(&mut uv, &charts, &opts).is_err());
    }

    #[test]
    fn hull_of_square_with_inner_point() {
        let h = convex_hull(&[[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]]);
        assert_eq!(h.len(), 4);
    }
}
