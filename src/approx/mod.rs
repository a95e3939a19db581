//! Planar-polygon approximation of a triangle mesh (Hu & Zhang 2017, "Shape approximation via
//! sparse optimization"): represent the surface by at most K planar polygons.
//!
//! The partition is found by the paper's method; the polygons are made from the planes, so a
//! fold-free, watertight polygon mesh follows from the construction, or nothing is written.
//!
//! Pipeline (all CPU; data flows one way, mesh → smoothing → partition → polygons → report):
//! 1. [`normals_l0`]: L0 smoothing of face normals (ALM; sparse systems in [`sparse`], sparse
//!    Cholesky with a CG fallback) → piecewise-constant normals;
//! 2. [`vertex_update`]: vertices follow the smoothed normals (Poisson-type least squares);
//!    their face areas weigh the clustering. Stages 1–2 do not depend on the seed and run
//!    once for all tries;
//! 3. [`cluster`]: region growing from the seed's faces + merging down to ≤ K regions, no
//!    region's normal cone wider than `max_cone_deg` while other merges are left, then
//!    [`lloyd`] relaxation (VSA's L2,1 step) so that boundaries run where the normal is equally
//!    far from both sides, and merges of corners whose planes meet far from the surface;
//! 4. [`outline`]: each region's plane is the least-squares plane of its input faces, corners
//!    are where the planes meet, each region's polygon (holes allowed) is its outline through
//!    those corners, triangulated in its plane ([`polygons`]), and the triangles of different
//!    polygons must not cross ([`intersect`]). Where the planes cannot realise the partition,
//!    the partition is split, merged or has faces moved — never the positions — and where
//!    that ends without a mesh after meeting a tunnel whose wall has no planes of its own, the
//!    polygons around it cover it (the handle closed);
//! 5. `refit`: each plane moved to the one nearest the region's input vertices (least
//!    absolute distances, the error the run reports) where the polygons built on them stay
//!    valid;
//! 6. `relabel`: border faces moved to the neighbouring region whose plane their vertices
//!    are nearer to (leaf faces, away from junctions, so the corners stay), the polygons built
//!    again and the planes refitted (stage 5 again) — kept only if valid and nearer.
//!
//! Several seeds are tried (`ApproxOptions::tries`, `restarts`); the nearest valid polygon
//! mesh is finished (every one, where that lost its planes): its partition filled to K as
//! VSA fills one ([`lloyd::fill`]) is realised too, once by the input's normals (the smoothing
//! flattened what the clustering could not see) and once by the smoothed ones. Each of the
//! three, if it has fewer than K regions, has the budget left go to halvings of its regions
//! into the two planes that fit each best ([`outline::spend_on_two_planes`]), then stages 5–6
//! again, kept if nearer; the nearest finished mesh is kept. If no draw is realised, the tries
//! are made again with each region on the principal plane its faces face
//! ([`geom::PlaneRule::Facing`]: a thin bent region's least-squares plane lies across it).
//! A closed connected input has one more candidate that needs no partition: the convex
//! polytope of K support planes (`hull.rs`), kept if nearer.
//! OUT.obj is the triangulation of the polygons: the connectivity inside each region is new.
#![forbid(unsafe_code)]

pub mod cluster;
pub mod geom;
mod hull;
pub mod intersect;
pub mod lloyd;
pub mod normals_l0;
pub mod outline;
pub mod polygons;
mod relabel;
pub mod sparse;
pub mod vertex_update;

use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use crate::linalg::SolveError;
use crate::mesh::{MeshError, Topology, TriMesh};
use cluster::ClusterOptions;
use geom::{dot, face_normals_areas, Plane, PlaneRule, V3};
use normals_l0::NormalL0Options;
use vertex_update::VertexUpdateOptions;

/// Errors of the approximation pipeline.
#[derive(Debug, thiserror::Error)]
pub enum ApproxError {
    #[error(transparent)]
    Mesh(#[from] MeshError),
    #[error("approx: {0}")]
    BadInput(String),
    #[error("approx: {0}")]
    Solve(#[from] SolveError),
    /// The result breaks the output's contract (folded, degenerate or non-finite faces); it
    /// is not written.
    #[error("approx: {0}")]
    BadOutput(String),
    /// No partition tried could be realised as a polygon mesh ([`outline::Defect`]); nothing
    /// is written.
    #[error("approx: {0}")]
    Unrealisable(String),
}

impl ApproxError {
    /// 2 for unusable input, 1 for a numerical failure.
    pub fn exit_code(&self) -> i32 {
        match self {
            ApproxError::Mesh(_) | ApproxError::BadInput(_) => 2,
            ApproxError::Solve(_) | ApproxError::BadOutput(_) | ApproxError::Unrealisable(_) => 1,
        }
    }
}

/// All parameters of [`approximate`].
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ApproxOptions {
    /// Largest number of planar regions.
    pub k: usize,
    /// Seed of the region-growing order.
    pub seed: u64,
    /// Partitions tried in any case (seeds `seed`, `seed + 1`, …); the valid polygon mesh with
    /// the least mean distance is kept. Which faces seed the regions decides the partition,
    /// and how far the planes' realisation must change it; independent partitions are
    /// independent draws of that, and the runs share the smoothing stages, so a few cost
    /// little (BENCHMARKS.md, planar approximation round 10).
    pub tries: usize,
    /// Further runs with seeds `seed + 1, seed + 2, …` while no run gave a valid polygon mesh
    /// (each a whole partition; [`outline::realise`] decides validity), or the best ends more
    /// than a quarter farther from the input than the partition it was given (a cascade of
    /// merges).
    pub restarts: usize,
    /// The stages' own parameters: 1, 2 and 3.
    pub normals: NormalL0Options,
    pub vertices: VertexUpdateOptions,
    pub partition: PartitionOptions,
}

/// Parameters of the partition stage ([`cluster`], [`lloyd`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PartitionOptions {
    /// Region-growing / merge angle θ in degrees.
    pub angle_deg: f64,
    /// θ is lowered (×0.75) while region growing gives fewer than K regions, down to this.
    pub min_angle_deg: f64,
    /// Largest normal cone half-angle (degrees) a clustering merge may create when others are
    /// left (see `cluster::ClusterOptions::max_cone_deg`).
    pub max_cone_deg: f64,
    /// Rounds of L2,1 Lloyd relaxation of the grown regions (see [`lloyd`]); 0 = off.
    pub lloyd_rounds: usize,
    /// Regions meeting at a vertex are merged while their planes' common point is farther than
    /// this × bbox diagonal from it (see `cluster::merge_unreachable_corners`) …
    pub corner_reach_rel: f64,
    /// … and farther than this × the vertex's distance to those planes.
    pub corner_amplification: f64,
}

impl Default for PartitionOptions {
    fn default() -> Self {
        PartitionOptions {
            angle_deg: 20.0,
            min_angle_deg: 3.0,
            max_cone_deg: 45.0,
            lloyd_rounds: 30,
            corner_reach_rel: 0.04,
            corner_amplification: 8.0,
        }
    }
}

impl ApproxOptions {
    /// Checks the user-facing settings against their ranges (usage errors, exit 2): at least
    /// one region, an angle in (0°, 180°], and at most 100 restarts (each is a whole run; a
    /// seed that 100 others could not beat is not found by the next million).
    pub fn validate(&self) -> Result<(), ApproxError> {
        if self.k == 0 {
            return Err(ApproxError::BadInput(
                "option k = 0 is outside its range [1, ∞)".into(),
            ));
        }
        let angle = self.partition.angle_deg;
        if !(angle.is_finite() && angle > 0.0 && angle <= 180.0) {
            return Err(ApproxError::BadInput(format!(
                "option angle = {angle} is outside its range (0, 180]"
            )));
        }
        for (name, v) in [("tries", self.tries), ("restarts", self.restarts)] {
            if v > 100 {
                return Err(ApproxError::BadInput(format!(
                    "option {name} = {v} is outside its range [0, 100]"
                )));
            }
        }
        Ok(())
    }

    pub fn new(k: usize) -> ApproxOptions {
        ApproxOptions {
            k,
            seed: 1,
            tries: 3,
            restarts: 4,
            normals: NormalL0Options::default(),
            vertices: VertexUpdateOptions::default(),
            partition: PartitionOptions::default(),
        }
    }
}

/// The pipeline's stages, for progress display.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Normals,
    Vertices,
    Cluster,
    Polygons,
}

impl Stage {
    pub const ALL: [Stage; 4] = [
        Stage::Normals,
        Stage::Vertices,
        Stage::Cluster,
        Stage::Polygons,
    ];
    pub fn name(self) -> &'static str {
        match self {
            Stage::Normals => "L0 normal smoothing",
            Stage::Vertices => "vertex update",
            Stage::Cluster => "clustering",
            Stage::Polygons => "polygons from the planes",
        }
    }
}

