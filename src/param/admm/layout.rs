//! Host mirrors of the ADMM shaders' push constants (`#[repr(C)]`, `Pod`, std430 layout).
//! Field lists match the `Push` blocks in `glsl/admm/*.comp`; sizes are asserted at compile
//! time. Storage buffers need no structs: they are the host's flat arrays as f32 (`vec4` per
//! 2x2 matrix, `uvec4` per face slot triple, `vec2` per edge direction).

use bytemuck::{Pod, Zeroable};

/// `face_newton.comp`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct FacePush {
    pub mu: f32,
    pub n_faces: u32,
    pub energy: u32,
    pub newton_iters: u32,
    pub save_prev: u32,
    /// First face of the dispatch (`n_faces` is the end): a split iteration's range.
    pub first: u32,
}

/// `edge_project.comp` and `dual_update.comp` (`n` = interior edges or slots).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct MuCountPush {
    pub mu: f32,
    /// End of the range (interior edges or slots).
    pub n: u32,
    /// First element of the dispatch.
    pub first: u32,
}

/// `residual.comp`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct ResidualPush {
    pub n_slots: u32,
    pub n_faces: u32,
    pub energy: u32,
}

const _: () = assert!(std::mem::size_of::<FacePush>() == 24);
const _: () = assert!(std::mem::size_of::<MuCountPush>() == 12);
const _: () = assert!(std::mem::size_of::<ResidualPush>() == 12);
