//! NIfTI-1 volumes: single-file `.nii`, and `.nii.gz`.
//!
//! The format: a 348-byte binary header (its first field, `sizeof_hdr = 348`, tells the
//! byte order), optional extensions, then the voxel data from byte `vox_offset`, `x`
//! (`i`) fastest, then `y`, then `z`. A `.nii.gz` file is the same, gzipped.

use std::io::Read;
use std::path::Path;

use flate2::read::MultiGzDecoder;
use glam::{DMat3, DVec3};

use crate::error::IoError;
use crate::files::{checked_voxel_count, read_file};
use crate::grey::Voxels;
use crate::orient::place;
use crate::samples::{check_data_len, data_len, decode, Layout, Order};
use crate::samples::{DataType, Endian};

/// Size of a NIfTI-1 header.
const HEADER_LEN: usize = 348;
/// Size of a NIfTI-2 header (refused).
const NIFTI2_HEADER_LEN: i32 = 540;
const GZIP_MAGIC: &[u8] = &[0x1f, 0x8b];

/// Reads a NIfTI-1 file (`.nii`, or gzipped `.nii.gz`). See [`read_nifti_bytes`].
pub fn read_nifti(path: &Path) -> Result<Voxels, IoError> {
    read_nifti_bytes(&read_file(path)?, path)
}

/// Reads a NIfTI-1 file held in memory, gzipped or not (told by the gzip magic, not
/// the name); `path` only names the file in errors.
///
/// **Data.** `datatype` may be `uint8`, `int8`, `uint16`, `int16`, `uint32`, `int32`,
/// `uint64`, `int64`, `float32` or `float64` (codes 2, 256, 512, 4, 768, 8, 1280,
/// 1024, 16, 64), in either byte order. When `scl_slope` is neither `0` nor `1` or
/// `scl_inter` is not `0`, values are scaled, `value * scl_slope + scl_inter`. Values are
/// labels (background `0`) when all are integers in `0..=u32::MAX`, grey levels
/// otherwise; a NaN is an error.
///
/// **Space.** Spacing and origin come from the header, in its units (`xyzt_units` is
/// not applied; usually millimetres). The index-to-world map is the sform when
/// `sform_code > 0`, else the qform (quaternion, `qfac`, `pixdim`) when
/// `qform_code > 0`, else `pixdim` alone with origin `0` (the precedence of nibabel).
/// When that map only scales, permutes and flips the axes (e.g. the usual
/// `diag(-1, -1, 1)` of radiological scanners), the volume is re-stored so that every
/// voxel centre is exactly where the map puts it in world (RAS+) coordinates. An oblique
/// rotation cannot be represented: it is dropped, keeping the map's voxel sizes and its
/// translation as the origin.
///
/// **Refused.** A file with neither byte order giving `sizeof_hdr = 348`, or without
/// the `n+1` magic, is an [`IoError::Format`]; NIfTI-2, header/image pairs (`ni1`),
/// other data types (bit, complex, RGB, float128) and 4-D or higher data are
/// [`IoError::Unsupported`]. A truncated header or data, data longer than declared, bad
/// dimensions, `vox_offset` and corrupt gzip are [`IoError::Format`]; volumes above
/// [`MAX_VOXELS`](crate::files::MAX_VOXELS) are [`IoError::TooLarge`], checked before any
/// allocation (and a `.nii.gz` is never inflated beyond its declared size plus one byte).
pub fn read_nifti_bytes(bytes: &[u8], path: &Path) -> Result<Voxels, IoError> {
    let inflated;
    let bytes = if bytes.starts_with(GZIP_MAGIC) {
        inflated = inflate(bytes, path)?;
        &inflated[..]
    } else {
        bytes
    };
    let header = Header::parse(bytes, path)?;
    let layout = header.layout;
    let expected = data_len(&layout) as usize;
    let data = bytes.get(header.vox_offset..).unwrap_or_default();
    check_data_len(path, data.len(), expected, &layout)?;
    let voxels = decode(path, data, layout, header.scale)?;
    let (voxels, _) = place(voxels, header.matrix, header.translation)
        .map_err(|source| IoError::Volume { path: path.to_path_buf(), source })?;
    Ok(voxels)
}