/// Seconds per stage.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimes {
    pub normals: f64,
    pub vertices: f64,
    pub cluster: f64,
    pub polygons: f64,
    /// Of the run returned; `ApproxReport::seconds_all_runs` adds the restarts.
    pub total: f64,
}

/// Everything the CLI writes to `--report`.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct ApproxReport {
    pub faces: usize,
    /// Seed of the run returned (see `ApproxOptions::restarts`; `None`: the convex polytope,
    /// which no seed's partition made) and how many realisations the search used (made ahead
    /// on a spare core and not used: not counted).
    pub seed_used: Option<u64>,
    pub runs: usize,
    /// Wall time of all runs together (what the caller waited).
    pub seconds_all_runs: f64,
    pub vertices: usize,
    pub k_requested: usize,
    pub k_obtained: usize,
    /// What the smoothing and the partition stage did (in the JSON among the report's own
    /// fields).
    #[serde(flatten)]
    pub partition: PartitionFacts,
    pub bbox_diagonal: f64,
    /// Headline error: mean over input vertices of the distance to their region's plane (a
    /// vertex on several regions counts the mean over them); planes are the final ones.
    pub mean_input_distance: f64,
    pub mean_input_distance_rel: f64,
    /// The same for the partition as clustered (before the realisation changed it), each
    /// region on its least-absolute-distances plane, as the output's (stage 5): what the
    /// realisation started from.
    pub partition_mean_input_distance: f64,
    pub max_input_distance: f64,
    pub max_input_distance_rel: f64,
    /// Planarity of the output: worst distance of an output vertex to a plane of its region.
    pub max_planarity_deviation: f64,
    pub max_planarity_deviation_rel: f64,
    /// Output faces whose normal points against their region's plane normal.
    pub flipped_faces: usize,
    /// Output faces with area ≤ 1e-12·diag².
    pub degenerate_faces: usize,
    /// Regions given away face by face to their neighbours' planes instead of a merge, where
    /// an outline crossed itself (see [`outline::realise`]; counted in `merges` too).
    pub regions_dissolved: usize,
    /// Regions split in two by the realisation (answering a defect, or spending the budget
    /// left on the worst fit), and regions merged into a neighbour or given away (see
    /// [`outline::realise`]).
    pub regions_split: usize,
    pub merges: usize,
    /// Of `regions_split`, halvings of a region into the two planes that fit it best, made on
    /// the kept mesh where no region's normal halving could be realised and budget was left
    /// (see [`outline::spend_on_two_planes`]).
    pub plane_halvings: usize,
    /// How each region's plane was chosen among its faces' principal planes: `least_squares`,
    /// or `facing` where no draw could be realised on the least-squares planes (see
    /// [`PlaneRule`]; a note says so); `None` (JSON `null`) for the polytope (`seed_used`
    /// `None`), whose planes are support planes, no fit of a region's faces.
    pub plane_rule: Option<PlaneRule>,
    pub polygons: usize,
    pub polygon_holes: usize,
    pub corners: usize,
    /// V − E + F of the input and of the polygon mesh: equal unless a region holds a handle
    /// of the input, which its planar polygon closes (each closed handle adds 2; a note says
    /// so).
    pub euler_input: i64,
    pub euler_polygons: i64,
    pub seconds: StageTimes,
    /// Plain-language notes on anything that did not meet the targets.
    pub notes: Vec<String>,
    pub options: ApproxOptions,
}

/// Result of [`approximate`].
#[derive(Clone, Debug)]
pub struct ApproxOutput {
    /// The polygons and their triangles (OUT.obj: [`polygons::PolygonMesh::to_obj`]).
    pub polygons: polygons::PolygonMesh,
    /// The region of each input face.
    pub face_cluster: Vec<u32>,
    /// The plane of each region (`face_cluster`'s labels index it).
    pub planes: Vec<Plane>,
    pub report: ApproxReport,
}

impl ApproxOutput {
    /// The output's contract: finite, no face flipped against its region's plane and none
    /// degenerate.
    /// A result that breaks it is not written (exit 1), with the counts and what to try.
    pub fn check_fold_free(&self) -> Result<(), ApproxError> {
        let r = &self.report;
        let finite = |p: &V3| p.iter().all(|c| c.is_finite());
        if let Some(v) = self.polygons.positions.iter().position(|p| !finite(p)) {
            return Err(ApproxError::BadOutput(format!(
                "output vertex {v} is not finite; nothing was written"
            )));
        }
        if r.flipped_faces + r.degenerate_faces == 0 {
            return Ok(());
        }
        Err(ApproxError::BadOutput(format!(
            "the best of {} run(s) at K = {} has {} flipped and {} degenerate face(s); nothing \
             was written (another K, --seed or more --restarts may avoid them)",
            r.runs, r.k_requested, r.flipped_faces, r.degenerate_faces
        )))
    }
}

/// Runs the whole pipeline on a validated mesh (see [`crate::mesh::load`]): the partitions of
/// `ApproxOptions::tries` seeds, then of further seeds while no valid polygon mesh came out or
/// the best lost its planes to a cascade of merges (see `ApproxOptions::restarts`); the valid
/// mesh nearest the input is returned. `progress` is told when each stage starts.
///
/// Why several seeds: which faces seed the regions decides the partition, and whether its
/// planes realise it as a polygon mesh is a property of the partition; another seed gives an
/// independent partition, so a fault that survives one run's splits and merges is often
/// absent from the next (BENCHMARKS.md, planar approximation rounds). Each seed costs a
/// clustering and a realisation; two run at a time (see `best_run`).
pub fn approximate(
    mesh: &TriMesh,
    topo: &Topology,
    opts: &ApproxOptions,
    progress: &mut dyn FnMut(Stage),
) -> Result<ApproxOutput, ApproxError> {
    opts.validate()?;
    // Work at unit scale (exactly: a power of two), report and return in the file's units.
    let (scale, normalized) = crate::mesh::Scale::normalized(mesh);
    let mut best = best_run(&normalized, topo, opts, progress)?;
    for p in best.polygons.positions.iter_mut() {
        *p = scale.invert(*p);
    }
    for pl in best.planes.iter_mut() {
        pl.d = scale.length(pl.d);
    }
    let r = &mut best.report;
    for x in [
        &mut r.bbox_diagonal,
        &mut r.mean_input_distance,
        &mut r.partition_mean_input_distance,
        &mut r.max_input_distance,
        &mut r.max_planarity_deviation,
    ] {
        *x = scale.length(*x);
    }
    Ok(best)
}

/// [`approximate`] at unit scale: the restarts.
fn best_run(
    mesh: &TriMesh,
    topo: &Topology,
    opts: &ApproxOptions,
    progress: &mut dyn FnMut(Stage),
) -> Result<ApproxOutput, ApproxError> {
    let t = Instant::now();
    let surface = outline::Surface::new(topo, mesh);
    let smoothed = smooth(&surface, opts, progress)?;
    // The polytope needs no partition: made beside the search, in the time its threads leave
    // idle (on the same surface: the search does not change it).
    std::thread::scope(|scope| {
        let polytope = scope.spawn(|| {
            let start = Instant::now();
            let r = hull::polytope(&surface, opts.k, opts.partition.lloyd_rounds);
            (r, start.elapsed().as_secs_f64())
        });
        let found = search(&surface, mesh, opts, &smoothed, t, progress);
        let polytope = polytope.join();
        let polytope = polytope.unwrap_or_else(|e| std::panic::resume_unwind(e));
        or_polytope(&surface, opts, &smoothed, found, polytope, t)
    })
}

