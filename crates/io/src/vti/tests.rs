//! Tests of the `.vti` reader.

use std::io::Write;

use base64::engine::general_purpose::STANDARD;
use base64::Engine;
use flate2::write::ZlibEncoder;
use flate2::Compression;

use super::*;

const P: &str = "img.vti";

fn read(bytes: &[u8]) -> Result<Voxels, IoError> {
    read_vti_bytes(bytes, Path::new(P))
}

fn message(bytes: &[u8]) -> String {
    let text = read(bytes).unwrap_err().to_string();
    assert!(text.starts_with("img.vti: "), "{text}");
    text
}

fn labels(v: Voxels) -> voxreg_digisurf::LabelVolume {
    match v {
        Voxels::Labels(v) => v,
        Voxels::Grey(g) => panic!("labels expected, got grey {:?}", g.dims()),
    }
}

/// A file with one piece, whole extent `extent`, one array in `section`.
fn vti(root_attrs: &str, image_attrs: &str, section: &str, array: &str, appended: &[u8]) -> Vec<u8> {
    let mut s = format!(
        "<?xml version=\"1.0\"?>\n<VTKFile type=\"ImageData\" version=\"1.0\" {root_attrs}>\n\
         <ImageData {image_attrs}>\n<Piece>\n<{section}>\n{array}\n</{}>\n</Piece>\n</ImageData>\n",
        section.split(' ').next().unwrap()
    )
    .into_bytes();
    s.extend_from_slice(appended);
    s.extend_from_slice(b"</VTKFile>\n");
    s
}

const EXTENT: &str = "WholeExtent=\"0 2 0 1 0 1\" Origin=\"10 20 30\" Spacing=\"0.5 1 2\"";

/// The test values: 2x1x1 cells or 3x2x2 points, x + 3 y + 6 z.
fn values(n: usize) -> Vec<i32> {
    (0..n as i32).collect()
}

