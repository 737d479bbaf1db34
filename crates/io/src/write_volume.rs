//! Volume output: MagicaVoxel `.vox` and DGtal `.vol`.

use std::io::{self, Write};
use std::path::Path;

use dot_vox::{Color, DotVoxData, Frame, Model, SceneNode, ShapeModel, Size, Voxel};
use voxreg_digisurf::{BlockVolume, LabelVolume};

use crate::error::IoError;
use crate::files::lowercase_extension;
use crate::material::Palette;
use crate::mesh::write_file_atomically;

/// The largest model MagicaVoxel opens, per axis.
pub const VOX_MAX_MODEL: usize = 256;

/// Writes `volume` to `path`, choosing the format by the extension: `.vox` (see
/// [`write_vox`]) or `.vol` (see [`write_vol`]). Labels must fit a byte (`0..=255`).
pub fn write_volume(path: &Path, volume: &LabelVolume, palette: Option<&Palette>) -> Result<(), IoError> {
    match lowercase_extension(path).as_deref() {
        Some("vox") => write_vox(path, volume, palette),
        Some("vol") => write_vol(path, volume),
        _ => Err(IoError::UnsupportedExtension { path: path.to_path_buf(), expected: ".vox or .vol" }),
    }
}

fn check_byte_labels(path: &Path, volume: &LabelVolume, what: &str) -> Result<(), IoError> {
    match volume.labels().iter().find(|&&l| l > 255) {
        Some(l) => Err(IoError::unsupported(path, format!("label {l} does not fit {what} (0..=255)"))),
        None => Ok(()),
    }
}

/// Writes `volume` as a MagicaVoxel `.vox` file: label `l` (`1..=255`) is colour index
/// `l`, label 0 is empty. A volume larger than [`VOX_MAX_MODEL`] along an axis is split
/// into models of at most that size, placed by a scene graph (one group of translated
/// shapes) so that reading the file back (e.g. with [`read_vox`](crate::vox::read_vox))
/// gives the same labels at the same lattice positions. The palette's colours are
/// written (a default grey ramp without one); materials are not written back.
pub fn write_vox(path: &Path, volume: &LabelVolume, palette: Option<&Palette>) -> Result<(), IoError> {
    check_byte_labels(path, volume, "a .vox colour index")?;
    if volume.is_empty() {
        return Err(IoError::unsupported(path, "an empty volume has no .vox model"));
    }
    let mut models = Vec::new();
    let mut placements = Vec::new();
    split_models(volume.labels(), [0; 3], &mut models, &mut placements);
    write_models(path, models, placements, palette)
}

/// Writes the blocks of `volume` (a scene of objects far apart) as [`write_volume`] does:
/// `.vox`, each block split into models of at most [`VOX_MAX_MODEL`] voxels per axis and
/// placed where it lies, a model of the lattice's empty corners only where no block
/// reaches them (reading the file back gives the volume's labels, dense, or as blocks
/// with [`read_vox_scene_bytes`](crate::read_vox_scene_bytes)); `.vol`, the volume made
/// dense (its whole lattice: the caller checks that it fits in memory).
pub fn write_volume_blocks(
    path: &Path,
    volume: &BlockVolume,
    palette: Option<&Palette>,
) -> Result<(), IoError> {
    if volume.background() != 0 {
        return Err(IoError::unsupported(path, "blocks are written with background 0 only"));
    }
    match lowercase_extension(path).as_deref() {
        Some("vox") => {}
        Some("vol") => {
            let dense =
                volume.to_dense().map_err(|source| IoError::Volume { path: path.to_path_buf(), source })?;
            return write_vol(path, &dense);
        }
        _ => {
            return Err(IoError::UnsupportedExtension { path: path.to_path_buf(), expected: ".vox or .vol" })
        }
    }
    for b in volume.blocks() {
        if let Some(l) = b.labels.iter().find(|&&l| l > 255) {
            return Err(IoError::unsupported(
                path,
                format!("label {l} does not fit a .vox colour index (0..=255)"),
            ));
        }
    }
    if volume.is_empty() {
        return Err(IoError::unsupported(path, "an empty volume has no .vox model"));
    }
    let mut models = Vec::new();
    let mut placements = Vec::new();
    for b in volume.blocks() {
        split_models(&b.labels, b.offset, &mut models, &mut placements);
    }
    // The lattice's extent: its first and last voxels, as empty models where no block
    // holds them.
    let dims = volume.dims();
    for corner in [[0; 3], dims.map(|d| d - 1)] {
        let held = volume.blocks().iter().any(|b| {
            let (lo, hi) = b.bounds();
            (0..3).all(|k| lo[k] <= corner[k] && corner[k] < hi[k])
        });
        if !held {
            let empty = ndarray::Array3::zeros((1, 1, 1));
            split_models(&empty, corner, &mut models, &mut placements);
        }
    }
    write_models(path, models, placements, palette)
}