/// The draws of [`best_run`]: on the least-squares planes of `surface`, then on the facing
/// ones (a surface of `mesh` of that rule, made only then); with the realisations made.
fn search(
    surface: &outline::Surface<'_>,
    mesh: &TriMesh,
    opts: &ApproxOptions,
    smoothed: &Smoothed,
    t: Instant,
    progress: &mut dyn FnMut(Stage),
) -> (Result<ApproxOutput, ApproxError>, usize) {
    let topo = surface.topo;
    let mut runs = Draws::default();
    // Every region on its least-squares plane first (the nearest plane); where no draw can be
    // realised so, every region on the principal plane its faces face ([`PlaneRule::Facing`]):
    // thin bent regions — a flange's rim, a bolt hole's wall — have their least-squares
    // planes across them, parallel to their neighbours'. The second pass makes the draws
    // made in any case (`tries`), not the restarts the first one spent: a mesh neither rule
    // realises is told so in the time of about two passes' tries plus the restarts.
    let tries_only = opts.tries.max(1) - 1;
    let last = opts.restarts.max(tries_only);
    let found = match best_on(opts, last, smoothed, surface, t, &mut runs, progress) {
        Err(ApproxError::Unrealisable(least_squares)) => {
            let mut facing = outline::Surface::new(topo, mesh);
            facing.rule = PlaneRule::Facing;
            let facing = best_on(opts, tries_only, smoothed, &facing, t, &mut runs, progress);
            facing.map_err(|e| match e {
                ApproxError::Unrealisable(facing) => ApproxError::Unrealisable(format!(
                    "no run of seeds {}..={} gave a valid polygon mesh of the input ({}) with \
                     at most K = {} regions on the regions' least-squares planes (the last: \
                     {least_squares}), nor of seeds {}..={} on the planes their faces face (the \
                     last: {facing}); nothing was written ({})",
                    opts.seed,
                    opts.seed.wrapping_add(last as u64),
                    topo.describe(),
                    opts.k,
                    opts.seed,
                    opts.seed.wrapping_add(tries_only as u64),
                    // The realisation of a partition is determined by it: other seeds help only
                    // where they draw other partitions.
                    if runs.seeds_one_partition() {
                        "every seed drew the same partition, so more --restarts cannot help; a \
                         larger K may"
                    } else {
                        "a larger K, or more --restarts, may"
                    }
                )),
                e => e,
            })
        }
        done => done,
    };
    (found, runs.made)
}

/// A closed connected input has one more candidate that needs no partition: the convex
/// polytope of K support planes ([`hull::polytope`], made beside the search, with its
/// seconds), kept if it is valid and nearer the input than `found` (what the search found,
/// with the realisations it made), or where the search realised nothing.
///
/// Why on every such run, not only where the search failed or lost its planes: which is
/// nearer is only known once both are measured, and the polytope costs a Lloyd iteration
/// over the faces, a small share of a search's time (BENCHMARKS, planar approximation round
/// 37). A rule for when to skip it would be one more threshold to be wrong on an unseen
/// part.
fn or_polytope(
    surface: &outline::Surface<'_>,
    opts: &ApproxOptions,
    smoothed: &Smoothed,
    (mut found, runs): (Result<ApproxOutput, ApproxError>, usize),
    (polytope, secs): (Option<outline::Realised>, f64),
    t: Instant,
) -> Result<ApproxOutput, ApproxError> {
    if let Ok(o) = &mut found {
        // What the caller waited: the polytope may have ended after the search.
        o.report.seconds_all_runs = t.elapsed().as_secs_f64();
    }
    let nearest = match &found {
        Ok(o) => Some((o.report.mean_input_distance, o.report.k_obtained)),
        Err(ApproxError::Unrealisable(_)) => None,
        Err(_) => return found,
    };
    let Some(r) = polytope else {
        trace(|| "no polytope: not one closed surface, or its facets do not close".into());
        return found;
    };
    let mut run = assess(surface, opts, smoothed, None, r, secs);
    let report = &mut run.report;
    let (mean, diag) = (report.mean_input_distance, surface.diag);
    let k = report.k_obtained;
    trace(|| {
        format!(
            "the polytope: {k} planes, {:.3e}·diag, {secs:.3} s beside the search",
            mean / diag
        )
    });
    if report.flipped_faces + report.degenerate_faces > 0 || nearest.is_some_and(|n| n.0 <= mean) {
        return found;
    }
    let why = nearest.map_or(
        "no partition into K regions could be realised by its planes".into(),
        |(d, k)| {
            let d = d / diag;
            format!("the nearest partition realised ({k} regions, {d:.2e}·diag) is farther away")
        },
    );
    let note = format!(
        "{why}: the polygon mesh is the convex polytope of {} support planes of the input \
         (K = {}), which closes its handles and fills its concavities",
        report.k_obtained, opts.k
    );
    report.notes.insert(0, note);
    (report.runs, report.seconds_all_runs) = (runs, t.elapsed().as_secs_f64());
    Ok(run.into())
}

/// Whether a realisation lost its planes to merges (a cascade): its mean distance to the
/// input ends more than a quarter above that of the partition it was given.
fn lost_planes(mean: f64, partition: f64) -> bool {
    mean > 1.25 * partition
}

/// What one draw gives: its realisation and partition (or why it has none), the realisations
/// it made, and its seed and its partition's fingerprint.
type Drawn = (Result<(Run, Partitioned), ApproxError>, usize, (u64, u64));

/// What the draws of a run made: the realisations, and each seed's partition (fingerprint).
#[derive(Default)]
struct Draws {
    made: usize,
    partitions: std::collections::HashMap<u64, u64>,
}

impl Draws {
    /// Whether more than one seed was drawn and all drew the same partition.
    fn seeds_one_partition(&self) -> bool {
        let mut p = self.partitions.values();
        let first = p.next();
        self.partitions.len() > 1 && p.all(|x| Some(x) == first)
    }
}

