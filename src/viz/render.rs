//! The checkerboard texture-mapping view (`foldfree render`): reading an OBJ with its `vt` (or
//! a glTF file with a TEXCOORD set),
//! expanding it to per-corner vertices (so UV seams stay sharp) and encoding the rendered
//! RGBA8 pixels as PNG. The drawing itself is [`crate::gpu::render_checker`].

use std::io;
use std::path::Path;

use crate::{Error, Result};

/// An OBJ's positions, texture coordinates and triangles with separate position and UV
/// indices per corner (polygons fan-triangulated).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct UvObj {
    pub positions: Vec<[f64; 3]>,
    pub uvs: Vec<[f64; 2]>,
    /// Per triangle, the position index of each corner.
    pub faces: Vec<[usize; 3]>,
    /// Per triangle, the UV index of each corner.
    pub face_uvs: Vec<[usize; 3]>,
}

impl UvObj {
    /// One vertex per triangle corner: `(positions, uvs, indices)` ready for drawing. The UVs
    /// are moved and uniformly scaled so that their bounding box's longer side is the unit
    /// interval (a checker of N squares per unit then spans the layout N times).
    pub fn corners(&self) -> (Vec<[f32; 3]>, Vec<[f32; 2]>, Vec<u32>) {
        let n = self.faces.len() * 3;
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for t in self.face_uvs.iter().flatten() {
            for a in 0..2 {
                lo[a] = lo[a].min(self.uvs[*t][a]);
                hi[a] = hi[a].max(self.uvs[*t][a]);
            }
        }
        let side = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let scale = if side > 0.0 { 1.0 / side } else { 1.0 };
        // Positions at unit scale before they become f32 (whose range ends at 3.4e38): the
        // camera frames the bounding box, so the picture is the same at any scale.
        let unit = crate::mesh::Scale::fit(&self.positions);
        let mut positions = Vec::with_capacity(n);
        let mut uvs = Vec::with_capacity(n);
        for (f, t) in self.faces.iter().zip(&self.face_uvs) {
            for k in 0..3 {
                let p = unit.apply(self.positions[f[k]]);
                let uv = self.uvs[t[k]];
                positions.push([p[0] as f32, p[1] as f32, p[2] as f32]);
                uvs.push([
                    ((uv[0] - lo[0]) * scale) as f32,
                    ((uv[1] - lo[1]) * scale) as f32,
                ]);
            }
        }
        let indices = (0..n as u32).collect();
        (positions, uvs, indices)
    }
}

/// Resolves a 1-based (or negative, relative) OBJ index against `count` items.
fn resolve(token: &str, count: usize) -> Option<usize> {
    let i: i64 = token.parse().ok()?;
    let idx = if i > 0 {
        i - 1
    } else if i < 0 {
        count as i64 + i
    } else {
        return None;
    };
    (0..count as i64).contains(&idx).then_some(idx as usize)
}

