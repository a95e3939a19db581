//! `foldfree volmap` / `volcheck` as library calls: reading and checking the inputs, building
//! the start map and constraints for each mode, progress display, writing and re-checking
//! the output, and the JSON report. main.rs only parses arguments.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::ball::{ball_target, slide_on_sphere, Slid, SlideReport};
use super::constraints::{constraints_text, read_constraints};
use super::harmonic::harmonic_extension;
use super::tetgen::{
    files_of, output_texts, parse_output, read_any_with_limit, tet_input, tet_output,
};
use super::volmap::{evaluate, volmap_on, MapQuality, VolmapOptions, VolmapReport};
use super::{TetMesh, VolError};
use crate::files::Outputs;
use crate::mesh::Scale;

/// Where the position constraints come from.
#[derive(Clone, Debug, PartialEq)]
pub enum ConstraintSource {
    /// The init's boundary vertex positions (needs an init).
    FixBoundary,
    /// A `vertex x y z` file.
    File(PathBuf),
    /// Boundary onto the unit sphere, interior harmonic.
    Ball,
}

/// One `foldfree volmap` run.
#[derive(Clone, Debug)]
pub struct VolmapJob {
    pub rest: PathBuf,
    pub init: Option<PathBuf>,
    pub constraints: ConstraintSource,
    pub output: PathBuf,
    pub report: Option<PathBuf>,
    /// Where to write the constraints the map meets (`vertex x y z`).
    pub write_constraints: Option<PathBuf>,
    /// Where to write the rest mesh the map is of: the input, or the input refined where the
    /// ball target split edges ([`SlideReport::splits`]), so `volcheck` can check the map.
    pub write_rest: Option<PathBuf>,
    pub quiet: bool,
    /// Refuse meshes of more tets (and files larger than such a mesh's text).
    pub max_tets: usize,
    pub options: VolmapOptions,
    /// Where the untangler's per-tet terms run (`--backend`); `device` names a Vulkan device,
    /// `validation` turns on the validation layer.
    pub backend: crate::gpu::BackendChoice,
    pub device: Option<String>,
    pub validation: bool,
}

/// The JSON written by `--report`.
#[derive(Clone, Debug, Serialize)]
pub struct VolmapFileReport {
    pub rest: String,
    pub init: Option<String>,
    pub output: String,
    pub constraints: String,
    /// Where the untangler's per-tet terms ran: "cpu", or the Vulkan device's name.
    pub backend: String,
    /// Ball target: boundary triangles not positive seen from the centre (0 = star-shaped).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sphere_nonpositive_faces: Option<usize>,
    /// Ball target: the untangling with the boundary sliding on the sphere, whose end
    /// positions became the constraints (when it left no tet inverted).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sphere_sliding: Option<SlideReport>,
    #[serde(flatten)]
    pub run: VolmapReport,
    /// Re-measured from the written file.
    pub written: MapQuality,
    /// ρ < θ, judged at the solve's unit scale (see [`run_volmap_job`]): the map is the
    /// requested one. When false the fold-free map is still written, and the CLI exits 3.
    pub constraints_met: bool,
}

/// Reads a rest mesh of at most `max_tets` tets and checks it (structure, orientation, zero
/// volumes).
pub fn read_rest(path: &Path, max_tets: usize) -> Result<TetMesh, VolError> {
    let m = read_any_with_limit(path, max_tets)?;
    m.check_rest(path)?;
    Ok(m)
}

/// Reads a map of `rest` (same tets), returning its positions.
pub fn read_map(rest: &TetMesh, rest_path: &Path, path: &Path) -> Result<Vec<[f64; 3]>, VolError> {
    // Twice the rest's tets: a file that large cannot be a map of it, but a map of it refined
    // by the ball target still reads, and is then named as a map of another mesh.
    let m = read_any_with_limit(path, rest.tets.len().saturating_mul(2))?;
    same_tets(rest, rest_path, &m, path)?;
    Ok(m.positions)
}

