//! NumPy `.npy` arrays.
//!
//! The format: the magic `\x93NUMPY`, a version (1.0, 2.0 or 3.0), the length of the
//! header (`u16` in version 1, `u32` after), the header (a Python dict literal with the
//! keys `descr`, `fortran_order` and `shape`), then the array's bytes.

use std::path::Path;

use crate::error::IoError;
use crate::files::{checked_voxel_count, read_file};
use crate::grey::Voxels;
use crate::samples::{check_data_len, data_len, decode, Layout, Order};
use crate::samples::{DataType, Endian};

const MAGIC: &[u8] = b"\x93NUMPY";

/// Reads a NumPy `.npy` file holding a 3-D array. See [`read_npy_bytes`].
pub fn read_npy(path: &Path) -> Result<Voxels, IoError> {
    read_npy_bytes(&read_file(path)?, path)
}

/// Reads a NumPy `.npy` file held in memory; `path` only names the file in errors.
///
/// **Axes.** The array must have shape `(X, Y, Z)`: element `a[x, y, z]` is voxel
/// `[x, y, z]`, whether the file is in C order (`z` fastest, the NumPy default; the
/// volume then keeps that layout) or Fortran order (`x` fastest). An array saved as
/// `a[z, y, x]`, as image stacks often are, must be transposed first
/// (`np.save(f, a.transpose())`).
///
/// **Types.** `descr` may be `|u1`, `|i1`, `|b1` (bool), `u2`, `i2`, `u4`, `i4`, `u8`,
/// `i8`, `f4`, `f8` with byte order `<` or `>` (`=` and `|` are read as little endian).
/// Values are labels when all are integers in `0..=u32::MAX`, grey levels otherwise; a
/// NaN is an error. Spacing `1`, origin `0`.
///
/// Other dtypes (half floats, complex, strings, objects, structured arrays) and arrays
/// of other than 3 dimensions are [`IoError::Unsupported`]; a bad magic, version or
/// header, a zero dimension, or data that do not match the shape are
/// [`IoError::Format`]; shapes above [`MAX_VOXELS`](crate::files::MAX_VOXELS) are
/// [`IoError::TooLarge`] (checked before any allocation).
pub fn read_npy_bytes(bytes: &[u8], path: &Path) -> Result<Voxels, IoError> {
    let not_npy = |message: String| IoError::format(path, format!("not a NumPy .npy file: {message}"));
    if !bytes.starts_with(MAGIC) {
        return Err(not_npy(format!("no magic \\x93NUMPY at the start ({})", preview(bytes))));
    }
    let (major, minor) = match bytes.get(6..8) {
        Some(&[major, minor]) => (major, minor),
        _ => return Err(not_npy("the file ends inside its version".into())),
    };
    let (len_size, header_len) = match major {
        1 => (2, bytes.get(8..10).map(|b| u16::from_le_bytes([b[0], b[1]]) as usize)),
        2 | 3 => (4, bytes.get(8..12).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)),
        _ => {
            return Err(IoError::unsupported(
                path,
                format!(".npy version {major}.{minor} (1.0, 2.0, 3.0 are read)"),
            ))
        }
    };
    let Some(header_len) = header_len else {
        return Err(not_npy("the file ends inside its header length".into()));
    };
    let start: usize = 8 + len_size;
    let Some(header) = bytes.get(start..start.saturating_add(header_len)) else {
        return Err(not_npy(format!(
            "truncated header: {header_len} bytes declared, {} found",
            bytes.len() - start.min(bytes.len())
        )));
    };
    let header = std::str::from_utf8(header).map_err(|_| not_npy("the header is not text".into()))?;
    let dict = parse_dict(header)
        .map_err(|e| not_npy(format!("header {e}: {}", header.trim_end().escape_debug())))?;

    let descr = match dict.get("descr") {
        Some(Value::Str(s)) => s.clone(),
        Some(_) => return Err(IoError::unsupported(path, "structured dtype (descr is not a string)")),
        None => return Err(not_npy("the header has no 'descr'".into())),
    };
    let (dtype, endian) = parse_descr(&descr).ok_or_else(|| {
        IoError::unsupported(
            path,
            format!("dtype '{descr}' (integers of 1 to 8 bytes, bool, f4 and f8 are read)"),
        )
    })?;
    let fortran = match dict.get("fortran_order") {
        Some(Value::Bool(b)) => *b,
        _ => return Err(not_npy("the header has no boolean 'fortran_order'".into())),
    };
    let shape = match dict.get("shape") {
        Some(Value::Tuple(shape)) => shape.clone(),
        _ => return Err(not_npy("the header has no tuple 'shape'".into())),
    };
    let [x, y, z] = shape[..] else {
        let shape: Vec<String> = shape.iter().map(u64::to_string).collect();
        return Err(IoError::unsupported(
            path,
            format!("array of shape ({}): a 3-D array of shape (X, Y, Z) is needed", shape.join(", ")),
        ));
    };
    if [x, y, z].contains(&0) {
        return Err(IoError::format(path, format!("empty array of shape ({x}, {y}, {z})")));
    }
    checked_voxel_count(path, [x, y, z], dtype.size() as u64 + 8)?;
    let order = if fortran { Order::XFastest } else { Order::ZFastest };
    let layout = Layout { dims: [x, y, z].map(|d| d as usize), dtype, endian, order };
    let data = &bytes[start + header_len..];
    check_data_len(path, data.len(), data_len(&layout) as usize, &layout)?;
    decode(path, data, layout, None)
}