/// The draws of [`best_run`] on `surface` (its plane rule), seeds `opts.seed ..= opts.seed +
/// last` at most, the nearest valid one kept and finished; `runs` counts the realisations
/// made, `t` is when the whole run started.
fn best_on(
    opts: &ApproxOptions,
    last: usize,
    smoothed: &Smoothed,
    surface: &outline::Surface<'_>,
    t: Instant,
    runs: &mut Draws,
    progress: &mut dyn FnMut(Stage),
) -> Result<ApproxOutput, ApproxError> {
    let bad = |o: &Run| o.report.flipped_faces + o.report.degenerate_faces;
    // Another seed's partition is an independent draw of a realisation that lost its planes.
    let done = |o: &Run| {
        bad(o) == 0
            && !lost_planes(
                o.report.mean_input_distance,
                o.report.partition_mean_input_distance,
            )
    };
    // Fewest bad faces, then the smaller mean distance.
    let key = |o: &Run| (bad(o), o.report.mean_input_distance);
    let mut unrealised: Option<ApproxError> = None;
    let with_seed = |seed: u64| ApproxOptions {
        seed,
        ..opts.clone()
    };
    // Giving a region away stops the cascade of merges that a region whose outline crosses
    // itself starts, but it can start one of its own: `o`'s partition realised with merges
    // alone too (`alone`), and the mesh nearer the input kept.
    let alone = |seed: u64, part: &Partitioned, stop: &AtomicBool| {
        realise(surface, &with_seed(seed), smoothed, part, false, stop)
    };
    let nearer = |o: Run, alone: Result<Run, ApproxError>| match alone {
        Ok(m) if key(&m) < key(&o) => Ok(m),
        Ok(_) | Err(ApproxError::Unrealisable(_)) => Ok(o),
        Err(e) => Err(e),
    };
    // One seed: its partition, realised giving regions away, or with merges alone where
    // that realises nothing; with the realisations made. Where it gave a region away and
    // ended below K regions (merges the budget could not win back: a cascade), the merges-
    // alone realisation is made too — which ends nearest is only known once both are
    // realised. (One with all K regions is realised so only if kept.) The merges-alone
    // realisation is offered to the pool beside the other: a thread with nothing else to do
    // starts it at once, and it is stopped as soon as the other shows it is not wanted;
    // else it is made after the other, if wanted. Its result, when used, is the same
    // either way.
    let realised = |seed: u64, part: Partitioned| {
        let sub = with_seed(seed);
        let wanted = |first: &Result<Run, ApproxError>| match first {
            Err(ApproxError::Unrealisable(_)) => true,
            Ok(o) => o.report.regions_dissolved > 0 && o.report.k_obtained < sub.k,
            Err(_) => false,
        };
        let unwanted = AtomicBool::new(false);
        let (first, beside) = rayon::join(
            || {
                let never = AtomicBool::new(false);
                let first = realise(surface, &sub, smoothed, &part, true, &never);
                if !wanted(&first) {
                    unwanted.store(true, Ordering::Relaxed);
                }
                first
            },
            || (!unwanted.load(Ordering::Relaxed)).then(|| alone(seed, &part, &unwanted)),
        );
        let (out, made) = if wanted(&first) {
            // `unwanted` was never set: `beside` ran to its end.
            let second = beside.unwrap_or_else(|| alone(seed, &part, &AtomicBool::new(false)));
            match first {
                Ok(o) => (nearer(o, second), 2),
                _ => (second, 2),
            }
        } else {
            (first, 1)
        };
        (out.map(|o| (o, part)), made)
    };
    let draw = |seed: u64, progress: &mut dyn FnMut(Stage)| {
        let part = partition(surface, &with_seed(seed), smoothed, progress);
        progress(Stage::Polygons);
        let fingerprint = outline::hash_of(&part.labels);
        let (out, made) = realised(seed, part);
        (out, made, (seed, fingerprint))
    };
    // Budget a candidate left unused (no region's normal halving could be realised) goes to
    // two-plane halvings, then the planes are refitted and the borders relabelled again; kept
    // if nearer. Made on the finished draws' candidates only, before they are compared: which
    // is nearest is a property of the finished meshes, and a candidate with budget left may
    // end nearer than one without.
    let completed = |b: Run, part: &Partitioned| -> Run {
        if b.report.k_obtained >= opts.k {
            return b;
        }
        let t = Instant::now();
        let mut r = b.realised.clone();
        if outline::spend_on_two_planes(surface, &mut r, opts.k) == 0 {
            return b;
        }
        let (sub, polygons) = (with_seed(b.report.options.seed), b.report.seconds.polygons);
        let halved = finish(surface, &sub, smoothed, part, r, t, polygons);
        if key(&halved) < key(&b) {
            halved
        } else {
            b
        }
    };
    // A draw `(b, part)` finished: further candidates, independent of each other (each reads
    // only its partition), so made in parallel; the nearest is returned with the realisations
    // made:
    // - if it gave regions away with all K regions left, its partition realised with merges
    //   alone too;
    // - its partition with the budget its corner merges left spent ([`filled`]), once by the
    //   input's normals (the error measured) and once by the smoothed ones (the clustering's
    //   signal: where the input is noisy, its cuts follow the shape), realised: further
    //   candidates — they replace no draw, so no run ends farther from the input for them.
    let tail = |b: Run, part: Partitioned| -> Result<(Run, usize), ApproxError> {
        let seed = b.report.options.seed;
        let dissolved = b.report.regions_dissolved > 0 && b.report.k_obtained == opts.k;
        let first = || {
            if dissolved {
                nearer(b, alone(seed, &part, &AtomicBool::new(false))).map(|b| completed(b, &part))
            } else {
                Ok(completed(b, &part))
            }
        };
        let fills = || {
            let sub = with_seed(seed);
            let by_input = filled(surface, &sub, smoothed, &part, true);
            let by_smoothed = filled(surface, &sub, smoothed, &part, false)
                .filter(|fp| by_input.as_ref().is_none_or(|fi| fi.labels != fp.labels));
            let fin = |fp: Option<Partitioned>| {
                fp.map(|fp| {
                    let (out, made) = realised(seed, fp);
                    (out.map(|(o, fp)| completed(o, &fp)), made)
                })
            };
            let (a, b) = rayon::join(|| fin(by_input), || fin(by_smoothed));
            [a, b]
        };
        let (b, fills) = rayon::join(first, fills);
        let mut made = usize::from(dissolved);
        let mut best = b?;
        for (out, fill_made) in fills.into_iter().flatten() {
            made += fill_made;
            match out {
                Ok(o) if key(&o) < key(&best) => best = o,
                Ok(_) | Err(ApproxError::Unrealisable(_)) => {}
                Err(e) => return Err(e),
            }
        }
        Ok((best, made))
    };
    let tries = opts.tries.max(1);
    // The draws are independent (each only reads the smoothed surface). They are made in
    // waves of two seeds, always two (not the machine's core count), the search stopping
    // after a wave once `tries` draws are made and the nearest is `done` — so which draws are
    // made, and the mesh kept (the nearest of them all), do not depend on the machine; a
    // restart drawn beside the one that made it unnecessary is kept too: it is made anyway.
    // The draws before the first wave end that can stop the search are made in any case, and
    // are made in parallel (rayon; results in seed order, whichever finishes first).
    let certain = (2 * tries.div_ceil(2)).min(last + 1);
    // Every draw realised, in seed order. The index of the nearest of runs given by their
    // keys (ties go to the earlier seed), for the draws and the finished meshes alike.
    let mut drawn: Vec<(Run, Partitioned)> = Vec::new();
    let nearest = |keys: &mut dyn Iterator<Item = (usize, f64)>| {
        let i = keys
            .enumerate()
            .reduce(|a, b| if b.1 < a.1 { b } else { a });
        i.map(|(i, _)| i)
    };
    let nearest_draw = |d: &[(Run, Partitioned)]| nearest(&mut d.iter().map(|d| key(&d.0)));
    let absorb = |drawn: &mut Vec<(Run, Partitioned)>,
                  unrealised: &mut Option<ApproxError>,
                  made: Vec<Drawn>,
                  runs: &mut Draws|
     -> Result<(), ApproxError> {
        for (out, m, (seed, partition)) in made {
            runs.made += m;
            runs.partitions.insert(seed, partition);
            match out {
                Ok(d) => drawn.push(d),
                // Another seed's partition may be realisable.
                Err(e @ ApproxError::Unrealisable(_)) => *unrealised = Some(e),
                Err(e) => return Err(e),
            }
        }
        Ok(())
    };
    let seed_of = |j: usize| opts.seed.wrapping_add(j as u64);
    let on_two = |from: usize, to: usize, progress: &mut dyn FnMut(Stage)| {
        if to - from == 1 {
            vec![draw(seed_of(from), progress)]
        } else {
            progress(Stage::Cluster);
            (from..to)
                .into_par_iter()
                .map(|j| draw(seed_of(j), &mut |_| {}))
                .collect()
        }
    };
    let first = on_two(0, certain, progress);
    absorb(&mut drawn, &mut unrealised, first, runs)?;
    // When the last wave is one draw, the nearest draw so far is finished (`tail`) beside it
    // (the draw's seed and its tail): used if that draw is one of those finished below.
    let mut speculated = None;
    let mut i = certain;
    while i <= last && !nearest_draw(&drawn).is_some_and(|b| done(&drawn[b].0)) {
        let wave = (last + 1 - i).min(2);
        let made = match nearest_draw(&drawn) {
            Some(b) if i == last => {
                let (run, part) = drawn[b].clone();
                progress(Stage::Cluster);
                let seed = run.report.options.seed;
                let (d, t) = rayon::join(|| draw(seed_of(i), &mut |_| {}), || tail(run, part));
                speculated = Some((seed, t));
                vec![d]
            }
            _ => on_two(i, i + wave, progress),
        };
        absorb(&mut drawn, &mut unrealised, made, runs)?;
        i += wave;
    }
    // The nearest draw finished, or every draw where the nearest lost its planes: the tail
    // changes the ranking most where merges took planes (its fills win them back), so the
    // nearest unfinished draw says little about the nearest finished one then (BENCHMARKS,
    // planar approximation round 25). At most `last + 1` tails, on such runs only.
    if let Some(b) = nearest_draw(&drawn).filter(|&b| done(&drawn[b].0)) {
        drawn = vec![drawn.swap_remove(b)];
    }
    let tails: Vec<_> = drawn
        .into_iter()
        .map(|d| (speculated.take_if(|s| s.0 == d.0.report.options.seed), d))
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|(s, (run, part))| s.map_or_else(|| tail(run, part), |(_, t)| t))
        .collect();
    let mut finished = Vec::with_capacity(tails.len());
    for t in tails {
        let (run, made) = t?;
        runs.made += made;
        finished.push(run);
    }
    // Unrealisable: the last draw's defect (the caller says which draws failed).
    let Some(b) = nearest(&mut finished.iter().map(key)) else {
        return Err(unrealised.unwrap_or(ApproxError::Unrealisable(String::new())));
    };
    let mut best = finished.swap_remove(b);
    best.report.runs = runs.made;
    best.report.seconds_all_runs = t.elapsed().as_secs_f64();
    Ok(best.into())
}

/// What the seed-independent stages give every run: the L0-smoothed normals, the updated
/// vertices' face areas, and how long each stage took.
struct Smoothed {
    sm: normals_l0::NormalL0Result,
    /// Face areas of the updated surface (the vertices moved by the vertex update).
    a1: Vec<f64>,
    seconds_normals: f64,
    seconds_vertices: f64,
}