/// `m` (read from `path`) has the vertex count and the tets of `rest`.
fn same_tets(rest: &TetMesh, rest_path: &Path, m: &TetMesh, path: &Path) -> Result<(), VolError> {
    if m.positions.len() != rest.positions.len() || m.tets != rest.tets {
        return Err(VolError::Input(format!(
            "{}: not a map of {} ({} vertices / {} tets against {} / {}, or different tets; a \
             ball map refined where the untangler found no room is a map of the rest written \
             with --write-rest)",
            path.display(),
            rest_path.display(),
            m.positions.len(),
            m.tets.len(),
            rest.positions.len(),
            rest.tets.len()
        )));
    }
    Ok(())
}

/// Constraints of a mode, given the rest mesh and the (optional) init positions.
pub fn constraints_for(
    rest: &TetMesh,
    init: Option<&[[f64; 3]]>,
    source: &ConstraintSource,
) -> Result<Vec<(u32, [f64; 3])>, VolError> {
    match source {
        ConstraintSource::FixBoundary => {
            let init = init.ok_or_else(|| VolError::Input("--fix-boundary needs --init".into()))?;
            Ok(rest
                .boundary_vertices()
                .into_iter()
                .map(|v| (v, init[v as usize]))
                .collect())
        }
        ConstraintSource::File(p) => read_constraints(p, rest.positions.len()),
        ConstraintSource::Ball => Ok(ball_target(rest, None)?.1),
    }
}

/// `--target ball` maps the rest onto the unit sphere of its own coordinates, so the rest's
/// size is part of the problem: beyond 1e±100 the map's Jacobians (≈ 1/size) make the
/// distortion ‖J‖² + ‖J⁻¹‖² overflow f64 (1e±300 squared), and no solve can succeed. That is
/// the input's units, refused up front, not a solver failure after the work.
fn ball_scale_in_range(rest: &TetMesh, path: &Path) -> Result<(), VolError> {
    let f = Scale::fit(&rest.positions).factor;
    // 2^±340 ≈ 2e±102: every mesh between 1e-100 and 1e100 across passes (the factor is the
    // power of two at or above its largest coordinate).
    if !(2f64.powi(-340)..=2f64.powi(340)).contains(&f) {
        return Err(VolError::Input(format!(
            "{}: --target ball maps onto the unit sphere, but the mesh is about {f:.0e} across: \
             the map's distortion would overflow; scale the mesh to between 1e-100 and 1e100",
            path.display()
        )));
    }
    Ok(())
}

