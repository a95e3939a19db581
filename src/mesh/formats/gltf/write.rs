//! Writing a [`GltfScene`] back with a new `TEXCOORD_n` per primitive (see the module doc).

use std::collections::HashMap;

use serde_json::{json, Value};

use super::read::GltfScene;
use super::{component, ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER};

/// The container to write.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum GltfTarget {
    /// One `.glb`: JSON chunk and BIN chunk.
    Glb,
    /// JSON whose one buffer is the file `bin_uri` (a name relative to the JSON's folder).
    Gltf { bin_uri: String },
}

/// The bytes to write: the `.glb` or `.gltf`, and for `.gltf` the `.bin` beside it.
#[derive(Clone, Debug)]
pub struct Written {
    pub main: Vec<u8>,
    pub bin: Option<Vec<u8>>,
}

impl GltfScene {
    /// The `n` of the `TEXCOORD_n` each primitive gets: `requested`, or the next free index
    /// (the number of sets it has). glTF wants a primitive's sets numbered 0, 1, … without
    /// gaps, so a requested set that exists or would leave a gap is refused, naming the
    /// primitive.
    pub fn uv_sets(&self, requested: Option<u32>) -> Result<Vec<u32>, String> {
        self.primitives
            .iter()
            .map(|p| {
                let next = p.texcoord_sets.len() as u32;
                match requested {
                    None => Ok(next),
                    Some(n) if p.texcoord_sets.contains(&n) => Err(format!(
                        "{} already has TEXCOORD_{n}; choose another --uv-set (its next free \
                         set is {next})",
                        p.path()
                    )),
                    Some(n) if n > next => Err(format!(
                        "{}: --uv-set {n} would leave a gap after its {next} TEXCOORD set(s); \
                         glTF numbers sets 0, 1, … (use --uv-set {next})",
                        p.path()
                    )),
                    Some(n) => Ok(n),
                }
            })
            .collect()
    }
}

