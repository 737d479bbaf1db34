//! The regularized surface as arrays: the whole mesh, one interface, or one region's
//! closed outward surface; writing them with the library's writers; mesh checks.

use std::path::PathBuf;
use std::sync::Arc;

use glam::DVec3;
use numpy::ndarray::Array2;
use numpy::{IntoPyArray, PyReadonlyArray2};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use voxreg_digisurf::{DigitalSurface, InterfaceId, PatchParams, RegionId};
use voxreg_io::{interface_name, write_mesh, Material, Palette, QuadMesh};

use crate::error::{no_panic, Error, Result};

/// Which part of the surface a mesh covers.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub(crate) enum Part {
    /// Every quad, in surfel order.
    All,
    /// One interface, oriented from its lower region to its higher one; with `true`,
    /// split at pinches so it is 2-manifold.
    Interface(u32, bool),
    /// One region's surface, oriented outward; with `true`, split at pinches so it is
    /// 2-manifold (closed regions become watertight).
    Region(u32, bool),
}

/// A mesh's arrays before they become numpy arrays (built without the GIL).
pub(crate) struct Arrays {
    vertices: Vec<f64>,
    quads: Vec<i64>,
    labels: Vec<u32>,
    colors: Option<Vec<u8>>,
    groups: Vec<(String, Vec<i64>)>,
    label_names: Vec<(u32, String)>,
}

impl Arrays {
    pub(crate) fn of(mesh: &QuadMesh) -> Self {
        let colors = (!mesh.materials.is_empty())
            .then(|| mesh.face_materials.iter().flat_map(|&m| mesh.materials[m as usize].color).collect());
        Arrays {
            vertices: mesh.positions.iter().flat_map(|p| p.to_array()).collect(),
            quads: mesh.quads.iter().flat_map(|q| q.map(i64::from)).collect(),
            labels: mesh.face_labels.iter().flatten().copied().collect(),
            colors,
            groups: mesh
                .groups
                .iter()
                .map(|g| (g.name.clone(), g.faces.iter().map(|&f| i64::from(f)).collect()))
                .collect(),
            label_names: mesh.named_labels.iter().map(|l| (l.label, l.name.clone())).collect(),
        }
    }

    /// `{"vertices": (n, 3) float64, "quads": (m, 4) int64, "labels": (m, 2) uint32,
    /// "colors": (m, 4) uint8 or None, "groups": [(name, faces int64)], "label_names":
    /// {label: name}}`, the vectors moved into numpy without a copy.
    pub(crate) fn into_dict(self, py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
        fn rows<T: numpy::Element>(py: Python<'_>, v: Vec<T>, width: usize) -> Bound<'_, PyAny> {
            let n = v.len() / width;
            Array2::from_shape_vec((n, width), v).expect("whole rows").into_pyarray(py).into_any()
        }
        let d = PyDict::new(py);
        d.set_item("vertices", rows(py, self.vertices, 3))?;
        d.set_item("quads", rows(py, self.quads, 4))?;
        d.set_item("labels", rows(py, self.labels, 2))?;
        d.set_item("colors", self.colors.map(|c| rows(py, c, 4)))?;
        let groups = PyList::empty(py);
        for (name, faces) in self.groups {
            groups.append((name, faces.into_pyarray(py)))?;
        }
        d.set_item("groups", groups)?;
        let names = PyDict::new(py);
        for (label, name) in self.label_names {
            names.set_item(label, name)?;
        }
        d.set_item("label_names", names)?;
        Ok(d)
    }
}

/// A part as Python names it: `("interface" | "region", index, manifold)`.
pub(crate) type PartSpec = (String, u32, bool);

/// An interface as Python sees it: its file name, its regions' smallest labels, its regions.
type InterfaceEntry = (String, (u32, u32), (u32, u32));

/// A regularized surface: the digital surface, its regularized positions and the input's
/// palette. Opaque to Python users; `voxreg.Mesh` keeps one to build sub-meshes and to
/// write files exactly as the CLI does.
#[pyclass(frozen, module = "voxreg._voxreg")]
pub(crate) struct Surface {
    pub(crate) surface: Arc<DigitalSurface>,
    pub(crate) positions: Arc<Vec<DVec3>>,
    pub(crate) palette: Option<Palette>,
}

impl Surface {
    pub(crate) fn part(kind: Option<PartSpec>) -> Result<Part> {
        Ok(match kind {
            None => Part::All,
            Some((k, i, m)) if k == "interface" => Part::Interface(i, m),
            Some((k, i, m)) if k == "region" => Part::Region(i, m),
            Some((k, _, _)) => {
                return Err(Error::parameter(format!("unknown part '{k}' (interface or region)")))
            }
        })
    }