/// `labels` (voxel `[0, 0, 0]` at lattice position `offset`) as models of at most
/// [`VOX_MAX_MODEL`] voxels per axis, and each model's scene translation.
fn split_models(
    labels: &ndarray::Array3<u32>,
    offset: [usize; 3],
    models: &mut Vec<Model>,
    placements: &mut Vec<[i64; 3]>,
) {
    let dims = labels.dim();
    let dims = [dims.0, dims.1, dims.2];
    let starts: Vec<Vec<usize>> =
        dims.iter().map(|&d| (0..d.div_ceil(VOX_MAX_MODEL)).map(|b| b * VOX_MAX_MODEL).collect()).collect();
    for &z0 in &starts[2] {
        for &y0 in &starts[1] {
            for &x0 in &starts[0] {
                let lo = [x0, y0, z0];
                let size = [0, 1, 2].map(|k| (dims[k] - lo[k]).min(VOX_MAX_MODEL));
                let mut voxels = Vec::new();
                for z in 0..size[2] {
                    for y in 0..size[1] {
                        for x in 0..size[0] {
                            let l = labels[[lo[0] + x, lo[1] + y, lo[2] + z]];
                            if l != 0 {
                                voxels.push(Voxel { x: x as u8, y: y as u8, z: z as u8, i: (l - 1) as u8 });
                            }
                        }
                    }
                }
                models.push(Model {
                    size: Size { x: size[0] as u32, y: size[1] as u32, z: size[2] as u32 },
                    voxels,
                });
                // MagicaVoxel places a model's voxel floor(size / 2) at the translation.
                placements.push([0, 1, 2].map(|k| (offset[k] + lo[k] + size[k] / 2) as i64));
            }
        }
    }
}

/// Writes `models` placed by `placements` (a scene graph unless there is one model).
fn write_models(
    path: &Path,
    models: Vec<Model>,
    placements: Vec<[i64; 3]>,
    palette: Option<&Palette>,
) -> Result<(), IoError> {
    let mut scenes = Vec::new();
    if models.len() > 1 {
        let n = models.len() as u32;
        scenes.push(SceneNode::Transform {
            attributes: Default::default(),
            frames: vec![Frame::new(Default::default())],
            child: 1,
            layer_id: u32::MAX,
        });
        scenes.push(SceneNode::Group {
            attributes: Default::default(),
            children: (0..n).map(|i| 2 + 2 * i).collect(),
        });
        for (i, t) in placements.iter().enumerate() {
            let mut frame = dot_vox::Dict::new();
            frame.insert("_t".into(), format!("{} {} {}", t[0], t[1], t[2]));
            scenes.push(SceneNode::Transform {
                attributes: Default::default(),
                frames: vec![Frame::new(frame)],
                child: 3 + 2 * i as u32,
                layer_id: 0,
            });
            scenes.push(SceneNode::Shape {
                attributes: Default::default(),
                models: vec![ShapeModel { model_id: i as u32, attributes: Default::default() }],
            });
        }
    }
    let colors: Vec<Color> = (1..=256usize)
        .map(|l| {
            let c = palette.and_then(|p| p.colors.get(l).copied()).unwrap_or([(l % 256) as u8; 4]);
            Color { r: c[0], g: c[1], b: c[2], a: c[3] }
        })
        .collect();
    let data = DotVoxData {
        version: if scenes.is_empty() { 150 } else { 200 },
        index_map: dot_vox::DEFAULT_INDEX_MAP.to_vec(),
        models,
        palette: colors,
        materials: Vec::new(),
        layers: if scenes.is_empty() {
            Vec::new()
        } else {
            vec![dot_vox::Layer { attributes: Default::default() }]
        },
        scenes,
    };
    write_file_atomically(path, |mut w| data.write_vox(&mut w))
}

