//! Mutation tests of every reader's bytes entry point: thousands of corrupted versions of
//! real and synthetic files (truncated, bytes flipped, inserted or deleted, header
//! numbers replaced by boundary values), each of which must be read or refused with an
//! error naming the file, never a panic. Deterministic (a fixed-seed xorshift), so a
//! failure reproduces; the crashing input is written to the test's temporary
//! directory. The coverage-guided counterpart is `fuzz/` (cargo-fuzz, nightly).
//!
//! Also replays `tests/regressions/`: inputs that once crashed a reader, named
//! `<reader>-<what>.bin` (none so far: the fuzzers found no panic), and keeps the one
//! out-of-memory input they found (`.oom`, see its test).

use std::io::Write;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};

use flate2::write::{GzEncoder, ZlibEncoder};
use flate2::Compression;
use voxreg_io::{
    read_longvol_bytes, read_mrc_bytes, read_nifti_bytes, read_npy_bytes, read_nrrd_bytes, read_pgm3d_bytes,
    read_raw_bytes, read_tiff_bytes, read_vol_bytes, read_vox_bytes, read_vti_bytes, read_zarr_entries,
    DataType, Endian, IoError, RawSpec,
};
use voxreg_testkit::Xorshift;

fn data(name: &str) -> Vec<u8> {
    std::fs::read(Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data")).join(name)).unwrap()
}

/// A reader's bytes entry point, returning only whether it succeeded.
type Reader = fn(&[u8]) -> Result<(), IoError>;

const PATH: &str = "mutant.bin";

fn readers() -> Vec<(&'static str, Reader)> {
    vec![
        ("vol", |b| read_vol_bytes(b, Path::new(PATH)).map(drop)),
        ("longvol", |b| read_longvol_bytes(b, Path::new(PATH)).map(drop)),
        ("pgm3d", |b| read_pgm3d_bytes(b, Path::new(PATH)).map(drop)),
        ("vox", |b| read_vox_bytes(b, Path::new(PATH)).map(drop)),
        ("nifti", |b| read_nifti_bytes(b, Path::new(PATH)).map(drop)),
        ("vti", |b| read_vti_bytes(b, Path::new(PATH)).map(drop)),
        ("npy", |b| read_npy_bytes(b, Path::new(PATH)).map(drop)),
        ("tiff", |b| read_tiff_bytes(b, Path::new(PATH)).map(drop)),
        ("nrrd", |b| read_nrrd_bytes(b, Path::new(PATH)).map(drop)),
        ("mrc", |b| read_mrc_bytes(b, Path::new(PATH)).map(drop)),
        ("zarr", |b| read_zarr_entries(&unpack_store(b), Path::new(PATH)).map(drop)),
        ("raw", |b| {
            read_raw_bytes(b, Path::new(PATH), &RawSpec { dtype: DataType::U16, ..RawSpec::new([4, 3, 2]) })
                .map(drop)
        }),
    ]
}

/// Boundary values written over header numbers.
const NUMBERS: &[&str] = &[
    "0",
    "1",
    "-1",
    "2",
    "255",
    "256",
    "65535",
    "65536",
    "2147483648",
    "4294967296",
    "18446744073709551616",
    "1e308",
    "nan",
    "",
];

/// One random corruption of `seed`.
fn mutate(seed: &[u8], rng: &mut Xorshift) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(3) {
        match rng.below(7) {
            0 => b.truncate(rng.below(b.len() + 1)),
            1 => {
                for _ in 0..1 + rng.below(8) {
                    if !b.is_empty() {
                        let i = rng.below(b.len());
                        b[i] ^= 1 << rng.below(8);
                    }
                }
            }
            2 => {
                let i = rng.below(b.len() + 1);
                let n = 1 + rng.below(16);
                let bytes: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
                b.splice(i..i, bytes);
            }
            3 if !b.is_empty() => {
                let i = rng.below(b.len());
                let n = (1 + rng.below(16)).min(b.len() - i);
                b.drain(i..i + n);
            }
            4 => {
                // Replace a run of ASCII digits in the first 1 KiB by a boundary value.
                let head = b.len().min(1024);
                let runs: Vec<usize> = (0..head)
                    .filter(|&i| b[i].is_ascii_digit() && (i == 0 || !b[i - 1].is_ascii_digit()))
                    .collect();
                if !runs.is_empty() {
                    let start = runs[rng.below(runs.len())];
                    let end = (start..b.len()).find(|&i| !b[i].is_ascii_digit()).unwrap_or(b.len());
                    b.splice(start..end, NUMBERS[rng.below(NUMBERS.len())].bytes());
                }
            }
            5 => {
                // Overwrite 1, 2, 4 or 8 bytes of a binary header with an extreme value.
                if !b.is_empty() {
                    let width = 1 << rng.below(4);
                    let i = rng.below(b.len().min(512));
                    let v: u64 =
                        [0, 1, u64::MAX, 0x7fff, 0x8000, 0xffff, 0x7fff_ffff, 0xffff_ffff][rng.below(8)];
                    for k in 0..width.min(b.len() - i) {
                        b[i + k] = (v >> (8 * k)) as u8;
                    }
                }
            }
            _ => {
                // Duplicate a chunk (longer data than declared).
                if !b.is_empty() {
                    let i = rng.below(b.len());
                    let n = (1 + rng.below(64)).min(b.len() - i);
                    let chunk = b[i..i + n].to_vec();
                    b.extend_from_slice(&chunk);
                }
            }
        }
    }
    b
}

