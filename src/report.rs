//! The JSON run report.
#![forbid(unsafe_code)]
