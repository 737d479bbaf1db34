//! MagicaVoxel `.vox` volumes, parsed by the `dot_vox` crate.

use std::path::Path;

use dot_vox::{DotVoxData, Model, SceneNode};
use glam::DVec3;
use ndarray::{Array3, ShapeBuilder};
use voxreg_digisurf::{Block, BlockVolume, LabelVolume};

use crate::error::IoError;
use crate::files::{checked_voxel_count, read_file};
use crate::loaded::LoadedVolume;
use crate::material::apply_vox_material;
use crate::material::Palette;

/// Scene graphs nested deeper than this are refused (they are malformed or cyclic).
const MAX_SCENE_DEPTH: usize = 64;
/// At most this many scene-graph nodes are visited: groups listing the same child many
/// times, nested, would otherwise expand exponentially.
const MAX_SCENE_VISITS: usize = 1 << 20;
/// At most this many model instances are placed.
pub const VOX_MAX_INSTANCES: usize = 1 << 16;
/// At most this many voxels are placed, over all instances.
pub const VOX_MAX_PLACED_VOXELS: u64 = 1 << 28;

/// Reads a MagicaVoxel `.vox` file as a labeled volume with its palette.
///
/// See [`read_vox_bytes`] for the mapping of colours to labels and of models to space.
pub fn read_vox(path: &Path) -> Result<LoadedVolume, IoError> {
    read_vox_bytes(&read_file(path)?, path)
}

/// Reads a MagicaVoxel `.vox` file held in memory; `path` only names the file in errors.
///
/// **Labels.** A voxel of MagicaVoxel colour index `c` (`1..=255`) gets label `c`;
/// label `0` is empty space (the background), and so are voxels of colour index `0`.
/// A colour index past the end of a short `RGBA` palette is an [`IoError::Format`]. The palette is returned as 256 RGBA
/// entries indexed by label, entry `0` transparent black.
///
/// **Names.** A `MATL` chunk with a `_name` property names its colour's label
/// ([`Palette::names`]); MagicaVoxel itself writes none. Layer and node names are not
/// label names (a layer holds models of many colours, a colour spans layers) and are
/// not read.
///
/// **Space.** MagicaVoxel coordinates `x, y, z` (`z` up) are the volume's `[x, y, z]`,
/// with spacing `1`, and the origin is chosen so that lattice corners fall on integer
/// MagicaVoxel coordinates: voxel `[x, y, z]` fills the unit cube from `(x, y, z)` to
/// `(x + 1, y + 1, z + 1)`.
///
/// - A file with one model gives a volume of exactly the model's size, origin `0.5`
///   (the model's own transform, if any, is ignored).
/// - A file with several models places each shape of the scene graph (format 200:
///   nested groups, instancing) by the composition of the transforms above it,
///   MagicaVoxel's way: a model pivots about `floor(size / 2)`, is rotated or mirrored
///   by the `_r` byte (a signed axis permutation) and translated by `_t`; everything
///   lands in one volume spanning all models, where overlapping models let the later one
///   win. Hidden nodes and nodes on hidden layers are skipped. Only the first frame of
///   animated transforms and the first model of animated shapes are used. A multi-model
///   file without a scene graph (animation frames) gives its model 0, the first frame.
/// - [`VoxOptions::model`] picks one model by index instead, placed as a single-model
///   file is ([`read_vox_bytes_with`]; `voxreg --model K`).
///
/// Files that `dot_vox` cannot parse, with no model, with a voxel outside its model's
/// size, or with a `_t` translation that is not three integers are [`IoError::Format`]
/// errors; scene graphs placing more than [`VOX_MAX_INSTANCES`] instances or
/// [`VOX_MAX_PLACED_VOXELS`] voxels are [`IoError::Unsupported`] (checked while
/// walking the graph, before any volume is allocated); volumes above
/// [`MAX_VOXELS`](crate::files::MAX_VOXELS) are [`IoError::TooLarge`], and those above the
/// memory budget [`IoError::OverBudget`].
pub fn read_vox_bytes(bytes: &[u8], path: &Path) -> Result<LoadedVolume, IoError> {
    read_vox_bytes_with(bytes, path, &VoxOptions::default())
}

/// How [`read_vox_bytes_with`] reads a file of several models.
#[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
pub struct VoxOptions {
    /// Read only this model (0-based, in file order), alone in its own lattice, ignoring
    /// the scene graph. Default: `None` (the scene graph; model 0 without one).
    pub model: Option<usize>,
}

/// The size of every model of a `.vox` file held in memory, in file order (for
/// `voxreg info` and choosing [`VoxOptions::model`]).
pub fn vox_model_sizes(bytes: &[u8], path: &Path) -> Result<Vec<[u32; 3]>, IoError> {
    let data = dot_vox::load_bytes(bytes)
        .map_err(|e| IoError::format(path, format!("not a valid MagicaVoxel .vox file (dot_vox: {e})")))?;
    Ok(data.models.iter().map(|m| [m.size.x, m.size.y, m.size.z]).collect())
}