/// Writes `volume` as a DGtal Vol file, version 3 (zlib-compressed bytes, `x` fastest).
/// Labels must fit a byte.
pub fn write_vol(path: &Path, volume: &LabelVolume) -> Result<(), IoError> {
    check_byte_labels(path, volume, "a .vol byte")?;
    let [nx, ny, nz] = volume.dims();
    let mut bytes = Vec::with_capacity(volume.len());
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                bytes.push(volume.labels()[[x, y, z]] as u8);
            }
        }
    }
    write_file_atomically(path, |w: &mut dyn Write| {
        write!(
            w,
            "Center-X: {}\nCenter-Y: {}\nCenter-Z: {}\nX: {nx}\nY: {ny}\nZ: {nz}\nVoxel-Size: 1\n\
             Alpha-Color: 0\nVoxel-Endian: 0\nInt-Endian: 0123\nVersion: 3\n.\n",
            nx / 2,
            ny / 2,
            nz / 2
        )?;
        let mut z = flate2::write::ZlibEncoder::new(w, flate2::Compression::default());
        z.write_all(&bytes)?;
        z.finish().map(|_| ()).map_err(io::Error::other)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vol::read_vol;
    use crate::vox::read_vox;
    use voxreg_testkit::Lcg;

    fn random_volume(dims: [usize; 3]) -> LabelVolume {
        let mut rng = Lcg::new(7);
        LabelVolume::from_fn(dims, |_| {
            let r = rng.below(5);
            if r < 3 {
                0
            } else {
                r * 50
            }
        })
    }

    #[test]
    fn vox_round_trip_with_split_models() {
        let dir = tempfile::tempdir().unwrap();
        for dims in [[5, 4, 3], [300, 3, 2], [2, 260, 257]] {
            let v = random_volume(dims);
            let path = dir.path().join("v.vox");
            write_vox(&path, &v, None).unwrap();
            let back = read_vox(&path).unwrap().volume;
            assert_eq!(back.dims(), dims);
            assert_eq!(back.labels(), v.labels(), "{dims:?}");
        }
    }

    #[test]
    fn blocks_round_trip_through_a_vox_scene() {
        use voxreg_digisurf::{Block, BlockVolume};
        let dir = tempfile::tempdir().unwrap();
        let block = |offset: [usize; 3], dims: [usize; 3]| Block {
            offset,
            labels: random_volume(dims).labels().to_owned(),
        };
        // A block over two models along x, one alone far off, the lattice's corners empty.
        let blocks = vec![block([3, 2, 1], [300, 3, 2]), block([900, 40, 50], [2, 3, 4])];
        let volume = BlockVolume::new([1000, 50, 60], blocks, 0).unwrap();
        for name in ["b.vox", "b.vol"] {
            let path = dir.path().join(name);
            write_volume_blocks(&path, &volume, None).unwrap();
            let back = crate::read_volume(&path).unwrap().volume;
            assert_eq!(back.dims(), volume.dims(), "{name}");
            assert_eq!(back.labels(), volume.to_dense().unwrap().labels(), "{name}");
        }
    }

    #[test]
    fn vol_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let v = random_volume([7, 5, 3]);
        let path = dir.path().join("v.vol");
        write_vol(&path, &v).unwrap();
        assert_eq!(read_vol(&path).unwrap().labels(), v.labels());
    }

    #[test]
    fn wide_labels_are_refused_and_nothing_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let v = LabelVolume::from_fn([2, 1, 1], |p| if p[0] == 0 { 300 } else { 0 });
        for name in ["v.vox", "v.vol", "v.nii"] {
            assert!(write_volume(&dir.path().join(name), &v, None).is_err());
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }
}
