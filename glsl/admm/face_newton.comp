#version 450
// ADMM face step (CPU twin: kernels::face_newton in src/param/admm/kernels.rs).
// A_f ← argmin w_f E(A) + (nμ_f/2)‖A − B̄‖², B̄ = mean over the face's n slots of Y_t + Λ_t/μ_f,
// μ_f = μ m_f the face's penalty,
// by projected Newton: H⁺ = H with negative eigenvalues clamped to 0 (analytic eigensystem),
// p = −(w H⁺ + nμ I)⁻¹ ∇F, step min(1, 0.9 · largest flip-free step), Armijo backtracking.
// Bindings: 0 A vec4[F] (rw), 1 Y vec4[S], 2 Λ vec4[S], 3 face_slots uvec4[F] (xyz; NO_SLOT pad),
//           4 weight float[F], 5 A_prev vec4[F] (written when save_prev != 0), 6 penalty float[F].
// One thread per face, workgroups of 64, 2-D grid (see grid.glsl).
#extension GL_GOOGLE_include_directive : require
// The layout must precede grid.glsl: glslang bakes gl_WorkGroupSize into global_index()
// where it is defined.
layout(local_size_x = 64) in;
#include "grid.glsl"
#include "admm.glsl"

layout(std430, set = 0, binding = 0) buffer Abuf { vec4 A[]; };
layout(std430, set = 0, binding = 1) readonly buffer Ybuf { vec4 Y[]; };
layout(std430, set = 0, binding = 2) readonly buffer Lbuf { vec4 L[]; };
layout(std430, set = 0, binding = 3) readonly buffer Slots { uvec4 face_slots[]; };
layout(std430, set = 0, binding = 4) readonly buffer Weights { float weight[]; };
layout(std430, set = 0, binding = 5) writeonly buffer Aprev { vec4 A_prev[]; };
layout(std430, set = 0, binding = 6) readonly buffer Penalty { float penalty[]; };

layout(push_constant) uniform Push {
    float mu;
    uint n_faces;
    uint energy;
    uint newton_iters;
    uint save_prev;
    // First element of this dispatch: an iteration may be split into ranges (job slices).
    uint first;
} pc;

const int MAX_HALVINGS = 24;
const float ARMIJO = 1e-4;
const float FLIP_FREE_FRACTION = 0.9;

float face_objective(uint kind, vec4 a, vec4 bbar, float nmu, float w) {
    float e = energy_value(kind, a);
    if (e >= INF) return INF;
    vec4 d = a - bbar;
    return w * e + 0.5 * nmu * dot(d, d);
}

void main() {
    uint f = pc.first + global_index();
    if (f >= pc.n_faces) return;
    vec4 a = A[f];
    if (pc.save_prev != 0u) A_prev[f] = a;

    uvec4 sl = face_slots[f];
    float mu_f = pc.mu * penalty[f];
    vec4 bbar = vec4(0.0);
    uint n = 0u;
    for (int k = 0; k < 3; ++k) {
        uint s = sl[k];
        if (s != NO_SLOT) {
            bbar += Y[s] + L[s] / mu_f;
            n += 1u;
        }
    }
    float w = weight[f];
    float nmu = float(n) * mu_f;
    if (n > 0u) {
        bbar /= float(n);
    } else {
        // No interior edge: only the face's own energy, kept definite by a proximal term (the
        // CPU twin explains the 1e-3).
        nmu = 1e-3 * w;
        bbar = a;
    }

    for (uint it = 0u; it < pc.newton_iters; ++it) {
        // Isolated face: proximal centre at the current iterate (damping, not a pull back).
        if (n == 0u) bbar = a;
        float e;
        vec4 g;
        energy_grad(pc.energy, a, e, g);
        if (!(e < INF)) break;
        vec4 pull = nmu * (a - bbar);
        vec4 grad = w * g + pull;
        vec4 lam;
        vec4 modes[4];
        hessian_eigensystem(pc.energy, a, lam, modes);
        vec4 p = vec4(0.0);
        for (int k = 0; k < 4; ++k) {
            // Twist and flip (modes 0, 1) are orthogonal to the energy gradient (rotation
            // invariance): their components come from the penalty pull only, so f32 noise
            // along a clamped twist is not divided by a tiny nμ (kernels::projected_newton_direction).
            vec4 gk = k < 2 ? pull : grad;
            p += (-dot(modes[k], gk) / (w * max(lam[k], 0.0) + nmu)) * modes[k];
        }
        float slope = dot(grad, p);
        if (!(slope < 0.0)) break;
        vec4 d0 = a - bbar;
        float f0 = w * e + 0.5 * nmu * dot(d0, d0);
        float t = min(1.0, FLIP_FREE_FRACTION * max_flip_free_step(a, p));
        bool accepted = false;
        for (int k = 0; k < MAX_HALVINGS; ++k) {
            vec4 cand = a + t * p;
            float f1 = face_objective(pc.energy, cand, bbar, nmu, w);
            if (f1 <= f0 + ARMIJO * t * slope) {
                a = cand;
                accepted = true;
                break;
            }
            t *= 0.5;
        }
        if (!accepted) break;
    }
    A[f] = a;
}
