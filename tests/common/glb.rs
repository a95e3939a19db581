//! Small glTF files built in tests: a triangle mesh with per-vertex normals and a TEXCOORD_0,
//! as a `.glb` (indexed or not), and an independent reader (the `gltf` crate's) of what
//! foldfree writes.

use serde_json::json;

/// One primitive's vertex data.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Prim {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub uv0: Vec<[f32; 2]>,
    /// `None`: a non-indexed primitive (every 3 vertices a triangle).
    pub indices: Option<Vec<u32>>,
    /// The POSITION displacements of one morph target, if any.
    pub target: Option<Vec<[f32; 3]>>,
}

impl Prim {
    /// A smooth-shaded indexed primitive: area-weighted vertex normals, TEXCOORD_0 the x, y of
    /// the bounding box mapped to [0, 1].
    pub fn smooth(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Prim {
        let mut normals = vec![[0.0f64; 3]; positions.len()];
        for f in faces {
            let [a, b, c] = f.map(|v| positions[v as usize]);
            let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let n = [
                e1[1] * e2[2] - e1[2] * e2[1],
                e1[2] * e2[0] - e1[0] * e2[2],
                e1[0] * e2[1] - e1[1] * e2[0],
            ];
            for &v in f {
                for d in 0..3 {
                    normals[v as usize][d] += n[d];
                }
            }
        }
        let (lo, hi) = bounds(positions);
        Prim {
            positions: positions.iter().map(|p| p.map(|c| c as f32)).collect(),
            normals: normals.iter().map(|n| unit(*n)).collect(),
            uv0: positions
                .iter()
                .map(|p| {
                    [
                        ((p[0] - lo[0]) / (hi[0] - lo[0]).max(1e-30)) as f32,
                        ((p[1] - lo[1]) / (hi[1] - lo[1]).max(1e-30)) as f32,
                    ]
                })
                .collect(),
            indices: Some(faces.iter().flatten().copied().collect()),
            target: None,
        }
    }

    /// The same surface flat-shaded and non-indexed: three vertices of its own per triangle,
    /// with the face normal (so every vertex is split, as exporters do for hard edges).
    pub fn flat(positions: &[[f64; 3]], faces: &[[u32; 3]]) -> Prim {
        let smooth = Prim::smooth(positions, faces);
        let mut p = Prim::default();
        for f in faces {
            let [a, b, c] = f.map(|v| positions[v as usize]);
            let e1 = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let e2 = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let n = unit([
                e1[1] * e2[2] - e1[2] * e2[1],
                e1[2] * e2[0] - e1[0] * e2[2],
                e1[0] * e2[1] - e1[1] * e2[0],
            ]);
            for &v in f {
                p.positions.push(smooth.positions[v as usize]);
                p.normals.push(n);
                p.uv0.push(smooth.uv0[v as usize]);
            }
        }
        p
    }
}

/// A sphere: an octahedron subdivided `levels` times, projected to the unit sphere (closed,
/// genus 0, vertices shared between triangles — so atlas seams split glTF vertices).
pub fn sphere(levels: usize) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
    let mut p: Vec<[f64; 3]> = vec![
        [1.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, -1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
    ];
    let mut f: Vec<[u32; 3]> = vec![
        [0, 2, 4],
        [2, 1, 4],
        [1, 3, 4],
        [3, 0, 4],
        [2, 0, 5],
        [1, 2, 5],
        [3, 1, 5],
        [0, 3, 5],
    ];
    for _ in 0..levels {
        let mut mid = std::collections::HashMap::new();
        let mut next = Vec::new();
        for t in &f {
            let mut m = [0u32; 3];
            for k in 0..3 {
                let (a, b) = (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]));
                m[k] = *mid.entry((a, b)).or_insert_with(|| {
                    let (pa, pb) = (p[a as usize], p[b as usize]);
                    let c = [0, 1, 2].map(|d| (pa[d] + pb[d]) / 2.0);
                    let l = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
                    p.push(c.map(|x| x / l));
                    (p.len() - 1) as u32
                });
            }
            next.push([t[0], m[0], m[2]]);
            next.push([m[0], t[1], m[1]]);
            next.push([m[2], m[1], t[2]]);
            next.push([m[0], m[1], m[2]]);
        }
        f = next;
    }
    (p, f)
}

fn bounds(positions: &[[f64; 3]]) -> ([f64; 3], [f64; 3]) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in positions {
        for d in 0..3 {
            lo[d] = lo[d].min(p[d]);
            hi[d] = hi[d].max(p[d]);
        }
    }
    (lo, hi)
}

fn unit(n: [f64; 3]) -> [f32; 3] {
    let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt().max(1e-300);
    [(n[0] / l) as f32, (n[1] / l) as f32, (n[2] / l) as f32]
}

