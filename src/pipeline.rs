//! The one-call jobs behind the CLI (`foldfree param`, `foldfree stats`), usable by any host:
//! the CLI only parses arguments, prints, and maps errors to exit codes.
#![forbid(unsafe_code)]

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::init::tutte::{tutte, TutteWeights};
use crate::mesh::{self, Topology, TriMesh};
use crate::metrics;
use crate::param::admm::{self, AdmmOptions, AdmmProblem, History};
use crate::param::Energy;
use crate::report::ParamReport;
use crate::{Error, Result};

/// Which start map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InitMethod {
    /// Tutte embedding (uniform or mean-value weights): flip-free, high distortion.
    Tutte(TutteWeights),
    /// Least-squares conformal map: near-optimal for MIPS, may flip a few faces (ADMM repairs).
    Lscm,
}

/// Which solver runs after the start map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SolverChoice {
    /// Output the start map as is.
    None,
    /// ADMM on the chosen backend.
    Admm,
    /// The global proxy/Newton solver ([`crate::param::global`]) on the CPU.
    Global,
}

/// Where ADMM runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendChoice {
    /// Vulkan on a real GPU; the CPU backend when the only device is a CPU rasterizer or none.
    Auto,
    Cpu,
    Vulkan,
}

/// When `foldfree param` cuts the mesh into disk charts.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum CutMode {
    /// Cut only meshes that are not a single disk (closed, higher genus, several holes, several
    /// components).
    #[default]
    Auto,
    /// Never cut: a mesh that is not a disk is an error.
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
    pub init: InitMethod,
    pub solver: SolverChoice,
    pub backend: BackendChoice,
    /// Vulkan device name substring or index.
    pub device: Option<String>,
    pub validation: bool,
    /// Per-kernel device times from timestamp queries (Vulkan backend; slows the run down,
    /// since every iteration is then its own submission).
    pub profile: bool,
    pub admm: AdmmOptions,
    pub validate: mesh::validate::ValidateOptions,
    /// Write the best flip-free map even when the solver did not converge (the run still
    /// reports the non-convergence; the CLI exits 1).
    pub keep_best: bool,
    pub cut: CutMode,
    pub cut_options: crate::param::cut::CutOptions,
    pub pack: crate::param::pack::PackOptions,
}

impl ParamJob {
    /// A job with the documented defaults: LSCM start, ADMM (MIPS), automatic backend.
    pub fn new(input: impl Into<PathBuf>, output: impl Into<PathBuf>) -> ParamJob {
        ParamJob {
            input: input.into(),
            output: output.into(),
            init: InitMethod::Lscm,
            solver: SolverChoice::Admm,
            backend: BackendChoice::Auto,
            device: None,
            validation: false,
            profile: false,
            admm: AdmmOptions::default(),
            validate: mesh::validate::ValidateOptions::default(),
            keep_best: false,
            cut: CutMode::Auto,
            cut_options: Default::default(),
            pack: Default::default(),
        }
    }
}

/// Output of [`run_param`]: the map and its report (already written to `job.output`).
pub struct ParamOutput {
    /// The mesh the UVs belong to: the input, or the input split along its seams when it was
    /// cut (same faces in the same order, one vertex per UV).
    pub mesh: TriMesh,
    /// One UV per vertex of `mesh`.
    pub uv: Vec<[f64; 2]>,
    pub report: ParamReport,
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => false,
    }
}

/// The start map of a disk mesh.
pub fn initial_map(mesh: &TriMesh, topo: &Topology, init: InitMethod) -> Result<Vec<[f64; 2]>> {
    let boundary = topo
        .boundary_loops
        .first()
        .ok_or_else(|| Error::Usage("the mesh has no boundary loop".into()))?;
    let uv = match init {
        InitMethod::Tutte(w) => tutte(&mesh.positions, &mesh.faces, boundary, w)?,
        InitMethod::Lscm => crate::init::lscm::lscm(&mesh.positions, &mesh.faces, boundary)?,
    };
    Ok(uv)
}

