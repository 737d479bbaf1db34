//! glTF 2.0 output (`.glb` binary, `.gltf` with an embedded buffer).

use std::io::{self, Write};
use std::path::Path;

use base64::{engine::general_purpose::STANDARD as BASE64, Engine as _};
use glam::{DVec3, Vec3};
use gltf::json::{self as gj, validation::Checked, validation::USize64, Index};
use rayon::prelude::*;

use crate::error::IoError;
use crate::files::lowercase_extension;
use crate::material::Material;
use crate::mesh::write_atomically;
use crate::mesh::QuadMesh;

/// Writes `mesh` to `path` as glTF 2.0: binary `.glb`, or `.gltf` JSON with the buffer
/// embedded as a base64 data URI (one self-contained file either way).
///
/// Quads are split into two triangles along the diagonal from their first vertex (a
/// triangle of a quad stays in the quad's convex hull, as the papers' Proposition 2
/// requires); a triangle, written as a quad repeating its last vertex, stays one. Faces are grouped into one primitive per material, so each face keeps its
/// material's colour exactly; vertices on a boundary between materials are duplicated.
/// Per-vertex normals are the area-weighted average of the quad normals around the
/// vertex, over the whole mesh (so shading is continuous across materials). A mesh
/// without materials gets one grey diffuse material.
///
/// Scene: one node and mesh named `voxreg` holding every primitive; for a mesh whose
/// labels have names ([`QuadMesh::named_labels`]), a node `voxreg` whose children are
/// one node and mesh per primitive, named after the label of its faces' solid side
/// (the name as the file writes it; the material's name where that label has none), so
/// viewers list the segments by name.
///
/// Materials map to glTF's metallic-roughness model: base colour (sRGB converted to
/// linear), metalness, roughness, emission (`emissiveFactor` = colour x emission), and
/// transparency (`alphaMode: BLEND` when opacity < 1). Materials are double-sided, since
/// surfaces of label volumes may be open.
///
/// Written to a temporary file renamed onto `path` when complete; an inconsistent mesh
/// is refused with [`IoError::InvalidMesh`] before anything is created.
pub fn write_gltf(path: &Path, mesh: &QuadMesh) -> Result<(), IoError> {
    let binary = lowercase_extension(path).as_deref() != Some("gltf");
    write_atomically(path, mesh, check_gltf, |mesh, w| encode_gltf(mesh, binary, w))
}

fn check_gltf(mesh: &QuadMesh) -> Result<(), String> {
    if let Some(i) = mesh.positions.iter().position(|p| !p.as_vec3().is_finite()) {
        return Err(format!("vertex {i} at {} does not fit a glTF float", mesh.positions[i]));
    }
    if mesh.quads.is_empty() {
        return Err("no face to write".into());
    }
    Ok(())
}

/// Area-weighted vertex normals (each quad's normal is half the cross product of its
/// diagonals, whose length is the quad's area).
fn vertex_normals(mesh: &QuadMesh) -> Vec<Vec3> {
    let mut n = vec![DVec3::ZERO; mesh.positions.len()];
    for q in &mesh.quads {
        let p = q.map(|v| mesh.positions[v as usize]);
        let face = 0.5 * (p[2] - p[0]).cross(p[3] - p[1]);
        for v in q {
            n[*v as usize] += face;
        }
    }
    n.iter().map(|v| v.normalize_or(DVec3::Z).as_vec3()).collect()
}

/// One primitive's data: its vertices (indices into the mesh) and triangles.
struct Part {
    material: usize,
    /// The inner label its faces share, if they do.
    label: Option<u32>,
    vertices: Vec<u32>,
    triangles: Vec<u32>,
}