/// The parsed file and the model instances it places, in scene-graph order.
fn placed(bytes: &[u8], path: &Path, options: &VoxOptions) -> Result<(DotVoxData, Vec<Instance>), IoError> {
    let data = dot_vox::load_bytes(bytes)
        .map_err(|e| IoError::format(path, format!("not a valid MagicaVoxel .vox file (dot_vox: {e})")))?;
    // MagicaVoxel models are at most 256 voxels per axis; a larger declared size is a
    // corrupt (or hostile) file, refused before allocating anything for it.
    if let Some((i, m)) = data.models.iter().enumerate().find(|(_, m)| model_size(m).iter().any(|&s| s > 256))
    {
        return Err(IoError::format(
            path,
            format!(
                "model {i} declares size {}x{}x{}: MagicaVoxel models are at most 256 per axis",
                m.size.x, m.size.y, m.size.z
            ),
        ));
    }
    // One model alone: exactly its own lattice, whatever its transform.
    let alone = |model: usize| {
        let size = model_size(&data.models[model]);
        let placement = Placement { translation: size.map(|s| s / 2), ..Placement::IDENTITY };
        vec![Instance { model, placement }]
    };
    let instances = match (data.models.len(), options.model) {
        (0, _) => return Err(IoError::format(path, "the .vox file holds no model")),
        (n, Some(k)) if k >= n => {
            return Err(IoError::format(
                path,
                format!("model {k} does not exist: the file has {n} model(s), 0 to {}", n - 1),
            ))
        }
        (_, Some(k)) => alone(k),
        (1, None) => alone(0),
        // Scene-graph chunks that `dot_vox` skipped (it drops a chunk it cannot parse):
        // placing the models without them would silently drop models.
        (_, None) if scene_chunks(bytes) != data.scenes.len() => {
            return Err(IoError::format(
                path,
                format!(
                    "corrupt scene graph: {} of its {} nTRN, nGRP and nSHP chunks could not be read",
                    scene_chunks(bytes).saturating_sub(data.scenes.len()),
                    scene_chunks(bytes)
                ),
            ))
        }
        // Models without a scene graph to place them: animation frames; the first.
        (_, None) if data.scenes.is_empty() => alone(0),
        (_, None) => scene_instances(&data, path)?,
    };
    Ok((data, instances))
}

/// [`read_vox_bytes`] with the choice of model of `options`.
pub fn read_vox_bytes_with(bytes: &[u8], path: &Path, options: &VoxOptions) -> Result<LoadedVolume, IoError> {
    let (data, instances) = placed(bytes, path, options)?;
    let boxes: Vec<Bounds> =
        instances.iter().map(|inst| inst.placement.bounds(model_size(&data.models[inst.model]))).collect();
    let (lo, hi) = enclosing(&boxes);
    let dims = [0, 1, 2].map(|k| (hi[k] - lo[k]).max(0) as u64);
    let count = checked_voxel_count(path, dims, 4)?;
    let dims = dims.map(|d| d as usize);

    let empty = empty_voxels(bytes, data.models.len());
    let mut labels = vec![0u32; count];
    for inst in &instances {
        place(&data, path, inst, &empty, (lo, dims), &mut labels)?;
    }
    let volume = LabelVolume::from_x_fastest(dims, labels)
        .and_then(|v| v.with_origin(DVec3::new(lo[0] as f64, lo[1] as f64, lo[2] as f64) + 0.5))
        .map_err(|source| IoError::Volume { path: path.to_path_buf(), source })?;
    Ok(LoadedVolume { volume, palette: Some(palette(&data)), units: None })
}

/// A `.vox` scene read as blocks ([`read_vox_scene_bytes`]).
#[derive(Clone, Debug)]
pub struct VoxScene {
    /// The scene's lattice (the bounding box of its models, placed as
    /// [`read_vox_bytes`] places them), with one block per cluster of models.
    pub volume: BlockVolume,
    /// The palette, as [`read_vox_bytes`] returns it.
    pub palette: Palette,
}

impl VoxScene {
    /// Whether the blocks hold less than half of the lattice's voxels: a scene whose
    /// dense volume would be mostly empty space.
    pub fn is_sparse(&self) -> bool {
        (self.volume.block_voxels() as u128) * 2 < self.volume.len()
    }
}

