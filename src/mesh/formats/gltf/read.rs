//! Reading a glTF file into a welded [`TriMesh`] with the map back to its primitives.

use std::collections::HashMap;
use std::path::Path;

use gltf::accessor::{DataType, Dimensions};
use gltf::mesh::{Mode, Semantic};

use super::super::{located, Encoding, SurfaceFormat, SurfaceInfo};
use crate::mesh::{MeshError, TriMesh};

const GLB_MAGIC: &[u8; 4] = b"glTF";
const CHUNK_JSON: u32 = 0x4E4F_534A;
const CHUNK_BIN: u32 = 0x004E_4942;

/// A glTF file read for mapping: the welded mesh the solvers see, the primitives it came from,
/// and the document and buffers to write it back with.
#[derive(Clone, Debug)]
pub struct GltfScene {
    /// Every triangle of every primitive, in the order meshes → primitives → triangles; each
    /// primitive's vertices welded by exactly equal position (see the module doc).
    pub mesh: TriMesh,
    pub primitives: Vec<Primitive>,
    /// Whether the file was a `.glb` (by content, not by name).
    pub binary: bool,
    pub(super) doc: gltf::Document,
    /// The JSON as read, written back with only the changes the map needs.
    pub(super) json: serde_json::Value,
    /// Each buffer's bytes, at least its `byteLength` long.
    pub(super) buffers: Vec<Vec<u8>>,
    /// The external buffer files that were read (inputs of the run too).
    pub external: Vec<std::path::PathBuf>,
}

/// Where a run of [`GltfScene::mesh`]'s faces came from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Primitive {
    /// Index in `meshes` and in that mesh's `primitives`.
    pub mesh: usize,
    pub primitive: usize,
    /// glTF vertices (the `POSITION` accessor's count).
    pub vertex_count: usize,
    /// The primitive's first face in [`GltfScene::mesh`]; it owns `triangles.len()` faces.
    pub first_face: usize,
    /// Each triangle as glTF vertex indices of this primitive.
    pub triangles: Vec<[u32; 3]>,
    /// Whether the primitive has an `indices` accessor.
    pub indexed: bool,
    /// The `n` of every `TEXCOORD_n` attribute, ascending.
    pub texcoord_sets: Vec<u32>,
}

impl Primitive {
    /// `meshes[m].primitives[p]`, the JSON path errors name.
    pub fn path(&self) -> String {
        format!("meshes[{}].primitives[{}]", self.mesh, self.primitive)
    }
}

/// Reads `path` (`.gltf` or `.glb`, told apart by content) within the byte limit of
/// `max_faces` faces; external buffers are read from the file's folder within what is left of
/// that limit.
pub fn read_gltf(path: &Path, max_faces: usize) -> Result<GltfScene, MeshError> {
    let bytes = super::super::read_input(path, max_faces, SurfaceFormat::Gltf)?;
    let folder = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."))
        .to_path_buf();
    let mut budget = crate::files::byte_limit(max_faces).saturating_sub(bytes.len() as u64);
    let mut files = Vec::new();
    let mut external = |uri: &str| -> Result<Vec<u8>, String> {
        let name = Path::new(uri);
        if uri.contains(':') || name.is_absolute() {
            return Err(format!("URI {uri:?} is not a relative file name"));
        }
        let file = folder.join(name);
        let data = crate::files::read_bounded(&file, budget, "the input's limit")
            .map_err(|e| format!("external buffer {uri:?}: {e}"))?;
        budget = budget.saturating_sub(data.len() as u64);
        files.push(file);
        Ok(data)
    };
    let mut scene = parse_gltf(&bytes, path, &mut external)?;
    scene.external = files;
    Ok(scene)
}

