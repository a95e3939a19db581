//! The pipeline of Xu & Liu 2022 ("Generation of foldover-free volumetric mapping guided by
//! Jacobian matrix"): guide Jacobians from an initial map that may fold, a guided deformation
//! that starts from the (fold-free) rest shape, position constraints by an increasing
//! penalty, then a distortion-only post-optimisation with the constrained vertices fixed.
//! Every phase runs [`newton`] from a fold-free point with a fold-free line search, so the
//! result is fold-free by construction (and checked again before it is returned).

use std::time::Instant;

use serde::Serialize;

use super::energy::{inv3, mul3, sym_dirichlet, Mat3, IDENTITY};
use super::line_search::max_flip_free_step;
use super::newton::{
    corner_weights, edge_matrix_of, jacobian, newton, position_energy, NewtonOptions, Objective,
    Pattern,
};
use super::tet::{sub, TetMesh};
use super::untangle::{untangle_sliding, UntangleOptions};
use super::VolError;

/// Parameters of the method (defaults: the paper's). The `[volmap]` table of a tuning file
/// ([`crate::tuning`]); an optional phase is a table, or `false` for none.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VolmapOptions {
    /// Weight ω of ‖J' − J‖² in the deformation energy.
    pub omega: f64,
    /// Target position energy θ.
    pub theta: f64,
    /// First penalty weight λ_S and its growth per converged round.
    pub lambda0: f64,
    pub lambda_growth: f64,
    pub max_rounds: usize,
    /// When a penalty round leaves ρ above half its previous value, continue the penalty
    /// rounds with the unguided (rest-relative) distortion. Off by default: the paper's
    /// guided rounds; this variant is an experiment that has not released a stall where it
    /// was measured (BENCHMARKS.md, volumetric maps).
    pub unguide_on_stall: bool,
    /// Newton settings of the deformation and penalty phases.
    pub newton: NewtonOptions,
    /// Newton settings of the penalty rounds (separate so they can be tightened; BENCHMARKS.md
    /// records that tighter PCG did not change where a penalty stall ends: the stall is in the
    /// penalty trade-off, not in the linear solves).
    pub penalty: NewtonOptions,
    /// Newton settings of the post-optimisation (None: skipped).
    #[serde(with = "crate::tuning::phase")]
    pub post: Option<NewtonOptions>,
    /// Replace the deformation and penalty phases by the untangler of Garanzha et al. 2021
    /// started from the init with the constrained vertices on their targets (ρ = 0 by
    /// construction). If it leaves an inverted tet, the paper's phases run as usual.
    /// On by default: it imposes the constraints instead of penalising them, so when it ends
    /// fold-free ρ = 0 by construction, where the penalty rounds trade ρ against distortion
    /// and can stall above θ (BENCHMARKS.md measures both); None runs the paper's pipeline only.
    #[serde(with = "crate::tuning::phase")]
    pub untangle: Option<UntangleOptions>,
    /// `--target ball`: Newton on the distortion with the boundary sliding on the sphere,
    /// after the sliding untangler (None: skipped). Capped because the path is long: thin
    /// protrusions spread over the sphere at steps the flip-free bound keeps small, and every
    /// step is fold-free and on the sphere, so stopping early costs distortion, never validity.
    /// The cap (150) is a time budget, not a derived value; it has been measured on the shared
    /// tet meshes only, not over the corpus' tet folder (BENCHMARKS.md).
    #[serde(with = "crate::tuning::phase")]
    pub ball_relax: Option<NewtonOptions>,
    /// `--target ball`: Newton on the distortion of the boundary surface's spherical
    /// embedding before the interior is built (None: the coarse-to-fine embedding as it
    /// is). See [`super::ball::relax_on_sphere`]: every step is fold-free, so the cap is a time
    /// budget.
    #[serde(with = "crate::tuning::phase")]
    pub sphere_relax: Option<NewtonOptions>,
    /// `--target ball`: rounds of chord splits where the sliding untangler leaves tets
    /// inverted (0: never refine; the run then ends with exit 3 if a tet stays inverted).
    /// Each round splits at least one chord and there are finitely many, so the rounds end;
    /// the cap is a time budget (each round is another untangling), see
    /// [`super::ball::slide_on_sphere`].
    pub ball_refine_rounds: usize,
}

