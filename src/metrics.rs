//! Distortion and validity measures of a UV map, in f64.
//!
//! Conventions (shared with ../shared/peers.md, so our numbers sit in the same table as the
//! tools we compare against): per face, J is the Jacobian of the affine map from the 3D
//! triangle (laid isometrically in its plane) to its UV triangle, σ1 ≥ |σ2| its singular
//! values with σ2 < 0 when the face is flipped.
//! - flips: faces with signed UV area ≤ 0;
//! - conformal distortion δcon = σ1/σ2, averaged over faces *unweighted* (the seed paper's
//!   table), also area-weighted and its maximum;
//! - MIPS energy σ1/σ2 + σ2/σ1, area-weighted mean;
//! - symmetric Dirichlet σ1² + σ1⁻² + σ2² + σ2⁻², area-weighted mean after scaling the UV so
//!   its total area equals the 3D area (so the score is scale-invariant: 4 for an isometry up
//!   to scale).
//!
//! A flipped or degenerate face has no finite distortion in our convention: its δ and
//! energies are +∞ and so are the means (a foldover-free claim must not be averaged away).
//! The tools in peers.md are scored with *unsigned* singular values (|σ2|), which keeps a
//! flipped face finite; [`Metrics::unsigned`] repeats those scores that way so a folded map
//! (LSCM) can still be compared with their table.
#![forbid(unsafe_code)]

use serde::Serialize;

use crate::linalg::small::{svd2_signed_values, Mat2};
use crate::linalg::vec3::{cross, dot, norm, sub};

/// Distortion of one face.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct FaceDistortion {
    /// Largest singular value σ1 of J (+∞ for a zero-area 3D triangle).
    pub sigma_max: f64,
    /// Signed smallest singular value σ2: |σ2| ≤ σ1, negative when the face is flipped.
    pub sigma_min: f64,
    /// Area of the 3D triangle.
    pub area_3d: f64,
    /// Signed area of the UV triangle (≤ 0: flipped).
    pub uv_area: f64,
}

impl FaceDistortion {
    /// A face with a positive 3D area and a positive signed UV area.
    pub fn is_valid(&self) -> bool {
        self.area_3d > 0.0
            && self.uv_area > 0.0
            && self.sigma_min > 0.0
            && self.sigma_max.is_finite()
    }

    /// δcon = σ1/σ2, +∞ when flipped or degenerate.
    pub fn delta_con(&self) -> f64 {
        if self.is_valid() {
            self.sigma_max / self.sigma_min
        } else {
            f64::INFINITY
        }
    }

    /// MIPS σ1/σ2 + σ2/σ1, +∞ when flipped or degenerate.
    pub fn mips(&self) -> f64 {
        if self.is_valid() {
            self.sigma_max / self.sigma_min + self.sigma_min / self.sigma_max
        } else {
            f64::INFINITY
        }
    }

    /// Symmetric Dirichlet σ1² + σ1⁻² + σ2² + σ2⁻² of the map scaled by `scale`, +∞ when
    /// flipped or degenerate.
    pub fn symmetric_dirichlet(&self, scale: f64) -> f64 {
        if self.is_valid() {
            sd(scale * self.sigma_max, scale * self.sigma_min)
        } else {
            f64::INFINITY
        }
    }
}

/// σ1² + σ1⁻² + σ2² + σ2⁻²
#[inline]
fn sd(s1: f64, s2: f64) -> f64 {
    s1 * s1 + 1.0 / (s1 * s1) + s2 * s2 + 1.0 / (s2 * s2)
}

