//! What the page draws of one surface: its quads, face groups and colours, the staircase
//! positions, and the arrays the server sends as little-endian binary.

use std::path::Path;

use serde::Serialize;
use voxreg_digisurf::{BlockVolume, DigitalSurface, LabelVolume};
use voxreg_io::{interface_name, InputError, InputOptions, Palette, QuadMesh};
use voxreg_regularize::{Overrides, Preset};

/// The voxels of an input: every voxel stored, or (a MagicaVoxel scene of models far
/// apart) blocks in a lattice of background, whose surface is that of the volume made
/// dense, id for id, for the memory and time of the blocks alone.
#[derive(Clone, Debug)]
pub enum Volume {
    /// Every voxel stored.
    Dense(LabelVolume),
    /// The models' own boxes ([`voxreg_io::read_sparse_input`]).
    Blocks(BlockVolume),
}

impl From<LabelVolume> for Volume {
    fn from(v: LabelVolume) -> Volume {
        Volume::Dense(v)
    }
}

impl From<BlockVolume> for Volume {
    fn from(v: BlockVolume) -> Volume {
        Volume::Blocks(v)
    }
}

impl Volume {
    /// Number of voxels of the lattice along x, y and z.
    pub fn dims(&self) -> [usize; 3] {
        match self {
            Volume::Dense(v) => v.dims(),
            Volume::Blocks(v) => v.dims(),
        }
    }
}

/// Reads an input as `voxreg regularize` does ([`voxreg_io::read_input`] with `options`),
/// from `bytes` where given (an upload: `path` only names it, nothing else is read): as
/// blocks where it is a MagicaVoxel scene of models far apart
/// ([`voxreg_io::read_sparse_input`]), so that such a scene opens within the memory of its
/// models' boxes, else dense. Returns the volume and the file's palette, if any.
pub fn read_volume(
    path: &Path,
    bytes: Option<&[u8]>,
    options: &InputOptions<'_>,
) -> Result<(Volume, Option<Palette>), InputError> {
    if let Some(scene) = voxreg_io::read_sparse_input(path, bytes, options)? {
        return Ok((Volume::Blocks(scene.volume), Some(scene.palette)));
    }
    let input = match bytes {
        Some(b) => voxreg_io::read_input_bytes(b, path, options)?,
        None => voxreg_io::read_input(path, options)?,
    };
    Ok((Volume::Dense(input.volume), input.palette))
}

/// An input the viewer shows: the volume, its palette, and the parameters to start from.
#[derive(Clone, Debug)]
pub struct Loaded {
    /// The file name shown on the page and in the equivalent command line.
    pub name: String,
    /// The labelled volume, dense or as blocks ([`read_volume`]).
    pub volume: Volume,
    /// The `.vox` palette (colours of the labels), if any.
    pub palette: Option<Palette>,
    /// The preset of the first solve.
    pub preset: Preset,
    /// The options applied over it (the command line's), kept by the panel's solves
    /// while the preset stays.
    pub overrides: Overrides,
}

/// A group of faces the page lists, with a visibility toggle and a colour: the interfaces
/// of a multi-region surface, or the labels (colours) of a single-interface one.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub(crate) struct Group {
    pub(crate) name: String,
    pub(crate) color: [u8; 3],
    pub(crate) faces: usize,
}

/// The static part of what the page draws (per surface).
#[derive(Debug)]
pub(crate) struct Model {
    pub(crate) quads: Vec<u8>,
    pub(crate) face_groups: Vec<u8>,
    pub(crate) face_colors: Vec<u8>,
    pub(crate) staircase: Vec<u8>,
    pub(crate) groups: Vec<Group>,
    pub(crate) vertices: usize,
    pub(crate) faces: usize,
    /// The labels the groups stand for, when the groups are labels (a single-interface
    /// surface); `None` when they are the interfaces, in interface order.
    pub(crate) group_labels: Option<Vec<u32>>,
}

/// The colour the page gives a face whose inner label is `label`: the palette's, else
/// [`label_color`].
pub(crate) fn face_color(palette: Option<&Palette>, label: u32) -> [u8; 3] {
    match palette.and_then(|p| p.material(label)) {
        Some(m) => [m.color[0], m.color[1], m.color[2]],
        None => label_color(label),
    }
}

/// A distinct colour per label without a palette: hues spaced by the golden angle.
pub(crate) fn label_color(label: u32) -> [u8; 3] {
    let h = (f64::from(label) * 0.618_033_988_75 + 0.1).fract() * 6.0;
    let (s, v) = (0.55, 0.9);
    let c = v * s;
    let x = c * (1.0 - (h % 2.0 - 1.0).abs());
    let (r, g, b) = match h as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = v - c;
    [r, g, b].map(|t| ((t + m) * 255.0).round() as u8)
}

/// `values` as little-endian `f32`s.
pub(crate) fn f32_bytes(values: impl IntoIterator<Item = f64>) -> Vec<u8> {
    values.into_iter().flat_map(|v| (v as f32).to_le_bytes()).collect()
}

