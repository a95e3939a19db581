//! The `foldfree param` job, usable by any host: load and validate, map (one disk, or an atlas
//! of charts), measure, write. The CLI only parses arguments, prints, and maps the result to an
//! exit code (0 converged, 3 written but not converged, 2 bad input, 1 anything else).
#![forbid(unsafe_code)]

use std::path::PathBuf;
use std::time::Instant;

use crate::files::Outputs;
use crate::init::InitMethod;
use crate::mesh::formats::gltf;
use crate::mesh::{self, Scale, TriMesh};
use crate::metrics;
use crate::param::admm::AdmmOptions;
use crate::param::atlas::run_atlas;
use crate::param::map::{compute_map, OnDevice, Progress, SolverChoice};
use crate::param::Energy;
use crate::report::ParamReport;
use crate::{Error, Result};

pub use crate::gpu::BackendChoice;

/// When `foldfree param` cuts the mesh into disk charts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum CutMode {
    /// Cut only meshes that are not a single disk (closed, higher genus, several holes, several
    /// components).
    #[default]
    Auto,
    /// Never cut: a mesh that is not a disk is an error.
    #[cfg_attr(feature = "cli", value(name = "none"))]
    Never,
    /// Always go through the cutting and packing path, even for a disk (one chart, packed into
    /// the unit square).
    Always,
}

/// Everything `foldfree param` needs.
#[derive(Clone, Debug)]
pub struct ParamJob {
    pub input: PathBuf,
    pub output: PathBuf,
    /// The JSON report, committed with the map.
    pub report: Option<PathBuf>,
    /// Pictures of the map and the run, committed with the map.
    pub images: crate::viz::ImageOutputs,
    pub init: InitMethod,
    /// The solver of a disk mesh.
    pub solver: SolverChoice,
    /// The solver of each chart of an atlas. The global solver by default: on the corpus'
    /// closed meshes it reached equal or lower SD than ADMM + hand-off in a fifth to a twelfth
    /// of the time (BENCHMARKS.md, "Atlas chart solver").
    pub atlas_solver: SolverChoice,
    /// Every map bijective: no chart boundary overlaps itself (see
    /// [`crate::param::global::scaffold`]); `false` gives the unconstrained optimum, and an
    /// atlas then splits the charts that overlap (`CutOptions::overlap_splits`).
    pub bijective: bool,
    pub backend: BackendChoice,
    /// Vulkan device name substring or index.
    pub device: Option<String>,
    pub validation: bool,
    /// Per-kernel device times from timestamp queries (Vulkan backend; slows the run down,
    /// since every iteration is then its own submission).
    pub profile: bool,
    /// The energy; `None` picks MIPS (conformal) for a disk and symmetric Dirichlet
    /// (isometric) for a mesh cut into charts, where a conformal map shrinks protrusions
    /// (limbs, ears) by orders of magnitude and texel density with them.
    pub energy: Option<Energy>,
    /// ADMM settings; its `energy` is replaced by the one the job resolves (see `energy`).
    pub admm: AdmmOptions,
    pub validate: mesh::validate::ValidateOptions,
    pub cut: CutMode,
    pub cut_options: crate::param::cut::CutOptions,
    pub pack: crate::param::pack::PackOptions,
    /// glTF output: the `TEXCOORD_n` set to write (`None`: each primitive's next free one).
    pub uv_set: Option<u32>,
}

impl ParamJob {
    /// A job with the documented defaults: LSCM start, ADMM (MIPS on a disk, SD on an atlas),
    /// automatic backend.
    pub fn new(input: impl Into<PathBuf>, output: impl Into<PathBuf>) -> ParamJob {
        ParamJob {
            input: input.into(),
            output: output.into(),
            report: None,
            images: Default::default(),
            init: InitMethod::Lscm,
            solver: SolverChoice::Admm,
            atlas_solver: SolverChoice::Global,
            bijective: true,
            backend: BackendChoice::Auto,
            device: None,
            validation: false,
            profile: false,
            energy: None,
            admm: AdmmOptions::default(),
            // Pinched vertices are split into one per fan: a UV map has no reason to keep
            // touching sheets together.
            validate: mesh::validate::ValidateOptions {
                allow_pinched_vertices: true,
                ..Default::default()
            },
            cut: CutMode::Auto,
            cut_options: Default::default(),
            pack: Default::default(),
            uv_set: None,
        }
    }
}

