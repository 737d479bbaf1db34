//! Inputs that reach outside themselves or say nonsense: detached data and links
//! leading out of the input's directory, inputs that are not regular files, files and
//! compressed chunks larger than the memory budget, degenerate or unrepresentable
//! placements, corrupt scene graphs, control characters in units. Each is a one-line
//! error naming the file (or, for units, escaped), never a hang, a read of another
//! file or a silent replacement.

use std::io::Write;
use std::os::unix::fs::symlink;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use flate2::write::GzEncoder;
use flate2::Compression;
use voxreg_io::{
    read_input, read_mrc_bytes, read_nrrd_bytes, read_volume, read_vox_bytes, read_voxels, with_max_memory,
    InputError, InputOptions, IoError, Voxels,
};

/// `f()`, or a panic when it takes more than `secs` seconds (it runs on a thread of
/// its own, left behind if it blocks).
fn within<T: Send + 'static>(secs: u64, f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(Duration::from_secs(secs)).expect("the reader returns at once")
}

/// A `.npy` of `u1` values, shape `(1, 1, 1)`, followed by `padding` bytes.
fn npy_with_padding(path: &Path, padding: usize) {
    let mut bytes = voxreg_testkit::npy_bytes("|u1", [1; 3], [1]);
    bytes.resize(bytes.len() + padding, 0);
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn a_fifo_is_refused_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["pipe.vol", "pipe.nii.gz", "pipe.vox"] {
        let fifo = dir.path().join(name);
        assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
        let err = within(10, move || read_volume(&fifo).map(drop).unwrap_err().to_string());
        assert!(err.contains(&format!("{name}: a FIFO, not a regular file")), "{err}");
    }
}

#[test]
fn a_link_to_a_device_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let link = dir.path().join("zero.npy");
    symlink("/dev/zero", &link).unwrap();
    let err = within(10, move || read_volume(&link).map(drop).unwrap_err().to_string());
    assert!(err.contains("zero.npy: a device, not a regular file"), "{err}");
}

#[test]
fn a_file_larger_than_the_budget_is_not_read() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("padded.npy");
    npy_with_padding(&path, 2 << 20);
    let err = with_max_memory(1 << 20, || read_volume(&path)).unwrap_err();
    assert!(matches!(err, IoError::OverBudget { .. }), "{err}");
    assert!(
        err.to_string().contains("padded.npy: the file needs 2.0 MiB, over the memory limit of 1.0 MiB"),
        "{err}"
    );
}

/// A detached NRRD header of 2x2x2 `uchar` naming `data_file`, written as `path`.
fn write_nhdr(path: &Path, data_file: &str, extra: &str) {
    let text = format!(
        "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n{extra}data file: {data_file}\n\n"
    );
    std::fs::write(path, text).unwrap();
}

#[test]
fn nrrd_detached_data_stay_in_the_header_directory() {
    let dir = tempfile::tempdir().unwrap();
    let inner = dir.path().join("in");
    std::fs::create_dir_all(inner.join("sub")).unwrap();
    std::fs::write(dir.path().join("secret.raw"), [7u8; 8]).unwrap();
    std::fs::write(inner.join("ok.raw"), [1u8; 8]).unwrap();
    std::fs::write(inner.join("sub/deep.raw"), [2u8; 8]).unwrap();
    symlink(dir.path().join("secret.raw"), inner.join("out.raw")).unwrap();
    symlink(inner.join("ok.raw"), inner.join("in.raw")).unwrap();
    let header = inner.join("h.nhdr");
    let outside = [
        ("/etc/passwd", ""),
        ("/proc/self/environ", "byte skip: -1\n"),
        ("../secret.raw", ""),
        ("sub/../../secret.raw", ""),
        ("out.raw", ""),
    ];
    for (file, extra) in outside {
        write_nhdr(&header, file, extra);
        let err = read_voxels(&header).unwrap_err().to_string();
        assert!(err.starts_with(&format!("{}: ", header.display())), "{file}: {err}");
        assert!(
            err.contains(&format!("data file '{file}' is outside the header's directory")),
            "{file}: {err}"
        );
    }
    for (file, value) in [("ok.raw", 1), ("sub/deep.raw", 2), ("in.raw", 1)] {
        write_nhdr(&header, file, "");
        let Voxels::Labels(v) = read_voxels(&header).unwrap().voxels else { panic!("grey") };
        assert_eq!(v.label_counts(), vec![(value, 8)], "{file}");
    }
    // A FIFO beside the header is refused, not waited on.
    assert!(Command::new("mkfifo").arg(inner.join("fifo.raw")).status().unwrap().success());
    write_nhdr(&header, "fifo.raw", "");
    let err = within(10, move || read_voxels(&header).map(drop).unwrap_err().to_string());
    assert!(err.contains("fifo.raw: a FIFO, not a regular file"), "{err}");
}