fn zlib(bytes: &[u8]) -> Vec<u8> {
    let mut e = ZlibEncoder::new(Vec::new(), Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut e = GzEncoder::new(Vec::new(), Compression::default());
    e.write_all(bytes).unwrap();
    e.finish().unwrap()
}

/// A small NIfTI-1 file: 4x3x2 int16, a qform flipping x.
fn nifti() -> Vec<u8> {
    let mut h = vec![0u8; 352];
    let mut put = |at: usize, v: &[u8]| h[at..at + v.len()].copy_from_slice(v);
    put(0, &348i32.to_le_bytes());
    for (k, d) in [3i16, 4, 3, 2].iter().enumerate() {
        put(40 + 2 * k, &d.to_le_bytes());
    }
    put(70, &4i16.to_le_bytes());
    for (k, v) in [1f32, 0.5, 1.0, 2.0].iter().enumerate() {
        put(76 + 4 * k, &v.to_le_bytes());
    }
    put(108, &352f32.to_le_bytes());
    put(112, &1f32.to_le_bytes());
    put(252, &1i16.to_le_bytes());
    put(264, &1f32.to_le_bytes()); // quatern_d = 1: x and y flipped
    put(344, b"n+1\0");
    h.extend((0..24i16).flat_map(|v| (v - 3).to_le_bytes()));
    h
}

/// Small `.vti` files in each encoding.
fn vtis() -> Vec<Vec<u8>> {
    let values: Vec<u8> = (0..24u16).flat_map(|v| v.to_le_bytes()).collect();
    let b64 = |b: &[u8]| base64_encode(b);
    let head = |root: &str, array: &str| {
        format!(
            "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" {root}>\n\
             <ImageData WholeExtent=\"0 4 0 3 0 2\" Origin=\"1 2 3\" Spacing=\"0.5 1 2\">\n\
             <Piece Extent=\"0 4 0 3 0 2\">\n<CellData Scalars=\"a\">\n{array}\n</CellData>\n</Piece>\n</ImageData>\n"
        )
    };
    let ascii: Vec<String> = (0..24).map(|v: u16| v.to_string()).collect();
    let mut files = vec![
        (head(
            "",
            &format!(
                "<DataArray type=\"UInt16\" Name=\"a\" format=\"ascii\">{}</DataArray>",
                ascii.join(" ")
            ),
        ) + "</VTKFile>\n")
            .into_bytes(),
        (head(
            "header_type=\"UInt32\"",
            &format!(
                "<DataArray type=\"UInt16\" Name=\"a\" format=\"binary\">{}{}</DataArray>",
                b64(&48u32.to_le_bytes()),
                b64(&values)
            ),
        ) + "</VTKFile>\n")
            .into_bytes(),
    ];
    let mut raw =
        head("", "<DataArray type=\"UInt16\" Name=\"a\" format=\"appended\" offset=\"0\"/>").into_bytes();
    raw.extend_from_slice(b"<AppendedData encoding=\"raw\">\n_");
    raw.extend_from_slice(&48u32.to_le_bytes());
    raw.extend_from_slice(&values);
    raw.extend_from_slice(b"\n</AppendedData>\n</VTKFile>\n");
    files.push(raw);
    let (a, b) = values.split_at(32);
    let (za, zb) = (zlib(a), zlib(b));
    let header: Vec<u8> =
        [2u64, 32, 16, za.len() as u64, zb.len() as u64].iter().flat_map(|w| w.to_le_bytes()).collect();
    let compressed = head(
        "header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\"",
        "<DataArray type=\"UInt16\" Name=\"a\" format=\"appended\" offset=\"0\"/>",
    ) + &format!(
        "<AppendedData encoding=\"base64\">\n   _{}{}\n</AppendedData>\n</VTKFile>\n",
        b64(&header),
        b64(&[za, zb].concat())
    );
    files.push(compressed.into_bytes());
    files
}

/// Standard base64 with padding (the crate is not a dev-dependency of this test).
fn base64_encode(bytes: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n = (u32::from(c[0]) << 16)
            | (u32::from(*c.get(1).unwrap_or(&0)) << 8)
            | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            if k <= c.len() {
                s.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                s.push('=');
            }
        }
    }
    s
}