/// Parses a glTF file in memory; `external` returns the bytes of a buffer's relative URI (or
/// why not). `file` only names the source in errors.
pub fn parse_gltf(
    bytes: &[u8],
    file: &Path,
    external: &mut dyn FnMut(&str) -> Result<Vec<u8>, String>,
) -> Result<GltfScene, MeshError> {
    let Container { json, bin, binary } = split_container(bytes, file)?;
    let json: serde_json::Value =
        serde_json::from_slice(json).map_err(|e| at_path(file, format!("not valid JSON: {e}")))?;
    let root: gltf::json::Root = serde_json::from_value(json.clone())
        .map_err(|e| at_path(file, format!("not a glTF 2.0 document: {e}")))?;
    check_position_indices(&root, file)?;
    let doc = gltf::Document::from_json(root).map_err(|e| match e {
        gltf::Error::Validation(errors) => {
            let (path, why) = &errors[0];
            let more = match errors.len() {
                1 => String::new(),
                n => format!(" (and {} more)", n - 1),
            };
            located(file, path, format!("{why}{more}"))
        }
        other => located(file, "JSON", other),
    })?;
    let buffers = load_buffers(&doc, bin, file, external)?;
    let (mesh, primitives) = build_mesh(&doc, &buffers, file)?;
    Ok(GltfScene {
        mesh,
        primitives,
        binary,
        doc,
        json,
        buffers,
        external: Vec::new(),
    })
}

impl GltfScene {
    /// What [`super::super::read_surface`] reports about the file.
    pub fn info(&self) -> SurfaceInfo {
        let mut info = SurfaceInfo::new(
            SurfaceFormat::Gltf,
            if self.binary {
                Encoding::BinaryLittleEndian
            } else {
                Encoding::Text
            },
        );
        info.source_face_count = self.mesh.faces.len();
        info
    }

    /// Texture coordinates `TEXCOORD_set` of primitive `k` in foldfree's convention (origin at
    /// the bottom-left: `(u, 1 − v)` of the file's), one per glTF vertex; `None` when the
    /// primitive has no such set. `FLOAT` or normalized `UNSIGNED_BYTE`/`UNSIGNED_SHORT`.
    pub fn texcoords(&self, k: usize, set: u32) -> Result<Option<Vec<[f64; 2]>>, String> {
        let Some(p) = self.primitives.get(k) else {
            return Ok(None);
        };
        let Some(prim) = self
            .doc
            .meshes()
            .nth(p.mesh)
            .and_then(|m| m.primitives().nth(p.primitive))
        else {
            return Ok(None);
        };
        let Some(acc) = prim.get(&Semantic::TexCoords(set)) else {
            return Ok(None);
        };
        let at = format!("{}.attributes.TEXCOORD_{set}", p.path());
        let el = Elements::new(&acc, &self.buffers, &at)?;
        if el.dims != 2 || !(el.float || el.normalized) {
            return Err(format!(
                "{at}: texture coordinates must be VEC2 FLOAT or normalized integers"
            ));
        }
        Ok(Some(
            (0..el.count)
                .map(|i| {
                    let c = el.components(i);
                    [c[0], 1.0 - c[1]]
                })
                .collect(),
        ))
    }

    /// The primitive and triangle of face `face` of [`GltfScene::mesh`], as
    /// `meshes[m].primitives[p] triangle t`.
    pub fn face_place(&self, face: usize) -> Option<String> {
        let k = self
            .primitives
            .partition_point(|p| p.first_face <= face)
            .checked_sub(1)?;
        let p = &self.primitives[k];
        let t = face - p.first_face;
        (t < p.triangles.len()).then(|| format!("{} triangle {t}", p.path()))
    }

    /// A validation error of [`GltfScene::mesh`] that names a face, with the glTF primitive
    /// and triangle appended (the merged mesh's face numbers mean nothing in the file); other
    /// errors as they are.
    pub fn locate(&self, e: MeshError) -> MeshError {
        let face = match &e {
            MeshError::Degenerate { face, .. }
            | MeshError::RepeatedVertex { face, .. }
            | MeshError::DuplicateFace { face, .. } => *face,
            MeshError::InconsistentOrientation { f1, .. } => *f1,
            _ => return e,
        };
        let Some(place) = self.face_place(face) else {
            return e;
        };
        let (file, text) = match &e {
            MeshError::Degenerate { file, .. }
            | MeshError::RepeatedVertex { file, .. }
            | MeshError::DuplicateFace { file, .. }
            | MeshError::InconsistentOrientation { file, .. } => (file.clone(), e.to_string()),
            _ => return e,
        };
        let prefix = format!("{}: ", file.display());
        let what = text.strip_prefix(&prefix).unwrap_or(&text);
        MeshError::InPlace {
            place,
            what: what.to_string(),
            file,
        }
    }

