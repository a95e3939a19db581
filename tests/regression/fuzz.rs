//! Every input a fuzz target ever crashed on (tests/data/fuzz, see its README and FUZZING.md)
//! goes through the same reader again: a result or an error naming the file, never a panic.

use std::fs;

// Found by the fuzzers (FUZZING.md): each file in tests/data/fuzz once crashed a reader.
#[test]
fn fuzzer_finds_stay_fixed() {
    let dir = crate::common::data("fuzz");
    let mut seen = 0;
    for entry in fs::read_dir(&dir).expect("list tests/data/fuzz") {
        let path = entry.expect("entry").path();
        let bytes = fs::read(&path).expect("read");
        let text = String::from_utf8_lossy(&bytes);
        let name = path.display().to_string();
        match path.extension().and_then(|e| e.to_str()) {
            Some("obj") => {
                if let Ok((mesh, _)) = foldfree::mesh::obj::parse_obj_with_info(&bytes, &path) {
                    let _ = foldfree::mesh::validate::validate_with_topology(
                        &mesh,
                        &path,
                        &Default::default(),
                    );
                }
            }
            Some("mesh") => {
                if let Err(e) = foldfree::vol::medit::parse_medit(&text, &path) {
                    assert!(e.to_string().contains(&name), "{e}");
                }
            }
            Some(ext @ ("ply" | "off" | "stl" | "gltf" | "glb")) => {
                let format = match ext {
                    "ply" => foldfree::mesh::SurfaceFormat::Ply,
                    "off" => foldfree::mesh::SurfaceFormat::Off,
                    "gltf" | "glb" => foldfree::mesh::SurfaceFormat::Gltf,
                    _ => foldfree::mesh::SurfaceFormat::Stl,
                };
                match foldfree::mesh::formats::parse_surface(&bytes, &path, format) {
                    Ok((mesh, _)) => {
                        let _ = foldfree::mesh::validate::validate_with_topology(
                            &mesh,
                            &path,
                            &Default::default(),
                        );
                    }
                    Err(e) => assert!(e.to_string().contains(&name), "{e}"),
                }
            }
            Some("node") => {
                let _ = foldfree::vol::tetgen::parse_node(&text, &path);
            }
            _ => continue,
        }
        seen += 1;
    }
    assert!(seen >= 1, "no regression inputs found in {}", dir.display());
}