/// The first bytes of `bytes`, escaped, for error messages.
fn preview(bytes: &[u8]) -> String {
    format!("starts with '{}'", bytes[..bytes.len().min(8)].escape_ascii())
}

/// The data type and byte order of a simple `descr` such as `<u2`.
fn parse_descr(descr: &str) -> Option<(DataType, Endian)> {
    let (endian, rest) = match descr.as_bytes().first()? {
        b'<' | b'=' | b'|' => (Endian::Little, &descr[1..]),
        b'>' => (Endian::Big, &descr[1..]),
        _ => (Endian::Little, descr),
    };
    let dtype = match rest {
        "u1" | "b1" => DataType::U8,
        "i1" => DataType::I8,
        "u2" => DataType::U16,
        "i2" => DataType::I16,
        "u4" => DataType::U32,
        "i4" => DataType::I32,
        "u8" => DataType::U64,
        "i8" => DataType::I64,
        "f4" => DataType::F32,
        "f8" => DataType::F64,
        _ => return None,
    };
    Some((dtype, endian))
}

/// A value of the header dict.
#[derive(Clone, Debug, PartialEq)]
enum Value {
    Str(String),
    Bool(bool),
    Tuple(Vec<u64>),
    /// Anything else (a list, as in structured dtypes).
    Other,
}

struct Dict(Vec<(String, Value)>);

impl Dict {
    fn get(&self, key: &str) -> Option<&Value> {
        self.0.iter().find(|(k, _)| k == key).map(|(_, v)| v)
    }
}

/// A cursor over the header text.
struct Cursor<'a> {
    text: &'a [u8],
    pos: usize,
}

