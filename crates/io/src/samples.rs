//! Binary sample types, and the decoding of samples into labels or grey levels.

use std::fmt;
use std::path::Path;
use std::str::FromStr;

use ndarray::Array3;
use voxreg_digisurf::LabelVolume;

use crate::error::IoError;
use crate::grey::as_label;
use crate::grey::{GreyVolume, Voxels};

/// The type of one voxel value in a binary file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DataType {
    /// Unsigned 8-bit integer.
    U8,
    /// Signed 8-bit integer.
    I8,
    /// Unsigned 16-bit integer.
    U16,
    /// Signed 16-bit integer.
    I16,
    /// Unsigned 32-bit integer.
    U32,
    /// Signed 32-bit integer.
    I32,
    /// Unsigned 64-bit integer.
    U64,
    /// Signed 64-bit integer.
    I64,
    /// IEEE 754 single-precision float.
    F32,
    /// IEEE 754 double-precision float.
    F64,
}

impl DataType {
    /// Every data type, in declaration order.
    pub const ALL: [DataType; 10] = [
        DataType::U8,
        DataType::I8,
        DataType::U16,
        DataType::I16,
        DataType::U32,
        DataType::I32,
        DataType::U64,
        DataType::I64,
        DataType::F32,
        DataType::F64,
    ];

    /// The size of one value in bytes.
    pub fn size(self) -> usize {
        match self {
            DataType::U8 | DataType::I8 => 1,
            DataType::U16 | DataType::I16 => 2,
            DataType::U32 | DataType::I32 | DataType::F32 => 4,
            DataType::U64 | DataType::I64 | DataType::F64 => 8,
        }
    }

    /// The short name: `u8`, `i8`, ..., `f32`, `f64` (what [`FromStr`] parses).
    pub fn name(self) -> &'static str {
        match self {
            DataType::U8 => "u8",
            DataType::I8 => "i8",
            DataType::U16 => "u16",
            DataType::I16 => "i16",
            DataType::U32 => "u32",
            DataType::I32 => "i32",
            DataType::U64 => "u64",
            DataType::I64 => "i64",
            DataType::F32 => "f32",
            DataType::F64 => "f64",
        }
    }
}

impl fmt::Display for DataType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for DataType {
    type Err = String;

    /// Parses a short name (`u8`, `i16`, `f32`, ...), case insensitive.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let lower = s.to_ascii_lowercase();
        DataType::ALL.into_iter().find(|t| t.name() == lower).ok_or_else(|| {
            let names: Vec<&str> = DataType::ALL.iter().map(|t| t.name()).collect();
            format!("unknown data type '{s}' (expected one of {})", names.join(", "))
        })
    }
}

/// The byte order of multi-byte values.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Endian {
    /// Least significant byte first (x86, ARM; the default).
    #[default]
    Little,
    /// Most significant byte first.
    Big,
}

impl FromStr for Endian {
    type Err = String;

    /// Parses `little` (or `le`) and `big` (or `be`), case insensitive.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.to_ascii_lowercase().as_str() {
            "little" | "le" => Ok(Endian::Little),
            "big" | "be" => Ok(Endian::Big),
            _ => Err(format!("unknown byte order '{s}' (expected little or big)")),
        }
    }
}

/// The order of a volume's values in a file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Order {
    /// `x` fastest, then `y`, then `z` (Fortran order of an `(X, Y, Z)` array).
    XFastest,
    /// `z` fastest, then `y`, then `x` (C order of an `(X, Y, Z)` array).
    ZFastest,
}

impl Order {
    /// The voxel of the `i`-th value.
    fn voxel(self, dims: [usize; 3], i: usize) -> [usize; 3] {
        match self {
            Order::XFastest => [i % dims[0], (i / dims[0]) % dims[1], i / (dims[0] * dims[1])],
            Order::ZFastest => [i / (dims[1] * dims[2]), (i / dims[2]) % dims[1], i % dims[2]],
        }
    }
}

