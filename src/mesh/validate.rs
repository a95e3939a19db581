//! Input checks that turn every way a mesh can break the solvers into a precise error, before
//! any numeric work: the solvers may then assume finite, non-degenerate, manifold, consistently
//! oriented triangles.

use std::path::Path;

use super::{formats, MeshError, Scale, Topology, TriMesh};
use crate::linalg::vec3::{cross, norm, sub};

/// Thresholds of [`validate`].
#[derive(Clone, Debug, PartialEq)]
pub struct ValidateOptions {
    /// A face is degenerate when its area ≤ `degenerate_rel_tol` × (bounding-box diagonal)²;
    /// relative, so the test does not depend on the file's units.
    pub degenerate_rel_tol: f64,
    /// Accept pinched (non-manifold) vertices, for a caller that splits them
    /// ([`crate::mesh::topology::split_pinched`]); every other check still applies.
    pub allow_pinched_vertices: bool,
    /// Refuse meshes with more faces than this, and files larger than an OBJ of that many
    /// faces, whatever the format (a memory / time guard; `None`: no limit).
    pub max_faces: Option<usize>,
}

impl Default for ValidateOptions {
    fn default() -> Self {
        ValidateOptions {
            degenerate_rel_tol: 1e-12,
            allow_pinched_vertices: false,
            max_faces: Some(crate::files::DEFAULT_MAX_ELEMENTS),
        }
    }
}

/// Facts found while validating that later stages need.
#[derive(Clone, Debug, PartialEq)]
pub struct ValidationReport {
    /// Vertices used by no face, ascending (kept in the output, ignored by the solvers).
    pub unreferenced_vertices: Vec<u32>,
    /// Diagonal of the bounding box of the referenced vertices (the mesh's length scale).
    pub bbox_diagonal: f64,
    /// Smallest face area, in the file's units.
    pub min_face_area: f64,
}

/// Checks the mesh; the first failure in this order is returned: no faces, too many faces,
/// non-finite coordinate (any vertex, referenced or not), face index out of range, repeated
/// vertex in a face, degenerate face, duplicate face (same vertex set), non-manifold edge,
/// non-manifold vertex, inconsistent orientation. Each error names the element; indices are
/// 0-based.
pub fn validate(
    mesh: &TriMesh,
    file: &Path,
    opts: &ValidateOptions,
) -> Result<ValidationReport, MeshError> {
    validate_with_topology(mesh, file, opts).map(|(report, _)| report)
}

/// Reads a surface file (OBJ, PLY, OFF or STL by its extension: [`formats::read_surface`]),
/// validates it and builds its topology (built once, shared by the checks).
pub fn load(
    path: &Path,
    opts: &ValidateOptions,
) -> Result<(TriMesh, Topology, ValidationReport), MeshError> {
    if formats::SurfaceFormat::from_path(path)? == formats::SurfaceFormat::Gltf {
        let (scene, topo, report) = load_gltf(path, opts)?;
        return Ok((scene.mesh, topo, report));
    }
    let max = opts.max_faces.unwrap_or(usize::MAX);
    let (mesh, _) = formats::read_surface(path, max)?;
    let (report, topo) = validate_with_topology(&mesh, path, opts)?;
    Ok((mesh, topo, report))
}

/// [`load`] of a glTF file, keeping the document (to write it back); an error about a face
/// names the glTF primitive and triangle ([`formats::gltf::GltfScene::locate`]).
pub fn load_gltf(
    path: &Path,
    opts: &ValidateOptions,
) -> Result<(formats::gltf::GltfScene, Topology, ValidationReport), MeshError> {
    let max = opts.max_faces.unwrap_or(usize::MAX);
    let scene = formats::gltf::read_gltf(path, max)?;
    let (report, topo) =
        validate_with_topology(&scene.mesh, path, opts).map_err(|e| scene.locate(e))?;
    Ok((scene, topo, report))
}

