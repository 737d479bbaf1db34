//! Fuzzes the viewer's request handling (`Viewer::respond_to`, what each connection runs):
//! any bytes are answered with an HTTP response or nothing, never a panic, and a declared
//! body is never allocated before it is received.
//!
//! `{HOST}` and `{TOKEN}` in an input stand for the server's `Host` and its session's
//! token (random), so that inputs reach the routes behind the checks.
#![no_main]

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use voxreg_view::Viewer;

fn viewer() -> &'static Viewer {
    static VIEWER: OnceLock<Viewer> = OnceLock::new();
    VIEWER.get_or_init(|| {
        let refuse = |name: &str, _: &[u8]| Err(format!("{name}: uploads are not read while fuzzing"));
        let viewer = Viewer::bind(0, Box::new(refuse)).expect("a loopback port");
        // Stopped: a request for a newer frame or for events returns at once.
        viewer.stop_handle().stop();
        viewer
    })
}

/// `data` with the placeholders replaced.
fn substituted(viewer: &Viewer, data: &[u8]) -> Vec<u8> {
    let text = String::from_utf8_lossy(data);
    if !text.contains("{HOST}") && !text.contains("{TOKEN}") {
        return data.to_vec();
    }
    let host = format!("127.0.0.1:{}", viewer.addr().port());
    text.replace("{HOST}", &host).replace("{TOKEN}", viewer.token()).into_bytes()
}

fuzz_target!(|data: &[u8]| {
    let viewer = viewer();
    let out = viewer.respond_to(&substituted(viewer, data));
    assert!(out.is_empty() || out.starts_with(b"HTTP/1.1 "), "{}", String::from_utf8_lossy(&out));
});
