//! `foldfree param`: the options a user decides; the solvers' knobs come from `--tuning`.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use foldfree::files::DEFAULT_MAX_ELEMENTS;
use foldfree::init::tutte::TutteWeights;
use foldfree::init::InitMethod;
use foldfree::param::{self, BackendChoice, CutMode, Energy, ParamJob, SolverChoice};

use crate::{element_limit, read_tuning};

#[derive(clap::Args)]
pub struct ParamArgs {
    /// Input surface: OBJ, PLY, OFF, STL or glTF (.gltf, .glb) by extension (triangles or
    /// polygons; polygons are fan-triangulated; STL corners, and a glTF primitive's vertices, at
    /// equal positions are welded).
    input: PathBuf,
    /// Output OBJ (the input's v and f order, plus one vt per vertex), or for a glTF input a
    /// .glb or .gltf (+ .bin beside it): the input document with a new TEXCOORD set.
    #[arg(short, long)]
    output: PathBuf,
    /// glTF output: the TEXCOORD_n set the map is written to (default: the next free one of
    /// each primitive; a set that exists, or would leave a gap, is refused).
    #[arg(long, value_name = "N")]
    uv_set: Option<u32>,
    /// Start map. Default: tutte with --solver global, lscm otherwise (also for the charts of
    /// an atlas, which the global solver maps unless --solver is given).
    #[arg(long, value_enum)]
    init: Option<InitMethod>,
    /// Solver. Default: admm for a disk (with the hand-off to the global solver when it
    /// stalls), global for the charts of a mesh cut into an atlas (unless --max-iters is
    /// given).
    #[arg(long, value_enum)]
    solver: Option<SolverChoice>,
    /// Distortion energy. Default: mips (conformal) for a disk, sd (isometric) for a mesh cut
    /// into charts, where a conformal map shrinks limbs and ears and texel density with them.
    #[arg(long, value_enum)]
    energy: Option<Energy>,
    #[arg(long, value_enum, default_value = "auto")]
    backend: BackendChoice,
    /// Vulkan device: a substring of its name or its index (see `foldfree devices`).
    #[arg(long)]
    device: Option<String>,
    /// ADMM iteration cap (the tuning file's `[admm] max_iters`).
    #[arg(long)]
    max_iters: Option<usize>,
    /// Solver knobs: `[admm]` (penalty μ, tolerances, acceleration, recovery, …) and `[cut]`
    /// (seam curvature, extra and splitting seams, stretch limit); see `foldfree dev tuning`
    /// for every key and its default.
    #[arg(long, value_name = "FILE.toml")]
    tuning: Option<PathBuf>,
    /// Write the JSON report here.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Cutting into disk charts: `auto` cuts meshes that are not a disk (closed, any genus,
    /// several holes or components), `none` refuses them, `always` also packs a disk.
    #[arg(long, value_enum, default_value = "auto")]
    cut: CutMode,
    /// Refuse meshes with more faces than this (and files far larger than such a mesh needs)
    /// before any heavy work; 0 = no limit.
    #[arg(long, default_value_t = DEFAULT_MAX_ELEMENTS)]
    max_faces: usize,
    /// Texture side in texels the charts are packed for (atlas path).
    #[arg(long, default_value_t = 1024)]
    resolution: u32,
    /// Empty texels between packed charts and to the texture's border.
    #[arg(long, default_value_t = 2)]
    padding: u32,
    /// Texels per unit of 3D length instead of a fixed resolution: the texture is the smallest
    /// square (a multiple of 4 texels) that holds the charts at this density.
    #[arg(long, conflicts_with = "resolution")]
    texel_density: Option<f64>,
    /// Texture pages the charts may be packed into (atlas path): page k is the UV tile
    /// [k, k+1] × [0, 1] (UDIM tile 1001 + k), each a texture of --resolution².
    #[arg(long, default_value_t = 1)]
    max_pages: u32,
    /// Enable the Khronos validation layer (any message fails the run).
    #[arg(long)]
    validation: bool,
    /// Per-kernel device times (Vulkan backend) in the report.
    #[arg(long)]
    profile: bool,
    /// No progress display.
    #[arg(short, long)]
    quiet: bool,
    /// Write the UV layout as SVG: faces coloured by conformal distortion σ1/σ2 (blue at 1,
    /// orange at 2 and above), flipped faces red, with a legend.
    #[arg(long, value_name = "PATH")]
    svg: Option<PathBuf>,
    /// Write the UV layout as PNG (same colours as --svg, no legend).
    #[arg(long, value_name = "PATH")]
    png: Option<PathBuf>,
    /// Side of the --png picture in pixels.
    #[arg(long, value_name = "N", default_value_t = 1024,
          value_parser = clap::value_parser!(u32).range(16..=8192))]
    png_size: u32,
    /// Write the convergence plot (residuals and energy against iteration): PNG when PATH
    /// ends in .png, else SVG; may be given twice (one of each).
    #[arg(long, value_name = "PATH")]
    plot: Vec<PathBuf>,
    /// Let the boundary of a map overlap itself (the unconstrained optimum, locally injective
    /// only): by default every map is bijective, the solver keeping each chart's boundary
    /// apart with a scaffold (SCAF), and an atlas never needs splitting seams.
    #[arg(long)]
    no_bijective: bool,
}

