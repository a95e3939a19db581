//! `foldfree approx`: at most K planar polygons.

use std::path::PathBuf;

use foldfree::files::{Outputs, DEFAULT_MAX_ELEMENTS};
use foldfree::mesh;

use crate::element_limit;

#[derive(clap::Args)]
pub struct ApproxArgs {
    /// Input surface, OBJ, PLY, OFF or STL (manifold, consistently oriented triangles).
    input: PathBuf,
    /// Largest number of planar regions.
    #[arg(short, value_name = "K")]
    k: usize,
    /// Output OBJ: the triangles of the polygons (the connectivity inside each region is new).
    #[arg(short, long)]
    output: PathBuf,
    /// Also write one planar polygon per region (holes bridged in) to this OBJ.
    #[arg(long, value_name = "POLY.obj")]
    polygons: Option<PathBuf>,
    /// Write the polygons as triangles (those of the output, ear-clipped in each plane).
    #[arg(long)]
    triangulate: bool,
    /// Seed of the region-growing order.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Further runs with seeds seed+1, seed+2, … while no run gave a valid polygon mesh, or
    /// the best lost its planes to merges (more than a quarter farther from the input than
    /// its partition); 0 = only the --tries.
    #[arg(long, default_value_t = 4)]
    restarts: usize,
    /// Partitions tried in any case (seeds seed, seed+1, …): the valid polygon mesh with the
    /// least mean distance to the input is written.
    #[arg(long, default_value_t = 3)]
    tries: usize,
    /// Region-growing / merge angle in degrees.
    #[arg(long, default_value_t = 20.0)]
    angle: f64,
    /// Write the JSON report here.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Refuse meshes with more faces (and files larger than such a mesh's text); 0 = no limit.
    #[arg(long, default_value_t = DEFAULT_MAX_ELEMENTS)]
    max_faces: usize,
    /// No progress display.
    #[arg(short, long)]
    quiet: bool,
}

pub fn run_approx(args: ApproxArgs) -> foldfree::Result<()> {
    use foldfree::approx::{self, ApproxOptions, Stage};
    let mut outputs = Outputs::new();
    outputs.input(&args.input);
    outputs.output(&args.output, "planar mesh", &["obj"])?;
    if let Some(p) = &args.polygons {
        outputs.output(p, "polygons", &["obj"])?;
    }
    if let Some(p) = &args.report {
        outputs.output(p, "report", &["json"])?;
    }
    let mut opts = ApproxOptions::new(args.k);
    opts.seed = args.seed;
    opts.restarts = args.restarts;
    opts.tries = args.tries;
    opts.partition.angle_deg = args.angle;
    opts.validate()?;
    let validate = mesh::ValidateOptions {
        max_faces: Some(element_limit(args.max_faces)),
        ..Default::default()
    };
    let (m, topo, _) = mesh::load(&args.input, &validate)?;
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        let b = indicatif::ProgressBar::new(Stage::ALL.len() as u64);
        b.set_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} approx [{bar:20}] {pos}/{len} {msg}",
            )
            .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        b.enable_steady_tick(std::time::Duration::from_millis(120));
        b
    };
    let out = approx::approximate(&m, &topo, &opts, &mut |s| {
        let i = Stage::ALL.iter().position(|&x| x == s).unwrap_or(0);
        bar.set_position(i as u64);
        bar.set_message(s.name());
    });
    bar.finish_and_clear();
    let out = out?;
    let r = &out.report;
    // The contract of the output: every face keeps its orientation and area.
    out.check_fold_free()?;
    outputs.set(&args.output, out.polygons.to_obj(true).into_bytes());
    if let Some(p) = &args.polygons {
        outputs.set(p, out.polygons.to_obj(args.triangulate).into_bytes());
    }
    if let Some(p) = &args.report {
        outputs.set(p, serde_json::to_vec_pretty(r).unwrap_or_default());
    }
    outputs.commit()?;
    eprintln!("{r}");
    Ok(())
}
