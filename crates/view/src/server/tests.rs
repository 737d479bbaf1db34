//! The server over real loopback connections: pages, the event stream, solves, downloads,
//! and bad requests answered with messages while the server keeps serving.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::Path;
use std::time::{Duration, Instant};

use voxreg_digisurf::LabelVolume;

use super::FRAME_WAIT;
use voxreg_regularize::{Overrides, Preset, SolverChoice};

use crate::{Loaded, StopHandle, Viewer};

/// A digital ball of radius 4 (papers preset: one quick solve).
fn ball(name: &str) -> Loaded {
    let volume = LabelVolume::from_fn([11, 11, 11], |[x, y, z]| {
        let d = |c: usize| c as f64 - 5.0;
        u32::from(d(x).powi(2) + d(y).powi(2) + d(z).powi(2) <= 16.0)
    });
    Loaded {
        name: name.into(),
        volume: volume.into(),
        palette: None,
        preset: Preset::Papers,
        overrides: Overrides::default(),
    }
}

/// Reads what the command line reads (no options), from memory, as the CLI's loader does.
fn load(name: &str, bytes: &[u8]) -> Result<Loaded, String> {
    let v = voxreg_io::read_input_bytes(bytes, Path::new(name), &voxreg_io::InputOptions::default())
        .map_err(|e| e.to_string())?;
    Ok(Loaded {
        name: name.to_string(),
        volume: v.volume.into(),
        palette: v.palette,
        preset: Preset::Papers,
        overrides: Overrides::default(),
    })
}

struct Running {
    addr: SocketAddr,
    token: String,
    stop: StopHandle,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Drop for Running {
    fn drop(&mut self) {
        self.stop.stop();
        if let Some(t) = self.thread.take() {
            t.join().expect("the server thread ends cleanly");
        }
    }
}

fn start() -> Running {
    start_with(ball("ball.vol"))
}

fn start_with(loaded: Loaded) -> Running {
    let viewer = Viewer::bind(0, Box::new(load)).unwrap();
    assert!(viewer.addr().ip().is_loopback());
    assert!(viewer.url().starts_with("http://127.0.0.1:"));
    assert!(viewer.url().ends_with(&format!("/?token={}", viewer.token())));
    viewer.open(loaded);
    let (addr, stop, token) = (viewer.addr(), viewer.stop_handle(), viewer.token().to_string());
    Running { addr, token, stop, thread: Some(std::thread::spawn(move || viewer.serve())) }
}

impl Running {
    /// `path` with the session's token.
    fn tokened(&self, path: &str) -> String {
        let sep = if path.contains('?') { '&' } else { '?' };
        format!("{path}{sep}token={}", self.token)
    }

    fn host(&self) -> String {
        format!("127.0.0.1:{}", self.addr.port())
    }
}

/// One request (`Connection: close`): the status and the body.
fn request(addr: SocketAddr, method: &str, path: &str, host: Option<&str>, body: &[u8]) -> (u16, Vec<u8>) {
    let (status, _, body) = exchange(addr, method, path, host, body);
    (status, body)
}

/// One request: the status, the head and the body.
fn exchange(
    addr: SocketAddr,
    method: &str,
    path: &str,
    host: Option<&str>,
    body: &[u8],
) -> (u16, String, Vec<u8>) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
    let host = host.map(|h| format!("Host: {h}\r\n")).unwrap_or_default();
    let head = format!(
        "{method} {path} HTTP/1.1\r\n{host}Content-Length: {}\r\nConnection: close\r\n\r\n",
        body.len()
    );
    s.write_all(head.as_bytes()).unwrap();
    s.write_all(body).unwrap();
    let mut out = Vec::new();
    s.read_to_end(&mut out).unwrap();
    let end = out.windows(4).position(|w| w == b"\r\n\r\n").expect("a response head") + 4;
    let status = String::from_utf8_lossy(&out[9..12]).parse().unwrap();
    (status, String::from_utf8_lossy(&out[..end]).into_owned(), decode_body(&out[..end], &out[end..]))
}

fn decode_body(head: &[u8], body: &[u8]) -> Vec<u8> {
    let chunked = String::from_utf8_lossy(head).to_ascii_lowercase().contains("transfer-encoding: chunked");
    if !chunked {
        return body.to_vec();
    }
    let (mut out, mut rest) = (Vec::new(), body);
    loop {
        let line = rest.windows(2).position(|w| w == b"\r\n").unwrap();
        let n = usize::from_str_radix(std::str::from_utf8(&rest[..line]).unwrap().trim(), 16).unwrap();
        if n == 0 {
            return out;
        }
        out.extend_from_slice(&rest[line + 2..line + 2 + n]);
        rest = &rest[line + 4 + n..];
    }
}

/// A GET of `path` with the session's token.
fn get(r: &Running, path: &str) -> (u16, Vec<u8>) {
    request(r.addr, "GET", &r.tokened(path), Some(&r.host()), b"")
}

/// A POST of `body` to `path` with the session's token.
fn post(r: &Running, path: &str, body: &[u8]) -> (u16, Vec<u8>) {
    request(r.addr, "POST", &r.tokened(path), Some(&r.host()), body)
}

fn json(bytes: &[u8]) -> serde_json::Value {
    serde_json::from_slice(bytes).unwrap_or_else(|e| panic!("{e}: {}", String::from_utf8_lossy(bytes)))
}