/// Inflates a `.nii.gz`: the header first, then no more than it declares (plus one
/// byte, so that longer data is still detected).
fn inflate(bytes: &[u8], path: &Path) -> Result<Vec<u8>, IoError> {
    let corrupt = |e: std::io::Error| IoError::format(path, format!("corrupt or truncated gzip data: {e}"));
    let mut decoder = MultiGzDecoder::new(bytes);
    let mut out = Vec::with_capacity(HEADER_LEN);
    (&mut decoder).take(HEADER_LEN as u64).read_to_end(&mut out).map_err(corrupt)?;
    let header = Header::parse(&out, path)?;
    let total = header.vox_offset as u64 + data_len(&header.layout);
    (&mut decoder).take(total + 1 - HEADER_LEN as u64).read_to_end(&mut out).map_err(corrupt)?;
    Ok(out)
}

/// What the header says.
struct Header {
    layout: Layout,
    vox_offset: usize,
    scale: Option<(f64, f64)>,
    /// Index-to-world map: columns are the world steps of `i`, `j`, `k`.
    matrix: DMat3,
    translation: DVec3,
}

impl Header {
    /// Parses the header at the start of `bytes` (which may hold more).
    fn parse(bytes: &[u8], path: &Path) -> Result<Header, IoError> {
        let not_nifti = |message: String| IoError::format(path, format!("not a NIfTI-1 file: {message}"));
        let Some(&[a, b, c, d]) = bytes.get(..4) else {
            return Err(not_nifti(format!("{} bytes, too short for a header", bytes.len())));
        };
        let (le, be) = (i32::from_le_bytes([a, b, c, d]), i32::from_be_bytes([a, b, c, d]));
        let endian = if le == HEADER_LEN as i32 {
            Endian::Little
        } else if be == HEADER_LEN as i32 {
            Endian::Big
        } else if le == NIFTI2_HEADER_LEN || be == NIFTI2_HEADER_LEN {
            return Err(IoError::unsupported(path, "NIfTI-2 (only NIfTI-1 is read)"));
        } else {
            return Err(not_nifti(format!("sizeof_hdr is {le}, not 348")));
        };
        if bytes.len() < HEADER_LEN {
            return Err(IoError::format(
                path,
                format!("truncated header: {HEADER_LEN} bytes needed, {} found", bytes.len()),
            ));
        }
        let h = Fields { bytes, endian };
        match &bytes[344..348] {
            b"n+1\0" => {}
            b"ni1\0" => {
                return Err(IoError::unsupported(
                    path,
                    "header/image pair (magic ni1: the data are in a separate .img file)",
                ))
            }
            m => return Err(not_nifti(format!("magic '{}', not 'n+1'", m.escape_ascii()))),
        }

        let dim: [i16; 8] = std::array::from_fn(|k| h.i16(40 + 2 * k));
        let ndim = dim[0];
        if !(1..=7).contains(&ndim) {
            return Err(IoError::format(
                path,
                format!("dim[0] = {ndim}: the number of dimensions must be 1 to 7"),
            ));
        }
        let ndim = ndim as usize;
        let mut dims = [1u64; 3];
        for k in 1..=ndim.min(3) {
            if dim[k] < 1 {
                return Err(IoError::format(
                    path,
                    format!("dim[{k}] = {}: each dimension must be at least 1", dim[k]),
                ));
            }
            dims[k - 1] = dim[k] as u64;
        }
        if let Some(k) = (4..=ndim).find(|&k| dim[k] > 1) {
            return Err(IoError::unsupported(
                path,
                format!("{ndim}-D data with dim[{k}] = {}: only 3-D volumes are read", dim[k]),
            ));
        }
        let code = h.i16(70);
        let dtype = match code {
            2 => DataType::U8,
            4 => DataType::I16,
            8 => DataType::I32,
            16 => DataType::F32,
            64 => DataType::F64,
            256 => DataType::I8,
            512 => DataType::U16,
            768 => DataType::U32,
            1024 => DataType::I64,
            1280 => DataType::U64,
            _ => {
                let name = match code {
                    0 => "unknown",
                    1 => "binary",
                    32 => "complex64",
                    128 => "rgb24",
                    1536 => "float128",
                    1792 => "complex128",
                    2048 => "complex256",
                    2304 => "rgba32",
                    _ => "not a NIfTI-1 type",
                };
                return Err(IoError::unsupported(
                    path,
                    format!("datatype {code} ({name}): only integers of 8 to 64 bits, float32 and float64 are read"),
                ));
            }
        };
        checked_voxel_count(path, dims, dtype.size() as u64 + 8)?;
        let layout = Layout { dims: dims.map(|d| d as usize), dtype, endian, order: Order::XFastest };

        let vox_offset = h.f32(108);
        if !(vox_offset.is_finite() && (HEADER_LEN as f64..=f64::from(u32::MAX)).contains(&vox_offset)) {
            return Err(IoError::format(path, format!("vox_offset {vox_offset}: must be at least 348")));
        }
        let (slope, inter) = (h.f32(112), h.f32(116));
        let scale =
            (slope.is_finite() && slope != 0.0 && (slope != 1.0 || (inter.is_finite() && inter != 0.0)))
                .then_some((slope, if inter.is_finite() { inter } else { 0.0 }));

        let pixdim: [f64; 8] = std::array::from_fn(|k| h.f32(76 + 4 * k));
        let (qform_code, sform_code) = (h.i16(252), h.i16(254));
        let (matrix, translation) = if sform_code > 0 {
            let row = |r: usize| [0, 1, 2, 3].map(|c| h.f32(280 + 16 * r + 4 * c));
            let rows = [row(0), row(1), row(2)];
            let col = |c: usize| DVec3::new(rows[0][c], rows[1][c], rows[2][c]);
            (DMat3::from_cols(col(0), col(1), col(2)), col(3))
        } else if qform_code > 0 {
            let [b, c, d, qx, qy, qz] = [0, 1, 2, 3, 4, 5].map(|k| h.f32(256 + 4 * k));
            let qfac = if pixdim[0] < 0.0 { -1.0 } else { 1.0 };
            let r = quaternion_matrix(b, c, d);
            let step = DVec3::new(pixdim[1].abs(), pixdim[2].abs(), pixdim[3].abs() * qfac);
            (
                DMat3::from_cols(r.x_axis * step.x, r.y_axis * step.y, r.z_axis * step.z),
                DVec3::new(qx, qy, qz),
            )
        } else {
            (DMat3::from_diagonal(DVec3::new(pixdim[1].abs(), pixdim[2].abs(), pixdim[3].abs())), DVec3::ZERO)
        };
        Ok(Header { layout, vox_offset: vox_offset as usize, scale, matrix, translation })
    }
}

