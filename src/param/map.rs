//! The map of one disk (a whole disk mesh or one chart of an atlas): start map → solver →
//! the checks that keep a flipped or non-finite map from ever being returned.
//!
//! The default pipeline cannot end without a flip-free map on a valid disk. ADMM runs first (it
//! is the GPU path); when it stops without meeting its stop test — it stalled (μ at its cap and
//! no progress, see [`crate::param::admm::driver`]) or used up its iterations — it hands its best
//! flip-free map to the global solver ([`crate::param::global`]), whose every step is flip-free
//! and decreases the energy (largest flip-free step, then Armijo backtracking). So the result is
//! never worse than ADMM's best map, and the global solver's own stop test decides convergence.
//! [`SolverPath`] names what ran. Ctrl-C ends the run with the best map so far, no hand-off.
//!
//! With `bijective` (the default of every job) the map's boundary does not cross itself
//! either: the global solver keeps it apart ([`crate::param::global::scaffold`]), and a map of
//! ADMM's whose boundary overlaps (its per-face steps know nothing of the boundary) goes to the
//! bijective global solver from the start map, or from Tutte's when the start map is not an
//! embedding.
#![forbid(unsafe_code)]

use std::time::Instant;

use serde::Serialize;

use crate::init::{initial_map, normalize_area, InitMethod, TutteWeights};
use crate::mesh::{self, Topology, TriMesh};
use crate::param::admm::{self, AdmmOptions, AdmmProblem, History};
use crate::param::global::{self, scaffold, GlobalOptions};
use crate::Result;

/// Which solver runs after the start map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum SolverChoice {
    /// Output the start map as is.
    None,
    /// ADMM on the chosen backend; the global solver finishes when ADMM stops short.
    Admm,
    /// The global proxy/Newton solver ([`crate::param::global`]) on the CPU.
    Global,
}

impl SolverChoice {
    /// The name the CLI and the report use.
    pub fn name(self) -> &'static str {
        match self {
            SolverChoice::None => "none",
            SolverChoice::Admm => "admm",
            SolverChoice::Global => "global",
        }
    }
}

/// ADMM on a Vulkan device: the context, whether to time every kernel (`--profile`), and
/// how submissions reach the queue (`None`: one waited-for submission per batch; see
/// [`admm::vulkan::Slicing`] for an asynchronous job's slices).
#[derive(Clone, Debug)]
pub struct OnDevice<'a> {
    pub ctx: &'a crate::gpu::Context,
    pub profile: bool,
    pub slicing: Option<admm::vulkan::Slicing>,
}

impl<'a> OnDevice<'a> {
    /// Plain batches, no profiling.
    pub fn new(ctx: &'a crate::gpu::Context) -> OnDevice<'a> {
        OnDevice {
            ctx,
            profile: false,
            slicing: None,
        }
    }
}

/// What a running solve reports: every residual check of ADMM, every iteration of the global
/// solver (so a host can show progress whichever runs; Ctrl-C reaches both through
/// [`AdmmOptions::stop`]).
#[derive(Clone, Copy, Debug)]
pub enum Progress<'a> {
    Admm(&'a History),
    Global(&'a global::GlobalIteration),
}

/// The solvers that produced a map, in order.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub enum SolverPath {
    /// The start map.
    #[default]
    #[serde(rename = "none")]
    None,
    /// ADMM alone (it met its stop test, or was interrupted).
    #[serde(rename = "admm")]
    Admm,
    /// ADMM, then the global solver from ADMM's best flip-free map.
    #[serde(rename = "admm+global")]
    AdmmGlobal,
    /// The global solver alone.
    #[serde(rename = "global")]
    Global,
}

impl SolverPath {
    /// The name the report and the CLI use.
    pub fn name(self) -> &'static str {
        match self {
            SolverPath::None => "none",
            SolverPath::Admm => "admm",
            SolverPath::AdmmGlobal => "admm+global",
            SolverPath::Global => "global",
        }
    }