/// Polls the state until `done` holds of it.
fn wait_for(r: &Running, done: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
    let t = Instant::now();
    loop {
        let state = json(&get(r, "/api/state").1);
        if done(&state) {
            return state;
        }
        assert!(t.elapsed() < Duration::from_secs(60), "timed out: {state}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn error_of(reply: (u16, Vec<u8>)) -> (u16, String) {
    let message = json(&reply.1)["error"].as_str().unwrap_or_default().to_string();
    (reply.0, message)
}

#[test]
fn serves_the_page_and_its_assets_to_its_own_host_only() {
    let r = start();
    let (status, page) = get(&r, "/");
    assert_eq!(status, 200);
    assert!(String::from_utf8_lossy(&page).contains("<canvas"));
    for asset in
        ["/app.js", "/style.css", "/three/three.module.min.js", "/three/OrbitControls.js", "/three/LICENSE"]
    {
        let (status, body) = get(&r, asset);
        assert_eq!(status, 200, "{asset}");
        assert!(!body.is_empty(), "{asset}");
    }
    let localhost = format!("localhost:{}", r.addr.port());
    assert_eq!(request(r.addr, "GET", "/", Some(&localhost), b"").0, 200);
    // Another site's name for this address (DNS rebinding), or none: refused.
    let (status, message) = error_of(request(r.addr, "GET", "/", Some("evil.example:80"), b""));
    assert_eq!((status, message.as_str()), (403, "unexpected Host 'evil.example:80'"));
    assert_eq!(error_of(get(&r, "/nothing-here")), (404, "no such page: /nothing-here".into()));
    assert_eq!(error_of(request(r.addr, "DELETE", "/", Some(&localhost), b"")).0, 405);
}

/// Sends `head` (no body, whatever it declares) and reads the answer: status and body.
fn send_head(addr: SocketAddr, head: &str) -> (u16, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    s.write_all(head.as_bytes()).unwrap();
    let mut out = Vec::new();
    s.read_to_end(&mut out).unwrap();
    let text = String::from_utf8_lossy(&out).into_owned();
    let status = text.get(9..12).and_then(|c| c.parse().ok()).unwrap_or(0);
    (status, text.split_once("\r\n\r\n").map(|(_, b)| b.to_string()).unwrap_or_default())
}

#[test]
fn a_huge_declared_body_is_refused_before_it_is_read() {
    let r = start();
    wait_for(&r, |s| s["final"] == true);
    // A terabyte declared (and not sent), to every kind of route: answered at once, and
    // the server stays up.
    for (method, path) in
        [("POST", "/api/open?name=a.vox"), ("POST", "/api/solve"), ("GET", "/api/state"), ("GET", "/")]
    {
        let head = format!(
            "{method} {} HTTP/1.1\r\nHost: {}\r\nContent-Length: 1000000000000\r\n\r\n",
            r.tokened(path),
            r.host()
        );
        let (status, body) = send_head(r.addr, &head);
        assert_eq!(status, 413, "{method} {path}: {body}");
        assert!(body.contains("the request body is over"), "{body}");
    }
    // Chunked bodies (no length to check first), conflicting lengths and huge heads too.
    let chunked = format!(
        "POST {} HTTP/1.1\r\nHost: {}\r\nTransfer-Encoding: chunked\r\n\r\n",
        r.tokened("/api/solve"),
        r.host()
    );
    assert_eq!(send_head(r.addr, &chunked).0, 411);
    let two = format!(
        "POST {} HTTP/1.1\r\nHost: {}\r\nContent-Length: 2\r\nContent-Length: 3\r\n\r\n",
        r.tokened("/api/solve"),
        r.host()
    );
    assert_eq!(send_head(r.addr, &two).0, 400);
    let big = format!("GET / HTTP/1.1\r\nHost: {}\r\nX-Pad: {}\r\n\r\n", r.host(), "a".repeat(20_000));
    assert_eq!(send_head(r.addr, &big).0, 431);
    assert_eq!(json(&get(&r, "/api/state").1)["final"], true);
}

#[test]
fn the_api_needs_the_session_token_and_refuses_other_origins() {
    let r = start();
    let state = wait_for(&r, |s| s["final"] == true);
    let host = r.host();
    // The page itself is public; its API is not, without the token or with a wrong one.
    assert_eq!(request(r.addr, "GET", "/", Some(&host), b"").0, 200);
    for path in ["/api/state", "/api/surface", "/api/positions", "/api/events", "/api/download?format=ply"] {
        let (status, message) = error_of(request(r.addr, "GET", path, Some(&host), b""));
        assert_eq!(status, 403, "{path}");
        assert!(message.contains("token"), "{message}");
        let wrong = format!("{path}{}token=0123", if path.contains('?') { '&' } else { '?' });
        assert_eq!(request(r.addr, "GET", &wrong, Some(&host), b"").0, 403, "{wrong}");
    }
    // The token in a header does as well as in the query.
    let head = format!("GET /api/state HTTP/1.1\r\nHost: {host}\r\nX-Voxreg-Token: {}\r\n\r\n", r.token);
    assert_eq!(send_head(r.addr, &head).0, 200);
    // Another site's page, posting a solve as text/plain (no preflight): refused, with or
    // without the token, and nothing is queued.
    let mut tuning = state["tuning"].clone();
    tuning["refine"] = serde_json::json!(1_000_000);
    let body = tuning.to_string();
    for path in ["/api/solve".to_string(), r.tokened("/api/solve")] {
        let head = format!(
            "POST {path} HTTP/1.1\r\nHost: {host}\r\nOrigin: https://evil.example\r\nContent-Type: text/plain\r\n\
             Content-Length: {}\r\n\r\n{body}",
            body.len()
        );
        assert_eq!(send_head(r.addr, &head).0, 403, "{path}");
    }
    let fetch_site = format!(
        "POST {} HTTP/1.1\r\nHost: {host}\r\nSec-Fetch-Site: cross-site\r\nContent-Length: {}\r\n\r\n{body}",
        r.tokened("/api/solve"),
        body.len()
    );
    assert_eq!(send_head(r.addr, &fetch_site).0, 403);
    let upload = format!(
        "POST /api/open?name=x.vox HTTP/1.1\r\nHost: {host}\r\nOrigin: null\r\nContent-Length: 3\r\n\r\nVOX"
    );
    assert_eq!(send_head(r.addr, &upload).0, 403);
    let now = json(&get(&r, "/api/state").1);
    assert_eq!(now["job"], state["job"], "{now}");
    // The page's own origin, with the token: accepted.
    tuning["refine"] = state["tuning"]["refine"].clone();
    let body = tuning.to_string();
    let own = format!(
        "POST {} HTTP/1.1\r\nHost: {host}\r\nOrigin: http://{host}\r\nSec-Fetch-Site: same-origin\r\n\
         Content-Length: {}\r\n\r\n{body}",
        r.tokened("/api/solve"),
        body.len()
    );
    assert_eq!(send_head(r.addr, &own).0, 202);
}

#[test]
fn uploads_are_read_from_memory_only() {
    let r = start();
    wait_for(&r, |s| s["final"] == true);
    // A detached NRRD header naming a file outside the upload (present, readable, the
    // right size): refused, and the surface stays.
    let dir = tempfile::tempdir().unwrap();
    let secret = dir.path().join("secret.raw");
    std::fs::write(&secret, [1u8, 2, 3, 4, 5, 6, 7, 8]).unwrap();
    for file in [secret.display().to_string(), "../../../../etc/passwd".to_string()] {
        let header = format!(
            "NRRD0004\ntype: uint8\ndimension: 3\nsizes: 2 2 2\nencoding: raw\ndata file: {file}\n\n"
        );
        let (status, message) = error_of(post(&r, "/api/open?name=evil.nhdr", header.as_bytes()));
        assert_eq!(status, 400, "{file}: {message}");
        assert!(message.contains("evil.nhdr") && message.contains("detached"), "{message}");
    }
    assert_eq!(json(&get(&r, "/api/state").1)["name"], "ball.vol");
    // A Zarr store or a pattern of slices names other files too.
    for name in ["a.zarr", "slice*.tif"] {
        let (status, message) = error_of(post(&r, &format!("/api/open?name={name}"), b"{}"));
        assert_eq!(status, 400, "{name}: {message}");
    }
}

#[test]
fn requests_held_in_memory_are_answered_as_over_a_connection() {
    let viewer = Viewer::bind(0, Box::new(load)).unwrap();
    viewer.stop_handle().stop();
    let host = format!("127.0.0.1:{}", viewer.addr().port());
    let status = |raw: &[u8]| {
        let out = viewer.respond_to(raw);
        String::from_utf8_lossy(out.get(9..12).unwrap_or_default()).parse::<u16>().unwrap_or(0)
    };
    let page = format!("GET / HTTP/1.1\r\nHost: {host}\r\n\r\n");
    assert_eq!(status(page.as_bytes()), 200);
    let state = format!("GET /api/state?token={} HTTP/1.1\r\nHost: {host}\r\n\r\n", viewer.token());
    assert_eq!(status(state.as_bytes()), 200);
    let events = format!("GET /api/events?token={} HTTP/1.1\r\nHost: {host}\r\n\r\n", viewer.token());
    assert!(String::from_utf8_lossy(&viewer.respond_to(events.as_bytes())).contains("\r\n\r\ndata: {"));
    let solve = format!(
        "POST /api/solve?token={} HTTP/1.1\r\nHost: {host}\r\nContent-Length: 2\r\n\r\n{{x",
        viewer.token()
    );
    assert_eq!(status(solve.as_bytes()), 400);
    // Nothing, garbage, a truncated body: never a panic.
    assert!(viewer.respond_to(b"").is_empty());
    assert_eq!(status(b"\x00\xff garbage\r\n\r\n"), 400);
    let short = format!(
        "POST /api/solve?token={} HTTP/1.1\r\nHost: {host}\r\nContent-Length: 9\r\n\r\n{{}}",
        viewer.token()
    );
    assert_eq!(status(short.as_bytes()), 400);
}

#[test]
fn a_solve_streams_its_state_and_its_result_downloads_in_every_format() {
    let r = start();
    let state = wait_for(&r, |s| s["final"] == true);
    let vertices = state["vertices"].as_u64().unwrap() as usize;
    let faces = state["faces"].as_u64().unwrap() as usize;
    assert!(state["summary"].as_str().unwrap().contains(&format!("{faces} quads")));
    assert_eq!(get(&r, "/api/positions").1.len(), 12 * vertices);
    let surface = get(&r, "/api/surface").1;
    assert_eq!(surface.len(), 8 + (16 + 4 + 3) * faces + 12 * vertices);
    assert_eq!(surface[..8], [(faces as u32).to_le_bytes(), (vertices as u32).to_le_bytes()].concat());
    assert_eq!(get(&r, "/api/normals").1.len(), 12 * faces);
    assert!(state["command"]
        .as_str()
        .unwrap()
        .starts_with("voxreg regularize ball.vol -o ball.glb --preset papers"));
    // The result, as the command line writes it.
    let (status, glb) = get(&r, "/api/download?format=glb");
    assert_eq!((status, &glb[..4]), (200, &b"glTF"[..]));
    let (status, ply) = get(&r, "/api/download?format=ply");
    assert_eq!((status, &ply[..3]), (200, &b"ply"[..]));
    let (status, obj) = get(&r, "/api/download?format=obj");
    assert_eq!(status, 200);
    assert_eq!(String::from_utf8_lossy(&obj).lines().filter(|l| l.starts_with("f ")).count(), faces);
    // A re-solve with other weights: a new final frame with other positions.
    let mut tuning = state["tuning"].clone();
    tuning["gamma"] = serde_json::json!(2.0);
    let before = get(&r, "/api/positions").1;
    assert_eq!(post(&r, "/api/solve", tuning.to_string().as_bytes()).0, 202);
    let frame = state["frame"].as_u64().unwrap();
    let again = wait_for(&r, |s| s["final"] == true && s["frame"].as_u64().unwrap() > frame);
    assert_eq!(again["tuning"]["gamma"], 2.0);
    assert_ne!(get(&r, "/api/positions").1, before);
    // The event stream sends the state.
    let mut s = TcpStream::connect(r.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    write!(s, "GET {} HTTP/1.1\r\nHost: {}\r\n\r\n", r.tokened("/api/events"), r.host()).unwrap();
    let mut seen = Vec::new();
    let mut buf = [0u8; 4096];
    while !String::from_utf8_lossy(&seen).contains("\n\n{") && !seen.windows(2).any(|w| w == b"}\n") {
        let n = s.read(&mut buf).unwrap();
        assert!(n > 0, "the stream ended: {}", String::from_utf8_lossy(&seen));
        seen.extend_from_slice(&buf[..n]);
    }
    let text = String::from_utf8_lossy(&seen);
    assert!(text.starts_with("HTTP/1.1 200 OK\r\nContent-Type: text/event-stream"), "{text}");
    let data = text.split("data: ").nth(1).unwrap().lines().next().unwrap();
    assert_eq!(json(data.as_bytes())["name"], "ball.vol");
}

#[test]
fn bad_requests_are_answered_with_messages_and_the_server_keeps_serving() {
    let r = start();
    let state = wait_for(&r, |s| s["final"] == true);
    let (status, message) = error_of(post(&r, "/api/solve", b"{not json"));
    assert_eq!(status, 400);
    assert!(message.starts_with("bad parameters:"), "{message}");
    let mut tuning = state["tuning"].clone();
    tuning["alpha"] = serde_json::json!(0.0);
    let (status, message) = error_of(post(&r, "/api/solve", tuning.to_string().as_bytes()));
    assert_eq!(status, 400);
    assert!(message.contains("alpha must be finite and positive"), "{message}");
    tuning["alpha"] = serde_json::json!(0.01);
    tuning["clamp"] = serde_json::json!(3.0);
    assert!(error_of(post(&r, "/api/solve", tuning.to_string().as_bytes())).1.contains("(0, 1)"));
    assert_eq!(error_of(get(&r, "/api/download?format=stl")).0, 400);
    assert_eq!(error_of(post(&r, "/api/open", b"abc")).0, 400);
    // A corrupt file: the reader's message, naming the file; the old surface stays.
    let (status, message) = error_of(post(&r, "/api/open?name=broken%20model.vox", b"VOX garbage"));
    assert_eq!(status, 400);
    assert!(message.contains("broken model.vox"), "{message}");
    let (status, message) = error_of(post(&r, "/api/open?name=empty.vol", b""));
    assert_eq!(status, 400, "{message}");
    assert_eq!(json(&get(&r, "/api/state").1)["name"], "ball.vol");
    // A panicking request is answered, and the next one too.
    assert_eq!(error_of(get(&r, "/api/test-panic")), (500, "internal error: a test panic".into()));
    assert_eq!(get(&r, "/").0, 200);
    assert_eq!(json(&get(&r, "/api/state").1)["final"], true);
}

#[test]
fn a_dropped_file_replaces_the_surface() {
    let r = start();
    let first = wait_for(&r, |s| s["final"] == true);
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/axes.vox");
    let bytes = std::fs::read(path).unwrap();
    let (status, body) = post(&r, "/api/open?name=axes.vox", &bytes);
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    let state = wait_for(&r, |s| s["final"] == true && s["name"] == "axes.vox");
    assert!(state["model_id"].as_u64() > first["model_id"].as_u64());
    assert_ne!(state["faces"], first["faces"]);
    let surface = get(&r, "/api/surface").1;
    let (faces, vertices) =
        (state["faces"].as_u64().unwrap() as usize, state["vertices"].as_u64().unwrap() as usize);
    assert_eq!(surface.len(), 8 + (16 + 4 + 3) * faces + 12 * vertices);
    // The .vox palette colours the faces (the last array): several colours.
    let colors: std::collections::HashSet<_> = surface[surface.len() - 3 * faces..].chunks(3).collect();
    assert!(colors.len() > 1, "{colors:?}");
}

#[test]
fn a_request_for_a_newer_frame_waits_for_it() {
    let r = start();
    let done = wait_for(&r, |s| s["final"] == true && s["busy"] == false);
    let frame = done["frame"].as_u64().unwrap();
    let host = format!("127.0.0.1:{}", r.addr.port());
    let frame_of = |head: &str| -> u64 {
        let line = head.lines().find(|l| l.to_ascii_lowercase().starts_with("x-frame:")).expect("X-Frame");
        line[8..].trim().parse().unwrap()
    };
    // A frame newer than one already there: at once.
    let t = Instant::now();
    let (status, head, _) =
        exchange(r.addr, "GET", &r.tokened(&format!("/api/positions?after={}", frame - 1)), Some(&host), b"");
    assert_eq!((status, frame_of(&head)), (200, frame));
    assert!(t.elapsed() < Duration::from_millis(500));
    // One still to come: answered when the re-solve publishes it.
    let mut tuning = done["tuning"].clone();
    tuning["gamma"] = serde_json::json!(0.5);
    let posted = std::thread::spawn({
        let addr = r.addr;
        let host = host.clone();
        let path = r.tokened("/api/solve");
        move || {
            std::thread::sleep(Duration::from_millis(200));
            request(addr, "POST", &path, Some(&host), tuning.to_string().as_bytes()).0
        }
    });
    let t = Instant::now();
    let (status, head, body) =
        exchange(r.addr, "GET", &r.tokened(&format!("/api/positions?after={frame}")), Some(&host), b"");
    let waited = t.elapsed();
    assert_eq!(posted.join().unwrap(), 202);
    assert_eq!(status, 200);
    assert!(frame_of(&head) > frame, "{head}");
    assert!(waited >= Duration::from_millis(150) && waited < FRAME_WAIT, "{waited:?}");
    assert_eq!(body.len(), 12 * done["vertices"].as_u64().unwrap() as usize);
}

#[test]
fn a_newer_solve_stops_the_running_one() {
    // A ball of radius 18 through the default pipeline (four solves), with the iterative
    // solver, whose iterations are where a run can stop.
    let volume = LabelVolume::from_fn([41, 41, 41], |[x, y, z]| {
        let d = |c: usize| c as f64 - 20.0;
        u32::from(d(x).powi(2) + d(y).powi(2) + d(z).powi(2) <= 324.0)
    });
    let mut overrides = Overrides::default();
    overrides.solver = Some(SolverChoice::Cg);
    let r = start_with(Loaded {
        name: "big.vol".into(),
        volume: volume.into(),
        palette: None,
        preset: Preset::Default,
        overrides,
    });
    let running = wait_for(&r, |s| {
        let stage = s["stage"].as_str().unwrap_or("");
        s["busy"] == true
            && (stage.starts_with("refine") || ["solve 1/4", "solve 2/4", "solve 3/4"].contains(&stage))
    });
    let mut tuning = running["tuning"].clone();
    tuning["gamma"] = serde_json::json!(0.7);
    assert_eq!(post(&r, "/api/solve", tuning.to_string().as_bytes()).0, 202);
    let done = wait_for(&r, |s| s["final"] == true && s["busy"] == false);
    assert_eq!(done["tuning"]["gamma"], 0.7);
    assert_eq!(done["superseded"], 1, "{done}");
    assert_eq!(done["error"], serde_json::Value::Null);
}

#[test]
fn a_re_solve_of_the_same_surface_starts_from_the_last_result() {
    // The iterative solver (the one that takes a starting guess), one solve per run.
    let volume = LabelVolume::from_fn([25, 25, 25], |[x, y, z]| {
        let d = |c: usize| c as f64 - 12.0;
        u32::from(d(x).powi(2) + d(y).powi(2) + d(z).powi(2) <= 100.0)
    });
    let mut overrides = Overrides::default();
    overrides.solver = Some(SolverChoice::Cg);
    let (copy, base) = (volume.clone(), overrides.clone());
    let r = start_with(Loaded {
        name: "ball.vol".into(),
        volume: volume.into(),
        palette: None,
        preset: Preset::Papers,
        overrides,
    });
    let first = wait_for(&r, |s| s["final"] == true && s["busy"] == false);
    assert_eq!(first["warm"], false, "the first run of a surface is cold");
    let cold = first["iterations"].as_u64().unwrap();
    let mut tuning = first["tuning"].clone();
    tuning["gamma"] = serde_json::json!(0.13);
    assert_eq!(post(&r, "/api/solve", tuning.to_string().as_bytes()).0, 202);
    let frame = first["frame"].as_u64().unwrap();
    let again =
        wait_for(&r, |s| s["final"] == true && s["busy"] == false && s["frame"].as_u64().unwrap() > frame);
    assert_eq!(again["warm"], true, "{again}");
    let warm = again["iterations"].as_u64().unwrap();
    assert!(warm < cold, "warm {warm} iterations, cold {cold}");
    // The warm re-solve (its first iteration on the last run's multigrid cycle) ends at
    // the result of a cold run with its parameters, as `voxreg regularize` computes it.
    let p = serde_json::from_value::<crate::Tuning>(tuning.clone())
        .unwrap()
        .params(Preset::Papers, &base)
        .unwrap();
    let cold_run = voxreg_regularize::regularize(&copy, &p).unwrap();
    let shown = get(&r, "/api/positions").1;
    let shown: Vec<f32> = shown.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().unwrap())).collect();
    let d = shown
        .chunks_exact(3)
        .zip(cold_run.positions.iter())
        .map(|(x, c)| (glam::DVec3::new(x[0].into(), x[1].into(), x[2].into()) - *c).length())
        .fold(0.0, f64::max);
    assert_eq!(shown.len(), 3 * cold_run.positions.len());
    assert!(d <= 10.0 * p.solver.cg.tolerance, "warm and cold results differ by {d} voxel");
    let report = json(&get(&r, "/api/report").1);
    assert_eq!(report["report"]["solves"][0]["quick_start_iterations"], 1, "{report}");
    // The panel's smoothness reaches the solver (bounded, clamped) and the command line.
    tuning["smoothness"] = serde_json::json!(0.5);
    tuning["clamp"] = serde_json::Value::Null;
    // As the page sends it: the panel has no solver field (the command line's `cg` stays
    // in the base options, and the panel's boxes drop it).
    tuning["solver"] = serde_json::Value::Null;
    assert_eq!(post(&r, "/api/solve", tuning.to_string().as_bytes()).0, 202);
    let frame = again["frame"].as_u64().unwrap();
    let clamped =
        wait_for(&r, |s| s["final"] == true && s["busy"] == false && s["frame"].as_u64().unwrap() > frame);
    assert!(clamped["command"].as_str().unwrap().contains("--smoothness 0.5"), "{clamped}");
    let report = json(&get(&r, "/api/report").1);
    assert_eq!(report["report"]["params"]["solver"]["choice"], "bounded", "{report}");
}

#[test]
fn a_voxel_art_re_solve_starts_from_the_last_result() {
    // The clamped bounded solver of the voxel-art preset takes the last result too.
    let volume = LabelVolume::from_fn([14, 12, 10], |[x, y, z]| {
        u32::from((2..12).contains(&x) && y > 1 && z > 1 && y + z < 18)
    })
    .with_background(Some(0));
    let r = start_with(Loaded {
        name: "art.vox".into(),
        volume: volume.into(),
        palette: None,
        preset: Preset::VoxelArt,
        overrides: Overrides::default(),
    });
    let first = wait_for(&r, |s| s["final"] == true && s["busy"] == false);
    assert_eq!(first["warm"], false);
    let mut tuning = first["tuning"].clone();
    tuning["gamma"] = serde_json::json!(tuning["gamma"].as_f64().unwrap() * 1.3);
    assert_eq!(post(&r, "/api/solve", tuning.to_string().as_bytes()).0, 202);
    let frame = first["frame"].as_u64().unwrap();
    let again =
        wait_for(&r, |s| s["final"] == true && s["busy"] == false && s["frame"].as_u64().unwrap() > frame);
    assert_eq!(again["warm"], true, "{again}");
    let report = json(&get(&r, "/api/report").1);
    assert_eq!(report["report"]["solves"][0]["solver"], "bounded", "{report}");
}

#[test]
fn a_voxel_edit_rebuilds_the_surface_and_re_solves_from_the_shape_shown() {
    let r = start();
    let first = wait_for(&r, |s| s["final"] == true && s["busy"] == false);
    let (model, faces) = (first["model_id"].as_u64().unwrap(), first["faces"].as_u64().unwrap());
    // Face 0 of the ball: remove the voxel behind it.
    let edit = serde_json::json!({ "model": model, "face": 0 });
    assert_eq!(post(&r, "/api/edit", edit.to_string().as_bytes()).0, 202);
    let edited =
        wait_for(&r, |s| s["model_id"].as_u64() > Some(model) && s["final"] == true && s["busy"] == false);
    assert_eq!(edited["edited"], true, "{edited}");
    assert_eq!(edited["error"], serde_json::Value::Null, "{edited}");
    assert_ne!(edited["faces"].as_u64().unwrap(), faces, "{edited}");
    assert!(edited["edit_ms"].as_f64().is_some(), "{edited}");
    let model = edited["model_id"].as_u64().unwrap();
    let surface = get(&r, "/api/surface").1;
    assert_eq!(
        u64::from(u32::from_le_bytes(surface[..4].try_into().unwrap())),
        edited["faces"].as_u64().unwrap()
    );
    // Bad edits: a stale surface, a face out of range, a voxel outside the volume, junk.
    let stale = serde_json::json!({ "model": model - 1, "face": 0 });
    let (status, message) = error_of(post(&r, "/api/edit", stale.to_string().as_bytes()));
    assert_eq!(status, 409);
    assert!(message.contains("click again"), "{message}");
    let far = serde_json::json!({ "model": model, "face": 1_000_000 });
    let (status, message) = error_of(post(&r, "/api/edit", far.to_string().as_bytes()));
    assert_eq!(status, 400);
    assert!(message.starts_with("no face 1000000"), "{message}");
    let (status, message) = error_of(post(&r, "/api/edit", b"{\"model\": 1}"));
    assert_eq!(status, 400);
    assert!(message.starts_with("bad edit:"), "{message}");
    assert_eq!(get(&r, "/").0, 200);
}

#[test]
fn adding_a_voxel_outside_the_volume_is_refused_with_a_message() {
    // A solid filling its whole volume: every face is on the border, and the voxel across
    // it is outside.
    let volume = LabelVolume::from_fn([3, 3, 3], |_| 1).with_background(Some(0));
    let r = start_with(Loaded {
        name: "cube.vol".into(),
        volume: volume.into(),
        palette: None,
        preset: Preset::Papers,
        overrides: Overrides::default(),
    });
    let first = wait_for(&r, |s| s["final"] == true && s["busy"] == false);
    let model = first["model_id"].as_u64().unwrap();
    let add = serde_json::json!({ "model": model, "face": 0, "add": true });
    assert_eq!(post(&r, "/api/edit", add.to_string().as_bytes()).0, 202);
    let refused = wait_for(&r, |s| !s["error"].is_null());
    assert!(refused["error"].as_str().unwrap().contains("outside the volume"), "{refused}");
    assert_eq!(refused["model_id"].as_u64(), Some(model));
    assert_eq!(get(&r, "/").0, 200);
}

/// A level of detail as `/api/level?k=K` serves it.
struct LevelMesh {
    quads: Vec<[u32; 4]>,
    groups: Vec<u32>,
    labels: Vec<[u32; 2]>,
    positions: Vec<[f32; 3]>,
    colors: Vec<[u8; 3]>,
}

fn level_mesh(bytes: &[u8]) -> LevelMesh {
    let u32_at = |i: usize| u32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
    let (faces, vertices) = (u32_at(0) as usize, u32_at(4) as usize);
    assert_eq!(bytes.len(), 8 + (16 + 4 + 8 + 3) * faces + 12 * vertices);
    let (q, g) = (8, 8 + 16 * faces);
    let (l, p) = (g + 4 * faces, g + 12 * faces);
    let c = p + 12 * vertices;
    let f32_at = |i: usize| f32::from_le_bytes(bytes[i..i + 4].try_into().unwrap());
    LevelMesh {
        quads: (0..faces).map(|f| [0, 1, 2, 3].map(|k| u32_at(q + 16 * f + 4 * k))).collect(),
        groups: (0..faces).map(|f| u32_at(g + 4 * f)).collect(),
        labels: (0..faces).map(|f| [u32_at(l + 8 * f), u32_at(l + 8 * f + 4)]).collect(),
        positions: (0..vertices).map(|v| [0, 1, 2].map(|k| f32_at(p + 12 * v + 4 * k))).collect(),
        colors: (0..faces).map(|f| [0, 1, 2].map(|k| bytes[c + 3 * f + k])).collect(),
    }
}

/// Per label: the Euler characteristic of the faces it bounds, and the edges left
/// unmatched once each face is oriented away from the label (a face's normal points from
/// its inner label to its outer one): none when every region is closed and oriented.
fn regions(m: &LevelMesh) -> std::collections::BTreeMap<u32, (i64, usize)> {
    use std::collections::{BTreeMap, BTreeSet, HashMap};
    let mut faces: BTreeMap<u32, Vec<Vec<u32>>> = BTreeMap::new();
    for (q, l) in m.quads.iter().zip(&m.labels) {
        // The distinct corners (a triangle repeats its last vertex).
        let p: Vec<u32> = (0..4).filter(|&i| q[i] != q[(i + 3) % 4]).map(|i| q[i]).collect();
        assert!(p.len() >= 3, "{q:?}");
        faces.entry(l[0]).or_default().push(p.clone());
        faces.entry(l[1]).or_default().push(p.into_iter().rev().collect());
    }
    faces
        .into_iter()
        .map(|(label, polygons)| {
            let mut verts = BTreeSet::new();
            let mut edges: HashMap<(u32, u32), i64> = HashMap::new();
            for p in &polygons {
                for i in 0..p.len() {
                    let (a, b) = (p[i], p[(i + 1) % p.len()]);
                    verts.insert(a);
                    *edges.entry((a.min(b), a.max(b))).or_default() += if a < b { 1 } else { -1 };
                }
            }
            let euler = verts.len() as i64 - edges.len() as i64 + polygons.len() as i64;
            (label, (euler, edges.values().filter(|&&c| c != 0).count()))
        })
        .collect()
}

#[test]
fn a_level_of_detail_is_served_closed_per_region_and_a_new_run_replaces_it() {
    // A ball of radius 7 in two labels, each its own region (the default preset): three
    // interfaces, a junction line where they meet.
    let volume = LabelVolume::from_fn([17, 17, 17], |[x, y, z]| {
        let d = |c: usize| c as f64 - 8.0;
        let inside = d(x).powi(2) + d(y).powi(2) + d(z).powi(2) <= 49.0;
        if !inside {
            0
        } else if x < 8 {
            1
        } else {
            2
        }
    });
    let r = start_with(Loaded {
        name: "halves.vol".into(),
        volume: volume.into(),
        palette: None,
        preset: Preset::Default,
        overrides: Overrides::default(),
    });
    let state = wait_for(&r, |s| s["final"] == true && s["busy"] == false);
    let faces = state["faces"].as_u64().unwrap() as usize;
    assert_eq!((state["level"].as_u64(), state["level_count"].as_u64()), (Some(0), Some(4)));
    assert_eq!((state["level_shown"].as_u64(), &state["levels"]), (Some(0), &serde_json::Value::Null));
    // Nothing is simplified before a coarser level is chosen.
    assert_eq!(error_of(get(&r, "/api/level?k=1")).0, 409);
    // The choice is a state change: a JSON body within the form limit, the token, the
    // page's own origin; bad levels are refused with a message.
    for (body, expected) in [
        (&b"{\"level\": 4}"[..], "no level 4: the levels of detail are 0 to 3"),
        (b"{\"level\": -1}", "bad level:"),
        (b"{\"level\": 1, \"k\": 2}", "bad level:"),
        (b"level=1", "bad level:"),
    ] {
        let (status, message) = error_of(post(&r, "/api/level", body));
        assert_eq!(status, 400);
        assert!(message.starts_with(expected), "{message}");
    }
    let choose = |level: usize| format!("{{\"level\":{level}}}");
    let host = r.host();
    assert_eq!(request(r.addr, "POST", "/api/level", Some(&host), choose(1).as_bytes()).0, 403);
    let body = choose(1);
    let foreign = format!(
        "POST {} HTTP/1.1\r\nHost: {host}\r\nOrigin: https://evil.example\r\nContent-Length: {}\r\n\r\n{body}",
        r.tokened("/api/level"),
        body.len()
    );
    assert_eq!(send_head(r.addr, &foreign).0, 403);
    let huge =
        format!("POST {} HTTP/1.1\r\nHost: {host}\r\nContent-Length: 70000\r\n\r\n", r.tokened("/api/level"));
    assert_eq!(send_head(r.addr, &huge).0, 413);
    assert_eq!(json(&get(&r, "/api/state").1)["level"], 0, "a refused choice changed the level");

    // Level 2 chosen: the pyramid is computed once, and the page is told to show it.
    assert_eq!(post(&r, "/api/level", choose(2).as_bytes()), (200, b"{\"level\":2}".to_vec()));
    let ready = wait_for(&r, |s| s["level_shown"] == 2);
    assert_eq!(ready["frame"], state["frame"], "the level choice re-solved");
    let counts: Vec<usize> =
        ready["levels"].as_array().unwrap().iter().map(|l| l["faces"].as_u64().unwrap() as usize).collect();
    assert_eq!(counts.len(), 4);
    assert_eq!(counts[0], faces);
    assert!(counts[1] < faces && counts.windows(2).all(|w| w[1] <= w[0]), "{counts:?} of {faces}");
    let levels: Vec<LevelMesh> = (0..4)
        .map(|k| {
            let (status, head, bytes) =
                exchange(r.addr, "GET", &r.tokened(&format!("/api/level?k={k}")), Some(&host), b"");
            assert_eq!(status, 200, "{}", String::from_utf8_lossy(&bytes));
            assert!(head.contains(&format!("X-Frame: {}", ready["frame"])), "{head}");
            level_mesh(&bytes)
        })
        .collect();
    let full = &levels[0];
    let names: Vec<&str> =
        ready["groups"].as_array().unwrap().iter().map(|g| g["name"].as_str().unwrap()).collect();
    assert_eq!(names.len(), 3, "{names:?}");
    let colour_of: std::collections::HashMap<u32, [u8; 3]> =
        full.labels.iter().zip(&full.colors).map(|(l, c)| (l[0], *c)).collect();
    let full_regions = regions(full);
    assert_eq!(full_regions.keys().copied().collect::<Vec<_>>(), [0, 1, 2]);
    for (k, level) in levels.iter().enumerate() {
        assert_eq!(level.quads.len(), counts[k], "level {k}");
        assert!(level.positions.iter().flatten().all(|x| x.is_finite()));
        assert!(level.quads.iter().flatten().all(|&v| (v as usize) < level.positions.len()));
        // Each region closed, of the full surface's topology; the colours, labels and
        // groups (interfaces) of the full surface.
        let per_region = regions(level);
        for (label, (euler, open)) in &per_region {
            assert_eq!(*open, 0, "level {k}: region {label} is not closed");
            assert_eq!(*euler, full_regions[label].0, "level {k}: region {label}");
        }
        assert_eq!(per_region.len(), full_regions.len(), "level {k}");
        for f in 0..level.quads.len() {
            let l = level.labels[f];
            assert_eq!(level.colors[f], colour_of[&l[0]], "level {k} face {f}");
            assert_eq!(level.colors[f], crate::model::label_color(l[0]), "level {k} face {f}");
            // The interface of its two labels (named after them, in either order).
            let name = names[level.groups[f] as usize];
            let pair = [format!("interface_{}_{}", l[0], l[1]), format!("interface_{}_{}", l[1], l[0])];
            assert!(pair.contains(&name.to_string()), "level {k} face {f}: {l:?} in {name}");
        }
    }
    // The downloads give the level, as `--lod` writes it.
    let (status, obj) = get(&r, "/api/download?format=obj&level=2");
    assert_eq!(status, 200);
    assert_eq!(String::from_utf8_lossy(&obj).lines().filter(|l| l.starts_with("f ")).count(), counts[2]);
    assert_eq!(get(&r, "/api/download?format=obj&level=9").0, 400);
    // Voxel edits need the full surface.
    let edit = serde_json::json!({ "model": ready["model_id"], "face": 0 }).to_string();
    let (status, message) = error_of(post(&r, "/api/edit", edit.as_bytes()));
    assert_eq!(status, 409);
    assert!(message.starts_with("voxel edits apply to the full surface"), "{message}");

    // A new run drops the levels; the level stays chosen and is computed again for the new
    // result.
    let mut tuning = ready["tuning"].clone();
    tuning["gamma"] = serde_json::json!(2.0);
    assert_eq!(post(&r, "/api/solve", tuning.to_string().as_bytes()).0, 202);
    let frame = ready["frame"].as_u64().unwrap();
    let again = wait_for(&r, |s| s["frame"].as_u64().unwrap() > frame && s["level_shown"] == 2);
    assert_eq!(again["tuning"]["gamma"], 2.0);
    let (status, head, bytes) = exchange(r.addr, "GET", &r.tokened("/api/level?k=2"), Some(&host), b"");
    assert_eq!(status, 200);
    assert!(head.contains(&format!("X-Frame: {}", again["frame"])), "{head}");
    assert_ne!(level_mesh(&bytes).positions, levels[2].positions);
    // Back to the full surface: nothing else changes.
    assert_eq!(post(&r, "/api/level", choose(0).as_bytes()).0, 200);
    let full_again = wait_for(&r, |s| s["level_shown"] == 0);
    assert_eq!(full_again["frame"], again["frame"]);
}

#[test]
fn a_refusal_reaches_the_peer_whose_body_went_unread() {
    // A request refused before its body is read (here: no token) still gets its answer:
    // the server reads and drops the rest before it closes, where closing with the body
    // unread would reset the connection, at times before the answer was read.
    let r = start();
    wait_for(&r, |s| s["final"] == true);
    let host = r.host();
    let body = vec![b'x'; 60_000];
    for _ in 0..20 {
        assert_eq!(request(r.addr, "POST", "/api/level", Some(&host), &body).0, 403);
    }
}