/// Runs a job end to end and returns the report. Every output (the map, its TetGen pair, the
/// report, the constraints met) is checked before the work and committed together after the
/// written map was re-read and checked; on any error nothing is written.
pub fn run_volmap_job(job: &VolmapJob) -> Result<VolmapFileReport, VolError> {
    job.options.validate()?;
    let mut outputs = Outputs::new();
    tet_input(&mut outputs, &job.rest);
    if let Some(p) = &job.init {
        tet_input(&mut outputs, p);
    }
    if let ConstraintSource::File(p) = &job.constraints {
        outputs.input(p);
    }
    tet_output(&mut outputs, &job.output, "map")?;
    if let Some(p) = &job.report {
        outputs.output(p, "report", &["json"])?;
    }
    if let Some(p) = &job.write_constraints {
        outputs.output(p, "constraints", &[])?;
    }
    if let Some(p) = &job.write_rest {
        tet_output(&mut outputs, p, "rest")?;
    }
    let mut rest_file = read_rest(&job.rest, job.max_tets)?;
    let ctx = crate::gpu::open_backend(job.backend, job.device.as_deref(), job.validation)?;
    let init_file = match &job.init {
        Some(p) => Some(read_map(&rest_file, &job.rest, p)?),
        None => None,
    };
    // The solve runs at unit scale (exactly: a power of two; J, δ_t and every step are
    // unchanged), so a mesh in nanometres or in light years is the same problem, and θ judges ρ
    // at that scale. The ball target is the unit sphere of the output's coordinates: there the
    // rest's size is part of the problem, and nothing is rescaled.
    let scale = match job.constraints {
        ConstraintSource::Ball => Scale::default(),
        _ => Scale::fit(&rest_file.positions),
    };
    if job.constraints == ConstraintSource::Ball {
        ball_scale_in_range(&rest_file, &job.rest)?;
    }
    // Problems of the input found while solving (a boundary surface that is not a sphere, a
    // degenerate tet) name the rest file, as the reader's errors do.
    let locate = |e: VolError| match e {
        VolError::Input(msg) => VolError::Input(format!("{}: {msg}", job.rest.display())),
        e => e,
    };
    let scaled = |p: &[[f64; 3]]| -> Vec<[f64; 3]> { p.iter().map(|&q| scale.apply(q)).collect() };
    let mut rest = TetMesh {
        positions: scaled(&rest_file.positions),
        ..rest_file.clone()
    };
    let init_pos = init_file.as_deref().map(scaled);
    let mut sphere_bad = None;
    let mut sliding = None;
    let (init, targets) = match &job.constraints {
        ConstraintSource::Ball => {
            let (start, t, bad) =
                ball_target(&rest, job.options.sphere_relax.as_ref()).map_err(locate)?;
            sphere_bad = Some(bad);
            let start = init_pos.unwrap_or(start);
            match &job.options.untangle {
                Some(u) => {
                    let Slid {
                        mesh: refined,
                        map: x,
                        targets: slid,
                        report: mut s,
                    } = slide_on_sphere(
                        &rest,
                        &start,
                        &t,
                        u,
                        job.options.ball_relax.as_ref(),
                        job.options.ball_refine_rounds,
                        ctx.as_ref(),
                    )
                    .map_err(locate)?;
                    let ok = s.inverted_left == 0;
                    if ok {
                        // The edges split on the way are the output's: the rest refined
                        // the same way (midpoints; appended vertices and tets).
                        if !s.splits.is_empty() {
                            rest_file = TetMesh {
                                positions: refined
                                    .positions
                                    .iter()
                                    .map(|&p| scale.invert(p))
                                    .collect(),
                                ..refined.clone()
                            };
                            rest = refined;
                        }
                        sliding = Some(s);
                        (x, slid)
                    } else {
                        // The paper's phases go on from the start on the input's tets.
                        s.splits.clear();
                        sliding = Some(s);
                        (start, t)
                    }
                }
                None => (start, t),
            }
        }
        src => {
            let mut t = constraints_for(&rest, init_pos.as_deref(), src)?;
            if let ConstraintSource::File(path) = src {
                for (_, p) in &mut t {
                    *p = scale.apply(*p);
                }
                // At unit scale a target 1e100 away has a squared distance of 1e200, and the
                // penalty energy multiplies that again: further out it overflows and no
                // fold-free map can be found (was exit 1 after the work). The file's fault.
                if let Some((v, p)) = t.iter().find(|(_, p)| p.iter().any(|c| c.abs() > 1e100)) {
                    return Err(VolError::Input(format!(
                        "{}: the target of vertex {v} ({:e}, {:e}, {:e}) is more than 1e100 \
                         times the rest mesh's size away; its squared distance overflows f64",
                        path.display(),
                        scale.invert(*p)[0],
                        scale.invert(*p)[1],
                        scale.invert(*p)[2]
                    )));
                }
            }
            let init = match init_pos {
                Some(p) => p,
                None => harmonic_extension(&rest, &rest.positions, &t)?,
            };
            (init, t)
        }
    };
    let bar = if job.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        let b = indicatif::ProgressBar::new_spinner();
        b.set_style(
            indicatif::ProgressStyle::with_template("{spinner} {prefix:>20} it {pos:>4}  {msg}")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner()),
        );
        b
    };
    let mut current = String::new();
    let out = volmap_on(
        &rest,
        &init,
        &targets,
        &job.options,
        ctx.as_ref(),
        &mut |phase, it, e| {
            if phase != current {
                current = phase.to_string();
                bar.set_prefix(current.clone());
            }
            bar.set_position(it as u64);
            bar.set_message(format!("E {e:.6e}"));
        },
    );
    bar.finish_and_clear();
    let (x, mut run) = out.map_err(locate)?;
    if let Some(ctx) = &ctx {
        ctx.check_validation_messages()?;
    }
    let x: Vec<[f64; 3]> = x.iter().map(|&p| scale.invert(p)).collect();
    let texts = output_texts(&job.output, &rest_file, &x)?;
    // Independent check of what will be written: parsed back from the text, judged at the
    // solve's scale, reported in the file's units (ρ is a squared length).
    let written_mesh = parse_output(&job.output, &texts)?;
    same_tets(&rest_file, &job.rest, &written_mesh, &job.output)?;
    let mut written = evaluate(&rest, &scaled(&written_mesh.positions), &targets);
    let constraints_met = written.rho < job.options.theta;
    let area = |r: f64| scale.length(scale.length(r));
    written.rho = area(written.rho);
    run.quality.rho = area(run.quality.rho);
    for p in &mut run.phases {
        p.rho = area(p.rho);
    }
    let targets: Vec<(u32, [f64; 3])> =
        targets.iter().map(|&(v, p)| (v, scale.invert(p))).collect();
    if written.inverted > 0 || !written.delta_t.is_finite() {
        return Err(VolError::BadResult(format!(
            "{}: the map has {} inverted tet(s) (δ_t {}); nothing was written",
            job.output.display(),
            written.inverted,
            written.delta_t
        )));
    }
    for (f, t) in files_of(&job.output)?.iter().zip(texts) {
        outputs.set(f, t.into_bytes());
    }
    if let Some(p) = &job.write_rest {
        let texts = output_texts(p, &rest_file, &rest_file.positions)?;
        for (f, t) in files_of(p)?.iter().zip(texts) {
            outputs.set(f, t.into_bytes());
        }
    }
    let report = VolmapFileReport {
        rest: job.rest.display().to_string(),
        init: job.init.as_ref().map(|p| p.display().to_string()),
        output: job.output.display().to_string(),
        constraints: match &job.constraints {
            ConstraintSource::FixBoundary => "fix-boundary".into(),
            ConstraintSource::File(p) => p.display().to_string(),
            ConstraintSource::Ball => "ball".into(),
        },
        backend: ctx
            .as_ref()
            .map_or_else(|| "cpu".to_string(), |c| c.device_name().to_string()),
        sphere_nonpositive_faces: sphere_bad,
        sphere_sliding: sliding,
        run,
        written,
        constraints_met,
    };
    if let Some(p) = &job.write_constraints {
        let header = format!(
            "constraints met by {} (foldfree volmap {})\nvertex_index x y z (0-based)",
            job.output.display(),
            job.rest.display()
        );
        outputs.set(p, constraints_text(&targets, &header).into_bytes());
    }
    if let Some(p) = &job.report {
        let text = serde_json::to_vec_pretty(&report)
            .map_err(|e| VolError::BadResult(format!("report serialisation: {e}")))?;
        outputs.set(p, text);
    }
    outputs.commit()?;
    Ok(report)
}

