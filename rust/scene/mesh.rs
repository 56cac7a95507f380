//! Reading a mesh object's OBJ file (via `tobj`) or PLY file (via `ply-rs-bw`), triangulated, into
//! world-space triangles, validated: every error names the object's field and the file.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::DVec3;

use super::{MAX_MAGNITUDE, V3};
use crate::error::{Error, Result};
use crate::geometry::mesh::Mesh;

/// `file` as written, resolved against `base` (the scene file's folder; the current directory when
/// `None`) and made absolute.
pub fn resolve(file: &str, base: Option<&Path>) -> PathBuf {
    let p = Path::new(file);
    let p = match base {
        Some(b) if p.is_relative() => b.join(p),
        _ => p.to_path_buf(),
    };
    std::path::absolute(&p).unwrap_or(p)
}

/// The largest mesh file read (README: "Input limits"): 256 MiB.
pub const MAX_MESH_BYTES: u64 = 256 << 20;

/// The most PLY elements (vertices, faces and any other element together) and the most OBJ vertices plus
/// triangles one mesh may have (README: "Input limits"); each costs some 100-200 bytes once placed.
pub const MAX_MESH_ELEMENTS: usize = 10_000_000;

/// The bytes of the regular file `path`, at most `limit` of them. Anything else (a directory, a FIFO, a
/// device such as /dev/zero) is refused before it is read: it is opened without blocking and checked
/// again once open, so that a FIFO cannot hang the open and an endless device cannot fill the memory.
pub fn read_regular(path: &Path, limit: u64, what: &str) -> std::result::Result<Vec<u8>, String> {
    use std::io::Read;
    use std::os::unix::fs::OpenOptionsExt;
    let not_regular =
        || format!("not a regular file (a directory, FIFO or device): not read as the {what} file");
    let meta = std::fs::metadata(path).map_err(|_| format!("cannot open the {what} file"))?;
    if !meta.is_file() {
        return Err(not_regular());
    }
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(|_| format!("cannot open the {what} file"))?;
    let meta = file
        .metadata()
        .map_err(|_| format!("cannot read the {what} file"))?;
    if !meta.is_file() {
        return Err(not_regular());
    }
    let too_big =
        |n: u64| format!("the {what} file is {n} bytes, more than the {limit} read (the limit)");
    if meta.len() > limit {
        return Err(too_big(meta.len()));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(limit + 1)
        .read_to_end(&mut bytes)
        .map_err(|_| format!("cannot read the {what} file"))?;
    if bytes.len() as u64 > limit {
        return Err(too_big(bytes.len() as u64));
    }
    Ok(bytes)
}

/// One PLY element as read: a vertex's `x y z` (and `nx ny nz`), a face's index list; any other
/// property is ignored. A few dozen bytes each, whatever the element.
#[derive(Default)]
struct PlyItem {
    xyz: [Option<f32>; 3],
    normal: [Option<f32>; 3],
    indices: Option<Vec<i64>>,
}

impl PlyItem {
    fn set(&mut self, name: &str, v: f64) -> ply_rs_bw::ply::PropertyAccessResult {
        let slot = match name {
            "x" => &mut self.xyz[0],
            "y" => &mut self.xyz[1],
            "z" => &mut self.xyz[2],
            "nx" => &mut self.normal[0],
            "ny" => &mut self.normal[1],
            "nz" => &mut self.normal[2],
            _ => return ply_rs_bw::ply::PropertyAccessResult::Ignored,
        };
        *slot = Some(v as f32);
        ply_rs_bw::ply::PropertyAccessResult::Set
    }
}

impl ply_rs_bw::ply::PropertyAccess for PlyItem {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(
        &mut self,
        name: &str,
        property: ply_rs_bw::ply::Property,
    ) -> ply_rs_bw::ply::PropertyAccessResult {
        use ply_rs_bw::ply::Property as P;
        let list = |l: Vec<i64>| Some(l);
        let number = match property {
            P::Float(v) => Some(v as f64),
            P::Double(v) => Some(v),
            P::Char(v) => Some(v as f64),
            P::UChar(v) => Some(v as f64),
            P::Short(v) => Some(v as f64),
            P::UShort(v) => Some(v as f64),
            P::Int(v) => Some(v as f64),
            P::UInt(v) => Some(v as f64),
            _ => None,
        };
        if let Some(v) = number {
            return self.set(name, v);
        }
        if name != "vertex_indices" && name != "vertex_index" {
            return ply_rs_bw::ply::PropertyAccessResult::Ignored;
        }
        self.indices = match property {
            P::ListChar(l) => list(l.into_iter().map(i64::from).collect()),
            P::ListUChar(l) => list(l.into_iter().map(i64::from).collect()),
            P::ListShort(l) => list(l.into_iter().map(i64::from).collect()),
            P::ListUShort(l) => list(l.into_iter().map(i64::from).collect()),
            P::ListInt(l) => list(l.into_iter().map(i64::from).collect()),
            P::ListUInt(l) => list(l.into_iter().map(i64::from).collect()),
            _ => None,
        };
        ply_rs_bw::ply::PropertyAccessResult::Set
    }
}

/// The fewest bytes one element of `def` takes in the file: a binary element's fixed-size properties and
/// list counts, an ASCII element's one character and one separator per property.
fn min_element_bytes(
    def: &ply_rs_bw::ply::ElementDef,
    encoding: ply_rs_bw::ply::Encoding,
) -> usize {
    use ply_rs_bw::ply::{PropertyType, ScalarType as S};
    let size = |s: &S| match s {
        S::Char | S::UChar => 1,
        S::Short | S::UShort => 2,
        S::Int | S::UInt | S::Float => 4,
        S::Double => 8,
    };
    let bytes: usize = def
        .properties
        .values()
        .map(|p| match (&p.data_type, encoding) {
            (_, ply_rs_bw::ply::Encoding::Ascii) => 2,
            (PropertyType::Scalar(s), _) | (PropertyType::List(s, _), _) => size(s),
        })
        .sum();
    bytes.max(1)
}

/// Refuse a header whose element counts the file cannot hold (or that pass MAX_MESH_ELEMENTS) before any
/// element is read, so that memory stays in proportion to the file.
fn check_counts(header: &ply_rs_bw::ply::Header, body: usize) -> std::result::Result<(), String> {
    let mut need = 0usize;
    let mut total = 0usize;
    for def in header.elements.values() {
        total = total.saturating_add(def.count);
        need = need.saturating_add(
            def.count
                .saturating_mul(min_element_bytes(def, header.encoding)),
        );
    }
    if total > MAX_MESH_ELEMENTS {
        return Err(format!(
            "the PLY header declares {total} elements, more than the {MAX_MESH_ELEMENTS} read (the limit)"
        ));
    }
    if need > body {
        return Err(format!(
            "the PLY header declares {total} elements, more than its {body} bytes of data can hold"
        ));
    }
    Ok(())
}

/// A PLY parser's error in one line, without the file's text it quotes.
fn ply_error(e: &ply_rs_bw::parser::ParseError) -> String {
    let at = e
        .line()
        .map(|l| format!(" at line {l}"))
        .unwrap_or_default();
    let why = match e.kind() {
        std::io::ErrorKind::UnexpectedEof => "it ends early",
        _ => "malformed",
    };
    format!("not a valid PLY file ({why}{at})")
}

/// A PLY file's `vertex` (`x`, `y`, `z`, and `nx`, `ny`, `nz` when every vertex has them) and `face`
/// (`vertex_indices` or `vertex_index`, polygons split into fans) elements in `tobj`'s form, so that
/// both formats share one validation.
fn read_ply(bytes: &[u8]) -> std::result::Result<Vec<tobj::Model>, String> {
    let parser = ply_rs_bw::parser::Parser::<PlyItem>::new();
    let mut reader = ply_rs_bw::parser::Reader::new(std::io::Cursor::new(bytes));
    let header = parser.read_header(&mut reader).map_err(|e| ply_error(&e))?;
    check_counts(&header, bytes.len() - reader.get_ref().position() as usize)?;
    let mut vertices = Vec::new();
    let mut faces = Vec::new();
    for (name, def) in &header.elements {
        let items = parser
            .read_payload_for_element(&mut reader, def, &header)
            .map_err(|e| ply_error(&e))?;
        match name.as_str() {
            "vertex" => vertices = items,
            "face" => faces = items,
            _ => {}
        }
    }
    let mut mesh = tobj::Mesh::default();
    for (k, v) in vertices.iter().enumerate() {
        for (axis, c) in ["x", "y", "z"].iter().zip(v.xyz) {
            let c = c.ok_or_else(|| format!("vertex {} has no number {axis:?}", k + 1))?;
            mesh.positions.push(c);
        }
        if let [Some(x), Some(y), Some(z)] = v.normal {
            mesh.normals.extend([x, y, z]);
        }
    }
    if mesh.normals.len() != mesh.positions.len() {
        mesh.normals.clear();
    }
    for (k, f) in faces.iter().enumerate() {
        let idx = f
            .indices
            .as_deref()
            .ok_or_else(|| format!("face {} has no integer list vertex_indices", k + 1))?;
        if let Some(&bad) = idx.iter().find(|&&i| i < 0 || i >= vertices.len() as i64) {
            return Err(format!(
                "face {}: vertex index {bad} is out of range ({} vertices)",
                k + 1,
                vertices.len()
            ));
        }
        for j in 1..idx.len().saturating_sub(1) {
            mesh.indices
                .extend([idx[0] as u32, idx[j] as u32, idx[j + 1] as u32]);
        }
    }
    Ok(vec![tobj::Model::new(mesh, String::new())])
}

/// An OBJ file's objects, triangulated; a material library it names is not read (the scene gives the
/// material).
fn read_obj(bytes: &[u8]) -> std::result::Result<Vec<tobj::Model>, String> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let mut reader = std::io::BufReader::new(std::io::Cursor::new(bytes));
    let no_materials = |_: &Path| Err(tobj::LoadError::OpenFileFailed);
    let (models, _) =
        tobj::load_obj_buf(&mut reader, &opts, no_materials).map_err(|e| match e {
            tobj::LoadError::ReadError => "cannot read the OBJ file".to_string(),
            e => format!("not a valid OBJ file ({e})"),
        })?;
    let elements: usize = models
        .iter()
        .map(|m| m.mesh.positions.len() / 3 + m.mesh.indices.len() / 3)
        .sum();
    if elements > MAX_MESH_ELEMENTS {
        return Err(format!(
            "the OBJ file has {elements} vertices and triangles, more than the {MAX_MESH_ELEMENTS} read (the limit)"
        ));
    }
    Ok(models)
}