/// Scales `uv` about its centroid so its total |area| equals the 3D area: Jacobians are then
/// O(1), which keeps the device's f32 arithmetic well inside its range.
pub fn normalize_area(mesh: &TriMesh, uv: &mut [[f64; 2]], area_3d: f64) {
    let a = crate::init::total_signed_area(&mesh.faces, uv).abs();
    if !(a > 0.0 && a.is_finite() && area_3d > 0.0) {
        return;
    }
    let s = (area_3d / a).sqrt();
    let n = uv.len().max(1) as f64;
    let c = uv
        .iter()
        .fold([0.0, 0.0], |acc, p| [acc[0] + p[0] / n, acc[1] + p[1] / n]);
    for p in uv.iter_mut() {
        *p = [(p[0] - c[0]) * s, (p[1] - c[1]) * s];
    }
}

/// Opens a Vulkan context for `job`, or says why the CPU backend runs instead.
fn choose_backend(job: &ParamJob) -> Result<Option<crate::gpu::Context>> {
    use crate::gpu::{Context, ContextDesc};
    let desc = ContextDesc {
        validation: job.validation,
        device: job.device.clone(),
        ..ContextDesc::default()
    };
    match job.backend {
        BackendChoice::Cpu => Ok(None),
        BackendChoice::Vulkan => Ok(Some(Context::new(&desc)?)),
        BackendChoice::Auto => match Context::new(&desc) {
            // A CPU "GPU" (lavapipe) is slower than the native f64 backend on the same cores.
            Ok(ctx) if ctx.device_type() == crate::gpu::vk::PhysicalDeviceType::CPU => Ok(None),
            Ok(ctx) => Ok(Some(ctx)),
            Err(e) if e.is_unavailable() => Ok(None),
            Err(e) => Err(e.into()),
        },
    }
}

/// What [`compute_map`] produced.
pub struct MapOutput {
    /// #V flip-free, finite UVs.
    pub uv: Vec<[f64; 2]>,
    /// Flipped faces of the start map.
    pub init_flips: usize,
    /// The ADMM run, when the solver ran.
    pub admm: Option<admm::AdmmResult>,
    /// The global solver's run, when it ran.
    pub global: Option<crate::param::global::GlobalResult>,
    /// Per-kernel device times (Vulkan with `profile`).
    pub kernel_times: Option<admm::vulkan::KernelTimes>,
    /// Bytes the kernels move per iteration (Vulkan).
    pub bytes_per_iteration: Option<u64>,
    pub seconds_init: f64,
    pub seconds_solve: f64,
}