fn npy() -> Vec<u8> {
    let mut header = "{'descr': '<f4', 'fortran_order': False, 'shape': (4, 3, 2), }".to_string();
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut b = b"\x93NUMPY\x01\x00".to_vec();
    b.extend_from_slice(&(header.len() as u16).to_le_bytes());
    b.extend_from_slice(header.as_bytes());
    b.extend((0..24).flat_map(|v| (v as f32 * 0.5).to_le_bytes()));
    b
}

/// The seeds of each reader: real files where small enough, synthetic ones otherwise.
fn seeds(reader: &str) -> Vec<Vec<u8>> {
    match reader {
        "vol" => vec![data("cat10.vol"), data("bunny-32.vol")],
        "longvol" => {
            let mut v3 = b"X: 4\nY: 3\nZ: 2\nLvoxel-Size: 4\nVersion: 3\n.\n".to_vec();
            v3.extend(zlib(&(0..24u64).flat_map(|v| (v << 30).to_le_bytes()).collect::<Vec<u8>>()));
            vec![data("test.longvol"), v3]
        }
        "pgm3d" => {
            vec![data("ascii_ball.pgm3d"), b"P3D\n# c\n4 3 2\n255\n".iter().copied().chain(0..24).collect()]
        }
        "vox" => vec![data("chr_army1.vox"), data("not_a.vox")],
        "nifti" => vec![nifti(), gzip(&nifti())],
        "vti" => vtis(),
        "npy" => vec![npy()],
        "mrc" => vec![data("formats/mode1.mrc"), data("formats/mode6.mrc")],
        "nrrd" => vec![data("formats/labels.nrrd"), data("formats/organs.seg.nrrd")],
        "tiff" => vec![data("formats/stack_imagej.tif"), data("formats/stack.ome.tif")],
        "raw" => vec![(0..48).collect(), [0u8; 48].to_vec()],
        "zarr" => ["labels_v2.zarr", "labels_v3.zarr", "labels_sharded.zarr", "image.ome.zarr"]
            .iter()
            .map(|name| {
                pack_store(&Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/formats")).join(name))
            })
            .collect(),
        _ => unreachable!(),
    }
}

/// The separator of a packed Zarr store (what the `zarr` fuzz target reads): entries
/// `key\n<bytes>` joined by it.
const STORE_SEPARATOR: &[u8] = b"\n%%\n";

/// A packed store's entries, as the `zarr` fuzz target splits them.
fn unpack_store(bytes: &[u8]) -> Vec<(&str, &[u8])> {
    let mut entries = Vec::new();
    let mut rest = bytes;
    loop {
        let end = rest.windows(STORE_SEPARATOR.len()).position(|w| w == STORE_SEPARATOR);
        let entry = &rest[..end.unwrap_or(rest.len())];
        let key_end = entry.iter().position(|&b| b == b'\n').unwrap_or(entry.len());
        if let Ok(key) = std::str::from_utf8(&entry[..key_end]) {
            entries.push((key, entry.get(key_end + 1..).unwrap_or(&[])));
        }
        match end {
            Some(e) => rest = &rest[e + STORE_SEPARATOR.len()..],
            None => return entries,
        }
    }
}

/// The files of the Zarr directory `dir`, packed (keys relative to it, in name order).
fn pack_store(dir: &Path) -> Vec<u8> {
    fn walk(dir: &Path, prefix: &str, out: &mut Vec<(String, Vec<u8>)>) {
        let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
        entries.sort();
        for path in entries {
            let key = format!("{prefix}{}", path.file_name().unwrap().to_str().unwrap());
            if path.is_dir() {
                walk(&path, &format!("{key}/"), out);
            } else {
                out.push((key, std::fs::read(&path).unwrap()));
            }
        }
    }
    let mut files = Vec::new();
    walk(dir, "", &mut files);
    let packed: Vec<Vec<u8>> =
        files.into_iter().map(|(key, bytes)| [key.as_bytes(), b"\n", &bytes].concat()).collect();
    packed.join(STORE_SEPARATOR)
}

/// Runs `read` on `bytes`; on a panic, saves the input and fails.
fn check(name: &str, read: Reader, bytes: &[u8], what: &str) {
    let outcome = catch_unwind(AssertUnwindSafe(|| read(bytes)));
    match outcome {
        Ok(Ok(())) => {}
        Ok(Err(e)) => {
            let text = e.to_string();
            assert!(text.starts_with(&format!("{PATH}: ")), "{name} {what}: error without the path: {text}");
        }
        Err(_) => {
            let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR"));
            let file = dir.join(format!("crash-{name}-{}.bin", what.replace(' ', "_")));
            std::fs::write(&file, bytes).unwrap();
            panic!("{name} panicked on {what}; input saved to {}", file.display());
        }
    }
}

#[test]
fn mutated_inputs_never_panic() {
    let iterations: usize =
        std::env::var("VOXREG_MUTATIONS").ok().and_then(|v| v.parse().ok()).unwrap_or(2000);
    for (name, read) in readers() {
        let seeds = seeds(name);
        for (s, seed) in seeds.iter().enumerate() {
            // Every seed is itself valid (not_a.vox excepted).
            if !(name == "vox" && s == 1) {
                assert!(read(seed).is_ok(), "{name} seed {s}: {:?}", read(seed).unwrap_err());
            }
            let mut rng = Xorshift::new(0x9e37_79b9_7f4a_7c15 ^ ((s as u64 + 1) << 32) ^ name.len() as u64);
            for i in 0..iterations / seeds.len() {
                let bytes = mutate(seed, &mut rng);
                check(name, read, &bytes, &format!("seed {s} mutation {i}"));
            }
        }
    }
}

#[test]
fn every_reader_refuses_every_other_format() {
    let all: Vec<(&str, Vec<u8>)> =
        readers().iter().flat_map(|(n, _)| seeds(n).into_iter().map(|s| (*n, s))).collect();
    for (name, read) in readers() {
        for (other, bytes) in &all {
            if *other != name && name != "raw" {
                // Raw data accept any 48 bytes; the others must see the wrong format.
                assert!(read(bytes).is_err(), "{name} accepted a {other} file");
            }
            check(name, read, bytes, &format!("a {other} file"));
        }
    }
}

#[test]
fn regressions_never_panic() {
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/regressions"));
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    let readers = readers();
    for entry in entries {
        let path = entry.unwrap().path();
        let name = path.file_name().unwrap().to_str().unwrap().to_string();
        if !name.ends_with(".bin") {
            continue;
        }
        let reader = name.split('-').next().unwrap();
        let (_, read) =
            readers.iter().find(|(n, _)| *n == reader).unwrap_or_else(|| panic!("{name}: no reader"));
        check(reader, *read, &std::fs::read(&path).unwrap(), &name);
    }
}

/// Found by `cargo fuzz run vox`: a 4.5 KB `.vox` whose single model declares
/// 10621184 x 7 x 12 voxels (under `MAX_VOXELS`) makes `read_vox_bytes` allocate the
/// dense volume, 3.5 GB of labels, for 171 voxels. Not a panic, so not replayed with the
/// `.bin` regressions; ignored until the `.vox` reader bounds model sizes (MagicaVoxel's
/// own limit is 256 per axis).
#[test]
fn vox_sparse_model_of_892m_voxels_is_refused() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/regressions/vox-sparse-model-of-892M-voxels.oom");
    let bytes = std::fs::read(path).unwrap();
    assert!(read_vox_bytes(&bytes, Path::new(PATH)).is_err());
}