/// [`validate`], also returning the topology the manifold and orientation checks needed.
pub fn validate_with_topology(
    mesh: &TriMesh,
    file: &Path,
    opts: &ValidateOptions,
) -> Result<(ValidationReport, Topology), MeshError> {
    let nv = mesh.positions.len();
    let nf = mesh.faces.len();
    if nf == 0 {
        return Err(MeshError::Empty {
            file: file.to_path_buf(),
        });
    }
    if let Some(max) = opts.max_faces {
        if nf > max {
            return Err(MeshError::TooLarge {
                file: file.to_path_buf(),
                what: format!("{nf} faces, more than the limit of {max}"),
            });
        }
    }

    // Indices and CSR offsets are u32, and NO_FACE must differ from every face index.
    if nv >= u32::MAX as usize || nf >= (u32::MAX / 3) as usize {
        return Err(MeshError::TooLarge {
            file: file.to_path_buf(),
            what: format!("{nv} vertices and {nf} faces exceed the 32-bit index range"),
        });
    }

    for (v, p) in mesh.positions.iter().enumerate() {
        if let Some(&value) = p.iter().find(|c| !c.is_finite()) {
            return Err(MeshError::NonFinite {
                file: file.to_path_buf(),
                vertex: v,
                value,
            });
        }
    }

    check_indices(mesh, file)?;

    for (f, &[a, b, c]) in mesh.faces.iter().enumerate() {
        let repeated = if a == b || a == c {
            Some(a)
        } else if b == c {
            Some(b)
        } else {
            None
        };
        if let Some(v) = repeated {
            return Err(MeshError::RepeatedVertex {
                file: file.to_path_buf(),
                face: f,
                vertex: v as usize,
            });
        }
    }

    // Areas on scale-normalised coordinates (see [`Scale`]): relative to the bounding box
    // of the referenced vertices (a stray unused vertex must not change the scale), and free of
    // underflow at 1e-100 or overflow at 1e100. Reported in the file's units.
    let sim = Scale::fit(
        mesh.faces
            .iter()
            .flatten()
            .map(|&v| &mesh.positions[v as usize]),
    );
    let at = |v: u32| sim.apply(mesh.positions[v as usize]);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for tri in &mesh.faces {
        for &v in tri {
            let p = at(v);
            for d in 0..3 {
                lo[d] = lo[d].min(p[d]);
                hi[d] = hi[d].max(p[d]);
            }
        }
    }
    let diagonal = (0..3).map(|d| (hi[d] - lo[d]).powi(2)).sum::<f64>().sqrt();
    let threshold = opts.degenerate_rel_tol * diagonal * diagonal;
    let mut min_area = f64::INFINITY;
    for (f, tri) in mesh.faces.iter().enumerate() {
        let area = face_area(tri.map(at));
        if area <= threshold || area.is_nan() {
            let (a, t) = (
                sim.length(sim.length(area)),
                sim.length(sim.length(threshold)),
            );
            // "area 0, below inf" says nothing: where the file's units do not square into
            // f64, say it relative to the box, as the test is made.
            if !(t.is_finite() && t > 0.0 && a.is_finite()) {
                return Err(MeshError::DegenerateRelative {
                    file: file.to_path_buf(),
                    face: f,
                    rel_area: area / (diagonal * diagonal),
                    tolerance: opts.degenerate_rel_tol,
                });
            }
            return Err(MeshError::Degenerate {
                file: file.to_path_buf(),
                face: f,
                area: a,
                threshold: t,
            });
        }
        min_area = min_area.min(area);
    }
    let bbox_diagonal = sim.length(diagonal);
    let min_face_area = sim.length(sim.length(min_area));

    if let Some((other, face)) = first_duplicate(&mesh.faces) {
        return Err(MeshError::DuplicateFace {
            file: file.to_path_buf(),
            face,
            other,
        });
    }

    // Non-manifold edges (and, as a precondition, the checks above) are the topology's errors.
    let topo = Topology::build(mesh, file)?;

    if let Some(&v) = topo
        .nonmanifold_vertices
        .first()
        .filter(|_| !opts.allow_pinched_vertices)
    {
        return Err(MeshError::NonManifoldVertex {
            file: file.to_path_buf(),
            vertex: v as usize,
            fans: topo.fan_count(v),
        });
    }

    for &e in &topo.interior_edges {
        let [f0, f1] = topo.edge_faces[e as usize];
        let d0 = directed(mesh, &topo, f0, e);
        let d1 = directed(mesh, &topo, f1, e);
        if d0 == d1 {
            return Err(MeshError::InconsistentOrientation {
                file: file.to_path_buf(),
                f0: f0 as usize,
                f1: f1 as usize,
                v0: d0.0 as usize,
                v1: d0.1 as usize,
            });
        }
    }

    let report = ValidationReport {
        unreferenced_vertices: topo.unreferenced.clone(),
        bbox_diagonal,
        min_face_area,
    };
    Ok((report, topo))
}

/// `IndexOutOfRange` for the first face that refers past the vertices.
fn check_indices(mesh: &TriMesh, file: &Path) -> Result<(), MeshError> {
    let nv = mesh.positions.len();
    for (f, tri) in mesh.faces.iter().enumerate() {
        if let Some(&v) = tri.iter().find(|&&v| v as usize >= nv) {
            return Err(MeshError::IndexOutOfRange {
                file: file.to_path_buf(),
                face: f,
                index: i64::from(v),
                count: nv,
            });
        }
    }
    Ok(())
}

/// The duplicate cell (same vertex set, any order) with the smallest index and the first cell
/// it copies, as `(first, duplicate)`: cells sorted by their sorted vertices, so copies are
/// adjacent and each run of copies is in index order. Faces here, tets in `vol::tet`.
pub(crate) fn first_duplicate<const N: usize>(cells: &[[u32; N]]) -> Option<(usize, usize)> {
    let mut keyed: Vec<([u32; N], usize)> = cells
        .iter()
        .enumerate()
        .map(|(i, c)| {
            let mut key = *c;
            key.sort_unstable();
            (key, i)
        })
        .collect();
    keyed.sort_unstable();
    let (key, dup) = keyed
        .windows(2)
        .filter(|w| w[0].0 == w[1].0)
        .map(|w| w[1])
        .min_by_key(|&(_, i)| i)?;
    let first = keyed[keyed.partition_point(|(k, _)| *k < key)].1;
    Some((first, dup))
}

/// ½|(p1−p0)×(p2−p0)|; indices already checked.
fn face_area([p0, p1, p2]: [[f64; 3]; 3]) -> f64 {
    0.5 * norm(cross(sub(p1, p0), sub(p2, p0)))
}

/// Direction `(from, to)` in which face `f` traverses edge `e`.
fn directed(mesh: &TriMesh, topo: &Topology, f: u32, e: u32) -> (u32, u32) {
    let tri = mesh.faces[f as usize];
    // Topology assigned `e` to one side of each face listed on it.
    let k = topo.face_edges[f as usize]
        .iter()
        .position(|&x| x == e)
        .unwrap_or(0);
    (tri[k], tri[(k + 1) % 3])
}
