// Shared ADMM definitions: 2x2 matrices are vec4 (a, b, c, d) = [a b; c d] row-major, matching
// the host's [f64; 4]. Energies: 0 = MIPS tr(AᵀA)/det A, 1 = symmetric Dirichlet ‖A‖² + ‖A⁻¹‖².
// CPU twin: src/param/energy.rs and src/param/admm/kernels.rs. Keep both in step.

const uint NO_SLOT = 0xffffffffu;
const uint ENERGY_MIPS = 0u;
const uint ENERGY_SD = 1u;
// A large finite stand-in for +∞ (a true inf in a GLSL constant is not portable).
const float INF = 3.0e38;

float det2(vec4 a) { return a.x * a.w - a.y * a.z; }

// ∂det/∂A = (d, −c, −b, a).
vec4 grad_det(vec4 a) { return vec4(a.w, -a.z, -a.y, a.x); }

// +∞ when det ≤ 0: any line search that only accepts finite values is flip-proof.
float energy_value(uint kind, vec4 a) {
    float d = det2(a);
    if (!(d > 0.0)) return INF;
    float s = dot(a, a);
    float id = 1.0 / d;
    if (kind == ENERGY_MIPS) return s * id;
    return s + s * id * id;
}

// Value, gradient and Hessian (row-major 4x4 over (a, b, c, d)); only for det > 0.
// MIPS: H = 2I/D − 2(x∇Dᵀ + ∇D xᵀ)/D² − s H_D/D² + 2s ∇D∇Dᵀ/D³.
// SD:   H = 2I(1 + 1/D²) − 4(x∇Dᵀ + ∇D xᵀ)/D³ − 2s H_D/D³ + 6s ∇D∇Dᵀ/D⁴.
// Powers of 1/D instead of D: D⁴ underflows f32 long before 1/D⁴ overflows.
void energy_eval(uint kind, vec4 a, out float e, out vec4 g, out float h[16]) {
    float d = det2(a);
    float s = dot(a, a);
    vec4 gd = grad_det(a);
    float id = 1.0 / d;
    float id2 = id * id;
    float cdiag, cmix, chd, cgg;
    if (kind == ENERGY_MIPS) {
        e = s * id;
        g = 2.0 * a * id - s * gd * id2;
        cdiag = 2.0 * id;
        cmix = 2.0 * id2;
        chd = s * id2;
        cgg = 2.0 * s * id2 * id;
    } else {
        e = s + s * id2;
        g = 2.0 * a + 2.0 * a * id2 - 2.0 * s * gd * id2 * id;
        cdiag = 2.0 + 2.0 * id2;
        cmix = 4.0 * id2 * id;
        chd = 2.0 * s * id2 * id;
        cgg = 6.0 * s * id2 * id2;
    }
    for (int i = 0; i < 4; ++i) {
        for (int j = 0; j < 4; ++j) {
            float hdij = 0.0;
            if ((i == 0 && j == 3) || (i == 3 && j == 0)) hdij = 1.0;
            if ((i == 1 && j == 2) || (i == 2 && j == 1)) hdij = -1.0;
            h[i * 4 + j] = (i == j ? cdiag : 0.0) - cmix * (a[i] * gd[j] + gd[i] * a[j]) - chd * hdij
                + cgg * gd[i] * gd[j];
        }
    }
}

// Smallest positive root of c2 t² + c1 t + c0 (∞ if none), without cancellation.
float smallest_positive_root(float c2, float c1, float c0) {
    float scale = max(abs(c2), max(abs(c1), abs(c0)));
    if (scale == 0.0) return INF;
    if (abs(c2) <= 1e-7 * scale) {
        if (c1 == 0.0) return INF;
        float t = -c0 / c1;
        return t > 0.0 ? t : INF;
    }
    float disc = c1 * c1 - 4.0 * c2 * c0;
    if (disc < 0.0) return INF;
    float sq = sqrt(disc);
    float q = -0.5 * (c1 + (c1 >= 0.0 ? sq : -sq));
    float best = INF;
    float t1 = q / c2;
    if (t1 > 0.0) best = t1;
    if (q != 0.0) {
        float t2 = c0 / q;
        if (t2 > 0.0 && t2 < best) best = t2;
    }
    return best;
}

// Largest t with det(A + τP) > 0 on [0, t).
float max_flip_free_step(vec4 a, vec4 p) {
    return smallest_positive_root(det2(p), dot(grad_det(a), p), det2(a));
}
