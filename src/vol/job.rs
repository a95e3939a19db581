//! `foldfree volmap` / `volcheck` as library calls: reading and checking the inputs, building
//! the start map and constraints for each mode, progress display, writing and re-checking
//! the output, and the JSON report. main.rs only parses arguments.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::ball::{ball_target, slide_on_sphere, SlideReport};
use super::constraints::{constraints_text, read_constraints};
use super::harmonic::harmonic_extension;
use super::tetgen::{read_any, write_any};
use super::volmap::{evaluate, volmap, MapQuality, VolmapOptions, VolmapReport};
use super::{TetMesh, VolError};

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
    pub quiet: bool,
    pub options: VolmapOptions,
}

/// The JSON written by `--report`.
#[derive(Clone, Debug, Serialize)]
pub struct VolmapFileReport {
    pub rest: String,
    pub init: Option<String>,
    pub output: String,
    pub constraints: String,
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
}

/// Reads a rest mesh and checks it (orientation, zero volumes).
pub fn read_rest(path: &Path) -> Result<TetMesh, VolError> {
    let m = read_any(path)?;
    m.check_rest(path)?;
    Ok(m)
}

/// Reads a map of `rest` (same tets), returning its positions.
pub fn read_map(rest: &TetMesh, rest_path: &Path, path: &Path) -> Result<Vec<[f64; 3]>, VolError> {
    let m = read_any(path)?;
    if m.positions.len() != rest.positions.len() || m.tets != rest.tets {
        return Err(VolError::Input(format!(
            "{}: not a map of {} ({} vertices / {} tets against {} / {}, or different tets)",
            path.display(),
            rest_path.display(),
            m.positions.len(),
            m.tets.len(),
            rest.positions.len(),
            rest.tets.len()
        )));
    }
    Ok(m.positions)
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
        ConstraintSource::Ball => Ok(ball_target(rest)?.1),
    }
}

/// Runs a job end to end and returns the report (also written to `job.report`).
pub fn run_volmap_job(job: &VolmapJob) -> Result<VolmapFileReport, VolError> {
    if job.output == job.rest || Some(&job.output) == job.init.as_ref() {
        return Err(VolError::Input(
            "refusing to overwrite an input with the output".into(),
        ));
    }
    let rest = read_rest(&job.rest)?;
    let init_pos = match &job.init {
        Some(p) => Some(read_map(&rest, &job.rest, p)?),
        None => None,
    };
    let mut sphere_bad = None;
    let mut sliding = None;
    let (init, targets) = match &job.constraints {
        ConstraintSource::Ball => {
            let (start, t, bad) = ball_target(&rest)?;
            sphere_bad = Some(bad);
            let start = init_pos.unwrap_or(start);
            match &job.options.untangle {
                Some(u) => {
                    let (x, slid, s) =
                        slide_on_sphere(&rest, &start, &t, u, job.options.ball_relax.as_ref())?;
                    let ok = s.inverted_left == 0;
                    sliding = Some(s);
                    if ok {
                        (x, slid)
                    } else {
                        (start, t)
                    }
                }
                None => (start, t),
            }
        }
        src => {
            let t = constraints_for(&rest, init_pos.as_deref(), src)?;
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
    let out = volmap(&rest, &init, &targets, &job.options, &mut |phase, it, e| {
        if phase != current {
            current = phase.to_string();
            bar.set_prefix(current.clone());
        }
        bar.set_position(it as u64);
        bar.set_message(format!("E {e:.6e}"));
    });
    bar.finish_and_clear();
    let (x, run) = out?;
    write_any(&job.output, &rest, &x)?;
    // Independent check of what was written.
    let written_pos = read_map(&rest, &job.rest, &job.output)?;
    let written = evaluate(&rest, &written_pos, &targets);
    if written.inverted > 0 {
        return Err(VolError::BadResult(format!(
            "{}: {} inverted tet(s) after writing",
            job.output.display(),
            written.inverted
        )));
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
        sphere_nonpositive_faces: sphere_bad,
        sphere_sliding: sliding,
        run,
        written,
    };
    if let Some(p) = &job.write_constraints {
        let header = format!(
            "constraints met by {} (foldfree volmap {})\nvertex_index x y z (0-based)",
            job.output.display(),
            job.rest.display()
        );
        crate::mesh::write_atomic(p, constraints_text(&targets, &header).as_bytes()).map_err(
            |source| VolError::Io {
                path: p.clone(),
                source,
            },
        )?;
    }
    if let Some(p) = &job.report {
        let text = serde_json::to_string_pretty(&report)
            .map_err(|e| VolError::BadResult(format!("report serialisation: {e}")))?;
        crate::mesh::write_atomic(p, text.as_bytes()).map_err(|source| VolError::Io {
            path: p.clone(),
            source,
        })?;
    }
    Ok(report)
}
