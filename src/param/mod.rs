//! Parameterization solvers: energies, the ADMM solver (CPU twin and Vulkan), UV recovery.
#![forbid(unsafe_code)]

pub mod admm;
pub mod energy;
pub mod global;
pub mod recover;

pub use energy::Energy;