/// Load the OBJ or PLY (by extension) at `path`, placed at `position` and scaled by `scale`.
pub fn load(field: &str, path: &Path, position: V3, scale: f64) -> Result<Arc<Mesh>> {
    let shown = path.display();
    let err = |m: String| Error::scene(field, format!("{shown}: {m}"));
    let is_ply = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    let kind = if is_ply { "PLY" } else { "OBJ" };
    let bytes = read_regular(path, MAX_MESH_BYTES, kind).map_err(err)?;
    let models = if is_ply {
        read_ply(&bytes)
    } else {
        read_obj(&bytes)
    }
    .map_err(err)?;
    drop(bytes);
    let at = DVec3::from_array(position);
    let mut tris = Vec::new();
    let mut normals = Vec::new();
    let mut smooth = true;
    for m in &models {
        let mesh = &m.mesh;
        let nv = mesh.positions.len() / 3;
        if mesh.indices.len() % 3 != 0 {
            return Err(err(format!("object {:?}: faces are not triangles", m.name)));
        }
        if let Some(&bad) = mesh.indices.iter().find(|&&i| i as usize >= nv) {
            return Err(err(format!(
                "object {:?}: vertex index {} is out of range ({nv} vertices)",
                m.name,
                bad as i64 + 1
            )));
        }
        if let Some(k) = mesh.positions.iter().position(|v| !v.is_finite()) {
            let why = if mesh.positions[k].is_nan() {
                "is not finite (NaN)"
            } else {
                "is out of range (beyond +-3.4e38, a 32-bit float's range)"
            };
            return Err(err(format!("vertex {} {why}", k / 3 + 1)));
        }
        let has_normals = mesh.normals.len() == mesh.positions.len()
            && mesh.normals.iter().all(|v| v.is_finite());
        smooth &= has_normals;
        let vertex = |i: u32| {
            let i = 3 * i as usize;
            let p = &mesh.positions[i..i + 3];
            at + scale * DVec3::new(p[0] as f64, p[1] as f64, p[2] as f64)
        };
        let normal = |i: u32| {
            let i = 3 * i as usize;
            let n = &mesh.normals[i..i + 3];
            // A negative scale mirrors the mesh; normals keep pointing outward.
            scale.signum() * DVec3::new(n[0] as f64, n[1] as f64, n[2] as f64)
        };
        for f in mesh.indices.chunks_exact(3) {
            tris.push([vertex(f[0]), vertex(f[1]), vertex(f[2])]);
            if has_normals {
                normals.push([normal(f[0]), normal(f[1]), normal(f[2])]);
            }
        }
    }
    if tris.is_empty() {
        return Err(err("the mesh has no triangles".into()));
    }
    let far = |v: &DVec3| v.abs().max_element() > MAX_MAGNITUDE;
    if let Some(k) = tris.iter().position(|t| t.iter().any(far)) {
        return Err(err(format!(
            "triangle {} lies beyond +-{MAX_MAGNITUDE:e} m once placed (position + scale x vertex)",
            k + 1
        )));
    }
    let normals = smooth.then_some(normals.as_slice());
    let mesh = Mesh::new(&tris, normals).ok_or_else(|| {
        err(format!(
            "all {} triangles are degenerate (zero area)",
            tris.len()
        ))
    })?;
    Ok(Arc::new(mesh))
}