    /// The quad mesh of `part`, coloured from the palette as the CLI colours it.
    pub(crate) fn quad_mesh(&self, part: Part) -> QuadMesh {
        let s = &self.surface;
        let mut mesh = match part {
            Part::All => QuadMesh::from_surface(s, &self.positions),
            Part::Interface(i, manifold) => QuadMesh::from_patch(
                s,
                &s.interface_patch(InterfaceId(i), &PatchParams { manifold }),
                &self.positions,
            ),
            Part::Region(r, manifold) => QuadMesh::from_patch(
                s,
                &s.region_patch(RegionId(r), &PatchParams { manifold }),
                &self.positions,
            ),
        };
        if let Some(palette) = &self.palette {
            // Colour transfer: each quad takes the colour and material of its solid voxel.
            mesh.assign_materials(palette);
        }
        mesh
    }

    pub(crate) fn arrays(&self, part: Part) -> Arrays {
        Arrays::of(&self.quad_mesh(part))
    }

    pub(crate) fn check_part(&self, part: Part) -> Result<()> {
        let (what, i, n) = match part {
            Part::All => return Ok(()),
            Part::Interface(i, _) => ("interface", i, self.surface.interfaces().len()),
            Part::Region(r, _) => ("region", r, self.surface.regions().len()),
        };
        if i as usize >= n {
            return Err(Error::parameter(format!("{what} {i} out of range (the surface has {n})")));
        }
        Ok(())
    }

    /// The smallest label of region `r` (the name the CLI's files use).
    fn label_of(&self, r: RegionId) -> u32 {
        self.surface.regions().labels(r).first().copied().unwrap_or(u32::MAX)
    }
}

#[pymethods]
impl Surface {
    /// The arrays of the whole mesh (`part=None`), of `("interface", i, manifold)` or of
    /// `("region", r, manifold)`: see `Arrays::into_dict`.
    #[pyo3(signature = (part=None))]
    fn mesh<'py>(&self, py: Python<'py>, part: Option<PartSpec>) -> PyResult<Bound<'py, PyDict>> {
        let part = Self::part(part)?;
        self.check_part(part)?;
        let arrays = py.detach(|| no_panic(|| Ok(self.arrays(part))))?;
        arrays.into_dict(py)
    }

    /// Writes the part to `path` (.obj, .ply, .glb or .gltf) with the library's writers.
    #[pyo3(signature = (path, part=None))]
    fn save(&self, py: Python<'_>, path: PathBuf, part: Option<PartSpec>) -> PyResult<()> {
        let part = Self::part(part)?;
        self.check_part(part)?;
        check_extension(&path)?;
        py.detach(|| no_panic(|| write_mesh(&path, &self.quad_mesh(part)).map_err(|e| Error::io(&e))))?;
        Ok(())
    }

    /// Per interface, in order: `(name, (a, b), (region_a, region_b))`, `a` and `b` the
    /// smallest labels of its lower and higher regions.
    fn interfaces(&self) -> Vec<InterfaceEntry> {
        let s = &self.surface;
        s.interfaces()
            .iter()
            .enumerate()
            .map(|(i, iface)| {
                let [a, b] = iface.regions;
                (interface_name(s, InterfaceId(i as u32)), (self.label_of(a), self.label_of(b)), (a.0, b.0))
            })
            .collect()
    }

    /// The region of `label`, or `None` if no voxel has it.
    fn region_of(&self, label: u32) -> Option<u32> {
        self.surface.regions().region_of(label).map(|r| r.0)
    }

    /// Each region's labels, in region order.
    fn region_labels(&self) -> Vec<Vec<u32>> {
        let regions = self.surface.regions();
        (0..regions.len() as u32).map(|r| regions.labels(RegionId(r)).to_vec()).collect()
    }

    /// The background region, if the volume has one.
    fn background_region(&self) -> Option<u32> {
        self.surface.regions().background().map(|r| r.0)
    }
}