/// One value of a [`DataType`].
trait Sample: Copy {
    const SIZE: usize;
    fn read(bytes: &[u8], endian: Endian) -> Self;
    fn label(self) -> Option<u32>;
    fn grey(self) -> f64;
}

macro_rules! sample {
    ($t:ty, int) => {
        sample!($t, |v: $t| u32::try_from(v).ok());
    };
    ($t:ty, float) => {
        sample!($t, |v: $t| as_label(v as f64));
    };
    ($t:ty, $label:expr) => {
        impl Sample for $t {
            const SIZE: usize = std::mem::size_of::<$t>();
            fn read(bytes: &[u8], endian: Endian) -> Self {
                let mut b = [0u8; std::mem::size_of::<$t>()];
                b.copy_from_slice(bytes);
                match endian {
                    Endian::Little => <$t>::from_le_bytes(b),
                    Endian::Big => <$t>::from_be_bytes(b),
                }
            }
            fn label(self) -> Option<u32> {
                ($label)(self)
            }
            fn grey(self) -> f64 {
                self as f64
            }
        }
    };
}

sample!(u8, int);
sample!(i8, int);
sample!(u16, int);
sample!(i16, int);
sample!(u32, int);
sample!(i32, int);
sample!(u64, int);
sample!(i64, int);
sample!(f32, float);
sample!(f64, float);

/// The layout of a volume's values in a byte buffer.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layout {
    /// The volume's dimensions.
    pub(crate) dims: [usize; 3],
    /// The type of each value.
    pub(crate) dtype: DataType,
    /// Their byte order.
    pub(crate) endian: Endian,
    /// Their order.
    pub(crate) order: Order,
}

/// Decodes `bytes`, exactly the values of `layout`, into labels when every value (after
/// `scale`, `value * slope + intercept`) is an integer in `0..=u32::MAX`, and into grey
/// levels otherwise. A NaN is an [`IoError::Format`] naming the voxel.
pub(crate) fn decode(
    path: &Path,
    bytes: &[u8],
    layout: Layout,
    scale: Option<(f64, f64)>,
) -> Result<Voxels, IoError> {
    match layout.dtype {
        DataType::U8 => decode_as::<u8>(path, bytes, layout, scale),
        DataType::I8 => decode_as::<i8>(path, bytes, layout, scale),
        DataType::U16 => decode_as::<u16>(path, bytes, layout, scale),
        DataType::I16 => decode_as::<i16>(path, bytes, layout, scale),
        DataType::U32 => decode_as::<u32>(path, bytes, layout, scale),
        DataType::I32 => decode_as::<i32>(path, bytes, layout, scale),
        DataType::U64 => decode_as::<u64>(path, bytes, layout, scale),
        DataType::I64 => decode_as::<i64>(path, bytes, layout, scale),
        DataType::F32 => decode_as::<f32>(path, bytes, layout, scale),
        DataType::F64 => decode_as::<f64>(path, bytes, layout, scale),
    }
}

fn decode_as<T: Sample>(
    path: &Path,
    bytes: &[u8],
    layout: Layout,
    scale: Option<(f64, f64)>,
) -> Result<Voxels, IoError> {
    let Layout { dims, endian, order, .. } = layout;
    let count = dims.iter().product::<usize>();
    if bytes.len() != count * T::SIZE {
        // The readers check the length with a better message; this is a safety net.
        return Err(IoError::format(
            path,
            format!("{} bytes of voxel data for {count} voxels of {} bytes", bytes.len(), T::SIZE),
        ));
    }
    let values = || bytes.chunks_exact(T::SIZE).map(|b| T::read(b, endian));
    let volume_error = |source| IoError::Volume { path: path.to_path_buf(), source };
    match scale {
        None if values().all(|v| v.label().is_some()) => {
            let labels = values().map(|v| v.label().unwrap_or(0)).collect();
            Ok(Voxels::Labels(label_volume(dims, order, labels).map_err(volume_error)?))
        }
        None => grey(path, values().map(T::grey), dims, order),
        Some((slope, inter)) => {
            let scaled = || values().map(|v| v.grey() * slope + inter);
            if scaled().all(|v| as_label(v).is_some()) {
                let labels = scaled().map(|v| as_label(v).unwrap_or(0)).collect();
                Ok(Voxels::Labels(label_volume(dims, order, labels).map_err(volume_error)?))
            } else {
                grey(path, scaled(), dims, order)
            }
        }
    }
}