/// The summary `foldfree volmap` prints: the map's quality, then one line per phase (no
/// trailing newline).
impl std::fmt::Display for VolmapFileReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = self;
        let q = &r.written;
        write!(
            f,
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
        )?;
        if let Some(s) = &r.sphere_sliding {
            write!(
                f,
                "\n  {:<20} {:>4} it {:>6} ε   {:>7.2} s  inverted {} → {} (boundary sliding on the sphere)",
                "ball untangle", s.iterations, s.eps_updates, s.seconds, s.inverted_start, s.inverted_left
            )?;
            if let Some(&[first, ..]) = s.splits.first() {
                write!(
                    f,
                    "\n  {:<20} {:>4} interior edge(s) split where the untangler found no room: vertices {first}–{} appended at edge midpoints, {} tets now (--write-rest writes the refined rest)",
                    "ball refine",
                    s.splits.len(),
                    first as usize + s.splits.len() - 1,
                    q.tets,
                )?;
            }
            if let Some(d) = s.delta_t_before_relax {
                write!(
                    f,
                    "\n  {:<20} {:>4} it {:>9} {:>7.2} s  δ_t {d:.4} before (boundary sliding on the sphere)",
                    "ball relax", s.relax_iterations, "", s.relax_seconds
                )?;
            }
        }
        for p in &r.run.phases {
            write!(
                f,
                "\n  {:<20} {:>4} it {:>6} cg  {:>7.2} s  E {:.6e}  ρ {:.3e}",
                p.name, p.iterations, p.cg_iterations, p.seconds, p.energy, p.rho
            )?;
        }
        Ok(())
    }
}