/// Parses OBJ text with `v`, `vt` and `f v/t[/n]` lines (other lines are ignored). Every face
/// corner must carry a UV index; a file without `vt` is a usage error (exit code 2).
pub fn parse_obj_with_uv(text: &str, name: &str) -> Result<UvObj> {
    let has_vt = text.lines().any(|l| {
        let mut it = l.split_whitespace();
        it.next() == Some("vt")
    });
    if !has_vt {
        return Err(no_vt(name));
    }
    let mut obj = UvObj::default();
    let bad = |line: usize, what: String| Error::Usage(format!("{name}:{line}: {what}"));
    for (ln, raw) in text.lines().enumerate() {
        let line_no = ln + 1;
        let line = raw.split('#').next().unwrap_or("").trim();
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it.take(3).filter_map(|s| s.parse().ok()).collect();
                if c.len() != 3 || c.iter().any(|x| !x.is_finite()) {
                    return Err(bad(line_no, format!("bad vertex line `{line}`")));
                }
                obj.positions.push([c[0], c[1], c[2]]);
            }
            Some("vt") => {
                let c: Vec<f64> = it.take(2).filter_map(|s| s.parse().ok()).collect();
                if c.len() != 2 || c.iter().any(|x| !x.is_finite()) {
                    return Err(bad(
                        line_no,
                        format!("bad texture coordinate line `{line}`"),
                    ));
                }
                obj.uvs.push([c[0], c[1]]);
            }
            Some("f") => {
                let mut pos = Vec::new();
                let mut tex = Vec::new();
                for corner in it {
                    let mut parts = corner.split('/');
                    let v = parts.next().and_then(|s| resolve(s, obj.positions.len()));
                    let t = parts.next().filter(|s| !s.is_empty());
                    let Some(v) = v else {
                        return Err(bad(line_no, format!("bad vertex index in `{corner}`")));
                    };
                    let Some(t) = t else {
                        return Err(bad(
                            line_no,
                            format!("face corner `{corner}` has no texture coordinate index"),
                        ));
                    };
                    let Some(t) = resolve(t, obj.uvs.len()) else {
                        return Err(bad(line_no, format!("bad texture index in `{corner}`")));
                    };
                    pos.push(v);
                    tex.push(t);
                }
                if pos.len() < 3 {
                    return Err(bad(line_no, "face with fewer than 3 corners".into()));
                }
                for k in 1..pos.len() - 1 {
                    obj.faces.push([pos[0], pos[k], pos[k + 1]]);
                    obj.face_uvs.push([tex[0], tex[k], tex[k + 1]]);
                }
            }
            _ => {}
        }
    }
    if obj.faces.is_empty() {
        return Err(Error::Usage(format!("{name}: no faces")));
    }
    Ok(obj)
}

fn no_vt(name: &str) -> Error {
    Error::Usage(format!(
        "{name}: no texture coordinates (`vt` lines); run `foldfree param` first to get a UV map"
    ))
}

/// Reads a UV-mapped surface: an OBJ with `vt` ([`read_obj_with_uv`]) or a glTF file with a
/// `TEXCOORD_set` in every primitive ([`read_gltf_with_uv`]; `set` is ignored for OBJ).
pub fn read_with_uv(path: &Path, max_faces: usize, set: Option<u32>) -> Result<UvObj> {
    match crate::mesh::SurfaceFormat::from_path(path)? {
        crate::mesh::SurfaceFormat::Gltf => read_gltf_with_uv(path, max_faces, set),
        _ => read_obj_with_uv(path, max_faces),
    }
}

/// A glTF file's triangles with texture coordinates `TEXCOORD_set` (default: the highest set
/// every primitive has, which is the one `foldfree param` added), turned to foldfree's
/// bottom-left origin (`(u, 1 − v)`), so the checker looks as it does through the OBJ of the
/// same map. Positions are the file's, welded per primitive as for mapping; UVs stay per glTF
/// vertex, so seams stay sharp.
pub fn read_gltf_with_uv(path: &Path, max_faces: usize, set: Option<u32>) -> Result<UvObj> {
    let scene = crate::mesh::formats::gltf::read_gltf(path, max_faces)?;
    let common = scene
        .primitives
        .iter()
        .map(|p| p.texcoord_sets.iter().max().copied())
        .min()
        .flatten();
    let Some(set) = set.or(common) else {
        return Err(Error::Usage(format!(
            "{}: a primitive has no TEXCOORD set; run `foldfree param` first to get a UV map",
            path.display()
        )));
    };
    let mut obj = UvObj {
        positions: scene.mesh.positions.clone(),
        faces: scene
            .mesh
            .faces
            .iter()
            .map(|f| f.map(|v| v as usize))
            .collect(),
        ..UvObj::default()
    };
    for (k, p) in scene.primitives.iter().enumerate() {
        let uv = scene
            .texcoords(k, set)
            .map_err(|e| Error::Usage(format!("{}: {e}", path.display())))?
            .ok_or_else(|| {
                Error::Usage(format!(
                    "{}: {} has no TEXCOORD_{set}",
                    path.display(),
                    p.path()
                ))
            })?;
        let base = obj.uvs.len();
        obj.uvs.extend(uv);
        obj.face_uvs
            .extend(p.triangles.iter().map(|t| t.map(|v| base + v as usize)));
    }
    obj.check_finite(path)
}