/// The rotation of the NIfTI-1 quaternion `(a, b, c, d)`, `a` completed from `b, c, d`
/// (as `nifti_quatern_to_mat44` does).
fn quaternion_matrix(b: f64, c: f64, d: f64) -> DMat3 {
    let n = b * b + c * c + d * d;
    let (a, b, c, d) = if 1.0 - n < 1e-7 {
        // A 180-degree rotation: normalize (b, c, d), a = 0.
        let s = if n > 0.0 { 1.0 / n.sqrt() } else { 0.0 };
        (0.0, b * s, c * s, d * s)
    } else {
        ((1.0 - n).sqrt(), b, c, d)
    };
    DMat3::from_cols(
        DVec3::new(a * a + b * b - c * c - d * d, 2.0 * (b * c + a * d), 2.0 * (b * d - a * c)),
        DVec3::new(2.0 * (b * c - a * d), a * a + c * c - b * b - d * d, 2.0 * (c * d + a * b)),
        DVec3::new(2.0 * (b * d + a * c), 2.0 * (c * d - a * b), a * a + d * d - c * c - b * b),
    )
}

/// Typed access to the header's fields.
struct Fields<'a> {
    bytes: &'a [u8],
    endian: Endian,
}

impl Fields<'_> {
    fn array<const N: usize>(&self, at: usize) -> [u8; N] {
        std::array::from_fn(|k| self.bytes[at + k])
    }

    fn i16(&self, at: usize) -> i16 {
        match self.endian {
            Endian::Little => i16::from_le_bytes(self.array(at)),
            Endian::Big => i16::from_be_bytes(self.array(at)),
        }
    }

    fn f32(&self, at: usize) -> f64 {
        f64::from(match self.endian {
            Endian::Little => f32::from_le_bytes(self.array(at)),
            Endian::Big => f32::from_be_bytes(self.array(at)),
        })
    }
}

#[cfg(test)]
mod tests {
    use std::io::Write;

    use flate2::write::GzEncoder;
    use flate2::Compression;

    use super::*;

    const P: &str = "brain.nii";

    /// A minimal NIfTI-1 header builder, little endian unless `big`.
    struct Nii {
        bytes: Vec<u8>,
        big: bool,
    }