/// Reads a MagicaVoxel `.vox` file held in memory as [`read_vox_bytes_with`] does, into
/// blocks built from the models' own boxes instead of one volume over their bounding
/// box: models far apart cost their own voxels, not the empty space between them.
///
/// **Blocks.** The models' boxes are grouped into clusters: two boxes closer than one
/// empty voxel along every axis (touching or overlapping) are in one cluster, and so are
/// two clusters whose boxes are; each cluster becomes one dense [`Block`] over its box,
/// filled with its models in scene-graph order (a later model overwrites an earlier one
/// where they overlap, as in [`read_vox_bytes`]). The clusters' boxes are then at least
/// one voxel apart, as [`BlockVolume`] requires, and [`BlockVolume::to_dense`] is the
/// volume of [`read_vox_bytes_with`].
///
/// Errors are those of [`read_vox_bytes_with`], except that the blocks' voxels, not the
/// bounding box's, are held against [`MAX_VOXELS`](crate::files::MAX_VOXELS) and the memory
/// budget, and that lattices of more than `2^31` voxels along an axis are
/// [`IoError::TooLarge`].
pub fn read_vox_scene_bytes(bytes: &[u8], path: &Path, options: &VoxOptions) -> Result<VoxScene, IoError> {
    let (data, instances) = placed(bytes, path, options)?;
    let boxes: Vec<Bounds> =
        instances.iter().map(|inst| inst.placement.bounds(model_size(&data.models[inst.model]))).collect();
    let (lo, hi) = enclosing(&boxes);
    let dims = [0, 1, 2].map(|k| (hi[k] - lo[k]).max(0) as u64);
    if dims.iter().any(|&d| d > 1 << 31) {
        return Err(IoError::TooLarge { path: path.to_path_buf(), dims, limit: crate::files::MAX_VOXELS });
    }
    let (cluster_of, cluster_boxes) = clusters(&boxes);
    let sizes: Vec<[u64; 3]> =
        cluster_boxes.iter().map(|(a, b)| [0, 1, 2].map(|k| (b[k] - a[k]) as u64)).collect();
    let total: u128 = sizes.iter().map(|s| s.iter().map(|&d| u128::from(d)).product::<u128>()).sum();
    if total > u128::from(crate::files::MAX_VOXELS) {
        return Err(IoError::TooLarge { path: path.to_path_buf(), dims, limit: crate::files::MAX_VOXELS });
    }
    let what = format!(
        "{} blocks of {total} voxels in all (a scene of {}x{}x{})",
        sizes.len(),
        dims[0],
        dims[1],
        dims[2]
    );
    crate::limits::check_memory(path, &what, total * 4)?;

    let empty = empty_voxels(bytes, data.models.len());
    let mut blocks = Vec::with_capacity(cluster_boxes.len());
    for (c, &(a, _)) in cluster_boxes.iter().enumerate() {
        let size = sizes[c].map(|d| d as usize);
        let mut labels = vec![0u32; size.iter().product()];
        for (inst, _) in instances.iter().zip(&cluster_of).filter(|(_, &k)| k == c) {
            place(&data, path, inst, &empty, (a, size), &mut labels)?;
        }
        let labels = Array3::from_shape_vec((size[0], size[1], size[2]).f(), labels)
            .map_err(|e| IoError::format(path, e.to_string()))?;
        blocks.push(Block { offset: [0, 1, 2].map(|k| (a[k] - lo[k]) as usize), labels });
    }
    let volume = BlockVolume::new(dims.map(|d| d as usize), blocks, 0)
        .and_then(|v| v.with_origin(DVec3::new(lo[0] as f64, lo[1] as f64, lo[2] as f64) + 0.5))
        .map_err(|source| IoError::Volume { path: path.to_path_buf(), source })?;
    Ok(VoxScene { volume, palette: palette(&data) })
}

/// A box of the lattice, `[lo, hi)`, in MagicaVoxel coordinates.
type Bounds = ([i64; 3], [i64; 3]);

/// The box enclosing `boxes`.
fn enclosing(boxes: &[Bounds]) -> Bounds {
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for (a, b) in boxes {
        for k in 0..3 {
            lo[k] = lo[k].min(a[k]);
            hi[k] = hi[k].max(b[k]);
        }
    }
    (lo, hi)
}

/// Whether two boxes are closer than one empty voxel along every axis (they overlap,
/// touch, or meet at an edge or a corner).
fn near(a: &Bounds, b: &Bounds) -> bool {
    (0..3).all(|k| b.0[k] <= a.1[k] && a.0[k] <= b.1[k])
}

/// Groups `boxes` into clusters whose boxes are at least one voxel apart along some
/// axis: the cluster of each box, and each cluster's box, clusters numbered by their
/// first box.
fn clusters(boxes: &[Bounds]) -> (Vec<usize>, Vec<Bounds>) {
    let mut cluster_of: Vec<usize> = (0..boxes.len()).collect();
    let mut current: Vec<Bounds> = boxes.to_vec();
    loop {
        // Union of the current clusters' boxes that are near, swept along x.
        let mut parent: Vec<usize> = (0..current.len()).collect();
        fn find(p: &mut [usize], mut x: usize) -> usize {
            while p[x] != x {
                p[x] = p[p[x]];
                x = p[x];
            }
            x
        }
        let mut order: Vec<usize> = (0..current.len()).collect();
        order.sort_unstable_by_key(|&i| current[i].0[0]);
        let mut merged = false;
        for (n, &i) in order.iter().enumerate() {
            for &j in &order[n + 1..] {
                if current[j].0[0] > current[i].1[0] {
                    break;
                }
                if near(&current[i], &current[j]) {
                    let (a, b) = (find(&mut parent, i), find(&mut parent, j));
                    if a != b {
                        parent[a.max(b)] = a.min(b);
                        merged = true;
                    }
                }
            }
        }
        // Renumber the roots by their first box, and their boxes.
        let mut number = vec![usize::MAX; current.len()];
        let mut next: Vec<Bounds> = Vec::new();
        for i in 0..current.len() {
            let r = find(&mut parent, i);
            if number[r] == usize::MAX {
                number[r] = next.len();
                next.push(current[i]);
            }
            let (a, b) = &mut next[number[r]];
            for k in 0..3 {
                a[k] = a[k].min(current[i].0[k]);
                b[k] = b[k].max(current[i].1[k]);
            }
        }
        for c in &mut cluster_of {
            *c = number[find(&mut parent, *c)];
        }
        current = next;
        if !merged {
            return (cluster_of, current);
        }
    }
}

