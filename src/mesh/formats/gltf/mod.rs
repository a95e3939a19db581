//! glTF 2.0 surfaces in and out: `.gltf` (JSON, buffers in `.bin` files beside it or in base64
//! data URIs) and `.glb` (binary: one JSON chunk and one BIN chunk).
//!
//! **Reading** ([`parse_gltf`], [`read_gltf`]). The JSON is parsed and validated (references,
//! enums, required fields) by the `gltf` crate, whose errors carry the JSON path; the GLB
//! container is split here, and accessor data are read here with every count, offset and stride
//! checked against the bytes there are (the crate's readers slice without checking). Every
//! primitive of every mesh in `meshes` is read — not only those the default scene instances —
//! because a UV map belongs to the mesh, which all its nodes share; node transforms are
//! ignored (each mesh is mapped in its own coordinates). Primitives must be `TRIANGLES`,
//! indexed or not, with a `FLOAT` `VEC3` `POSITION`. Within a primitive, vertices at exactly
//! equal positions are welded for topology: a glTF file splits vertices where normals or UVs
//! are discontinuous, and such a split is not a cut of the surface. Primitives are not welded
//! to each other, so each is its own component (charts of an atlas never cross primitives).
//! Refused with a `MeshError` naming the JSON path (exit 2): sparse accessors, accessors
//! without a bufferView, non-triangle modes, data URIs other than base64 buffers, missing
//! external buffers, buffers shorter than their `byteLength` or their views, out-of-range
//! indices, required extensions the crate does not know (Draco, meshopt, quantization).
//!
//! **Writing** ([`write_gltf`]). The same document comes back: every JSON field the file had is
//! kept, and each primitive gains one `TEXCOORD_n` (`FLOAT` `VEC2`). glTF puts the UV origin
//! at the top-left of the image, OBJ and foldfree at the bottom-left, so the written
//! coordinate is `(u, 1 − v)`. Where the map has a seam through a glTF vertex (atlas charts,
//! pinched vertices) that vertex is duplicated with all its attributes and morph targets,
//! and the primitive gets new attribute accessors and a new index accessor; a primitive
//! without seams keeps its accessors and only gains the new set. All buffers become one: the
//! old buffers' bytes (so images, skins and animations in them keep their views), then the new
//! data.

mod read;
mod write;

pub use read::{parse_gltf, read_gltf, GltfScene, Primitive};
pub use write::{write_gltf, GltfTarget, Written};

/// glTF `componentType` codes.
pub(crate) mod component {
    pub const UNSIGNED_SHORT: u64 = 5123;
    pub const UNSIGNED_INT: u64 = 5125;
    pub const FLOAT: u64 = 5126;
}

/// `bufferView.target` codes.
pub(crate) const ARRAY_BUFFER: u64 = 34962;
pub(crate) const ELEMENT_ARRAY_BUFFER: u64 = 34963;