impl Model {
    /// Everything the page needs to draw the surface, in one response (`/api/surface`):
    /// the face and vertex counts (`u32`), then the quads (4 `u32` vertex ids per face),
    /// the face groups (`u32`), the staircase positions (3 `f32` per vertex) and the face
    /// colours (3 `u8` per face), little-endian; the colours last so that every `u32` and
    /// `f32` array starts 4-byte aligned.
    pub(crate) fn surface_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(
            8 + self.quads.len() + self.face_groups.len() + self.staircase.len() + self.face_colors.len(),
        );
        out.extend_from_slice(&(self.faces as u32).to_le_bytes());
        out.extend_from_slice(&(self.vertices as u32).to_le_bytes());
        for part in [&self.quads, &self.face_groups, &self.staircase, &self.face_colors] {
            out.extend_from_slice(part);
        }
        out
    }

    pub(crate) fn new(surface: &DigitalSurface, palette: Option<&Palette>) -> Model {
        let surfels = surface.surfels();
        let color_of = |label: u32| face_color(palette, label);
        // The solid side of a face is its inner label (the background's region is last).
        let mut face_groups = vec![0u32; surfels.len()];
        let mut groups = Vec::new();
        let mut group_labels = None;
        if surface.interfaces().len() > 1 {
            for (i, interface) in surface.interfaces().iter().enumerate() {
                let first = interface.surfels.first().map(|s| surfels[s.index()].labels[0]).unwrap_or(0);
                groups.push(Group {
                    name: interface_name(surface, voxreg_digisurf::InterfaceId(i as u32)),
                    color: color_of(first),
                    faces: interface.surfels.len(),
                });
                for s in &interface.surfels {
                    face_groups[s.index()] = i as u32;
                }
            }
        } else {
            let mut labels: Vec<u32> = surfels.iter().map(|s| s.labels[0]).collect();
            labels.sort_unstable();
            labels.dedup();
            let mut counts = vec![0usize; labels.len()];
            for (f, s) in surfels.iter().enumerate() {
                let g = labels.binary_search(&s.labels[0]).unwrap_or(0);
                face_groups[f] = g as u32;
                counts[g] += 1;
            }
            groups = labels
                .iter()
                .zip(counts)
                .map(|(&l, faces)| Group { name: format!("label_{l}"), color: color_of(l), faces })
                .collect();
            group_labels = Some(labels);
        }
        let face_colors = surfels.iter().flat_map(|s| color_of(s.labels[0])).collect();
        Model {
            quads: surfels.iter().flat_map(|s| s.vertices.map(|v| v.0)).flat_map(u32::to_le_bytes).collect(),
            face_groups: face_groups.iter().flat_map(|g| g.to_le_bytes()).collect(),
            face_colors,
            staircase: f32_bytes(surface.positions().iter().flat_map(|p| p.to_array())),
            groups,
            vertices: surface.num_vertices(),
            faces: surfels.len(),
            group_labels,
        }
    }

    /// The group of each face of `mesh`, a simplification of this surface's mesh
    /// ([`QuadMesh::from_surface`]: one mesh group per interface, in interface order, which
    /// the simplifier keeps): the interface's group, or the inner label's.
    pub(crate) fn face_groups_of(&self, mesh: &QuadMesh) -> Vec<u32> {
        match &self.group_labels {
            Some(labels) => {
                mesh.face_labels.iter().map(|l| labels.binary_search(&l[0]).unwrap_or(0) as u32).collect()
            }
            None => {
                let mut out = vec![0u32; mesh.quads.len()];
                for (g, group) in mesh.groups.iter().enumerate() {
                    for &f in &group.faces {
                        if let Some(slot) = out.get_mut(f as usize) {
                            *slot = g as u32;
                        }
                    }
                }
                out
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn label_colours_are_distinct_and_bright() {
        let colours: Vec<_> = (0..16).map(label_color).collect();
        for (i, a) in colours.iter().enumerate() {
            assert!(a.iter().any(|&c| c > 150), "{a:?}");
            for b in &colours[..i] {
                let d: i32 = a.iter().zip(b).map(|(&x, &y)| (i32::from(x) - i32::from(y)).abs()).sum();
                assert!(d > 20, "{a:?} {b:?}");
            }
        }
    }

    #[test]
    fn two_labels_give_their_interfaces_as_groups() {
        // Labels 1 and 2 side by side in background 0: interfaces 1|2, 1|0, 2|0.
        let volume = LabelVolume::from_fn([4, 2, 2], |[x, _, _]| if x < 2 { 1 } else { 2 });
        let surface = DigitalSurface::new(&volume, &voxreg_digisurf::RegionMap::per_label()).unwrap();
        let m = Model::new(&surface, None);
        assert_eq!(m.groups.len(), 3);
        assert_eq!(m.groups.iter().map(|g| g.faces).sum::<usize>(), m.faces);
        assert_eq!(m.quads.len(), 16 * m.faces);
        assert_eq!(m.staircase.len(), 12 * m.vertices);
        assert_eq!(m.face_colors.len(), 3 * m.faces);
        // Solid: one interface, so the groups are the labels.
        let surface = DigitalSurface::new(&volume, &voxreg_digisurf::RegionMap::single_solid()).unwrap();
        let m = Model::new(&surface, None);
        let names: Vec<_> = m.groups.iter().map(|g| g.name.as_str()).collect();
        assert_eq!(names, ["label_1", "label_2"]);
    }

    #[test]
    fn a_mesh_of_the_surface_gets_the_surfaces_groups() {
        // The mesh written of a surface (and its simplifications: the same groups, labels
        // and faces' labels) is grouped as the surface's faces are.
        let volume = LabelVolume::from_fn([4, 2, 2], |[x, _, _]| if x < 2 { 1 } else { 2 });
        for regions in [voxreg_digisurf::RegionMap::per_label(), voxreg_digisurf::RegionMap::single_solid()] {
            let surface = DigitalSurface::new(&volume, &regions).unwrap();
            let m = Model::new(&surface, None);
            let mesh = QuadMesh::from_surface(&surface, surface.positions().as_slice());
            let groups: Vec<u8> = m.face_groups_of(&mesh).iter().flat_map(|g| g.to_le_bytes()).collect();
            assert_eq!(groups, m.face_groups);
        }
    }
}