#[test]
fn nrrd_byte_skip_is_minus_one_for_raw_data_only() {
    let path = Path::new("skip.nrrd");
    let with = |skip: &str, encoding: &str| {
        let mut bytes = format!(
            "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 1 1\nencoding: {encoding}\nbyte skip: {skip}\n\n"
        )
        .into_bytes();
        bytes.extend([9, 9, 1, 2]);
        read_nrrd_bytes(&bytes, path)
    };
    // -1: the last bytes of the data.
    let Voxels::Labels(v) = with("-1", "raw").unwrap().voxels else { panic!("grey") };
    assert_eq!([v.label([0, 0, 0]), v.label([1, 0, 0])], [Some(1), Some(2)]);
    for (skip, encoding, expected) in [
        ("-2", "raw", "skip.nrrd: byte skip '-2'"),
        ("-1", "gzip", "skip.nrrd: unsupported: byte skip -1 with a compressed or ascii encoding"),
        ("-1", "ascii", "skip.nrrd: unsupported: byte skip -1"),
    ] {
        let err = with(skip, encoding).unwrap_err().to_string();
        assert!(err.starts_with(expected), "{skip} {encoding}: {err}");
    }
}

/// `members` gzip members, each of `member` zero bytes, then one of `tail`.
fn gzip_members(member: usize, members: usize, tail: &[u8]) -> Vec<u8> {
    let mut e = GzEncoder::new(Vec::new(), Compression::best());
    e.write_all(&vec![0; member]).unwrap();
    let one = e.finish().unwrap();
    let mut out = one.repeat(members);
    let mut e = GzEncoder::new(Vec::new(), Compression::best());
    e.write_all(tail).unwrap();
    out.extend(e.finish().unwrap());
    out
}

#[test]
fn nrrd_gzip_byte_skip_is_inflated_and_dropped() {
    // 64 MiB skipped from 64 KiB of gzip: read, with a budget of 1 MiB.
    let skip = 64usize << 20;
    let mut bytes =
        format!("NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 1 1\nencoding: gzip\nbyte skip: {skip}\n\n")
            .into_bytes();
    bytes.extend(gzip_members(1 << 20, 64, &[3, 4]));
    assert!(bytes.len() < 1 << 17, "{}", bytes.len());
    let loaded = with_max_memory(1 << 20, || read_nrrd_bytes(&bytes, Path::new("z.nrrd"))).unwrap();
    let Voxels::Labels(v) = loaded.voxels else { panic!("grey") };
    assert_eq!([v.label([0, 0, 0]), v.label([1, 0, 0])], [Some(3), Some(4)]);
    // A skip past the stream's end is truncated data.
    let mut bytes =
        b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 1 1\nencoding: gzip\nbyte skip: 99999999999\n\n"
            .to_vec();
    bytes.extend(gzip_members(1 << 10, 1, &[3, 4]));
    let err = read_nrrd_bytes(&bytes, Path::new("z.nrrd")).unwrap_err().to_string();
    assert!(
        err.starts_with("z.nrrd: truncated data: 1026 bytes inflated of the 99999999999 to skip"),
        "{err}"
    );
}

#[test]
fn nrrd_collinear_or_coplanar_directions_are_refused() {
    for directions in
        ["(1,0,0) (2,0,0) (0,0,1)", "(1,0,0) (0,1,0) (1,1,0)", "(1,1,1) (1,1,1.0000001) (0,0,1)"]
    {
        let mut bytes = format!(
            "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 2 1 1\nencoding: raw\nspace directions: {directions}\n\n"
        )
        .into_bytes();
        bytes.extend([1, 2]);
        let err = read_nrrd_bytes(&bytes, Path::new("c.nrrd")).unwrap_err().to_string();
        assert!(err.starts_with("c.nrrd: space directions: "), "{directions}: {err}");
        assert!(err.contains("collinear or coplanar"), "{directions}: {err}");
    }
}