/// Jacobian of the affine map from the 3D triangle `p` to the UV triangle `uv`, and the 3D
/// area. The triangle is laid in its plane with p0 at the origin and x along p1 − p0:
/// J = [uv1 − uv0, uv2 − uv0]·[x1 − x0, x2 − x0]⁻¹. `None` for a zero-area 3D triangle.
pub fn face_jacobian(p: [[f64; 3]; 3], uv: [[f64; 2]; 3]) -> Option<(Mat2, f64)> {
    let (e1, e2) = (sub(p[1], p[0]), sub(p[2], p[0]));
    let l1 = norm(e1);
    let n_len = norm(cross(e1, e2));
    if l1 <= 0.0 || n_len <= 0.0 || !n_len.is_finite() {
        return None;
    }
    // Frame coordinates: x1 = (|e1|, 0), x2 = (e2·e1/|e1|, |e1×e2|/|e1|).
    let x2x = dot(e1, e2) / l1;
    let x2y = n_len / l1;
    let (du1, dv1) = (uv[1][0] - uv[0][0], uv[1][1] - uv[0][1]);
    let (du2, dv2) = (uv[2][0] - uv[0][0], uv[2][1] - uv[0][1]);
    // X⁻¹ = [[1/l1, −x2x/(l1·x2y)], [0, 1/x2y]]
    let (i00, i01, i11) = (1.0 / l1, -x2x / (l1 * x2y), 1.0 / x2y);
    let j = [
        [du1 * i00, du1 * i01 + du2 * i11],
        [dv1 * i00, dv1 * i01 + dv2 * i11],
    ];
    j.iter()
        .flatten()
        .all(|x| x.is_finite())
        .then_some((j, 0.5 * n_len))
}

/// Distortion of the face with 3D corners `p` and UV corners `uv`.
pub fn face_distortion(p: [[f64; 3]; 3], uv: [[f64; 2]; 3]) -> FaceDistortion {
    let uv_area = 0.5
        * ((uv[1][0] - uv[0][0]) * (uv[2][1] - uv[0][1])
            - (uv[2][0] - uv[0][0]) * (uv[1][1] - uv[0][1]));
    match face_jacobian(p, uv) {
        Some((j, area_3d)) => {
            let [s1, s2] = svd2_signed_values(&j);
            FaceDistortion {
                sigma_max: s1,
                sigma_min: s2,
                area_3d,
                uv_area,
            }
        }
        None => FaceDistortion {
            sigma_max: f64::INFINITY,
            sigma_min: 0.0,
            area_3d: 0.0,
            uv_area,
        },
    }
}

/// Per-face distortion of a map (#F entries).
pub fn face_distortions(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    uv: &[[f64; 2]],
) -> Vec<FaceDistortion> {
    faces
        .iter()
        .map(|f| {
            let [a, b, c] = [f[0] as usize, f[1] as usize, f[2] as usize];
            face_distortion(
                [positions[a], positions[b], positions[c]],
                [uv[a], uv[b], uv[c]],
            )
        })
        .collect()
}

/// Per-face signed singular values `[σ1, σ2]` of the 3D → UV Jacobian (σ2 < 0 when flipped;
/// `[+∞, 0]` for a zero-area 3D triangle).
pub fn face_singular_values(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    uv: &[[f64; 2]],
) -> Vec<[f64; 2]> {
    face_distortions(positions, faces, uv)
        .iter()
        .map(|d| [d.sigma_max, d.sigma_min])
        .collect()
}

/// The scores of [`Metrics`] computed with unsigned singular values σ1 ≥ |σ2|, as the tools
/// in ../shared/peers.md are scored: a flipped face with non-zero area stays finite.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct UnsignedScores {
    pub delta_con_mean: f64,
    pub delta_con_max: f64,
    /// Area-weighted SD after scaling the UV so Σ|UV area| equals the 3D area.
    pub sd_energy: f64,
}

/// Summary of a map's validity and distortion (see the module docs for the conventions).
/// Means are +∞ as soon as one face is flipped or degenerate, and NaN when there are no faces.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Metrics {
    pub faces: usize,
    /// Faces with signed UV area ≤ 0.
    pub flips: usize,
    /// Faces whose 3D triangle has zero area (no Jacobian).
    pub degenerate_3d: usize,
    /// Mean of σ1/σ2 over faces, unweighted.
    pub delta_con_mean: f64,
    /// Mean of σ1/σ2 weighted by 3D area.
    pub delta_con_area_mean: f64,
    pub delta_con_max: f64,
    /// Area-weighted mean of σ1/σ2 + σ2/σ1 (2 for a conformal map).
    pub mips_energy: f64,
    /// Area-weighted mean of σ1² + σ1⁻² + σ2² + σ2⁻² after scaling total UV area to the 3D
    /// area (4 for an isometry up to scale).
    pub sd_energy: f64,
    /// Total signed UV area.
    pub uv_area: f64,
    /// Total 3D area.
    pub area_3d: f64,
    /// Pairs of non-adjacent boundary segments (over all loops) that intersect in UV.
    pub boundary_self_intersections: usize,
    /// The same scores with unsigned singular values (peers' convention).
    pub unsigned: UnsignedScores,
}