fn grey(
    path: &Path,
    values: impl Iterator<Item = f64>,
    dims: [usize; 3],
    order: Order,
) -> Result<Voxels, IoError> {
    let values: Vec<f64> = values.collect();
    if let Some(i) = values.iter().position(|v| v.is_nan()) {
        let [x, y, z] = order.voxel(dims, i);
        return Err(IoError::format(path, format!("grey level NaN at voxel [{x}, {y}, {z}]")));
    }
    let volume = match order {
        Order::XFastest => GreyVolume::from_x_fastest(dims, values),
        Order::ZFastest => Array3::from_shape_vec((dims[0], dims[1], dims[2]), values)
            .map_err(|e| voxreg_digisurf::SurfaceError::InvalidVolume(e.to_string()))
            .and_then(GreyVolume::new),
    };
    volume.map(Voxels::Grey).map_err(|source| IoError::Volume { path: path.to_path_buf(), source })
}

fn label_volume(
    dims: [usize; 3],
    order: Order,
    labels: Vec<u32>,
) -> Result<LabelVolume, voxreg_digisurf::SurfaceError> {
    match order {
        Order::XFastest => LabelVolume::from_x_fastest(dims, labels),
        Order::ZFastest => Array3::from_shape_vec((dims[0], dims[1], dims[2]), labels)
            .map(LabelVolume::new)
            .map_err(|e| voxreg_digisurf::SurfaceError::InvalidVolume(e.to_string())),
    }
}

/// Checks that `found` bytes of voxel data are the `expected` ones of `layout`:
/// fewer is a truncated file, more a header whose dimensions do not match the data.
pub(crate) fn check_data_len(
    path: &Path,
    found: usize,
    expected: usize,
    layout: &Layout,
) -> Result<(), IoError> {
    let [x, y, z] = layout.dims;
    let declared = || {
        format!(
            "{x}x{y}x{z} voxels of {} ({} bytes each) = {expected} bytes declared",
            layout.dtype,
            layout.dtype.size()
        )
    };
    if found < expected {
        Err(IoError::format(path, format!("truncated voxel data: {}, {found} found", declared())))
    } else if found > expected {
        Err(IoError::format(path, format!("dimensions do not match the data: {}, {found} found", declared())))
    } else {
        Ok(())
    }
}