impl Default for VolmapOptions {
    fn default() -> Self {
        VolmapOptions {
            omega: 1e-4,
            theta: 1e-6,
            lambda0: 1e-3,
            lambda_growth: 1e4,
            max_rounds: 8,
            unguide_on_stall: false,
            newton: NewtonOptions::default(),
            penalty: NewtonOptions::default(),
            // The default relative stop (1e-4) of every Newton phase: the post-optimisation
            // converges linearly at a rate well below 1 (each step gains a fixed fraction of
            // what is left), so the energy it stops at is within a few 1e-4 of the limit.
            post: Some(NewtonOptions {
                max_iters: 500,
                ..NewtonOptions::default()
            }),
            untangle: Some(UntangleOptions::default()),
            ball_relax: Some(NewtonOptions {
                max_iters: 150,
                ..NewtonOptions::default()
            }),
            sphere_relax: Some(NewtonOptions::default()),
            ball_refine_rounds: 8,
        }
    }
}

impl VolmapOptions {
    /// Checks every setting against its meaningful range (the CLI's usage errors, exit 2,
    /// for hosts too): weights and tolerances positive and finite, λ growth above 1 (else the
    /// penalty rounds never tighten), iteration caps at least 1 and at most 1e6 (a cap far
    /// beyond any converging run only turns a stall into a hang).
    pub fn validate(&self) -> Result<(), crate::OptionError> {
        let bad = |what: &str, value: String, range: &str| {
            crate::OptionError::reject("volmap", what, value, range)
        };
        let pos = |x: f64| x.is_finite() && x > 0.0;
        for (what, x) in [
            ("omega", self.omega),
            ("theta", self.theta),
            ("lambda0", self.lambda0),
        ] {
            if !pos(x) {
                return bad(what, x.to_string(), "(0, ∞), finite");
            }
        }
        if !(self.lambda_growth.is_finite() && self.lambda_growth > 1.0) {
            return bad(
                "lambda_growth",
                self.lambda_growth.to_string(),
                "(1, ∞), finite",
            );
        }
        if !(1..=1000).contains(&self.max_rounds) {
            return bad("max_rounds", self.max_rounds.to_string(), "[1, 1000]");
        }
        if self.ball_refine_rounds > 1000 {
            return bad(
                "ball_refine_rounds",
                self.ball_refine_rounds.to_string(),
                "[0, 1000]",
            );
        }
        let newtons = [
            ("newton", Some(&self.newton)),
            ("penalty", Some(&self.penalty)),
            ("post", self.post.as_ref()),
            ("ball_relax", self.ball_relax.as_ref()),
            ("sphere_relax", self.sphere_relax.as_ref()),
        ];
        for (what, n) in newtons {
            let Some(n) = n else { continue };
            if !(1..=1_000_000).contains(&n.max_iters) {
                return bad(
                    &format!("{what}.max_iters"),
                    n.max_iters.to_string(),
                    "[1, 1e6]",
                );
            }
            if !(pos(n.rel_tol) && n.rel_tol < 1.0) {
                return bad(&format!("{what}.rel_tol"), n.rel_tol.to_string(), "(0, 1)");
            }
            if !(pos(n.cg.tolerance) && n.cg.tolerance < 1.0) {
                return bad(
                    &format!("{what}.cg.tolerance"),
                    n.cg.tolerance.to_string(),
                    "(0, 1)",
                );
            }
        }
        if let Some(u) = &self.untangle {
            for (what, n) in [
                ("untangle.max_outer", u.max_outer),
                ("untangle.max_inner", u.max_inner),
            ] {
                if !(1..=1_000_000).contains(&n) {
                    return bad(what, n.to_string(), "[1, 1e6]");
                }
            }
            if u.stall_decades.is_nan() || u.stall_decades <= 0.0 {
                return bad(
                    "untangle.stall_decades",
                    u.stall_decades.to_string(),
                    "(0, ∞]",
                );
            }
        }
        Ok(())
    }
}

/// One phase of the run.
#[derive(Clone, Debug, Serialize)]
pub struct PhaseReport {
    pub name: String,
    pub iterations: usize,
    pub cg_iterations: usize,
    pub seconds: f64,
    /// Objective at the end of the phase.
    pub energy: f64,
    /// Penalty weight (penalty rounds only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lambda: Option<f64>,
    /// Position energy ρ at the end of the phase.
    pub rho: f64,
}

