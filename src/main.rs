//! `foldfree`: the command-line front end. It parses arguments, calls the library, prints, and
//! maps errors to exit codes (0 success, 2 bad input or usage, 1 any other failure; `param` also
//! 3: a flip-free map was written but the stop test was not met).

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use clap::{Parser, Subcommand, ValueEnum};
use foldfree::init::tutte::TutteWeights;
use foldfree::init::InitMethod;
use foldfree::mesh;
use foldfree::param::admm::AdmmOptions;
use foldfree::param::Energy;

use foldfree::files::{Outputs, DEFAULT_MAX_ELEMENTS};
use foldfree::param::{self, BackendChoice, ParamJob, SolverChoice};

#[derive(Parser)]
#[command(
    name = "foldfree",
    version,
    about = "Foldover-free, low-distortion maps of meshes (Vulkan compute + CPU f64)"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Topology facts and the validation verdict of a mesh.
    Stats {
        /// Input surface: OBJ, PLY, OFF or STL by extension.
        input: PathBuf,
        /// Print JSON instead of text.
        #[arg(long)]
        json: bool,
        /// Refuse meshes with more faces (and files larger than such a mesh's text); 0 = no limit.
        #[arg(long, default_value_t = DEFAULT_MAX_ELEMENTS, value_parser = clap::value_parser!(usize))]
        max_faces: usize,
    },
    /// UV-parameterize a mesh without flipped triangles (a disk, or any manifold mesh cut into
    /// charts).
    #[command(after_help = PARAM_AFTER_HELP)]
    Param(Box<ParamArgs>),
    /// List the Vulkan devices and which one would be used.
    Devices,
    /// Render a UV-mapped OBJ (with `vt`) or glTF (a TEXCOORD set) textured with a checkerboard through its UVs, to PNG
    /// (offscreen Vulkan graphics).
    Render(RenderArgs),
    /// Approximate a triangle mesh by at most K planar polygons (Hu & Zhang 2017).
    Approx(ApproxArgs),
    /// Time `param` over meshes, energies and backends; prints a Markdown table.
    Bench {
        /// Input surface files, OBJ, PLY, OFF or STL (disk topology).
        meshes: Vec<PathBuf>,
        /// Energies to run (mips, sd).
        #[arg(long, value_enum, num_args = 1.., default_values = ["mips", "sd"])]
        energy: Vec<EnergyArg>,
        /// Backends to run (cpu, vulkan, auto).
        #[arg(long, value_enum, num_args = 1.., default_values = ["cpu", "vulkan"])]
        backend: Vec<BackendArg>,
        #[arg(long)]
        max_iters: Option<usize>,
        /// Directory for the output meshes.
        #[arg(long, default_value = "target/bench-out")]
        out_dir: PathBuf,
        /// Device profile instead: per-kernel timestamps of the ADMM iteration (`--max-iters`
        /// iterations, default 200), bytes and bandwidth against the device's streaming rate,
        /// dispatch overhead, and `param` end to end on Vulkan vs CPU (benches/gpu_profile.sh).
        #[arg(long)]
        profile: bool,
    },
    /// Foldover-free volumetric map of a tet mesh (Xu & Liu 2022).
    #[command(after_help = VOLMAP_AFTER_HELP)]
    Volmap(Box<VolmapArgs>),
    /// Write a constraints file (`vertex x y z`) twisting part of a tet mesh's boundary.
    VolmapConstraints(VolConstraintArgs),
    /// Check a tet map against its rest mesh: inverted tets, δ_t, ρ (exit 1 if inverted).
    Volcheck(VolcheckArgs),
}

