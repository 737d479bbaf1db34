//! MagicaVoxel `.vox` volumes, parsed by the `dot_vox` crate.

use std::path::Path;

use dot_vox::{DotVoxData, Model, SceneNode};
use glam::DVec3;
use voxreg_digisurf::LabelVolume;

use crate::volume::{checked_voxel_count, read_file};
use crate::{IoError, LoadedVolume};

/// Scene graphs nested deeper than this are refused (they are malformed or cyclic).
const MAX_SCENE_DEPTH: usize = 64;

/// Reads a MagicaVoxel `.vox` file as a labeled volume with its palette.
///
/// See [`read_vox_bytes`] for the mapping of colours to labels and of models to space.
pub fn read_vox(path: &Path) -> Result<LoadedVolume, IoError> {
    read_vox_bytes(&read_file(path)?, path)
}

/// Reads a MagicaVoxel `.vox` file held in memory; `path` only names the file in errors.
///
/// **Labels.** A voxel of MagicaVoxel colour index `c` (`1..=255`) gets label `c`;
/// label `0` is empty space (the background). The palette is returned as 256 RGBA
/// entries indexed by label, entry `0` transparent black.
///
/// **Space.** MagicaVoxel coordinates `x, y, z` (`z` up) are the volume's `[x, y, z]`,
/// with spacing `1`, and the origin is chosen so that lattice corners fall on integer
/// MagicaVoxel coordinates: voxel `[x, y, z]` fills the unit cube from `(x, y, z)` to
/// `(x + 1, y + 1, z + 1)`.
///
/// - A file with one model gives a volume of exactly the model's size, origin `0.5`
///   (the model's own transform, if any, is ignored).
/// - A file with several models places each shape of the scene graph at its
///   translation, MagicaVoxel's way (a model's centre, `floor(size / 2)`, at the
///   translation), in one volume spanning them all; where models overlap, the later one
///   wins. Only the first frame of animated transforms and the first model of animated
///   shapes are used, and hidden layers are still read. Rotated or mirrored models are
///   refused with [`IoError::Unsupported`], as is a multi-model file without a scene
///   graph.
///
/// Files that `dot_vox` cannot parse, with no model, or with a voxel outside its
/// model's size are [`IoError::Format`] errors; volumes above
/// [`MAX_VOXELS`](crate::MAX_VOXELS) are [`IoError::TooLarge`].
pub fn read_vox_bytes(bytes: &[u8], path: &Path) -> Result<LoadedVolume, IoError> {
    let data = dot_vox::load_bytes(bytes)
        .map_err(|e| IoError::format(path, format!("not a valid MagicaVoxel .vox file (dot_vox: {e})")))?;
    let instances = match data.models.len() {
        0 => return Err(IoError::format(path, "the .vox file holds no model")),
        1 => vec![Instance { model: 0, min_corner: [0; 3] }],
        _ => scene_instances(&data, path)?,
    };

    // The bounding box of all instances, in MagicaVoxel coordinates.
    let mut lo = [i64::MAX; 3];
    let mut hi = [i64::MIN; 3];
    for inst in &instances {
        let size = model_size(&data.models[inst.model]);
        for k in 0..3 {
            lo[k] = lo[k].min(inst.min_corner[k]);
            hi[k] = hi[k].max(inst.min_corner[k] + size[k]);
        }
    }
    let dims = [0, 1, 2].map(|k| (hi[k] - lo[k]).max(0) as u64);
    let count = checked_voxel_count(path, dims)?;
    let dims = dims.map(|d| d as usize);

    let mut labels = vec![0u32; count];
    for inst in &instances {
        let model = &data.models[inst.model];
        let size = model_size(model);
        for v in &model.voxels {
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
            let q = [0, 1, 2].map(|k| (p[k] + inst.min_corner[k] - lo[k]) as usize);
            labels[q[0] + dims[0] * (q[1] + dims[1] * q[2])] = u32::from(v.i) + 1;
        }
    }
    let volume = LabelVolume::from_x_fastest(dims, labels)
        .and_then(|v| v.with_origin(DVec3::new(lo[0] as f64, lo[1] as f64, lo[2] as f64) + 0.5))
        .map_err(|source| IoError::Volume { path: path.to_path_buf(), source })?;
    Ok(LoadedVolume { volume, palette: Some(palette(&data)) })
}

/// The palette as 256 RGBA entries indexed by label (`dot_vox`'s 0-based index + 1).
fn palette(data: &DotVoxData) -> Vec<[u8; 4]> {
    let mut palette = vec![[0u8; 4]; 256];
    for (entry, colour) in palette[1..].iter_mut().zip(&data.palette) {
        *entry = colour.into();
    }
    palette
}

fn model_size(model: &Model) -> [i64; 3] {
    [model.size.x, model.size.y, model.size.z].map(i64::from)
}

/// One model placed in the scene: its index and the MagicaVoxel coordinates of its
/// minimal corner.
struct Instance {
    model: usize,
    min_corner: [i64; 3],
}