/// Writes the voxels of `inst` into `labels`, the box of `dims` voxels from `lo` (`x`
/// fastest), which holds the instance's box.
fn place(
    data: &DotVoxData,
    path: &Path,
    inst: &Instance,
    empty: &[Vec<usize>],
    (lo, dims): ([i64; 3], [usize; 3]),
    labels: &mut [u32],
) -> Result<(), IoError> {
    let model = &data.models[inst.model];
    let size = model_size(model);
    let mut skip = empty.get(inst.model).map_or(&[][..], Vec::as_slice).iter().peekable();
    for (k, v) in model.voxels.iter().enumerate() {
        // Colour index 0 is empty space in MagicaVoxel (`dot_vox` reads it as 1).
        if skip.next_if_eq(&&k).is_some() {
            continue;
        }
        if usize::from(v.i) >= data.palette.len() {
            return Err(IoError::format(
                path,
                format!(
                    "model {}: colour index {} has no entry in the file's palette of {} colours",
                    inst.model,
                    u32::from(v.i) + 1,
                    data.palette.len()
                ),
            ));
        }
        let p = [v.x, v.y, v.z].map(i64::from);
        if (0..3).any(|k| p[k] >= size[k]) {
            return Err(IoError::format(
                path,
                format!(
                    "model {}: voxel ({}, {}, {}) lies outside its size {}x{}x{}",
                    inst.model, p[0], p[1], p[2], size[0], size[1], size[2]
                ),
            ));
        }
        let w = inst.placement.voxel(p, size);
        let q = [0, 1, 2].map(|k| (w[k] - lo[k]) as usize);
        labels[q[0] + dims[0] * (q[1] + dims[1] * q[2])] = u32::from(v.i) + 1;
    }
    Ok(())
}

