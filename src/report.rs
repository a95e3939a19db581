//! The JSON run report written by `foldfree param --report R.json`.
//!
//! Non-finite numbers (the energies of a flipped map) are written as `null`, since JSON has no
//! infinity; `flips` tells why.
#![forbid(unsafe_code)]

use serde::Serialize;

/// Everything a run measured. Field names are part of the CLI's interface.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ParamReport {
    pub input: String,
    pub output: String,
    pub vertices: usize,
    pub faces: usize,
    pub interior_edges: usize,
    pub boundary_loops: usize,
    pub unreferenced_vertices: usize,
    /// Pinched (non-manifold) vertices of the input, each split into one vertex per fan for the
    /// map: the `vt` of the sheets that touched there are separate.
    pub pinched_vertices_split: usize,
    pub flips: usize,
    pub delta_con_mean: f64,
    pub delta_con_area_mean: f64,
    pub delta_con_max: f64,
    pub mips_energy: f64,
    pub sd_energy: f64,
    pub boundary_self_intersections: usize,
    pub seconds: f64,
    pub seconds_load: f64,
    pub seconds_init: f64,
    pub seconds_solve: f64,
    pub backend: String,
    pub device: String,
    pub init: String,
    /// The solver asked for: `none`, `admm` or `global`.
    pub solver: String,
    /// The solvers that ran, in order: `none`, `admm`, `admm+global` (ADMM stopped short and
    /// handed its best flip-free map to the global solver) or `global`; for an atlas the
    /// longest path any chart took.
    pub solver_path: String,
    /// Why the run stopped and, when it did not converge, how far from the stop test it was
    /// (the largest chart for an atlas).
    pub stop: String,
    pub energy: Option<String>,
    /// `iterations_start_proxy + iterations_admm + iterations_global`.
    pub iterations: usize,
    /// Proxy iterations of the global solver that made ADMM's SD start (0 otherwise).
    pub iterations_start_proxy: usize,
    pub iterations_admm: usize,
    pub iterations_global: usize,
    /// Whether the stop test of the last solver was met (every chart's, for an atlas). A map
    /// that did not converge is still written (exit code 3).
    pub converged: Option<bool>,
    pub mu_rel: Option<f64>,
    pub init_flips: usize,
    /// Maps a solver was to start from that were replaced by Tutte's embedding, by reason,
    /// over all charts: the map the report's `init` names, or ADMM's result handed on (one
    /// chart can count more than once).
    pub tutte_starts: TutteStarts,
    /// Device time per kernel (`--profile`, Vulkan only).
    pub kernel_times: Option<crate::param::admm::vulkan::KernelTimes>,
    /// Bytes the kernels read and write per iteration (Vulkan only), for bandwidth estimates.
    pub bytes_per_iteration: Option<u64>,
    pub history: Vec<crate::param::admm::History>,
    /// Whether the output OBJ was written: always when a report is produced — every run that
    /// has a flip-free map writes it.
    pub written: bool,
    /// How the written texture coordinates are to be read.
    pub uv_output: UvOutput,
    /// Seams, charts and packing, when the mesh was cut into charts.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub atlas: Option<AtlasReport>,
    /// The global solver's stop reason, per-phase totals and per-iteration history (when it
    /// ran: `--solver global`, or after ADMM's hand-off).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub global: Option<crate::param::global::GlobalResult>,
}

/// Why maps were replaced by Tutte's embedding before a solve, counted. Tutte's map of a disk
/// is flip-free with a convex boundary whatever the mesh, so every solver can start from it;
/// the report says so, since the `init` it names was then not where the solver started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct TutteStarts {
    /// The map had flipped faces (no solver crosses det = 0).
    pub folded: usize,
    /// Its energy was infinite (a face shrunk to nothing: a barrier no step crosses).
    pub non_finite: usize,
    /// Its boundary crossed or touched itself (the bijective solvers start from a simple one).
    pub boundary_crosses_itself: usize,
}

impl TutteStarts {
    /// Counts one replacement of a map that is `folded`, of `finite` energy and with a
    /// `simple` boundary (the first reason that holds); false when there is none.
    pub fn note(&mut self, folded: bool, finite: bool, simple: bool) -> bool {
        if folded {
            self.folded += 1;
        } else if !finite {
            self.non_finite += 1;
        } else if !simple {
            self.boundary_crosses_itself += 1;
        } else {
            return false;
        }
        true
    }

    /// The counts of `self` and `o` together (an atlas's charts).
    pub fn add(&mut self, o: &TutteStarts) {
        self.folded += o.folded;
        self.non_finite += o.non_finite;
        self.boundary_crosses_itself += o.boundary_crosses_itself;
    }
}

/// The written file's texture-coordinate convention, so that a reader of the report knows how
/// to read the UVs without knowing the formats: OBJ's origin is the image's bottom-left (foldfree
/// works in it), glTF's is the top-left (`v_file = 1 − v`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct UvOutput {
    /// `obj` or `gltf`.
    pub format: &'static str,
    /// `bottom-left` (OBJ) or `top-left` (glTF: written as `v' = 1 − v`).
    pub v_origin: &'static str,
    /// glTF: the `TEXCOORD_n` written, per primitive in file order (meshes, then primitives).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub texcoord_sets: Vec<u32>,
}

