//! Volumes written by the formats' own tools (`data/formats/`, made by
//! `data/formats/make.py`: tifffile, pynrrd, mrcfile, zarr): each reads as the same
//! labels with the spacing and units its metadata give; and round trips.

use std::path::{Path, PathBuf};

use glam::DVec3;
use voxreg_digisurf::LabelVolume;
use voxreg_io::{read_voxels, IoError, LoadedVoxels, Voxels};

pub(crate) fn sample(name: &str) -> PathBuf {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/formats")).join(name)
}

/// The volume of every sample: `labels()` of `make.py`.
fn expected() -> LabelVolume {
    LabelVolume::from_fn([6, 5, 4], |[x, y, z]| {
        if (3..5).contains(&x) && (2..4).contains(&y) && (2..4).contains(&z) {
            2
        } else if (1..4).contains(&x) && (1..4).contains(&y) && (1..3).contains(&z) {
            1
        } else {
            0
        }
    })
}

/// Reads `name`, checks its labels against [`expected`] and returns it.
fn read_sample(name: &str) -> LoadedVoxels {
    let loaded = read_voxels(&sample(name)).unwrap_or_else(|e| panic!("{name}: {e}"));
    let Voxels::Labels(volume) = &loaded.voxels else { panic!("{name}: grey levels") };
    assert_eq!(volume.labels(), expected().labels(), "{name}");
    loaded
}

fn assert_spacing(loaded: &LoadedVoxels, spacing: [f64; 3], units: Option<&str>, name: &str) {
    assert!(
        (loaded.voxels.spacing() - DVec3::from_array(spacing)).abs().max_element() < 1e-12,
        "{name}: {}",
        loaded.voxels.spacing()
    );
    assert_eq!(loaded.units.as_deref(), units, "{name}");
}

#[test]
fn tiff_stacks() {
    let imagej = read_sample("stack_imagej.tif");
    assert_spacing(&imagej, [0.5, 0.5, 2.0], Some("µm"), "imagej");
    let ome = read_sample("stack.ome.tif");
    assert_spacing(&ome, [0.25, 0.25, 1.0], Some("µm"), "ome");
    let dir = read_sample("slices");
    assert_spacing(&dir, [1.0; 3], None, "slices");
    let pattern = read_sample("slices/slice_*.tif");
    assert_eq!(pattern.voxels, dir.voxels);
    let err = read_voxels(&sample("slices/none_*.tif")).unwrap_err();
    assert!(err.to_string().contains("none_*.tif: no .tif or .tiff slices match"), "{err}");
}

/// A multi-page TIFF written by the `tiff` crate's encoder, 16-bit, reads back exactly;
/// pages of different sizes are refused naming the file.
#[test]
fn tiff_round_trip_and_mismatched_pages() {
    use tiff::encoder::{colortype, TiffEncoder};
    let dims = [7usize, 3, 5];
    let value = |x: usize, y: usize, z: usize| ((x * 31 + y * 7 + z * 1009) % 65_521) as u16;
    let mut bytes = std::io::Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::new(&mut bytes).unwrap();
        for z in 0..dims[2] {
            let page: Vec<u16> =
                (0..dims[1]).flat_map(|y| (0..dims[0]).map(move |x| value(x, y, z))).collect();
            enc.write_image::<colortype::Gray16>(dims[0] as u32, dims[1] as u32, &page).unwrap();
        }
    }
    let path = Path::new("round.tif");
    let loaded = voxreg_io::read_tiff_bytes(bytes.get_ref(), path).unwrap();
    let Voxels::Labels(volume) = loaded.voxels else { panic!("grey") };
    assert_eq!(volume.dims(), dims);
    assert_eq!(volume.labels(), &ndarray::Array3::from_shape_fn(dims, |(x, y, z)| u32::from(value(x, y, z))));

    let mut bytes = std::io::Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::new(&mut bytes).unwrap();
        enc.write_image::<colortype::Gray8>(2, 2, &[0; 4]).unwrap();
        enc.write_image::<colortype::Gray8>(3, 2, &[0; 6]).unwrap();
    }
    let err = voxreg_io::read_tiff_bytes(bytes.get_ref(), path).unwrap_err();
    assert!(matches!(err, IoError::Format { .. }), "{err}");
    assert_eq!(err.to_string(), "round.tif: page 1 is 3x2 of u8, page 0 2x2 of u8");
}