/// Evaluates a map: `positions` #V×3, `faces` #F×3, `uv` #V×2, `boundary_loops` the boundary
/// cycles of the mesh (for the self-intersection count; may be empty).
pub fn evaluate(
    positions: &[[f64; 3]],
    faces: &[[u32; 3]],
    uv: &[[f64; 2]],
    boundary_loops: &[Vec<u32>],
) -> Metrics {
    let d = face_distortions(positions, faces, uv);
    let nf = d.len();
    let flips = d
        .iter()
        .filter(|f| f.uv_area.is_nan() || f.uv_area <= 0.0)
        .count();
    let degenerate_3d = d
        .iter()
        .filter(|f| f.area_3d.is_nan() || f.area_3d <= 0.0)
        .count();
    let area_3d: f64 = d.iter().map(|f| f.area_3d).sum();
    let uv_area: f64 = d.iter().map(|f| f.uv_area).sum();
    let all_valid = d.iter().all(FaceDistortion::is_valid);
    let nan_if_empty = |x: f64| if nf == 0 { f64::NAN } else { x };

    let (delta_con_mean, delta_con_area_mean, delta_con_max, mips_energy, sd_energy) = if all_valid
    {
        // Scale s with s²·(UV area) = 3D area; σ scales linearly with the UV.
        let s = if uv_area > 0.0 {
            (area_3d / uv_area).sqrt()
        } else {
            f64::INFINITY
        };
        let wsum = |g: &dyn Fn(&FaceDistortion) -> f64| {
            d.iter().map(|f| f.area_3d * g(f)).sum::<f64>() / area_3d
        };
        (
            d.iter().map(FaceDistortion::delta_con).sum::<f64>() / nf as f64,
            wsum(&FaceDistortion::delta_con),
            d.iter()
                .map(FaceDistortion::delta_con)
                .fold(f64::NEG_INFINITY, f64::max),
            wsum(&FaceDistortion::mips),
            wsum(&|f| f.symmetric_dirichlet(s)),
        )
    } else {
        (
            f64::INFINITY,
            f64::INFINITY,
            f64::INFINITY,
            f64::INFINITY,
            f64::INFINITY,
        )
    };

    // Peers' convention: |σ2|; only a zero singular value or a degenerate 3D face is infinite.
    let unsigned = {
        let abs_uv_area: f64 = d.iter().map(|f| f.uv_area.abs()).sum();
        let s = (area_3d / abs_uv_area).sqrt();
        let delta = |f: &FaceDistortion| {
            if f.area_3d > 0.0 && f.sigma_min != 0.0 {
                f.sigma_max / f.sigma_min.abs()
            } else {
                f64::INFINITY
            }
        };
        let sd_u = |f: &FaceDistortion| {
            if f.area_3d > 0.0 && f.sigma_min != 0.0 && s.is_finite() {
                sd(s * f.sigma_max, s * f.sigma_min.abs())
            } else {
                f64::INFINITY
            }
        };
        let sd_energy = if degenerate_3d == 0 {
            d.iter().map(|f| f.area_3d * sd_u(f)).sum::<f64>() / area_3d
        } else {
            f64::INFINITY
        };
        UnsignedScores {
            delta_con_mean: nan_if_empty(d.iter().map(delta).sum::<f64>() / nf as f64),
            delta_con_max: nan_if_empty(d.iter().map(delta).fold(f64::NEG_INFINITY, f64::max)),
            sd_energy: nan_if_empty(sd_energy),
        }
    };

    Metrics {
        faces: nf,
        flips,
        degenerate_3d,
        delta_con_mean: nan_if_empty(delta_con_mean),
        delta_con_area_mean: nan_if_empty(delta_con_area_mean),
        delta_con_max: nan_if_empty(delta_con_max),
        mips_energy: nan_if_empty(mips_energy),
        sd_energy: nan_if_empty(sd_energy),
        uv_area,
        area_3d,
        boundary_self_intersections: boundary_self_intersections(uv, boundary_loops),
        unsigned,
    }
}

