//! 3-vector arithmetic on `[f64; 3]`: the one copy the crate's geometry uses (starting maps,
//! face frames, cutting, tet maps, the approximation stages). Plain arrays rather than
//! `glam::DVec3` because positions are stored, read and written as `[f64; 3]` everywhere (mesh
//! files, GPU buffers through bytemuck), so formulas over them read without conversions; the
//! operations are written out in the order glam uses, so either gives the same bits.
#![forbid(unsafe_code)]

/// A 3-vector.
pub type V3 = [f64; 3];

#[inline]
pub fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline]
pub fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
pub fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[inline]
pub fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
pub fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
pub fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

/// Unit vector along `a`, or `None` for a (numerically) zero vector.
#[inline]
pub fn normalize(a: V3) -> Option<V3> {
    let l = norm(a);
    (l > 0.0 && l.is_finite()).then(|| scale(a, 1.0 / l))
}