#[test]
fn nrrd_files() {
    for name in ["labels.nrrd", "detached.nhdr", "organs.seg.nrrd"] {
        let loaded = read_sample(name);
        assert_spacing(&loaded, [0.5, 0.5, 1.5], Some("mm"), name);
        assert_eq!(loaded.voxels.origin(), DVec3::new(10.0, -4.0, 2.5), "{name}");
        assert_eq!(loaded.palette.is_some(), name.ends_with(".seg.nrrd"), "{name}");
    }
    let palette = read_sample("organs.seg.nrrd").palette.unwrap();
    assert_eq!(palette.colors.len(), 3);
    assert_eq!(palette.colors[1], [204, 51, 51, 255]);
    assert_eq!(palette.colors[2], [51, 102, 230, 255]);
    let names: Vec<&str> = palette.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["color_0", "liver", "spleen"]);
}

/// Hand-made headers: a flipped, permuted space; ascii data; and the errors naming the
/// file for truncated data, a 4-D array and a missing detached file.
#[test]
fn nrrd_space_and_errors() {
    let path = Path::new("t.nrrd");
    // Index axis 0 runs along -y (step 2), axis 1 along +x (step 3), axis 2 along z.
    let header = "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 3 2 1\nencoding: raw\n\
                  space: left-posterior-superior\nspace directions: (0,-2,0) (3,0,0) (0,0,1)\n\
                  space origin: (1,2,3)\n\n";
    let mut bytes = header.as_bytes().to_vec();
    bytes.extend(1..=6u8);
    let loaded = voxreg_io::read_nrrd_bytes(&bytes, path).unwrap();
    let Voxels::Labels(v) = loaded.voxels else { panic!("grey") };
    assert_eq!(v.dims(), [2, 3, 1]);
    assert_eq!(v.spacing(), DVec3::new(3.0, 2.0, 1.0));
    // World (1 + 3 i, 2 - 2 j, 3) holds index [j, i, 0], value 1 + j + 3 i.
    assert_eq!(v.origin(), DVec3::new(1.0, -2.0, 3.0));
    for (x, y) in [(0i64, 0i64), (1, 0), (0, 2), (1, 1)] {
        let (i, j) = (x, 2 - y);
        assert_eq!(v.label([x, y, 0]), Some(1 + j as u32 + 3 * i as u32), "[{x}, {y}]");
    }
    let ascii =
        "NRRD0004\ntype: float\ndimension: 3\nsizes: 2 1 1\nencoding: ascii\nspacings: 2 2 2\n\n0.5 7\n";
    let grey = voxreg_io::read_nrrd_bytes(ascii.as_bytes(), path).unwrap().voxels;
    assert!(matches!(grey, Voxels::Grey(_)));
    assert_eq!(grey.spacing(), DVec3::splat(2.0));

    let cases: [(Vec<u8>, &str); 4] = [
        (bytes[..bytes.len() - 1].to_vec(), "t.nrrd: truncated data: 5 bytes of 6"),
        (header.replace("dimension: 3", "dimension: 4").into_bytes(), "t.nrrd: unsupported: dimension 4"),
        (
            header.replace("encoding: raw\n", "encoding: raw\ndata file: none.raw\n").into_bytes(),
            "none.raw: ",
        ),
        (b"P3D\n".to_vec(), "t.nrrd: not a NRRD file: no magic"),
    ];
    for (bytes, expected) in cases {
        let err = voxreg_io::read_nrrd_bytes(&bytes, path).unwrap_err().to_string();
        assert!(err.starts_with(expected), "{err}");
    }
    let sizes = header.replace("sizes: 3 2 1", "sizes: 100000 100000 100000");
    let err = voxreg_io::read_nrrd_bytes(sizes.as_bytes(), path).unwrap_err();
    assert!(matches!(err, IoError::TooLarge { .. }), "{err}");
}