/// The map of a validated disk mesh, shared by the CLI job and embedding hosts: start map, a
/// Tutte safety net when the start map folds, ADMM on `ctx` (Vulkan) or on the CPU, and the
/// checks that keep a flipped or non-finite map from ever being returned. With a context, any
/// validation message it collected fails the run.
pub fn compute_map(
    mesh: &TriMesh,
    topo: &Topology,
    init: InitMethod,
    solver: SolverChoice,
    opts: &AdmmOptions,
    ctx: Option<&crate::gpu::Context>,
    profile: bool,
    progress: &mut dyn FnMut(&History),
) -> Result<MapOutput> {
    let t1 = Instant::now();
    let frames = mesh::frames::compute(mesh);
    let area_3d: f64 = frames.area.iter().sum();
    let mut uv = initial_map(mesh, topo, init)?;
    normalize_area(mesh, &mut uv, area_3d);
    let init_flips = crate::init::count_flips(&mesh.faces, &uv);
    let seconds_init = t1.elapsed().as_secs_f64();

    let t2 = Instant::now();
    let mut out = MapOutput {
        uv: Vec::new(),
        init_flips,
        admm: None,
        global: None,
        kernel_times: None,
        bytes_per_iteration: None,
        seconds_init,
        seconds_solve: 0.0,
    };
    if solver == SolverChoice::Admm {
        let problem = AdmmProblem::new(mesh, topo, &frames);
        // A start map with flips (LSCM can fold) gets a flip-free safety net: never output a
        // flipped map because the solver could not unfold one.
        let fallback = if init_flips > 0 {
            let mut t = initial_map(mesh, topo, InitMethod::Tutte(TutteWeights::Uniform))?;
            normalize_area(mesh, &mut t, area_3d);
            Some(t)
        } else {
            None
        };
        let mut solve = |exec: &mut dyn admm::driver::Executor| {
            admm::solve(
                &problem,
                &mesh.faces,
                &uv,
                fallback.as_deref(),
                opts,
                exec,
                progress,
            )
        };
        let result = match ctx {
            Some(_) if opts.accel != admm::Accel::None => {
                return Err(crate::Error::Usage(
                    "--accel anderson runs on the CPU backend only (use --backend cpu)".into(),
                ));
            }
            Some(ctx) => {
                let mut exec = admm::vulkan::VulkanExecutor::new(
                    ctx,
                    &problem,
                    opts.energy,
                    opts.newton_iters,
                    profile,
                )?;
                let r = solve(&mut exec)?;
                out.kernel_times = exec.kernel_times().cloned();
                out.bytes_per_iteration = Some(exec.bytes_per_iteration());
                let messages = ctx.take_validation_messages();
                if !messages.is_empty() {
                    return Err(crate::gpu::GpuError::Invalid(format!(
                        "{} Vulkan validation messages, first: {}",
                        messages.len(),
                        messages[0]
                    ))
                    .into());
                }
                r
            }
            None => {
                let mut exec =
                    admm::cpu::CpuExecutor::new(&problem, opts.energy, opts.newton_iters)
                        .with_accel(opts.accel, opts.aa_depth, opts.aa_every);
                solve(&mut exec)?
            }
        };
        uv.clone_from(&result.uv);
        out.admm = Some(result);
    } else if solver == SolverChoice::Global {
        use crate::param::global::{self, GlobalOptions};
        // A folded start (LSCM can fold) is replaced by uniform Tutte: the solver never
        // crosses det = 0, so it cannot unfold.
        if init_flips > 0 {
            uv = initial_map(mesh, topo, InitMethod::Tutte(TutteWeights::Uniform))?;
            normalize_area(mesh, &mut uv, area_3d);
        }
        let gopts = GlobalOptions {
            stop: opts.stop.clone(),
            ..GlobalOptions::for_energy(opts.energy)
        };
        let result = global::solve(mesh, &frames, &uv, &gopts, &mut |_| {})?;
        uv.clone_from(&result.uv);
        out.global = Some(result);
    }
    out.seconds_solve = t2.elapsed().as_secs_f64();
    let flips = crate::init::count_flips(&mesh.faces, &uv);
    if flips > 0 {
        return Err(crate::linalg::SolveError::Failed {
            what: format!(
                "the map has {flips} flipped faces (start map: {init_flips} flips); nothing was written"
            ),
        }
        .into());
    }
    if uv.iter().any(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(crate::linalg::SolveError::NonFinite {
            what: "UV coordinates".into(),
        }
        .into());
    }
    out.uv = uv;
    Ok(out)
}

/// `foldfree param`: load and validate, start map, solve, recover, measure, write the OBJ
/// (atomically; never over the input). `progress` sees every residual check.
pub fn run_param(job: &ParamJob, progress: &mut dyn FnMut(&History)) -> Result<ParamOutput> {
    let t0 = Instant::now();
    if same_file(&job.input, &job.output) {
        return Err(Error::Usage(format!(
            "refusing to overwrite the input {}",
            job.input.display()
        )));
    }
    let (mesh, topo, vreport) = mesh::load(&job.input, &job.validate)?;
    if job.cut == CutMode::Never || (job.cut == CutMode::Auto && topo.is_disk()) {
        topo.require_disk(&job.input)?;
    }
    let t_load = t0.elapsed().as_secs_f64();

    let ctx = if job.solver == SolverChoice::Admm {
        choose_backend(job)?
    } else {
        None
    };
    if job.cut == CutMode::Always || !topo.is_disk() {
        return run_atlas(
            job,
            mesh,
            &topo,
            &vreport,
            ctx.as_ref(),
            t0,
            t_load,
            progress,
        );
    }
    let map = compute_map(
        &mesh,
        &topo,
        job.init,
        job.solver,
        &job.admm,
        ctx.as_ref(),
        job.profile,
        progress,
    )?;
    let uv = map.uv;
    let m = metrics::evaluate(&mesh.positions, &mesh.faces, &uv, &topo.boundary_loops);
    let converged = map.admm.as_ref().map_or(true, |r| r.converged)
        && map.global.as_ref().map_or(true, |r| r.converged());
    let written = converged || job.keep_best;
    if written {
        mesh::obj::write_obj_with_uv(&job.output, &mesh, &uv).map_err(|source| Error::Io {
            path: job.output.clone(),
            source,
        })?;
    }

    let mut report = ParamReport {
        init: init_name(job.init).into(),
        init_flips: map.init_flips,
        backend: "cpu".into(),
        device: "host CPU".into(),
        solver: "none".into(),
        kernel_times: map.kernel_times,
        bytes_per_iteration: map.bytes_per_iteration,
        ..ParamReport::default()
    };
    if let Some(result) = map.admm {
        report.backend = result.backend.into();
        report.device = result.device;
        report.solver = "admm".into();
        report.energy = Some(energy_name(job.admm.energy).into());
        report.iterations = result.iterations;
        report.converged = Some(result.converged);
        report.mu_rel = Some(result.mu_rel_final);
        report.history = result.history;
    }
    report.written = written;
    if let Some(result) = map.global {
        report.solver = "global".into();
        report.energy = Some(energy_name(job.admm.energy).into());
        report.iterations = result.iterations;
        report.converged = Some(result.converged());
        report.global = Some(result);
    }
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

fn init_name(init: InitMethod) -> &'static str {
    match init {
        InitMethod::Tutte(TutteWeights::Uniform) => "tutte",
        InitMethod::Tutte(TutteWeights::MeanValue) => "tutte_mean_value",
        InitMethod::Lscm => "lscm",
    }
}