/// A little-endian MRC header of 2x1x1 `int8` voxels with the given cell and origin,
/// then the data.
fn mrc(cell: [f32; 3], origin: [f32; 3]) -> Vec<u8> {
    let mut h = vec![0u8; 1024];
    let mut put = |i: usize, v: [u8; 4]| h[4 * i..4 * i + 4].copy_from_slice(&v);
    for (i, v) in [(0, 2i32), (1, 1), (2, 1), (3, 0), (7, 2), (8, 1), (9, 1), (16, 1), (17, 2), (18, 3)] {
        put(i, v.to_le_bytes());
    }
    for (k, c) in cell.iter().enumerate() {
        put(10 + k, c.to_le_bytes());
    }
    for (k, o) in origin.iter().enumerate() {
        put(49 + k, o.to_le_bytes());
    }
    h[208..212].copy_from_slice(b"MAP ");
    h[212] = 0x44;
    h.extend([1, 0]);
    h
}

#[test]
fn mrc_cells_and_origins_that_are_not_numbers_are_refused() {
    let path = Path::new("m.mrc");
    assert_eq!(read_mrc_bytes(&mrc([4.0, 1.0, 1.0], [0.0; 3]), path).unwrap().voxels.spacing().x, 2.0);
    // A zero cell is MRC's "unset": unit spacing.
    assert_eq!(read_mrc_bytes(&mrc([0.0; 3], [0.0; 3]), path).unwrap().voxels.spacing().x, 1.0);
    for (cell, origin, expected) in [
        ([f32::NAN, 1.0, 1.0], [0.0; 3], "m.mrc: cell NaN x 1 x 1 is not a size"),
        ([1.0, -1.0, 1.0], [0.0; 3], "m.mrc: cell 1 x -1 x 1 is not a size"),
        ([1.0, 1.0, f32::INFINITY], [0.0; 3], "m.mrc: cell 1 x 1 x inf is not a size"),
        ([1.0; 3], [0.0, f32::NAN, 0.0], "m.mrc: origin [0, NaN, 0] is not finite"),
    ] {
        let err = read_mrc_bytes(&mrc(cell, origin), path).unwrap_err().to_string();
        assert!(err.starts_with(expected), "{err}");
    }
}

/// Reads `bytes` as the file `name` through `read_input`, as the front ends do.
fn read_as(name: &str, bytes: &[u8]) -> (tempfile::TempDir, Result<voxreg_io::Input, InputError>) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    let result = read_input(&path, &InputOptions::default());
    (dir, result)
}

/// A NIfTI-1 file of 2x1x1 `uint8`, unit voxels, its qform translating by `offset`.
fn nifti(offset: [f32; 3]) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    let mut put = |at: usize, v: &[u8]| h[at..at + v.len()].copy_from_slice(v);
    put(0, &348i32.to_le_bytes());
    for (k, d) in [3i16, 2, 1, 1].iter().enumerate() {
        put(40 + 2 * k, &d.to_le_bytes());
    }
    put(70, &2i16.to_le_bytes());
    put(72, &8i16.to_le_bytes());
    for (k, v) in [1f32, 1.0, 1.0, 1.0].iter().enumerate() {
        put(76 + 4 * k, &v.to_le_bytes());
    }
    put(108, &352f32.to_le_bytes());
    put(252, &1i16.to_le_bytes());
    for (k, o) in offset.iter().enumerate() {
        put(268 + 4 * k, &o.to_le_bytes());
    }
    put(344, b"n+1\0");
    h.extend([1u8, 0]);
    h
}

#[test]
fn coordinates_a_mesh_cannot_represent_are_refused() {
    let (_d, ok) = read_as("a.nii", &nifti([1e6, 0.0, 0.0]));
    assert_eq!(ok.unwrap().volume.origin().x, 1e6);
    let (_d, far) = read_as("far.nii", &nifti([1e20, 0.0, 0.0]));
    let err = far.unwrap_err().to_string();
    assert!(err.contains("far.nii: voxel spacing 1 along x is below the precision of coordinates"), "{err}");
    let (_d, farther) = read_as("farther.nii", &nifti([1e30, 0.0, 0.0]));
    let err = farther.unwrap_err().to_string();
    assert!(err.contains("farther.nii: coordinates along x reach 1.0000000150474662e30"), "{err}");
    let (_d, tiny) = read_as("tiny.mrc", &mrc([1e-38, 1.0, 1.0], [0.0; 3]));
    let err = tiny.unwrap_err().to_string();
    assert!(err.contains("tiny.mrc: voxel spacing 4.999999675228202e-39 along x is below 1e-30"), "{err}");
    assert!(voxreg_io::check_coordinates([4; 3], glam::DVec3::splat(1e20), glam::DVec3::splat(-1e29)).is_ok());
    let err = voxreg_io::check_coordinates([4; 3], glam::DVec3::splat(1e30), glam::DVec3::ZERO).unwrap_err();
    assert!(err.contains("beyond 1e30"), "{err}");
}

