//! Binary `DataArray` payloads: raw or base64 sources, VTK's block headers, zlib.

use std::io::Read;

use base64::Engine;
use flate2::read::ZlibDecoder;

use super::Codec;
use crate::samples::Endian;

/// A source of binary bytes.
pub(super) trait Source {
    /// The next `n` bytes, or an error if there are fewer.
    fn take(&mut self, n: usize) -> Result<Vec<u8>, String>;
    /// At most how many bytes are left: a bound for header-declared counts.
    fn remaining(&self) -> usize;
}

pub(super) struct Raw<'a> {
    pub(super) data: &'a [u8],
}

impl Source for Raw<'_> {
    fn take(&mut self, n: usize) -> Result<Vec<u8>, String> {
        if n > self.data.len() {
            return Err(format!("truncated data: {n} bytes needed, {} left", self.data.len()));
        }
        let (head, tail) = self.data.split_at(n);
        self.data = tail;
        Ok(head.to_vec())
    }

    fn remaining(&self) -> usize {
        self.data.len()
    }
}

/// Base64 text decoded on demand. VTK encodes the header and the data separately,
/// each padded, others encode them as one stream: decoding segment by segment, each
/// ending at a padded group, reads both.
pub(super) struct Base64<'a> {
    pub(super) text: &'a [u8],
    /// Decoded bytes not yet taken.
    pub(super) buf: Vec<u8>,
}

impl Source for Base64<'_> {
    fn take(&mut self, n: usize) -> Result<Vec<u8>, String> {
        while self.buf.len() < n {
            if self.text.is_empty() {
                return Err(format!("truncated base64 data: {n} bytes needed, {} left", self.buf.len()));
            }
            // Decode no more groups than needed, and stop after a padded group.
            let groups = (n - self.buf.len()).div_ceil(3);
            let mut len = self.text.len().min(groups.saturating_mul(4));
            if let Some(pad) = self.text[..len].iter().position(|&b| b == b'=') {
                len = (pad / 4 + 1) * 4;
            }
            if len > self.text.len() || len % 4 != 0 {
                return Err("truncated base64 data (not a whole number of 4-character groups)".into());
            }
            let (segment, rest) = self.text.split_at(len);
            base64::engine::general_purpose::STANDARD
                .decode_vec(segment, &mut self.buf)
                .map_err(|e| format!("bad base64 data: {e}"))?;
            self.text = rest;
        }
        let rest = self.buf.split_off(n);
        Ok(std::mem::replace(&mut self.buf, rest))
    }

    fn remaining(&self) -> usize {
        self.buf.len() + self.text.len() / 4 * 3
    }
}

/// Reads binary data: header, then raw or zlib-compressed bytes, exactly `expected`.
pub(super) fn read_binary(src: &mut dyn Source, codec: Codec, expected: usize) -> Result<Vec<u8>, String> {
    let word = |src: &mut dyn Source| -> Result<u64, String> {
        let b = src.take(codec.word)?;
        let mut w = [0u8; 8];
        match (codec.endian, codec.word) {
            (Endian::Little, _) => w[..codec.word].copy_from_slice(&b),
            (Endian::Big, k) => {
                w[..k].copy_from_slice(&b);
                w[..k].reverse();
            }
        }
        Ok(u64::from_le_bytes(w))
    };
    let mismatch = |declared: u64| {
        let what =
            if declared < expected as u64 { "truncated data" } else { "dimensions do not match the data" };
        format!("{what}: the array holds {declared} bytes, the extent needs {expected}")
    };
    if !codec.compressed {
        let n = word(src)?;
        if n != expected as u64 {
            return Err(mismatch(n));
        }
        return src.take(expected);
    }
    let blocks = word(src)?;
    let block_size = word(src)?;
    let last = word(src)?;
    let total = match blocks {
        0 => 0u128,
        b => {
            u128::from(b - 1) * u128::from(block_size) + u128::from(if last == 0 { block_size } else { last })
        }
    };
    if total != expected as u128 {
        return Err(mismatch(u64::try_from(total).unwrap_or(u64::MAX)));
    }
    if last > block_size {
        return Err(format!("last block of {last} bytes exceeds the block size {block_size}"));
    }
    // Each block's compressed size is a header word still to be read: a count the data
    // cannot hold is refused before allocating for it.
    if blocks > (src.remaining() / codec.word) as u64 {
        return Err(format!(
            "the header declares {blocks} compressed blocks, but only {} bytes follow",
            src.remaining()
        ));
    }
    // zlib expands at most about 1032 times: more declared output than the compressed
    // bytes left can give is a corrupt header.
    if expected as u128 > (src.remaining() as u128 + 1) * 1032 {
        return Err(format!(
            "the header declares {expected} bytes, more than the {} compressed bytes that follow can hold",
            src.remaining()
        ));
    }
    let mut sizes = Vec::with_capacity(blocks as usize);
    for _ in 0..blocks {
        sizes.push(word(src)?);
    }
    let mut out = Vec::with_capacity(expected.min(1 << 24));
    for (k, &size) in sizes.iter().enumerate() {
        let raw = if k + 1 == sizes.len() && last != 0 { last } else { block_size };
        let compressed = src.take(usize::try_from(size).map_err(|_| "absurd block size")?)?;
        let before = out.len();
        ZlibDecoder::new(&compressed[..])
            .take(raw + 1)
            .read_to_end(&mut out)
            .map_err(|e| format!("block {k}: corrupt zlib data: {e}"))?;
        if (out.len() - before) as u64 != raw {
            return Err(format!(
                "block {k}: {} bytes after decompression, {raw} declared",
                out.len() - before
            ));
        }
    }
    Ok(out)
}