/// Orientation of (a, b, c): (b − a) × (c − a), > 0 counter-clockwise.
#[inline]
fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])
}

/// Whether `c`, known to be collinear with segment ab, lies within its bounding box.
#[inline]
fn within(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> bool {
    a[0].min(b[0]) <= c[0]
        && c[0] <= a[0].max(b[0])
        && a[1].min(b[1]) <= c[1]
        && c[1] <= a[1].max(b[1])
}

/// Whether the closed segments p1p2 and p3p4 share a point (touching counts).
pub fn segments_intersect(p1: [f64; 2], p2: [f64; 2], p3: [f64; 2], p4: [f64; 2]) -> bool {
    let d1 = orient(p3, p4, p1);
    let d2 = orient(p3, p4, p2);
    let d3 = orient(p1, p2, p3);
    let d4 = orient(p1, p2, p4);
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && within(p3, p4, p1))
        || (d2 == 0.0 && within(p3, p4, p2))
        || (d3 == 0.0 && within(p1, p2, p3))
        || (d4 == 0.0 && within(p1, p2, p4))
}

/// Number of pairs of boundary segments (over all loops) that intersect in UV while sharing
/// no vertex. 0 for a map whose boundary is a set of simple, disjoint curves.
///
/// Uniform grid with about one segment per cell: each segment is entered in the cells its
/// bounding box covers, and a pair is tested only in the cell holding the lower-left corner
/// of the overlap of their boxes, so it is counted once. Expected O(n) for a boundary whose
/// segments have similar lengths.
pub fn boundary_self_intersections(uv: &[[f64; 2]], loops: &[Vec<u32>]) -> usize {
    let mut count = 0;
    visit_boundary_intersections(uv, loops, &mut |_, _| count += 1);
    count
}

/// The intersecting pairs [`boundary_self_intersections`] counts, as (segment, segment) with
/// segments given by their end vertices in loop order — where to cut a chart whose boundary
/// overlaps itself.
pub fn boundary_intersecting_pairs(uv: &[[f64; 2]], loops: &[Vec<u32>]) -> Vec<[[u32; 2]; 2]> {
    let mut pairs = Vec::new();
    visit_boundary_intersections(uv, loops, &mut |a, b| pairs.push([a, b]));
    pairs
}

fn visit_boundary_intersections(
    uv: &[[f64; 2]],
    loops: &[Vec<u32>],
    visit: &mut dyn FnMut([u32; 2], [u32; 2]),
) {
    let mut segs: Vec<[u32; 2]> = Vec::new();
    for l in loops {
        if l.len() < 2 {
            continue;
        }
        for k in 0..l.len() {
            let (a, b) = (l[k], l[(k + 1) % l.len()]);
            if a != b && (a as usize) < uv.len() && (b as usize) < uv.len() {
                segs.push([a, b]);
            }
        }
    }
    visit_segment_intersections(uv, &segs, visit);
}

/// Number of pairs of the segments `segs` (vertex pairs into `uv`) that intersect while
/// sharing no vertex: [`boundary_self_intersections`] for boundary edges given directly (the
/// global solver's bijectivity check after every step).
pub fn segment_intersections(uv: &[[f64; 2]], segs: &[[u32; 2]]) -> usize {
    let mut count = 0;
    visit_segment_intersections(uv, segs, &mut |_, _| count += 1);
    count
}

