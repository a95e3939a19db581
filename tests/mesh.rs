//! `foldfree::mesh`: reading (OBJ, PLY, OFF, STL, glTF), topology and validation.

mod common;

// The modules live in tests/mesh/ (an inline module maps the folder without `#[path]`).
mod mesh {
    mod formats;
    mod gltf;
    mod topology;
    mod validate;
}
