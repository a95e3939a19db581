#version 450
// Gather a host's mesh data out of its own buffer layout into a packed array:
//   dst[i * width + k] = src[first_word + i * stride_words + k],  k < width,  i < n
// as raw 32-bit words (f32 positions or u32 indices alike; no conversion, so the copy is exact).
// The host's buffer is bound as a raw word array, so its layout (offset and stride in bytes,
// multiples of 4) is pure arithmetic here; words between the elements are not read.
// Bindings: 0 = src (the host's range, read-only), 1 = dst (packed, write-only).
// Push constants: n (elements), first_word, stride_words, width (words per element, <= 4).
// Workgroup: 64; one thread per element.
#extension GL_GOOGLE_include_directive : require

// Before the include (see grid.glsl): global_index() folds gl_WorkGroupSize where defined.
layout(local_size_x = 64) in;
#include "grid.glsl"

layout(std430, set = 0, binding = 0) readonly buffer Src { uint words[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Dst { uint packed_words[]; };
layout(push_constant) uniform Push {
    uint n;
    uint first_word;
    uint stride_words;
    uint width;
} pc;

void main() {
    uint i = global_index();
    if (i >= pc.n) return;
    uint s = pc.first_word + i * pc.stride_words;
    uint d = i * pc.width;
    for (uint k = 0u; k < pc.width; ++k) {
        packed_words[d + k] = words[s + k];
    }
}