impl UvOutput {
    pub fn obj() -> UvOutput {
        UvOutput {
            format: "obj",
            v_origin: "bottom-left",
            texcoord_sets: Vec::new(),
        }
    }
}

impl ParamReport {
    /// Copies the map's measures (flips, distortions, energies, overlaps).
    pub fn set_metrics(&mut self, m: &crate::metrics::Metrics) {
        self.flips = m.flips;
        self.delta_con_mean = m.delta_con_mean;
        self.delta_con_area_mean = m.delta_con_area_mean;
        self.delta_con_max = m.delta_con_max;
        self.mips_energy = m.mips_energy;
        self.sd_energy = m.sd_energy;
        self.boundary_self_intersections = m.boundary_self_intersections;
    }
}

/// What cutting and packing did (`foldfree param` on a mesh that is not a disk).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct AtlasReport {
    pub charts: usize,
    /// Faces per chart.
    pub chart_faces: Vec<usize>,
    /// `vt` records written (split vertices).
    pub texture_coordinates: usize,
    /// Input edges cut open.
    pub seam_edges: usize,
    /// Their total 3D length.
    pub seam_length: f64,
    /// Genus of the input (summed over components), when defined.
    pub genus: Option<i64>,
    pub components: usize,
    /// Σ chart UV area / area of the pages used (each the unit square `[k, k+1] × [0, 1]`).
    pub packing_efficiency: f64,
    /// Texels some chart touches / all texels of the pages used, at `resolution` (xatlas's
    /// "utilization").
    pub texel_coverage: f64,
    /// Texture pages used (`--max-pages`; page `k` is UDIM tile 1001 + k).
    pub pages: u32,
    /// Texture side in texels, and the empty texels kept between charts and to the border.
    pub resolution: u32,
    pub padding: u32,
    /// Texels per unit of 3D length.
    pub texels_per_unit: f64,
    /// Seconds spent packing.
    pub seconds_pack: f64,
    /// Seams added to relieve stretched tips (`CutOptions::extra_seams`).
    pub extra_seams: usize,
    /// Charts split because their map's boundary overlapped itself
    /// (`CutOptions::overlap_splits`).
    pub overlap_splits: usize,
    /// Charts added by splitting charts whose map still overlapped itself after those seams
    /// into pieces that do not overlap, each keeping its part of the map
    /// ([`crate::param::injective`]).
    pub injective_pieces: usize,
    pub seconds_cut: f64,
}

/// The summary `foldfree param` prints: what ran, how far it converged, the distortion, and
/// the atlas and device-time lines when there are any (one line each, no trailing newline).
impl std::fmt::Display for ParamReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let r = self;
        write!(
            f,
            "foldfree: {} → {}: {} faces, backend {} ({}), init {}, solver {}",
            r.input, r.output, r.faces, r.backend, r.device, r.init, r.solver_path
        )?;
        match r.converged {
            Some(true) => write!(f, ", converged in {} iterations", r.iterations)?,
            Some(false) => write!(
                f,
                ", NOT converged after {} iterations (best flip-free map written)",
                r.iterations
            )?,
            None => {}
        }
        if r.solver_path == "admm+global" {
            write!(f, "\n  {}", r.stop)?;
        }
        write!(
            f,
            "\n  flips {}  δcon mean {:.4} (area-weighted {:.4}, max {:.3})  MIPS {:.5}  SD {:.5}  boundary overlaps {}  {:.2} s",
            r.flips,
            r.delta_con_mean,
            r.delta_con_area_mean,
            r.delta_con_max,
            r.mips_energy,
            r.sd_energy,
            r.boundary_self_intersections,
            r.seconds
        )?;
        if let Some(a) = &r.atlas {
            write!(
                f,
                "\n  cut: {} chart(s), {} seam edges (length {:.4}), {} vt; packed in {} page(s) of {}² with {} texels padding: efficiency {:.1}% of the area, {:.1}% of the texels",
                a.charts,
                a.seam_edges,
                a.seam_length,
                a.texture_coordinates,
                a.pages,
                a.resolution,
                a.padding,
                100.0 * a.packing_efficiency,
                100.0 * a.texel_coverage
            )?;
            if a.overlap_splits + a.injective_pieces > 0 {
                write!(
                    f,
                    "\n  charts whose map overlapped itself: {} split by a seam and re-mapped, {} more cut into pieces that keep their map",
                    a.overlap_splits, a.injective_pieces
                )?;
            }
        }
        if let Some(t) = &r.kernel_times {
            let per = |ns: u64| ns as f64 / 1e3 / t.iterations.max(1) as f64;
            write!(
                f,
                "\n  device time per iteration: face_newton {:.1} µs, edge_project {:.1} µs, dual_update {:.1} µs; residual {:.1} µs per check",
                per(t.face_newton_ns),
                per(t.edge_project_ns),
                per(t.dual_update_ns),
                t.residual_ns as f64 / 1e3 / r.history.len().max(1) as f64
            )?;
        }
        Ok(())
    }
}