/// The models placed by the scene graph, in scene-graph order.
fn scene_instances(data: &DotVoxData, path: &Path) -> Result<Vec<Instance>, IoError> {
    if data.scenes.is_empty() {
        return Err(IoError::unsupported(
            path,
            format!("{} models without a scene graph to place them", data.models.len()),
        ));
    }
    let mut instances = Vec::new();
    walk(data, path, 0, [0; 3], 0, &mut instances)?;
    if instances.is_empty() {
        return Err(IoError::format(path, "the scene graph places no model"));
    }
    Ok(instances)
}

fn walk(
    data: &DotVoxData,
    path: &Path,
    node: u32,
    translation: [i64; 3],
    depth: usize,
    out: &mut Vec<Instance>,
) -> Result<(), IoError> {
    if depth > MAX_SCENE_DEPTH {
        return Err(IoError::format(path, format!("scene graph deeper than {MAX_SCENE_DEPTH} (a cycle?)")));
    }
    let Some(scene_node) = data.scenes.get(node as usize) else {
        return Err(IoError::format(path, format!("scene graph names node {node}, which does not exist")));
    };
    match scene_node {
        SceneNode::Transform { frames, child, .. } => {
            let mut t = translation;
            if let Some(frame) = frames.first() {
                if let Some(r) = frame.attributes.get("_r") {
                    // Bits 0-1 and 2-3: the columns of the non-zero entries of rows 1 and 2;
                    // bits 4-6: their signs. The identity is 0b000_01_00.
                    if r.trim().parse::<u8>().map(|b| b & 0x7f) != Ok(0b0000100) {
                        return Err(IoError::unsupported(
                            path,
                            format!("node {node} rotates or mirrors its models (_r {r})"),
                        ));
                    }
                }
                if let Some(p) = frame.position() {
                    t = [
                        translation[0] + i64::from(p.x),
                        translation[1] + i64::from(p.y),
                        translation[2] + i64::from(p.z),
                    ];
                }
            }
            walk(data, path, *child, t, depth + 1, out)
        }
        SceneNode::Group { children, .. } => {
            children.iter().try_for_each(|&c| walk(data, path, c, translation, depth + 1, out))
        }
        SceneNode::Shape { models, .. } => {
            let Some(shape_model) = models.first() else { return Ok(()) };
            let model = shape_model.model_id as usize;
            let Some(m) = data.models.get(model) else {
                return Err(IoError::format(
                    path,
                    format!("node {node} names model {model}, which does not exist"),
                ));
            };
            let size = model_size(m);
            out.push(Instance { model, min_corner: [0, 1, 2].map(|k| translation[k] - size[k] / 2) });
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
        let data = DotVoxData {
            version: 150,
            index_map: dot_vox::DEFAULT_INDEX_MAP.to_vec(),
            models,
            palette: (0..=255u8).map(|i| Color { r: i, g: 255 - i, b: 7, a: 255 }).collect(),
            materials: Vec::new(),
            scenes,
            layers: Vec::new(),
        };
        let mut bytes = Vec::new();
        data.write_vox(&mut bytes).unwrap();
        bytes
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
        let palette = loaded.palette.unwrap();
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
    fn rotated_models_are_refused() {
        let err = read_vox_bytes(&two_models(Some("36")), Path::new("m.vox")).unwrap_err();
        assert!(matches!(err, IoError::Unsupported { .. }), "{err}");
        assert!(err.to_string().starts_with("m.vox: unsupported: node 4 rotates"), "{err}");
        // The identity rotation is fine, and a garbage one is refused, not a panic.
        assert!(read_vox_bytes(&two_models(Some("4")), Path::new("m.vox")).is_ok());
        assert!(read_vox_bytes(&two_models(Some("255")), Path::new("m.vox")).is_err());
    }

    #[test]
    fn malformed_models() {
        let outside = encode(vec![model([2, 2, 2], &[[0, 2, 0, 0]])], Vec::new());
        let err = read_vox_bytes(&outside, Path::new("m.vox")).unwrap_err();
        assert!(err.to_string().contains("voxel (0, 2, 0) lies outside its size 2x2x2"), "{err}");

        let huge = encode(vec![model([u32::MAX, u32::MAX, 2], &[])], Vec::new());
        let err = read_vox_bytes(&huge, Path::new("m.vox")).unwrap_err();
        assert!(matches!(err, IoError::TooLarge { .. }), "{err}");

        let none = encode(Vec::new(), Vec::new());
        assert!(read_vox_bytes(&none, Path::new("m.vox")).unwrap_err().to_string().contains("no model"));

        let no_scene = encode(vec![model([1, 1, 1], &[]), model([1, 1, 1], &[])], Vec::new());
        let err = read_vox_bytes(&no_scene, Path::new("m.vox")).unwrap_err();
        assert!(err.to_string().contains("2 models without a scene graph"), "{err}");

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
