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