/// The number of scene-graph chunks (`nTRN`, `nGRP`, `nSHP`) among the children of the
/// file's `MAIN` chunk.
fn scene_chunks(bytes: &[u8]) -> usize {
    let word = |at: usize| -> Option<usize> {
        let b = bytes.get(at..at.checked_add(4)?)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    let Some(children) = word(16) else { return 0 };
    let start = 20 + word(12).unwrap_or(0);
    let end = start.saturating_add(children).min(bytes.len());
    let (mut at, mut count) = (start, 0);
    while at + 12 <= end {
        let (Some(n), Some(m)) = (word(at + 4), word(at + 8)) else { break };
        count += usize::from(matches!(&bytes[at..at + 4], b"nTRN" | b"nGRP" | b"nSHP"));
        let Some(next) = (at + 12).checked_add(n).and_then(|c| c.checked_add(m)) else { break };
        at = next;
    }
    count
}

/// The positions, in each model's voxel list, of voxels of colour index 0 (empty in
/// MagicaVoxel), found by walking the file's `XYZI` chunks as `dot_vox` does (a model
/// for each `XYZI` after a `SIZE`). Empty lists when the walk does not find one chunk per
/// model.
fn empty_voxels(bytes: &[u8], models: usize) -> Vec<Vec<usize>> {
    let word = |at: usize| -> Option<usize> {
        let b = bytes.get(at..at.checked_add(4)?)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
    };
    let mut out = Vec::new();
    // "VOX ", version, then MAIN: id, content size, children size, content, children.
    let Some(children) = word(16) else { return vec![Vec::new(); models] };
    let start = 20 + word(12).unwrap_or(0);
    let end = start.saturating_add(children).min(bytes.len());
    let mut at = start;
    let mut size_seen = false;
    while at + 12 <= end {
        let (Some(n), Some(m)) = (word(at + 4), word(at + 8)) else { break };
        let id = &bytes[at..at + 4];
        let content = at + 12;
        if id == b"SIZE" {
            size_seen = true;
        } else if id == b"XYZI" && size_seen {
            let count = word(content).unwrap_or(0);
            match bytes.get(content + 4..).and_then(|d| d.get(..count.checked_mul(4)?)) {
                Some(voxels) if count.checked_mul(4).is_some_and(|b| b + 4 <= n) => out.push(
                    voxels.chunks_exact(4).enumerate().filter(|(_, v)| v[3] == 0).map(|(k, _)| k).collect(),
                ),
                _ => out.push(Vec::new()),
            }
        }
        let Some(next) = content.checked_add(n).and_then(|c| c.checked_add(m)) else { break };
        at = next;
    }
    if out.len() == models {
        out
    } else {
        vec![Vec::new(); models]
    }
}

/// The palette as 256 RGBA entries indexed by label (`dot_vox`'s 0-based index + 1),
/// with the `MATL` materials (whose ids are MagicaVoxel's 1-based colour indices, so
/// they are labels too) and their `_name`s.
fn palette(data: &DotVoxData) -> Palette {
    let mut colors = vec![[0u8; 4]; 256];
    for (entry, colour) in colors[1..].iter_mut().zip(&data.palette) {
        *entry = colour.into();
    }
    let mut palette = Palette::from_colors(colors);
    for m in &data.materials {
        if let Some(material) = palette.materials.get_mut(m.id as usize) {
            if m.id > 0 {
                apply_vox_material(material, &m.properties);
            }
        }
        if let Some(name) = m.properties.get("_name").filter(|_| m.id > 0) {
            palette.set_name(m.id, name);
        }
    }
    palette
}

fn model_size(model: &Model) -> [i64; 3] {
    [model.size.x, model.size.y, model.size.z].map(i64::from)
}

/// One model placed in the scene: its index and its placement.
struct Instance {
    model: usize,
    placement: Placement,
}

/// A rigid placement of the lattice: `world = rotation * local + translation`, where
/// `rotation` is a signed permutation (MagicaVoxel's `_r` byte) and `translation` is in
/// voxels.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
struct Placement {
    /// Rows of a signed permutation matrix.
    rotation: [[i64; 3]; 3],
    translation: [i64; 3],
}

impl Placement {
    const IDENTITY: Placement =
        Placement { rotation: [[1, 0, 0], [0, 1, 0], [0, 0, 1]], translation: [0; 3] };

    /// Decodes MagicaVoxel's rotation byte: bits 0-1 and 2-3 give the column of the
    /// non-zero entry of rows 0 and 1 (row 2 takes the remaining column), bits 4, 5, 6
    /// the signs of rows 0, 1, 2 (set: negative). `None` if it is not a permutation.
    fn rotation_from_byte(byte: u8) -> Option<[[i64; 3]; 3]> {
        let c0 = (byte & 3) as usize;
        let c1 = ((byte >> 2) & 3) as usize;
        if c0 > 2 || c1 > 2 || c0 == c1 {
            return None;
        }
        let c2 = 3 - c0 - c1;
        let mut r = [[0i64; 3]; 3];
        for (row, col) in [c0, c1, c2].into_iter().enumerate() {
            r[row][col] = if byte & (1 << (4 + row)) != 0 { -1 } else { 1 };
        }
        Some(r)
    }

    fn apply(&self, v: [i64; 3]) -> [i64; 3] {
        [0, 1, 2].map(|i| (0..3).map(|j| self.rotation[i][j] * v[j]).sum::<i64>() + self.translation[i])
    }

    /// `self` after `child`: the placement of the child's local frame in `self`'s parent.
    fn then(&self, child: &Placement) -> Placement {
        let mut rotation = [[0i64; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                rotation[i][j] = (0..3).map(|k| self.rotation[i][k] * child.rotation[k][j]).sum();
            }
        }
        Placement { rotation, translation: self.apply(child.translation) }
    }

    /// World voxel of local voxel `v` of a model of `size`: MagicaVoxel pivots a model
    /// about `floor(size / 2)`, so the voxel centre `v + 1/2 - floor(size / 2)` is
    /// rotated and translated; world voxel = that centre minus 1/2. Computed in doubled
    /// integer coordinates to stay exact.
    fn voxel(&self, v: [i64; 3], size: [i64; 3]) -> [i64; 3] {
        let twice_centre = [0, 1, 2].map(|k| 2 * v[k] + 1 - 2 * (size[k] / 2));
        let rotated = [0, 1, 2].map(|i| (0..3).map(|j| self.rotation[i][j] * twice_centre[j]).sum::<i64>());
        [0, 1, 2].map(|k| (rotated[k] + 2 * self.translation[k] - 1).div_euclid(2))
    }

    /// The world box `[lo, hi)` of a model of `size`.
    fn bounds(&self, size: [i64; 3]) -> ([i64; 3], [i64; 3]) {
        let a = self.voxel([0; 3], size);
        let b = self.voxel([0, 1, 2].map(|k| (size[k] - 1).max(0)), size);
        ([0, 1, 2].map(|k| a[k].min(b[k])), [0, 1, 2].map(|k| a[k].max(b[k]) + 1))
    }
}

fn hidden(attributes: &dot_vox::Dict) -> bool {
    attributes.get("_hidden").is_some_and(|h| h.trim() == "1")
}

/// The models placed by the scene graph, in scene-graph order.
fn scene_instances(data: &DotVoxData, path: &Path) -> Result<Vec<Instance>, IoError> {
    if data.scenes.is_empty() {
        return Err(IoError::unsupported(
            path,
            format!("{} models without a scene graph to place them", data.models.len()),
        ));
    }
    let mut walk_state = Walk { instances: Vec::new(), visits: 0, voxels: 0 };
    walk(data, path, 0, Placement::IDENTITY, 0, &mut walk_state)?;
    let instances = walk_state.instances;
    if instances.is_empty() {
        return Err(IoError::format(path, "the scene graph places no model"));
    }
    Ok(instances)
}

/// What the scene-graph walk has found and how far it went.
struct Walk {
    instances: Vec<Instance>,
    /// Nodes visited.
    visits: usize,
    /// Voxels of the instances found.
    voxels: u64,
}

fn walk(
    data: &DotVoxData,
    path: &Path,
    node: u32,
    placement: Placement,
    depth: usize,
    out: &mut Walk,
) -> Result<(), IoError> {
    if depth > MAX_SCENE_DEPTH {
        return Err(IoError::format(path, format!("scene graph deeper than {MAX_SCENE_DEPTH} (a cycle?)")));
    }
    out.visits += 1;
    if out.visits > MAX_SCENE_VISITS {
        return Err(IoError::unsupported(
            path,
            format!("the scene graph expands to more than {MAX_SCENE_VISITS} nodes (groups listing the same child many times?)"),
        ));
    }
    let Some(scene_node) = data.scenes.get(node as usize) else {
        return Err(IoError::format(path, format!("scene graph names node {node}, which does not exist")));
    };
    match scene_node {
        SceneNode::Transform { attributes, frames, child, layer_id } => {
            let layer_hidden = data.layers.get(*layer_id as usize).is_some_and(|l| hidden(&l.attributes));
            if hidden(attributes) || layer_hidden {
                return Ok(());
            }
            let mut local = Placement::IDENTITY;
            if let Some(frame) = frames.first() {
                if let Some(r) = frame.attributes.get("_r") {
                    local.rotation =
                        r.trim().parse::<u8>().ok().and_then(Placement::rotation_from_byte).ok_or_else(
                            || IoError::format(path, format!("node {node}: '{r}' is not a rotation (_r)")),
                        )?;
                }
                if let Some(t) = frame.attributes.get("_t") {
                    let p =
                        frame.position().filter(|_| t.split_whitespace().count() == 3).ok_or_else(|| {
                            IoError::format(
                                path,
                                format!("node {node}: '{t}' is not a translation (_t: three integers)"),
                            )
                        })?;
                    local.translation = [i64::from(p.x), i64::from(p.y), i64::from(p.z)];
                }
            }
            walk(data, path, *child, placement.then(&local), depth + 1, out)
        }
        SceneNode::Group { attributes, children } => {
            if hidden(attributes) {
                return Ok(());
            }
            children.iter().try_for_each(|&c| walk(data, path, c, placement, depth + 1, out))
        }
        SceneNode::Shape { attributes, models } => {
            if hidden(attributes) {
                return Ok(());
            }
            let Some(shape_model) = models.first() else { return Ok(()) };
            let model = shape_model.model_id as usize;
            if data.models.get(model).is_none() {
                return Err(IoError::format(
                    path,
                    format!("node {node} names model {model}, which does not exist"),
                ));
            }
            out.voxels += data.models[model].voxels.len() as u64;
            if out.instances.len() >= VOX_MAX_INSTANCES || out.voxels > VOX_MAX_PLACED_VOXELS {
                return Err(IoError::unsupported(
                    path,
                    format!(
                        "the scene graph places more than {VOX_MAX_INSTANCES} model instances or {VOX_MAX_PLACED_VOXELS} voxels"
                    ),
                ));
            }
            out.instances.push(Instance { model, placement });
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use dot_vox::{Color, Dict, Frame, ShapeModel, Size, Voxel};

    use super::*;

    fn model(size: [u32; 3], voxels: &[[u8; 4]]) -> Model {
        Model {
            size: Size { x: size[0], y: size[1], z: size[2] },
            voxels: voxels.iter().map(|&[x, y, z, i]| Voxel { x, y, z, i }).collect(),
        }
    }

    fn encode(models: Vec<Model>, scenes: Vec<SceneNode>) -> Vec<u8> {
        let palette = (0..=255u8).map(|i| Color { r: i, g: 255 - i, b: 7, a: 255 }).collect();
        voxreg_testkit::vox_bytes(models, palette, scenes)
    }

    fn transform(child: u32, t: &str, r: Option<&str>) -> SceneNode {
        let mut attributes = Dict::new();
        attributes.insert("_t".into(), t.into());
        if let Some(r) = r {
            attributes.insert("_r".into(), r.into());
        }
        SceneNode::Transform {
            attributes: Dict::new(),
            frames: vec![Frame::new(attributes)],
            child,
            layer_id: 0,
        }
    }

    fn shape(model_id: u32) -> SceneNode {
        SceneNode::Shape {
            attributes: Dict::new(),
            models: vec![ShapeModel { model_id, attributes: Dict::new() }],
        }
    }

    fn two_models(r: Option<&str>) -> Vec<u8> {
        encode(
            vec![model([2, 1, 1], &[[0, 0, 0, 0], [1, 0, 0, 4]]), model([3, 1, 1], &[[2, 0, 0, 9]])],
            vec![
                transform(1, "0 0 0", None),
                SceneNode::Group { attributes: Dict::new(), children: vec![2, 4] },
                transform(3, "1 0 0", None),
                shape(0),
                transform(5, "-5 2 1", r),
                shape(1),
            ],
        )
    }

    #[test]
    fn single_model_labels_palette_and_origin() {
        let bytes = encode(vec![model([2, 3, 4], &[[0, 0, 0, 0], [1, 2, 3, 254]])], Vec::new());
        let loaded = read_vox_bytes(&bytes, Path::new("m.vox")).unwrap();
        let v = &loaded.volume;
        assert_eq!(v.dims(), [2, 3, 4]);
        assert_eq!(v.label([0, 0, 0]), Some(1));
        assert_eq!(v.label([1, 2, 3]), Some(255));
        assert_eq!(v.label([1, 0, 0]), Some(0));
        assert_eq!(v.corner_position([0, 0, 0]), DVec3::ZERO);
        assert_eq!(v.corner_position([2, 3, 4]), DVec3::new(2.0, 3.0, 4.0));
        let palette = loaded.palette.unwrap().colors;
        assert_eq!(palette.len(), 256);
        assert_eq!(palette[0], [0, 0, 0, 0]);
        assert_eq!(palette[1], [0, 255, 7, 255]);
        assert_eq!(palette[255], [254, 1, 7, 255]);
    }

    #[test]
    fn several_models_placed_by_translation() {
        let loaded = read_vox_bytes(&two_models(None), Path::new("m.vox")).unwrap();
        let v = &loaded.volume;
        // Model 0 (2x1x1) centred at x = 1: x in 0..2. Model 1 (3x1x1) centred at
        // (-5, 2, 1): x in -6..-3, y = 2, z = 1. Box: x in -6..2, y in 0..3, z in 0..2.
        assert_eq!(v.dims(), [8, 3, 2]);
        assert_eq!(v.corner_position([0, 0, 0]), DVec3::new(-6.0, 0.0, 0.0));
        assert_eq!(v.label([6, 0, 0]), Some(1));
        assert_eq!(v.label([7, 0, 0]), Some(5));
        assert_eq!(v.label([2, 2, 1]), Some(10));
        let solid: usize = v.labels().iter().filter(|&&l| l != 0).count();
        assert_eq!(solid, 3);
    }

    #[test]
    fn rotated_and_mirrored_models_are_placed() {
        // _r 36: rows (0, 1, 2) -> columns (0, 1, 2), row 1 negative: mirror y. Model 1
        // (3x1x1, pivot (1, 0, 0)) at (-5, 2, 1): its voxels' centres y + 1/2 - 0 = 1/2
        // become -1/2, so they land at y = 2 - 1 = 1.
        let v = read_vox_bytes(&two_models(Some("36")), Path::new("m.vox")).unwrap().volume;
        assert_eq!(v.dims(), [8, 2, 2]);
        assert_eq!(v.corner_position([0, 0, 0]), DVec3::new(-6.0, 0.0, 0.0));
        assert_eq!(v.label([2, 1, 1]), Some(10));
        // _r 17: row 0 -> column 1 (negative), row 1 -> column 0: a quarter turn about z.
        // Model 1 now runs along y, from y = 1 to 3, at x = -6.
        let v = read_vox_bytes(&two_models(Some("17")), Path::new("m.vox")).unwrap().volume;
        assert_eq!(v.dims(), [8, 4, 2]);
        assert_eq!(v.label([0, 3, 1]), Some(10)); // voxel x = 2 of the model
        assert_eq!(v.labels().iter().filter(|&&l| l == 10).count(), 1);
        // Not a signed permutation: refused, not a panic.
        for bad in ["255", "3", "x"] {
            let err = read_vox_bytes(&two_models(Some(bad)), Path::new("m.vox")).unwrap_err();
            assert!(err.to_string().contains("is not a rotation"), "{err}");
        }
    }

    #[test]
    fn nested_transforms_compose() {
        let p = Placement { rotation: Placement::rotation_from_byte(17).unwrap(), translation: [1, 2, 3] };
        let q = p.then(&p);
        // Two quarter turns: a half turn about z.
        assert_eq!(q.rotation, [[-1, 0, 0], [0, -1, 0], [0, 0, 1]]);
        assert_eq!(q.apply([0, 0, 0]), p.apply(p.apply([0, 0, 0])));
        assert_eq!(Placement::rotation_from_byte(4), Some(Placement::IDENTITY.rotation));
    }

    #[test]
    fn hidden_nodes_and_layers_are_skipped() {
        let hide = |mut node: SceneNode, layer: u32| {
            if let SceneNode::Transform { attributes, layer_id, .. } = &mut node {
                if layer == 0 {
                    attributes.insert("_hidden".into(), "1".into());
                }
                *layer_id = layer;
            }
            node
        };
        for layer in [0, 1] {
            let mut data = dot_vox::load_bytes(&two_models(None)).unwrap();
            data.scenes[4] = hide(data.scenes[4].clone(), layer);
            let mut hidden_layer = Dict::new();
            hidden_layer.insert("_hidden".into(), "1".into());
            data.layers =
                vec![dot_vox::Layer { attributes: Dict::new() }, dot_vox::Layer { attributes: hidden_layer }];
            let mut bytes = Vec::new();
            data.write_vox(&mut bytes).unwrap();
            let v = read_vox_bytes(&bytes, Path::new("m.vox")).unwrap().volume;
            assert_eq!(v.dims(), [2, 1, 1], "layer {layer}: only model 0 remains");
            assert!(v.labels().iter().all(|&l| l != 10));
        }
    }

    #[test]
    fn malformed_models() {
        let outside = encode(vec![model([2, 2, 2], &[[0, 2, 0, 0]])], Vec::new());
        let err = read_vox_bytes(&outside, Path::new("m.vox")).unwrap_err();
        assert!(err.to_string().contains("voxel (0, 2, 0) lies outside its size 2x2x2"), "{err}");

        let huge = encode(vec![model([u32::MAX, u32::MAX, 2], &[])], Vec::new());
        let err = read_vox_bytes(&huge, Path::new("m.vox")).unwrap_err();
        assert!(err.to_string().contains("at most 256 per axis"), "{err}");

        let none = encode(Vec::new(), Vec::new());
        assert!(read_vox_bytes(&none, Path::new("m.vox")).unwrap_err().to_string().contains("no model"));

        // Models without a scene graph (animation frames): model 0, or the one asked for.
        let no_scene =
            encode(vec![model([1, 1, 1], &[[0, 0, 0, 1]]), model([2, 1, 1], &[[1, 0, 0, 3]])], Vec::new());
        let first = read_vox_bytes(&no_scene, Path::new("m.vox")).unwrap().volume;
        assert_eq!(first.dims(), [1, 1, 1]);
        let second = read_vox_bytes_with(&no_scene, Path::new("m.vox"), &VoxOptions { model: Some(1) })
            .unwrap()
            .volume;
        assert_eq!(second.dims(), [2, 1, 1]);
        assert_eq!(second.labels()[[1, 0, 0]], 4);
        let err =
            read_vox_bytes_with(&no_scene, Path::new("m.vox"), &VoxOptions { model: Some(2) }).unwrap_err();
        assert!(err.to_string().contains("model 2 does not exist: the file has 2 model(s), 0 to 1"), "{err}");
        assert_eq!(vox_model_sizes(&no_scene, Path::new("m.vox")).unwrap(), vec![[1, 1, 1], [2, 1, 1]]);

        let dangling =
            encode(vec![model([1, 1, 1], &[]), model([1, 1, 1], &[])], vec![transform(7, "0 0 0", None)]);
        let err = read_vox_bytes(&dangling, Path::new("m.vox")).unwrap_err();
        assert!(err.to_string().contains("node 7, which does not exist"), "{err}");

        let cycle = encode(
            vec![model([1, 1, 1], &[]), model([1, 1, 1], &[])],
            vec![SceneNode::Group { attributes: Dict::new(), children: vec![0] }],
        );
        let err = read_vox_bytes(&cycle, Path::new("m.vox")).unwrap_err();
        assert!(err.to_string().contains("a cycle?"), "{err}");
    }

    /// A scene of `models`, each under its own transform `(t, r)` in one group.
    fn scene(models: Vec<Model>, placements: &[(String, Option<String>)]) -> Vec<u8> {
        let n = placements.len() as u32;
        let mut scenes = vec![
            transform(1, "0 0 0", None),
            SceneNode::Group { attributes: Dict::new(), children: (0..n).map(|k| 2 + 2 * k).collect() },
        ];
        for (k, (t, r)) in placements.iter().enumerate() {
            scenes.push(transform(3 + 2 * k as u32, t, r.as_deref()));
            scenes.push(shape(k as u32));
        }
        encode(models, scenes)
    }

    #[test]
    fn scenes_read_as_blocks_are_the_dense_volume() {
        // Random scenes of up to five models (1 to 3 voxels a side, random voxels and
        // colours), translated within 8 or 3 voxels and rotated: apart, touching at a face, an
        // edge or a corner, overlapping (a later model overwrites).
        let mut x = 7u64;
        let mut next = |n: u64| {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (x >> 33) % n
        };
        let (mut sparse, mut clustered) = (0, 0);
        for _ in 0..400 {
            let count = 1 + next(5) as usize;
            // Half the scenes spread over 16 voxels, half crowded into 6.
            let spread = if next(2) == 0 { 16 } else { 6 };
            let mut models = Vec::new();
            let mut placements = Vec::new();
            for _ in 0..count {
                let size = [1 + next(3) as u32, 1 + next(3) as u32, 1 + next(3) as u32];
                let mut voxels = Vec::new();
                for z in 0..size[2] as u8 {
                    for y in 0..size[1] as u8 {
                        for x in 0..size[0] as u8 {
                            if next(4) != 0 {
                                voxels.push([x, y, z, next(6) as u8]);
                            }
                        }
                    }
                }
                models.push(model(size, &voxels));
                let mut at = || next(spread) as i64 - spread as i64 / 2;
                let t = format!("{} {} {}", at(), at(), at());
                let c0 = next(3) as u8;
                let c1 = (c0 + 1 + next(2) as u8) % 3;
                let r = (next(2) == 0).then(|| (c0 | (c1 << 2) | ((next(8) as u8) << 4)).to_string());
                placements.push((t, r));
            }
            let bytes = scene(models, &placements);
            let dense = read_vox_bytes(&bytes, Path::new("s.vox")).unwrap();
            let blocks = read_vox_scene_bytes(&bytes, Path::new("s.vox"), &VoxOptions::default()).unwrap();
            assert_eq!(blocks.volume.to_dense().unwrap(), dense.volume, "{placements:?}");
            assert_eq!(blocks.palette, dense.palette.unwrap());
            sparse += usize::from(blocks.is_sparse());
            clustered += usize::from(blocks.volume.blocks().len() < count);
        }
        assert!(sparse > 100 && clustered > 100, "{sparse} sparse, {clustered} with models clustered");
    }

    #[test]
    fn models_far_apart_make_blocks_of_their_own_boxes() {
        // Two models 2,047 voxels apart and one overlapping the first: two blocks of 4 and
        // 1 voxels in a 2049 x 1024 x 1024 lattice, read within a 1 MiB budget.
        let bytes = scene(
            vec![
                model([3, 1, 1], &[[0, 0, 0, 4], [1, 0, 0, 4], [2, 0, 0, 4]]),
                model([1, 1, 1], &[[0, 0, 0, 8]]),
                model([2, 1, 1], &[[0, 0, 0, 7], [1, 0, 0, 7]]),
            ],
            &[("0 0 0".into(), None), ("2047 1023 1023".into(), None), ("2 0 0".into(), None)],
        );
        let s = crate::limits::with_max_memory(1 << 20, || {
            read_vox_scene_bytes(&bytes, Path::new("f.vox"), &VoxOptions::default())
        })
        .unwrap();
        let v = &s.volume;
        assert!(s.is_sparse());
        assert_eq!(v.dims(), [2049, 1024, 1024]);
        assert_eq!(v.blocks().len(), 2);
        assert_eq!(v.block_voxels(), 5);
        // Model 0 covers x = -1..2, model 2 x = 1..3: model 2 wins at x = 1.
        assert_eq!((0..4).map(|x| v.label([x, 0, 0])).collect::<Vec<_>>(), [5, 5, 8, 8]);
        assert_eq!(v.label([2048, 1023, 1023]), 9);
        assert_eq!(v.origin(), DVec3::new(-0.5, 0.5, 0.5));
        // The dense reader refuses the same file under that budget.
        let dense = crate::limits::with_max_memory(1 << 20, || read_vox_bytes(&bytes, Path::new("f.vox")));
        assert!(matches!(dense, Err(IoError::OverBudget { .. } | IoError::TooLarge { .. })), "{dense:?}");
    }

    #[test]
    fn garbage_is_refused_without_panicking() {
        let real = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/chr_army1.vox")).unwrap();
        for len in (0..real.len()).step_by(7) {
            let _ = read_vox_bytes(&real[..len], Path::new("m.vox"));
        }
        let err = read_vox_bytes(b"VOX but not really", Path::new("m.vox")).unwrap_err();
        assert!(matches!(err, IoError::Format { .. }));
        assert_eq!(
            err.to_string(),
            "m.vox: not a valid MagicaVoxel .vox file (dot_vox: Not a valid MagicaVoxel .vox file)"
        );
    }
}