fn le(values: &[i32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn zlib(data: &[u8]) -> Vec<u8> {
    let mut enc = ZlibEncoder::new(Vec::new(), Compression::default());
    enc.write_all(data).unwrap();
    enc.finish().unwrap()
}

/// Compressed framing: blocks of `block` bytes, UInt32 header.
fn compressed(data: &[u8], block: usize) -> (Vec<u8>, Vec<u8>) {
    let chunks: Vec<Vec<u8>> = data.chunks(block).map(zlib).collect();
    let last = data.len() % block;
    let mut header = Vec::new();
    for w in [chunks.len(), block, last].into_iter().chain(chunks.iter().map(Vec::len)) {
        header.extend_from_slice(&(w as u32).to_le_bytes());
    }
    (header, chunks.concat())
}

#[test]
fn bundled_channels() {
    let bytes = std::fs::read(concat!(env!("CARGO_MANIFEST_DIR"), "/../../data/channels.vti")).unwrap();
    let v = labels(read(&bytes).unwrap());
    assert_eq!(v.dims(), [250, 250, 100]);
    assert_eq!(v.spacing(), DVec3::ONE);
    assert_eq!(v.origin(), DVec3::splat(0.5));
    assert_eq!(v.label_counts(), vec![(0, 5184411), (1, 684869), (2, 142051), (3, 214455), (4, 24214)]);
}

#[test]
fn ascii_cell_and_point_data() {
    let array = format!(
        "<DataArray type=\"Int32\" Name=\"a\" format=\"ascii\">{}</DataArray>",
        values(2).iter().map(i32::to_string).collect::<Vec<_>>().join(" ")
    );
    let v = labels(read(&vti("", EXTENT, "CellData Scalars=\"a\"", &array, b"")).unwrap());
    assert_eq!(v.dims(), [2, 1, 1]);
    assert_eq!(v.label([1, 0, 0]), Some(1));
    // Cell centres: origin + (i + 0.5) * spacing.
    assert_eq!(v.origin(), DVec3::new(10.25, 20.5, 31.0));
    assert_eq!(v.spacing(), DVec3::new(0.5, 1.0, 2.0));

    let array = format!(
        "<DataArray type=\"Float64\" Name=\"p\" format=\"ascii\">\n{}\n</DataArray>",
        values(12).iter().map(|v| format!("{v}.0")).collect::<Vec<_>>().join("\n")
    );
    let v = labels(read(&vti("", EXTENT, "PointData", &array, b"")).unwrap());
    assert_eq!(v.dims(), [3, 2, 2]);
    assert_eq!(v.label([2, 1, 1]), Some(11));
    assert_eq!(v.origin(), DVec3::new(10.0, 20.0, 30.0));
}

#[test]
fn binary_inline_raw_compressed_and_split_headers() {
    let data = le(&values(12));
    // Header and data encoded together, and separately (as VTK does).
    let together = STANDARD.encode([(data.len() as u32).to_le_bytes().to_vec(), data.clone()].concat());
    let apart = STANDARD.encode((data.len() as u32).to_le_bytes()) + &STANDARD.encode(&data);
    let (h, c) = compressed(&data, 20);
    let zipped = STANDARD.encode(&h) + &STANDARD.encode(&c);
    for (root, text) in [("", together), ("", apart), ("compressor=\"vtkZLibDataCompressor\"", zipped)] {
        let array =
            format!("<DataArray type=\"Int32\" Name=\"p\" format=\"binary\">\n  {text}\n</DataArray>");
        let v = labels(read(&vti(root, EXTENT, "PointData", &array, b"")).unwrap());
        assert_eq!(v.label([2, 1, 1]), Some(11), "{root}");
        assert_eq!(v.label([1, 1, 0]), Some(4), "{root}");
    }
}

#[test]
fn appended_raw_and_base64_big_endian_uint64_headers() {
    let data = le(&values(12));
    // Raw, little endian, two arrays: the second one is read (active scalars).
    let mut raw = b"<AppendedData encoding=\"raw\">\n_".to_vec();
    raw.extend_from_slice(&4u32.to_le_bytes());
    raw.extend_from_slice(&[9, 9, 9, 9]);
    raw.extend_from_slice(&(data.len() as u32).to_le_bytes());
    raw.extend_from_slice(&data);
    raw.extend_from_slice(b"\n</AppendedData>\n");
    let arrays = "<DataArray type=\"Int32\" Name=\"other\" format=\"appended\" offset=\"0\"/>\n\
                  <DataArray type=\"Int32\" Name=\"p\" format=\"appended\" offset=\"8\"/>";
    let v = labels(read(&vti("", EXTENT, "PointData Scalars=\"p\"", arrays, &raw)).unwrap());
    assert_eq!(v.label([2, 1, 1]), Some(11));

    // Base64, big endian, UInt64 header, compressed.
    let be: Vec<u8> = values(12).iter().flat_map(|v| (*v as i16).to_be_bytes()).collect();
    let chunks = [zlib(&be[..16]), zlib(&be[16..])];
    let mut header = Vec::new();
    for w in [2, 16, 8, chunks[0].len() as u64, chunks[1].len() as u64] {
        header.extend_from_slice(&w.to_be_bytes());
    }
    let text = STANDARD.encode(&header) + &STANDARD.encode(chunks.concat());
    let appended = format!("<AppendedData encoding=\"base64\">\n   _{text}\n</AppendedData>\n");
    let root = "byte_order=\"BigEndian\" header_type=\"UInt64\" compressor=\"vtkZLibDataCompressor\"";
    let array = "<DataArray type=\"Int16\" Name=\"p\" format=\"appended\" offset=\"0\"/>";
    let v = labels(read(&vti(root, EXTENT, "PointData", array, appended.as_bytes())).unwrap());
    assert_eq!(v.label([2, 1, 1]), Some(11));
    assert_eq!(v.label([0, 1, 1]), Some(9));
}

#[test]
fn pieces_direction_and_grey_levels() {
    // Two pieces of 2x2x1 points each, splitting z; Direction flips x.
    let text = |vals: &[f32]| vals.iter().map(|v| v.to_string()).collect::<Vec<_>>().join(" ");
    let s = format!(
        "<VTKFile type=\"ImageData\"><ImageData WholeExtent=\"0 1 0 1 0 1\" Direction=\"-1 0 0 0 1 0 0 0 1\">\
         <Piece Extent=\"0 1 0 1 1 1\"><PointData><DataArray type=\"Float32\" Name=\"g\">{}</DataArray></PointData></Piece>\
         <Piece Extent=\"0 1 0 1 0 0\"><PointData><DataArray type=\"Float32\" Name=\"g\">{}</DataArray></PointData></Piece>\
         </ImageData></VTKFile>",
        text(&[4.5, 5.5, 6.5, 7.5]),
        text(&[0.5, 1.5, 2.5, 3.5]),
    );
    let Voxels::Grey(g) = read(s.as_bytes()).unwrap() else { panic!("grey expected") };
    assert_eq!(g.dims(), [2, 2, 2]);
    // Stored x = 1 is at world x = -1: the new voxel 0.
    assert_eq!(g.origin(), DVec3::new(-1.0, 0.0, 0.0));
    assert_eq!(g.values()[[0, 0, 0]], 1.5);
    assert_eq!(g.values()[[1, 1, 1]], 6.5);
}

#[test]
fn bad_input() {
    let ascii =
        |values: &str| format!("<DataArray type=\"UInt8\" Name=\"a\" format=\"ascii\">{values}</DataArray>");
    let cell = |array: &str| vti("", EXTENT, "CellData", array, b"");
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (b"".to_vec(), "malformed XML"),
        (b"\x89PNG\r\n".to_vec(), "not UTF-8"),
        (b"<VTKFile type=\"ImageData\"><ImageData>".to_vec(), "malformed XML"),
        (b"<html/>".to_vec(), "the root element is <html>"),
        (b"<VTKFile type=\"PolyData\"/>".to_vec(), "unsupported: VTK dataset type PolyData"),
        (b"<VTKFile type=\"ImageData\"/>".to_vec(), "no <ImageData>"),
        (
            vti("compressor=\"vtkLZ4DataCompressor\"", EXTENT, "CellData", &ascii("1 2"), b""),
            "unsupported: compressor",
        ),
        (
            vti("header_type=\"UInt16\"", EXTENT, "CellData", &ascii("1 2"), b""),
            "unsupported: header_type UInt16",
        ),
        (vti("byte_order=\"Middle\"", EXTENT, "CellData", &ascii("1 2"), b""), "unknown byte_order"),
        (vti("", "WholeExtent=\"0 2 0 1\"", "CellData", &ascii("1 2"), b""), "is not six integers"),
        (vti("", "WholeExtent=\"2 0 0 1 0 1\"", "CellData", &ascii("1 2"), b""), "empty or out-of-range"),
        (
            vti("", "WholeExtent=\"0 2 0 1 0 1\" Spacing=\"1 nan 1\"", "CellData", &ascii("1 2"), b""),
            "Spacing",
        ),
        (
            vti("", "WholeExtent=\"0 2 0 1 0 1\" Spacing=\"1 0 1\"", "CellData", &ascii("1 2"), b""),
            "degenerate",
        ),
        (vti("", EXTENT, "CellData", "", b""), "no <DataArray>"),
        (cell(&ascii("1")), "truncated data: 1 values for 2 voxels"),
        (cell(&ascii("1 2 3")), "dimensions do not match the data"),
        (cell(&ascii("1 300")), "value 1: '300' is not a u8"),
        (cell("<DataArray type=\"String\" Name=\"a\">x y</DataArray>"), "unsupported: DataArray type String"),
        (
            cell("<DataArray type=\"UInt8\" NumberOfComponents=\"3\">1 2 3 4 5 6</DataArray>"),
            "unsupported: NumberOfComponents 3",
        ),
        (cell("<DataArray type=\"UInt8\" NumberOfTuples=\"5\">1 2</DataArray>"), "NumberOfTuples 5"),
        (cell("<DataArray type=\"UInt8\" format=\"hex\">1 2</DataArray>"), "unknown format 'hex'"),
        (cell("<DataArray type=\"UInt8\" format=\"binary\">AgAAAAE</DataArray>"), "truncated base64 data"),
        (
            cell("<DataArray type=\"UInt8\" format=\"binary\">AwAAAAECAw==</DataArray>"),
            "the array holds 3 bytes, the extent needs 2",
        ),
        (
            cell("<DataArray type=\"UInt8\" format=\"binary\">AQAAAAE=</DataArray>"),
            "truncated data: the array holds 1 bytes",
        ),
        (cell("<DataArray type=\"UInt8\" format=\"binary\">!!!!AAAA</DataArray>"), "bad base64 data"),
        (cell("<DataArray type=\"UInt8\" format=\"appended\" offset=\"0\"/>"), "no <AppendedData>"),
        (
            cell("<DataArray type=\"Float32\" format=\"ascii\">1 nan</DataArray>"),
            "grey level NaN at voxel [1, 0, 0]",
        ),
        (
            vti(
                "",
                EXTENT,
                "CellData",
                "<DataArray type=\"UInt8\" format=\"appended\" offset=\"99\"/>",
                b"<AppendedData encoding=\"raw\">_\x02\0\0\0\x01\x02</AppendedData>",
            ),
            "offset 99 is past",
        ),
        (
            vti("", EXTENT, "CellData", &ascii("1 2"), b"<AppendedData encoding=\"gzip\">_</AppendedData>"),
            "no encoding",
        ),
        (
            vti("", EXTENT, "CellData", &ascii("1 2"), b"<AppendedData encoding=\"raw\">xx</AppendedData>"),
            "does not start with '_'",
        ),
        (
            vti("", "WholeExtent=\"0 100000 0 100000 0 100000\"", "CellData", &ascii("1"), b""),
            "exceeds the limit",
        ),
    ];
    crate::testing::assert_refused(&cases, message);
    // Raw appended data cut short (nothing after them).
    let mut cut = vti(
        "",
        EXTENT,
        "CellData",
        "<DataArray type=\"UInt8\" format=\"appended\" offset=\"0\"/>",
        b"<AppendedData encoding=\"raw\">_\x02\0\0\0\x01",
    );
    cut.truncate(cut.len() - "</VTKFile>\n".len());
    assert!(message(&cut).contains("truncated data: 2 bytes needed, 1 left"));
    // Compressed: corrupt block, wrong sizes.
    let data = [1u8, 2];
    let (h, c) = compressed(&data, 2);
    let zipped = |h: &[u8], c: &[u8]| {
        let array = format!(
            "<DataArray type=\"UInt8\" format=\"binary\">{}{}</DataArray>",
            STANDARD.encode(h),
            STANDARD.encode(c)
        );
        vti("compressor=\"vtkZLibDataCompressor\"", EXTENT, "CellData", &array, b"")
    };
    assert!(read(&zipped(&h, &c)).is_ok());
    assert!(message(&zipped(&h, &vec![b'!'; c.len()])).contains("corrupt zlib data"));
    let mut bad = h.clone();
    bad[4] = 3; // block size 3: 3 bytes declared
    assert!(message(&zipped(&bad, &c)).contains("the array holds 3 bytes"));
    let mut huge = h.clone();
    huge[..4].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(message(&zipped(&huge, &c)).contains("dimensions do not match the data"));
    // A piece outside the whole extent, and pieces that do not cover it.
    let piece = |extent: &str| {
        format!(
            "<VTKFile type=\"ImageData\"><ImageData WholeExtent=\"0 1 0 0 0 0\"><Piece Extent=\"{extent}\">\
             <PointData><DataArray type=\"UInt8\">1</DataArray></PointData></Piece></ImageData></VTKFile>"
        )
    };
    assert!(message(piece("0 2 0 0 0 0").as_bytes()).contains("outside the WholeExtent"));
    assert!(message(piece("1 1 0 0 0 0").as_bytes()).contains("cannot cover"));
}