/// Refuses a file name the mesh writers do not know, with the CLI's message.
fn check_extension(path: &std::path::Path) -> Result<()> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("obj" | "ply" | "glb" | "gltf" | "stl" | "vtp") => Ok(()),
        _ => Err(Error::new(
            crate::error::Kind::Io,
            format!(
                "{}: unsupported output format (expected .obj, .ply, .glb, .gltf, .stl or .vtp)",
                path.display()
            ),
        )),
    }
}

pub(crate) fn positions_of(vertices: &PyReadonlyArray2<'_, f64>) -> Result<Vec<DVec3>> {
    let v = vertices.as_array();
    if v.ncols() != 3 {
        return Err(Error::input(format!("vertices must be an (n, 3) array, got {:?}", v.shape())));
    }
    Ok(v.rows().into_iter().map(|r| DVec3::new(r[0], r[1], r[2])).collect())
}

pub(crate) fn quads_of(quads: &PyReadonlyArray2<'_, i64>, n: usize) -> Result<Vec<[u32; 4]>> {
    let q = quads.as_array();
    if q.ncols() != 4 {
        return Err(Error::input(format!("quads must be an (m, 4) array, got {:?}", q.shape())));
    }
    q.rows()
        .into_iter()
        .enumerate()
        .map(|(f, r)| {
            let mut out = [0u32; 4];
            for (o, &i) in out.iter_mut().zip(r.iter()) {
                *o = u32::try_from(i).ok().filter(|&i| (i as usize) < n).ok_or_else(|| {
                    Error::input(format!("quad {f} names vertex {i}, beyond the {n} vertices"))
                })?;
            }
            Ok(out)
        })
        .collect()
}

pub(crate) fn labels_of(labels: &PyReadonlyArray2<'_, u32>, m: usize) -> Result<Vec<[u32; 2]>> {
    let l = labels.as_array();
    if l.dim() != (m, 2) {
        return Err(Error::input(format!("labels must be an ({m}, 2) array, got {:?}", l.shape())));
    }
    Ok(l.rows().into_iter().map(|r| [r[0], r[1]]).collect())
}

/// The quality counts of a quad mesh (`voxreg check`): faces, self-intersecting face
/// pairs, faces with a non-finite vertex, folded quads, folded adjacent pairs, the first
/// intersecting pair, and the mean angle between adjacent quads
/// (`voxreg_quality::mean_adjacent_angle_deg`).
#[pyfunction]
pub(crate) fn check<'py>(
    py: Python<'py>,
    vertices: PyReadonlyArray2<'py, f64>,
    quads: PyReadonlyArray2<'py, i64>,
) -> PyResult<Bound<'py, PyDict>> {
    let positions = positions_of(&vertices)?;
    let quads = quads_of(&quads, positions.len())?;
    let (r, mean_angle) = py.detach(|| {
        no_panic(|| {
            Ok((
                voxreg_quality::check(&positions, &quads),
                voxreg_quality::mean_adjacent_angle_deg(&positions, &quads),
            ))
        })
    })?;
    let d = PyDict::new(py);
    d.set_item("faces", r.faces)?;
    d.set_item("intersecting_pairs", r.intersecting_pairs)?;
    d.set_item("invalid_faces", r.invalid_faces)?;
    d.set_item("folded_quads", r.folded_quads)?;
    d.set_item("folded_pairs", r.folded_pairs)?;
    d.set_item("first_intersection", r.first_intersection)?;
    d.set_item("clean", r.is_clean())?;
    d.set_item("mean_angle_deg", mean_angle)?;
    Ok(d)
}