pub fn run_param(args: ParamArgs) -> foldfree::Result<()> {
    let tuning = read_tuning(args.tuning.as_ref())?;
    let solver = args.solver.unwrap_or(SolverChoice::Admm);
    // The global solver runs on the CPU with its own documented stopping rule.
    let admm_only = args.max_iters.is_some() || args.backend == BackendChoice::Vulkan;
    if solver == SolverChoice::Global && admm_only {
        return Err(foldfree::Error::Usage(
            "--solver global runs on the CPU with its own stopping rule: --backend vulkan, \
             --max-iters and the tuning file's [admm] table apply to ADMM only"
                .into(),
        ));
    }
    let init = match args.init {
        Some(i) => i,
        None if solver != SolverChoice::Admm => InitMethod::Tutte(TutteWeights::Uniform),
        None => InitMethod::Lscm,
    };
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // A second Ctrl-C while stopping falls through to the default handler's exit.
        let _ = ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
        });
    }
    let mut admm = tuning.admm;
    // The tuning's defaults are MIPS's; the job resolves the energy (and `for_energy` leaves
    // every energy-dependent setting `None`, so nothing else changes with it).
    admm.energy = args.energy.unwrap_or(Energy::Mips);
    if let Some(n) = args.max_iters {
        admm.max_iters = n;
    }
    admm.stop = Some(stop);
    let mut job = ParamJob::new(&args.input, &args.output);
    job.report = args.report.clone();
    job.uv_set = args.uv_set;
    job.images = foldfree::viz::ImageOutputs {
        layout_svg: args.svg.clone(),
        layout_png: args.png.clone(),
        png_size: args.png_size,
        plot_svg: args.plot.iter().find(|p| !is_png(p)).cloned(),
        plot_png: args.plot.iter().find(|p| is_png(p)).cloned(),
        ..Default::default()
    };
    job.init = init;
    job.solver = solver;
    job.bijective = !args.no_bijective;
    // An ADMM iteration cap says the user wants ADMM on the charts too.
    job.atlas_solver = args.solver.unwrap_or(if admm_only {
        SolverChoice::Admm
    } else {
        SolverChoice::Global
    });
    // With `[admm] accel = "anderson"` the library runs `auto` on the CPU (and refuses
    // `vulkan`): the acceleration exists on the CPU backend only.
    job.backend = args.backend;
    job.device = args.device.clone();
    job.validation = args.validation;
    job.profile = args.profile;
    job.admm = admm;
    job.energy = args.energy;
    job.validate.max_faces = Some(element_limit(args.max_faces));
    job.cut = args.cut;
    job.pack = foldfree::param::pack::PackOptions {
        resolution: args.resolution,
        padding: args.padding,
        texels_per_unit: args.texel_density,
        max_pages: args.max_pages,
    };
    job.cut_options = tuning.cut;

    // A spinner with the running solver's state: ADMM's residual checks, the global solver's
    // iterations (the hand-off, `--solver global`, and every chart of an atlas).
    let bar = if args.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        let b = indicatif::ProgressBar::new_spinner();
        b.set_style(
            indicatif::ProgressStyle::with_template("{spinner} {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
        );
        b
    };
    let out = param::run_param(&job, &mut |p| match p {
        param::Progress::Admm(h) => bar.set_message(format!(
            "ADMM it {}  μ·F {:.0}  primal {:.1e}  dual {:.1e}  E {:.6}",
            h.iteration, h.mu_rel, h.primal, h.dual, h.energy
        )),
        param::Progress::Global(g) => bar.set_message(format!(
            "global it {} ({:?})  E {:.6}  |∇E| {:.1e}",
            g.iteration, g.phase, g.energy, g.grad_norm
        )),
    });
    bar.finish_and_clear();
    let out = out?;
    let r = &out.report;
    eprintln!("{r}");
    if r.converged == Some(false) {
        return Err(foldfree::Error::NotConverged(format!(
            "{}: the stop test was not met ({}); the best flip-free map was written to {}",
            r.input, r.stop, r.output
        )));
    }
    Ok(())
}

/// `foldfree param --help`: the hand-off, the tuning file and the exit codes.
pub const AFTER_HELP: &str = "\
ADMM (the default solver) stops when its residuals and energy change are under tolerance and
the recovered map is flip-free. When it stalls (penalty at its cap and no progress) or reaches
--max-iters, it hands its best flip-free map to the global solver, which converges when its
energy stops decreasing; the report's solver_path says admm or admm+global.

Solver knobs (ADMM's penalty, tolerances, acceleration and recovery; the seams of the cut)
are read from a TOML file, --tuning FILE.toml; `foldfree dev tuning` prints every key with its
default (README.md, \"Tuning files\").

Exit codes:
  0  converged; the map was written
  3  a flip-free map was written, but the stop test was not met (iteration cap, Ctrl-C);
     the message and the report's `stop` say how far from it the run was
  2  bad input or usage (nothing written)
  1  anything else: Vulkan failure, I/O (nothing written)";

/// Whether `path` names a PNG file (by extension, any case).
fn is_png(path: &std::path::Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("png"))
}
