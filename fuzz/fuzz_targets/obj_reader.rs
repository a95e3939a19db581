//! Any bytes as an OBJ file: the reader and the validation must return a mesh or a located
//! error — never panic, hang or allocate without bound.
#![no_main]

use std::path::Path;

use foldfree::mesh::{obj, validate};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let file = Path::new("fuzz.obj");
    if let Ok((mesh, _info)) = obj::parse_obj_with_info(data, file) {
        let _ =
            validate::validate_with_topology(&mesh, file, &validate::ValidateOptions::default());
    }
});
