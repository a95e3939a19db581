//! Any bytes as a TetGen `.node`/`.ele` pair (split at the first NUL byte): the readers return
//! a tet mesh or a located error, never panic, hang or allocate without bound.
#![no_main]

use std::path::Path;

use foldfree::vol::{tetgen, TetMesh};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let (node, ele) = text.split_once('\0').unwrap_or((&text, ""));
    if let Ok((positions, _refs, base)) = tetgen::parse_node(node, Path::new("fuzz.node")) {
        if let Ok((tets, _)) = tetgen::parse_ele(ele, Path::new("fuzz.ele"), positions.len(), base)
        {
            let m = TetMesh::new(positions, tets);
            if m.check_structure(Path::new("fuzz.node")).is_ok() {
                let _ = m.inverted(&m.positions);
                let _ = m.boundary_faces();
            }
        }
    }
});
