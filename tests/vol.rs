//! `foldfree::vol`: volume maps of tet meshes and the Vulkan untangler.

mod common;

// The modules live in tests/vol/ (an inline module maps the folder without `#[path]`).
mod vol {
    mod untangle_gpu;
    mod volmap;
}