fn parts(mesh: &QuadMesh) -> Vec<Part> {
    let n_materials = mesh.materials.len().max(1);
    let mut faces: Vec<Vec<usize>> = vec![Vec::new(); n_materials];
    for f in 0..mesh.quads.len() {
        let m = mesh.face_materials.get(f).map_or(0, |&m| m as usize);
        faces[m].push(f);
    }
    let mut local = vec![u32::MAX; mesh.positions.len()];
    let mut out = Vec::new();
    for (m, fs) in faces.into_iter().enumerate().filter(|(_, fs)| !fs.is_empty()) {
        let mut vertices = Vec::new();
        let mut triangles = Vec::with_capacity(6 * fs.len());
        let mut id = |v: u32, vertices: &mut Vec<u32>| {
            if local[v as usize] == u32::MAX {
                local[v as usize] = vertices.len() as u32;
                vertices.push(v);
            }
            local[v as usize]
        };
        let inner = |f: &usize| mesh.face_labels[*f][0];
        let label = fs.first().map(inner).filter(|&l| fs.iter().all(|f| inner(f) == l));
        for f in fs {
            let [a, b, c, d] = mesh.quads[f].map(|v| id(v, &mut vertices));
            // A triangle is written as a quad repeating a vertex: one triangle, not a
            // degenerate second one.
            if d == c || d == a {
                triangles.extend([a, b, c]);
            } else {
                triangles.extend([a, b, c, a, c, d]);
            }
        }
        for &v in &vertices {
            local[v as usize] = u32::MAX;
        }
        out.push(Part { material: m, label, vertices, triangles });
    }
    out
}

/// `out` as one little-endian `f32 x 3` record of `at(v)` per vertex `v` of `vertices`,
/// written in parallel.
fn vec3_records(out: &mut [u8], vertices: &[u32], at: impl Fn(usize) -> Vec3 + Sync) {
    out.par_chunks_mut(12).zip(vertices.par_iter()).for_each(|(o, &v)| {
        for (chunk, c) in o.chunks_exact_mut(4).zip(at(v as usize).to_array()) {
            chunk.copy_from_slice(&c.to_le_bytes());
        }
    })
}

fn material_json(m: &Material) -> gj::Material {
    let [r, g, b] = m.linear_rgb();
    let opacity = m.opacity();
    let e = m.emission.clamp(0.0, 1.0);
    gj::Material {
        name: Some(m.name.clone()),
        alpha_mode: Checked::Valid(if opacity < 1.0 {
            gj::material::AlphaMode::Blend
        } else {
            gj::material::AlphaMode::Opaque
        }),
        double_sided: true,
        pbr_metallic_roughness: gj::material::PbrMetallicRoughness {
            base_color_factor: gj::material::PbrBaseColorFactor([r, g, b, opacity]),
            metallic_factor: gj::material::StrengthFactor(m.metallic.clamp(0.0, 1.0)),
            roughness_factor: gj::material::StrengthFactor(m.roughness.clamp(0.0, 1.0)),
            ..Default::default()
        },
        emissive_factor: gj::material::EmissiveFactor([r * e, g * e, b * e]),
        ..Default::default()
    }
}