impl Cursor<'_> {
    fn skip_ws(&mut self) {
        while self.text.get(self.pos).is_some_and(u8::is_ascii_whitespace) {
            self.pos += 1;
        }
    }

    fn peek(&mut self) -> Option<u8> {
        self.skip_ws();
        self.text.get(self.pos).copied()
    }

    fn eat(&mut self, c: u8) -> bool {
        if self.peek() == Some(c) {
            self.pos += 1;
            true
        } else {
            false
        }
    }

    fn expect(&mut self, c: u8) -> Result<(), String> {
        if self.eat(c) {
            Ok(())
        } else {
            Err(format!("expected '{}' at byte {}", c as char, self.pos))
        }
    }

    fn string(&mut self) -> Result<String, String> {
        let quote = match self.peek() {
            Some(q @ (b'\'' | b'"')) => q,
            _ => return Err(format!("expected a quoted string at byte {}", self.pos)),
        };
        let start = self.pos + 1;
        let len = self.text[start..].iter().position(|&c| c == quote).ok_or("unterminated string")?;
        self.pos = start + len + 1;
        Ok(String::from_utf8_lossy(&self.text[start..start + len]).into_owned())
    }

    fn word(&mut self) -> &[u8] {
        self.skip_ws();
        let start = self.pos;
        while self.text.get(self.pos).is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_') {
            self.pos += 1;
        }
        &self.text[start..self.pos]
    }

    fn value(&mut self, depth: usize) -> Result<Value, String> {
        if depth > 8 {
            return Err("nested too deeply".into());
        }
        match self.peek() {
            Some(b'\'' | b'"') => self.string().map(Value::Str),
            Some(b'(') => {
                self.pos += 1;
                let mut items = Vec::new();
                while !self.eat(b')') {
                    let word = self.word();
                    let digits = word.strip_suffix(b"L").unwrap_or(word);
                    let n = std::str::from_utf8(digits).ok().and_then(|d| d.parse::<u64>().ok());
                    items.push(n.ok_or_else(|| format!("expected a dimension at byte {}", self.pos))?);
                    if !self.eat(b',') {
                        self.expect(b')')?;
                        break;
                    }
                }
                Ok(Value::Tuple(items))
            }
            Some(b'[') => {
                // Skip a list (of a structured dtype), balancing brackets and quotes.
                self.pos += 1;
                let mut open = 1usize;
                while open > 0 {
                    match self.text.get(self.pos) {
                        None => return Err("unterminated list".into()),
                        Some(b'[' | b'(') => open += 1,
                        Some(b']' | b')') => open -= 1,
                        Some(b'\'' | b'"') => {
                            self.string()?;
                            continue;
                        }
                        _ => {}
                    }
                    self.pos += 1;
                }
                Ok(Value::Other)
            }
            _ => match self.word() {
                b"True" => Ok(Value::Bool(true)),
                b"False" => Ok(Value::Bool(false)),
                _ => Err(format!("unexpected value at byte {}", self.pos)),
            },
        }
    }
}

