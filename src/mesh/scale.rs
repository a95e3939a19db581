//! Scale normalisation: every solver works on coordinates of order one, whatever the file's
//! units. A mesh scaled by 1e-100 would otherwise have face areas that underflow (a cross
//! product squares lengths twice: 1e-400) and one scaled by 1e100 energies and Hessians that
//! overflow; bounding-box extents near 1e308 are not even representable. The map is computed on
//! the normalised copy and mapped back, so results agree with the unit-scale run up to scaling.

/// `x ↦ x / factor` with `factor` the power of two at or above the largest coordinate
/// magnitude. A power of two makes the scaling exact in floating point: sums, products and
/// quotients of scaled numbers are the scaled results, so a mesh scaled by 2^k gives
/// bit-identical normalised coordinates, and the solvers' results at any scale are those at
/// unit scale, up to the (exact) scale. No translation: a shift would round every coordinate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scale {
    pub factor: f64,
}

impl Default for Scale {
    fn default() -> Self {
        Scale { factor: 1.0 }
    }
}

impl Scale {
    /// The scale of `points` (finite coordinates; 1 for none, or for all zero).
    pub fn fit<'a>(points: impl IntoIterator<Item = &'a [f64; 3]>) -> Scale {
        let m = points
            .into_iter()
            .flatten()
            .map(|c| c.abs())
            .fold(0.0f64, f64::max);
        if !(m.is_finite() && m > 0.0) {
            return Scale::default();
        }
        Scale {
            factor: power_of_two_at_least(m),
        }
    }

    /// The scale of the vertices `mesh`'s faces use (a stray unused vertex does not set it) and
    /// the mesh at that scale: what every entry point (`param`, `approx`, embedding) solves.
    pub fn normalized(mesh: &super::TriMesh) -> (Scale, super::TriMesh) {
        let scale = Scale::fit(
            mesh.faces
                .iter()
                .flatten()
                .map(|&v| &mesh.positions[v as usize]),
        );
        let unit = super::TriMesh {
            positions: mesh.positions.iter().map(|&p| scale.apply(p)).collect(),
            faces: mesh.faces.clone(),
        };
        (scale, unit)
    }

    /// File coordinates → normalised (every coordinate in [−1, 1]; [−2, 2] above 2^1023).
    pub fn apply(&self, p: [f64; 3]) -> [f64; 3] {
        p.map(|c| c / self.factor)
    }

    /// Normalised → file coordinates.
    pub fn invert(&self, q: [f64; 3]) -> [f64; 3] {
        q.map(|c| c * self.factor)
    }

    /// A normalised length in file units (may overflow to ∞ or underflow to 0 for extreme
    /// files: for reports only).
    pub fn length(&self, l: f64) -> f64 {
        l * self.factor
    }
}

/// The smallest power of two ≥ `x` (x > 0, finite), within the normal exponent range.
fn power_of_two_at_least(x: f64) -> f64 {
    let e = x.log2().ceil().clamp(-1022.0, 1023.0) as i64;
    let p = f64::from_bits(((e + 1023) as u64) << 52);
    // log2 may round: make sure x / p ≤ 1.
    if p < x && e < 1023 {
        p * 2.0
    } else {
        p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalises_any_finite_scale_exactly() {
        let unit = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]];
        let s1 = Scale::fit(&unit);
        let n1: Vec<_> = unit.iter().map(|&p| s1.apply(p)).collect();
        for k in [-300, -100, -7, 0, 9, 100, 300] {
            let f = 2f64.powi(k);
            let scaled: Vec<[f64; 3]> = unit.iter().map(|p| p.map(|c| c * f)).collect();
            let s = Scale::fit(&scaled);
            let n: Vec<_> = scaled.iter().map(|&p| s.apply(p)).collect();
            assert_eq!(n, n1, "2^{k}");
            for (p, q) in scaled.iter().zip(&n) {
                assert_eq!(s.invert(*q), *p);
            }
        }
        // Near the top of the range: no overflow, coordinates within [−2, 2].
        let big = [
            [-1e308, 0.0, 0.0],
            [1.7e308, 1e308, 0.0],
            [0.0, -1e308, 1.0],
        ];
        let s = Scale::fit(&big);
        for p in &big {
            let q = s.apply(*p);
            assert!(q.iter().all(|c| c.is_finite() && c.abs() <= 2.0), "{q:?}");
            assert_eq!(s.invert(q), *p);
        }
    }
}
