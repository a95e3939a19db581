#version 450
// ADMM residual reduction (CPU twin: cpu::residuals). Thread i adds slot i's
// ‖Y − A‖² (primal), ‖A − A_prev‖² (dual), ‖A‖², each times its face's penalty factor m_f,
// and face i's w E(A); a shared-memory tree
// reduces each workgroup to one vec4 (primal², dual², ‖A‖², energy) in partials[group];
// the host sums the partials in f64.
// Bindings: 0 A vec4[F], 1 Y vec4[S], 2 A_prev vec4[F], 3 slot_face uint[S], 4 weight float[F],
//           5 partials vec4[#groups] (written), 6 penalty float[F]. Workgroups of 64 (the tree
//           assumes it).
#extension GL_GOOGLE_include_directive : require
// The layout must precede grid.glsl: glslang bakes gl_WorkGroupSize into global_index()
// where it is defined.
layout(local_size_x = 64) in;
#include "grid.glsl"
#include "admm.glsl"

layout(std430, set = 0, binding = 0) readonly buffer Abuf { vec4 A[]; };
layout(std430, set = 0, binding = 1) readonly buffer Ybuf { vec4 Y[]; };
layout(std430, set = 0, binding = 2) readonly buffer Aprev { vec4 A_prev[]; };
layout(std430, set = 0, binding = 3) readonly buffer SlotFace { uint slot_face[]; };
layout(std430, set = 0, binding = 4) readonly buffer Weights { float weight[]; };
layout(std430, set = 0, binding = 5) writeonly buffer Partials { vec4 partials[]; };
layout(std430, set = 0, binding = 6) readonly buffer Penalty { float penalty[]; };

layout(push_constant) uniform Push {
    uint n_slots;
    uint n_faces;
    uint energy;
} pc;

shared vec4 acc[64];

void main() {
    uint i = global_index();
    vec4 r = vec4(0.0);
    if (i < pc.n_slots) {
        uint f = slot_face[i];
        vec4 a = A[f];
        vec4 dy = Y[i] - a;
        vec4 da = a - A_prev[f];
        float m = penalty[f];
        r.x = m * dot(dy, dy);
        r.y = m * dot(da, da);
        r.z = m * dot(a, a);
    }
    if (i < pc.n_faces) {
        r.w = weight[i] * energy_value(pc.energy, A[i]);
    }
    uint l = gl_LocalInvocationIndex;
    acc[l] = r;
    barrier();
    for (uint stride = 32u; stride > 0u; stride >>= 1u) {
        if (l < stride) acc[l] += acc[l + stride];
        barrier();
    }
    // The 2-D grid may round the group count up: groups wholly past the data write nothing,
    // so partials needs ceil(max(n_slots, n_faces) / 64) entries.
    uint group = gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x;
    if (l == 0u && group * 64u < max(pc.n_slots, pc.n_faces)) {
        partials[group] = acc[0];
    }
}