#[derive(clap::Args)]
struct VolmapArgs {
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
    /// `--target ball`: cap on the Newton steps that lower the distortion while the boundary
    /// still slides on the sphere (0: none; the boundary is then fixed where the untangler
    /// left it).
    #[arg(long, value_name = "N", default_value_t = 150)]
    ball_relax_iters: usize,
    /// Where the untangler's per-tet energy and gradient run: `vulkan` (glsl/vol/untangle_tet.comp,
    /// f32), `cpu` (f64), or `auto` (Vulkan on a real GPU, the CPU when the only device is a CPU
    /// rasterizer such as lavapipe).
    #[arg(long, value_enum, default_value = "auto")]
    backend: BackendArg,
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
    /// Newton iteration cap per phase.
    #[arg(long)]
    max_iters: Option<usize>,
    /// Skip the post-optimisation.
    #[arg(long)]
    no_post: bool,
    /// Growth of the penalty weight λ_S per converged round.
    #[arg(long)]
    lambda_growth: Option<f64>,
    /// Cap on penalty rounds.
    #[arg(long)]
    max_rounds: Option<usize>,
    /// Relative residual of the Newton systems' PCG solves.
    #[arg(long)]
    cg_tol: Option<f64>,
    /// PCG preconditioner of the Newton systems.
    #[arg(long, value_parser = ["jacobi", "ic0", "amg"])]
    precond: Option<String>,
    /// Skip the default first stage (untangling the init with the constraints held exactly,
    /// Garanzha et al. 2021; for `--target ball` also the untangling with the boundary
    /// sliding on the sphere) and run the paper's guided deformation + penalty rounds only.
    #[arg(long)]
    no_untangle: bool,
    /// Refuse meshes with more tets (and files larger than such a mesh's text); 0 = no limit.
    #[arg(long, default_value_t = DEFAULT_MAX_ELEMENTS)]
    max_tets: usize,
    /// No progress display.
    #[arg(short, long)]
    quiet: bool,
}

#[derive(clap::Args)]
struct VolConstraintArgs {
    /// Rest tet mesh.
    rest: PathBuf,
    /// Output constraints file.
    #[arg(short, long)]
    output: PathBuf,
    /// Twist angle (degrees) of the far end about the longest bounding-box axis.
    #[arg(long, default_value_t = 60.0, allow_hyphen_values = true)]
    twist: f64,
    /// Fraction of the length held at each end (near end fixed, far end twisted).
    #[arg(long, default_value_t = 0.15)]
    fraction: f64,
    /// Refuse meshes with more tets (and files larger than such a mesh's text); 0 = no limit.
    #[arg(long, default_value_t = DEFAULT_MAX_ELEMENTS)]
    max_tets: usize,
}