/// The cutting path of [`run_param`]: cut into disk charts, map each chart, pack the charts
/// into [0,1]², write the OBJ with the input's `v` (count and order) and one `vt` per split
/// vertex (`f v/vt`), and report seams, charts and packing.
#[allow(clippy::too_many_arguments)]
fn run_atlas(
    job: &ParamJob,
    input: TriMesh,
    topo: &Topology,
    vreport: &mesh::ValidationReport,
    ctx: Option<&crate::gpu::Context>,
    t0: Instant,
    t_load: f64,
    progress: &mut dyn FnMut(&History),
) -> Result<ParamOutput> {
    use crate::param::{cut, pack};
    let t_cut = Instant::now();
    let mut cutm = cut::cut_to_disks(&input, topo, &job.cut_options, &job.input)?;
    let mut extra = Vec::new();
    while extra.len() < job.cut_options.extra_seams {
        match most_shrunk_vertex(&cutm, &job.input)? {
            Some((v, ratio)) if ratio > job.cut_options.stretch_limit => extra.push(v),
            _ => break,
        }
        cutm = cut::cut_to_disks_through(&input, topo, &job.cut_options, &job.input, &extra)?;
    }
    let mut seconds_cut = t_cut.elapsed().as_secs_f64();

    // Map every chart; while some chart's boundary overlaps itself in UV, split it across
    // the overlap and map the two halves (charts left whole keep their maps).
    let mut base = cut::base_cut(&input, topo, &job.cut_options, &job.input, &extra)?;
    let mut splits: Vec<cut::Split> = Vec::new();
    let mut failed: Vec<cut::Split> = Vec::new();
    let mut cache: std::collections::HashMap<Vec<u32>, MapOutput> = Default::default();
    let maps = loop {
        let mut maps = Vec::with_capacity(cutm.charts.len());
        let mut new_splits = Vec::new();
        for faces in &cutm.charts {
            let (sub, global) = cutm.chart_mesh(faces);
            let sub_topo = Topology::build(&sub, &job.input)?;
            let map = match cache.remove(faces) {
                Some(m) => m,
                None => compute_map(
                    &sub,
                    &sub_topo,
                    job.init,
                    job.solver,
                    &job.admm,
                    ctx,
                    job.profile,
                    progress,
                )?,
            };
            let candidates = overlap_splits(&map.uv, &sub_topo, &global, &cutm.origin, faces);
            if !candidates.is_empty() {
                new_splits.push(candidates);
            }
            maps.push(map);
        }
        // Per overlapping chart, the first candidate seam that really splits it.
        let t = Instant::now();
        let before = splits.len();
        for candidates in new_splits {
            if splits.len() >= job.cut_options.overlap_splits {
                break;
            }
            for sp in candidates {
                if failed.contains(&sp) {
                    continue;
                }
                if base.try_split(topo, &sp) {
                    splits.push(sp);
                    break;
                }
                failed.push(sp);
            }
        }
        if splits.len() == before {
            break maps; // nothing overlaps, or no seam could split what does
        }
        let recut = base.finish(&input, topo, &job.input)?;
        seconds_cut += t.elapsed().as_secs_f64();
        for (faces, map) in cutm.charts.iter().zip(maps) {
            cache.insert(faces.clone(), map);
        }
        cutm = recut;
    };

    let mut uv = vec![[0.0f64; 2]; cutm.mesh.positions.len()];
    let mut chart_meshes = Vec::with_capacity(cutm.charts.len());
    let mut report = ParamReport {
        init: init_name(job.init).into(),
        backend: "cpu".into(),
        device: "host CPU".into(),
        solver: "none".into(),
        ..ParamReport::default()
    };
    let mut seconds_init = 0.0;
    let mut seconds_solve = 0.0;
    let mut converged = true;
    let mut largest = 0usize;
    for (faces, map) in cutm.charts.iter().zip(maps) {
        let (sub, global) = cutm.chart_mesh(faces);
        for (l, &g) in global.iter().enumerate() {
            uv[g as usize] = map.uv[l];
        }
        seconds_init += map.seconds_init;
        seconds_solve += map.seconds_solve;
        report.init_flips += map.init_flips;
        if let Some(result) = map.admm {
            report.backend = result.backend.into();
            report.device = result.device;
            report.solver = "admm".into();
            report.iterations += result.iterations;
            converged &= result.converged;
            // The convergence plot shows the largest chart.
            if faces.len() > largest {
                largest = faces.len();
                report.history = result.history;
                report.mu_rel = Some(result.mu_rel_final);
            }
        }
        if let Some(result) = map.global {
            report.solver = "global".into();
            report.iterations += result.iterations;
            converged &= result.converged();
            if faces.len() > largest {
                largest = faces.len();
                report.global = Some(result);
            }
        }
        chart_meshes.push((global, sub));
    }
    if report.solver != "none" {
        report.converged = Some(converged);
        report.energy = Some(energy_name(job.admm.energy).into());
    }

    let frames = mesh::frames::compute(&cutm.mesh);
    let chart_faces: Vec<Vec<[u32; 3]>> = cutm
        .charts
        .iter()
        .map(|fs| fs.iter().map(|&f| cutm.mesh.faces[f as usize]).collect())
        .collect();
    let refs: Vec<pack::ChartRef> = chart_meshes
        .iter()
        .zip(&chart_faces)
        .zip(&cutm.charts)
        .map(|(((global, _), faces), fs)| pack::ChartRef {
            vertices: global,
            faces,
            area_3d: fs.iter().map(|&f| frames.area[f as usize]).sum(),
        })
        .collect();
    let packing = pack::pack(&mut uv, &refs, &job.pack);

    let split_topo = Topology::build(&cutm.mesh, &job.input)?;
    let m = metrics::evaluate(
        &cutm.mesh.positions,
        &cutm.mesh.faces,
        &uv,
        &split_topo.boundary_loops,
    );
    if m.flips > 0 || uv.iter().any(|p| !(p[0].is_finite() && p[1].is_finite())) {
        return Err(crate::linalg::SolveError::Failed {
            what: format!(
                "the packed atlas has {} flipped faces or non-finite UVs; nothing was written",
                m.flips
            ),
        }
        .into());
    }
    report.written = converged || job.keep_best;
    if report.written {
        mesh::obj::write_obj_with_corner_uv(&job.output, &input, &uv, &cutm.mesh.faces).map_err(
            |source| Error::Io {
                path: job.output.clone(),
                source,
            },
        )?;
    }

    report.input = job.input.display().to_string();
    report.output = job.output.display().to_string();
    report.vertices = input.positions.len();
    report.faces = input.faces.len();
    report.interior_edges = topo.interior_edges.len() - cutm.seam_edges.len();
    report.boundary_loops = topo.boundary_loops.len();
    report.unreferenced_vertices = vreport.unreferenced_vertices.len();
    report.set_metrics(&m);
    report.atlas = Some(crate::report::AtlasReport {
        charts: cutm.charts.len(),
        chart_faces: cutm.charts.iter().map(Vec::len).collect(),
        texture_coordinates: uv.len(),
        seam_edges: cutm.seam_edges.len(),
        seam_length: cutm.seam_length,
        genus: topo.genus(),
        components: topo.components,
        packing_efficiency: packing.efficiency,
        margin: job.pack.margin,
        extra_seams: extra.len(),
        overlap_splits: splits.len(),
        seconds_cut,
    });
    report.seconds_load = t_load;
    report.seconds_init = seconds_init;
    report.seconds_solve = seconds_solve;
    report.seconds = t0.elapsed().as_secs_f64();
    Ok(ParamOutput {
        mesh: cutm.mesh,
        uv,
        report,
    })
}

