#version 450
// Checker colour from floor(uv * N) parity (shade 0) or the flat normal mapped to RGB (shade 1:
// planar regions become uniform patches), times two-sided Lambert shading of the flat normal.

layout(location = 0) in vec2 in_uv;
layout(location = 1) in vec3 in_world;

layout(push_constant) uniform Push {
    mat4 view_proj;
    vec4 light_dir;
    float checker;
    uint shade;
} pc;

layout(location = 0) out vec4 out_color;

void main() {
    vec3 n = normalize(cross(dFdx(in_world), dFdy(in_world)));
    vec3 base;
    if (pc.shade == 1u) {
        base = 0.25 + 0.7 * abs(n);
    } else {
        ivec2 cell = ivec2(floor(in_uv * pc.checker));
        bool light = ((cell.x + cell.y) & 1) == 0;
        base = light ? vec3(0.95, 0.93, 0.88) : vec3(0.18, 0.22, 0.32);
    }
    float lambert = abs(dot(n, pc.light_dir.xyz));
    out_color = vec4(base * (0.35 + 0.65 * lambert), 1.0);
}
