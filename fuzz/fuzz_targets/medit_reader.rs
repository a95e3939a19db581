//! Any bytes as a MEDIT `.mesh` file: the reader returns a tet mesh or a located error, never
//! panics, hangs or allocates without bound. A mesh that parses is also checked for its
//! structure and inverted tets.
#![no_main]

use std::path::Path;

use foldfree::vol::medit;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let text = String::from_utf8_lossy(data);
    let file = Path::new("fuzz.mesh");
    if let Ok(mesh) = medit::parse_medit(&text, file) {
        if mesh.check_structure(file).is_ok() {
            let _ = mesh.inverted(&mesh.positions);
            let _ = mesh.boundary_faces();
        }
    }
});