/// The document of `scene` with texture coordinates `uv` (foldfree's bottom-left origin),
/// indexed per face corner of `scene.mesh` by `corner_uv` (#F×3), written into set `uv_set`
/// (or the next free one) of every primitive. Fails on non-finite coordinates or indices out
/// of range (nothing non-finite is ever written) and on a refused `uv_set`.
pub fn write_gltf(
    scene: &GltfScene,
    uv: &[[f64; 2]],
    corner_uv: &[[u32; 3]],
    uv_set: Option<u32>,
    target: &GltfTarget,
) -> Result<Written, String> {
    if corner_uv.len() != scene.mesh.faces.len() {
        return Err(format!(
            "{} corner texture indices for {} faces",
            corner_uv.len(),
            scene.mesh.faces.len()
        ));
    }
    if corner_uv.iter().flatten().any(|&t| t as usize >= uv.len()) {
        return Err(format!(
            "a face refers to a texture coordinate past the {} given",
            uv.len()
        ));
    }
    if let Some(t) = uv.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
        return Err(format!("texture coordinate {t} is not finite"));
    }
    let sets = scene.uv_sets(uv_set)?;
    let mut json = scene.json.clone();
    let mut blob = Blob::default();
    // The old buffers, one after the other, and their views moved onto the one new buffer.
    let mut base = Vec::with_capacity(scene.buffers.len());
    for b in &scene.buffers {
        base.push(blob.bytes.len());
        blob.bytes.extend_from_slice(b);
        blob.align();
    }
    let views = array(&mut json, "bufferViews")?;
    for (i, v) in views.iter_mut().enumerate() {
        let obj = v
            .as_object_mut()
            .ok_or_else(|| format!("bufferViews[{i}] is not an object"))?;
        let buffer = obj.get("buffer").and_then(Value::as_u64).unwrap_or(0) as usize;
        let offset = obj.get("byteOffset").and_then(Value::as_u64).unwrap_or(0) as usize;
        let moved = base.get(buffer).copied().unwrap_or(0) + offset;
        obj.insert("buffer".into(), json!(0));
        obj.insert("byteOffset".into(), json!(moved));
    }
    blob.first_view = views.len();
    blob.first_accessor = array(&mut json, "accessors")?.len();

    for (k, p) in scene.primitives.iter().enumerate() {
        let split = Split::of(
            &p.triangles,
            &corner_uv[p.first_face..p.first_face + p.triangles.len()],
            p.vertex_count,
        );
        let texcoords: Vec<u8> = split
            .uv
            .iter()
            .flat_map(|t| {
                let [u, v] = t.map_or([0.0, 0.0], |t| uv[t as usize]);
                [u as f32, (1.0 - v) as f32]
            })
            .flat_map(f32::to_le_bytes)
            .collect();
        let count = split.uv.len();
        let pointer = format!("/meshes/{}/primitives/{}", p.mesh, p.primitive);
        let path = p.path();
        let prim = json
            .pointer(&pointer)
            .cloned()
            .ok_or_else(|| format!("{path}: not in the document"))?;
        let mut prim = match prim {
            Value::Object(o) => o,
            _ => return Err(format!("{path} is not an object")),
        };
        if !split.extra.is_empty() {
            // Seams through glTF vertices: every attribute and morph target gets the copies.
            let copy = |blob: &mut Blob, json: &mut Value, old: &Value, at: &str| {
                let index = old
                    .as_u64()
                    .ok_or_else(|| format!("{at} is not an accessor index"))?
                    as usize;
                let (mut bytes, size) = scene.packed(index, at)?;
                for &gv in &split.extra {
                    let s = gv as usize * size;
                    bytes.extend_from_within(s..s + size);
                }
                let mut acc = json
                    .get("accessors")
                    .and_then(|a| a.get(index))
                    .cloned()
                    .ok_or_else(|| format!("{at}: no accessor {index}"))?;
                let view = blob.vertex_view(&bytes, size);
                if let Some(o) = acc.as_object_mut() {
                    o.remove("byteOffset");
                    o.insert("bufferView".into(), json!(view));
                    o.insert("count".into(), json!(count));
                }
                Ok::<Value, String>(json!(blob.accessor(acc)))
            };
            if let Some(Value::Object(attrs)) = prim.get_mut("attributes") {
                for (name, old) in attrs.iter_mut() {
                    *old = copy(
                        &mut blob,
                        &mut json,
                        old,
                        &format!("{path}.attributes.{name}"),
                    )?;
                }
            }
            if let Some(Value::Array(targets)) = prim.get_mut("targets") {
                for (t, target) in targets.iter_mut().enumerate() {
                    if let Value::Object(attrs) = target {
                        for (name, old) in attrs.iter_mut() {
                            let at = format!("{path}.targets[{t}].{name}");
                            *old = copy(&mut blob, &mut json, old, &at)?;
                        }
                    }
                }
            }
            let indices = blob.indices(&split.triangles, count);
            prim.insert("indices".into(), json!(indices));
        }
        let view = blob.vertex_view(&texcoords, 8);
        let acc = blob.accessor(json!({
            "bufferView": view,
            "componentType": component::FLOAT,
            "count": count,
            "type": "VEC2",
        }));
        if let Some(Value::Object(attrs)) = prim.get_mut("attributes") {
            attrs.insert(format!("TEXCOORD_{}", sets[k]), json!(acc));
        }
        *json
            .pointer_mut(&pointer)
            .ok_or_else(|| format!("{path}: not in the document"))? = Value::Object(prim);
    }

    blob.align();
    let total = blob.bytes.len();
    array(&mut json, "bufferViews")?.append(&mut blob.views);
    array(&mut json, "accessors")?.append(&mut blob.accessors);
    let mut buffer = json!({ "byteLength": total });
    if let GltfTarget::Gltf { bin_uri } = target {
        buffer["uri"] = json!(bin_uri);
    }
    json["buffers"] = json!([buffer]);
    let text = serde_json::to_vec(&json).map_err(|e| format!("JSON: {e}"))?;
    Ok(match target {
        GltfTarget::Glb => Written {
            main: glb(text, blob.bytes)?,
            bin: None,
        },
        GltfTarget::Gltf { .. } => Written {
            main: text,
            bin: Some(blob.bytes),
        },
    })
}

/// `json[key]` as an array, made empty when missing.
fn array<'a>(json: &'a mut Value, key: &str) -> Result<&'a mut Vec<Value>, String> {
    let obj = json
        .as_object_mut()
        .ok_or_else(|| "the document is not a JSON object".to_string())?;
    obj.entry(key)
        .or_insert_with(|| Value::Array(Vec::new()))
        .as_array_mut()
        .ok_or_else(|| format!("{key} is not an array"))
}

/// A `.glb`: header, JSON chunk padded with spaces, BIN chunk padded with zeros.
fn glb(mut text: Vec<u8>, mut bin: Vec<u8>) -> Result<Vec<u8>, String> {
    while text.len() % 4 != 0 {
        text.push(b' ');
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + text.len() + 8 + bin.len();
    let word = |n: usize| {
        u32::try_from(n)
            .map(u32::to_le_bytes)
            .map_err(|_| format!("{total} bytes, more than a GLB can hold"))
    };
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&word(total)?);
    out.extend_from_slice(&word(text.len())?);
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&text);
    out.extend_from_slice(&word(bin.len())?);
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    Ok(out)
}

/// The new buffer's bytes and the views and accessors appended to the document.
#[derive(Default)]
struct Blob {
    bytes: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
    first_view: usize,
    first_accessor: usize,
}