#[test]
fn vox_corrupt_scene_graph_is_refused_not_dropped() {
    let mut bytes = voxreg_testkit::two_model_vox("4 0 0");
    let whole = read_vox_bytes(&bytes, Path::new("s.vox")).unwrap();
    assert_eq!(whole.volume.label_counts(), vec![(0, 3), (2, 2)]);
    // The first nTRN's attribute count made huge: dot_vox drops the chunk.
    let at = bytes.windows(4).position(|w| w == b"nTRN").unwrap();
    bytes[at + 16..at + 20].copy_from_slice(&u32::MAX.to_le_bytes());
    let err = read_vox_bytes(&bytes, Path::new("s.vox")).unwrap_err().to_string();
    assert!(err.starts_with("s.vox: corrupt scene graph: 1 of its 6 nTRN, nGRP and nSHP chunks"), "{err}");
}

#[test]
fn control_characters_in_units_and_names_are_escaped() {
    // NRRD space units.
    let mut bytes = b"NRRD0004\ntype: uchar\ndimension: 3\nsizes: 1 1 1\nencoding: raw\nspace units: \"\x1b[2Jmm\" \"\x1b[2Jmm\" \"\x1b[2Jmm\"\n\n".to_vec();
    bytes.push(1);
    let units = read_nrrd_bytes(&bytes, Path::new("u.nrrd")).unwrap().units.unwrap();
    assert_eq!(units, "\\u{1b}[2Jmm");
    // An ImageJ TIFF's unit.
    use tiff::encoder::{colortype, TiffEncoder};
    use tiff::tags::Tag;
    let mut tif = std::io::Cursor::new(Vec::new());
    {
        let mut enc = TiffEncoder::new(&mut tif).unwrap();
        let mut image = enc.new_image::<colortype::Gray8>(1, 1).unwrap();
        image.encoder().write_tag(Tag::ImageDescription, "ImageJ=1.54\nunit=\x1b]0;owned\x07\n").unwrap();
        image.write_data(&[1]).unwrap();
    }
    let units = voxreg_io::read_tiff_bytes(tif.get_ref(), Path::new("u.tif")).unwrap().units.unwrap();
    assert_eq!(units, "\\u{1b}]0;owned\\u{7}");
    // An OME-Zarr axis unit.
    let space = |n: &str| format!(r#"{{"name": "{n}", "type": "space", "unit": "\u001b[31mnm"}}"#);
    let zattrs = format!(
        r#"{{"multiscales": [{{"version": "0.4", "axes": [{}, {}, {}],
            "datasets": [{{"path": "0", "coordinateTransformations": [{{"type": "scale", "scale": [1, 1, 1]}}]}}]}}]}}"#,
        space("z"),
        space("y"),
        space("x")
    );
    let zarray =
        br#"{"zarr_format": 2, "shape": [1, 1, 1], "chunks": [1, 1, 1], "dtype": "|u1", "compressor": null,
                     "fill_value": 1, "order": "C", "filters": null}"#;
    let entries = [
        (".zgroup", &br#"{"zarr_format": 2}"#[..]),
        (".zattrs", zattrs.as_bytes()),
        ("0/.zarray", &zarray[..]),
    ];
    let units = voxreg_io::read_zarr_entries(&entries, Path::new("u.zarr")).unwrap().units.unwrap();
    assert_eq!(units, "\\u{1b}[31mnm");
}

