//! `foldfree::param`: the ADMM solver (driver, CPU executor, Vulkan kernels, Anderson
//! acceleration), the global solver, and atlases of meshes that are not disks.

mod common;

// The modules live in tests/param/ (an inline module maps the folder without `#[path]`).
mod param {
    mod admm_anderson;
    mod admm_cpu;
    mod admm_driver;
    mod admm_gpu;
    mod atlas;
    mod global_solver;
}

use common::start_map as start;
use foldfree::mesh::{self, Topology, TriMesh};
use foldfree::param::admm::AdmmProblem;

/// `tests/data/NAME` and its ADMM problem.
fn load(name: &str) -> (TriMesh, Topology, AdmmProblem) {
    let (m, t) = common::load(name);
    let frames = mesh::frames::compute(&m);
    let p = AdmmProblem::new(&m, &t, &frames);
    (m, t, p)
}
