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

// Value and gradient; only for det > 0.
// MIPS: ∇E = 2x/D − s∇D/D²;  SD: ∇E = 2x + 2x/D² − 2s∇D/D³.
void energy_grad(uint kind, vec4 a, out float e, out vec4 g) {
    float d = det2(a);
    float s = dot(a, a);
    vec4 gd = grad_det(a);
    float id = 1.0 / d;
    float id2 = id * id;
    if (kind == ENERGY_MIPS) {
        e = s * id;
        g = 2.0 * a * id - s * gd * id2;
    } else {
        e = s + s * id2;
        g = 2.0 * a + 2.0 * a * id2 - 2.0 * s * gd * id2 * id;
    }
}

// (cos, sin) of half the angle of the unit vector (c, s), half angle in (−π/2, π/2]
// (CPU twin: kernels::half_angle). No trigonometric calls.
vec2 half_angle(float c, float s) {
    if (c >= 0.0) {
        float ch = sqrt(0.5 * (1.0 + c));
        return vec2(ch, s / (2.0 * ch));
    }
    float sh = sqrt(0.5 * (1.0 - c));
    float ch = s / (2.0 * sh);
    return ch >= 0.0 ? vec2(ch, sh) : vec2(-ch, -sh);
}

// U X Vᵀ for U = rot(φ), Vᵀ = rot(θ) given as (cos, sin); row-major vec4.
vec4 rotate2(vec2 u, vec4 x, vec2 vt) {
    vec4 ux = vec4(u.x * x.x - u.y * x.z, u.x * x.y - u.y * x.w, u.y * x.x + u.x * x.z, u.y * x.y + u.x * x.w);
    return vec4(ux.x * vt.x + ux.y * vt.y, -ux.x * vt.y + ux.y * vt.x, ux.z * vt.x + ux.w * vt.y,
                -ux.z * vt.y + ux.w * vt.x);
}

// Closed-form Hessian eigensystem (Smith, de Goes & Kim 2019, 2D): A = U diag(σ1, σ2) Vᵀ;
// twist U[0 −1; 1 0]Vᵀ/√2, flip U[0 1; 1 0]Vᵀ/√2, two scaling modes U diag(c)Vᵀ.
// CPU twin: kernels::hessian_eigensystem.
void hessian_eigensystem(uint kind, vec4 a, out vec4 lam, out vec4 modes[4]) {
    float e = 0.5 * (a.x + a.w);
    float f = 0.5 * (a.x - a.w);
    float g = 0.5 * (a.z + a.y);
    float h = 0.5 * (a.z - a.y);
    float q = length(vec2(e, h));
    float r = length(vec2(f, g));
    // Signed SVD without trigonometry (CPU twin: kernels::svd2): a1 = ∠(f, g), a2 = ∠(e, h),
    // φ = (a1 + a2)/2 by a half angle, θ = φ − a1.
    vec2 u1 = r > 0.0 ? vec2(f, g) / r : vec2(1.0, 0.0);
    vec2 u2 = q > 0.0 ? vec2(e, h) / q : vec2(1.0, 0.0);
    vec2 u = half_angle(u1.x * u2.x - u1.y * u2.y, u1.y * u2.x + u1.x * u2.y);
    vec2 vt = vec2(u.x * u1.x + u.y * u1.y, u.y * u1.x - u.x * u1.y);
    float s1 = q + r;
    float s2 = q - r;
    float p12 = s1 * s2;
    float twist, flip, h11, h22, h12;
    if (kind == ENERGY_MIPS) {
        float d = 1.0 / (p12 * p12);
        twist = -(s1 - s2) * (s1 - s2) * d;
        flip = (s1 + s2) * (s1 + s2) * d;
        h11 = 2.0 * s2 / (s1 * s1 * s1);
        h22 = 2.0 * s1 / (s2 * s2 * s2);
        h12 = -(s1 * s1 + s2 * s2) * d;
    } else {
        float p3 = 1.0 / (p12 * p12 * p12);
        twist = 2.0 - 2.0 * (s1 * s1 - p12 + s2 * s2) * p3;
        flip = 2.0 + 2.0 * (s1 * s1 + p12 + s2 * s2) * p3;
        h11 = 2.0 + 6.0 / (s1 * s1 * s1 * s1);
        h22 = 2.0 + 6.0 / (s2 * s2 * s2 * s2);
        h12 = 0.0;
    }
    // Rotation ψ with tan 2ψ = 2 h12 / (h11 − h22), by a half angle.
    vec2 d = vec2(h11 - h22, 2.0 * h12);
    float dn = length(d);
    vec2 cs = dn > 0.0 ? half_angle(d.x / dn, d.y / dn) : vec2(1.0, 0.0);
    float c = cs.x;
    float s = cs.y;
    float l1 = h11 * c * c + 2.0 * h12 * s * c + h22 * s * s;
    float l2 = h11 * s * s - 2.0 * h12 * s * c + h22 * c * c;
    const float R = 0.70710678118654752;
    lam = vec4(twist, flip, l1, l2);
    modes[0] = rotate2(u, vec4(0.0, -R, R, 0.0), vt);
    modes[1] = rotate2(u, vec4(0.0, R, R, 0.0), vt);
    modes[2] = rotate2(u, vec4(c, 0.0, 0.0, s), vt);
    modes[3] = rotate2(u, vec4(-s, 0.0, 0.0, c), vt);
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