/// A Zarr v3 array directory of 4x4x4 `uint8` in one chunk with `codecs`, its chunk
/// `c/0/0/0` holding `chunk`.
fn zarr_v3(dir: &Path, codecs: &str, chunk: &[u8]) -> PathBuf {
    let store = dir.join("a.zarr");
    std::fs::create_dir_all(store.join("c/0/0")).unwrap();
    let meta = format!(
        r#"{{"zarr_format": 3, "node_type": "array", "shape": [4, 4, 4], "data_type": "uint8",
            "chunk_grid": {{"name": "regular", "configuration": {{"chunk_shape": [4, 4, 4]}}}},
            "chunk_key_encoding": {{"name": "default", "configuration": {{"separator": "/"}}}},
            "fill_value": 0, "codecs": {codecs}}}"#
    );
    std::fs::write(store.join("zarr.json"), meta).unwrap();
    std::fs::write(store.join("c/0/0/0"), chunk).unwrap();
    store
}

#[test]
fn zarr_chunks_are_read_from_the_store_only() {
    let dir = tempfile::tempdir().unwrap();
    let raw = r#"[{"name": "bytes"}]"#;
    let store = zarr_v3(dir.path(), raw, &[1; 64]);
    let Voxels::Labels(v) = read_voxels(&store).unwrap().voxels else { panic!("grey") };
    assert_eq!(v.label_counts(), vec![(1, 64)]);
    // The chunk a link to a file outside the store.
    std::fs::write(dir.path().join("outside"), [2; 64]).unwrap();
    std::fs::remove_file(store.join("c/0/0/0")).unwrap();
    symlink(dir.path().join("outside"), store.join("c/0/0/0")).unwrap();
    let err = read_voxels(&store).unwrap_err().to_string();
    assert!(err.contains("c/0/0/0: a link out of the Zarr store"), "{err}");
    // A directory of the store a link to one outside.
    std::fs::remove_file(store.join("c/0/0/0")).unwrap();
    std::fs::remove_dir_all(store.join("c")).unwrap();
    symlink(dir.path(), store.join("c")).unwrap();
    let err = read_voxels(&store).unwrap_err().to_string();
    assert!(err.contains("a link out of the Zarr store"), "{err}");
    // A chunk that is a FIFO: refused, not waited on.
    std::fs::remove_file(store.join("c")).unwrap();
    std::fs::create_dir_all(store.join("c/0/0")).unwrap();
    assert!(Command::new("mkfifo").arg(store.join("c/0/0/0")).status().unwrap().success());
    let err = within(10, move || read_voxels(&store).map(drop).unwrap_err().to_string());
    assert!(err.contains("c/0/0/0: a FIFO, not a regular file"), "{err}");
}

#[test]
fn zarr_chunks_inflating_past_their_size_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    // 64 bytes declared, 64 MiB inflated.
    let bomb = {
        let mut e = GzEncoder::new(Vec::new(), Compression::best());
        e.write_all(&vec![0; 64 << 20]).unwrap();
        e.finish().unwrap()
    };
    let store =
        zarr_v3(dir.path(), r#"[{"name": "bytes"}, {"name": "gzip", "configuration": {"level": 9}}]"#, &bomb);
    let err = read_voxels(&store).unwrap_err().to_string();
    assert!(err.contains("chunk c/0/0/0 inflates past the"), "{err}");
    // The same codecs and a chunk of the right size read.
    let mut e = GzEncoder::new(Vec::new(), Compression::best());
    e.write_all(&[3; 64]).unwrap();
    std::fs::write(store.join("c/0/0/0"), e.finish().unwrap()).unwrap();
    let Voxels::Labels(v) = read_voxels(&store).unwrap().voxels else { panic!("grey") };
    assert_eq!(v.label_counts(), vec![(3, 64)]);
    // zstd: a frame declaring its 64 MiB, and one inflating to them without declaring it.
    let zstd_codecs =
        r#"[{"name": "bytes"}, {"name": "zstd", "configuration": {"level": 1, "checksum": false}}]"#;
    let declared = zstd::bulk::compress(&vec![0; 64 << 20], 1).unwrap();
    let store = zarr_v3(dir.path(), zstd_codecs, &declared);
    let err = read_voxels(&store).unwrap_err().to_string();
    assert!(err.contains("chunk c/0/0/0 inflates past the"), "{err}");
    let mut streamed = Vec::new();
    {
        let mut e = zstd::stream::write::Encoder::new(&mut streamed, 1).unwrap();
        e.include_contentsize(false).unwrap();
        e.write_all(&vec![0; 64 << 20]).unwrap();
        e.finish().unwrap();
    }
    std::fs::write(store.join("c/0/0/0"), &streamed).unwrap();
    let err = read_voxels(&store).unwrap_err().to_string();
    assert!(err.contains("chunk c/0/0/0 inflates past the"), "{err}");
}