    /// Raw bytes of accessor `index`, element by element (tightly packed), and its element size.
    pub(super) fn packed(&self, index: usize, at: &str) -> Result<(Vec<u8>, usize), String> {
        let acc = self
            .doc
            .accessors()
            .nth(index)
            .ok_or_else(|| format!("{at}: no accessor {index}"))?;
        let el = Elements::new(&acc, &self.buffers, at)?;
        let mut out = Vec::with_capacity(el.count * el.size);
        for i in 0..el.count {
            out.extend_from_slice(el.get(i));
        }
        Ok((out, el.size))
    }
}

/// The parts of a glTF file.
struct Container<'a> {
    json: &'a [u8],
    /// A `.glb`'s BIN chunk.
    bin: Option<&'a [u8]>,
    /// Whether the file is a `.glb`.
    binary: bool,
}

/// The JSON bytes and the BIN chunk of a `.glb`, or the whole file as JSON. Every length is
/// checked against the bytes there are.
fn split_container<'a>(bytes: &'a [u8], file: &Path) -> Result<Container<'a>, MeshError> {
    if !bytes.starts_with(GLB_MAGIC) {
        return Ok(Container {
            json: bytes,
            bin: None,
            binary: false,
        });
    }
    let word = |at: usize| -> Option<u32> {
        let b = bytes.get(at..at.checked_add(4)?)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let short = |at: usize, what: &str| located(file, format!("byte {at}"), format!("GLB: {what}"));
    let version = word(4).ok_or_else(|| short(4, "the header is cut off"))?;
    if version != 2 {
        return Err(short(4, &format!("version {version}, only 2 is read")));
    }
    let length = word(8).ok_or_else(|| short(8, "the header is cut off"))? as usize;
    if length > bytes.len() || length < 12 {
        return Err(short(
            8,
            &format!(
                "the header says {length} bytes, the file has {}",
                bytes.len()
            ),
        ));
    }
    let mut at = 12;
    let mut json = None;
    let mut bin = None;
    while at < length {
        let (Some(len), Some(kind)) = (word(at), word(at + 4)) else {
            return Err(short(at, "a chunk header is cut off"));
        };
        let start = at + 8;
        let end = start
            .checked_add(len as usize)
            .filter(|&e| e <= length)
            .ok_or_else(|| {
                short(
                    at,
                    &format!("a chunk of {len} bytes runs past the file's {length}"),
                )
            })?;
        let data = &bytes[start..end];
        match kind {
            CHUNK_JSON if json.is_none() && at == 12 => json = Some(data),
            CHUNK_BIN if json.is_some() && bin.is_none() => bin = Some(data),
            CHUNK_JSON | CHUNK_BIN => {
                return Err(short(at, "a JSON or BIN chunk out of place"));
            }
            // Unknown chunk types are skipped, as the specification asks.
            _ => {}
        }
        at = end;
    }
    let json = json.ok_or_else(|| short(12, "no JSON chunk first"))?;
    Ok(Container {
        json,
        bin,
        binary: true,
    })
}

