//! Parameterization solvers: energies, the ADMM solver (CPU twin and Vulkan), UV recovery.
#![forbid(unsafe_code)]

pub mod admm;
pub mod cut;
pub mod energy;
pub mod global;
pub mod pack;
pub mod recover;

pub use energy::Energy;
