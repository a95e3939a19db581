//! Distortion and validity measures of a UV map, in f64.
#![forbid(unsafe_code)]
