//! Fuzzes the viewer's request handling (`Viewer::respond_to`, what each connection runs):
//! any bytes are answered with an HTTP response or nothing, never a panic, and a declared
//! body is never allocated before it is received.
//!
//! `{HOST}` and `{TOKEN}` in an input stand for the server's `Host` and its session's
//! token (random), so that inputs reach the routes behind the checks (`request_case`).
#![no_main]

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use voxreg_view::Viewer;

mod request_case;

fn viewer() -> &'static Viewer {
    static VIEWER: OnceLock<Viewer> = OnceLock::new();
    VIEWER.get_or_init(request_case::viewer)
}

fuzz_target!(|data: &[u8]| {
    let viewer = viewer();
    let out = viewer.respond_to(&request_case::substituted(viewer, data));
    assert!(out.is_empty() || out.starts_with(b"HTTP/1.1 "), "{}", String::from_utf8_lossy(&out));
});
