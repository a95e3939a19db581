//! Foldover-free volumetric maps of tetrahedral meshes (Xu & Liu 2022, "Generation of
//! foldover-free volumetric mapping guided by Jacobian matrix"): tet-mesh I/O (MEDIT, TetGen),
//! the 3D symmetric Dirichlet energy with an analytic PSD Hessian, projected Newton with a
//! fold-free line search, and the guided-deformation / penalty / post-optimisation pipeline.
#![forbid(unsafe_code)]

pub mod ball;
pub mod constraints;
pub mod energy;
pub mod error;
pub mod harmonic;
pub mod job;
pub mod line_search;
pub mod medit;
pub mod newton;
pub mod progressive;
pub mod tet;
pub mod tetgen;
pub mod untangle;
pub mod volmap;

pub use error::VolError;

/// Position constraints: (vertex, target position).
pub type Targets = Vec<(u32, [f64; 3])>;
pub use medit::read_medit;
pub use tet::TetMesh;
pub use tetgen::{read_any, read_any_with_limit, write_any};
pub use volmap::{evaluate, volmap, MapQuality, VolmapOptions, VolmapReport};
