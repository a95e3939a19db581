//! Any bytes as a `.gltf` or `.glb` (told apart by the `glTF` magic, as the reader does; no
//! external buffers): the reader returns a mesh whose every face index is in range and every
//! primitive's triangles index its vertices, or a located error — never panics, hangs or
//! allocates without bound. A file that reads is validated and written back (`.glb` and
//! `.gltf`) with a map per welded vertex; the `.glb` must read again with one more TEXCOORD set.
#![no_main]

use std::path::Path;

use foldfree::mesh::formats::gltf::{parse_gltf, write_gltf, GltfTarget};
use foldfree::mesh::validate;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let file = Path::new("fuzz.gltf");
    let mut no_files = |_: &str| Err("no external buffers here".to_string());
    let Ok(scene) = parse_gltf(data, file, &mut no_files) else {
        return;
    };
    let n = scene.mesh.positions.len();
    assert!(
        scene.mesh.faces.iter().flatten().all(|&v| (v as usize) < n),
        "a parsed mesh refers past its vertices"
    );
    for p in &scene.primitives {
        assert!(p.triangles.iter().flatten().all(|&v| (v as usize) < p.vertex_count));
    }
    let _ = validate::validate_with_topology(&scene.mesh, file, &validate::ValidateOptions::default());
    let uv: Vec<[f64; 2]> = scene
        .mesh
        .positions
        .iter()
        .map(|p| [p[0], p[1]])
        .map(|t| if t.iter().all(|c| c.is_finite()) { t } else { [0.0; 2] })
        .collect();
    let faces = scene.mesh.faces.clone();
    let bin = GltfTarget::Gltf {
        bin_uri: "fuzz.bin".into(),
    };
    let _ = write_gltf(&scene, &uv, &faces, None, &bin);
    if let Ok(w) = write_gltf(&scene, &uv, &faces, None, &GltfTarget::Glb) {
        let again = parse_gltf(&w.main, file, &mut no_files).expect("a written .glb reads back");
        for (a, b) in scene.primitives.iter().zip(&again.primitives) {
            assert_eq!(a.texcoord_sets.len() + 1, b.texcoord_sets.len());
        }
    }
});