/// Distortion and validity of a map of a rest mesh.
#[derive(Clone, Copy, Debug, Default, Serialize, PartialEq)]
pub struct MapQuality {
    pub tets: usize,
    /// Tets with det ≤ 0 (or NaN).
    pub inverted: usize,
    /// Volume-weighted mean of ‖J‖² + ‖J⁻¹‖² over all tets (∞ if any is inverted).
    pub delta_t: f64,
    /// The same over tets with at least one unconstrained vertex.
    pub delta_t_free: f64,
    /// Tets whose four vertices are all constrained.
    pub pinned_tets: usize,
    /// Largest per-tet ‖J‖² + ‖J⁻¹‖².
    pub max_distortion: f64,
    /// Position energy ρ = Σ‖xᵥ − x̃ᵥ‖² over the constraints.
    pub rho: f64,
}

/// The JSON report of `foldfree volmap`.
#[derive(Clone, Debug, Serialize)]
pub struct VolmapReport {
    pub vertices: usize,
    pub tets: usize,
    pub constrained_vertices: usize,
    pub inverted_init: usize,
    pub inverted_output: usize,
    pub quality: MapQuality,
    /// Constrained vertices were moved exactly onto their targets (ρ = 0) by a fold-free step.
    pub snapped: bool,
    pub phases: Vec<PhaseReport>,
    pub seconds: f64,
}

/// Rest-shape data shared by all phases: edge-matrix inverses and volume weights.
struct Rest {
    dm_inv: Vec<Mat3>,
    weight: Vec<f64>,
}

/// Ds of tet `t` at `x` (columns = edges from corner 0).
fn edge_matrix(x: &[[f64; 3]], t: &[u32; 4]) -> Mat3 {
    edge_matrix_of(t.map(|v| x[v as usize]))
}

fn rest_data(mesh: &TetMesh) -> Result<Rest, VolError> {
    let mut dm_inv = Vec::with_capacity(mesh.tets.len());
    let mut vol = Vec::with_capacity(mesh.tets.len());
    for (i, t) in mesh.tets.iter().enumerate() {
        let dm = edge_matrix(&mesh.positions, t);
        let inv = inv3(&dm).ok_or_else(|| {
            VolError::Input(format!("rest tet {i} is degenerate (singular edge matrix)"))
        })?;
        dm_inv.push(inv);
        vol.push(super::energy::det3(&dm) / 6.0);
    }
    let total: f64 = vol.iter().sum();
    Ok(Rest {
        dm_inv,
        weight: vol.iter().map(|v| v / total).collect(),
    })
}

/// The post-optimisation objective: volume-weighted symmetric Dirichlet distortion of the
/// rest → x map itself (no guide, no penalty), with `fixed` vertices held and `on_sphere`
/// ones sliding on the unit sphere.
pub fn distortion_objective(
    rest: &TetMesh,
    fixed: Vec<bool>,
    on_sphere: Vec<bool>,
) -> Result<Objective, VolError> {
    let rd = rest_data(rest)?;
    let d: Vec<_> = rd.dm_inv.iter().map(corner_weights).collect();
    Ok(Objective {
        tets: rest.tets.clone(),
        weight: rd.weight,
        d_dist: d.clone(),
        d_fit: d,
        guide: vec![IDENTITY; rest.tets.len()],
        omega: 0.0,
        targets: Vec::new(),
        lambda: 0.0,
        fixed,
        on_sphere,
    })
}

/// Per-tet ‖J‖² + ‖J⁻¹‖² of the rest → `x` Jacobian (+∞ when inverted).
pub fn tet_distortions(mesh: &TetMesh, x: &[[f64; 3]]) -> Vec<f64> {
    mesh.tets
        .iter()
        .map(|t| {
            let dm = edge_matrix(&mesh.positions, t);
            match inv3(&dm) {
                Some(inv) => sym_dirichlet(&mul3(&edge_matrix(x, t), &inv)),
                None => f64::INFINITY,
            }
        })
        .collect()
}