/// `gltf-json` 1.4.1's validation indexes `accessors` with a primitive's POSITION before it
/// checks that index (a panic on a file whose POSITION names a missing accessor): refused here
/// first, with the error and path the validation would give.
fn check_position_indices(root: &gltf::json::Root, file: &Path) -> Result<(), MeshError> {
    use gltf::json::validation::Checked;
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            if let Some(i) = prim.attributes.get(&Checked::Valid(Semantic::Positions)) {
                if i.value() >= root.accessors.len() {
                    return Err(located(
                        file,
                        format!("meshes[{m}].primitives[{p}].attributes.POSITION"),
                        format!(
                            "accessor {} does not exist ({} accessors)",
                            i.value(),
                            root.accessors.len()
                        ),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// Each buffer's bytes: the GLB BIN chunk, a base64 data URI or an external file.
fn load_buffers(
    doc: &gltf::Document,
    bin: Option<&[u8]>,
    file: &Path,
    external: &mut dyn FnMut(&str) -> Result<Vec<u8>, String>,
) -> Result<Vec<Vec<u8>>, MeshError> {
    let mut out = Vec::new();
    for b in doc.buffers() {
        let at = format!("buffers[{}]", b.index());
        let data = match b.source() {
            gltf::buffer::Source::Bin => bin.map(<[u8]>::to_vec).ok_or_else(|| {
                located(file, &at, "refers to the GLB BIN chunk, but there is none")
            })?,
            gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                decode_data_uri(uri).map_err(|e| located(file, &at, e))?
            }
            gltf::buffer::Source::Uri(uri) => external(uri).map_err(|e| located(file, &at, e))?,
        };
        if data.len() < b.length() {
            return Err(located(
                file,
                &at,
                format!(
                    "byteLength is {}, but the data has {} bytes",
                    b.length(),
                    data.len()
                ),
            ));
        }
        out.push(data);
    }
    Ok(out)
}

/// A base64 buffer data URI (`application/octet-stream` or `application/gltf-buffer`).
fn decode_data_uri(uri: &str) -> Result<Vec<u8>, String> {
    use base64::Engine as _;
    const KINDS: [&str; 2] = [
        "data:application/octet-stream;base64,",
        "data:application/gltf-buffer;base64,",
    ];
    let payload = KINDS
        .iter()
        .find_map(|k| uri.strip_prefix(k))
        .ok_or_else(|| {
            let head: String = uri.chars().take(40).collect();
            format!("unsupported data URI {head:?}…; only base64 buffers are read")
        })?;
    base64::engine::general_purpose::STANDARD
        .decode(payload)
        .map_err(|e| format!("data URI: bad base64: {e}"))
}

/// An accessor's elements inside its buffer, bounds checked once.
struct Elements<'a> {
    data: &'a [u8],
    /// Byte offset of element 0 in `data`, and of element i + 1 after element i.
    start: usize,
    stride: usize,
    /// Bytes of one element.
    size: usize,
    count: usize,
    kind: DataType,
    dims: usize,
    float: bool,
    normalized: bool,
}

impl<'a> Elements<'a> {
    fn new(acc: &gltf::Accessor<'_>, buffers: &'a [Vec<u8>], at: &str) -> Result<Self, String> {
        let at = format!("{at} (accessor {})", acc.index());
        if acc.sparse().is_some() {
            return Err(format!("{at}: sparse accessors are not supported"));
        }
        let view = acc.view().ok_or_else(|| {
            format!("{at}: an accessor without a bufferView (all zeros) is not supported")
        })?;
        let data = buffers
            .get(view.buffer().index())
            .ok_or_else(|| format!("{at}: no buffer {}", view.buffer().index()))?;
        let view_end = view
            .offset()
            .checked_add(view.length())
            .filter(|&e| e <= data.len())
            .ok_or_else(|| {
                format!(
                    "{at}: bufferView {} (bytes {} + {}) runs past buffer {}'s {} bytes",
                    view.index(),
                    view.offset(),
                    view.length(),
                    view.buffer().index(),
                    data.len()
                )
            })?;
        let kind = acc.data_type();
        let dims = acc.dimensions().multiplicity();
        let size = kind.size() * dims;
        if matches!(
            acc.dimensions(),
            Dimensions::Mat2 | Dimensions::Mat3 | Dimensions::Mat4
        ) && kind.size() < 4
        {
            return Err(format!("{at}: small-component matrices are not supported"));
        }
        let stride = view.stride().unwrap_or(size);
        if stride < size {
            return Err(format!(
                "{at}: byteStride {stride} is less than the element's {size} bytes"
            ));
        }
        let count = acc.count();
        let start = view.offset().saturating_add(acc.offset());
        let needed = match count {
            0 => Some(start),
            n => (n - 1)
                .checked_mul(stride)
                .and_then(|b| b.checked_add(size))
                .and_then(|b| b.checked_add(start)),
        };
        if !matches!(needed, Some(e) if e <= view_end) {
            return Err(format!(
                "{at}: {count} elements of {size} bytes (stride {stride}) from byte {} run past \
                 bufferView {} ({} bytes)",
                acc.offset(),
                view.index(),
                view.length()
            ));
        }
        Ok(Elements {
            data,
            start,
            stride,
            size,
            count,
            kind,
            dims,
            float: kind == DataType::F32,
            normalized: acc.normalized(),
        })
    }

    /// The bytes of element `i` (< count).
    fn get(&self, i: usize) -> &'a [u8] {
        let at = self.start + i * self.stride;
        &self.data[at..at + self.size]
    }

    /// Element `i`'s first (up to) four components as numbers: floats as they are, normalized
    /// integers mapped to [0, 1] / [−1, 1] as the specification says, other integers as values.
    fn components(&self, i: usize) -> [f64; 4] {
        let b = self.get(i);
        let mut out = [0.0; 4];
        let w = self.kind.size();
        for (k, c) in b.chunks_exact(w).take(4).enumerate() {
            let (x, scale) = match self.kind {
                DataType::I8 => (f64::from(c[0] as i8), 127.0),
                DataType::U8 => (f64::from(c[0]), 255.0),
                DataType::I16 => (f64::from(i16::from_le_bytes([c[0], c[1]])), 32767.0),
                DataType::U16 => (f64::from(u16::from_le_bytes([c[0], c[1]])), 65535.0),
                DataType::U32 => (f64::from(u32::from_le_bytes([c[0], c[1], c[2], c[3]])), 1.0),
                DataType::F32 => (f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])), 1.0),
            };
            out[k] = if self.normalized {
                (x / scale).max(-1.0)
            } else {
                x
            };
        }
        out
    }

    /// Element `i` as an index (unsigned integer scalars).
    fn index(&self, i: usize) -> u64 {
        let b = self.get(i);
        match self.kind {
            DataType::U8 => u64::from(b[0]),
            DataType::U16 => u64::from(u16::from_le_bytes([b[0], b[1]])),
            _ => u64::from(u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        }
    }
}

