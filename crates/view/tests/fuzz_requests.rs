//! Replays the request fuzz target's seeds (`fuzz/seeds/request/`) and thousands of
//! deterministic mutations of them (bytes flipped, inserted, deleted, cut, numbers
//! replaced by boundary values) through [`Viewer::respond_to`], as the fuzz target does:
//! every input is answered with an HTTP response or nothing, never a panic. Every
//! `cargo test` runs it, with no nightly toolchain.

use std::panic::AssertUnwindSafe;
use std::path::Path;

use voxreg_testkit::Xorshift;

#[path = "../../../fuzz/fuzz_targets/request_case.rs"]
mod request_case;
use request_case::{substituted, viewer};

fn seeds() -> Vec<(String, Vec<u8>)> {
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../fuzz/seeds/request"));
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap()))
        .collect();
    out.sort();
    assert!(out.len() >= 10, "{} seeds", out.len());
    out
}

/// The status of a response (after a `100 Continue`), 0 for none.
fn status(out: &[u8]) -> u16 {
    let out = out.strip_prefix(&b"HTTP/1.1 100 Continue\r\n\r\n"[..]).unwrap_or(out);
    assert!(out.is_empty() || out.starts_with(b"HTTP/1.1 "), "{}", String::from_utf8_lossy(out));
    String::from_utf8_lossy(out.get(9..12).unwrap_or_default()).parse().unwrap_or(0)
}

#[test]
fn the_seeds_get_their_answers() {
    let viewer = viewer();
    let expected = [
        ("chunked.http", 411),
        ("cross-origin.http", 403),
        ("download.http", 409),
        ("edit.http", 409),
        ("events.http", 200),
        ("huge.http", 413),
        ("level.http", 409), // a level chosen, but no input open
        ("open.http", 400),
        ("page.http", 200),
        ("positions.http", 404),
        ("preset.http", 200),
        ("solve.http", 409), // well-formed parameters, but no input open
        ("state.http", 200),
    ];
    for (name, bytes) in seeds() {
        let got = status(&viewer.respond_to(&substituted(&viewer, &bytes)));
        if let Some((_, want)) = expected.iter().find(|(n, _)| *n == name) {
            assert_eq!(got, *want, "{name}");
        }
    }
}

fn mutate(seed: &[u8], rng: &mut Xorshift) -> Vec<u8> {
    let mut b = seed.to_vec();
    for _ in 0..1 + rng.below(4) {
        let at = rng.below(b.len() + 1);
        match rng.below(6) {
            0 if !b.is_empty() => {
                let i = at.min(b.len() - 1);
                b[i] ^= 1 << rng.below(8);
            }
            1 => b.insert(at, rng.next_u64() as u8),
            2 if at < b.len() => {
                b.remove(at);
            }
            3 => b.truncate(at),
            4 => {
                // A number replaced by a boundary value.
                let text = String::from_utf8_lossy(&b).into_owned();
                let digits: Vec<usize> =
                    text.match_indices(|c: char| c.is_ascii_digit()).map(|(i, _)| i).collect();
                if let Some(&i) = digits.get(rng.below(digits.len())) {
                    let end = text[i..].find(|c: char| !c.is_ascii_digit()).map_or(text.len(), |e| i + e);
                    let values = ["0", "-1", "18446744073709551616", "4294967295", "1e308", "NaN"];
                    let v = values[rng.below(values.len())];
                    b = format!("{}{v}{}", &text[..i], &text[end..]).into_bytes();
                }
            }
            _ => {
                // A line break or a header inserted.
                let piece: &[u8] = if rng.below(2) == 0 { b"\r\n" } else { b"Content-Length: 5\r\n" };
                let at = at.min(b.len());
                b.splice(at..at, piece.iter().copied());
            }
        }
    }
    b
}

#[test]
fn mutated_requests_are_answered_or_dropped_never_a_panic() {
    let viewer = viewer();
    let mut rng = Xorshift::new(0x9e37_79b9_7f4a_7c15);
    for (name, seed) in seeds() {
        let seed = substituted(&viewer, &seed);
        for i in 0..300 {
            let bytes = mutate(&seed, &mut rng);
            let out = std::panic::catch_unwind(AssertUnwindSafe(|| viewer.respond_to(&bytes)))
                .unwrap_or_else(|_| {
                    panic!("{name} mutation {i} panicked: {:?}", String::from_utf8_lossy(&bytes))
                });
            status(&out);
        }
    }
}