/// Measures a map of `mesh` against constraints (independent of the solver's state).
pub fn evaluate(mesh: &TetMesh, x: &[[f64; 3]], targets: &[(u32, [f64; 3])]) -> MapQuality {
    // Measured at the rest's unit scale (rest and map divided by one power of two: J, δ and
    // the volume weights' ratios are exact), so a rest at 1e100 mapped onto the unit sphere
    // does not overflow its volume-weighted sums; inversion is a sign, judged on the map at
    // its own unit scale.
    let rest_scale = crate::mesh::Scale::fit(&mesh.positions);
    let at = |s: crate::mesh::Scale, p: &[[f64; 3]]| -> Vec<[f64; 3]> {
        p.iter().map(|&q| s.apply(q)).collect()
    };
    let unit = TetMesh {
        positions: at(rest_scale, &mesh.positions),
        ..mesh.clone()
    };
    let xr = at(rest_scale, x);
    let xu = at(crate::mesh::Scale::fit(x), x);
    let mesh = &unit;
    let d = tet_distortions(mesh, &xr);
    let mut pinned = vec![false; x.len()];
    for (v, _) in targets {
        pinned[*v as usize] = true;
    }
    let (mut sw, mut s, mut swf, mut sf, mut max) = (0.0, 0.0, 0.0, 0.0, 0.0f64);
    let mut pinned_tets = 0;
    for (t, tet) in mesh.tets.iter().enumerate() {
        let w = mesh.volume_at(&mesh.positions, t);
        sw += w;
        s += w * d[t];
        max = max.max(d[t]);
        if tet.iter().all(|&v| pinned[v as usize]) {
            pinned_tets += 1;
        } else {
            swf += w;
            sf += w * d[t];
        }
    }
    MapQuality {
        tets: mesh.tets.len(),
        inverted: mesh.inverted(&xu).len(),
        delta_t: s / sw,
        delta_t_free: if swf > 0.0 { sf / swf } else { f64::NAN },
        pinned_tets,
        max_distortion: max,
        rho: position_energy(targets, x),
    }
}

/// Runs the method. `init` is the initial map (same vertex count as `rest`, may fold);
/// `targets` the position constraints. `progress(phase, iteration, energy)` is called after
/// every Newton step.
pub fn volmap(
    rest: &TetMesh,
    init: &[[f64; 3]],
    targets: &[(u32, [f64; 3])],
    opts: &VolmapOptions,
    progress: &mut dyn FnMut(&str, usize, f64),
) -> Result<(Vec<[f64; 3]>, VolmapReport), VolError> {
    volmap_on(rest, init, targets, opts, None, progress)
}