fn visit_segment_intersections(
    uv: &[[f64; 2]],
    segs: &[[u32; 2]],
    visit: &mut dyn FnMut([u32; 2], [u32; 2]),
) {
    let n = segs.len();
    if n < 2 {
        return;
    }
    let bbox: Vec<[f64; 4]> = segs
        .iter()
        .map(|s| {
            let (a, b) = (uv[s[0] as usize], uv[s[1] as usize]);
            [
                a[0].min(b[0]),
                a[1].min(b[1]),
                a[0].max(b[0]),
                a[1].max(b[1]),
            ]
        })
        .collect();
    if bbox.iter().flatten().any(|x| !x.is_finite()) {
        // Non-finite UVs: no meaningful geometry; fall back to the plain pair test.
        visit_pairs(
            uv,
            segs,
            &bbox,
            (0..n).collect::<Vec<_>>().as_slice(),
            None,
            visit,
        );
        return;
    }
    let lo = [
        bbox.iter().map(|b| b[0]).fold(f64::INFINITY, f64::min),
        bbox.iter().map(|b| b[1]).fold(f64::INFINITY, f64::min),
    ];
    let hi = [
        bbox.iter().map(|b| b[2]).fold(f64::NEG_INFINITY, f64::max),
        bbox.iter().map(|b| b[3]).fold(f64::NEG_INFINITY, f64::max),
    ];
    let g = ((n as f64).sqrt().ceil() as usize).clamp(1, 2048);
    let cell_of = |x: f64, axis: usize| -> usize {
        let ext = hi[axis] - lo[axis];
        if ext <= 0.0 {
            return 0;
        }
        (((x - lo[axis]) / ext * g as f64) as usize).min(g - 1)
    };
    let range = |b: &[f64; 4]| {
        (
            cell_of(b[0], 0),
            cell_of(b[2], 0),
            cell_of(b[1], 1),
            cell_of(b[3], 1),
        )
    };
    // Cell → segments, CSR: count → prefix sum → fill.
    let mut start = vec![0usize; g * g + 1];
    for b in &bbox {
        let (x0, x1, y0, y1) = range(b);
        for y in y0..=y1 {
            for x in x0..=x1 {
                start[y * g + x + 1] += 1;
            }
        }
    }
    for c in 0..g * g {
        start[c + 1] += start[c];
    }
    let mut fill = start.clone();
    let mut cell_segs = vec![0usize; start[g * g]];
    for (s, b) in bbox.iter().enumerate() {
        let (x0, x1, y0, y1) = range(b);
        for y in y0..=y1 {
            for x in x0..=x1 {
                cell_segs[fill[y * g + x]] = s;
                fill[y * g + x] += 1;
            }
        }
    }
    for c in 0..g * g {
        let here = &cell_segs[start[c]..start[c + 1]];
        visit_pairs(
            uv,
            segs,
            &bbox,
            here,
            Some(&|x: f64, y: f64| cell_of(y, 1) * g + cell_of(x, 0) == c),
            visit,
        );
    }
}

/// Visits the intersecting non-adjacent pairs among `ids`; `owner(x, y)` (if given) says
/// whether this cell owns the pair whose box overlap starts at (x, y).
fn visit_pairs(
    uv: &[[f64; 2]],
    segs: &[[u32; 2]],
    bbox: &[[f64; 4]],
    ids: &[usize],
    owner: Option<&dyn Fn(f64, f64) -> bool>,
    visit: &mut dyn FnMut([u32; 2], [u32; 2]),
) {
    for (k, &i) in ids.iter().enumerate() {
        for &j in &ids[k + 1..] {
            let (si, sj) = (segs[i], segs[j]);
            if si[0] == sj[0] || si[0] == sj[1] || si[1] == sj[0] || si[1] == sj[1] {
                continue; // adjacent segments share a vertex and always touch
            }
            let (bi, bj) = (bbox[i], bbox[j]);
            if bi[0] > bj[2] || bj[0] > bi[2] || bi[1] > bj[3] || bj[1] > bi[3] {
                continue;
            }
            if let Some(own) = owner {
                if !own(bi[0].max(bj[0]), bi[1].max(bj[1])) {
                    continue;
                }
            }
            if segments_intersect(
                uv[si[0] as usize],
                uv[si[1] as usize],
                uv[sj[0] as usize],
                uv[sj[1] as usize],
            ) {
                visit(si, sj);
            }
        }
    }
}
