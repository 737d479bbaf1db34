//! Sizes in bytes as people write them: parsed from options (`4G`) and formatted for
//! messages (`1.5 GiB`).

/// Parses a size such as `4G`, `512M`, `100k` or `1000000` (bytes; binary multiples
/// `k`, `M`, `G`, `T`, optionally followed by `i`, `B` or `iB`). `None` if malformed,
/// zero or overflowing.
pub fn parse_size(text: &str) -> Option<u64> {
    let t = text.trim();
    let t = t.strip_suffix('B').or_else(|| t.strip_suffix('b')).unwrap_or(t);
    let t = t.strip_suffix('i').unwrap_or(t);
    let (digits, shift) = match t.char_indices().last()? {
        (i, 'k' | 'K') => (&t[..i], 10),
        (i, 'm' | 'M') => (&t[..i], 20),
        (i, 'g' | 'G') => (&t[..i], 30),
        (i, 't' | 'T') => (&t[..i], 40),
        _ => (t, 0),
    };
    let value = digits.trim().parse::<f64>().ok().filter(|v| v.is_finite() && *v > 0.0)?;
    let bytes = value * (1u64 << shift) as f64;
    (bytes >= 1.0 && bytes < u64::MAX as f64).then_some(bytes as u64)
}

/// A size in bytes for messages: `1.5 GiB`, `12 MiB`, `300 bytes`.
pub fn format_size(bytes: u64) -> String {
    const UNITS: [(&str, u32); 4] = [("TiB", 40), ("GiB", 30), ("MiB", 20), ("KiB", 10)];
    for (unit, shift) in UNITS {
        if bytes >= 1 << shift {
            let v = bytes as f64 / (1u64 << shift) as f64;
            return if v >= 10.0 { format!("{v:.0} {unit}") } else { format!("{v:.1} {unit}") };
        }
    }
    format!("{bytes} bytes")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_format() {
        assert_eq!(parse_size("4G"), Some(4 << 30));
        assert_eq!(parse_size("512M"), Some(512 << 20));
        assert_eq!(parse_size("512MiB"), Some(512 << 20));
        assert_eq!(parse_size("1.5k"), Some(1536));
        assert_eq!(parse_size("1000"), Some(1000));
        for bad in ["", "G", "-1G", "0", "1X", "nanG", "1e30T"] {
            assert_eq!(parse_size(bad), None, "{bad}");
        }
        assert_eq!(format_size(3 << 30), "3.0 GiB");
        assert_eq!(format_size(12 << 20), "12 MiB");
        assert_eq!(format_size(300), "300 bytes");
    }
}