/// The number of bytes of the values of `layout` (the voxel count already checked
/// against [`MAX_VOXELS`](crate::files::MAX_VOXELS), so this cannot overflow a `u64`).
pub(crate) fn data_len(layout: &Layout) -> u64 {
    layout.dims.iter().map(|&d| d as u64).product::<u64>() * layout.dtype.size() as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: &str = "t.raw";

    fn layout(dims: [usize; 3], dtype: DataType, endian: Endian, order: Order) -> Layout {
        Layout { dims, dtype, endian, order }
    }

    #[test]
    fn names_parse_back() {
        for t in DataType::ALL {
            assert_eq!(t.name().parse::<DataType>(), Ok(t));
            assert_eq!(t.to_string().to_uppercase().parse::<DataType>(), Ok(t));
        }
        assert!("u7".parse::<DataType>().unwrap_err().contains("expected one of u8, i8"));
        assert_eq!("BE".parse::<Endian>(), Ok(Endian::Big));
        assert_eq!("little".parse::<Endian>(), Ok(Endian::Little));
        assert!("middle".parse::<Endian>().is_err());
    }

    #[test]
    fn integers_become_labels_in_either_order() {
        let bytes: Vec<u8> = (0u16..6).flat_map(|v| (v * 300).to_be_bytes()).collect();
        let l = layout([1, 2, 3], DataType::U16, Endian::Big, Order::XFastest);
        let Voxels::Labels(v) = decode(Path::new(P), &bytes, l, None).unwrap() else {
            panic!("labels expected")
        };
        assert_eq!(v.label([0, 1, 0]), Some(300));
        assert_eq!(v.label([0, 1, 2]), Some(1500));
        let l = layout([3, 2, 1], DataType::U16, Endian::Big, Order::ZFastest);
        let Voxels::Labels(v) = decode(Path::new(P), &bytes, l, None).unwrap() else {
            panic!("labels expected")
        };
        assert_eq!(v.label([0, 1, 0]), Some(300));
        assert_eq!(v.label([2, 1, 0]), Some(1500));
    }

    #[test]
    fn negative_fractional_wide_and_scaled_values_are_grey() {
        let cases: [(DataType, Vec<u8>); 4] = [
            (DataType::I8, vec![0, 0xff]),
            (DataType::F32, [0.0f32, 0.5].iter().flat_map(|v| v.to_le_bytes()).collect()),
            (DataType::U64, [0u64, 1 << 40].iter().flat_map(|v| v.to_le_bytes()).collect()),
            (DataType::F64, [0.0f64, 1.0].iter().flat_map(|v| v.to_le_bytes()).collect()),
        ];
        for (dtype, bytes) in cases {
            let l = layout([2, 1, 1], dtype, Endian::Little, Order::XFastest);
            let scale = (dtype == DataType::F64).then_some((0.5, 0.0));
            match decode(Path::new(P), &bytes, l, scale).unwrap() {
                Voxels::Grey(g) => assert_eq!(g.values()[[0, 0, 0]], 0.0, "{dtype}"),
                Voxels::Labels(_) => panic!("{dtype}: grey levels expected"),
            }
        }
        // Integral floats and a scale giving integers are labels.
        let bytes: Vec<u8> = [2.0f32, 7.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        let l = layout([2, 1, 1], DataType::F32, Endian::Little, Order::XFastest);
        assert!(matches!(decode(Path::new(P), &bytes, l, Some((2.0, 1.0))), Ok(Voxels::Labels(_))));
    }

    #[test]
    fn nan_names_the_file_and_voxel() {
        let bytes: Vec<u8> = [0.0f32, 1.0, f32::NAN, 2.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        for (order, voxel) in [(Order::XFastest, "[0, 1, 0]"), (Order::ZFastest, "[1, 0, 0]")] {
            let l = layout([2, 2, 1], DataType::F32, Endian::Little, order);
            let l = if order == Order::ZFastest { Layout { dims: [2, 1, 2], ..l } } else { l };
            let err = decode(Path::new(P), &bytes, l, None).unwrap_err().to_string();
            assert!(err.starts_with("t.raw: grey level NaN at voxel "), "{err}");
            assert!(err.ends_with(voxel), "{err}");
        }
    }

    #[test]
    fn length_checks() {
        let l = layout([2, 2, 2], DataType::U16, Endian::Little, Order::XFastest);
        assert_eq!(data_len(&l), 16);
        assert!(check_data_len(Path::new(P), 16, 16, &l).is_ok());
        let short = check_data_len(Path::new(P), 15, 16, &l).unwrap_err().to_string();
        assert_eq!(
            short,
            "t.raw: truncated voxel data: 2x2x2 voxels of u16 (2 bytes each) = 16 bytes declared, 15 found"
        );
        let long = check_data_len(Path::new(P), 17, 16, &l).unwrap_err().to_string();
        assert!(long.contains("dimensions do not match the data"), "{long}");
        assert!(decode(Path::new(P), &[0; 15], l, None).is_err());
    }
}