/// Where to split a chart whose UV boundary crosses itself: for each of the first few
/// crossing pairs of boundary segments, a seam between the midpoints of the two boundary arcs
/// that separate them, so each half holds one of the two segments. Empty when the boundary is
/// simple. Several candidates because a seam can fail to exist (no path through the chart's
/// interior between the two points).
fn overlap_splits(
    uv: &[[f64; 2]],
    topo: &Topology,
    global: &[u32],
    origin: &[u32],
    faces: &[u32],
) -> Vec<crate::param::cut::Split> {
    const CANDIDATES: usize = 4;
    let Some(&face) = faces.first() else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for [s1, s2] in metrics::boundary_intersecting_pairs(uv, &topo.boundary_loops) {
        if out.len() == CANDIDATES {
            break;
        }
        let Some(l) = topo.boundary_loops.iter().find(|l| l.contains(&s1[0])) else {
            continue;
        };
        let n = l.len();
        let pos = |v: u32| l.iter().position(|&w| w == v);
        let (Some(mut i), Some(mut j)) = (pos(s1[0]), pos(s2[0])) else {
            continue;
        };
        if i > j {
            std::mem::swap(&mut i, &mut j);
        }
        let input = |k: usize| origin[global[l[k % n] as usize] as usize];
        let a = input((i + 1 + j) / 2);
        let m2 = (j + 1 + i + n) / 2;
        // Both sides of a seam are on the boundary: step on if the midpoints are one input
        // vertex.
        let Some(b) = (0..n).map(|d| input(m2 + d)).find(|&b| b != a) else {
            continue;
        };
        let sp = crate::param::cut::Split { a, b, face };
        if !out.contains(&sp) {
            out.push(sp);
        }
    }
    out
}

