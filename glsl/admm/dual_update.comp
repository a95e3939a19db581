#version 450
// ADMM dual step (CPU twin: kernels::dual_update): Λ_t += μ m_f (Y_t − A_f), f = f(t).
// Bindings: 0 A vec4[F], 1 Y vec4[S], 2 Λ vec4[S] (rw), 3 slot_face uint[S], 4 penalty float[F].
// One thread per slot, workgroups of 64.
#extension GL_GOOGLE_include_directive : require
// The layout must precede grid.glsl: glslang bakes gl_WorkGroupSize into global_index()
// where it is defined.
layout(local_size_x = 64) in;
#include "grid.glsl"

layout(std430, set = 0, binding = 0) readonly buffer Abuf { vec4 A[]; };
layout(std430, set = 0, binding = 1) readonly buffer Ybuf { vec4 Y[]; };
layout(std430, set = 0, binding = 2) buffer Lbuf { vec4 L[]; };
layout(std430, set = 0, binding = 3) readonly buffer SlotFace { uint slot_face[]; };
layout(std430, set = 0, binding = 4) readonly buffer Penalty { float penalty[]; };

layout(push_constant) uniform Push {
    float mu;
    uint n_slots;
    // First element of this dispatch: an iteration may be split into ranges (job slices).
    uint first;
} pc;

void main() {
    uint s = pc.first + global_index();
    if (s >= pc.n_slots) return;
    uint f = slot_face[s];
    L[s] += (pc.mu * penalty[f]) * (Y[s] - A[f]);
}
