//! numpy label arrays into the library's volume, and back.
//!
//! **Copies.** A `uint32` array, whatever its strides (C, Fortran, a sliced or transposed
//! view), is borrowed: the library reads it in place as a `LabelView`. Every other
//! integer dtype is converted once into an owned `uint32` array by a checked conversion
//! (memory order kept, so no transposition), after the copy's size has been checked
//! against the memory budget.

use glam::DVec3;
use ndarray::{Array3, ShapeBuilder};
use numpy::ndarray::ArrayView3;
use numpy::{PyArray3, PyArrayMethods, PyReadonlyArray3, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use voxreg_digisurf::LabelView;
use voxreg_io::MAX_VOXELS;

use crate::error::{Error, Kind, Result};

/// The labels of a numpy array as the library reads them: borrowed, or converted.
pub(crate) enum Labels<'py> {
    /// A `uint32` array, read in place (numpy's borrow flag held against Rust writers).
    Borrowed(PyReadonlyArray3<'py, u32>),
    /// Any other dtype, converted into `uint32`.
    Converted(Array3<u32>),
}

impl Labels<'_> {
    pub(crate) fn view(&self) -> ArrayView3<'_, u32> {
        match self {
            Labels::Borrowed(a) => a.as_array(),
            Labels::Converted(a) => a.view(),
        }
    }
}

/// Refuses an allocation of `bytes` for `what` over `limit`, before it is made.
pub(crate) fn check_budget(what: &str, bytes: u128, limit: u64) -> Result<()> {
    if bytes > u128::from(limit) {
        return Err(over_budget(what, u64::try_from(bytes).unwrap_or(u64::MAX), limit));
    }
    Ok(())
}

/// The error of [`check_budget`]: `what` needs `bytes`, over `limit`.
pub(crate) fn over_budget(what: &str, bytes: u64, limit: u64) -> Error {
    Error::new(
        Kind::Voxreg,
        format!(
            "labels: {what} needs {}, over the memory limit of {} (raise it with max_memory=)",
            voxreg_io::format_size(bytes),
            voxreg_io::format_size(limit)
        ),
    )
}

/// An integer type a label can come from.
trait ToLabel: numpy::Element + Copy + std::fmt::Display {
    fn to_label(self) -> Option<u32>;
}

macro_rules! to_label {
    ($($t:ty),*) => {$(
        impl ToLabel for $t {
            #[inline]
            fn to_label(self) -> Option<u32> {
                u32::try_from(self).ok()
            }
        }
    )*};
}
to_label!(u8, u16, u32, u64, i8, i16, i32, i64);

impl ToLabel for bool {
    #[inline]
    fn to_label(self) -> Option<u32> {
        Some(u32::from(self))
    }
}

/// The labels of `array` (a numpy array of any integer or bool dtype, shape `(X, Y, Z)`
/// indexed `[x, y, z]`): borrowed if `uint32`, else converted within `limit` bytes. At
/// most [`MAX_VOXELS`] voxels, as the file readers accept.
pub(crate) fn labels_of<'py>(array: &Bound<'py, PyAny>, limit: u64) -> Result<Labels<'py>> {
    let untyped = array
        .cast::<PyUntypedArray>()
        .map_err(|_| Error::input("labels must be a numpy array (numpy.asarray accepts nested lists)"))?;
    if untyped.ndim() != 3 {
        return Err(Error::input(format!(
            "labels must be a 3-D array indexed [x, y, z], got shape ({})",
            untyped.shape().iter().map(|d| d.to_string()).collect::<Vec<_>>().join(", ")
        )));
    }
    let shape = untyped.shape();
    let voxels = shape.iter().map(|&d| d as u128).product::<u128>();
    if voxels > u128::from(MAX_VOXELS) {
        return Err(Error::input(format!(
            "labels: volume of {}x{}x{} voxels exceeds the limit of {MAX_VOXELS} voxels",
            shape[0], shape[1], shape[2]
        )));
    }
    if let Ok(a) = array.cast::<PyArray3<u32>>() {
        return Ok(Labels::Borrowed(a.try_readonly().map_err(|e| Error::input(format!("labels: {e}")))?));
    }
    macro_rules! try_dtype {
        ($($t:ty),*) => {$(
            if let Ok(a) = array.cast::<PyArray3<$t>>() {
                let ro = a.try_readonly().map_err(|e| Error::input(format!("labels: {e}")))?;
                let what = format!("a uint32 copy of its {voxels} {} labels", untyped.dtype());
                check_budget(&what, voxels * 4, limit)?;
                return convert::<$t>(ro.as_array()).map(Labels::Converted);
            }
        )*};
    }
    try_dtype!(u8, u16, u64, i32, i8, i16, i64, bool);
    let dtype = untyped.dtype().to_string();
    Err(Error::input(format!(
        "labels must be an integer array, got dtype {dtype} (grey levels: threshold them first, e.g. labels = grey > t)"
    )))
}

