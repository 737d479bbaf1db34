//! The viewer that answers the `request` fuzz target's inputs and the test that replays
//! its seeds (`crates/view/tests/fuzz_requests.rs`), and the placeholders of those inputs.

use voxreg_view::Viewer;

/// A viewer that refuses uploads, stopped: a request for a newer frame or for events
/// returns at once.
pub(crate) fn viewer() -> Viewer {
    let refuse = |name: &str, _: &[u8]| Err(format!("{name}: uploads are not read while fuzzing"));
    let viewer = Viewer::bind(0, Box::new(refuse)).expect("a loopback port");
    viewer.stop_handle().stop();
    viewer
}

/// `data` with `{HOST}` and `{TOKEN}` replaced by the viewer's `Host` and its session's
/// token (random), so that inputs reach the routes behind those checks.
pub(crate) fn substituted(viewer: &Viewer, data: &[u8]) -> Vec<u8> {
    let text = String::from_utf8_lossy(data);
    if !text.contains("{HOST}") && !text.contains("{TOKEN}") {
        return data.to_vec();
    }
    let host = format!("127.0.0.1:{}", viewer.addr().port());
    text.replace("{HOST}", &host).replace("{TOKEN}", viewer.token()).into_bytes()
}
