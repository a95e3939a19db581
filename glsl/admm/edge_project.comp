#version 450
// ADMM edge step (CPU twin: kernels::edge_project). For interior edge i with slots 2i, 2i+1
// and face penalties μ_k = μ m_fk: Q_k = A_fk − Λ_k/μ_k, r = Q1 e1 − Q2 e2,
// D = μ2‖e1‖² + μ1‖e2‖², Y1 = Q1 − (μ2/D) r e1ᵀ, Y2 = Q2 + (μ1/D) r e2ᵀ (the projection onto
// Y1 e1 = Y2 e2 in the metric of the two penalties; e_k is the edge in face k's own frame over a
// length common to both sides: unit between two faces of a surface, not between a chart face
// and a scaffold face).
// Bindings: 0 A vec4[F], 1 Y vec4[S] (written), 2 Λ vec4[S], 3 slot_face uint[S], 4 slot_dir vec2[S],
//           5 penalty float[F] (m_f).
// One thread per interior edge, workgroups of 64.
#extension GL_GOOGLE_include_directive : require
// The layout must precede grid.glsl: glslang bakes gl_WorkGroupSize into global_index()
// where it is defined.
layout(local_size_x = 64) in;
#include "grid.glsl"

layout(std430, set = 0, binding = 0) readonly buffer Abuf { vec4 A[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Ybuf { vec4 Y[]; };
layout(std430, set = 0, binding = 2) readonly buffer Lbuf { vec4 L[]; };
layout(std430, set = 0, binding = 3) readonly buffer SlotFace { uint slot_face[]; };
layout(std430, set = 0, binding = 4) readonly buffer SlotDir { vec2 slot_dir[]; };
layout(std430, set = 0, binding = 5) readonly buffer Penalty { float penalty[]; };

layout(push_constant) uniform Push {
    float mu;
    uint n_edges;
    // First element of this dispatch: an iteration may be split into ranges (job slices).
    uint first;
} pc;

void main() {
    uint i = pc.first + global_index();
    if (i >= pc.n_edges) return;
    uint s1 = 2u * i;
    uint s2 = s1 + 1u;
    uint f1 = slot_face[s1];
    uint f2 = slot_face[s2];
    float mu1 = pc.mu * penalty[f1];
    float mu2 = pc.mu * penalty[f2];
    vec4 q1 = A[f1] - L[s1] / mu1;
    vec4 q2 = A[f2] - L[s2] / mu2;
    vec2 e1 = slot_dir[s1];
    vec2 e2 = slot_dir[s2];
    vec2 r = vec2(q1.x * e1.x + q1.y * e1.y - q2.x * e2.x - q2.y * e2.y,
                  q1.z * e1.x + q1.w * e1.y - q2.z * e2.x - q2.w * e2.y);
    float den = mu2 * dot(e1, e1) + mu1 * dot(e2, e2);
    float t1 = mu2 / den;
    float t2 = mu1 / den;
    Y[s1] = q1 - t1 * vec4(r.x * e1.x, r.x * e1.y, r.y * e1.x, r.y * e1.y);
    Y[s2] = q2 + t2 * vec4(r.x * e2.x, r.x * e2.y, r.y * e2.x, r.y * e2.y);
}