/// A `.glb` with one mesh holding `prims`, one node and one scene.
pub fn glb(prims: &[Prim]) -> Vec<u8> {
    let mut bin: Vec<u8> = Vec::new();
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut add = |bin: &mut Vec<u8>, bytes: Vec<u8>, target: u32, acc: serde_json::Value| {
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        views.push(json!({"buffer": 0, "byteOffset": bin.len(), "byteLength": bytes.len(), "target": target}));
        bin.extend_from_slice(&bytes);
        let mut acc = acc;
        acc["bufferView"] = json!(views.len() - 1);
        accessors.push(acc);
        accessors.len() - 1
    };
    let floats = |v: &[f32]| v.iter().flat_map(|x| x.to_le_bytes()).collect::<Vec<u8>>();
    let mut primitives = Vec::new();
    let bounds = |v: &[[f32; 3]]| {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for q in v {
            for d in 0..3 {
                lo[d] = lo[d].min(q[d]);
                hi[d] = hi[d].max(q[d]);
            }
        }
        (lo, hi)
    };
    for p in prims {
        let (lo, hi) = bounds(&p.positions);
        let n = p.positions.len();
        let pos = add(
            &mut bin,
            floats(p.positions.as_flattened()),
            34962,
            json!({"componentType": 5126, "count": n, "type": "VEC3", "min": lo, "max": hi}),
        );
        let nor = add(
            &mut bin,
            floats(p.normals.as_flattened()),
            34962,
            json!({"componentType": 5126, "count": n, "type": "VEC3"}),
        );
        let uv = add(
            &mut bin,
            floats(p.uv0.as_flattened()),
            34962,
            json!({"componentType": 5126, "count": n, "type": "VEC2"}),
        );
        let mut prim = json!({
            "attributes": {"POSITION": pos, "NORMAL": nor, "TEXCOORD_0": uv},
            "mode": 4,
        });
        if let Some(t) = &p.target {
            let (lo, hi) = bounds(t);
            let d = add(
                &mut bin,
                floats(t.as_flattened()),
                34962,
                json!({"componentType": 5126, "count": n, "type": "VEC3", "min": lo, "max": hi}),
            );
            prim["targets"] = json!([{"POSITION": d}]);
        }
        if let Some(ix) = &p.indices {
            let i = add(
                &mut bin,
                ix.iter().flat_map(|x| x.to_le_bytes()).collect(),
                34963,
                json!({"componentType": 5125, "count": ix.len(), "type": "SCALAR"}),
            );
            prim["indices"] = json!(i);
        }
        primitives.push(prim);
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let doc = json!({
        "asset": {"version": "2.0", "generator": "foldfree tests"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": "kept"}],
        "meshes": [{"primitives": primitives, "name": "surface"}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    pack_glb(serde_json::to_vec(&doc).expect("json"), bin)
}

/// A GLB container of `json` and `bin` (each padded).
pub fn pack_glb(mut json: Vec<u8>, mut bin: Vec<u8>) -> Vec<u8> {
    while json.len() % 4 != 0 {
        json.push(b' ');
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&bin);
    out
}

/// A primitive as read back by the `gltf` crate (independent of foldfree's reader).
#[derive(Clone, Debug, Default)]
pub struct ReadPrim {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    /// Every TEXCOORD set, by index.
    pub uvs: Vec<Vec<[f32; 2]>>,
    pub indices: Vec<u32>,
    /// The first morph target's POSITION displacements (empty without one).
    pub target: Vec<[f32; 3]>,
}

/// Every primitive of every mesh of a `.glb` or `.gltf` (`bin`: the `.bin` of a `.gltf`).
pub fn read_back(main: &[u8], bin: Option<&[u8]>) -> (serde_json::Value, Vec<ReadPrim>) {
    let g = gltf::Gltf::from_slice(main).expect("the output parses as glTF");
    let blob: Vec<u8> = match bin {
        Some(b) => b.to_vec(),
        None => g.blob.clone().expect("a GLB has a BIN chunk"),
    };
    // The raw JSON (the crate's typed document drops what its features do not know).
    let text = if main.starts_with(b"glTF") {
        let len = u32::from_le_bytes(main[12..16].try_into().unwrap()) as usize;
        &main[20..20 + len]
    } else {
        main
    };
    let json: serde_json::Value = serde_json::from_slice(text).expect("json");
    let mut out = Vec::new();
    for m in g.document.meshes() {
        for p in m.primitives() {
            let r = p.reader(|_| Some(&blob[..]));
            let positions: Vec<[f32; 3]> = r.read_positions().expect("POSITION").collect();
            let n = positions.len();
            let mut uvs = Vec::new();
            while let Some(t) = r.read_tex_coords(uvs.len() as u32) {
                uvs.push(t.into_f32().collect());
            }
            let target = r
                .read_morph_targets()
                .next()
                .and_then(|(p, _, _)| p)
                .map(|p| p.collect())
                .unwrap_or_default();
            out.push(ReadPrim {
                target,
                normals: r.read_normals().map(|x| x.collect()).unwrap_or_default(),
                uvs,
                indices: r
                    .read_indices()
                    .map(|i| i.into_u32().collect())
                    .unwrap_or_else(|| (0..n as u32).collect()),
                positions,
            });
        }
    }
    (json, out)
}
