//! Starting maps: Tutte embedding (flip-free on a convex boundary).
#![forbid(unsafe_code)]
