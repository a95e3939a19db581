//! Errors about the input mesh. Each names the file (when there is one) and the element.

use std::path::PathBuf;

/// Why a mesh cannot be used. `file` is the source path, or `<memory>` for meshes built in code.
#[derive(Debug, thiserror::Error)]
pub enum MeshError {
    #[error("{file}: cannot read: {reason}")]
    Read { file: PathBuf, reason: String },
    #[error("{file}: the mesh has no faces")]
    Empty { file: PathBuf },
    #[error("{file}: vertex {vertex} has a non-finite coordinate ({value})")]
    NonFinite {
        file: PathBuf,
        vertex: usize,
        value: f64,
    },
    #[error("{file}: face {face} refers to vertex {index}, but there are only {count} vertices")]
    IndexOutOfRange {
        file: PathBuf,
        face: usize,
        index: i64,
        count: usize,
    },
    #[error("{file}: face {face} uses vertex {vertex} twice")]
    RepeatedVertex {
        file: PathBuf,
        face: usize,
        vertex: usize,
    },
    /// A degenerate face of a mesh whose size in the file's units overflows or underflows
    /// f64 when squared (coordinates near 1e±200 and beyond): the area is given relative to
    /// the bounding box, where the test is made.
    #[error("{file}: face {face} is degenerate (area {rel_area:.3e} x bbox diagonal^2, below the tolerance {tolerance:.3e}; in the file's units the area is not representable)")]
    DegenerateRelative {
        file: PathBuf,
        face: usize,
        rel_area: f64,
        tolerance: f64,
    },
    #[error("{file}: face {face} is degenerate (area {area:.3e}, below {threshold:.3e} = tolerance x bbox diagonal^2)")]
    Degenerate {
        file: PathBuf,
        face: usize,
        area: f64,
        threshold: f64,
    },
    #[error("{file}: edge ({v0}, {v1}) is non-manifold: it is shared by {count} faces (faces {faces:?})")]
    NonManifoldEdge {
        file: PathBuf,
        v0: usize,
        v1: usize,
        count: usize,
        faces: Vec<usize>,
    },
    #[error("{file}: vertex {vertex} is non-manifold: its faces form {fans} separate fans")]
    NonManifoldVertex {
        file: PathBuf,
        vertex: usize,
        fans: usize,
    },
    #[error("{file}: inconsistent orientation: faces {f0} and {f1} traverse edge ({v0}, {v1}) in the same direction")]
    InconsistentOrientation {
        file: PathBuf,
        f0: usize,
        f1: usize,
        v0: usize,
        v1: usize,
    },
    #[error("{file}: face {face} is a duplicate of face {other}")]
    DuplicateFace {
        file: PathBuf,
        face: usize,
        other: usize,
    },
    #[error("{file}: not a disk: {what}; this operation needs one connected component with one boundary loop and genus 0")]
    NotDisk { file: PathBuf, what: String },
    #[error("{file}: {what}")]
    TooLarge { file: PathBuf, what: String },
    /// Another error about a face or vertex, placed in the file's own terms where the file's
    /// numbering differs from the mesh's (a glTF primitive and its triangle).
    #[error("{file}: {place}: {what}")]
    InPlace {
        file: PathBuf,
        place: String,
        what: String,
    },
}