/// Writes a mesh given as arrays (no interface groups; one material per distinct colour).
#[pyfunction]
#[pyo3(signature = (path, vertices, quads, labels, colors=None))]
pub(crate) fn write_arrays(
    py: Python<'_>,
    path: PathBuf,
    vertices: PyReadonlyArray2<'_, f64>,
    quads: PyReadonlyArray2<'_, i64>,
    labels: PyReadonlyArray2<'_, u32>,
    colors: Option<PyReadonlyArray2<'_, u8>>,
) -> PyResult<()> {
    check_extension(&path)?;
    let positions = positions_of(&vertices)?;
    let quads = quads_of(&quads, positions.len())?;
    let face_labels = labels_of(&labels, quads.len())?;
    let mut mesh = QuadMesh { positions, quads, face_labels, ..Default::default() };
    if let Some(colors) = colors {
        let (materials, face_materials) = colors_materials(&colors, mesh.quads.len())?;
        mesh.materials = materials;
        mesh.face_materials = face_materials;
    }
    py.detach(|| no_panic(|| write_mesh(&path, &mesh).map_err(|e| Error::io(&e))))?;
    Ok(())
}

/// Per-face colours, (m, 3 | 4) uint8, as materials: one per distinct colour, and each
/// face's material.
pub(crate) fn colors_materials(
    colors: &PyReadonlyArray2<'_, u8>,
    faces: usize,
) -> Result<(Vec<Material>, Vec<u32>)> {
    let c = colors.as_array();
    if c.nrows() != faces || !(c.ncols() == 3 || c.ncols() == 4) {
        return Err(Error::input(format!("colors must be an ({faces}, 3 or 4) array, got {:?}", c.shape())));
    }
    let rgba: Vec<[u8; 4]> =
        c.rows().into_iter().map(|r| [r[0], r[1], r[2], if r.len() == 4 { r[3] } else { 255 }]).collect();
    let mut distinct = rgba.clone();
    distinct.sort_unstable();
    distinct.dedup();
    let materials =
        distinct.iter().enumerate().map(|(i, &c)| Material::diffuse(format!("color_{i}"), c)).collect();
    let face_materials = rgba.iter().map(|c| distinct.binary_search(c).unwrap_or(0) as u32).collect();
    Ok((materials, face_materials))
}

/// A binary PLY file written in parts (`voxreg_io::PlyParts`: `write_ply`'s file, the
/// vertices and faces written at their indices in any order): the chunked merge's
/// per-label files. `finish` renames it onto its path once complete; `discard`, or the
/// object's end, removes it.
#[pyclass(module = "voxreg._voxreg")]
pub(crate) struct PlyParts(Option<voxreg_io::PlyParts>);

impl PlyParts {
    fn open(&mut self) -> Result<&mut voxreg_io::PlyParts> {
        self.0.as_mut().ok_or_else(|| Error::input("the PLY file is already finished or discarded"))
    }
}

#[pymethods]
impl PlyParts {
    #[new]
    fn new(path: PathBuf, vertices: usize, faces: usize) -> PyResult<Self> {
        Ok(Self(Some(voxreg_io::PlyParts::create(&path, vertices, faces).map_err(|e| Error::io(&e))?)))
    }

    /// Writes `vertices` (n, 3) as vertices `first..first + n`.
    fn write_vertices(
        &mut self,
        py: Python<'_>,
        first: usize,
        vertices: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<()> {
        let positions = positions_of(&vertices)?;
        let w = self.open()?;
        py.detach(|| no_panic(|| w.write_vertices(first, &positions).map_err(|e| Error::io(&e))))?;
        Ok(())
    }

    /// Writes `quads` (m, 4) with their `labels` (m, 2) as faces `first..first + m`.
    fn write_faces(
        &mut self,
        py: Python<'_>,
        first: usize,
        quads: PyReadonlyArray2<'_, i64>,
        labels: PyReadonlyArray2<'_, u32>,
    ) -> PyResult<()> {
        let quads = quads_of(&quads, u32::MAX as usize)?;
        let labels = labels_of(&labels, quads.len())?;
        let w = self.open()?;
        py.detach(|| no_panic(|| w.write_faces(first, &quads, &labels).map_err(|e| Error::io(&e))))?;
        Ok(())
    }

    /// Renames the complete file onto its path.
    fn finish(&mut self, py: Python<'_>) -> PyResult<()> {
        let w = self.0.take().ok_or_else(|| Error::input("the PLY file is already finished or discarded"))?;
        py.detach(|| no_panic(|| w.finish().map_err(|e| Error::io(&e))))?;
        Ok(())
    }

    /// Removes the unfinished file.
    fn discard(&mut self) {
        self.0 = None;
    }
}