/// [`volmap`] with the untangler's per-tet terms on `device` (None: the CPU).
pub fn volmap_on(
    rest: &TetMesh,
    init: &[[f64; 3]],
    targets: &[(u32, [f64; 3])],
    opts: &VolmapOptions,
    device: Option<&crate::gpu::Context>,
    progress: &mut dyn FnMut(&str, usize, f64),
) -> Result<(Vec<[f64; 3]>, VolmapReport), VolError> {
    let start = Instant::now();
    let nv = rest.positions.len();
    if init.len() != nv {
        return Err(VolError::Input(format!(
            "the initial map has {} vertices, the rest mesh {nv}",
            init.len()
        )));
    }
    for (v, p) in targets {
        if *v as usize >= nv || p.iter().any(|c| !c.is_finite()) {
            return Err(VolError::Input(format!(
                "constraint on vertex {v}: index out of range or non-finite target"
            )));
        }
    }
    let rd = rest_data(rest)?;
    let pattern = Pattern::new(nv, &rest.tets);
    let inverted_init = rest.inverted(init).len();

    // 1. Guide Jacobians: the init's where it is positive, the identity elsewhere.
    let guide: Vec<Mat3> = rest
        .tets
        .iter()
        .zip(&rd.dm_inv)
        .map(|(t, inv)| {
            let j = mul3(&edge_matrix(init, t), inv);
            // A guide must be a positive Jacobian whose distortion is finite both ways: a tet
            // the init crushed to a subnormal volume has an inverse that overflows, and the
            // deformation would start at an infinite energy.
            if super::energy::det3(&j) > 0.0 && sym_dirichlet(&j).is_finite() {
                j
            } else {
                IDENTITY
            }
        })
        .collect();
    // D(J'·J⁻¹) with J' = Ds·Dm⁻¹: M = Ds·(Dm⁻¹·J⁻¹).
    let d_dist = rd
        .dm_inv
        .iter()
        .zip(&guide)
        .map(|(inv, g)| {
            // inv3 cannot fail: the guide was kept only when invertible.
            corner_weights(&mul3(inv, &inv3(g).unwrap_or(IDENTITY)))
        })
        .collect();
    let d_fit: Vec<_> = rd.dm_inv.iter().map(corner_weights).collect();
    let mut obj = Objective {
        tets: rest.tets.clone(),
        weight: rd.weight.clone(),
        d_dist,
        d_fit: d_fit.clone(),
        guide,
        omega: opts.omega,
        targets: targets.to_vec(),
        lambda: 0.0,
        fixed: vec![false; nv],
        on_sphere: Vec::new(),
    };

    // 2. Deformation from the rest shape.
    let mut x = rest.positions.clone();
    let mut phases = Vec::new();
    let mut run = |name: &str,
                   obj: &Objective,
                   x: &mut Vec<[f64; 3]>,
                   nopts: &NewtonOptions,
                   phases: &mut Vec<PhaseReport>|
     -> Result<(), VolError> {
        let t0 = Instant::now();
        if std::env::var_os("FOLDFREE_VOL_TRACE").is_some() {
            eprintln!("== {name} λ {}", obj.lambda);
        }
        let s = newton(obj, &pattern, x, nopts, &mut |it, e| progress(name, it, e)).map_err(
            |e| match e {
                VolError::BadResult(m) => VolError::BadResult(format!(
                    "{name} phase: {m}; no fold-free map was found, nothing was written"
                )),
                e => e,
            },
        )?;
        phases.push(PhaseReport {
            name: name.to_string(),
            iterations: s.iterations,
            cg_iterations: s.cg_iterations,
            seconds: t0.elapsed().as_secs_f64(),
            energy: s.energy,
            lambda: (obj.lambda != 0.0).then_some(obj.lambda),
            rho: position_energy(&obj.targets, x),
        });
        Ok(())
    };
    // 2'. Optional untangling from the init with the constraints met exactly.
    let mut untangled = false;
    let mut snapped = false;
    if let (Some(u), false) = (&opts.untangle, targets.is_empty()) {
        let mut y = init.to_vec();
        let mut fixed = vec![false; nv];
        for (v, p) in targets {
            y[*v as usize] = *p;
            fixed[*v as usize] = true;
        }
        let s = untangle_sliding(rest, &mut y, &fixed, &[], u, device)?;
        phases.push(PhaseReport {
            name: format!(
                "untangle ({} inverted left, {} with all corners fixed)",
                s.inverted, s.inverted_pinned
            ),
            iterations: s.iterations,
            cg_iterations: 0,
            seconds: s.seconds,
            energy: s.energy,
            lambda: None,
            rho: position_energy(targets, &y),
        });
        if s.inverted == 0 && y.iter().flatten().all(|c| c.is_finite()) {
            x = y;
            untangled = true;
        }
    }
    let skip = untangled;
    if !skip {
        run("deformation", &obj, &mut x, &opts.newton, &mut phases)?;
        // The deformation energy is blind to translations (and nearly to rotations, ω is tiny),
        // so the deformed shape sits wherever the rest shape was: move it rigidly onto the
        // constraints (Kabsch). A proper rigid motion changes no det and no D(J'J⁻¹).
        if targets.len() >= 3 {
            rigid_align(&mut x, targets);
        }

        // 3. Position constraints: penalty rounds until ρ < θ; after each round try to put the
        // constrained vertices exactly on their targets with one fold-free step.
        let mut unguided = false;
        if !targets.is_empty() {
            obj.lambda = opts.lambda0;
            let mut rho_prev = position_energy(targets, &x);
            for round in 0..opts.max_rounds {
                if try_snap(&obj, &mut x) {
                    snapped = true;
                    break;
                }
                let name = format!(
                    "constraints {}{}",
                    round + 1,
                    if unguided { " (unguided)" } else { "" }
                );
                run(&name, &obj, &mut x, &opts.penalty, &mut phases)?;
                let rho = position_energy(targets, &x);
                if rho < opts.theta {
                    snapped = try_snap(&obj, &mut x);
                    break;
                }
                // Stall: the guides of positive init tets next to folded ones pull interior
                // vertices to the init's side of the fold, against the boundary the penalty
                // pulls in, and lock them in slivers. Drop the guides (distortion w.r.t. the
                // rest shape, the post-optimisation energy) and retry at the same λ.
                if opts.unguide_on_stall && !unguided && rho > 0.5 * rho_prev {
                    unguided = true;
                    obj.d_dist = d_fit.clone();
                    obj.omega = 0.0;
                    rho_prev = rho;
                    continue;
                }
                rho_prev = rho;
                obj.lambda *= opts.lambda_growth;
            }
        }
    }
    snapped |= untangled;

    // 4. Post-optimisation: distortion of the map itself, constrained vertices fixed.
    if let Some(post) = &opts.post {
        let mut fixed = vec![false; nv];
        for (v, _) in targets {
            fixed[*v as usize] = true;
        }
        let post_obj = Objective {
            targets: targets.to_vec(),
            ..distortion_objective(rest, fixed, Vec::new())?
        };
        run("post-optimisation", &post_obj, &mut x, post, &mut phases)?;
    }

    let quality = evaluate(rest, &x, targets);
    if quality.inverted > 0 || x.iter().flatten().any(|c| !c.is_finite()) {
        return Err(VolError::BadResult(format!(
            "the result has {} inverted tet(s) or a non-finite coordinate; not written",
            quality.inverted
        )));
    }
    let report = VolmapReport {
        vertices: nv,
        tets: rest.tets.len(),
        constrained_vertices: targets.len(),
        inverted_init,
        inverted_output: quality.inverted,
        quality,
        snapped,
        phases,
        seconds: start.elapsed().as_secs_f64(),
    };
    Ok((x, report))
}