/// Output of [`run_param`]: the map and its report (already written with the job's other
/// outputs; `report.converged` says whether the stop test was met).
pub struct ParamOutput {
    /// The mesh the UVs belong to, in the file's units: the input, or the input split along
    /// its seams when it was cut (same faces in the same order, one vertex per UV; its faces
    /// are the `vt` indices of the written OBJ).
    pub mesh: TriMesh,
    /// One UV per vertex of `mesh`.
    pub uv: Vec<[f64; 2]>,
    pub report: ParamReport,
}

/// Opens a Vulkan context for `job`, or None for the CPU backend. Anderson acceleration exists
/// on the CPU backend only: `Auto` means the CPU then.
fn choose_backend(job: &ParamJob) -> Result<Option<crate::gpu::Context>> {
    let backend = match job.backend {
        BackendChoice::Auto if job.admm.accel != crate::param::admm::Accel::None => {
            BackendChoice::Cpu
        }
        b => b,
    };
    Ok(crate::gpu::open_backend(
        backend,
        job.device.as_deref(),
        job.validation,
    )?)
}

/// `foldfree param`: check the outputs, load and validate, normalise the scale, start map,
/// solve, recover, measure, and commit the OBJ, report and pictures together (never over an
/// input; on any error nothing is written). `progress` sees every ADMM residual check and
/// every global-solver iteration.
pub fn run_param(job: &ParamJob, progress: &mut dyn FnMut(Progress<'_>)) -> Result<ParamOutput> {
    let t0 = Instant::now();
    if job.admm.accel != crate::param::admm::Accel::None && job.backend == BackendChoice::Vulkan {
        return Err(Error::Usage(
            "[admm] accel = \"anderson\" runs on the CPU backend only (use --backend cpu or auto)"
                .into(),
        ));
    }
    job.admm.validate()?;
    job.cut_options.validate()?;
    job.pack.validate()?;
    let mut outputs = Outputs::new();
    outputs.input(&job.input);
    outputs.output(&job.output, "map", &["obj", "glb", "gltf"])?;
    let gltf_out = plan_gltf_output(job, &mut outputs)?;
    if let Some(p) = &job.report {
        outputs.output(p, "report", &["json"])?;
    }
    job.images.plan(&mut outputs)?;
    let (file_mesh, topo, vreport, scene) = load(job)?;
    for bin in scene.iter().flat_map(|s| &s.external) {
        outputs.late_input(bin)?;
    }
    let pinched = topo.nonmanifold_vertices.len();
    let split = (pinched > 0).then(|| mesh::topology::split_pinched(&file_mesh, &topo));
    let topo = match &split {
        Some(m) => mesh::Topology::build(m, &job.input)?,
        None => topo,
    };
    if job.cut == CutMode::Never || (job.cut == CutMode::Auto && topo.is_disk()) {
        topo.require_disk(&job.input)?;
    }
    // Every solver works at unit scale; the OBJ keeps the file's `v`.
    let (scale, mesh) = Scale::normalized(split.as_ref().unwrap_or(&file_mesh));
    let t_load = t0.elapsed().as_secs_f64();
    let mut out = solve(job, mesh, &topo, &vreport, t0, t_load, progress)?;
    out.report.vertices = file_mesh.positions.len();
    out.report.pinched_vertices_split = pinched;
    // Pictures from the normalised mesh and its map (distortion colours compare the two).
    job.images
        .render(&out.mesh, &out.uv, &out.report.history, &mut outputs)?;
    // Back to the file's units, exactly (a power of two): a disk's UVs have the mesh's scale,
    // an atlas is packed into the unit square.
    if out.report.atlas.is_none() {
        for t in &mut out.uv {
            *t = [scale.length(t[0]), scale.length(t[1])];
        }
        // Coordinates near f64's limit (1.8e308) give a map at their scale that does not fit
        // in it: the input's units are the problem (exit 2, before anything is written), not
        // a solver failure.
        if out.uv.iter().flatten().any(|c| !c.is_finite()) {
            return Err(Error::Usage(format!(
                "{}: the map has the mesh's size, and in this file's units (coordinates up to \
                 {:.1e}) it overflows f64; scale the mesh down, or use --cut always (an atlas \
                 is packed into [0, 1]²)",
                job.input.display(),
                scale.factor
            )));
        }
    }
    for p in &mut out.mesh.positions {
        *p = scale.invert(*p);
    }
    let not_written = |e: String| {
        Error::Solve(crate::linalg::SolveError::Failed {
            what: format!("{}: {e}; nothing was written", job.output.display()),
        })
    };
    match (&gltf_out, &scene) {
        (Some((target, bin)), Some(scene)) => {
            let w = gltf::write_gltf(scene, &out.uv, &out.mesh.faces, job.uv_set, target)
                .map_err(not_written)?;
            out.report.uv_output = crate::report::UvOutput {
                format: "gltf",
                v_origin: "top-left",
                texcoord_sets: scene.uv_sets(job.uv_set).map_err(not_written)?,
            };
            outputs.set(&job.output, w.main);
            if let (Some(path), Some(bytes)) = (bin, w.bin) {
                outputs.set(path, bytes);
            }
        }
        _ => {
            let text = mesh::obj::obj_text_with_corner_uv(&file_mesh, &out.uv, &out.mesh.faces)
                .map_err(|e| not_written(e.to_string()))?;
            out.report.uv_output = crate::report::UvOutput::obj();
            outputs.set(&job.output, text.into_bytes());
        }
    }
    out.report.written = true;
    out.report.seconds = t0.elapsed().as_secs_f64();
    if let Some(p) = &job.report {
        outputs.set(p, report_json(&out.report)?);
    }
    outputs.commit()?;
    Ok(out)
}

/// For a `.glb` / `.gltf` output: the container to write and, for `.gltf`, the `.bin` beside
/// it (planned with the map: same stem, committed together). A glTF output needs a glTF input,
/// whose document it writes back.
fn plan_gltf_output(
    job: &ParamJob,
    outputs: &mut Outputs,
) -> Result<Option<(gltf::GltfTarget, Option<PathBuf>)>> {
    let ext = job
        .output
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    if !matches!(ext.as_deref(), Some("glb" | "gltf")) {
        return Ok(None);
    }
    if mesh::SurfaceFormat::from_path(&job.input)? != mesh::SurfaceFormat::Gltf {
        return Err(Error::Usage(format!(
            "{}: a glTF output needs a glTF input (.gltf or .glb), whose document it extends; \
             write an OBJ instead",
            job.output.display()
        )));
    }
    if ext.as_deref() == Some("glb") {
        return Ok(Some((gltf::GltfTarget::Glb, None)));
    }
    let bin = job.output.with_extension("bin");
    outputs.output(&bin, "map's buffer", &["bin"])?;
    let bin_uri = bin
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    Ok(Some((gltf::GltfTarget::Gltf { bin_uri }, Some(bin))))
}

/// [`mesh::load`], and for a glTF input also the document to write back (its `--uv-set` is
/// checked here, before any work).
fn load(
    job: &ParamJob,
) -> Result<(
    TriMesh,
    mesh::Topology,
    mesh::ValidationReport,
    Option<gltf::GltfScene>,
)> {
    if mesh::SurfaceFormat::from_path(&job.input)? != mesh::SurfaceFormat::Gltf {
        let (m, topo, report) = mesh::load(&job.input, &job.validate)?;
        return Ok((m, topo, report, None));
    }
    let (scene, topo, report) = mesh::validate::load_gltf(&job.input, &job.validate)?;
    scene
        .uv_sets(job.uv_set)
        .map_err(|e| Error::Usage(format!("{}: {e}", job.input.display())))?;
    Ok((scene.mesh.clone(), topo, report, Some(scene)))
}

/// The solve of [`run_param`] on the normalised mesh: one disk, or the atlas path.
fn solve(
    job: &ParamJob,
    mesh: TriMesh,
    topo: &crate::mesh::Topology,
    vreport: &mesh::ValidationReport,
    t0: Instant,
    t_load: f64,
    progress: &mut dyn FnMut(Progress<'_>),
) -> Result<ParamOutput> {
    let atlas = job.cut == CutMode::Always || !topo.is_disk();
    let solver = if atlas { job.atlas_solver } else { job.solver };
    let ctx = if solver == SolverChoice::Admm {
        choose_backend(job)?
    } else {
        None
    };
    let mut admm = job.admm.clone();
    admm.energy = job.energy.unwrap_or(if atlas {
        Energy::SymmetricDirichlet
    } else {
        Energy::Mips
    });
    if atlas {
        return run_atlas(
            job,
            mesh,
            topo,
            vreport,
            solver,
            &admm,
            ctx.as_ref(),
            t0,
            t_load,
            progress,
        );
    }
    let device = ctx.as_ref().map(|ctx| OnDevice {
        profile: job.profile,
        ..OnDevice::new(ctx)
    });
    let map = compute_map(
        &mesh,
        topo,
        job.init,
        solver,
        job.bijective,
        &admm,
        device.as_ref(),
        progress,
    )?;
    let m = metrics::evaluate(&mesh.positions, &mesh.faces, &map.uv, &topo.boundary_loops);
    // compute_map returns flip-free maps only: every one is written.
    let mut report = ParamReport {
        init: job.init.name().into(),
        init_flips: map.init_flips,
        tutte_starts: map.tutte_starts,
        backend: "cpu".into(),
        device: "host CPU".into(),
        solver: solver.name().into(),
        solver_path: map.path.name().into(),
        stop: map.stop_summary(),
        ..ParamReport::default()
    };
    if solver != SolverChoice::None {
        report.energy = Some(admm.energy.name().into());
        report.converged = Some(map.converged());
    }
    let uv = map.uv;
    report.kernel_times = map.kernel_times;
    report.bytes_per_iteration = map.bytes_per_iteration;
    if let Some(result) = map.admm {
        report.backend = result.backend.into();
        report.device = result.device;
        report.iterations_admm = result.iterations;
        report.mu_rel = Some(result.mu_rel_final);
        report.history = result.history;
    }
    if let Some(result) = map.global {
        report.iterations_global = result.iterations;
        report.global = Some(result);
    }
    report.iterations_start_proxy = map.start_proxy_iterations;
    report.iterations =
        report.iterations_start_proxy + report.iterations_admm + report.iterations_global;
    report.input = job.input.display().to_string();
    report.output = job.output.display().to_string();
    report.vertices = mesh.positions.len();
    report.faces = mesh.faces.len();
    report.interior_edges = topo.interior_edges.len();
    report.boundary_loops = topo.boundary_loops.len();
    report.unreferenced_vertices = vreport.unreferenced_vertices.len();
    report.set_metrics(&m);
    report.seconds_load = t_load;
    report.seconds_init = map.seconds_init;
    report.seconds_solve = map.seconds_solve;
    report.seconds = t0.elapsed().as_secs_f64();
    Ok(ParamOutput { mesh, uv, report })
}

/// `report` as pretty JSON.
fn report_json(report: &ParamReport) -> Result<Vec<u8>> {
    serde_json::to_vec_pretty(report).map_err(|e| {
        Error::Solve(crate::linalg::SolveError::Failed {
            what: format!("report serialisation: {e}"),
        })
    })
}
