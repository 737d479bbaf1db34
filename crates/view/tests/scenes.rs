//! MagicaVoxel scenes through the viewer's load path ([`voxreg_view::read_volume`], then
//! the session's surface and solve), opened from the command line and uploaded: a scene
//! of models far apart as blocks, under a 4 GiB address-space limit; dense scenes with
//! the same answers, byte for byte, as the dense path.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use voxreg_io::InputOptions;
use voxreg_regularize::{Overrides, Preset};
use voxreg_view::{read_volume, Loaded, Viewer, Volume};

/// The environment variable that makes a test run its body (set when it re-runs itself
/// under the address-space limit).
const LIMITED: &str = "VOXREG_VIEW_TEST_LIMITED";

/// Loads as the command line's loader does (no options), from `bytes` where given.
fn load(name: &str, bytes: Option<&[u8]>) -> Result<Loaded, String> {
    let (volume, palette) =
        read_volume(Path::new(name), bytes, &InputOptions::default()).map_err(|e| e.to_string())?;
    let preset = if voxreg_io::is_voxel_art(Path::new(name)) { Preset::VoxelArt } else { Preset::Default };
    Ok(Loaded { name: name.into(), volume, palette, preset, overrides: Overrides::default() })
}

/// Answers one request through [`Viewer::respond_to`]: the status and the body.
fn request(viewer: &Viewer, method: &str, path: &str, body: &[u8]) -> (u16, Vec<u8>) {
    let sep = if path.contains('?') { '&' } else { '?' };
    let mut raw = format!(
        "{method} {path}{sep}token={} HTTP/1.1\r\nHost: {}\r\nContent-Length: {}\r\n\r\n",
        viewer.token(),
        viewer.addr(),
        body.len()
    )
    .into_bytes();
    raw.extend_from_slice(body);
    let out = viewer.respond_to(&raw);
    let head_end = out.windows(4).position(|w| w == b"\r\n\r\n").expect("a response head") + 4;
    let status = std::str::from_utf8(&out[9..12]).unwrap().parse().unwrap();
    (status, out[head_end..].to_vec())
}

/// Waits until the viewer's solve is over; returns the state.
fn finished(viewer: &Viewer) -> serde_json::Value {
    let start = Instant::now();
    loop {
        let (status, body) = request(viewer, "GET", "/api/state", b"");
        assert_eq!(status, 200);
        let state: serde_json::Value = serde_json::from_slice(&body).unwrap();
        if let Some(e) = state["error"].as_str() {
            panic!("the viewer's error: {e}");
        }
        if state["busy"] == false && state["stage"] == "done" {
            return state;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "no result in a minute: {state}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// What the page draws and downloads of `loaded`, opened (`upload`: `None`) or uploaded
/// into a viewer showing something else: the surface's arrays and the OBJ file.
fn shown(loaded: Loaded, upload: Option<(&str, &[u8])>) -> (Vec<u8>, Vec<u8>) {
    let viewer = Viewer::bind(0, Box::new(|name: &str, bytes: &[u8]| load(name, Some(bytes)))).unwrap();
    viewer.open(loaded);
    finished(&viewer);
    if let Some((name, bytes)) = upload {
        let (status, body) = request(&viewer, "POST", &format!("/api/open?name={name}"), bytes);
        assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
        let state = finished(&viewer);
        assert_eq!(state["name"], name, "{state}");
    }
    let (status, surface) = request(&viewer, "GET", "/api/surface", b"");
    assert_eq!(status, 200);
    let (status, obj) = request(&viewer, "GET", "/api/download?format=obj", b"");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&obj));
    (surface, obj)
}

/// A one-voxel stand-in the viewer shows before an upload.
fn placeholder() -> Loaded {
    let volume = voxreg_digisurf::LabelVolume::from_fn([3, 3, 3], |p| u32::from(p == [1, 1, 1]));
    Loaded {
        name: "one.vol".into(),
        volume: volume.into(),
        palette: None,
        preset: Preset::Default,
        overrides: Overrides::default(),
    }
}

#[test]
fn a_scene_of_models_far_apart_opens_as_blocks_under_ulimit() {
    if std::env::var_os(LIMITED).is_none() {
        // Re-run this test alone under a 4 GiB address space (the scene made dense is
        // 2002 x 2001 x 2001 voxels, 32 GiB of labels).
        let exe = std::env::current_exe().unwrap();
        let out = Command::new("sh")
            .arg("-c")
            .arg("ulimit -v 4194304 && exec \"$0\" \"$@\"")
            .arg(exe)
            .args(["--exact", "a_scene_of_models_far_apart_opens_as_blocks_under_ulimit", "--nocapture"])
            .env(LIMITED, "1")
            .output()
            .unwrap();
        let text =
            format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        assert!(out.status.success(), "under ulimit -v 4194304: {text}");
        assert!(text.contains("1 passed"), "{text}");
        return;
    }
    // Two two-voxel models 2,000 voxels apart along each axis: 20 quads.
    let bytes = voxreg_testkit::vox_scene(&[[2, 1, 1]; 2], &["0 0 0", "2000 2000 2000"]);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("apart.vox");
    std::fs::write(&path, &bytes).unwrap();
    let start = Instant::now();
    // From the command line (a path), and uploaded (from memory).
    let opened = load(path.to_str().unwrap(), None).unwrap();
    assert!(matches!(&opened.volume, Volume::Blocks(b) if b.dims() == [2002, 2001, 2001]));
    for (surface, obj) in [shown(opened, None), shown(placeholder(), Some(("apart.vox", bytes.as_slice())))] {
        let faces = u32::from_le_bytes(surface[..4].try_into().unwrap());
        assert_eq!(faces, 20);
        let quads = String::from_utf8_lossy(&obj).lines().filter(|l| l.starts_with("f ")).count();
        assert_eq!(quads, 20);
    }
    assert!(start.elapsed() < Duration::from_secs(20), "{:?}", start.elapsed());
}

#[test]
fn dense_scenes_show_as_the_dense_path_byte_for_byte() {
    // Bundled scenes (axes.vox is mostly empty space: read as blocks; chr_army1.vox is
    // one model: read dense) and a small scene of models apart (blocks): the surface
    // arrays and the downloaded mesh of the dense volume, opened and uploaded.
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data");
    let apart = voxreg_testkit::vox_scene(
        &[[3, 2, 2], [2, 3, 2], [2, 2, 1], [1, 4, 1]],
        &["0 0 0", "2 1 1", "14 3 -5", "-3 -30 -20"],
    );
    let mut inputs = vec![("apart.vox".to_string(), apart, Some(true))];
    for (name, sparse) in
        [("axes.vox", Some(true)), ("chr_army1.vox", Some(false)), ("placeholder-with-materials.vox", None)]
    {
        inputs.push((name.to_string(), std::fs::read(data.join(name)).unwrap(), sparse));
    }
    for (name, bytes, sparse) in inputs {
        let loaded = load(&name, Some(&bytes)).unwrap();
        if let Some(sparse) = sparse {
            assert_eq!(matches!(loaded.volume, Volume::Blocks(_)), sparse, "{name}");
        }
        let input = voxreg_io::read_input_bytes(&bytes, Path::new(&name), &InputOptions::default()).unwrap();
        let dense = Loaded { volume: input.volume.into(), palette: input.palette, ..loaded.clone() };
        let expected = shown(dense, None);
        assert_eq!(shown(loaded, None), expected, "{name}");
        assert_eq!(
            shown(placeholder(), Some((name.as_str(), bytes.as_slice()))),
            expected,
            "{name} uploaded"
        );
    }
}
