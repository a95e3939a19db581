//! Per-face isometric 2D frames: each triangle laid flat in its own plane, so distortion
//! energies compare a map's 2D triangle with an undistorted 2D reference.
//!
//! The Jacobian `A_f` (2×2) of a piecewise-linear map on face `f` maps local coordinates to UV:
//! `A_f (local_k − local_0) = uv_k − uv_0` for k = 1, 2, i.e.
//! `A_f = [uv_1 − uv_0 | uv_2 − uv_0] · [local_1 − local_0 | local_2 − local_0]⁻¹`.
//! Because `local[f][2][1] > 0`, `det A_f > 0` exactly when the UV triangle keeps the
//! orientation of the 3D face (no foldover).

use super::TriMesh;

/// Local frames of every face.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FaceFrames {
    /// (#F×3×2) corner coordinates in the face's frame: `[(0,0), (|p1−p0|, 0), (x2, y2)]`
    /// with `y2 > 0` for every non-degenerate face.
    pub local: Vec<[[f64; 2]; 3]>,
    /// (#F×2×3) orthonormal frame axes `[ex, ey]` in 3D: `ex` along p1−p0, `ey` in the face plane
    /// towards p2.
    pub axes: Vec<[[f64; 3]; 2]>,
    /// (#F) triangle area ½|(p1−p0)×(p2−p0)|.
    pub area: Vec<f64>,
}

use crate::linalg::vec3::{cross, dot, scale, sub};

/// Computes the frames. A degenerate face (zero area, zero first edge, non-finite or
/// out-of-range corner) gets an all-zero frame instead of NaNs; validation rejects such faces
/// before any solver sees them.
pub fn compute(mesh: &TriMesh) -> FaceFrames {
    let nf = mesh.faces.len();
    let mut frames = FaceFrames {
        local: Vec::with_capacity(nf),
        axes: Vec::with_capacity(nf),
        area: Vec::with_capacity(nf),
    };
    for f in &mesh.faces {
        let corner = |k: usize| mesh.positions.get(f[k] as usize).copied();
        let (Some(p0), Some(p1), Some(p2)) = (corner(0), corner(1), corner(2)) else {
            // Out-of-range index: validation reports it; here only avoid a panic.
            frames.area.push(0.0);
            frames.local.push([[0.0; 2]; 3]);
            frames.axes.push([[0.0; 3]; 2]);
            continue;
        };
        let e1 = sub(p1, p0);
        let e2 = sub(p2, p0);
        let n = cross(e1, e2);
        let l1 = dot(e1, e1).sqrt();
        let twice_area = dot(n, n).sqrt();
        frames.area.push(0.5 * twice_area);
        if !(l1 > 0.0 && twice_area > 0.0 && l1.is_finite() && twice_area.is_finite()) {
            frames.local.push([[0.0; 2]; 3]);
            frames.axes.push([[0.0; 3]; 2]);
            continue;
        }
        let ex = scale(e1, 1.0 / l1);
        // ey = n̂ × ex is exactly orthogonal to ex and in the plane, and |n × e1| = |n|·|e1|.
        let ey = scale(cross(n, e1), 1.0 / (twice_area * l1));
        // y2 = height of p2 over the first edge = 2·area / |e1| (positive by construction).
        let local = [[0.0, 0.0], [l1, 0.0], [dot(e2, ex), twice_area / l1]];
        frames.local.push(local);
        frames.axes.push([ex, ey]);
    }
    frames
}

impl FaceFrames {
    /// Expresses a 3D vector in face `f`'s frame (its component along the normal is dropped).
    pub fn to_local(&self, f: usize, v3: [f64; 3]) -> [f64; 2] {
        let [ex, ey] = self.axes[f];
        [dot(v3, ex), dot(v3, ey)]
    }

    /// Number of faces.
    pub fn len(&self) -> usize {
        self.area.len()
    }

    /// No faces.
    pub fn is_empty(&self) -> bool {
        self.area.is_empty()
    }
}
