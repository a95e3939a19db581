//! `foldfree render`: a checkerboard through a map's UVs, or flat normal colours, to PNG.

use std::path::PathBuf;

use foldfree::files::{Outputs, DEFAULT_MAX_ELEMENTS};
use foldfree::gpu::Shade;
use foldfree::mesh;

use crate::element_limit;

#[derive(clap::Args)]
pub struct RenderArgs {
    /// Input OBJ with texture coordinates (`vt`) or glTF (.glb, .gltf) with a TEXCOORD set,
    /// e.g. the output of `foldfree param`.
    input: PathBuf,
    /// glTF input: the TEXCOORD_n set the checker is drawn through (default: the highest set
    /// every primitive has, the one `foldfree param` adds).
    #[arg(long, value_name = "N")]
    uv_set: Option<u32>,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
    /// Checker squares across the UV layout (along the longer side of its bounding box).
    #[arg(long, value_name = "N", default_value_t = 16,
          value_parser = clap::value_parser!(u32).range(1..=4096))]
    checker: u32,
    /// Side of the square picture in pixels.
    #[arg(long, value_name = "W", default_value_t = 1024,
          value_parser = clap::value_parser!(u32).range(16..=8192))]
    size: u32,
    /// Direction from the mesh towards the camera, `x,y,z`.
    #[arg(long, value_name = "X,Y,Z", value_delimiter = ',', allow_hyphen_values = true,
          default_values_t = [0.0, 0.0, 1.0])]
    view: Vec<f32>,
    /// Vulkan device: a substring of its name or its index (see `foldfree devices`).
    #[arg(long)]
    device: Option<String>,
    /// Enable the Khronos validation layer (any message fails the run).
    #[arg(long)]
    validation: bool,
    /// `checker`: a checkerboard through the UVs (needs `vt`); `normals`: faces coloured by
    /// their flat normal (any triangle mesh, e.g. `approx` output: planar regions show as
    /// uniform patches; or a tet mesh's boundary surface, `.mesh` / `.node`).
    #[arg(long, value_enum, default_value = "checker")]
    shade: Shade,
    /// Refuse meshes with more faces or tets (and files larger than such a mesh's text); 0 = no
    /// limit.
    #[arg(long, default_value_t = DEFAULT_MAX_ELEMENTS)]
    max_elements: usize,
}

/// Per-corner positions, UVs and indices: what the render pipeline draws.
type Corners = (Vec<[f32; 3]>, Vec<[f32; 2]>, Vec<u32>);

/// The corners of a triangle surface with zero UVs, for `--shade normals`: an OBJ, PLY, OFF or
/// STL surface, or the boundary surface of a tet mesh (`.mesh`, `.node`/`.ele`; e.g. a `volmap` output).
fn surface_corners(path: &std::path::Path, max_elements: usize) -> foldfree::Result<Corners> {
    let is_tet = matches!(
        path.extension().and_then(|e| e.to_str()),
        Some("mesh" | "node" | "ele")
    );
    let m = if is_tet {
        let t = foldfree::vol::tetgen::read_any_with_limit(path, max_elements)?;
        mesh::TriMesh {
            faces: t.boundary_faces(),
            positions: t.positions,
        }
    } else {
        mesh::read_surface(path, max_elements)?.0
    };
    // Any surface is drawn, valid or not, but not NaN or infinite corners (nothing, or
    // garbage, would be drawn and the picture still written); positions go to unit scale
    // before they become f32, whose range ends at 3.4e38.
    if let Some(v) = m
        .positions
        .iter()
        .position(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(foldfree::Error::Mesh(mesh::MeshError::NonFinite {
            file: path.to_path_buf(),
            vertex: v,
            value: m.positions[v]
                .into_iter()
                .find(|c| !c.is_finite())
                .unwrap_or(f64::NAN),
        }));
    }
    let unit = mesh::Scale::fit(&m.positions);
    let mut positions = Vec::with_capacity(3 * m.faces.len());
    for f in &m.faces {
        for &v in f {
            let p = unit.apply(m.positions[v as usize]);
            positions.push([p[0] as f32, p[1] as f32, p[2] as f32]);
        }
    }
    let n = positions.len();
    Ok((positions, vec![[0.0; 2]; n], (0..n as u32).collect()))
}

pub fn run_render(args: RenderArgs) -> foldfree::Result<()> {
    use foldfree::gpu::{render_checker, Context, ContextDesc, RenderDesc};
    use foldfree::viz::render::{encode_rgba_png, read_with_uv};
    let mut outputs = Outputs::new();
    foldfree::vol::tetgen::tet_input(&mut outputs, &args.input);
    outputs.output(&args.output, "picture", &["png"])?;
    let max_elements = element_limit(args.max_elements);
    let (positions, uvs, indices) = match args.shade {
        Shade::Checker => read_with_uv(&args.input, max_elements, args.uv_set)?.corners(),
        Shade::Normals => surface_corners(&args.input, max_elements)?,
    };
    if indices.len() / 3 > max_elements {
        return Err(foldfree::Error::Usage(format!(
            "{}: {} triangles, more than --max-elements {}",
            args.input.display(),
            indices.len() / 3,
            args.max_elements
        )));
    }
    let view_dir = match args.view.as_slice() {
        &[x, y, z] if [x, y, z].iter().all(|c| c.is_finite()) && x * x + y * y + z * z > 0.0 => {
            [x, y, z]
        }
        _ => {
            return Err(foldfree::Error::Usage(
                "--view needs three finite numbers, not all zero".into(),
            ))
        }
    };
    let ctx = Context::new(&ContextDesc {
        validation: args.validation,
        device: args.device.clone(),
        ..ContextDesc::default()
    })?;
    let desc = RenderDesc {
        width: args.size,
        height: args.size,
        checker: args.checker,
        view_dir,
        shade: args.shade,
    };
    let rgba = render_checker(&ctx, &positions, &uvs, &indices, &desc)?;
    let messages = ctx.take_validation_messages();
    if !messages.is_empty() {
        return Err(foldfree::Error::Gpu(foldfree::gpu::GpuError::Invalid(
            format!(
                "{} validation message(s):\n{}",
                messages.len(),
                messages.join("\n")
            ),
        )));
    }
    let png =
        encode_rgba_png(args.size, args.size, &rgba).map_err(|source| foldfree::Error::Io {
            path: args.output.clone(),
            source,
        })?;
    outputs.set(&args.output, png);
    outputs.commit()?;
    println!(
        "wrote {} ({}x{}, {} triangles, {})",
        args.output.display(),
        args.size,
        args.size,
        indices.len() / 3,
        match args.shade {
            Shade::Checker => format!("checker {}", args.checker),
            Shade::Normals => "flat normal colours".to_string(),
        }
    );
    Ok(())
}
