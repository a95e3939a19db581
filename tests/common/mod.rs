//! Helpers shared by every test harness (`mod common;` in each harness root): where the test
//! data is and loading it, one seeded RNG, per-test temp dirs, Vulkan contexts under the
//! validation layer, running the `foldfree` binary, an independent OBJ checker and glTF
//! builders/readers. Each harness uses a subset, hence the `dead_code` allowance.
#![allow(dead_code)]

pub mod glb;
pub mod gpu;
pub mod objcheck;
pub mod rng;
pub mod run;
pub mod tempdir;

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use foldfree::init::{initial_map, normalize_area, InitMethod};
use foldfree::mesh::{self, Topology, TriMesh};

// Not every harness uses both.
#[allow(unused_imports)]
pub use rng::Rng;
#[allow(unused_imports)]
pub use tempdir::TempDir;

/// `tests/data`: every file a test reads (tests never read `../shared`).
pub fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data")
}

/// `tests/data/NAME`.
pub fn data(name: &str) -> PathBuf {
    data_dir().join(name)
}

/// `tests/data/NAME.obj`.
pub fn data_obj(name: &str) -> PathBuf {
    data_dir().join(format!("{name}.obj"))
}

/// The path named in errors about meshes built in memory.
pub fn mem() -> &'static Path {
    Path::new("<memory>")
}

/// `tests/data/NAME` read and validated by the library with the default options (panics on
/// error): the mesh and its topology.
pub fn load(name: &str) -> (TriMesh, Topology) {
    let (m, t, _) =
        mesh::load(&data(name), &mesh::ValidateOptions::default()).expect("test mesh loads");
    (m, t)
}

/// The start map `init` of `m`, scaled to the mesh's 3D area (panics on error).
pub fn start_map(m: &TriMesh, t: &Topology, init: InitMethod) -> Vec<[f64; 2]> {
    let mut uv = initial_map(m, t, init).expect("start map");
    let area: f64 = mesh::frames::compute(m).area.iter().sum();
    normalize_area(m, &mut uv, area);
    uv
}

/// Reads only the `v` and `f` lines of an OBJ (polygons fanned into triangles), independently
/// of the library's reader, for tests of code downstream of the mesh module.
pub fn read_v_f(path: &Path) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut positions = Vec::new();
    let mut faces = Vec::new();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it.take(3).map(|x| x.parse().unwrap()).collect();
                positions.push([c[0], c[1], c[2]]);
            }
            Some("f") => {
                let c: Vec<u32> = it
                    .map(|x| x.split('/').next().unwrap().parse::<u32>().unwrap() - 1)
                    .collect();
                for k in 1..c.len() - 1 {
                    faces.push([c[0], c[k], c[k + 1]]);
                }
            }
            _ => {}
        }
    }
    (positions, faces)
}

/// [`read_v_f`] of `tests/data/NAME`.
pub fn data_v_f(name: &str) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    read_v_f(&data(name))
}

/// Runs the `foldfree` binary of this build to completion with `args` (panics only when it
/// cannot be started).
pub fn foldfree<S: AsRef<OsStr>>(args: &[S]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_foldfree"))
        .args(args)
        .output()
        .expect("run foldfree")
}