/// The stages before the clustering (which the seed decides): L0 normal smoothing and the
/// vertex update, run once for every seed tried.
fn smooth(
    s: &outline::Surface<'_>,
    opts: &ApproxOptions,
    progress: &mut dyn FnMut(Stage),
) -> Result<Smoothed, ApproxError> {
    let topo = s.topo;
    if opts.k == 0 {
        return Err(ApproxError::BadInput("K must be at least 1".into()));
    }
    // The realisation walks each vertex's faces as one fan, in one orientation (the CLI's
    // validation refuses other meshes; a library caller's topology is checked here).
    if let Some(&v) = topo.nonmanifold_vertices.first() {
        return Err(ApproxError::BadInput(format!(
            "vertex {v} is non-manifold (its faces form more than one fan)"
        )));
    }
    if !topo.consistently_oriented {
        return Err(ApproxError::BadInput(
            "the faces are not consistently oriented".into(),
        ));
    }
    let (closed, open) = outline::components(topo);
    let least = 4 * closed + open;
    if opts.k < least {
        return Err(ApproxError::BadInput(format!(
            "K = {} is below the {least} polygons this mesh needs at least: a region cannot \
             span two connected components, and each of its {closed} closed components needs \
             four (a tetrahedron), each of its {open} open ones one",
            opts.k
        )));
    }
    if let Some(f) = s.areas.iter().position(|&a| a <= 0.0 || !a.is_finite()) {
        return Err(ApproxError::BadInput(format!("face {f} is degenerate")));
    }
    progress(Stage::Normals);
    let t = Instant::now();
    let sm = normals_l0::smooth_normals(s.pos, topo, &s.normals, &opts.normals)?;
    let seconds_normals = t.elapsed().as_secs_f64();
    progress(Stage::Vertices);
    let t = Instant::now();
    let p1 = vertex_update::update_vertices(s.pos, s.faces, topo, &sm.normals, &opts.vertices)?;
    let (_, a1) = face_normals_areas(&p1, s.faces);
    Ok(Smoothed {
        sm,
        a1,
        seconds_normals,
        seconds_vertices: t.elapsed().as_secs_f64(),
    })
}

/// The partition of one seed (`opts.seed`), regions `0..n`, and what the clustering did.
#[derive(Clone)]
struct Partitioned {
    labels: Vec<u32>,
    n: usize,
    /// Mean distance of the input to the regions' least-absolute-distances planes (as the
    /// realised mesh's after `refit`): the error the realisation starts from (a VSA-like
    /// partition, before any defect changed it).
    error: f64,
    facts: PartitionFacts,
    seconds: f64,
}

/// Stage 3, the clustering of the smoothed normals: region growing from the seed's faces,
/// Lloyd relaxation and the merges of corners the planes cannot reach.
fn partition(
    surface: &outline::Surface<'_>,
    opts: &ApproxOptions,
    smoothed: &Smoothed,
    progress: &mut dyn FnMut(Stage),
) -> Partitioned {
    let (sm, po, topo) = (&smoothed.sm, &opts.partition, surface.topo);
    progress(Stage::Cluster);
    let t = Instant::now();
    // Cluster on the smoothed normals (piecewise constant); areas from the updated surface.
    let a1 = &smoothed.a1;
    // θ is refined while region growing yields fewer than K regions: the budget K is then
    // spent on flatter regions (smaller error, less to fold) instead of being left unused.
    let mut angle = po.angle_deg;
    let cl = loop {
        let cl = cluster::cluster_faces(
            topo,
            &sm.normals,
            a1,
            &ClusterOptions {
                k: opts.k,
                angle_deg: angle,
                seed: opts.seed,
                max_cone_deg: po.max_cone_deg,
            },
        );
        if cl.grown >= opts.k || angle < po.min_angle_deg {
            break cl;
        }
        angle *= 0.75;
    };
    let mut labels = cl.face_cluster.clone();
    let lloyd_rounds = lloyd::relax(topo, &sm.normals, a1, &mut labels, po.lloyd_rounds);
    let boundary_moves = cluster::smooth_boundaries(topo, &mut labels, 16);
    let reach = po.corner_reach_rel * surface.diag;
    let corner_merges =
        cluster::merge_unreachable_corners(surface, &mut labels, reach, po.corner_amplification);
    let facts = PartitionFacts {
        regions_grown: cl.grown,
        regions_merged: cl.count,
        final_angle_deg: cl.final_angle_deg,
        lloyd_rounds,
        faces_reassigned: boundary_moves,
        corner_merges,
        crease_edges: sm.crease_edges,
        alm_rounds_normals: sm.rounds,
    };
    settle(surface, labels, facts, t)
}

/// `part` with the budget its corner merges left spent as VSA spends it (its incremental
/// insertion, [`lloyd::fill`]: the region of largest L2,1 error halved until K regions),
/// settled as [`partition`] settles its own; `None` when nothing could be added. The error is
/// the input's normals' (`by_input`: the smoothing flattened what the clustering could not
/// see — a curved face left as one region has one smoothed normal, no L2,1 error and no place
/// to cut) or the smoothed ones' (the clustering's own signal, then relaxed as a whole as
/// [`partition`] relaxes it; a relaxation on the input's normals would undo the smoothed
/// clustering's regions, so there each halving is relaxed within its region only).
///
/// Why: a region the corner merges made may be realisable as two once its planes are fitted
/// anew; whether it is, only the realisation tells — so this is a further candidate, kept
/// only if its realisation ends nearer the input.
fn filled(
    surface: &outline::Surface<'_>,
    opts: &ApproxOptions,
    smoothed: &Smoothed,
    part: &Partitioned,
    by_input: bool,
) -> Option<Partitioned> {
    let t = Instant::now();
    let metric = if by_input {
        surface.normals_metric()
    } else {
        lloyd::Normals {
            normals: &smoothed.sm.normals,
            areas: &smoothed.a1,
        }
    };
    let mut labels = part.labels.clone();
    let worth = |labels: &[u32], c, new| surface.adds_a_plane(labels, c, new);
    let topo = surface.topo;
    if lloyd::fill(topo, &metric, &mut labels, part.n, opts.k, worth) == part.n {
        return None;
    }
    let mut facts = part.facts.clone();
    if !by_input {
        let (normals, areas) = (metric.normals, metric.areas);
        facts.lloyd_rounds += lloyd::relax(
            topo,
            normals,
            areas,
            &mut labels,
            opts.partition.lloyd_rounds,
        );
    }
    let mut filled = settle(surface, labels, facts, t);
    filled.seconds += part.seconds;
    Some(filled)
}

/// The last steps of a partition: regions and faces that would collapse onto a line merged
/// or moved, labels renumbered, the planes fitted and the error measured.
fn settle(
    surface: &outline::Surface<'_>,
    mut labels: Vec<u32>,
    mut facts: PartitionFacts,
    t: Instant,
) -> Partitioned {
    let topo = surface.topo;
    facts.corner_merges += cluster::merge_collapsing_regions(surface, &mut labels);
    facts.faces_reassigned += cluster::fix_collapsing_faces(surface, &mut labels);
    let n = renumber(&mut labels);
    let at = cluster::vertex_clusters(topo, &labels);
    let planes = l1_planes(surface, &at, &outline::fit_planes(surface, &labels, n));
    let error = input_distances(surface.pos, &at, &planes).0;
    Partitioned {
        labels,
        n,
        error,
        facts,
        seconds: t.elapsed().as_secs_f64(),
    }
}

/// Stage 5: the planes fitted to the error the run is measured by. A region's least-squares
/// plane minimises the squared distance integrated over its faces; the headline error is the
/// mean absolute distance of the input *vertices* ([`input_distances`]), which over a fixed
/// partition is a sum of one term per region — `Σ w_v |n·p_v + d|` over the region's vertices,
/// `w_v` = 1 / the number of regions at `v` — so each region's least-absolute-distances plane
/// ([`geom::l1_plane`]) is the best plane for it. The two differ where the region is curved
/// (the median of the distances is not their mean) or its vertices are unevenly spread
/// (fillets and refined strips of CAD meshes weigh per vertex, not per area).
///
/// New planes move the corners, so the polygon mesh is built again from them; the regions
/// named by a fault (or owning a triangle the independent check finds flipped or degenerate)
/// go back halfway towards their least-squares plane, then to a quarter of the way, then all
/// the way, and the mesh is built again: at most 3 × regions + 1 builds. The result is kept
/// only if it is valid and nearer the input: never worse than the realisation it started
/// from.
fn refit(surface: &outline::Surface<'_>, r: &mut outline::Realised) {
    let (n, pos, diag) = (r.planes.len(), surface.pos, surface.diag);
    let regions_at = &cluster::vertex_clusters(surface.topo, &r.labels);
    let l1 = l1_planes(surface, regions_at, &r.planes);
    // Share of the way from the least-squares plane to the least-absolute-distances one.
    let mut t = vec![1.0f64; n];
    let mut builds = 0;
    loop {
        builds += 1;
        let planes: Vec<Plane> = r
            .planes
            .iter()
            .zip(&l1)
            .zip(&t)
            .map(|((a, b), &t)| geom::blend_planes(a, b, t))
            .collect();
        match build_checked(surface, &r.labels, &planes, r.closes_handles) {
            Ok(polygons) => {
                let error = |p: &[Plane]| input_distances(pos, regions_at, p).0;
                let (before, after) = (error(&r.planes), error(&planes));
                trace(|| {
                    format!(
                        "refit: mean distance {:.4e} → {:.4e}·diag (the L1 plane: {:.4e}), {builds} builds, {} of {n} regions at their L1 plane",
                        before / diag,
                        after / diag,
                        error(&l1) / diag,
                        t.iter().filter(|&&x| x == 1.0).count()
                    )
                });
                if after < before {
                    r.polygons = polygons;
                    r.planes = planes;
                }
                return;
            }
            Err(named) => {
                let mut moved = false;
                for x in named {
                    let t = &mut t[x as usize];
                    if *t > 0.0 {
                        // 1 → ½ → ¼ → 0.
                        *t = if *t > 0.3 { 0.5 * *t } else { 0.0 };
                        moved = true;
                    }
                }
                if !moved {
                    return;
                }
            }
        }
    }
}