fn convert<T: ToLabel>(view: ArrayView3<'_, T>) -> Result<Array3<u32>> {
    let (x, y, z) = view.dim();
    let collect = |values: &mut dyn Iterator<Item = &T>| -> Option<Vec<u32>> {
        let mut out = Vec::with_capacity(x * y * z);
        for v in values {
            out.push(v.to_label()?);
        }
        Some(out)
    };
    let built = if let Some(c) = view.as_slice() {
        collect(&mut c.iter()).map(|v| Array3::from_shape_vec((x, y, z), v))
    } else if let Some(f) = view.t().as_slice() {
        collect(&mut f.iter()).map(|v| Array3::from_shape_vec((x, y, z).f(), v))
    } else {
        collect(&mut view.iter()).map(|v| Array3::from_shape_vec((x, y, z), v))
    };
    match built {
        Some(array) => array.map_err(|e| Error::input(format!("labels: {e}"))),
        None => {
            let ((i, j, k), v) =
                view.indexed_iter().find(|(_, v)| v.to_label().is_none()).expect("a bad value");
            let why = if v.to_string().starts_with('-') { "negative" } else { "beyond 4294967295" };
            Err(Error::input(format!(
                "labels: voxel [{i}, {j}, {k}] has label {v}, which is {why} (labels are unsigned 32-bit integers)"
            )))
        }
    }
}

/// A volume over `labels` (borrowed) with its embedding and background.
pub(crate) fn volume<'a>(
    labels: ArrayView3<'a, u32>,
    spacing: [f64; 3],
    origin: [f64; 3],
    background: Option<u32>,
) -> Result<LabelView<'a>> {
    let (dims, s, o) = (labels.dim(), DVec3::from_array(spacing), DVec3::from_array(origin));
    if s.is_finite() && s.min_element() > 0.0 && o.is_finite() {
        voxreg_io::check_coordinates([dims.0, dims.1, dims.2], s, o)
            .map_err(|e| Error::parameter(format!("spacing and origin: {e}")))?;
    }
    LabelView::from_view(labels)
        .with_spacing(DVec3::from_array(spacing))
        .map_err(|e| Error::parameter(format!("spacing: {e}")))?
        .with_origin(DVec3::from_array(origin))
        .map_err(|e| Error::parameter(format!("origin: {e}")))
        .map(|v| v.with_background(background))
}

/// The library's labels as a numpy array of the same shape and memory order, moved (not
/// copied) into numpy.
pub(crate) fn to_numpy<'py>(py: Python<'py>, labels: Array3<u32>) -> Bound<'py, PyAny> {
    use numpy::ndarray::ShapeBuilder as _;
    use numpy::IntoPyArray;
    let (x, y, z) = labels.dim();
    let fortran = !labels.is_standard_layout() && labels.t().is_standard_layout();
    let labels = if fortran || labels.is_standard_layout() {
        labels
    } else {
        labels.as_standard_layout().into_owned()
    };
    let (data, _) = labels.into_raw_vec_and_offset();
    numpy::ndarray::Array3::from_shape_vec((x, y, z).set_f(fortran), data)
        .expect("the volume's shape")
        .into_pyarray(py)
        .into_any()
}
