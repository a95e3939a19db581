//! foldfree: foldover-free, low-distortion maps of meshes.
//!
//! Data flows one way:
//! `file → mesh (validate, topology) → init (Tutte) → solver → recover → metrics → file/report`.
//!
//! Only [`gpu`] contains `unsafe` code; every other module forbids it.

pub mod approx;
pub mod bench;
#[cfg(feature = "cli")]
pub mod cli;
pub mod embed;
pub mod error;
pub mod files;
pub mod gpu;
pub mod init;
pub mod linalg;
pub mod mesh;
pub mod metrics;
pub mod param;
pub mod report;
pub mod tuning;
pub mod viz;
pub mod vol;

pub use error::{Error, OptionError, Result};