/// The welded mesh of every primitive, and where its faces came from. Every attribute and
/// morph-target accessor of a primitive is bounds checked here, so writing cannot fail on
/// them later.
fn build_mesh(
    doc: &gltf::Document,
    buffers: &[Vec<u8>],
    file: &Path,
) -> Result<(TriMesh, Vec<Primitive>), MeshError> {
    let mut mesh = TriMesh::default();
    let mut prims = Vec::new();
    for m in doc.meshes() {
        for p in m.primitives() {
            let path = format!("meshes[{}].primitives[{}]", m.index(), p.index());
            let bad = |what: String| located(file, &path, what);
            if p.mode() != Mode::Triangles {
                return Err(bad(format!(
                    "mode {} ({:?}); only TRIANGLES (4) is read",
                    p.mode().as_gl_enum(),
                    p.mode()
                )));
            }
            let pos = p
                .get(&Semantic::Positions)
                .ok_or_else(|| bad("no POSITION attribute".into()))?;
            let positions = Elements::new(&pos, buffers, &format!("{path}.attributes.POSITION"))
                .map_err(|e| at_path(file, e))?;
            if !(positions.float && positions.dims == 3) {
                return Err(bad("POSITION must be VEC3 FLOAT".into()));
            }
            let n = positions.count;
            let texcoord_sets = check_vertex_accessors(&p, buffers, &path, n, file)?;
            let triangles = triangles(&p, buffers, &path, n, file)?;
            // Weld by exactly equal position (−0 and +0 are one position).
            let base = u32::try_from(mesh.positions.len())
                .ok()
                .filter(|b| b.checked_add(n as u32).is_some() && n < u32::MAX as usize)
                .ok_or_else(|| bad("more than 2³² vertices in the file".into()))?;
            let mut seen: HashMap<[u64; 3], u32> = HashMap::with_capacity(n);
            let mut welded = Vec::with_capacity(n);
            for i in 0..n {
                let c = positions.components(i);
                let p = [c[0] + 0.0, c[1] + 0.0, c[2] + 0.0];
                let key = p.map(f64::to_bits);
                let next = base + seen.len() as u32;
                let v = *seen.entry(key).or_insert_with(|| {
                    mesh.positions.push(p);
                    next
                });
                welded.push(v);
            }
            let first_face = mesh.faces.len();
            mesh.faces
                .extend(triangles.iter().map(|t| t.map(|v| welded[v as usize])));
            prims.push(Primitive {
                mesh: m.index(),
                primitive: p.index(),
                vertex_count: n,
                first_face,
                triangles,
                indexed: p.indices().is_some(),
                texcoord_sets,
            });
        }
    }
    if mesh.faces.is_empty() {
        return Err(MeshError::Empty {
            file: file.to_path_buf(),
        });
    }
    Ok((mesh, prims))
}