/// The input vertex around which a conformal (LSCM) map of its chart shrinks area the most,
/// with that shrink: (3D area share / UV area share), averaged over the vertex's faces by 3D
/// area. Conformal maps of long protrusions (ears, limbs, tails) shrink them exponentially; a
/// seam to the worst tip relieves it. `None` when no chart could be mapped.
fn most_shrunk_vertex(
    cutm: &crate::param::cut::CutMesh,
    file: &Path,
) -> Result<Option<(u32, f64)>> {
    let mut worst: Option<(u32, f64)> = None;
    for faces in &cutm.charts {
        if faces.len() < 2 {
            continue;
        }
        let (sub, global) = cutm.chart_mesh(faces);
        let sub_topo = Topology::build(&sub, file)?;
        let Ok(uv) = initial_map(&sub, &sub_topo, InitMethod::Lscm) else {
            continue;
        };
        let frames = mesh::frames::compute(&sub);
        let area_uv: Vec<f64> = sub
            .faces
            .iter()
            .map(|f| crate::init::face_area_2d(&uv, f))
            .collect();
        let (t3, tuv): (f64, f64) = (frames.area.iter().sum(), area_uv.iter().sum());
        if !(t3 > 0.0 && tuv > 0.0) {
            continue;
        }
        let mut num = vec![0.0f64; sub.positions.len()];
        let mut den = vec![0.0f64; sub.positions.len()];
        for (f, tri) in sub.faces.iter().enumerate() {
            let a3 = frames.area[f] / t3;
            let r = a3 / (area_uv[f] / tuv).max(1e-300);
            for &v in tri {
                num[v as usize] += a3 * r.min(1e12);
                den[v as usize] += a3;
            }
        }
        for v in 0..sub.positions.len() {
            if den[v] > 0.0 {
                let ratio = num[v] / den[v];
                if worst.map_or(true, |w| ratio > w.1) {
                    worst = Some((cutm.origin[global[v] as usize], ratio));
                }
            }
        }
    }
    Ok(worst)
}

fn energy_name(e: Energy) -> &'static str {
    match e {
        Energy::Mips => "mips",
        Energy::SymmetricDirichlet => "sd",
    }
}

/// Writes `report` as pretty JSON, atomically.
pub fn write_report(path: &Path, report: &ParamReport) -> Result<()> {
    let text =
        serde_json::to_string_pretty(report).map_err(|e| Error::Usage(format!("report: {e}")))?;
    mesh::obj::write_atomic(path, text.as_bytes()).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })
}
