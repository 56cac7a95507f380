//! Reading a mesh object's OBJ file (via `tobj`) or PLY file (via `ply-rs-bw`), triangulated, into
//! world-space triangles, validated: every error names the object's field and the file.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::DVec3;

use super::{MAX_MAGNITUDE, V3};
use crate::error::{Error, Result};
use crate::render::mesh::Mesh;

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

/// A PLY file's `vertex` (`x`, `y`, `z`, and `nx`, `ny`, `nz` when every vertex has them) and `face`
/// (`vertex_indices` or `vertex_index`, polygons split into fans) elements in `tobj`'s form, so that
/// both formats share one validation.
fn read_ply(path: &Path) -> std::result::Result<Vec<tobj::Model>, String> {
    use ply_rs_bw::ply::Property as P;
    let file = std::fs::File::open(path).map_err(|_| "cannot open the PLY file".to_string())?;
    let parser = ply_rs_bw::parser::Parser::<ply_rs_bw::ply::DefaultElement>::new();
    let ply = parser
        .read_ply(&mut std::io::BufReader::new(file))
        .map_err(|e| format!("not a valid PLY file ({e})"))?;
    let number = |p: Option<&P>| -> Option<f32> {
        Some(match *p? {
            P::Float(v) => v,
            P::Double(v) => v as f32,
            P::Char(v) => v as f32,
            P::UChar(v) => v as f32,
            P::Short(v) => v as f32,
            P::UShort(v) => v as f32,
            P::Int(v) => v as f32,
            P::UInt(v) => v as f32,
            _ => return None,
        })
    };
    let vertices = ply.payload.get("vertex").map_or(&[][..], Vec::as_slice);
    let mut mesh = tobj::Mesh::default();
    for (k, v) in vertices.iter().enumerate() {
        for axis in ["x", "y", "z"] {
            let c = number(v.get(axis))
                .ok_or_else(|| format!("vertex {} has no number {axis:?}", k + 1))?;
            mesh.positions.push(c);
        }
        if let (Some(x), Some(y), Some(z)) = (
            number(v.get("nx")),
            number(v.get("ny")),
            number(v.get("nz")),
        ) {
            mesh.normals.extend([x, y, z]);
        }
    }
    if mesh.normals.len() != mesh.positions.len() {
        mesh.normals.clear();
    }
    let faces = ply.payload.get("face").map_or(&[][..], Vec::as_slice);
    for (k, f) in faces.iter().enumerate() {
        let list = f.get("vertex_indices").or_else(|| f.get("vertex_index"));
        let idx: Vec<i64> = match list {
            Some(P::ListChar(l)) => l.iter().map(|&i| i as i64).collect(),
            Some(P::ListUChar(l)) => l.iter().map(|&i| i as i64).collect(),
            Some(P::ListShort(l)) => l.iter().map(|&i| i as i64).collect(),
            Some(P::ListUShort(l)) => l.iter().map(|&i| i as i64).collect(),
            Some(P::ListInt(l)) => l.iter().map(|&i| i as i64).collect(),
            Some(P::ListUInt(l)) => l.iter().map(|&i| i as i64).collect(),
            _ => return Err(format!("face {} has no integer list vertex_indices", k + 1)),
        };
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

/// Load the OBJ or PLY (by extension) at `path`, placed at `position` and scaled by `scale`.
pub fn load(field: &str, path: &Path, position: V3, scale: f64) -> Result<Arc<Mesh>> {
    let shown = path.display();
    let err = |m: String| Error::scene(field, format!("{shown}: {m}"));
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let is_ply = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ply"));
    let models = if is_ply {
        read_ply(path).map_err(err)?
    } else {
        // Materials (.mtl) are not used: the scene gives the material.
        tobj::load_obj(path, &opts)
            .map_err(|e| match e {
                tobj::LoadError::OpenFileFailed => err("cannot open the OBJ file".into()),
                tobj::LoadError::ReadError => err("cannot read the OBJ file".into()),
                e => err(format!("not a valid OBJ file ({e})")),
            })?
            .0
    };
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
            return Err(err(format!(
                "vertex {} is not finite ({})",
                k / 3 + 1,
                mesh.positions[k]
            )));
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
