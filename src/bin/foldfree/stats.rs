//! `foldfree stats` and `foldfree devices`.

use std::path::PathBuf;

use foldfree::files::DEFAULT_MAX_ELEMENTS;
use foldfree::mesh;

use crate::element_limit;

#[derive(clap::Args)]
pub struct StatsArgs {
    /// Input surface: OBJ, PLY, OFF or STL by extension.
    input: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
    /// Refuse meshes with more faces (and files larger than such a mesh's text); 0 = no limit.
    #[arg(long, default_value_t = DEFAULT_MAX_ELEMENTS, value_parser = clap::value_parser!(usize))]
    max_faces: usize,
}

pub fn run_stats(a: StatsArgs) -> foldfree::Result<()> {
    let (input, json, max_faces) = (a.input, a.json, a.max_faces);
    let opts = mesh::ValidateOptions {
        max_faces: Some(element_limit(max_faces)),
        ..Default::default()
    };
    let (m, topo, report) = mesh::load(&input, &opts)?;
    let genus = topo.genus();
    if json {
        let v = serde_json::json!({
            "file": input.display().to_string(),
            "vertices": m.positions.len(),
            "faces": m.faces.len(),
            "edges": topo.edges.len(),
            "interior_edges": topo.interior_edges.len(),
            "boundary_edges": topo.boundary_edges.len(),
            "boundary_loops": topo.boundary_loops.len(),
            "components": topo.components,
            "euler_characteristic": topo.euler_characteristic,
            "genus": genus,
            "unreferenced_vertices": report.unreferenced_vertices.len(),
            "is_disk": topo.is_disk(),
            "description": topo.describe(),
            "bbox_diagonal": report.bbox_diagonal,
            "min_face_area": report.min_face_area,
            "valid": true,
        });
        println!("{}", serde_json::to_string_pretty(&v).unwrap_or_default());
    } else {
        println!("file: {}", input.display());
        println!(
            "vertices: {} ({} unreferenced)",
            m.positions.len(),
            report.unreferenced_vertices.len()
        );
        println!("faces: {}", m.faces.len());
        println!(
            "edges: {} ({} interior, {} boundary)",
            topo.edges.len(),
            topo.interior_edges.len(),
            topo.boundary_edges.len()
        );
        let lens: Vec<usize> = topo.boundary_loops.iter().map(Vec::len).collect();
        println!("boundary loops: {} {:?}", lens.len(), lens);
        println!("components: {}", topo.components);
        println!("euler characteristic: {}", topo.euler_characteristic);
        match genus {
            Some(g) => println!("genus: {g}"),
            None => println!("genus: undefined"),
        }
        println!(
            "bbox diagonal: {:.6e}, min face area: {:.6e}",
            report.bbox_diagonal, report.min_face_area
        );
        println!("topology: {}", topo.describe());
        println!(
            "valid: yes; disk: {}",
            if topo.is_disk() { "yes" } else { "no" }
        );
    }
    Ok(())
}

pub fn run_devices() -> foldfree::Result<()> {
    let ctx = foldfree::gpu::Context::new(&foldfree::gpu::ContextDesc::default())?;
    println!(
        "selected: {} ({})",
        ctx.device_name(),
        ctx.device_type_name()
    );
    Ok(())
}
