//! Any bytes as a MEDIT `.mesh` file and as a TetGen `.node`/`.ele` pair (split at the first
//! NUL byte): the readers must return a tet mesh or a located error — never panic, hang or
//! allocate without bound. A mesh that parses is also checked for inverted tets.
#![no_main]

use std::path::Path;

use foldfree::vol::{medit, tetgen};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    if let Ok(mesh) = medit::parse_medit(&text, Path::new("fuzz.mesh")) {
        let _ = mesh.inverted(&mesh.positions);
    }
    let (node, ele) = text.split_once('\0').unwrap_or((&text, ""));
    if let Ok((positions, _refs, base)) = tetgen::parse_node(node, Path::new("fuzz.node")) {
        let _ = tetgen::parse_ele(ele, Path::new("fuzz.ele"), positions.len(), base);
    }
});
