//! Arbitrary small meshes (any indices, repeated, out of range, any topology) through topology
//! building, validation and — when valid — cutting into disk charts and a Tutte map of each
//! chart: errors are fine, panics and non-disk charts are not.
#![no_main]

use std::path::Path;

use foldfree::mesh::{validate, Topology, TriMesh};
use foldfree::param::cut::{cut_to_disks, CutOptions};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&n, rest)) = data.split_first() else {
        return;
    };
    let n = (n % 32) as usize + 1;
    if rest.len() < 3 * n {
        return;
    }
    let (coords, idx) = rest.split_at(3 * n);
    // Positions on a small integer lattice keep degenerate and coincident cases likely.
    let positions: Vec<[f64; 3]> = coords
        .chunks_exact(3)
        .map(|c| {
            [
                f64::from(c[0] % 8),
                f64::from(c[1] % 8),
                f64::from(c[2] % 8),
            ]
        })
        .collect();
    // Indices may run past the vertex count on purpose.
    let faces: Vec<[u32; 3]> = idx
        .chunks_exact(3)
        .take(64)
        .map(|c| [c[0], c[1], c[2]].map(|i| u32::from(i) % (n as u32 + 2)))
        .collect();
    let mesh = TriMesh { positions, faces };
    let file = Path::new("<fuzz>");
    if Topology::build(&mesh, file).is_err() {
        return;
    }
    let opts = validate::ValidateOptions::default();
    let Ok((_, topo)) = validate::validate_with_topology(&mesh, file, &opts) else {
        return;
    };
    match cut_to_disks(&mesh, &topo, &CutOptions::default(), file) {
        Ok(cut) => {
            for faces in &cut.charts {
                let (sub, _) = cut.chart_mesh(faces);
                let t = Topology::build(&sub, file).expect("a chart builds");
                assert!(t.is_disk(), "chart is a {}", t.describe());
            }
        }
        Err(e) => panic!("valid mesh could not be cut: {e}"),
    }
});