impl UvObj {
    /// A NaN or infinite position or UV would be drawn as nothing or as garbage and the
    /// picture still written: refused, naming the file and the vertex or UV.
    pub fn check_finite(self, path: &Path) -> Result<UvObj> {
        if let Some(v) = self
            .positions
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            let value = self.positions[v].into_iter().find(|c| !c.is_finite());
            return Err(Error::Mesh(crate::mesh::MeshError::NonFinite {
                file: path.to_path_buf(),
                vertex: v,
                value: value.unwrap_or(f64::NAN),
            }));
        }
        if let Some(t) = self
            .uvs
            .iter()
            .position(|p| !p.iter().all(|c| c.is_finite()))
        {
            return Err(Error::Usage(format!(
                "{}: texture coordinate {t} is not finite ({:?})",
                path.display(),
                self.uvs[t]
            )));
        }
        Ok(self)
    }
}

/// Reads `path` with [`parse_obj_with_uv`].
pub fn read_obj_with_uv(path: &Path, max_faces: usize) -> Result<UvObj> {
    // PLY, OFF and STL surfaces carry no UVs foldfree reads: say so rather than "binary file?".
    let format = crate::mesh::SurfaceFormat::from_path(path)?;
    if format != crate::mesh::SurfaceFormat::Obj {
        return Err(Error::Usage(format!(
            "{}: no texture coordinates: the checker needs an OBJ with `vt`; draw this {} \
             surface with --shade normals, or map it with `foldfree param` (its output is OBJ)",
            path.display(),
            format.name()
        )));
    }
    let limit = crate::files::byte_limit(max_faces);
    let bytes = crate::files::read_bounded(path, limit, "the --max-faces limit")?;
    let text = String::from_utf8(bytes).map_err(|_| {
        crate::Error::Mesh(crate::mesh::MeshError::Read {
            file: path.to_path_buf(),
            reason: "not UTF-8 text (binary file?)".into(),
        })
    })?;
    parse_obj_with_uv(&text, &path.display().to_string())?.check_finite(path)
}

/// Encodes `width × height` RGBA8 pixels (rows top to bottom) as PNG.
pub fn encode_rgba_png(width: u32, height: u32, rgba: &[u8]) -> io::Result<Vec<u8>> {
    let mut out = Vec::new();
    let mut enc = png::Encoder::new(&mut out, width, height);
    enc.set_color(png::ColorType::Rgba);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Fast);
    let mut writer = enc.write_header().map_err(io::Error::other)?;
    writer.write_image_data(rgba).map_err(io::Error::other)?;
    writer.finish().map_err(io::Error::other)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_corners_with_seams() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\nvt 5 5\n\
                    f 1/1 2/2 4/4 3/3\nf 1/5 2/2 3/3\n";
        let obj = parse_obj_with_uv(text, "t.obj").expect("parses");
        assert_eq!(obj.faces, vec![[0, 1, 3], [0, 3, 2], [0, 1, 2]]);
        assert_eq!(obj.face_uvs, vec![[0, 1, 3], [0, 3, 2], [4, 1, 2]]);
        let (p, t, i) = obj.corners();
        assert_eq!((p.len(), t.len(), i.len()), (9, 9, 9));
        // UVs normalised to the bounding box [0, 5]²: (5, 5) becomes (1, 1).
        assert_eq!(t[6], [1.0, 1.0]);
        assert_eq!(t[0], [0.0, 0.0]);
    }

    #[test]
    fn no_vt_is_a_usage_error() {
        let err =
            parse_obj_with_uv("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "a.obj").expect_err("no vt");
        assert_eq!(err.exit_code(), 2);
        assert!(err.to_string().contains("no texture coordinates"), "{err}");
        let err = parse_obj_with_uv("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1 2 3\n", "a.obj")
            .expect_err("corner without vt index");
        assert!(err.to_string().contains("texture coordinate"), "{err}");
    }
}
