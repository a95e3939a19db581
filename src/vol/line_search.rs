//! The largest step that inverts no tet: along x + t·p every tet's det is a cubic in t, and
//! the step must stay below its smallest positive root. Newton steps are at most 1, so only
//! roots in (0, [`HORIZON`]] matter; they are bracketed between the cubic's critical points
//! and bisected, which is exact in sign (the returned bound has det > 0 as evaluated), unlike
//! closed-form cubic roots that lose digits on nearly-degenerate tets.

use rayon::prelude::*;

use super::tet::{cross, dot, sub};

/// Roots beyond this are irrelevant (the caller never steps further).
pub const HORIZON: f64 = 2.0;

/// Coefficients c0..c3 of det[E + tP] with E, P given by their three edge columns.
pub fn det_cubic(e: [[f64; 3]; 3], p: [[f64; 3]; 3]) -> [f64; 4] {
    let [e1, e2, e3] = e;
    let [p1, p2, p3] = p;
    let c0 = dot(e1, cross(e2, e3));
    let c1 = dot(p1, cross(e2, e3)) + dot(e1, cross(p2, e3)) + dot(e1, cross(e2, p3));
    let c2 = dot(e1, cross(p2, p3)) + dot(p1, cross(e2, p3)) + dot(p1, cross(p2, e3));
    let c3 = dot(p1, cross(p2, p3));
    [c0, c1, c2, c3]
}

#[inline]
fn eval(c: &[f64; 4], t: f64) -> f64 {
    ((c[3] * t + c[2]) * t + c[1]) * t + c[0]
}

/// Smallest t in (0, HORIZON] with c(t) ≤ 0, given c(0) > 0 (∞ when none); the returned
/// value is the lower end of a bisected bracket, so c is still positive there.
pub fn first_nonpositive(c: &[f64; 4]) -> f64 {
    if !super::tet::is_positive(c[0]) {
        return 0.0;
    }
    // Critical points: 3c3 t² + 2c2 t + c1 = 0, kept in (0, HORIZON).
    let mut breaks = vec![0.0];
    let (a, b, cc) = (3.0 * c[3], 2.0 * c[2], c[1]);
    let mut crit = Vec::new();
    if a != 0.0 {
        let disc = b * b - 4.0 * a * cc;
        if disc >= 0.0 {
            let sq = disc.sqrt();
            let q = -0.5 * (b + if b >= 0.0 { sq } else { -sq });
            if q != 0.0 {
                crit.push(q / a);
                crit.push(cc / q);
            } else {
                crit.push(0.0);
            }
        }
    } else if b != 0.0 {
        crit.push(-cc / b);
    }
    crit.retain(|&t| t > 0.0 && t < HORIZON);
    crit.sort_by(|x, y| x.total_cmp(y));
    breaks.extend(crit);
    breaks.push(HORIZON);
    for w in breaks.windows(2) {
        let (mut lo, mut hi) = (w[0], w[1]);
        if eval(c, hi) > 0.0 {
            continue;
        }
        if !super::tet::is_positive(eval(c, lo)) {
            return lo;
        }
        // c(lo) > 0 ≥ c(hi), monotone in between: bisect.
        for _ in 0..100 {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if eval(c, mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        return lo;
    }
    f64::INFINITY
}

/// Largest flip-free step over all tets for positions `x` and direction `p` (∞ when no tet
/// reaches zero volume before [`HORIZON`]).
pub fn max_flip_free_step(tets: &[[u32; 4]], x: &[[f64; 3]], p: &[[f64; 3]]) -> f64 {
    tets.par_iter()
        .map(|t| {
            let [a, b, c, d] = t.map(|i| i as usize);
            let e = [sub(x[b], x[a]), sub(x[c], x[a]), sub(x[d], x[a])];
            let q = [sub(p[b], p[a]), sub(p[c], p[a]), sub(p[d], p[a])];
            first_nonpositive(&det_cubic(e, q))
        })
        .reduce(|| f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_matches_determinant_and_root_is_first() {
        let e = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let p = [[-1.5, 0.2, 0.1], [0.3, -0.4, 0.0], [0.0, 0.1, 0.2]];
        let c = det_cubic(e, p);
        for t in [0.0, 0.3, 0.9, 1.7] {
            let m = |k: usize| {
                [
                    e[k][0] + t * p[k][0],
                    e[k][1] + t * p[k][1],
                    e[k][2] + t * p[k][2],
                ]
            };
            let d = dot(m(0), cross(m(1), m(2)));
            assert!((d - eval(&c, t)).abs() < 1e-12);
        }
        let r = first_nonpositive(&c);
        assert!(r > 0.0 && r < HORIZON);
        assert!(eval(&c, r) > 0.0 && eval(&c, r * (1.0 + 1e-9)) <= 1e-12);
        for k in 1..100 {
            assert!(eval(&c, r * k as f64 / 100.0) > 0.0);
        }
        // A step that only grows the tet has no root.
        assert_eq!(first_nonpositive(&det_cubic(e, e)), f64::INFINITY);
    }
}
