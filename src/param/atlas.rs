//! The cutting path of `foldfree param`: meshes that are not one disk (closed, any genus,
//! several holes or components) are cut into disk charts, each chart is mapped as a disk
//! ([`crate::param::map::compute_map`]), and the charts are packed into the unit square.
#![forbid(unsafe_code)]

use std::path::Path;
use std::time::Instant;

use crate::init::{initial_map, InitMethod};
use crate::mesh::{self, Topology, TriMesh};
use crate::metrics;
use crate::param::job::{ParamJob, ParamOutput};
use crate::param::map::{
    compute_map_from, MapOutput, OnDevice, Progress, SolverChoice, SolverPath,
};
use crate::param::AdmmOptions;
use crate::report::ParamReport;
use crate::Result;

/// The cutting path of [`crate::param::job::run_param`]: cut into disk charts, map each chart, pack the charts
/// into [0,1]², write the OBJ with the input's `v` (count and order) and one `vt` per split
/// vertex (`f v/vt`), and report seams, charts and packing.
#[allow(clippy::too_many_arguments)]
pub(crate) fn run_atlas(
    job: &ParamJob,
    input: TriMesh,
    topo: &Topology,
    vreport: &mesh::ValidationReport,
    solver: SolverChoice,
    admm: &AdmmOptions,
    ctx: Option<&crate::gpu::Context>,
    t0: Instant,
    t_load: f64,
    progress: &mut dyn FnMut(Progress<'_>),
) -> Result<ParamOutput> {
    use crate::param::{cut, pack};
    let t_cut = Instant::now();
    let mut cutm = cut::cut_to_disks(&input, topo, &job.cut_options, &job.input)?;
    let mut extra = Vec::new();
    // The charts' LSCM maps, kept across the seam loop (a seam leaves the other charts as
    // they were) and for the start maps of the charts the loop ends with.
    let mut lscm = LscmCache::default();
    while extra.len() < job.cut_options.extra_seams {
        match most_shrunk_vertex(&cutm, &job.input, &mut lscm)? {
            // The same vertex again means its seam did not help: stop (a large
            // `extra_seams` otherwise re-cut the same seam for ever).
            Some((v, ratio)) if ratio > job.cut_options.stretch_limit && !extra.contains(&v) => {
                extra.push(v)
            }
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
    let device = ctx.map(|ctx| OnDevice {
        profile: job.profile,
        ..OnDevice::new(ctx)
    });
    // Charts split into injective pieces (the last resort, [`crate::param::injective`]).
    let mut pieces_made = 0usize;
    let mut pieces_tried = false;
    let maps = loop {
        let mut maps = Vec::with_capacity(cutm.charts.len());
        let mut new_splits = Vec::new();
        let mut overlapping = Vec::new();
        for (c, faces) in cutm.charts.iter().enumerate() {
            let (sub, global) = cutm.chart_mesh(faces);
            let sub_topo = Topology::build(&sub, &job.input)?;
            let map = match cache.remove(faces) {
                Some(m) => m,
                None => {
                    let t1 = Instant::now();
                    let uv = match lscm.take(faces, &global) {
                        Some(Some(uv)) if job.init == InitMethod::Lscm => uv,
                        _ => initial_map(&sub, &sub_topo, job.init)?,
                    };
                    compute_map_from(
                        &sub,
                        &sub_topo,
                        uv,
                        t1,
                        solver,
                        job.bijective,
                        admm,
                        device.as_ref(),
                        progress,
                    )?
                }
            };
            if !metrics::boundary_intersecting_pairs(&map.uv, &sub_topo.boundary_loops).is_empty() {
                overlapping.push(c);
                new_splits.push(overlap_splits(
                    &map.uv,
                    &sub_topo,
                    &global,
                    &cutm.origin,
                    faces,
                ));
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
        let keep_overlaps = job.cut_options.overlap_splits == 0;
        if splits.len() == before && (overlapping.is_empty() || pieces_tried || keep_overlaps) {
            break maps; // nothing overlaps (or nothing more can be done about it)
        }
        let mut kept: Vec<(Vec<u32>, MapOutput)> = Vec::new();
        if splits.len() == before {
            // No seam could split what overlaps, or the budget is spent: split each
            // overlapping chart into pieces that do not overlap, keeping its map.
            pieces_tried = true;
            for (c, (faces, map)) in cutm.charts.iter().zip(maps).enumerate() {
                if !overlapping.contains(&c) {
                    cache.insert(faces.clone(), map);
                    continue;
                }
                let (sub, _) = cutm.chart_mesh(faces);
                let piece = crate::param::injective::injective_pieces(&map.uv, &sub.faces);
                for (i, &f) in faces.iter().enumerate() {
                    for &e in &topo.face_edges[f as usize] {
                        let [g0, g1] = topo.edge_faces[e as usize];
                        let g = if g0 == f { g1 } else { g0 };
                        if let Ok(j) = faces.binary_search(&g) {
                            if piece[i] != piece[j] {
                                base.cut_edge(e);
                            }
                        }
                    }
                }
                pieces_made += piece.iter().max().map_or(0, |&m| m as usize);
                kept.push((faces.clone(), map));
            }
        } else {
            for (faces, map) in cutm.charts.iter().zip(maps) {
                cache.insert(faces.clone(), map);
            }
        }
        let recut = base.finish(&input, topo, &job.input)?;
        seconds_cut += t.elapsed().as_secs_f64();
        for (faces, map) in kept {
            for (piece_faces, piece_map) in pieces_of(&cutm, &recut, &faces, map) {
                cache.insert(piece_faces, piece_map);
            }
        }
        cutm = recut;
    };

    let mut uv = vec![[0.0f64; 2]; cutm.mesh.positions.len()];
    let mut chart_meshes = Vec::with_capacity(cutm.charts.len());
    let mut report = ParamReport {
        init: job.init.name().into(),
        backend: "cpu".into(),
        device: "host CPU".into(),
        solver: "none".into(),
        ..ParamReport::default()
    };
    let mut seconds_init = 0.0;
    let mut seconds_solve = 0.0;
    let mut converged = true;
    let mut path = SolverPath::None;
    let mut stop = String::new();
    let mut largest = 0usize;
    for (faces, map) in cutm.charts.iter().zip(maps) {
        let (sub, global) = cutm.chart_mesh(faces);
        for (l, &g) in global.iter().enumerate() {
            uv[g as usize] = map.uv[l];
        }
        seconds_init += map.seconds_init;
        seconds_solve += map.seconds_solve;
        report.init_flips += map.init_flips;
        report.tutte_starts.add(&map.tutte_starts);
        converged &= map.converged();
        path = path.combine(map.path);
        // The report's stop line, convergence plot and global history show the largest chart.
        let is_largest = faces.len() > largest;
        if is_largest {
            largest = faces.len();
            stop = map.stop_summary();
        }
        report.iterations_start_proxy += map.start_proxy_iterations;
        if let Some(result) = &map.admm {
            report.backend = result.backend.into();
            report.device.clone_from(&result.device);
            report.iterations_admm += result.iterations;
            if is_largest {
                report.history.clone_from(&result.history);
                report.mu_rel = Some(result.mu_rel_final);
            }
        }
        if let Some(result) = map.global {
            report.iterations_global += result.iterations;
            if is_largest {
                report.global = Some(result);
            }
        }
        chart_meshes.push((global, sub));
    }
    report.iterations =
        report.iterations_start_proxy + report.iterations_admm + report.iterations_global;
    if solver != SolverChoice::None {
        report.solver = solver.name().into();
        report.solver_path = path.name().into();
        report.converged = Some(converged);
        report.energy = Some(admm.energy.name().into());
        report.stop = stop;
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
    let t_pack = Instant::now();
    let packing = pack::pack(&mut uv, &refs, &job.pack)?;
    let seconds_pack = t_pack.elapsed().as_secs_f64();

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
        texel_coverage: packing.coverage,
        pages: packing.pages,
        resolution: packing.resolution,
        padding: job.pack.padding,
        texels_per_unit: packing.texels_per_unit,
        seconds_pack,
        extra_seams: extra.len(),
        overlap_splits: splits.len(),
        injective_pieces: pieces_made,
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

/// The charts of `recut` that came from splitting the chart `faces` of `old` into injective
/// pieces, each with the part of the chart's map `map` on its faces (corner by corner: a piece
/// is a disk cut out of the chart, so its vertices are chart vertices). The largest piece
/// carries the chart's solver record (iterations, path, stop test); the others have none.
fn pieces_of(
    old: &crate::param::cut::CutMesh,
    recut: &crate::param::cut::CutMesh,
    faces: &[u32],
    map: MapOutput,
) -> Vec<(Vec<u32>, MapOutput)> {
    let (sub, _) = old.chart_mesh(faces);
    let corner_uv = |i: usize| sub.faces[i].map(|v| map.uv[v as usize]);
    let mut out: Vec<(Vec<u32>, MapOutput)> = recut
        .charts
        .iter()
        .filter(|c| c.first().is_some_and(|f| faces.binary_search(f).is_ok()))
        .map(|c| {
            let (piece, _) = recut.chart_mesh(c);
            let mut uv = vec![[0.0; 2]; piece.positions.len()];
            for (k, &f) in c.iter().enumerate() {
                let i = faces
                    .binary_search(&f)
                    .expect("a piece's faces are its chart's");
                for (&v, p) in piece.faces[k].iter().zip(corner_uv(i)) {
                    uv[v as usize] = p;
                }
            }
            (c.clone(), MapOutput::unsolved(uv, 0, 0.0))
        })
        .collect();
    if let Some(largest) = out.iter_mut().max_by_key(|(c, _)| c.len()) {
        let uv = std::mem::take(&mut largest.1.uv);
        largest.1 = MapOutput { uv, ..map };
    }
    out
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
    lscm: &mut LscmCache,
) -> Result<Option<(u32, f64)>> {
    let mut worst: Option<(u32, f64)> = None;
    let mut kept = LscmCache::default();
    for faces in &cutm.charts {
        if faces.len() < 2 {
            continue;
        }
        let (sub, global) = cutm.chart_mesh(faces);
        let key = (faces.clone(), global.clone());
        let uv = match lscm.0.remove(&key) {
            Some(uv) => uv,
            None => {
                let sub_topo = Topology::build(&sub, file)?;
                initial_map(&sub, &sub_topo, InitMethod::Lscm).ok()
            }
        };
        let Some(uv) = kept.0.entry(key).or_insert(uv).as_ref() else {
            continue;
        };
        let frames = mesh::frames::compute(&sub);
        let area_uv: Vec<f64> = sub
            .faces
            .iter()
            .map(|f| crate::init::face_area_2d(uv, f))
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
                if worst.is_none_or(|w| ratio > w.1) {
                    worst = Some((cutm.origin[global[v] as usize], ratio));
                }
            }
        }
    }
    // Only the current charts' maps are worth keeping.
    *lscm = kept;
    Ok(worst)
}

/// LSCM maps of charts (`None`: LSCM failed), by chart: its faces and the cut mesh's vertex
/// of each of its vertices, which together fix the chart's mesh (a seam inside a chart keeps
/// its faces but splits vertices). LSCM is deterministic, so a kept map is the map.
#[derive(Default)]
struct LscmCache(std::collections::HashMap<ChartKey, Option<Uv>>);

/// A chart's faces and the cut mesh's vertex of each of its vertices.
type ChartKey = (Vec<u32>, Vec<u32>);
type Uv = Vec<[f64; 2]>;

impl LscmCache {
    fn take(&mut self, faces: &[u32], global: &[u32]) -> Option<Option<Uv>> {
        self.0.remove(&(faces.to_vec(), global.to_vec()))
    }
}