/// The polygons built on `planes` for `labels` ([`outline::build`]) and checked as every
/// output is ([`bad_triangles`]): new planes or borders can leave a triangle without area that
/// the construction does not test for (seen in the corpus sweep). On a fault, the regions it
/// names.
fn build_checked(
    surface: &outline::Surface<'_>,
    labels: &[u32],
    planes: &[Plane],
    close_handles: bool,
) -> Result<polygons::PolygonMesh, Vec<u32>> {
    let polygons =
        outline::build(surface, labels, planes, close_handles).map_err(|d| d.regions())?;
    let bad = bad_triangles(&polygons, planes, surface.diag);
    if bad.is_empty() {
        Ok(polygons)
    } else {
        Err(bad.iter().map(|b| polygons.triangle_region[b.0]).collect())
    }
}

/// Each region's least-absolute-distances plane ([`geom::l1_plane`]) of its input vertices,
/// a vertex on `m` regions weighing `1/m` in each (so the sum over regions is the headline
/// error, [`input_distances`]), from its plane in `start`.
fn l1_planes(s: &outline::Surface<'_>, regions_at: &[Vec<u32>], start: &[Plane]) -> Vec<Plane> {
    let mut members: Vec<Vec<(V3, f64)>> = vec![Vec::new(); start.len()];
    for (v, cs) in regions_at.iter().enumerate() {
        for &c in cs {
            members[c as usize].push((s.pos[v], 1.0 / cs.len() as f64));
        }
    }
    // Distances below this are zero at the output's precision (see `geom::l1_plane`).
    let floor = 1e-9 * s.diag;
    members
        .iter()
        .zip(start)
        .map(|(m, &p)| geom::l1_plane(m, p, floor, s.rule))
        .collect()
}

/// What the independent check finds wrong with an output triangle.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Bad {
    /// Its normal does not agree with its region's plane.
    Flipped,
    /// Its area is under 1e-12 × the squared bounding-box diagonal.
    Degenerate,
}

/// The output triangles that are flipped or degenerate (index, what), counted from the
/// positions alone — not from what the construction believes it made.
fn bad_triangles(mesh: &polygons::PolygonMesh, planes: &[Plane], diag: f64) -> Vec<(usize, Bad)> {
    let (normals, areas) = face_normals_areas(&mesh.positions, &mesh.triangles);
    mesh.triangle_region
        .iter()
        .enumerate()
        .filter_map(|(f, &reg)| {
            if areas[f] <= 1e-12 * diag * diag {
                Some((f, Bad::Degenerate))
            } else if dot(normals[f], planes[reg as usize].n) <= 0.0 {
                Some((f, Bad::Flipped))
            } else {
                None
            }
        })
        .collect()
}

/// The headline error: the mean over input vertices of their distance to their regions'
/// planes (a vertex on several regions counts the mean over them), and the largest.
fn input_distances(pos: &[V3], regions_at: &[Vec<u32>], planes: &[Plane]) -> (f64, f64) {
    let (mut sum, mut cnt, mut maxd) = (0.0, 0usize, 0.0f64);
    for (v, cs) in regions_at.iter().enumerate() {
        let ds: Vec<f64> = cs
            .iter()
            .map(|&c| planes[c as usize].signed_distance(pos[v]).abs())
            .collect();
        if !ds.is_empty() {
            sum += ds.iter().sum::<f64>() / ds.len() as f64;
            cnt += 1;
            maxd = ds.iter().copied().fold(maxd, f64::max);
        }
    }
    (sum / cnt.max(1) as f64, maxd)
}

/// A realised partition (stages 4–6) and its report.
#[derive(Clone)]
struct Run {
    realised: outline::Realised,
    report: ApproxReport,
}

impl From<Run> for ApproxOutput {
    fn from(run: Run) -> ApproxOutput {
        let r = run.realised;
        ApproxOutput {
            face_cluster: r.labels,
            planes: r.planes,
            polygons: r.polygons,
            report: run.report,
        }
    }
}

/// Stage 4, the partition realised by [`outline::realise`] (with `give_away` or merges
/// alone): polygons whose corners are where the planes meet, the partition split or merged
/// where they cannot realise it; then stages 5–6 ([`finish`]). Ends early, unrealised, once
/// `stop` is set.
fn realise(
    surface: &outline::Surface<'_>,
    opts: &ApproxOptions,
    smoothed: &Smoothed,
    part: &Partitioned,
    give_away: bool,
    stop: &AtomicBool,
) -> Result<Run, ApproxError> {
    let t = Instant::now();
    trace(|| {
        let e = part.error / surface.diag;
        format!(
            "partition before realising: {} regions, mean distance {e:.3e}·diag",
            part.n
        )
    });
    let (labels, k) = (part.labels.clone(), opts.k);
    let r = outline::realise(surface, labels, part.n, k, give_away, stop)
        .map_err(|e| ApproxError::Unrealisable(format!("seed {}: {e}", opts.seed)))?;
    Ok(finish(surface, opts, smoothed, part, r, t, 0.0))
}

/// Stages 5–6 on a realised partition (`refit`, `relabel`), then [`assess`]; the polygons
/// stage's seconds are `earlier` + those since `t`.
fn finish(
    surface: &outline::Surface<'_>,
    opts: &ApproxOptions,
    smoothed: &Smoothed,
    part: &Partitioned,
    mut r: outline::Realised,
    t: Instant,
    earlier: f64,
) -> Run {
    refit(surface, &mut r);
    if relabel::relabel(surface, &mut r) {
        refit(surface, &mut r);
    }
    let polygons = earlier + t.elapsed().as_secs_f64();
    assess(surface, opts, smoothed, Some(part), r, polygons)
}