/// Every attribute and morph-target accessor of primitive `p` (at JSON `path`) is in bounds,
/// has the POSITION count `n` and, when it holds floats, only finite ones (glTF forbids NaN
/// and infinities in accessor data, and attributes foldfree does not use are written back as
/// they were read: a non-finite one would be passed on); returns the `n` of its `TEXCOORD_n`
/// sets, ascending.
fn check_vertex_accessors(
    p: &gltf::Primitive<'_>,
    buffers: &[Vec<u8>],
    path: &str,
    n: usize,
    file: &Path,
) -> Result<Vec<u32>, MeshError> {
    let check = |acc: &gltf::Accessor<'_>, at: String| -> Result<(), MeshError> {
        let el = Elements::new(acc, buffers, &at).map_err(|e| at_path(file, e))?;
        if el.count != n {
            return Err(located(
                file,
                &at,
                format!("{} elements, but POSITION has {n}", el.count),
            ));
        }
        if el.float {
            if let Some(i) =
                (0..el.count).find(|&i| el.components(i)[..el.dims].iter().any(|x| !x.is_finite()))
            {
                return Err(located(
                    file,
                    &at,
                    format!(
                        "element {i} is not a finite number ({:?})",
                        &el.components(i)[..el.dims]
                    ),
                ));
            }
        }
        Ok(())
    };
    let mut texcoord_sets = Vec::new();
    for (semantic, acc) in p.attributes() {
        check(&acc, format!("{path}.attributes.{}", semantic.to_string()))?;
        if let Semantic::TexCoords(s) = semantic {
            texcoord_sets.push(s);
        }
    }
    texcoord_sets.sort_unstable();
    for (t, target) in p.morph_targets().enumerate() {
        for (name, acc) in [
            ("POSITION", target.positions()),
            ("NORMAL", target.normals()),
            ("TANGENT", target.tangents()),
        ] {
            if let Some(acc) = acc {
                check(&acc, format!("{path}.targets[{t}].{name}"))?;
            }
        }
    }
    Ok(texcoord_sets)
}

/// Primitive `p`'s triangles as vertex indices below `n`: its `indices` (unsigned integer
/// scalars, a multiple of 3, each checked) or, without them, every 3 vertices.
fn triangles(
    p: &gltf::Primitive<'_>,
    buffers: &[Vec<u8>],
    path: &str,
    n: usize,
    file: &Path,
) -> Result<Vec<[u32; 3]>, MeshError> {
    Ok(match p.indices() {
        Some(acc) => {
            let at = format!("{path}.indices");
            let el = Elements::new(&acc, buffers, &at).map_err(|e| at_path(file, e))?;
            if el.dims != 1 || !matches!(el.kind, DataType::U8 | DataType::U16 | DataType::U32) {
                return Err(located(
                    file,
                    &at,
                    "indices must be SCALAR UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT",
                ));
            }
            if el.count % 3 != 0 {
                return Err(located(
                    file,
                    &at,
                    format!("{} indices, not a multiple of 3", el.count),
                ));
            }
            let mut tris = Vec::with_capacity(el.count / 3);
            for t in 0..el.count / 3 {
                let mut tri = [0u32; 3];
                for k in 0..3 {
                    let v = el.index(3 * t + k);
                    if v >= n as u64 {
                        return Err(located(
                            file,
                            &at,
                            format!(
                                "triangle {t} refers to vertex {v}, but there are only \
                                 {n} vertices"
                            ),
                        ));
                    }
                    tri[k] = v as u32;
                }
                tris.push(tri);
            }
            tris
        }
        None => {
            if n % 3 != 0 {
                return Err(located(
                    file,
                    path,
                    format!("{n} vertices without indices, not a multiple of 3"),
                ));
            }
            (0..n as u32 / 3)
                .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                .collect()
        }
    })
}

/// A `Read` error whose reason already starts with its JSON path.
fn at_path(file: &Path, reason: String) -> MeshError {
    MeshError::Read {
        file: file.to_path_buf(),
        reason,
    }
}