    /// The path of several charts: the longest any chart took (`admm+global` once one chart
    /// needed the hand-off).
    pub fn combine(self, other: SolverPath) -> SolverPath {
        let rank = |p: SolverPath| match p {
            SolverPath::None => 0,
            SolverPath::Admm => 1,
            SolverPath::Global => 2,
            SolverPath::AdmmGlobal => 3,
        };
        if rank(other) > rank(self) {
            other
        } else {
            self
        }
    }
}

/// What [`compute_map`] produced.
pub struct MapOutput {
    /// #V flip-free, finite UVs.
    pub uv: Vec<[f64; 2]>,
    /// Flipped faces of the start map.
    pub init_flips: usize,
    /// Maps replaced by Tutte's before a solve, by reason.
    pub tutte_starts: crate::report::TutteStarts,
    /// The ADMM run, when it ran.
    pub admm: Option<admm::AdmmResult>,
    /// The global solver's run, when it ran (alone, or after ADMM's hand-off).
    pub global: Option<global::GlobalResult>,
    /// Proxy iterations of ADMM's SD start (0 when none ran; see [`compute_map`]).
    pub start_proxy_iterations: usize,
    pub path: SolverPath,
    /// Per-kernel device times (Vulkan with `profile`).
    pub kernel_times: Option<admm::vulkan::KernelTimes>,
    /// Bytes the kernels move per iteration (Vulkan).
    pub bytes_per_iteration: Option<u64>,
    pub seconds_init: f64,
    pub seconds_solve: f64,
}

impl MapOutput {
    /// `uv` as it is, with no solver run on it (path `none`).
    pub fn unsolved(uv: Vec<[f64; 2]>, init_flips: usize, seconds_init: f64) -> MapOutput {
        MapOutput {
            uv,
            init_flips,
            tutte_starts: Default::default(),
            admm: None,
            global: None,
            start_proxy_iterations: 0,
            path: SolverPath::None,
            kernel_times: None,
            bytes_per_iteration: None,
            seconds_init,
            seconds_solve: 0.0,
        }
    }

    /// Whether the last solver that ran met its stop test (true when no solver ran): the
    /// global solver's when it ran (alone or after the hand-off), else ADMM's.
    pub fn converged(&self) -> bool {
        match (&self.global, &self.admm) {
            (Some(g), _) => g.converged(),
            (None, Some(a)) => a.converged(),
            (None, None) => true,
        }
    }

    /// One line saying why the run stopped, and how far from its stop test when it did not
    /// meet it.
    pub fn stop_summary(&self) -> String {
        let admm = self.admm.as_ref().map(|r| r.stop_summary());
        let global = self.global.as_ref().map(|g| g.stop_summary());
        let summary = match (admm, global) {
            (Some(a), Some(g)) => format!("{a}; handed to the global solver: {g}"),
            (Some(a), None) => a,
            (None, Some(g)) => g,
            (None, None) => "start map only".into(),
        };
        match self.start_proxy_iterations {
            0 => summary,
            n => format!("start: {n} proxy iterations; {summary}"),
        }
    }
}

/// A flip-free map at the 3D area, the map of last resort: Floater's mean-value Tutte map
/// (positive weights, so an embedding on the convex boundary, and far less compressed than
/// uniform weights where the surface is curved, which is where a solver started from it spends
/// its iterations), or the uniform one should rounding fold a thin face of the former or
/// `usable` refuse it (an energy that overflows on a face shrunk to nothing).
fn tutte_map(
    mesh: &TriMesh,
    topo: &Topology,
    area_3d: f64,
    usable: &dyn Fn(&[[f64; 2]]) -> bool,
) -> Result<Vec<[f64; 2]>> {
    if let Ok(mut t) = initial_map(mesh, topo, InitMethod::Tutte(TutteWeights::MeanValue)) {
        normalize_area(mesh, &mut t, area_3d);
        if crate::init::count_flips(&mesh.faces, &t) == 0 && usable(&t) {
            return Ok(t);
        }
    }
    // The uniform map whatever `usable` says: the callers' flip checks judge it.
    let mut t = initial_map(mesh, topo, InitMethod::Tutte(TutteWeights::Uniform))?;
    normalize_area(mesh, &mut t, area_3d);
    Ok(t)
}

