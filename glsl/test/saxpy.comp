#version 450
// Round-trip test kernel: y[i] = a * x[i] + y[i].
// Bindings: 0 = x (read), 1 = y (read-write). Push constant: a, n. Workgroup: 64.
#extension GL_GOOGLE_include_directive : require

// Before the include: glslang folds gl_WorkGroupSize where global_index() is defined, so an
// include placed above this line silently uses a workgroup size of 1.
layout(local_size_x = 64) in;
#include "grid.glsl"

layout(std430, set = 0, binding = 0) readonly buffer X { float x[]; };
layout(std430, set = 0, binding = 1) buffer Y { float y[]; };
layout(push_constant) uniform Push { float a; uint n; } pc;

void main() {
    uint i = global_index();
    if (i >= pc.n) return;
    y[i] = pc.a * x[i] + y[i];
}