    impl Nii {
        fn new(dims: [i16; 3], datatype: i16, big: bool) -> Self {
            let mut n = Nii { bytes: vec![0; 352], big };
            n.i32(0, 348);
            n.i16(40, 3);
            for (k, &d) in dims.iter().enumerate() {
                n.i16(42 + 2 * k, d);
            }
            n.i16(70, datatype);
            for k in 0..4 {
                n.f32(76 + 4 * k, 1.0);
            }
            n.f32(108, 352.0);
            n.f32(112, 1.0);
            n.bytes[344..348].copy_from_slice(b"n+1\0");
            n
        }
        fn put(&mut self, at: usize, le: &[u8]) {
            let mut b = le.to_vec();
            if self.big {
                b.reverse();
            }
            self.bytes[at..at + b.len()].copy_from_slice(&b);
        }
        fn i16(&mut self, at: usize, v: i16) {
            self.put(at, &v.to_le_bytes());
        }
        fn i32(&mut self, at: usize, v: i32) {
            self.put(at, &v.to_le_bytes());
        }
        fn f32(&mut self, at: usize, v: f32) {
            self.put(at, &v.to_le_bytes());
        }
        fn with(mut self, data: &[u8]) -> Vec<u8> {
            self.bytes.extend_from_slice(data);
            self.bytes
        }
    }

    fn read(bytes: &[u8]) -> Result<Voxels, IoError> {
        read_nifti_bytes(bytes, Path::new(P))
    }

    fn message(bytes: &[u8]) -> String {
        let text = read(bytes).unwrap_err().to_string();
        assert!(text.starts_with("brain.nii: "), "{text}");
        text
    }

    fn labels(v: Voxels) -> voxreg_digisurf::LabelVolume {
        match v {
            Voxels::Labels(v) => v,
            Voxels::Grey(g) => panic!("labels expected, got grey {:?}", g.dims()),
        }
    }

    fn gzip(bytes: &[u8]) -> Vec<u8> {
        let mut enc = GzEncoder::new(Vec::new(), Compression::default());
        enc.write_all(bytes).unwrap();
        enc.finish().unwrap()
    }

    #[test]
    fn bundled_lobster() {
        let bytes =
            std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/lobsterCroped2.nii.gz")).unwrap();
        let v = labels(read(&bytes).unwrap());
        assert_eq!(v.dims(), [101, 101, 41]);
        assert_eq!(v.spacing(), DVec3::ONE);
        // qform: quaternion (0, 0, 1), i.e. diag(-1, -1, 1), offset (-50, -50, 10): x and y
        // are flipped, so the new voxel 0 is the stored voxel 100 along x and y.
        assert_eq!(v.origin(), DVec3::new(-150.0, -150.0, 10.0));
        let counts = v.label_counts();
        assert_eq!(counts.iter().map(|c| c.1).sum::<u64>(), 101 * 101 * 41);
        assert_eq!(counts.last().unwrap().0, 253);
        // Decompressed data: stored voxel (i, j, k) at byte 352 + i + 101 (j + 101 k).
        let raw = {
            let mut out = Vec::new();
            MultiGzDecoder::new(&bytes[..]).read_to_end(&mut out).unwrap();
            out
        };
        for (i, j, k) in [(0, 0, 0), (3, 70, 20), (100, 5, 40)] {
            let stored = raw[352 + i + 101 * (j + 101 * k)];
            assert_eq!(v.label([100 - i as i64, 100 - j as i64, k as i64]), Some(u32::from(stored)));
        }
    }

