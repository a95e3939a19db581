//! Triangle meshes as flat arrays: loading (OBJ, PLY, OFF, STL), validation, topology (CSR adjacency, edges,
//! boundary loops, Euler characteristic, genus), and per-face isometric 2D frames.
#![forbid(unsafe_code)]

pub mod error;
pub mod formats;
pub mod frames;
pub mod obj;
pub mod scale;
pub mod topology;
pub mod validate;

pub use error::MeshError;
pub use formats::{read_surface, SurfaceFormat, SurfaceInfo};
pub use frames::FaceFrames;
pub use obj::{obj_text_with_corner_uv, obj_text_with_uv, read_obj, read_obj_with_info, ObjInfo};
pub use scale::Scale;
pub use topology::Topology;
pub use validate::{load, ValidateOptions, ValidationReport};

/// Sentinel for "no face" (the missing side of a boundary edge).
pub const NO_FACE: u32 = u32::MAX;

/// A triangle mesh: `positions` is #V×3, `faces` is #F×3 0-based vertex indices, counter-clockwise
/// seen from the side the normal points to. Vertices used by no face are allowed and kept.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriMesh {
    pub positions: Vec<[f64; 3]>,
    pub faces: Vec<[u32; 3]>,
}