/// Applies the proper rigid motion that best fits the constrained vertices to their targets
/// (least squares; Kabsch 1976 with the reflection excluded).
pub fn rigid_align(x: &mut [[f64; 3]], targets: &[(u32, [f64; 3])]) {
    let n = targets.len() as f64;
    let mut cp = [0.0; 3];
    let mut cq = [0.0; 3];
    for (v, q) in targets {
        let p = x[*v as usize];
        for k in 0..3 {
            cp[k] += p[k] / n;
            cq[k] += q[k] / n;
        }
    }
    // C = Σ (q − q̄)(p − p̄)ᵀ; R = U·diag(1, 1, ±1)·Vᵀ for C = UΣVᵀ.
    let mut c = [[0.0; 3]; 3];
    for (v, q) in targets {
        let p = sub(x[*v as usize], cp);
        let q = sub(*q, cq);
        for i in 0..3 {
            for j in 0..3 {
                c[i][j] += q[i] * p[j];
            }
        }
    }
    let Some(r) = super::energy::closest_rotation(&c) else {
        return;
    };
    for p in x.iter_mut() {
        let d = sub(*p, cp);
        for i in 0..3 {
            p[i] = cq[i] + r[i][0] * d[0] + r[i][1] * d[1] + r[i][2] * d[2];
        }
    }
}

/// Moves every constrained vertex onto its target if that inverts no tet (checked by the
/// det cubics and again by the energy); returns whether it did.
fn try_snap(obj: &Objective, x: &mut [[f64; 3]]) -> bool {
    let mut p = vec![[0.0; 3]; x.len()];
    for (v, t) in &obj.targets {
        p[*v as usize] = sub(*t, x[*v as usize]);
    }
    if max_flip_free_step(&obj.tets, x, &p) <= 1.0 {
        return false;
    }
    let mut trial = x.to_vec();
    for (v, t) in &obj.targets {
        trial[*v as usize] = *t;
    }
    if obj.tet_energy(&trial).is_finite() {
        x.copy_from_slice(&trial);
        true
    } else {
        false
    }
}

/// Jacobian of the rest → `x` map of tet `t` (used by tests and checks).
pub fn tet_jacobian(rest: &TetMesh, x: &[[f64; 3]], t: usize) -> Option<Mat3> {
    let tet = &rest.tets[t];
    let inv = inv3(&edge_matrix(&rest.positions, tet))?;
    Some(jacobian(x, tet, &corner_weights(&inv)))
}
