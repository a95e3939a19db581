#version 450
// Scatter per-vertex UVs into a host's buffer with an arbitrary layout:
//   dst[first_word + i * stride_words + k] = uv[2 i + k],  k = 0, 1   (as 32-bit floats).
// The host's buffer is bound as a raw array of 32-bit words, so its layout (offset and stride in
// bytes, both multiples of 4) is pure arithmetic here; words between the UVs are not touched.
// Bindings: 0 = uv (read, 2 floats per vertex), 1 = dst (the host's range, write-only).
// Push constants: n (vertices), first_word, stride_words. Workgroup: 64; one thread per vertex.
#extension GL_GOOGLE_include_directive : require

// Before the include (see grid.glsl): global_index() folds gl_WorkGroupSize where defined.
layout(local_size_x = 64) in;
#include "grid.glsl"

layout(std430, set = 0, binding = 0) readonly buffer Src { float uv[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Dst { float words[]; };
layout(push_constant) uniform Push {
    uint n;
    uint first_word;
    uint stride_words;
} pc;

void main() {
    uint i = global_index();
    if (i >= pc.n) return;
    uint w = pc.first_word + i * pc.stride_words;
    words[w] = uv[2u * i];
    words[w + 1u] = uv[2u * i + 1u];
}
