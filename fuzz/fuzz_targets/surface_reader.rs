//! Any bytes as a PLY, OFF or STL file (the first byte picks the format, the rest is the file):
//! the reader returns a mesh whose every face index is in range, or a located error — never
//! panics, hangs or allocates without bound; a mesh is then validated like an OBJ.
#![no_main]

use std::path::Path;

use foldfree::mesh::formats::{parse_surface, SurfaceFormat};
use foldfree::mesh::validate;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&pick, bytes)) = data.split_first() else {
        return;
    };
    let format = match pick % 3 {
        0 => SurfaceFormat::Ply,
        1 => SurfaceFormat::Off,
        _ => SurfaceFormat::Stl,
    };
    let file = Path::new("fuzz.surface");
    if let Ok((mesh, _info)) = parse_surface(bytes, file, format) {
        let n = mesh.positions.len();
        assert!(
            mesh.faces.iter().flatten().all(|&v| (v as usize) < n),
            "a parsed mesh refers past its vertices"
        );
        let _ =
            validate::validate_with_topology(&mesh, file, &validate::ValidateOptions::default());
    }
});