/// The map of a validated disk mesh, shared by the CLI job and embedding hosts: start map, a
/// Tutte safety net when the start map folds, ADMM on `ctx` (Vulkan) or on the CPU with the
/// hand-off to the global solver (module docs), and the checks that keep a flipped or
/// non-finite map from ever being returned. With a context, any validation message it collected
/// fails the run. The entry points ([`crate::param::run_param`], the embedding engine) pass the
/// mesh at unit scale ([`crate::mesh::Scale`]) and map the result back.
#[allow(clippy::too_many_arguments)]
pub fn compute_map(
    mesh: &TriMesh,
    topo: &Topology,
    init: InitMethod,
    solver: SolverChoice,
    bijective: bool,
    opts: &AdmmOptions,
    device: Option<&OnDevice<'_>>,
    progress: &mut dyn FnMut(Progress<'_>),
) -> Result<MapOutput> {
    let t1 = Instant::now();
    let uv = initial_map(mesh, topo, init)?;
    compute_map_from(
        mesh, topo, uv, t1, solver, bijective, opts, device, progress,
    )
}

/// [`compute_map`] from a start map already computed (started at `t1`, for the report's
/// start-map time): the atlas has its charts' LSCM maps from choosing their seams.
#[allow(clippy::too_many_arguments)]
pub(crate) fn compute_map_from(
    mesh: &TriMesh,
    topo: &Topology,
    mut uv: Vec<[f64; 2]>,
    t1: Instant,
    solver: SolverChoice,
    bijective: bool,
    opts: &AdmmOptions,
    device: Option<&OnDevice<'_>>,
    progress: &mut dyn FnMut(Progress<'_>),
) -> Result<MapOutput> {
    let frames = mesh::frames::compute(mesh);
    let area_3d: f64 = frames.area.iter().sum();
    normalize_area(mesh, &mut uv, area_3d);
    let init_flips = crate::init::count_flips(&mesh.faces, &uv);
    let seconds_init = t1.elapsed().as_secs_f64();

    let t2 = Instant::now();
    let mut out = MapOutput::unsolved(Vec::new(), init_flips, seconds_init);
    let global_opts = GlobalOptions {
        stop: opts.stop.clone(),
        bijective,
        ..GlobalOptions::for_energy(opts.energy)
    };
    // A start the bijective global solver accepts: flip-free, finite energy and a boundary
    // that does not touch itself.
    let simple = |uv: &[[f64; 2]]| !bijective || global::scaffold::simple_boundary(uv, &mesh.faces);
    // The global solver from `uv` (from a Tutte map instead when `uv` folds, or when its energy
    // overflows — a face shrunk to ~1e-160 of the mean is flip-free but has SD = ∞: the solver
    // never crosses an infinite barrier, so it could not start), recorded in `out` as `path`.
    let finite = |uv: &[[f64; 2]]| {
        global::objective_and_gradient(mesh, &frames, opts.energy, uv)
            .is_ok_and(|(e, _)| e.is_finite())
    };
    let finish_globally = |uv: &mut Vec<[f64; 2]>,
                           folded: bool,
                           path: SolverPath,
                           out: &mut MapOutput,
                           progress: &mut dyn FnMut(Progress<'_>)|
     -> Result<()> {
        if out.tutte_starts.note(folded, finite(uv), simple(uv)) {
            // Tutte's map is an embedding: flip-free with a simple (convex) boundary.
            *uv = tutte_map(mesh, topo, area_3d, &finite)?;
        }
        let g = global::solve(mesh, &frames, uv, &global_opts, &mut |it| {
            progress(Progress::Global(it))
        })?;
        uv.clone_from(&g.uv);
        out.path = path;
        out.global = Some(g);
        Ok(())
    };
    match solver {
        SolverChoice::None => {}
        SolverChoice::Admm => {
            let problem = AdmmProblem::new(mesh, topo, &frames);
            let mut folded = init_flips > 0;
            if opts.energy == crate::param::Energy::SymmetricDirichlet {
                // SD's start: the conformal start map differs from SD's solution by area moved
                // across the whole mesh (protrusions the conformal map shrinks by orders of
                // magnitude must grow back), which ADMM's local steps carry one ring of faces
                // per iteration: 22 of 61 corpus disks stalled with μ at its cap. A proxy
                // step of the global solver (SLIM's local-global step: one Poisson solve
                // over the whole mesh) moves it in a few iterations. They run while each
                // lowers the energy by more than the global solver's own proxy switch (the
                // point where it judges the remaining change local and turns to Newton);
                // ADMM converges from there. Every step is flip-free, so the start is too.
                if out.tutte_starts.note(folded, finite(&uv), true) {
                    uv = tutte_map(mesh, topo, area_3d, &finite)?;
                }
                let start = global::solve(
                    mesh,
                    &frames,
                    &uv,
                    &GlobalOptions {
                        proxy_only: true,
                        // ADMM's steps do not keep the boundary apart: its result is checked
                        // below instead.
                        bijective: false,
                        ..global_opts.clone()
                    },
                    &mut |it| progress(Progress::Global(it)),
                )?;
                out.start_proxy_iterations = start.iterations;
                uv = start.uv;
                folded = false;
            }
            // A start map with flips (LSCM can fold) gets a flip-free safety net: never
            // output a flipped map because the solver could not unfold one.
            let fallback = if folded {
                Some(tutte_map(mesh, topo, area_3d, &finite)?)
            } else {
                None
            };
            let admm_start = uv.clone();
            let result = run_admm(
                &problem,
                &mesh.faces,
                &uv,
                fallback.as_deref(),
                opts,
                device,
                progress,
                &mut out,
            )?;
            uv.clone_from(&result.uv);
            out.path = SolverPath::Admm;
            if !result.converged() && !result.interrupted() {
                // The hand-off: from ADMM's best flip-free map (the start map or Tutte at
                // worst), every step of the global solver is flip-free and lowers the energy.
                finish_globally(
                    &mut uv,
                    result.flips > 0,
                    SolverPath::AdmmGlobal,
                    &mut out,
                    progress,
                )?;
            }
            let overlaps = !simple(&uv) && !result.interrupted();
            out.admm = Some(result);
            if overlaps {
                // ADMM's per-face steps know nothing of the boundary: a map whose boundary
                // overlaps is made again with the scaffold's triangles as more faces of the
                // same iteration (on the same device), from ADMM's start map when that is an
                // embedding, else from Tutte's; when that run stops short, the bijective
                // global solver finishes from its best map.
                let folded = crate::init::count_flips(&mesh.faces, &admm_start) > 0;
                let start =
                    if out
                        .tutte_starts
                        .note(folded, finite(&admm_start), simple(&admm_start))
                    {
                        tutte_map(mesh, topo, area_3d, &finite)?
                    } else {
                        admm_start
                    };
                let first = out.admm.take().expect("the ADMM run");
                match run_admm_scaffolded(&problem, mesh, &start, opts, device, progress, &mut out)?
                {
                    Some(mut r) if r.flips == 0 && simple(&r.uv) => {
                        // The scaffold kept its start's triangles, which bounds how far the
                        // boundary could slide; the global solver, whose scaffold follows the
                        // map, finishes (a few iterations where nothing was bound).
                        uv.clone_from(&r.uv);
                        r.iterations += first.iterations;
                        let interrupted = r.interrupted();
                        out.admm = Some(r);
                        out.path = SolverPath::Admm;
                        if !interrupted {
                            finish_globally(
                                &mut uv,
                                false,
                                SolverPath::AdmmGlobal,
                                &mut out,
                                progress,
                            )?;
                        }
                    }
                    _ => {
                        out.admm = Some(first);
                        let mut start = start;
                        finish_globally(
                            &mut start,
                            false,
                            SolverPath::AdmmGlobal,
                            &mut out,
                            progress,
                        )?;
                        uv = start;
                    }
                }
            }
        }
        SolverChoice::Global => {
            finish_globally(
                &mut uv,
                init_flips > 0,
                SolverPath::Global,
                &mut out,
                progress,
            )?;
        }
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

/// ADMM from the embedding `start` with SCAF's scaffold around it joined as more faces
/// ([`AdmmProblem::with_scaffold`]) on the same backend: a map ADMM keeps as its best has no
/// flipped face, chart or scaffold, so its boundary does not overlap. The scaffold keeps the
/// triangles and rest shapes of the start (ADMM's per-face state lives on them; rebuilding
/// would restart it), so its stiffness is pure bias here, never reset as in the global
/// solver: it gets the smallest weight, [`scaffold::WEIGHT_MIN`] of the chart's energy, and
/// only its faces' flip-free steps keep the boundary apart. `None` when the scaffold cannot
/// be built (a start whose boundary touches itself). The result's map is the chart's (#V).
fn run_admm_scaffolded(
    problem: &AdmmProblem,
    mesh: &TriMesh,
    start: &[[f64; 2]],
    opts: &AdmmOptions,
    device: Option<&OnDevice<'_>>,
    progress: &mut dyn FnMut(Progress<'_>),
    out: &mut MapOutput,
) -> Result<Option<admm::AdmmResult>> {
    let nv = mesh.positions.len();
    let boundary = scaffold::boundary_edges(&mesh.faces);
    let Some(s) = scaffold::Scaffold::build(bytemuck::cast_slice(start), nv, &boundary) else {
        return Ok(None);
    };
    let (e0, _) = admm::driver::map_energy(problem, &mesh.faces, start, opts.energy);
    let weight = scaffold::WEIGHT_MIN * e0 / s.faces.len().max(1) as f64;
    let mut uv = start.to_vec();
    uv.extend_from_slice(&s.frame);
    let faces: Vec<[u32; 3]> = mesh.faces.iter().chain(&s.faces).copied().collect();
    let joined = problem.with_scaffold(&mesh.faces, &s.faces, &uv, weight);
    let mut r = run_admm(&joined, &faces, &uv, None, opts, device, progress, out)?;
    r.uv.truncate(nv);
    Ok(Some(r))
}

/// ADMM on `ctx` (Vulkan) or on the CPU; device times and validation messages go into `out`.
#[allow(clippy::too_many_arguments)]
fn run_admm(
    problem: &AdmmProblem,
    faces: &[[u32; 3]],
    uv: &[[f64; 2]],
    fallback: Option<&[[f64; 2]]>,
    opts: &AdmmOptions,
    device: Option<&OnDevice<'_>>,
    progress: &mut dyn FnMut(Progress<'_>),
    out: &mut MapOutput,
) -> Result<admm::AdmmResult> {
    let mut solve = |exec: &mut dyn admm::driver::Executor| {
        admm::solve(problem, faces, uv, fallback, opts, exec, &mut |h| {
            progress(Progress::Admm(h))
        })
    };
    match device {
        Some(_) if opts.accel != admm::Accel::None => Err(crate::Error::Usage(
            "ADMM's Anderson acceleration (accel = \"anderson\") runs on the CPU backend only \
             (use --backend cpu)"
                .into(),
        )),
        Some(device) => {
            let ctx = device.ctx;
            let mut exec = admm::vulkan::VulkanExecutor::new(
                ctx,
                problem,
                opts.energy,
                opts.newton_iters,
                device.profile,
                device.slicing.clone(),
            )?;
            let r = solve(&mut exec)?;
            out.kernel_times = exec.kernel_times().cloned();
            out.bytes_per_iteration = Some(exec.bytes_per_iteration());
            ctx.check_validation_messages()?;
            Ok(r)
        }
        None => {
            let mut exec = admm::cpu::CpuExecutor::new(problem, opts.energy, opts.newton_iters)
                .with_accel(opts.accel, opts.aa_depth, opts.aa_every);
            solve(&mut exec)
        }
    }
}
