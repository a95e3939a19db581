//! Surface mesh files in: OBJ, PLY (ASCII, binary little and big endian), OFF (ASCII), STL
//! (ASCII and binary) and glTF 2.0 (`.gltf`, `.glb`; also written back, see [`gltf`]), chosen
//! by the file's extension; anything else is read as OBJ.
//!
//! The PLY, OFF and STL parsers are written here rather than taken from a crate: `stl_io`
//! returns plain `io::Error`s (no line or byte offset) and keeps `f32` coordinates (an ASCII
//! STL's decimals would be rounded), and with `ply-rs` we would still have to map its errors
//! and records back to lines, bytes and elements. The three formats are small; a parser of our
//! own names every error's place and checks every header count against the bytes left before
//! it reserves anything. Each parser here
//! - keeps the file's vertex and face order (PLY, OFF) so the output's `v`/`f` order is the
//!   input's, like the OBJ reader ([`super::obj`]);
//! - fan-triangulates polygons `(a0, a_i, a_{i+1})` like the OBJ reader;
//! - names the line (text) or byte offset (binary) and the element of every error it returns;
//! - never trusts a header count: a count is checked against the bytes left before anything is
//!   reserved, and all arithmetic on counts and offsets is checked;
//! - reads the whole file through [`crate::files::read_bounded`], so the size limit of the run
//!   holds for every format.
//!
//! Non-finite coordinates, degenerate, duplicate and non-manifold faces are left to
//! [`super::validate`], which names the element, as for OBJ.

pub mod gltf;
mod off;
mod ply;
mod stl;
mod text;

use std::path::Path;

use super::{obj, MeshError, TriMesh};

pub use off::parse_off;
pub use ply::parse_ply;
pub use stl::parse_stl;

/// The file formats [`read_surface`] reads, named by the file's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SurfaceFormat {
    Obj,
    Ply,
    Off,
    Stl,
    /// `.gltf` or `.glb` (told apart by content).
    Gltf,
}

impl SurfaceFormat {
    /// The format of `path` by its extension (case-insensitive); OBJ for any extension that is
    /// not another format's, so `mesh.txt` is still read. Tetrahedral and scene formats are
    /// refused here: they would otherwise parse as an OBJ with no faces.
    pub fn from_path(path: &Path) -> Result<SurfaceFormat, MeshError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        let Some(ext) = ext else {
            return Ok(SurfaceFormat::Obj);
        };
        let refused = match ext.as_str() {
            "ply" => return Ok(SurfaceFormat::Ply),
            "off" => return Ok(SurfaceFormat::Off),
            "stl" => return Ok(SurfaceFormat::Stl),
            "gltf" | "glb" => return Ok(SurfaceFormat::Gltf),
            "mesh" | "node" | "ele" | "vtk" => {
                "a tetrahedral mesh format; surface maps need a triangle mesh (OBJ, PLY, OFF or STL)"
            }
            "fbx" => "not read by foldfree; convert the surface to OBJ, PLY, OFF, STL or glTF",
            _ => return Ok(SurfaceFormat::Obj),
        };
        Err(MeshError::Read {
            file: path.to_path_buf(),
            reason: format!("'.{ext}' is {refused}"),
        })
    }

    /// The format's usual name, for messages.
    pub fn name(self) -> &'static str {
        match self {
            SurfaceFormat::Obj => "OBJ",
            SurfaceFormat::Ply => "PLY",
            SurfaceFormat::Off => "OFF",
            SurfaceFormat::Stl => "STL",
            SurfaceFormat::Gltf => "glTF",
        }
    }
}

/// How the file stored its numbers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoding {
    Text,
    BinaryLittleEndian,
    BinaryBigEndian,
}

/// What reading a surface file did besides producing the mesh.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SurfaceInfo {
    pub format: SurfaceFormat,
    pub encoding: Encoding,
    /// Faces (polygons) in the file; equals the triangle count when nothing was triangulated.
    pub source_face_count: usize,
    /// Polygons with more than 3 vertices, each fan-triangulated into (n − 2) triangles, so
    /// source faces then map one-to-many onto [`TriMesh::faces`].
    pub polygons_triangulated: usize,
    /// What the reader read past without using: OBJ records other than `v` and `f`, PLY
    /// properties and elements other than positions and face indices, STL corners merged into
    /// an earlier vertex at the same position. 0 for OFF (colours and normals are per line).
    pub skipped: usize,
}

impl SurfaceInfo {
    fn new(format: SurfaceFormat, encoding: Encoding) -> SurfaceInfo {
        SurfaceInfo {
            format,
            encoding,
            source_face_count: 0,
            polygons_triangulated: 0,
            skipped: 0,
        }
    }
}

impl From<obj::ObjInfo> for SurfaceInfo {
    fn from(o: obj::ObjInfo) -> SurfaceInfo {
        SurfaceInfo {
            format: SurfaceFormat::Obj,
            encoding: Encoding::Text,
            source_face_count: o.source_face_count,
            polygons_triangulated: o.polygons_triangulated,
            skipped: o.ignored_records,
        }
    }
}