#[derive(clap::Args)]
struct VolcheckArgs {
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

fn run_volmap(a: VolmapArgs) -> foldfree::Result<()> {
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
    let mut options = foldfree::vol::VolmapOptions::default();
    if let Some(n) = a.max_iters {
        options.newton.max_iters = n;
        options.penalty.max_iters = n;
        if let Some(p) = options.post.as_mut() {
            p.max_iters = n;
        }
    }
    let pre = match a.precond.as_deref() {
        Some("jacobi") => Some(foldfree::linalg::cg::Preconditioner::Jacobi),
        Some("ic0") => Some(foldfree::linalg::cg::Preconditioner::Ic0),
        Some(_) => Some(foldfree::linalg::cg::Preconditioner::Amg { block_size: 3 }),
        None => None,
    };
    for n in std::iter::once(&mut options.newton).chain(options.post.as_mut()) {
        if let Some(t) = a.cg_tol {
            n.cg.tolerance = t;
        }
        if let Some(p) = pre {
            n.cg.preconditioner = p;
        }
    }
    if a.no_post {
        options.post = None;
    }
    if let Some(g) = a.lambda_growth {
        options.lambda_growth = g;
    }
    if let Some(r) = a.max_rounds {
        options.max_rounds = r;
    }
    if a.no_untangle {
        options.untangle = None;
    }
    options.ball_relax = match (a.ball_relax_iters, options.ball_relax) {
        (0, _) | (_, None) => None,
        (n, Some(r)) => Some(foldfree::vol::newton::NewtonOptions { max_iters: n, ..r }),
    };
    let job = VolmapJob {
        rest: a.rest,
        init: a.init,
        constraints,
        output: a.output,
        report: a.report,
        write_constraints: a.write_constraints,
        quiet: a.quiet,
        max_tets: element_limit(a.max_tets),
        options,
        backend: backend_of(a.backend),
        device: a.device,
        validation: a.validation,
    };
    let r = run_volmap_job(&job)?;
    let q = &r.written;
    eprintln!(
        "foldfree volmap: {} tets, inverted init {} → output {}; δ_t {:.4} ({}, {} pinned), max {:.3e}, ρ {:.3e}{}, {:.2} s",
        q.tets,
        r.run.inverted_init,
        q.inverted,
        q.delta_t,
        // Every tet pinned: there is no free-tet mean to print (it is NaN, `null` in JSON).
        if q.delta_t_free.is_finite() {
            format!("free tets {:.4}", q.delta_t_free)
        } else {
            "no free tets".to_string()
        },
        q.pinned_tets,
        q.max_distortion,
        q.rho,
        if r.run.snapped { " (snapped)" } else { "" },
        r.run.seconds
    );
    let unmet = !r.constraints_met;
    if let Some(s) = &r.sphere_sliding {
        eprintln!(
            "  {:<20} {:>4} it {:>6} ε   {:>7.2} s  inverted {} → {} (boundary sliding on the sphere)",
            "ball untangle", s.iterations, s.eps_updates, s.seconds, s.inverted_start, s.inverted_left
        );
        if let Some(d) = s.delta_t_before_relax {
            eprintln!(
                "  {:<20} {:>4} it {:>9} {:>7.2} s  δ_t {d:.4} before (boundary sliding on the sphere)",
                "ball relax", s.relax_iterations, "", s.relax_seconds
            );
        }
    }
    for p in &r.run.phases {
        eprintln!(
            "  {:<20} {:>4} it {:>6} cg  {:>7.2} s  E {:.6e}  ρ {:.3e}",
            p.name, p.iterations, p.cg_iterations, p.seconds, p.energy, p.rho
        );
    }
    if unmet {
        // Written (fold-free) but not the requested map: exit 3, as for a parameterization
        // whose stop test was not met.
        return Err(foldfree::Error::NotConverged(format!(
            "{}: position constraints NOT met (ρ {:.3e}, θ = {:.0e} at unit scale); the fold-free map was written",
            job.output.display(),
            q.rho,
            job.options.theta
        )));
    }
    Ok(())
}

fn run_volmap_constraints(a: VolConstraintArgs) -> foldfree::Result<()> {
    use foldfree::vol::constraints::{constraints_text, twist_constraints};
    let mut outputs = Outputs::new();
    foldfree::vol::tetgen::tet_input(&mut outputs, &a.rest);
    outputs.output(&a.output, "constraints", &[])?;
    foldfree::vol::constraints::check_twist(a.twist, a.fraction)?;
    let rest = foldfree::vol::job::read_rest(&a.rest, element_limit(a.max_tets))?;
    let c = twist_constraints(&rest, a.twist, a.fraction);
    let header = format!(
        "foldfree volmap-constraints {} --twist {} --fraction {}\nvertex_index x y z (0-based)",
        a.rest.display(),
        a.twist,
        a.fraction
    );
    outputs.set(&a.output, constraints_text(&c, &header).into_bytes());
    outputs.commit()?;
    eprintln!(
        "wrote {} ({} constrained vertices)",
        a.output.display(),
        c.len()
    );
    Ok(())
}

fn run_volcheck(a: VolcheckArgs) -> foldfree::Result<()> {
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

#[derive(Clone, Copy, ValueEnum)]
enum InitArg {
    /// Tutte embedding, uniform weights (flip-free on a convex boundary).
    Tutte,
    /// Tutte embedding with Floater's mean-value weights.
    TutteMeanValue,
    /// Least-squares conformal map (may flip a few faces; ADMM repairs them).
    Lscm,
}

#[derive(Clone, Copy, ValueEnum)]
enum SolverArg {
    /// Output the start map.
    None,
    /// ADMM (per-face Newton, per-edge projection, dual update).
    Admm,
    /// Global proxy + projected-Newton solver with flip-free line search (CPU; Tutte start).
    Global,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum CutArg {
    Auto,
    None,
    Always,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum EnergyArg {
    /// Conformal: MIPS.
    Mips,
    /// Isometric: symmetric Dirichlet.
    Sd,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum AccelArg {
    /// Plain ADMM.
    None,
    /// Anderson acceleration with a residual safeguard (CPU backend only).
    Anderson,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum RecoveryArg {
    /// Least squares (Poisson, CG): spreads the consensus error over the mesh.
    Ls,
    /// The seed paper's breadth-first traversal: u(b) = u(a) + A_f (x_b − x_a).
    Bfs,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum BackendArg {
    /// Vulkan on a real GPU, else the CPU backend.
    Auto,
    Cpu,
    Vulkan,
}

#[derive(clap::Args)]
struct ParamArgs {
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
    /// Start map. Default: lscm with the ADMM solver, tutte otherwise.
    #[arg(long, value_enum)]
    init: Option<InitArg>,
    /// Solver. Default: admm for a disk (with the hand-off to the global solver when it
    /// stalls), global for the charts of a mesh cut into an atlas (unless ADMM-only options are
    /// given).
    #[arg(long, value_enum)]
    solver: Option<SolverArg>,
    /// Distortion energy. Default: mips (conformal) for a disk, sd (isometric) for a mesh cut
    /// into charts, where a conformal map shrinks limbs and ears and texel density with them.
    #[arg(long, value_enum)]
    energy: Option<EnergyArg>,
    #[arg(long, value_enum, default_value = "auto")]
    backend: BackendArg,
    /// Vulkan device: a substring of its name or its index (see `foldfree devices`).
    #[arg(long)]
    device: Option<String>,
    /// ADMM penalty as μ·#faces (default: 100 for MIPS, 1000 for SD; adapted automatically when
    /// the iteration oscillates).
    #[arg(long)]
    mu: Option<f64>,
    /// ADMM iteration cap.
    #[arg(long)]
    max_iters: Option<usize>,
    /// Least-squares re-synchronisation period (iterations, 0 = off).
    #[arg(long)]
    resync: Option<usize>,
    /// Keep μ fixed.
    #[arg(long)]
    fixed_mu: bool,
    /// Relative primal residual tolerance ‖Y − AS‖/‖AS‖.
    #[arg(long)]
    tol_primal: Option<f64>,
    /// Relative dual residual tolerance ‖ΔA S‖/‖AS‖.
    #[arg(long)]
    tol_dual: Option<f64>,
    /// Relative energy change tolerance between checks (met at 2 consecutive checks).
    #[arg(long)]
    tol_energy: Option<f64>,
    /// Checks without progress of the primal residual before μ is doubled (default 8 MIPS, 16 SD).
    #[arg(long)]
    stall_checks: Option<usize>,
    /// No residual balancing (by default μ is halved when the dual residual dominates a tight
    /// consensus).
    #[arg(long)]
    no_balance: bool,
    /// Newton steps per face per iteration.
    #[arg(long)]
    newton_iters: Option<u32>,
    /// Acceleration of the ADMM iteration; `anderson` runs on the CPU backend only.
    #[arg(long, value_enum, default_value = "none")]
    accel: AccelArg,
    /// Anderson history length (with `--accel anderson`).
    #[arg(long, default_value_t = 6, value_parser = clap::value_parser!(u64).range(1..=32))]
    aa_depth: u64,
    /// ADMM iterations per Anderson step (with `--accel anderson`).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=1000))]
    aa_every: u64,
    /// Plain ADMM iterations before Anderson acceleration starts (with `--accel anderson`;
    /// default 100 for MIPS, 0 for SD).
    #[arg(long)]
    aa_start: Option<u64>,
    /// While accelerating, lower μ (residual balancing) only once the relative energy change
    /// between checks is under this (default: no such condition).
    #[arg(long)]
    aa_balance_energy: Option<f64>,
    /// How per-vertex UVs are recovered from the ADMM per-face maps.
    #[arg(long, value_enum, default_value = "ls")]
    recovery: RecoveryArg,
    /// Write the JSON report here.
    #[arg(long)]
    report: Option<PathBuf>,
    /// Cutting into disk charts: `auto` cuts meshes that are not a disk (closed, any genus,
    /// several holes or components), `none` refuses them, `always` also packs a disk.
    #[arg(long, value_enum, default_value = "auto")]
    cut: CutArg,
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
    /// How strongly seams prefer curved regions (0 = shortest seams).
    #[arg(long, default_value_t = 1.0)]
    seam_curvature: f64,
    /// At most this many extra seams, each to the tip a conformal map shrinks most.
    #[arg(long, default_value_t = 8)]
    extra_seams: usize,
    /// At most this many seams splitting charts whose map's boundary overlaps itself; a chart
    /// still overlapping after them is cut into pieces that keep their map (every chart is
    /// then injective; 0 keeps overlapping charts).
    #[arg(long, default_value_t = 16)]
    overlap_splits: usize,
    /// Extra seams are cut while some vertex's area shrinks more than this factor.
    #[arg(long, default_value_t = 16.0)]
    stretch_limit: f64,
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
    /// Write the convergence plot (residuals and energy against iteration) as SVG.
    #[arg(long, value_name = "PATH")]
    plot: Option<PathBuf>,
    /// Write the convergence plot as PNG.
    #[arg(long, value_name = "PATH")]
    plot_png: Option<PathBuf>,
}

#[derive(clap::Args)]
struct ApproxArgs {
    /// Input surface, OBJ, PLY, OFF or STL (manifold, consistently oriented triangles).
    input: PathBuf,
    /// Largest number of planar regions.
    #[arg(short, value_name = "K")]
    k: usize,
    /// Output OBJ: the input's v and f order with moved vertices (each region planar).
    #[arg(short, long)]
    output: PathBuf,
    /// Also write one planar polygon per region (holes bridged in) to this OBJ.
    #[arg(long, value_name = "POLY.obj")]
    polygons: Option<PathBuf>,
    /// Write the polygons as triangles (ear clipping in each plane).
    #[arg(long)]
    triangulate: bool,
    /// Seed of the region-growing order.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Further runs with seeds seed+1, seed+2, … while the best run so far has a flipped or
    /// degenerate face (the best run is written; 0 = one run only).
    #[arg(long, default_value_t = 4)]
    restarts: usize,
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

fn run_approx(args: ApproxArgs) -> foldfree::Result<()> {
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
    opts.angle_deg = args.angle;
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
    outputs.set(
        &args.output,
        approx::mesh_obj(&out.positions, &m.faces).into_bytes(),
    );
    if let Some(p) = &args.polygons {
        outputs.set(p, out.polygons.to_obj(args.triangulate).into_bytes());
    }
    if let Some(p) = &args.report {
        outputs.set(p, serde_json::to_vec_pretty(r).unwrap_or_default());
    }
    outputs.commit()?;
    eprintln!(
        "foldfree approx: {} faces → {} regions (K = {}), {} polygons, {} corners, {:.2} s ({} run{}, seed {} kept)",
        r.faces,
        r.k_obtained,
        r.k_requested,
        r.polygons,
        r.corners,
        r.seconds_all_runs,
        r.runs,
        if r.runs == 1 { "" } else { "s" },
        r.seed_used
    );
    eprintln!(
        "  input→plane distance mean {:.4e} ({:.2e}·diag), max {:.4e}; planarity of output {:.2e}·diag; flipped {}, degenerate {}",
        r.mean_input_distance,
        r.mean_input_distance_rel,
        r.max_input_distance,
        r.max_planarity_deviation_rel,
        r.flipped_faces,
        r.degenerate_faces
    );
    for n in &r.notes {
        eprintln!("  note: {n}");
    }
    Ok(())
}

#[derive(clap::Args)]
struct RenderArgs {
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
    shade: ShadeArg,
    /// Refuse meshes with more faces or tets (and files larger than such a mesh's text); 0 = no
    /// limit.
    #[arg(long, default_value_t = DEFAULT_MAX_ELEMENTS)]
    max_elements: usize,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum ShadeArg {
    Checker,
    Normals,
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

fn run_render(args: RenderArgs) -> foldfree::Result<()> {
    use foldfree::gpu::{render_checker, Context, ContextDesc, RenderDesc};
    use foldfree::viz::render::{encode_rgba_png, read_with_uv};
    let mut outputs = Outputs::new();
    foldfree::vol::tetgen::tet_input(&mut outputs, &args.input);
    outputs.output(&args.output, "picture", &["png"])?;
    let max_elements = element_limit(args.max_elements);
    let (positions, uvs, indices) = match args.shade {
        ShadeArg::Checker => read_with_uv(&args.input, max_elements, args.uv_set)?.corners(),
        ShadeArg::Normals => surface_corners(&args.input, max_elements)?,
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
        shade: match args.shade {
            ShadeArg::Checker => foldfree::gpu::Shade::Checker,
            ShadeArg::Normals => foldfree::gpu::Shade::Normals,
        },
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
            ShadeArg::Checker => format!("checker {}", args.checker),
            ShadeArg::Normals => "flat normal colours".to_string(),
        }
    );
    Ok(())
}

/// `--max-faces` / `--max-tets`: 0 means no limit, for every command alike.
fn element_limit(n: usize) -> usize {
    if n == 0 {
        usize::MAX
    } else {
        n
    }
}

fn run_stats(input: PathBuf, json: bool, max_faces: usize) -> foldfree::Result<()> {
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

fn run_devices() -> foldfree::Result<()> {
    let ctx = foldfree::gpu::Context::new(&foldfree::gpu::ContextDesc::default())?;
    println!(
        "selected: {} ({})",
        ctx.device_name(),
        ctx.device_type_name()
    );
    Ok(())
}

fn energy_of(e: EnergyArg) -> Energy {
    match e {
        EnergyArg::Mips => Energy::Mips,
        EnergyArg::Sd => Energy::SymmetricDirichlet,
    }
}

fn backend_of(b: BackendArg) -> BackendChoice {
    match b {
        BackendArg::Auto => BackendChoice::Auto,
        BackendArg::Cpu => BackendChoice::Cpu,
        BackendArg::Vulkan => BackendChoice::Vulkan,
    }
}

fn run_bench(
    meshes: Vec<PathBuf>,
    energy: Vec<EnergyArg>,
    backend: Vec<BackendArg>,
    max_iters: Option<usize>,
    out_dir: PathBuf,
) -> foldfree::Result<()> {
    if meshes.is_empty() {
        return Err(foldfree::Error::Usage(
            "bench needs at least one mesh".into(),
        ));
    }
    let job = foldfree::bench::BenchJob {
        meshes,
        energies: energy.into_iter().map(energy_of).collect(),
        backends: backend.into_iter().map(backend_of).collect(),
        max_iters,
        out_dir,
    };
    if job.backends.contains(&BackendChoice::Vulkan) {
        let ctx = foldfree::gpu::Context::new(&foldfree::gpu::ContextDesc::default())?;
        let gbs = foldfree::bench::device_bandwidth(&ctx, 1 << 24, 5)?;
        println!(
            "device: {} — measured bandwidth (saxpy, 16M floats, best of 5): {gbs:.2} GB/s\n",
            ctx.device_name()
        );
    }
    let out = foldfree::bench::run_bench(&job, |line| eprintln!("{line}"))?;
    println!("{}", out.table);
    // A failed run is in the table, and its error decides the exit code.
    out.first_error.map_or(Ok(()), Err)
}

fn run_profile(
    meshes: Vec<PathBuf>,
    max_iters: Option<usize>,
    out_dir: PathBuf,
) -> foldfree::Result<()> {
    if meshes.is_empty() {
        return Err(foldfree::Error::Usage(
            "bench --profile needs at least one mesh".into(),
        ));
    }
    std::fs::create_dir_all(&out_dir).map_err(|source| foldfree::Error::Io {
        path: out_dir.clone(),
        source,
    })?;
    let ctx = foldfree::gpu::Context::new(&foldfree::gpu::ContextDesc::default())?;
    for mesh in &meshes {
        eprintln!("profiling {} …", mesh.display());
        let p = foldfree::bench::profile_mesh(&ctx, mesh, max_iters.unwrap_or(200), &out_dir)?;
        println!("{}", p.table());
    }
    Ok(())
}

fn run_param(args: ParamArgs) -> foldfree::Result<()> {
    let energy = args.energy.map(energy_of);
    let explicit_solver = args.solver.map(|s| match s {
        SolverArg::None => SolverChoice::None,
        SolverArg::Admm => SolverChoice::Admm,
        SolverArg::Global => SolverChoice::Global,
    });
    let solver = explicit_solver.unwrap_or(SolverChoice::Admm);
    // The global solver runs on the CPU with its own documented stopping rule.
    let admm_only = args.mu.is_some()
        || args.max_iters.is_some()
        || args.resync.is_some()
        || args.tol_primal.is_some()
        || args.tol_dual.is_some()
        || args.tol_energy.is_some()
        || args.newton_iters.is_some()
        || !matches!(args.accel, AccelArg::None)
        || matches!(args.recovery, RecoveryArg::Bfs)
        || matches!(args.backend, BackendArg::Vulkan);
    if solver == SolverChoice::Global && admm_only {
        return Err(foldfree::Error::Usage(
            "--solver global runs on the CPU with its own stopping rule: --backend vulkan, \
             --mu, --max-iters, --resync, --tol-*, --newton-iters, --accel and --recovery apply \
             to ADMM only"
                .into(),
        ));
    }
    if !matches!(args.accel, AccelArg::None) && matches!(args.backend, BackendArg::Vulkan) {
        return Err(foldfree::Error::Usage(
            "--accel anderson runs on the CPU backend only (use --backend cpu or auto)".into(),
        ));
    }
    let init = match args.init {
        Some(InitArg::Tutte) => InitMethod::Tutte(TutteWeights::Uniform),
        Some(InitArg::TutteMeanValue) => InitMethod::Tutte(TutteWeights::MeanValue),
        Some(InitArg::Lscm) => InitMethod::Lscm,
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
    let mut admm = AdmmOptions::for_energy(energy.unwrap_or(Energy::Mips));
    admm.mu_rel = args.mu;
    if let Some(n) = args.max_iters {
        admm.max_iters = n;
    }
    if let Some(r) = args.resync {
        admm.resync_every = r;
    }
    admm.adaptive_mu = !args.fixed_mu;
    if let Some(t) = args.tol_primal {
        admm.tol_primal = t;
    }
    if let Some(t) = args.tol_dual {
        admm.tol_dual = t;
    }
    if let Some(t) = args.tol_energy {
        admm.tol_energy = t;
    }
    admm.stall_checks = args.stall_checks;
    admm.balance = !args.no_balance;
    if let Some(n) = args.newton_iters {
        admm.newton_iters = n;
    }
    admm.accel = match args.accel {
        AccelArg::None => foldfree::param::admm::Accel::None,
        AccelArg::Anderson => foldfree::param::admm::Accel::Anderson,
    };
    admm.aa_depth = args.aa_depth as usize;
    admm.aa_every = args.aa_every as usize;
    admm.aa_start = args.aa_start.map(|n| n as usize);
    if let Some(t) = args.aa_balance_energy {
        admm.aa_balance_energy = t;
    }
    admm.recovery = match args.recovery {
        RecoveryArg::Ls => foldfree::param::recover::Recovery::LeastSquares,
        RecoveryArg::Bfs => foldfree::param::recover::Recovery::BreadthFirst,
    };
    let admm_accel_cpu_only = admm.accel != foldfree::param::admm::Accel::None;
    admm.stop = Some(stop);
    let mut job = ParamJob::new(&args.input, &args.output);
    job.report = args.report.clone();
    job.uv_set = args.uv_set;
    job.images = foldfree::viz::ImageOutputs {
        layout_svg: args.svg.clone(),
        layout_png: args.png.clone(),
        png_size: args.png_size,
        plot_svg: args.plot.clone(),
        plot_png: args.plot_png.clone(),
        ..Default::default()
    };
    job.init = init;
    job.solver = solver;
    // ADMM-only options say the user wants ADMM on the charts too.
    job.atlas_solver = explicit_solver.unwrap_or(if admm_only {
        SolverChoice::Admm
    } else {
        SolverChoice::Global
    });
    job.backend = match (args.backend, admm_accel_cpu_only) {
        // Anderson acceleration exists on the CPU backend only: `auto` means the CPU then.
        (BackendArg::Auto, true) => BackendChoice::Cpu,
        (b, _) => backend_of(b),
    };
    job.device = args.device.clone();
    job.validation = args.validation;
    job.profile = args.profile;
    job.admm = admm;
    job.energy = energy;
    job.validate.max_faces = Some(element_limit(args.max_faces));
    job.cut = match args.cut {
        CutArg::Auto => param::CutMode::Auto,
        CutArg::None => param::CutMode::Never,
        CutArg::Always => param::CutMode::Always,
    };
    job.pack = foldfree::param::pack::PackOptions {
        resolution: args.resolution,
        padding: args.padding,
        texels_per_unit: args.texel_density,
        max_pages: args.max_pages,
    };
    job.cut_options.curvature_weight = args.seam_curvature;
    job.cut_options.extra_seams = args.extra_seams;
    job.cut_options.overlap_splits = args.overlap_splits;
    job.cut_options.stretch_limit = args.stretch_limit;

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
    eprintln!(
        "foldfree: {} → {}: {} faces, backend {} ({}), init {}, solver {}{}",
        r.input,
        r.output,
        r.faces,
        r.backend,
        r.device,
        r.init,
        r.solver_path,
        match r.converged {
            Some(true) => format!(", converged in {} iterations", r.iterations),
            Some(false) => format!(
                ", NOT converged after {} iterations (best flip-free map written)",
                r.iterations
            ),
            None => String::new(),
        }
    );
    if r.solver_path == "admm+global" {
        eprintln!("  {}", r.stop);
    }
    eprintln!(
        "  flips {}  δcon mean {:.4} (area-weighted {:.4}, max {:.3})  MIPS {:.5}  SD {:.5}  boundary overlaps {}  {:.2} s",
        r.flips,
        r.delta_con_mean,
        r.delta_con_area_mean,
        r.delta_con_max,
        r.mips_energy,
        r.sd_energy,
        r.boundary_self_intersections,
        r.seconds
    );
    if let Some(a) = &r.atlas {
        eprintln!(
            "  cut: {} chart(s), {} seam edges (length {:.4}), {} vt; packed in {} page(s) of {}² with {} texels padding: efficiency {:.1}% of the area, {:.1}% of the texels",
            a.charts,
            a.seam_edges,
            a.seam_length,
            a.texture_coordinates,
            a.pages,
            a.resolution,
            a.padding,
            100.0 * a.packing_efficiency,
            100.0 * a.texel_coverage
        );
        if a.overlap_splits + a.injective_pieces > 0 {
            eprintln!(
                "  charts whose map overlapped itself: {} split by a seam and re-mapped, {} more cut into pieces that keep their map",
                a.overlap_splits, a.injective_pieces
            );
        }
    }
    if let Some(t) = &r.kernel_times {
        let per = |ns: u64| ns as f64 / 1e3 / t.iterations.max(1) as f64;
        eprintln!(
            "  device time per iteration: face_newton {:.1} µs, edge_project {:.1} µs, dual_update {:.1} µs; residual {:.1} µs per check",
            per(t.face_newton_ns),
            per(t.edge_project_ns),
            per(t.dual_update_ns),
            t.residual_ns as f64 / 1e3 / r.history.len().max(1) as f64
        );
    }
    if r.converged == Some(false) {
        return Err(foldfree::Error::NotConverged(format!(
            "{}: the stop test was not met ({}); the best flip-free map was written to {}",
            r.input, r.stop, r.output
        )));
    }
    Ok(())
}

/// `foldfree param --help`: the hand-off and the exit codes.
const PARAM_AFTER_HELP: &str = "\
ADMM (the default solver) stops when its residuals and energy change are under tolerance and
the recovered map is flip-free. When it stalls (penalty at its cap and no progress) or reaches
--max-iters, it hands its best flip-free map to the global solver, which converges when its
energy stops decreasing; the report's solver_path says admm or admm+global.

Exit codes:
  0  converged; the map was written
  3  a flip-free map was written, but the stop test was not met (iteration cap, Ctrl-C);
     the message and the report's `stop` say how far from it the run was
  2  bad input or usage (nothing written)
  1  anything else: Vulkan failure, I/O (nothing written)";

/// `foldfree volmap --help`: the exit codes.
const VOLMAP_AFTER_HELP: &str = "\
Exit codes:
  0  a fold-free map meeting the constraints (ρ < θ) was written
  3  a fold-free map was written, but the constraints are not met (the message gives ρ)
  2  bad input or usage, found before any work (nothing written)
  1  anything else: no fold-free map found, I/O (nothing written)";

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Stats {
            input,
            json,
            max_faces,
        } => run_stats(input, json, max_faces),
        Command::Param(args) => run_param(*args),
        Command::Devices => run_devices(),
        Command::Render(args) => run_render(args),
        Command::Approx(args) => run_approx(args),
        Command::Bench {
            meshes,
            max_iters,
            out_dir,
            profile: true,
            ..
        } => run_profile(meshes, max_iters, out_dir),
        Command::Bench {
            meshes,
            energy,
            backend,
            max_iters,
            out_dir,
            profile: false,
        } => run_bench(meshes, energy, backend, max_iters, out_dir),
        Command::Volmap(args) => run_volmap(*args),
        Command::VolmapConstraints(args) => run_volmap_constraints(args),
        Command::Volcheck(args) => run_volcheck(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("foldfree: error: {e}");
            ExitCode::from(e.exit_code() as u8)
        }
    }
}