#[test]
fn mrc_files() {
    for name in ["mode0.mrc", "mode1.mrc", "mode6.mrc", "labels.map"] {
        let loaded = read_sample(name);
        assert_spacing(&loaded, [1.5, 1.5, 3.0], Some("Å"), name);
    }
}

/// An MRC file made here, big-endian, with sections along x and columns along z
/// (`MAPC/MAPR/MAPS = 3, 2, 1`): the permutation is applied; a short file is refused.
#[test]
fn mrc_axis_map_and_errors() {
    let (nc, nr, ns) = (2i32, 3i32, 4i32);
    let mut h = vec![0u8; 1024];
    let mut put = |i: usize, v: [u8; 4]| h[4 * i..4 * i + 4].copy_from_slice(&v);
    for (i, v) in [(0, nc), (1, nr), (2, ns), (3, 1), (7, ns), (8, nr), (9, nc), (16, 3), (17, 2), (18, 1)] {
        put(i, v.to_be_bytes());
    }
    // Cell: x spans 4 sections of 2 Å, y 3 rows of 1 Å, z 2 columns of 0.5 Å.
    for (i, v) in [(10, 8.0f32), (11, 3.0), (12, 1.0)] {
        put(i, v.to_be_bytes());
    }
    h[208..212].copy_from_slice(b"MAP ");
    h[212] = 0x11;
    let value = |c: i32, r: i32, s: i32| (c + 10 * r + 100 * s) as i16;
    let mut bytes = h.clone();
    for s in 0..ns {
        for r in 0..nr {
            for c in 0..nc {
                bytes.extend(value(c, r, s).to_be_bytes());
            }
        }
    }
    let path = Path::new("t.mrc");
    let loaded = voxreg_io::read_mrc_bytes(&bytes, path).unwrap();
    let Voxels::Labels(v) = loaded.voxels else { panic!("grey") };
    assert_eq!(v.dims(), [4, 3, 2]);
    assert_eq!(v.spacing(), DVec3::new(2.0, 1.0, 0.5));
    for [x, y, z] in [[0, 0, 0], [3, 2, 1], [1, 2, 0]] {
        assert_eq!(v.label([x, y, z]), Some(value(z as i32, y as i32, x as i32) as u32), "{x} {y} {z}");
    }
    let err = voxreg_io::read_mrc_bytes(&bytes[..bytes.len() - 2], path).unwrap_err();
    assert!(err.to_string().starts_with("t.mrc: truncated voxel data"), "{err}");
    let err = voxreg_io::read_mrc_bytes(&bytes[..100], path).unwrap_err();
    assert!(err.to_string().starts_with("t.mrc: not an MRC file"), "{err}");
}

#[test]
fn zarr_arrays() {
    // v2 blosc, v3 zstd, v3 sharded gzip: no OME metadata, so unit spacing.
    for name in ["labels_v2.zarr", "labels_v3.zarr", "labels_sharded.zarr"] {
        let loaded = read_sample(name);
        assert_spacing(&loaded, [1.0; 3], None, name);
        assert_eq!(loaded.voxels.origin(), DVec3::ZERO, "{name}");
    }
}

#[test]
fn ome_zarr_images() {
    // The image reads as its level 0; the level, named by its path, the same.
    for name in ["image.ome.zarr", "image.ome.zarr/0", "image_v3.ome.zarr", "image_v3.ome.zarr/0"] {
        let loaded = read_sample(name);
        assert_spacing(&loaded, [0.5, 0.5, 2.0], Some("µm"), name);
    }
    // Level 1, every second voxel, at twice the spacing.
    for name in ["image.ome.zarr/1", "image_v3.ome.zarr/1"] {
        let loaded = read_voxels(&sample(name)).unwrap();
        let Voxels::Labels(v) = &loaded.voxels else { panic!("{name}: grey") };
        let full = expected();
        assert_eq!(v.dims(), [3, 3, 2], "{name}");
        for [x, y, z] in [[0, 0, 0], [1, 1, 0], [2, 1, 1], [1, 1, 1]] {
            assert_eq!(v.label([x, y, z]), full.label([2 * x, 2 * y, 2 * z]), "{name} {x} {y} {z}");
        }
        assert_spacing(&loaded, [1.0, 1.0, 4.0], Some("µm"), name);
    }
}