/// Reads a triangle surface in the format its extension names ([`SurfaceFormat::from_path`]),
/// from a file of at most `max_faces` faces' worth of bytes ([`crate::files::byte_limit`]; the
/// face count itself is checked by validation). Vertex and face order are the file's (STL:
/// see [`parse_stl`]).
pub fn read_surface(path: &Path, max_faces: usize) -> Result<(TriMesh, SurfaceInfo), MeshError> {
    let format = SurfaceFormat::from_path(path)?;
    if format == SurfaceFormat::Gltf {
        // External buffers are read from the file's folder.
        let scene = gltf::read_gltf(path, max_faces)?;
        let info = scene.info();
        return Ok((scene.mesh, info));
    }
    let bytes = read_input(path, max_faces, format)?;
    parse_surface(&bytes, path, format)
}

/// Parses a surface file already in memory as `format`; `file` only names the source in errors.
pub fn parse_surface(
    bytes: &[u8],
    file: &Path,
    format: SurfaceFormat,
) -> Result<(TriMesh, SurfaceInfo), MeshError> {
    match format {
        SurfaceFormat::Obj => obj::parse_obj_with_info(bytes, file).map(|(m, i)| (m, i.into())),
        SurfaceFormat::Ply => parse_ply(bytes, file),
        SurfaceFormat::Off => parse_off(bytes, file),
        SurfaceFormat::Stl => parse_stl(bytes, file),
        SurfaceFormat::Gltf => {
            let mut no_files =
                |uri: &str| Err(format!("external buffer {uri:?}: not read from memory"));
            gltf::parse_gltf(bytes, file, &mut no_files).map(|s| {
                let info = s.info();
                (s.mesh, info)
            })
        }
    }
}

/// The whole file, refused past the run's byte limit (`max_faces` faces' worth) as `TooLarge`
/// and, when missing or not a regular file, as `Read`: both exit 2.
pub(crate) fn read_input(
    path: &Path,
    max_faces: usize,
    format: SurfaceFormat,
) -> Result<Vec<u8>, MeshError> {
    let limit = crate::files::byte_limit(max_faces);
    let why = format!(
        "{} {} of at most {max_faces} faces",
        article(format),
        format.name()
    );
    crate::files::read_bounded(path, limit, &why).map_err(|e| match e {
        crate::files::FileError::TooLarge { .. } => MeshError::TooLarge {
            file: path.to_path_buf(),
            what: e.to_string(),
        },
        crate::files::FileError::Unreadable { reason, .. } => MeshError::Read {
            file: path.to_path_buf(),
            reason,
        },
        other => MeshError::Read {
            file: path.to_path_buf(),
            reason: other.to_string(),
        },
    })
}

fn article(format: SurfaceFormat) -> &'static str {
    match format {
        SurfaceFormat::Obj | SurfaceFormat::Off => "an",
        SurfaceFormat::Ply | SurfaceFormat::Stl | SurfaceFormat::Gltf => "a",
    }
}

/// The parsed mesh, or `Empty` (the OBJ reader's error) when the file has no faces.
fn finish(
    mesh: TriMesh,
    info: SurfaceInfo,
    file: &Path,
) -> Result<(TriMesh, SurfaceInfo), MeshError> {
    if mesh.faces.is_empty() {
        return Err(MeshError::Empty {
            file: file.to_path_buf(),
        });
    }
    Ok((mesh, info))
}

/// A `Read` error at a place in the file: `at` is "line N" or "byte N".
fn located(file: &Path, at: impl std::fmt::Display, what: impl std::fmt::Display) -> MeshError {
    MeshError::Read {
        file: file.to_path_buf(),
        reason: format!("{at}: {what}"),
    }
}

/// Appends the fan `(c0, c_i, c_{i+1})` of a polygon with at least 3 corners, counting it in
/// `info` (the OBJ reader's triangulation).
fn push_fan(faces: &mut Vec<[u32; 3]>, corners: &[u32], info: &mut SurfaceInfo) {
    info.source_face_count += 1;
    if corners.len() > 3 {
        info.polygons_triangulated += 1;
    }
    if let Some((&a, rest)) = corners.split_first() {
        for w in rest.windows(2) {
            faces.push([a, w[0], w[1]]);
        }
    }
}

/// `Vec::with_capacity` for a count a file announces, capped by what the bytes left can hold
/// (`min_bytes` per record): a header claiming 10⁹ records in a 1 kB file reserves nothing
/// unreasonable.
fn reserve_for<T>(announced: usize, bytes_left: usize, min_bytes: usize) -> Vec<T> {
    Vec::with_capacity(announced.min(bytes_left / min_bytes.max(1)))
}

/// A 0-based vertex index as written in the file, checked against the `count` vertices;
/// `face` is the first triangle of the polygon, as the OBJ reader reports it.
fn vertex_index(file: &Path, written: i64, count: usize, face: usize) -> Result<u32, MeshError> {
    match u32::try_from(written) {
        Ok(v) if (v as usize) < count => Ok(v),
        _ => Err(MeshError::IndexOutOfRange {
            file: file.to_path_buf(),
            face,
            index: written,
            count,
        }),
    }
}
