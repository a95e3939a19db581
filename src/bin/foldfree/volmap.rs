//! `foldfree volmap` (a fold-free tet map) and `foldfree volcheck` (checking one).

use std::path::PathBuf;

use foldfree::files::DEFAULT_MAX_ELEMENTS;
use foldfree::param::BackendChoice;

use crate::{element_limit, read_tuning};

#[derive(clap::Args)]
pub struct VolmapArgs {
    /// Rest tet mesh (.mesh, or TetGen .node/.ele).
    rest: PathBuf,
    /// Initial map (same tets; may contain inverted tets).
    #[arg(long)]
    init: Option<PathBuf>,
    /// Constraints: the init's boundary vertices stay where they are.
    #[arg(long, conflicts_with_all = ["constraints", "target"])]
    fix_boundary: bool,
    /// Constraints file: lines `vertex_index x y z` (0-based).
    #[arg(long, conflicts_with = "target")]
    constraints: Option<PathBuf>,
    /// Target shape: `ball` maps the boundary onto the unit sphere.
    #[arg(long, value_parser = ["ball"])]
    target: Option<String>,
    /// Output tet mesh (.mesh, or .node for TetGen).
    #[arg(short, long)]
    output: PathBuf,
    /// Write the JSON report here.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Where the untangler's per-tet energy and gradient run: `vulkan` (glsl/vol/untangle_tet.comp,
    /// f32), `cpu` (f64), or `auto` (Vulkan on a real GPU, the CPU when the only device is a CPU
    /// rasterizer such as lavapipe).
    #[arg(long, value_enum, default_value = "auto")]
    backend: BackendChoice,
    /// Vulkan device: a substring of its name or its index (see `foldfree devices`).
    #[arg(long)]
    device: Option<String>,
    /// Enable the Khronos validation layer (any message fails the run).
    #[arg(long)]
    validation: bool,
    /// Write the constraints the map meets (`vertex x y z`), e.g. the sphere positions the
    /// ball target's boundary slid to, for `volcheck --constraints`.
    #[arg(long, value_name = "FILE")]
    write_constraints: Option<PathBuf>,
    /// Write the rest mesh the map is of: the input, or the input refined where the ball
    /// target split interior edges (the report's `sphere_sliding.splits`), for
    /// `volcheck --rest`.
    #[arg(long, value_name = "FILE")]
    write_rest: Option<PathBuf>,
    /// Ball target: never split an interior edge; where the untangler finds no room the run
    /// ends with exit 3 instead of refining the mesh.
    #[arg(long)]
    no_refine: bool,
    /// Newton iteration cap per phase (the tuning file's `max_iters` of the deformation,
    /// penalty and post phases).
    #[arg(long)]
    max_iters: Option<usize>,
    /// Solver knobs (`[volmap]`: penalty growth and rounds, each Newton phase's stop and PCG
    /// settings, `post = false`, `untangle = false`, the ball target's relaxation cap); see
    /// `foldfree dev tuning` for every key and its default.
    #[arg(long, value_name = "FILE.toml")]
    tuning: Option<PathBuf>,
    /// Refuse meshes with more tets (and files larger than such a mesh's text); 0 = no limit.
    #[arg(long, default_value_t = DEFAULT_MAX_ELEMENTS)]
    max_tets: usize,
    /// No progress display.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(clap::Args)]
pub struct VolcheckArgs {
    /// The map to check (same tets as the rest mesh).
    map: PathBuf,
    /// Rest tet mesh.
    #[arg(long)]
    rest: PathBuf,
    /// Measure ρ against the boundary of this init map.
    #[arg(long)]
    init: Option<PathBuf>,
    /// Measure ρ against this constraints file.
    #[arg(long, conflicts_with = "init")]
    constraints: Option<PathBuf>,
    /// Also report how far the boundary vertices are from the unit sphere (`--target ball`
    /// maps; exit 1 above 1e-9).
    #[arg(long)]
    sphere: bool,
    /// Refuse meshes with more tets (and files larger than such a mesh's text); 0 = no limit.
    #[arg(long, default_value_t = DEFAULT_MAX_ELEMENTS)]
    max_tets: usize,
}

pub fn run_volmap(a: VolmapArgs) -> foldfree::Result<()> {
    use foldfree::vol::job::{run_volmap_job, ConstraintSource, VolmapJob};
    let constraints = match (a.fix_boundary, a.constraints, a.target) {
        (true, None, None) => ConstraintSource::FixBoundary,
        (false, Some(p), None) => ConstraintSource::File(p),
        (false, None, Some(_)) => ConstraintSource::Ball,
        _ => {
            return Err(foldfree::Error::Usage(
                "volmap needs one of --fix-boundary, --constraints FILE, --target ball".into(),
            ))
        }
    };
    let mut options = read_tuning(a.tuning.as_ref())?.volmap;
    if a.no_refine {
        options.ball_refine_rounds = 0;
    }
    if let Some(n) = a.max_iters {
        options.newton.max_iters = n;
        options.penalty.max_iters = n;
        if let Some(p) = options.post.as_mut() {
            p.max_iters = n;
        }
    }
    let job = VolmapJob {
        rest: a.rest,
        init: a.init,
        constraints,
        output: a.output,
        report: a.report,
        write_constraints: a.write_constraints,
        write_rest: a.write_rest,
        quiet: a.quiet,
        max_tets: element_limit(a.max_tets),
        options,
        backend: a.backend,
        device: a.device,
        validation: a.validation,
    };
    let r = run_volmap_job(&job)?;
    eprintln!("{r}");
    if !r.constraints_met {
        // Written (fold-free) but not the requested map: exit 3, as for a parameterization
        // whose stop test was not met.
        return Err(foldfree::Error::NotConverged(format!(
            "{}: position constraints NOT met (ρ {:.3e}, θ = {:.0e} at unit scale); the fold-free map was written",
            job.output.display(),
            r.written.rho,
            job.options.theta
        )));
    }
    Ok(())
}

pub fn run_volcheck(a: VolcheckArgs) -> foldfree::Result<()> {
    use foldfree::vol::job::{constraints_for, read_map, read_rest, ConstraintSource};
    let rest = read_rest(&a.rest, element_limit(a.max_tets))?;
    let x = read_map(&rest, &a.rest, &a.map)?;
    let targets = match (&a.init, &a.constraints) {
        (Some(p), _) => {
            let init = read_map(&rest, &a.rest, p)?;
            constraints_for(&rest, Some(&init), &ConstraintSource::FixBoundary)?
        }
        (None, Some(p)) => constraints_for(&rest, None, &ConstraintSource::File(p.clone()))?,
        (None, None) => Vec::new(),
    };
    let q = foldfree::vol::evaluate(&rest, &x, &targets);
    let mut json = serde_json::to_value(q).unwrap_or_default();
    let sphere = a
        .sphere
        .then(|| foldfree::vol::ball::sphere_deviation(&rest, &x));
    if let (Some(d), Some(o)) = (sphere, json.as_object_mut()) {
        o.insert("sphere_max_deviation".into(), d.into());
    }
    println!(
        "{}",
        serde_json::to_string_pretty(&json).unwrap_or_default()
    );
    if q.inverted > 0 {
        return Err(foldfree::Error::Vol(foldfree::vol::VolError::BadResult(
            format!("{}: {} inverted tet(s)", a.map.display(), q.inverted),
        )));
    }
    if let Some(d) = sphere.filter(|d| d.is_nan() || *d > 1e-9) {
        return Err(foldfree::Error::Vol(foldfree::vol::VolError::BadResult(
            format!(
                "{}: a boundary vertex is {d:.3e} off the unit sphere",
                a.map.display()
            ),
        )));
    }
    Ok(())
}

/// `foldfree volmap --help`: the exit codes.
pub const AFTER_HELP: &str = "\
Exit codes:
  0  a fold-free map meeting the constraints (ρ < θ) was written
  3  a fold-free map was written, but the constraints are not met (the message gives ρ)
  2  bad input or usage, found before any work (nothing written)
  1  anything else: no fold-free map found, I/O (nothing written)";
