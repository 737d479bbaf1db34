//! The keyword arguments of `voxreg.regularize` as the library's `Overrides` (the names
//! the CLI's flags have), resolved by the library over a preset, as the CLI resolves its
//! options.

use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyString};
use serde::de::value::{Error as DeError, MapDeserializer, SeqDeserializer};
use serde::de::{Deserializer, IntoDeserializer, Visitor};
use serde::Deserialize;
use voxreg_regularize::{InputFacts, Overrides, Params, Preset};

use crate::error::{Error, Result};

/// A Python argument as serde reads it (`None` arguments are left out: not given).
#[derive(Clone, Debug)]
enum Value {
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    List(Vec<Value>),
}

impl Value {
    /// `v` (a bool, an int, a float, a str, or a sequence of them).
    fn of(name: &str, v: &Bound<'_, PyAny>) -> Result<Value> {
        if let Ok(b) = v.cast::<PyBool>() {
            return Ok(Value::Bool(b.is_true()));
        }
        if let Ok(s) = v.cast::<PyString>() {
            return Ok(Value::Str(s.to_string()));
        }
        if let Ok(i) = v.extract::<i64>() {
            return Ok(Value::Int(i));
        }
        if let Ok(x) = v.extract::<f64>() {
            return Ok(Value::Float(x));
        }
        if let Ok(items) = v.try_iter() {
            let bad = |e: PyErr| Error::parameter(format!("{name}: {e}"));
            let items: Vec<Value> =
                items.map(|item| Value::of(name, &item.map_err(bad)?)).collect::<Result<_>>()?;
            return Ok(Value::List(items));
        }
        Err(Error::parameter(format!("{name}: unsupported value {v}")))
    }
}

impl<'de> Deserializer<'de> for Value {
    type Error = DeError;

    fn deserialize_any<V: Visitor<'de>>(self, visitor: V) -> std::result::Result<V::Value, DeError> {
        match self {
            Value::Bool(b) => visitor.visit_bool(b),
            Value::Int(i) => visitor.visit_i64(i),
            Value::Float(x) => visitor.visit_f64(x),
            Value::Str(s) => visitor.visit_string(s),
            Value::List(items) => visitor.visit_seq(SeqDeserializer::new(items.into_iter())),
        }
    }

    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> std::result::Result<V::Value, DeError> {
        visitor.visit_some(self)
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf unit
        unit_struct newtype_struct seq tuple tuple_struct map struct enum identifier ignored_any
    }
}

impl IntoDeserializer<'_, DeError> for Value {
    type Deserializer = Self;

    fn into_deserializer(self) -> Self {
        self
    }
}

/// `entries` as overrides; an entry's error names it (`refine must be a non-negative
/// integer, got -1`).
fn overrides_of(entries: Vec<(String, Value)>) -> Result<Overrides> {
    let read =
        |entries: Vec<(String, Value)>| Overrides::deserialize(MapDeserializer::new(entries.into_iter()));
    for (name, value) in &entries {
        if let Err(e) = read(vec![(name.clone(), value.clone())]) {
            let e = e.to_string();
            let e = e.lines().next().unwrap_or_default();
            let sep = if e.starts_with("must") { " " } else { ": " };
            return Err(Error::parameter(format!("{name}{sep}{e}")));
        }
    }
    read(entries).map_err(|e| Error::parameter(e.to_string()))
}

/// `preset=`: a preset's name, Python's spelling (`voxel_art`) or the CLI's.
pub(crate) fn preset(name: &str) -> Result<Preset> {
    name.parse().map_err(|_| {
        let names: Vec<String> =
            Preset::ALL.iter().map(|p| format!("'{}'", p.name().replace('-', "_"))).collect();
        Error::parameter(format!("preset must be one of {}, got '{name}'", names.join(", ")))
    })
}

/// The library's parameters: `preset` with the options of `options` (a dict of
/// [`Overrides`] fields; `None` values are not given) applied over it, validated.
pub(crate) fn params(preset_name: &str, options: &Bound<'_, PyDict>) -> Result<Params> {
    let preset = preset(preset_name)?;
    let mut entries = Vec::new();
    for (k, v) in options.iter() {
        let name: String = k.extract().map_err(|_| Error::parameter("option names must be strings"))?;
        if !v.is_none() {
            entries.push((name.clone(), Value::of(&name, &v)?));
        }
    }
    let overrides = overrides_of(entries)?;
    overrides.resolve(Some(preset), &InputFacts::default()).map_err(|e| Error::regularize("", &e))
}

/// The halo a chunked run of `preset` reads by default (`Preset::chunk_halo`).
#[pyfunction]
pub(crate) fn preset_halo(preset_name: &str) -> Result<usize> {
    Ok(preset(preset_name)?.chunk_halo())
}

/// The names of the options (`Overrides` fields), for the parity tests.
#[pyfunction]
pub(crate) fn option_names() -> Vec<&'static str> {
    Overrides::FIELDS.to_vec()
}
