//! `foldfree::gpu` and `foldfree::embed`: round trips through the Vulkan layer, the offscreen
//! checkerboard renderer (`foldfree render`), and the engine embedded in a host's renderer.
//! Every test runs under the validation layer.

mod common;

// The modules live in tests/gpu/ (an inline module maps the folder without `#[path]`).
mod gpu {
    mod embed;
    mod render;
    mod roundtrip;
}