/// An in-memory OME-Zarr 0.4 image of one level, `0`, of `shape` (no chunks: all fill
/// value), with the given axes, transformations and dataset path.
fn ome_store(shape: &str, axes: &str, transforms: &str, dataset: &str) -> Result<LoadedVoxels, IoError> {
    let zarray = format!(
        r#"{{"zarr_format": 2, "shape": {shape}, "chunks": {shape}, "dtype": "|u1", "compressor": null,
            "fill_value": 0, "order": "C", "filters": null}}"#
    );
    let zattrs = format!(
        r#"{{"multiscales": [{{"version": "0.4", "axes": {axes},
            "datasets": [{{"path": "{dataset}", "coordinateTransformations": {transforms}}}]}}]}}"#
    );
    let entries = [
        (".zgroup", &br#"{"zarr_format": 2}"#[..]),
        (".zattrs", zattrs.as_bytes()),
        ("0/.zarray", zarray.as_bytes()),
    ];
    voxreg_io::read_zarr_entries(&entries, Path::new("mem.zarr"))
}

/// OME-Zarr placements: time and channel axes of extent 1 are dropped, scale and
/// translation compose; and the errors, each naming the store.
#[test]
fn ome_zarr_metadata_and_errors() {
    let space = |n: &str| format!(r#"{{"name": "{n}", "type": "space", "unit": "nanometer"}}"#);
    let tczyx = format!(
        r#"[{{"name": "t", "type": "time"}}, {{"name": "c", "type": "channel"}}, {}, {}, {}]"#,
        space("z"),
        space("y"),
        space("x")
    );
    let transforms = r#"[{"type": "scale", "scale": [1, 1, 3, 2, 1]},
                         {"type": "translation", "translation": [0, 0, 30, 20, 10]}]"#;
    let loaded = ome_store("[1, 1, 2, 3, 4]", &tczyx, transforms, "0").unwrap();
    assert_eq!(loaded.voxels.dims(), [4, 3, 2]);
    assert_eq!(loaded.voxels.spacing(), DVec3::new(1.0, 2.0, 3.0));
    assert_eq!(loaded.voxels.origin(), DVec3::new(10.0, 20.0, 30.0));
    assert_eq!(loaded.units.as_deref(), Some("nm"));

    let zyx = format!("[{}, {}, {}]", space("z"), space("y"), space("x"));
    let scale = r#"[{"type": "scale", "scale": [1, 1, 1]}]"#;
    let five = r#"[{"type": "scale", "scale": [1, 1, 1, 1, 1]}]"#;
    let message = |r: Result<LoadedVoxels, IoError>| r.unwrap_err().to_string();
    for (result, expected) in [
        (ome_store("[2, 3, 4]", &zyx, scale, "../x"), "mem.zarr: OME-Zarr multiscales: dataset path '../x'"),
        (
            ome_store("[2, 3, 4]", &zyx, r#"[{"type": "scale", "scale": [1, 1]}]"#, "0"),
            "needs 3 finite numbers",
        ),
        (ome_store("[2, 3, 4]", &zyx, r#"[{"type": "scale", "path": "s"}]"#, "0"), "without inline values"),
        (ome_store("[2, 3, 4]", &zyx, scale, "1"), "mem.zarr: OME-Zarr dataset 1: array metadata is missing"),
        (ome_store("[2, 2, 3, 4]", &tczyx, five, "0"), "OME-Zarr metadata for 5 axes, the array has 4"),
        (ome_store("[2, 3, 4]", "[]", "[]", "0"), "OME-Zarr metadata for 0 axes"),
    ] {
        let m = message(result);
        assert!(m.starts_with("mem.zarr: ") && m.contains(expected) && !m.contains('\n'), "{m}");
    }
    let tzyx =
        format!(r#"[{{"name": "t", "type": "time"}}, {}, {}, {}]"#, space("z"), space("y"), space("x"));
    let four = r#"[{"type": "scale", "scale": [1, 1, 1, 1]}]"#;
    let m = message(ome_store("[2, 2, 3, 4]", &tzyx, four, "0"));
    assert!(m.contains("axis 0 (before z, y, x) has extent 2"), "{m}");
}

/// Absurd shapes and chunks are refused from the metadata alone, before any chunk is
/// decoded; a group that is not an image, and a directory that is no store, name the path.
#[test]
fn zarr_bad_input() {
    let array = |shape: &str, chunks: &str| {
        let zarray = format!(
            r#"{{"zarr_format": 2, "shape": {shape}, "chunks": {chunks}, "dtype": "<u2", "compressor": null,
                "fill_value": 0, "order": "C", "filters": null}}"#
        );
        voxreg_io::read_zarr_entries(&[(".zarray", zarray.as_bytes())], Path::new("big.zarr"))
    };
    let err = array("[100000, 100000, 100000]", "[64, 64, 64]").unwrap_err();
    assert!(matches!(err, IoError::TooLarge { .. }), "{err}");
    let err =
        voxreg_io::with_max_memory(1 << 30, || array("[4, 4, 4]", "[100000, 100000, 100000]")).unwrap_err();
    assert!(matches!(err, IoError::OverBudget { .. }), "{err}");
    assert!(
        err.to_string().starts_with("big.zarr: a chunk of [100000, 100000, 100000] elements needs"),
        "{err}"
    );
    // 2^63 * 2^63 * 4 elements: a product that wraps to 0 in 128 bits.
    let err = voxreg_io::with_max_memory(1 << 30, || {
        array("[4, 4, 4]", "[9223372036854775808, 9223372036854775808, 4]")
    })
    .unwrap_err();
    assert!(matches!(err, IoError::OverBudget { .. }), "{err}");
    let err = array("[4, 4]", "[4, 4]").unwrap_err();
    assert_eq!(err.to_string(), "big.zarr: unsupported: a 2-dimensional array (3 are read)");
    let err = array("[4, 4, 4]", "[4, 4]").unwrap_err();
    assert!(matches!(err, IoError::Format { .. }) && !err.to_string().contains('\n'), "{err}");

    let group = [(".zgroup", &br#"{"zarr_format": 2}"#[..])];
    let err = voxreg_io::read_zarr_entries(&group, Path::new("g.zarr")).unwrap_err();
    assert!(
        err.to_string().starts_with("g.zarr: unsupported: a Zarr group without OME-Zarr multiscales"),
        "{err}"
    );

    let dir = tempfile::tempdir().unwrap();
    let empty = dir.path().join("empty.zarr");
    std::fs::create_dir(&empty).unwrap();
    let err = read_voxels(&empty).unwrap_err();
    assert_eq!(
        err.to_string(),
        format!("{}: not a Zarr store: no zarr.json, .zarray or .zgroup", empty.display())
    );
    let missing = dir.path().join("missing.zarr");
    let err = read_voxels(&missing).unwrap_err();
    assert!(err.to_string().starts_with(&format!("{}: ", missing.display())), "{err}");
    // A chunk that does not decode.
    let zarray = br#"{"zarr_format": 2, "shape": [2, 2, 2], "chunks": [2, 2, 2], "dtype": "|u1",
                      "compressor": {"id": "zlib", "level": 1}, "fill_value": 0, "order": "C", "filters": null}"#;
    let entries = [(".zarray", &zarray[..]), ("0.0.0", &b"not zlib"[..])];
    let err = voxreg_io::read_zarr_entries(&entries, Path::new("bad.zarr")).unwrap_err();
    assert!(err.to_string().starts_with("bad.zarr: ") && !err.to_string().contains('\n'), "{err}");
}