/// The errors, the independent fold count and the report of `r`, the realisation of `part`
/// (`None`: of no partition), `polygons` seconds after the smoothing.
fn assess(
    surface: &outline::Surface<'_>,
    opts: &ApproxOptions,
    smoothed: &Smoothed,
    part: Option<&Partitioned>,
    r: outline::Realised,
    polygons: f64,
) -> Run {
    let (diag, pos) = (surface.diag, surface.pos);
    let vc = cluster::vertex_clusters(surface.topo, &r.labels);
    let mut times = StageTimes {
        normals: smoothed.seconds_normals,
        vertices: smoothed.seconds_vertices,
        cluster: part.map_or(0.0, |p| p.seconds),
        polygons,
        total: 0.0,
    };
    times.total = times.normals + times.vertices + times.cluster + times.polygons;
    let (mean, maxd) = input_distances(pos, &vc, &r.planes);
    let part_error = part.map_or(mean, |p| p.error);
    let mut maxp = 0.0f64;
    for (poly, &reg) in r.polygons.polygons.iter().zip(&r.polygons.region) {
        for &c in poly {
            let p = r.polygons.positions[c as usize];
            maxp = maxp.max(r.planes[reg as usize].signed_distance(p).abs());
        }
    }
    // The independent count of what the construction rules out.
    let bad = bad_triangles(&r.polygons, &r.planes, diag);
    let flipped = bad.iter().filter(|b| b.1 == Bad::Flipped).count();
    let degenerate = bad.len() - flipped;
    let mut notes = Vec::new();
    if r.merges > 0 {
        let given = match r.dissolved {
            0 => String::new(),
            d => format!(" ({d} of them regions given away to their neighbours)"),
        };
        notes.push(format!(
            "{} regions (K = {}): {} splits, {} merges{given} and {} wedges moved answered {} partitions the planes could not realise",
            r.planes.len(),
            opts.k,
            r.splits,
            r.merges,
            r.unpinched,
            r.defects.len()
        ));
    }
    if lost_planes(mean, part_error) {
        notes.push(format!(
            "the polygon mesh is {:.1}× farther from the input than the partition it realises \
             ({:.2e}·diag against {:.2e}·diag): merges took planes where the partition \
             needed them (a larger K, or other seeds, may keep them)",
            mean / part_error,
            mean / diag,
            part_error / diag
        ));
    }
    if surface.rule == PlaneRule::Facing {
        notes.push(
            "no partition could be realised with every region on its least-squares plane; each \
             region is on the principal plane its faces face (a thin bent region — a rim, a \
             fillet, a bolt hole's wall — has its least-squares plane across it)"
                .to_string(),
        );
    }
    let euler_input = surface.topo.euler_characteristic;
    let euler_polygons = r.polygons.euler_characteristic();
    if euler_polygons != euler_input {
        notes.push(format!(
            "the polygon mesh's Euler characteristic is {euler_polygons}, the input's \
             {euler_input}: regions holding a handle of the input close it ({} fewer)",
            match (euler_polygons - euler_input) / 2 {
                1 => "1 handle".to_string(),
                h => format!("{h} handles"),
            }
        ));
    }
    let rel = |x: f64| x / diag;
    let report = ApproxReport {
        faces: surface.faces.len(),
        seed_used: part.map(|_| opts.seed),
        runs: 1,
        seconds_all_runs: times.total,
        vertices: pos.len(),
        k_requested: opts.k,
        k_obtained: r.planes.len(),
        partition: part.map(|p| p.facts.clone()).unwrap_or_default(),
        bbox_diagonal: diag,
        mean_input_distance: mean,
        mean_input_distance_rel: rel(mean),
        partition_mean_input_distance: part_error,
        max_input_distance: maxd,
        max_input_distance_rel: rel(maxd),
        max_planarity_deviation: maxp,
        max_planarity_deviation_rel: rel(maxp),
        flipped_faces: flipped,
        degenerate_faces: degenerate,
        regions_dissolved: r.dissolved,
        plane_halvings: r.plane_halvings,
        plane_rule: part.map(|_| surface.rule),
        regions_split: r.splits,
        merges: r.merges,
        polygons: r.polygons.polygons.len(),
        polygon_holes: r.polygons.holes,
        corners: r.polygons.positions.len(),
        euler_input,
        euler_polygons,
        seconds: times,
        notes,
        options: opts.clone(),
    };
    Run {
        realised: r,
        report,
    }
}

/// What the smoothing and the partition stage did, for the report.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct PartitionFacts {
    /// Regions after region growing, before merging.
    pub regions_grown: usize,
    /// Regions after merging down to K (before corner merges and fold checks).
    pub regions_merged: usize,
    /// Merge angle reached (larger than asked when merges above θ were needed to reach K).
    pub final_angle_deg: f64,
    /// Lloyd rounds that changed the partition (see [`lloyd`]).
    pub lloyd_rounds: usize,
    /// Faces moved to a neighbouring region: all three corners shared with it, or two of
    /// three edge-neighbours in it (boundary smoothing).
    pub faces_reassigned: usize,
    /// Region merges at corners whose planes meet too far away, and of closed regions left
    /// with fewer than three neighbours by them.
    pub corner_merges: usize,
    /// Creases the L0 smoothing kept, and its ALM rounds.
    pub crease_edges: usize,
    pub alm_rounds_normals: usize,
}

/// Prints what `what` says to stderr, after "approx: ", when `FOLDFREE_APPROX_TRACE` is set
/// in the environment (what the stages met and decided, for a reader of one run; otherwise
/// `what` is not called).
pub(crate) fn trace(what: impl FnOnce() -> String) {
    if std::env::var_os("FOLDFREE_APPROX_TRACE").is_some() {
        eprintln!("approx: {}", what());
    }
}

/// Renumbers region labels to 0..count in order of first appearance (drops emptied regions).
fn renumber(labels: &mut [u32]) -> usize {
    let mut map = std::collections::HashMap::new();
    for l in labels.iter_mut() {
        let next = map.len() as u32;
        *l = *map.entry(*l).or_insert(next);
    }
    map.len()
}

/// The summary `foldfree approx` prints: regions and polygons, then distances and folds, then
/// the notes (no trailing newline).
impl std::fmt::Display for ApproxReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = self;
        write!(
            f,
            "foldfree approx: {} faces → {} regions (K = {}), {} polygons, {} corners, {:.2} s ({} run{}, {} kept)",
            r.faces,
            r.k_obtained,
            r.k_requested,
            r.polygons,
            r.corners,
            r.seconds_all_runs,
            r.runs,
            if r.runs == 1 { "" } else { "s" },
            r.seed_used
                .map_or("the polytope".into(), |s| format!("seed {s}"))
        )?;
        write!(
            f,
            "\n  input→plane distance mean {:.4e} ({:.2e}·diag), max {:.4e}; planarity of output {:.2e}·diag; flipped {}, degenerate {}",
            r.mean_input_distance,
            r.mean_input_distance_rel,
            r.max_input_distance,
            r.max_planarity_deviation_rel,
            r.flipped_faces,
            r.degenerate_faces
        )?;
        for n in &r.notes {
            write!(f, "\n  note: {n}")?;
        }
        Ok(())
    }
}

/// Meshes the unit tests of the stages share.
#[cfg(test)]
pub(crate) mod testing {
    use crate::mesh::{Topology, TriMesh};
    use std::path::Path;

