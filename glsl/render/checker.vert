#version 450
// Checkerboard texture-mapping view: positions and UVs, interleaved (vec3 + vec2).

layout(location = 0) in vec3 in_position;
layout(location = 1) in vec2 in_uv;

layout(push_constant) uniform Push {
    mat4 view_proj;
    vec4 light_dir;  // xyz: unit direction towards the light (world space)
    float checker;   // squares per unit of UV
    uint shade;      // 0: checker through the UVs, 1: flat normal colours
} pc;

layout(location = 0) out vec2 out_uv;
layout(location = 1) out vec3 out_world;

void main() {
    out_uv = in_uv;
    out_world = in_position;
    gl_Position = pc.view_proj * vec4(in_position, 1.0);
}
