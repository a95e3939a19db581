#version 450
// Grid coverage probe: hits[i] += 1 for every index i = global_index() < n, so a correct
// 1-D-over-2-D grid leaves exactly one hit per element.
// Bindings: 0 = hits (read-write, uint). Push constant: n. Workgroup: 64.
#extension GL_GOOGLE_include_directive : require

// Before the include: glslang folds gl_WorkGroupSize where global_index() is defined, so an
// include placed above this line silently uses a workgroup size of 1.
layout(local_size_x = 64) in;
#include "grid.glsl"

layout(std430, set = 0, binding = 0) buffer Hits { uint hits[]; };
layout(push_constant) uniform Push { uint n; } pc;

void main() {
    uint i = global_index();
    if (i >= pc.n) return;
    atomicAdd(hits[i], 1u);
}