#[test]
fn endianness_of_the_raw_spec_matters() {
    let spec = RawSpec { endian: Endian::Big, dtype: DataType::U16, ..RawSpec::new([1, 1, 1]) };
    let v = read_raw_bytes(&[1, 2], Path::new(PATH), &spec).unwrap();
    assert_eq!(v.clone().into_labels().unwrap().label([0, 0, 0]), Some(0x0102));
}

/// Replays the fuzzing seeds (`fuzz/seeds/<target>/`, small files from `data/` and
/// crashes found by fuzzing, kept as regressions) through the function each target
/// fuzzes, under a 1 GiB memory budget: every `cargo test` runs them, with no nightly
/// toolchain.
#[test]
fn fuzz_corpora_replay_without_panic() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../fuzz/seeds"));
    let readers = readers();
    let mut replayed = 0;
    for dir in std::fs::read_dir(root).unwrap() {
        let dir = dir.unwrap().path();
        let target = dir.file_name().unwrap().to_str().unwrap().to_string();
        for file in std::fs::read_dir(&dir).unwrap() {
            let file = file.unwrap().path();
            let bytes = std::fs::read(&file).unwrap();
            let what = file.display().to_string();
            voxreg_io::with_max_memory(1 << 30, || match target.as_str() {
                "mesh" => {
                    let result = catch_unwind(|| {
                        let Some((&pick, rest)) = bytes.split_first() else { return };
                        let name = if pick % 2 == 0 { "fuzz.obj" } else { "fuzz.ply" };
                        let _ = voxreg_io::read_mesh_bytes(rest, Path::new(name));
                    });
                    assert!(result.is_ok(), "{what}: panicked");
                }
                "regions" => {
                    let text = String::from_utf8_lossy(&bytes).into_owned();
                    let result = catch_unwind(|| voxreg_digisurf::RegionMap::parse(&text).is_ok());
                    assert!(result.is_ok(), "{what}: panicked");
                }
                // The front door's target; its seeds are replayed by voxreg-regularize's tests.
                "pipeline" => {}
                // The viewer's requests; replayed by voxreg-view's tests (`fuzz_requests.rs`).
                "request" => {}
                reader => {
                    let (_, read) = readers
                        .iter()
                        .find(|(n, _)| *n == reader)
                        .unwrap_or_else(|| panic!("{what}: no reader"));
                    check(reader, *read, &bytes, &what);
                }
            });
            replayed += 1;
        }
    }
    assert!(replayed >= 20, "{replayed} corpus files");
}