    /// n×n vertices in the plane z = 0, each square cut along the same diagonal: an interior
    /// vertex has six faces around it.
    pub fn grid(n: u32) -> (TriMesh, Topology) {
        let positions = (0..n * n)
            .map(|i| [(i % n) as f64, (i / n) as f64, 0.0])
            .collect();
        let mut faces = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let a = y * n + x;
                faces.push([a, a + 1, a + n + 1]);
                faces.push([a, a + n + 1, a + n]);
            }
        }
        let m = TriMesh { positions, faces };
        let t = Topology::build(&m, Path::new("grid")).unwrap();
        (m, t)
    }

    /// A strip of 2n faces (strip i over x ∈ [i, i + 1], y ∈ [0, 1], two faces each) folded
    /// into a roof at x = `ridge`: rising at 45° before it, falling after; faces face up.
    pub fn roof(n: u32, ridge: u32) -> (TriMesh, Topology) {
        let mut positions = Vec::new();
        for i in 0..=n {
            let (x, r) = (f64::from(i), f64::from(ridge));
            let z = if i <= ridge { x } else { 2.0 * r - x };
            positions.push([x, 0.0, z]);
            positions.push([x, 1.0, z]);
        }
        let faces = (0..n)
            .flat_map(|i| {
                let (a, b, c, d) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
                [[a, c, b], [b, c, d]]
            })
            .collect();
        let m = TriMesh { positions, faces };
        let t = Topology::build(&m, Path::new("roof")).unwrap();
        (m, t)
    }

    /// The unit cube's surface, an n×n grid of squares on each side cut along a diagonal,
    /// faces counter-clockwise seen from outside; with the side of each face (2·axis + 1 on
    /// the far side).
    pub fn cube(n: u32) -> (TriMesh, Topology, Vec<u32>) {
        let mut index = std::collections::HashMap::new();
        let mut m = TriMesh::default();
        let mut side_of = Vec::new();
        for axis in 0..3 {
            for far in [false, true] {
                let (u, w) = ((axis + 1) % 3, (axis + 2) % 3);
                let mut id = |i: u32, j: u32| -> u32 {
                    let mut p = [0; 3];
                    p[axis] = if far { n } else { 0 };
                    p[u] = i;
                    p[w] = j;
                    *index.entry(p).or_insert_with(|| {
                        m.positions.push(p.map(|c| f64::from(c) / f64::from(n)));
                        m.positions.len() as u32 - 1
                    })
                };
                for i in 0..n {
                    for j in 0..n {
                        let q = [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)];
                        // e_u × e_w = +e_axis: (u, w) order is counter-clockwise from +axis.
                        let (a, b) = ([q[0], q[1], q[2]], [q[0], q[2], q[3]]);
                        for f in [a, b] {
                            m.faces.push(if far { f } else { [f[0], f[2], f[1]] });
                            side_of.push(2 * axis as u32 + u32::from(far));
                        }
                    }
                }
            }
        }
        let t = Topology::build(&m, Path::new("cube")).unwrap();
        (m, t, side_of)
    }

    /// A closed coin: radius 1, thickness `h`, `seg` segments around; caps as fans, the rim
    /// one band of quads; outward counter-clockwise faces.
    pub fn coin(seg: u32, h: f64) -> (TriMesh, Topology) {
        let mut positions = vec![[0.0, 0.0, 0.0], [0.0, 0.0, h]];
        for z in [0.0, h] {
            for s in 0..seg {
                let t = std::f64::consts::TAU * f64::from(s) / f64::from(seg);
                positions.push([t.cos(), t.sin(), z]);
            }
        }
        let bottom = |s: u32| 2 + s % seg;
        let top = |s: u32| 2 + seg + s % seg;
        let mut faces = Vec::new();
        for s in 0..seg {
            faces.push([0, bottom(s + 1), bottom(s)]);
            faces.push([1, top(s), top(s + 1)]);
            faces.push([bottom(s), bottom(s + 1), top(s + 1)]);
            faces.push([bottom(s), top(s + 1), top(s)]);
        }
        let m = TriMesh { positions, faces };
        let t = Topology::build(&m, Path::new("coin")).unwrap();
        (m, t)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// Two grids sharing one corner vertex (a bowtie there): refused as bad input, naming the
    /// vertex, before any work.
    #[test]
    fn a_non_manifold_vertex_is_refused_as_bad_input() {
        let (g, _) = testing::grid(3);
        let mut m = g.clone();
        let shift = g.positions.len() as u32;
        // The second grid's first corner is the first grid's last (vertex 8): drop its own.
        m.positions.extend(
            g.positions
                .iter()
                .skip(1)
                .map(|p| [p[0] + 2.0, p[1] + 2.0, 0.0]),
        );
        let map = |v: u32| if v == 0 { 8 } else { v + shift - 1 };
        m.faces.extend(g.faces.iter().map(|f| f.map(map)));
        let t = Topology::build(&m, Path::new("bowtie")).unwrap();
        assert_eq!(t.nonmanifold_vertices, vec![8]);
        match approximate(&m, &t, &ApproxOptions::new(8), &mut |_| {}) {
            Err(e @ ApproxError::BadInput(_)) => {
                assert_eq!(e.exit_code(), 2);
                assert!(e.to_string().contains("vertex 8"), "{e}");
            }
            other => panic!("{:?}", other.map(|o| o.report)),
        }
    }

    /// A coin a twentieth as thick as it is wide: each piece of its rim is thinner than it is
    /// bent (a sixth of the rim: sagitta 0.13 > thickness 0.05), so its least-squares plane
    /// lies across it, parallel to the caps, and no partition into K = 8 regions is realised
    /// on least-squares planes. On the planes the faces face (the fallback) the draws realise
    /// the coin as a prism, and the report says which rule made it. (The search alone: on the
    /// whole run the coin's convex polytope is nearer: the next test.)
    #[test]
    fn the_draws_realise_a_coin_on_the_planes_its_faces_face() {
        let (m, t) = testing::coin(48, 0.05);
        let surface = outline::Surface::new(&t, &m);
        let opts = ApproxOptions::new(8);
        let smoothed = smooth(&surface, &opts, &mut |_| {}).unwrap();
        let (found, _) = search(&surface, &m, &opts, &smoothed, Instant::now(), &mut |_| {});
        let out = found.unwrap();
        let r = &out.report;
        assert_eq!(r.plane_rule, Some(PlaneRule::Facing), "{:?}", r.notes);
        assert!(r
            .notes
            .iter()
            .any(|n| n.contains("principal plane its faces face")));
        assert!((3..=8).contains(&r.k_obtained), "{} regions", r.k_obtained);
        assert!(r.max_planarity_deviation_rel <= 1e-6);
        assert_eq!(r.flipped_faces + r.degenerate_faces, 0);
        assert!(hull::watertight(&out.polygons.polygons));
        // The rim's regions stand on the caps: their planes are (nearly) vertical.
        let caps = out.planes.iter().filter(|p| p.n[2].abs() > 0.99).count();
        assert_eq!(caps, 2, "{:?}", out.planes);
    }

    /// On the whole run the coin keeps its polytope of K = 8 support planes: it is convex, and
    /// the polytope is nearer than what the draws realise (the test above); the run says why.
    #[test]
    fn a_convex_input_keeps_its_polytope_where_that_is_nearer() {
        let (m, t) = testing::coin(48, 0.05);
        let out = approximate(&m, &t, &ApproxOptions::new(8), &mut |_| {}).unwrap();
        let r = &out.report;
        assert_eq!((r.seed_used, r.plane_rule), (None, None), "{:?}", r.notes);
        assert!(r.notes[0].contains("is farther away"), "{:?}", r.notes);
        assert!(r.notes[0].contains("convex polytope"), "{:?}", r.notes);
        assert!((4..=8).contains(&r.k_obtained), "{} regions", r.k_obtained);
        assert!(r.max_planarity_deviation_rel <= 1e-6);
        assert_eq!(r.flipped_faces + r.degenerate_faces, 0);
        assert!(hull::watertight(&out.polygons.polygons));
    }

    /// A roof the smoothing flattened (one smoothed normal on both sides: no L2,1 error, no
    /// place to cut by) is still halved at its ridge when the budget is filled: the fill
    /// measures the input's normals.
    #[test]
    fn the_budget_goes_where_the_input_bends_though_the_smoothing_flattened_it() {
        let (mesh, topo) = testing::roof(8, 4);
        let surface = outline::Surface::new(&topo, &mesh);
        let nf = mesh.faces.len();
        let sm = normals_l0::NormalL0Result {
            normals: vec![[0.0, 0.0, 1.0]; nf],
            crease_edges: 0,
            rounds: 0,
        };
        let smoothed = Smoothed {
            sm,
            a1: surface.areas.clone(),
            seconds_normals: 0.0,
            seconds_vertices: 0.0,
        };
        let part = settle(&surface, vec![0; nf], Default::default(), Instant::now());
        assert_eq!(part.n, 1);
        let o = ApproxOptions::new(2);
        let fill = |by_input| filled(&surface, &o, &smoothed, &part, by_input);
        // By the smoothed normals there is nothing to cut.
        assert!(fill(false).is_none());
        let filled = fill(true).unwrap();
        assert_eq!(filled.n, 2);
        // Faces 0..8 are left of the ridge (x ≤ 4), 8..16 right of it.
        let left: Vec<bool> = filled
            .labels
            .iter()
            .map(|&l| l == filled.labels[0])
            .collect();
        assert_eq!(left, (0..nf).map(|f| f < 8).collect::<Vec<_>>());
        let diag = geom::bbox_diagonal(&mesh);
        assert!(filled.error < 1e-12 * diag, "{}", filled.error);
    }

    /// One region over a grid bent in x (`z = (x − ½)²`): its vertices' heights spread
    /// unevenly (the median of `(x − ½)²` over a uniform x is 1/16, its mean 1/12), so the
    /// least-absolute-distances plane is the level plane at the median height, nearer the
    /// input than the least-squares one, and the polygon built on it is the whole border.
    #[test]
    fn refit_moves_a_curved_region_to_its_median_plane_and_keeps_the_mesh_valid() {
        let (positions, faces) = crate::init::test_grid::bumpy(40, |x, _| (x - 0.5).powi(2));
        let mesh = TriMesh { positions, faces };
        let topo = Topology::build(&mesh, Path::new("generated")).unwrap();
        let surface = outline::Surface::new(&topo, &mesh);
        let labels = vec![0; mesh.faces.len()];
        let mut r = outline::realise(&surface, labels, 1, 1, true, &Default::default()).unwrap();
        let at = cluster::vertex_clusters(&topo, &r.labels);
        let before = input_distances(&mesh.positions, &at, &r.planes).0;
        refit(&surface, &mut r);
        let after = input_distances(&mesh.positions, &at, &r.planes).0;
        assert!(after < 0.99 * before, "{before} → {after}");
        // The level plane at the median height is the optimum; the refit plane is level and
        // as near the input to half a per cent (IRLS converges linearly on a sum this flat
        // near its minimum: its slope there is one vertex column's weight).
        let mut z: Vec<f64> = mesh.positions.iter().map(|p| p[2]).collect();
        z.sort_by(f64::total_cmp);
        let median = z[z.len() / 2];
        let p = r.planes[0];
        assert!(p.n[2].abs() > 1.0 - 1e-9, "{p:?}");
        let best: f64 = z.iter().map(|h| (h - median).abs()).sum::<f64>() / z.len() as f64;
        assert!(
            after <= 1.005 * best,
            "{after} vs {best} at the median {median}: {p:?}"
        );
        // The polygon is rebuilt on the new plane: its corners lie on it.
        for c in &r.polygons.positions {
            assert!(p.signed_distance(*c).abs() < 1e-12);
        }
        assert_eq!(r.polygons.polygons.len(), 1);
    }
}