fn encode_gltf(mesh: &QuadMesh, binary: bool, w: &mut dyn Write) -> io::Result<()> {
    let normals = vertex_normals(mesh);
    let parts = parts(mesh);
    let default_material = [Material::diffuse("default", [200, 200, 200, 255])];
    let materials: &[Material] = if mesh.materials.is_empty() { &default_material } else { &mesh.materials };

    let mut root = gj::Root {
        asset: gj::Asset { generator: Some("voxreg".into()), ..Default::default() },
        ..Default::default()
    };
    let material_ids: Vec<Index<gj::Material>> =
        materials.iter().map(|m| root.push(material_json(m))).collect();

    // One buffer: per part, positions and normals (f32 x 3), then u32 indices.
    let mut bin: Vec<u8> = Vec::new();
    let buffer = Index::new(0);
    // A view of `len` bytes appended to the buffer, written by `fill`.
    let view = |root: &mut gj::Root, bin: &mut Vec<u8>, len: usize, target, fill: &dyn Fn(&mut [u8])| {
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        let offset = bin.len();
        bin.resize(offset + len, 0);
        fill(&mut bin[offset..]);
        root.push(gj::buffer::View {
            buffer,
            byte_length: USize64::from(len),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            name: None,
            target: Some(Checked::Valid(target)),
            extensions: None,
            extras: Default::default(),
        })
    };
    let accessor = |view: Index<gj::buffer::View>, count: usize, component, type_, min, max| gj::Accessor {
        buffer_view: Some(view),
        byte_offset: None,
        count: USize64::from(count),
        component_type: Checked::Valid(gj::accessor::GenericComponentType(component)),
        extensions: None,
        extras: Default::default(),
        type_: Checked::Valid(type_),
        min,
        max,
        name: None,
        normalized: false,
        sparse: None,
    };
    let reserved: usize = parts.iter().map(|p| 24 * p.vertices.len() + 4 * p.triangles.len()).sum();
    bin.reserve_exact(reserved);
    let mut primitives = Vec::new();
    for part in &parts {
        let position = |v: usize| mesh.positions[v].as_vec3();
        let (lo, hi) =
            part.vertices.par_iter().map(|&v| (position(v as usize), position(v as usize))).reduce(
                || (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        let nv = part.vertices.len();
        let vp = view(&mut root, &mut bin, 12 * nv, gj::buffer::Target::ArrayBuffer, &|out| {
            vec3_records(out, &part.vertices, position)
        });
        let vn = view(&mut root, &mut bin, 12 * nv, gj::buffer::Target::ArrayBuffer, &|out| {
            vec3_records(out, &part.vertices, |v| normals[v])
        });
        let indices = |out: &mut [u8]| {
            out.par_chunks_mut(4)
                .zip(part.triangles.par_iter())
                .for_each(|(o, i)| o.copy_from_slice(&i.to_le_bytes()))
        };
        let vi = view(
            &mut root,
            &mut bin,
            4 * part.triangles.len(),
            gj::buffer::Target::ElementArrayBuffer,
            &indices,
        );
        let f32c = gj::accessor::ComponentType::F32;
        let ap = root.push(accessor(
            vp,
            nv,
            f32c,
            gj::accessor::Type::Vec3,
            Some(gj::Value::from(lo.to_array().to_vec())),
            Some(gj::Value::from(hi.to_array().to_vec())),
        ));
        let an = root.push(accessor(vn, nv, f32c, gj::accessor::Type::Vec3, None, None));
        let ai = root.push(accessor(
            vi,
            part.triangles.len(),
            gj::accessor::ComponentType::U32,
            gj::accessor::Type::Scalar,
            None,
            None,
        ));
        let mut attributes = std::collections::BTreeMap::new();
        attributes.insert(Checked::Valid(gj::mesh::Semantic::Positions), ap);
        attributes.insert(Checked::Valid(gj::mesh::Semantic::Normals), an);
        primitives.push(gj::mesh::Primitive {
            attributes,
            extensions: None,
            extras: Default::default(),
            indices: Some(ai),
            material: Some(material_ids[part.material]),
            mode: Checked::Valid(gj::mesh::Mode::Triangles),
            targets: None,
        });
    }
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    root.push(gj::Buffer {
        byte_length: USize64::from(bin.len()),
        name: None,
        uri: if binary {
            None
        } else {
            Some(format!("data:application/octet-stream;base64,{}", BASE64.encode(&bin)))
        },
        extensions: None,
        extras: Default::default(),
    });
    let new_mesh = |name: &str, primitives| gj::Mesh {
        extensions: None,
        extras: Default::default(),
        name: Some(name.into()),
        primitives,
        weights: None,
    };
    let node = if mesh.named_labels.is_empty() {
        let mesh_id = root.push(new_mesh("voxreg", primitives));
        root.push(gj::Node { mesh: Some(mesh_id), name: Some("voxreg".into()), ..Default::default() })
    } else {
        let mut children = Vec::new();
        for (part, primitive) in parts.iter().zip(primitives) {
            let named = part.label.and_then(|l| mesh.named_labels.iter().find(|n| n.label == l));
            let name = named.map_or(materials[part.material].name.as_str(), |n| n.name.as_str());
            let mesh_id = root.push(new_mesh(name, vec![primitive]));
            children.push(root.push(gj::Node {
                mesh: Some(mesh_id),
                name: Some(name.into()),
                ..Default::default()
            }));
        }
        root.push(gj::Node { children: Some(children), name: Some("voxreg".into()), ..Default::default() })
    };
    let scene = root.push(gj::Scene {
        extensions: None,
        extras: Default::default(),
        name: Some("voxreg".into()),
        nodes: vec![node],
    });
    root.scene = Some(scene);

    let json = gj::serialize::to_vec(&root).map_err(io::Error::other)?;
    if binary {
        let mut json = json;
        while json.len() % 4 != 0 {
            json.push(b' ');
        }
        let glb = gltf::binary::Glb {
            header: gltf::binary::Header { magic: *b"glTF", version: 2, length: 0 },
            json: json.into(),
            bin: Some(bin.into()),
        };
        glb.to_writer(crate::mesh::SmallWrites(w)).map_err(io::Error::other)
    } else {
        w.write_all(&json)
    }
}
