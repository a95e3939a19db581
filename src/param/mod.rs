//! Parameterization: the job (`job`), the map of one disk with the ADMM → global hand-off
//! (`map`), the atlas of cut meshes (`cut`, `atlas`, `pack`), energies, the ADMM solver (CPU twin
//! and Vulkan), the global solver, UV recovery.
#![forbid(unsafe_code)]

pub mod admm;
pub mod atlas;
pub mod cut;
pub mod energy;
pub mod global;
pub mod injective;
pub mod job;
pub mod map;
pub mod pack;
pub mod recover;

pub use admm::AdmmOptions;
pub use energy::Energy;
pub use job::{run_param, BackendChoice, CutMode, ParamJob, ParamOutput};
pub use map::{compute_map, MapOutput, OnDevice, Progress, SolverChoice, SolverPath};
