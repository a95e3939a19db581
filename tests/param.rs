//! `foldfree::param`: the ADMM solver (driver, CPU executor, Vulkan kernels, Anderson
//! acceleration), the global solver, and atlases of meshes that are not disks.

// The modules live in tests/param/ (an inline module maps the folder without `#[path]`).
mod param {
    mod admm_anderson;
    mod admm_cpu;
    mod admm_driver;
    mod admm_gpu;
    mod atlas;
    mod global_solver;
}