    #[test]
    fn types_byte_orders_and_gzip() {
        let values = [0i16, 300, 7, 2];
        for big in [false, true] {
            let data: Vec<u8> =
                values.iter().flat_map(|v| if big { v.to_be_bytes() } else { v.to_le_bytes() }).collect();
            let mut n = Nii::new([2, 2, 1], 4, big);
            n.f32(80, 0.5); // pixdim[1]
            n.f32(84, 2.0);
            let bytes = n.with(&data);
            for b in [bytes.clone(), gzip(&bytes)] {
                let v = labels(read(&b).unwrap());
                assert_eq!(v.label([1, 0, 0]), Some(300));
                assert_eq!(v.label([0, 1, 0]), Some(7));
                assert_eq!(v.spacing(), DVec3::new(0.5, 2.0, 1.0));
                assert_eq!(v.origin(), DVec3::ZERO);
            }
        }
        let floats: Vec<u8> = [0.5f32, 1.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        let Voxels::Grey(g) = read(&Nii::new([2, 1, 1], 16, false).with(&floats)).unwrap() else { panic!() };
        assert_eq!(g.values()[[0, 0, 0]], 0.5);
    }

    #[test]
    fn scaling_and_sform() {
        let mut n = Nii::new([2, 1, 1], 2, false);
        n.f32(112, 0.5);
        n.f32(116, -1.0);
        let Voxels::Grey(g) = read(&n.with(&[0, 5])).unwrap() else { panic!("grey expected") };
        assert_eq!(g.values()[[1, 0, 0]], 1.5);
        let mut n = Nii::new([2, 1, 1], 2, false);
        n.f32(112, 2.0);
        n.f32(116, 1.0);
        assert_eq!(labels(read(&n.with(&[0, 5])).unwrap()).label([1, 0, 0]), Some(11));

        // sform: i -> -z (step 3), j -> x (step 2), k -> y (step 1), offset (1, 2, 3).
        let mut n = Nii::new([2, 3, 4], 2, false);
        n.i16(254, 2);
        let rows = [[0.0, 2.0, 0.0, 1.0], [0.0, 0.0, 1.0, 2.0], [-3.0, 0.0, 0.0, 3.0]];
        for (r, row) in rows.iter().enumerate() {
            for (c, &v) in row.iter().enumerate() {
                n.f32(280 + 16 * r + 4 * c, v);
            }
        }
        let data: Vec<u8> = (0..24).collect();
        let v = labels(read(&n.with(&data)).unwrap());
        assert_eq!(v.dims(), [3, 4, 2]);
        assert_eq!(v.spacing(), DVec3::new(2.0, 1.0, 3.0));
        for (i, j, k) in [(0usize, 0usize, 0usize), (1, 2, 3), (1, 0, 2)] {
            let world = DVec3::new(1.0 + 2.0 * j as f64, 2.0 + k as f64, 3.0 - 3.0 * i as f64);
            let q = ((world - v.origin()) / v.spacing()).round();
            let label = v.label([q.x as i64, q.y as i64, q.z as i64]);
            assert_eq!(label, Some((i + 2 * (j + 3 * k)) as u32), "{i} {j} {k}");
        }
    }

    #[test]
    fn bad_input() {
        let ok = || Nii::new([2, 1, 1], 2, false);
        let set = |f: &dyn Fn(&mut Nii)| {
            let mut n = ok();
            f(&mut n);
            n.with(&[0, 0])
        };
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (b"".to_vec(), "not a NIfTI-1 file: 0 bytes"),
            (b"hello world".to_vec(), "not a NIfTI-1 file: sizeof_hdr is"),
            (ok().bytes[..200].to_vec(), "truncated header: 348 bytes needed, 200 found"),
            (set(&|n| n.i32(0, 540)), "unsupported: NIfTI-2"),
            (set(&|n| n.bytes[344..348].copy_from_slice(b"ni1\0")), "unsupported: header/image pair"),
            (set(&|n| n.bytes[344..348].copy_from_slice(b"\0\0\0\0")), "magic"),
            (set(&|n| n.i16(40, 0)), "dim[0] = 0"),
            (set(&|n| n.i16(40, 9)), "dim[0] = 9"),
            (set(&|n| n.i16(44, -3)), "dim[2] = -3"),
            (
                set(&|n| {
                    n.i16(40, 4);
                    n.i16(48, 5)
                }),
                "unsupported: 4-D data with dim[4] = 5",
            ),
            (set(&|n| n.i16(70, 128)), "unsupported: datatype 128 (rgb24)"),
            (set(&|n| n.i16(70, 3)), "unsupported: datatype 3"),
            (set(&|n| n.f32(108, 10.0)), "vox_offset 10"),
            (set(&|n| n.f32(108, f32::NAN)), "vox_offset NaN"),
            (set(&|n| n.f32(108, 400.0)), "truncated voxel data"),
            (ok().with(&[0]), "truncated voxel data: 2x1x1 voxels of u8"),
            (ok().with(&[0, 0, 0]), "dimensions do not match the data"),
            (set(&|n| n.f32(80, 0.0)), "degenerate index-to-world map"),
            (
                set(&|n| {
                    n.i16(252, 1);
                    n.f32(80, 0.0)
                }),
                "degenerate",
            ),
            (gzip(&ok().with(&[0]))[..20].to_vec(), "corrupt or truncated gzip data"),
            (gzip(&ok().with(&[0])), "truncated voxel data"),
            (gzip(&ok().with(&[0, 0, 0, 0])), "dimensions do not match the data"),
        ];
        crate::testing::assert_refused(&cases, message);
        let mut nan = Nii::new([2, 1, 1], 16, false);
        nan.f32(112, 1.0);
        let data: Vec<u8> = [1.0f32, f32::NAN].iter().flat_map(|v| v.to_le_bytes()).collect();
        assert!(message(&nan.with(&data)).contains("grey level NaN at voxel [1, 0, 0]"));
        let huge = Nii::new([30000, 30000, 30000], 2, false).with(&[0; 16]);
        assert!(matches!(read(&huge), Err(IoError::TooLarge { .. })));
        assert!(matches!(read(&gzip(&huge)), Err(IoError::TooLarge { .. })));
    }
}