/// Parses the header dict: `{'key': value, ...}` with an optional trailing comma.
fn parse_dict(text: &str) -> Result<Dict, String> {
    let mut c = Cursor { text: text.as_bytes(), pos: 0 };
    c.expect(b'{')?;
    let mut entries = Vec::new();
    while !c.eat(b'}') {
        let key = c.string()?;
        c.expect(b':')?;
        let value = c.value(0)?;
        entries.push((key, value));
        if !c.eat(b',') {
            c.expect(b'}')?;
            break;
        }
    }
    Ok(Dict(entries))
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: &str = "a.npy";

    /// A version-1 `.npy` file with this header dict and data, padded as NumPy does.
    fn npy(dict: &str, data: &[u8]) -> Vec<u8> {
        let mut header = dict.to_string();
        while (10 + header.len() + 1) % 64 != 0 {
            header.push(' ');
        }
        header.push('\n');
        let mut bytes = MAGIC.to_vec();
        bytes.extend_from_slice(&[1, 0]);
        bytes.extend_from_slice(&(header.len() as u16).to_le_bytes());
        bytes.extend_from_slice(header.as_bytes());
        bytes.extend_from_slice(data);
        bytes
    }

    fn read(bytes: &[u8]) -> Result<Voxels, IoError> {
        read_npy_bytes(bytes, Path::new(P))
    }

    fn message(bytes: &[u8]) -> String {
        let text = read(bytes).unwrap_err().to_string();
        assert!(text.starts_with("a.npy: "), "{text}");
        text
    }

    fn labels(v: Voxels) -> voxreg_digisurf::LabelVolume {
        match v {
            Voxels::Labels(v) => v,
            Voxels::Grey(_) => panic!("labels expected"),
        }
    }

    #[test]
    fn c_and_fortran_order_index_the_same_voxels() {
        // a[x, y, z] = x + 10 y + 100 z for shape (2, 3, 4).
        let value = |x: u16, y: u16, z: u16| x + 10 * y + 100 * z;
        let mut c = Vec::new();
        for x in 0..2 {
            for y in 0..3 {
                for z in 0..4 {
                    c.extend_from_slice(&value(x, y, z).to_le_bytes());
                }
            }
        }
        let mut f = Vec::new();
        for z in 0..4 {
            for y in 0..3 {
                for x in 0..2 {
                    f.extend_from_slice(&value(x, y, z).to_be_bytes());
                }
            }
        }
        let a =
            labels(read(&npy("{'descr': '<u2', 'fortran_order': False, 'shape': (2, 3, 4), }", &c)).unwrap());
        let b = labels(
            read(&npy("{\"descr\": \">u2\", \"fortran_order\": True, \"shape\": (2L, 3L, 4L)}", &f)).unwrap(),
        );
        assert_eq!(a.dims(), [2, 3, 4]);
        assert_eq!(a, b);
        assert_eq!(a.label([1, 2, 3]), Some(321));
    }

    #[test]
    fn versions_2_and_3_and_float_data() {
        let data: Vec<u8> = [0.25f64, 2.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        let mut bytes = npy("{'descr': '<f8', 'fortran_order': False, 'shape': (1, 1, 2), }", &data);
        // Re-frame as version 2: a 4-byte header length.
        let len = u16::from_le_bytes([bytes[8], bytes[9]]) as u32;
        for major in [2u8, 3] {
            let mut v2 = MAGIC.to_vec();
            v2.extend_from_slice(&[major, 0]);
            v2.extend_from_slice(&len.to_le_bytes());
            v2.extend_from_slice(&bytes[10..]);
            let Voxels::Grey(g) = read(&v2).unwrap() else { panic!("grey expected") };
            assert_eq!(g.values()[[0, 0, 1]], 2.0);
        }
        bytes.truncate(bytes.len() - 1);
        assert!(message(&bytes).contains("truncated voxel data: 1x1x2 voxels of f64"));
    }

    #[test]
    fn bad_input() {
        let ok = "{'descr': '|u1', 'fortran_order': False, 'shape': (2, 1, 1), }";
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (b"".to_vec(), "no magic"),
            (b"PK\x03\x04 zip".to_vec(), "not a NumPy .npy file: no magic"),
            (b"\x93NUMPY\x01".to_vec(), "ends inside its version"),
            (b"\x93NUMPY\x01\x00\x10".to_vec(), "ends inside its header length"),
            (b"\x93NUMPY\x04\x00\x10\x00".to_vec(), "unsupported: .npy version 4.0"),
            (b"\x93NUMPY\x01\x00\xff\x00{'descr'".to_vec(), "truncated header: 255 bytes declared, 8 found"),
            (npy(ok, &[1, 2, 3]), "dimensions do not match the data"),
            (npy(ok, &[1]), "truncated voxel data"),
            (
                npy("{'descr': '<f2', 'fortran_order': False, 'shape': (2, 1, 1), }", &[0; 4]),
                "unsupported: dtype '<f2'",
            ),
            (
                npy("{'descr': '<c8', 'fortran_order': False, 'shape': (2, 1, 1), }", &[0; 16]),
                "unsupported: dtype",
            ),
            (
                npy(
                    "{'descr': [('r', '<u1'), ('g', '<u1')], 'fortran_order': False, 'shape': (2, 1, 1), }",
                    &[0; 4],
                ),
                "unsupported: structured dtype",
            ),
            (
                npy("{'descr': '|u1', 'fortran_order': False, 'shape': (2, 2), }", &[0; 4]),
                "unsupported: array of shape (2, 2)",
            ),
            (npy("{'descr': '|u1', 'fortran_order': False, 'shape': (2, 0, 1), }", &[]), "empty array"),
            (npy("{'descr': '|u1', 'shape': (2, 1, 1), }", &[0; 2]), "no boolean 'fortran_order'"),
            (npy("{'descr': '|u1', 'fortran_order': False}", &[0; 2]), "no tuple 'shape'"),
            (npy("{'fortran_order': False, 'shape': (2, 1, 1)}", &[0; 2]), "no 'descr'"),
            (
                npy("{'descr': '|u1', 'fortran_order': Maybe, 'shape': (2, 1, 1)}", &[0; 2]),
                "unexpected value",
            ),
            (
                npy("{'descr': '|u1', 'fortran_order': False, 'shape': (2, x, 1)}", &[0; 2]),
                "expected a dimension",
            ),
            (npy("{'descr: '|u1'}", &[]), "header"),
            (npy("['descr']", &[]), "expected '{'"),
        ];
        crate::testing::assert_refused(&cases, message);
        let nan: Vec<u8> = [f32::NAN, 1.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        let text = message(&npy("{'descr': '<f4', 'fortran_order': False, 'shape': (1, 2, 1), }", &nan));
        assert!(text.contains("grey level NaN at voxel [0, 0, 0]"), "{text}");
        let huge =
            npy("{'descr': '<f8', 'fortran_order': False, 'shape': (100000, 100000, 100000), }", &[0; 8]);
        assert!(matches!(read(&huge), Err(IoError::TooLarge { .. })));
    }
}
