//! Tests that pin bugs found outside the unit tests: by the corpus sweeps (benches/sweep.py over
//! the shared meshes, reduced here to meshes in tests/data or built in the test) and by the
//! fuzzers (tests/data/fuzz). Each module says where its bug was found.

mod common;

// The modules live in tests/regression/ (an inline module maps the folder without `#[path]`).
mod regression {
    mod fuzz;
    mod sweep;
}
