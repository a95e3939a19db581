#version 450
// Per-tet untangling energy and gradient (Garanzha et al. 2021; CPU twin:
// vol::untangle::tet_terms): J = Σ_j x_j ⊗ D_j over the tet's corners,
// χ(D, ε) = (D + √(ε² + D²))/2 (the cancellation-free form for D < 0),
// f = w·[(1 − θ)‖J‖²/χ^{2/3} + θ(D² + 1)/χ] and its gradient over the 12 corner coordinates.
// Bindings: 0 positions vec4[V] (xyz), 1 tets uvec4[T], 2 corner weights vec4[3T] (entry
// 3t + c holds D_0..D_3 of Jacobian column c), 3 weights float[T], 4 energy float[T] (w),
// 5 gradient vec4[4T] (w; entry 4t + j is corner j's xyz).
// One thread per tet, workgroups of 64. Each thread writes only its own tet's slots, so the
// per-vertex sums (in a fixed order, on the host) need no atomics.
#extension GL_GOOGLE_include_directive : require
layout(local_size_x = 64) in;
#include "grid.glsl"

layout(std430, set = 0, binding = 0) readonly buffer Pos { vec4 pos[]; };
layout(std430, set = 0, binding = 1) readonly buffer Tets { uvec4 tets[]; };
layout(std430, set = 0, binding = 2) readonly buffer Corners { vec4 corners[]; };
layout(std430, set = 0, binding = 3) readonly buffer Weights { float weight[]; };
layout(std430, set = 0, binding = 4) writeonly buffer Energy { float energy[]; };
layout(std430, set = 0, binding = 5) writeonly buffer Grad { vec4 grad[]; };

layout(push_constant) uniform Push {
    float eps;
    float theta;
    uint n_tets;
} pc;

void main() {
    uint t = global_index();
    if (t >= pc.n_tets) return;
    uvec4 tet = tets[t];
    vec3 x[4] = vec3[4](pos[tet.x].xyz, pos[tet.y].xyz, pos[tet.z].xyz, pos[tet.w].xyz);
    vec4 d[3] = vec4[3](corners[3 * t], corners[3 * t + 1], corners[3 * t + 2]);
    // Rows of J: J[r][c] = Σ_j x_j[r] D_j[c]. GLSL matrices are column-major: m[c][r].
    vec3 row[3];
    for (int r = 0; r < 3; r++) {
        vec4 xr = vec4(x[0][r], x[1][r], x[2][r], x[3][r]);
        row[r] = vec3(dot(xr, d[0]), dot(xr, d[1]), dot(xr, d[2]));
    }
    // Cofactors (∂ det / ∂ J), rows = cross products of the other two rows.
    vec3 cof[3] = vec3[3](cross(row[1], row[2]), cross(row[2], row[0]), cross(row[0], row[1]));
    float det = dot(row[0], cof[0]);
    float e = pc.eps;
    float rt = sqrt(e * e + det * det);
    float chi = det >= 0.0 ? 0.5 * (det + rt) : 0.5 * e * e / (rt - det);
    float dchi = chi / rt;
    float c = dot(row[0], row[0]) + dot(row[1], row[1]) + dot(row[2], row[2]);
    float c13 = pow(chi, 1.0 / 3.0);
    float c23 = c13 * c13;
    float th = pc.theta;
    float w = weight[t];
    float f = (1.0 - th) * c / c23 + th * (det * det + 1.0) / chi;
    float df_dd = (1.0 - th) * (-2.0 / 3.0) * c / (c23 * chi) * dchi
        + th * (2.0 * det / chi - (det * det + 1.0) * dchi / (chi * chi));
    energy[t] = w * f;
    // P = ∂f/∂J = 2(1 − θ)J/χ^{2/3} + ∂f/∂D·cof; gradient of corner j, coordinate r:
    // w·Σ_c P[r][c] D_j[c].
    vec3 p[3];
    for (int r = 0; r < 3; r++) {
        p[r] = 2.0 * (1.0 - th) * row[r] / c23 + df_dd * cof[r];
    }
    for (int j = 0; j < 4; j++) {
        vec3 dj = vec3(d[0][j], d[1][j], d[2][j]);
        grad[4 * t + j] = vec4(w * dot(p[0], dj), w * dot(p[1], dj), w * dot(p[2], dj), 0.0);
    }
}
