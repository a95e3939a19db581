//! Parameterization solvers.
#![forbid(unsafe_code)]