impl Blob {
    /// Pads to a multiple of 4 bytes: every view starts 4-aligned, so every accessor is
    /// aligned to its component size.
    fn align(&mut self) {
        while self.bytes.len() % 4 != 0 {
            self.bytes.push(0);
        }
    }

    /// A vertex-attribute view of elements of `size` bytes, `packed` one after the other. The
    /// specification wants vertex elements 4-aligned: elements of other sizes (a VEC3 of
    /// bytes) are spread to a byteStride of the next multiple of 4.
    fn vertex_view(&mut self, packed: &[u8], size: usize) -> usize {
        self.align();
        let start = self.bytes.len();
        let stride = size.div_ceil(4) * 4;
        for e in packed.chunks(size.max(1)) {
            self.bytes.extend_from_slice(e);
            self.bytes.resize(self.bytes.len() + stride - e.len(), 0);
        }
        let mut view = json!({
            "buffer": 0,
            "byteOffset": start,
            "byteLength": self.bytes.len() - start,
            "target": ARRAY_BUFFER,
        });
        if stride != size {
            view["byteStride"] = json!(stride);
        }
        self.view(view)
    }

    fn view(&mut self, view: Value) -> usize {
        self.views.push(view);
        self.first_view + self.views.len() - 1
    }

    fn accessor(&mut self, acc: Value) -> usize {
        self.accessors.push(acc);
        self.first_accessor + self.accessors.len() - 1
    }

    /// An index accessor for `triangles` over `count` vertices: UNSIGNED_SHORT when every
    /// index fits below 65535 (the restart value, which glTF forbids as an index), else
    /// UNSIGNED_INT.
    fn indices(&mut self, triangles: &[[u32; 3]], count: usize) -> usize {
        self.align();
        let start = self.bytes.len();
        let short = count < 65535;
        for &v in triangles.iter().flatten() {
            if short {
                self.bytes.extend_from_slice(&(v as u16).to_le_bytes());
            } else {
                self.bytes.extend_from_slice(&v.to_le_bytes());
            }
        }
        let view = self.view(json!({
            "buffer": 0,
            "byteOffset": start,
            "byteLength": self.bytes.len() - start,
            "target": ELEMENT_ARRAY_BUFFER,
        }));
        self.accessor(json!({
            "bufferView": view,
            "componentType": if short { component::UNSIGNED_SHORT } else { component::UNSIGNED_INT },
            "count": triangles.len() * 3,
            "type": "SCALAR",
        }))
    }
}

/// One primitive's vertices after splitting at seams: glTF vertex `i` keeps index `i` with the
/// UV of its first corner, and every other UV at the same vertex gets a copy appended.
struct Split {
    /// The UV index of every output vertex (`None`: a vertex no triangle uses).
    uv: Vec<Option<u32>>,
    /// The glTF vertex each appended copy duplicates.
    extra: Vec<u32>,
    /// The triangles over the output vertices.
    triangles: Vec<[u32; 3]>,
}

impl Split {
    fn of(triangles: &[[u32; 3]], corner_uv: &[[u32; 3]], vertex_count: usize) -> Split {
        let mut uv: Vec<Option<u32>> = vec![None; vertex_count];
        let mut extra = Vec::new();
        let mut extra_uv = Vec::new();
        let mut copies: HashMap<(u32, u32), u32> = HashMap::new();
        let mut out = Vec::with_capacity(triangles.len());
        for (tri, tex) in triangles.iter().zip(corner_uv) {
            let mut t = [0u32; 3];
            for k in 0..3 {
                let (gv, ui) = (tri[k], tex[k]);
                t[k] = match uv[gv as usize] {
                    None => {
                        uv[gv as usize] = Some(ui);
                        gv
                    }
                    Some(u) if u == ui => gv,
                    Some(_) => *copies.entry((gv, ui)).or_insert_with(|| {
                        extra.push(gv);
                        extra_uv.push(Some(ui));
                        (vertex_count + extra.len() - 1) as u32
                    }),
                };
            }
            out.push(t);
        }
        uv.append(&mut extra_uv);
        Split {
            uv,
            extra,
            triangles: out,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_vertex_with_two_uvs_is_copied_once_per_extra_uv() {
        // Two triangles sharing vertices 1 and 2; vertex 2 has UV 5 in one, UV 6 in the other.
        let tris = [[0, 1, 2], [2, 1, 3]];
        let tex = [[0, 1, 5], [6, 1, 3]];
        let s = Split::of(&tris, &tex, 5);
        assert_eq!(s.extra, vec![2]);
        assert_eq!(s.triangles, vec![[0, 1, 2], [5, 1, 3]]);
        assert_eq!(
            s.uv,
            vec![Some(0), Some(1), Some(5), Some(3), None, Some(6)]
        );
    }
}
