//! The HTTP side: connections, routes, the event stream, the embedded assets, and the
//! rules that keep the server up and the session private (loopback peers and hosts only,
//! the session's token on every API request, no cross-origin requests, bodies bounded
//! before they are read, every request's panic caught).
//!
//! HTTP/1.1 is spoken here, on `std::net`, one request per connection: the head is read
//! (at most [`MAX_HEAD`] bytes) and parsed by `httparse`, the body is read only once its
//! declared length is known to be within the route's limit, and every response closes its
//! connection.

use std::io::{Cursor, Read, Write};
use std::net::{IpAddr, Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::mpsc::{self, Sender};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde_json::json;

use crate::levels::{level_bytes, LEVELS};
use crate::session::{mesh_file, panic_message, Edit, Job, Levels, Shared};
use voxreg_regularize::Preset;

use crate::error::ViewError;
use crate::model::Loaded;
use crate::tuning::Tuning;

/// Reads a file dropped on the page, from its name (whose extension says the format) and
/// its contents, held in memory: the command line's reading, with its options, and
/// nothing read from disk (a header naming another file is refused).
pub type Loader = dyn Fn(&str, &[u8]) -> Result<Loaded, String> + Send + Sync;

/// The largest file the page may upload.
const MAX_UPLOAD: u64 = 1 << 30;

/// The largest parameters, edit or level choice the page may post.
const MAX_FORM: u64 = 1 << 16;

/// The largest request head (request line and headers) read.
const MAX_HEAD: usize = 16 << 10;

/// The most headers a request may have.
const MAX_HEADERS: usize = 64;

/// How long a connection may stall while its request is read.
const READ_TIMEOUT: Duration = Duration::from_secs(30);

/// How long a response (or an event) may wait for a stalled reader.
const WRITE_TIMEOUT: Duration = Duration::from_secs(60);

/// How long, and how many bytes, a connection's end waits for and drops of what the peer
/// still sends after the answer (see `connection`).
const LINGER: Duration = Duration::from_millis(500);
const LINGER_BYTES: usize = 256 << 10;

/// How often an idle event stream sends a keep-alive comment (and notices a closed page).
const KEEP_ALIVE: Duration = Duration::from_secs(10);

/// The longest a request for a newer frame (`/api/positions?after=F`) waits for one; the
/// page asks again (its requests give up on a stalled connection after 4 s).
const FRAME_WAIT: Duration = Duration::from_secs(2);

/// The header the page may send its token in (it sends it as `?token=` too).
const TOKEN_HEADER: &str = "X-Voxreg-Token";

struct Asset {
    path: &'static str,
    mime: &'static str,
    bytes: &'static [u8],
}

const ASSETS: &[Asset] = &[
    Asset { path: "/", mime: "text/html; charset=utf-8", bytes: include_bytes!("../assets/index.html") },
    Asset { path: "/app.js", mime: "text/javascript", bytes: include_bytes!("../assets/app.js") },
    Asset { path: "/style.css", mime: "text/css", bytes: include_bytes!("../assets/style.css") },
    Asset {
        path: "/three/three.module.min.js",
        mime: "text/javascript",
        bytes: include_bytes!("../assets/three/three.module.min.js"),
    },
    Asset {
        path: "/three/OrbitControls.js",
        mime: "text/javascript",
        bytes: include_bytes!("../assets/three/OrbitControls.js"),
    },
    Asset { path: "/three/LICENSE", mime: "text/plain", bytes: include_bytes!("../assets/three/LICENSE") },
];

/// The viewer: a server bound to a loopback port, and the worker that solves.
///
/// [`Viewer::bind`] listens; [`Viewer::open`] queues the first input; [`Viewer::serve`]
/// answers requests until [`StopHandle::stop`] (from another thread: [`Viewer::stop_handle`]
/// gives the handle).
///
/// Every request under `/api/` must carry the session's token ([`Viewer::token`], part
/// of [`Viewer::url`]) as `?token=` or an `X-Voxreg-Token` header, and no request may
/// come from another origin (an `Origin` header other than the server's own): another
/// local user, or a web page open in the same browser, can neither read the state nor
/// queue work.
pub struct Viewer {
    listener: TcpListener,
    addr: SocketAddr,
    token: String,
    shared: Arc<Shared>,
    jobs: Mutex<Sender<Job>>,
    loader: Arc<Loader>,
}

/// Stops a serving [`Viewer`] from another thread.
#[derive(Clone)]
pub struct StopHandle {
    addr: SocketAddr,
    shared: Arc<Shared>,
}

impl StopHandle {
    /// Makes [`Viewer::serve`] return and closes the event streams.
    pub fn stop(&self) {
        self.shared.update(|s| s.shutdown = true);
        // Wake the accepting thread up.
        let _ = TcpStream::connect_timeout(&self.addr, Duration::from_secs(1));
    }
}

/// A parsed request: its head, and its body once read.
struct Request {
    method: String,
    path: String,
    query: String,
    headers: Vec<(String, String)>,
    body: Vec<u8>,
}

impl Request {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers.iter().find(|(n, _)| n.eq_ignore_ascii_case(name)).map(|(_, v)| v.as_str())
    }
}

/// A response: status, headers and the whole body.
struct Reply {
    status: u16,
    headers: Vec<(&'static str, String)>,
    body: Vec<u8>,
}

impl Reply {
    fn with_header(mut self, name: &'static str, value: &str) -> Reply {
        self.headers.push((name, value.to_string()));
        self
    }
}

impl Viewer {
    /// Listens on `127.0.0.1:port` (`port` 0: a free port); `loader` reads the files
    /// dropped on the page. The session's token is drawn from the system's random source.
    pub fn bind(port: u16, loader: Box<Loader>) -> Result<Viewer, ViewError> {
        let listener =
            TcpListener::bind(("127.0.0.1", port)).map_err(|e| ViewError::Bind(port, e.to_string()))?;
        let addr = listener.local_addr().map_err(|e| ViewError::Bind(port, e.to_string()))?;
        let mut random = [0u8; 16];
        getrandom::fill(&mut random).map_err(|e| ViewError::Bind(port, format!("no random token: {e}")))?;
        let token = random.iter().map(|b| format!("{b:02x}")).collect();
        let shared = Arc::new(Shared::default());
        let (tx, rx) = mpsc::channel();
        let worker_shared = Arc::clone(&shared);
        std::thread::Builder::new()
            .name("voxreg-view-solve".into())
            .spawn(move || crate::session::worker(worker_shared, rx))
            .map_err(|e| ViewError::Bind(port, e.to_string()))?;
        let levels_shared = Arc::clone(&shared);
        std::thread::Builder::new()
            .name("voxreg-view-levels".into())
            .spawn(move || crate::levels::worker(levels_shared))
            .map_err(|e| ViewError::Bind(port, e.to_string()))?;
        Ok(Viewer { listener, addr, token, shared, jobs: Mutex::new(tx), loader: Arc::from(loader) })
    }

    /// The page's address with the session's token, `http://127.0.0.1:PORT/?token=TOKEN`.
    pub fn url(&self) -> String {
        format!("http://{}/?token={}", self.addr, self.token)
    }

    /// The session's token: 32 hexadecimal digits, random.
    pub fn token(&self) -> &str {
        &self.token
    }

    /// The socket address the server listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// Queues `loaded` as the input shown, and its first solve.
    pub fn open(&self, loaded: Loaded) {
        let job = self.shared.next_job();
        self.send(Job::Open(Box::new(loaded), None, job));
    }

    /// A handle that stops [`Viewer::serve`].
    pub fn stop_handle(&self) -> StopHandle {
        StopHandle { addr: self.addr, shared: Arc::clone(&self.shared) }
    }

    fn send(&self, job: Job) {
        // The worker only ends when the viewer does.
        let _ = self.jobs.lock().unwrap_or_else(|e| e.into_inner()).send(job);
    }

    /// Answers requests, each connection on its own thread, until stopped.
    pub fn serve(self) {
        let viewer = Arc::new(self);
        loop {
            let accepted = viewer.listener.accept();
            if viewer.shared.lock().shutdown {
                break;
            }
            let Ok((stream, peer)) = accepted else {
                // Out of descriptors, or a connection reset before it was accepted.
                std::thread::sleep(Duration::from_millis(10));
                continue;
            };
            let v = Arc::clone(&viewer);
            // No thread to answer with: the connection is dropped (closed).
            let _ = std::thread::Builder::new()
                .name("voxreg-view-request".into())
                .spawn(move || v.connection(stream, peer.ip()));
        }
    }

    fn connection(&self, stream: TcpStream, peer: IpAddr) {
        let _ = stream.set_nodelay(true);
        let _ = stream.set_read_timeout(Some(READ_TIMEOUT));
        let _ = stream.set_write_timeout(Some(WRITE_TIMEOUT));
        let Ok(mut input) = stream.try_clone() else { return };
        let mut output = stream;
        self.handle(&mut input, &mut output, peer, false);
        let _ = output.flush();
        // A lingering close: the answer's end is sent, then what the peer still sends (a
        // body refused unread) is read and dropped for a moment. Closing with unread bytes
        // would reset the connection, and a reset can reach the peer before it has read the
        // answer (the refusal is then lost). Bounded in bytes and time.
        let _ = output.shutdown(std::net::Shutdown::Write);
        let _ = input.set_read_timeout(Some(LINGER));
        let started = std::time::Instant::now();
        let (mut buf, mut drained) = ([0u8; 4096], 0usize);
        while drained < LINGER_BYTES && started.elapsed() < LINGER {
            match input.read(&mut buf) {
                Ok(0) | Err(_) => break,
                Ok(n) => drained += n,
            }
        }
    }

    /// Answers one raw HTTP/1.1 request as the server answers a connection from a
    /// loopback peer, and returns the bytes it writes back: the function each connection
    /// runs, without a socket (for tests and fuzzing). An event stream stops after its
    /// first event.
    pub fn respond_to(&self, request: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        self.handle(&mut Cursor::new(request), &mut out, IpAddr::V4(Ipv4Addr::LOCALHOST), true);
        out
    }

    /// Reads one request from `input` and writes its answer to `output`. The body is read
    /// only when the route takes one and its declared length is within the route's limit;
    /// otherwise the answer is sent at once, and the connection closed unread.
    fn handle(&self, input: &mut impl Read, output: &mut impl Write, peer: IpAddr, once: bool) {
        let reply = match self.read_request(input, output, peer) {
            Ok(Some(request)) => {
                if request.method == "GET" && request.path == "/api/events" {
                    self.events(output, once);
                    return;
                }
                match catch_unwind(AssertUnwindSafe(|| self.route(&request))) {
                    Ok(r) => r,
                    Err(panic) => error(500, &format!("internal error: {}", panic_message(&*panic))),
                }
            }
            Ok(None) => return,
            Err(reply) => reply,
        };
        let _ = output.write_all(&serialize(&reply)).and_then(|()| output.flush());
    }

    /// The request on `input`, its body read; `Ok(None)` when the peer sent nothing;
    /// `Err` with the answer when it is refused.
    fn read_request(
        &self,
        input: &mut impl Read,
        output: &mut impl Write,
        peer: IpAddr,
    ) -> Result<Option<Request>, Reply> {
        if !peer.is_loopback() {
            return Err(error(403, "only loopback connections are served"));
        }
        let (head_len, mut bytes) = match read_head(input)? {
            Some(h) => h,
            None => return Ok(None),
        };
        let mut slots = [httparse::EMPTY_HEADER; MAX_HEADERS];
        let mut parsed = httparse::Request::new(&mut slots);
        match parsed.parse(&bytes[..head_len]) {
            Ok(httparse::Status::Complete(_)) => {}
            Ok(httparse::Status::Partial) => return Err(error(400, "an incomplete request head")),
            Err(httparse::Error::TooManyHeaders) => {
                return Err(error(431, &format!("more than {MAX_HEADERS} headers")))
            }
            Err(e) => return Err(error(400, &format!("a malformed request: {e}"))),
        }
        let target = parsed.path.unwrap_or("/").to_string();
        let (path, query) = target.split_once('?').unwrap_or((&target, ""));
        let mut request = Request {
            method: parsed.method.unwrap_or("").to_string(),
            path: path.to_string(),
            query: query.to_string(),
            headers: parsed
                .headers
                .iter()
                .map(|h| (h.name.to_string(), String::from_utf8_lossy(h.value).into_owned()))
                .collect(),
            body: Vec::new(),
        };
        self.allowed(&request).map_err(|why| error(403, &why))?;
        // The body: its length declared, within the route's limit, before any of it is read.
        if request.header("Transfer-Encoding").is_some() {
            return Err(error(411, "a request body needs a Content-Length (no chunked transfer)"));
        }
        let lengths: Vec<&str> = request
            .headers
            .iter()
            .filter(|(n, _)| n.eq_ignore_ascii_case("Content-Length"))
            .map(|(_, v)| v.trim())
            .collect();
        let length = match lengths.as_slice() {
            [] => 0,
            [one, rest @ ..] if rest.iter().all(|r| r == one) => {
                one.parse::<u64>().map_err(|_| error(400, &format!("a bad Content-Length '{one}'")))?
            }
            _ => return Err(error(400, "conflicting Content-Length headers")),
        };
        let limit = body_limit(&request.method, &request.path);
        if length > limit {
            return Err(error(413, &format!("the request body is over {limit} bytes")));
        }
        if request.header("Expect").is_some_and(|e| e.eq_ignore_ascii_case("100-continue")) && length > 0 {
            let _ = output.write_all(b"HTTP/1.1 100 Continue\r\n\r\n").and_then(|()| output.flush());
        }
        // What came after the head is the body's start; the rest is read as it arrives
        // (the buffer grows with what is received, not with what is declared).
        bytes.drain(..head_len);
        bytes.truncate(length as usize);
        let missing = length - bytes.len() as u64;
        input
            .take(missing)
            .read_to_end(&mut bytes)
            .map_err(|e| error(400, &format!("cannot read the request: {e}")))?;
        if bytes.len() as u64 != length {
            return Err(error(400, "the request body ended before its Content-Length"));
        }
        request.body = bytes;
        Ok(Some(request))
    }

    /// Only this server's own host names (a page on another site cannot reach it through
    /// DNS rebinding), no other origin, and the session's token on every API request.
    fn allowed(&self, request: &Request) -> Result<(), String> {
        let port = self.addr.port();
        let own = [format!("127.0.0.1:{port}"), format!("localhost:{port}")];
        match request.header("Host") {
            Some(h) if own.iter().any(|o| o == h) => {}
            Some(h) => return Err(format!("unexpected Host '{}'", printable(h))),
            None => return Err("no Host header".into()),
        }
        // Browsers name the page that sends a cross-origin request (and most same-origin
        // ones): only this server's own page may.
        if let Some(origin) = request.header("Origin") {
            if !own.iter().any(|o| origin == format!("http://{o}")) {
                return Err(format!("requests from other origins are refused ('{}')", printable(origin)));
            }
        }
        if let Some(site) = request.header("Sec-Fetch-Site") {
            if !matches!(site, "same-origin" | "none") {
                return Err(format!(
                    "requests from other sites are refused (Sec-Fetch-Site '{}')",
                    printable(site)
                ));
            }
        }
        if request.path.starts_with("/api/") {
            let given = request
                .header(TOKEN_HEADER)
                .map(str::to_string)
                .or_else(|| query_value(&request.query, "token"));
            if !given.is_some_and(|t| same_secret(t.as_bytes(), self.token.as_bytes())) {
                return Err(
                    "the viewer's token is missing or wrong: open the address voxreg view printed".into()
                );
            }
        }
        Ok(())
    }

    fn route(&self, request: &Request) -> Reply {
        let query = request.query.as_str();
        match (request.method.as_str(), request.path.as_str()) {
            ("GET", "/favicon.ico") => Reply { status: 204, headers: Vec::new(), body: Vec::new() },
            ("GET", "/api/state") => json_response(200, &self.state_json()),
            ("GET", "/api/surface") => self.model_bytes(|m| m.surface_bytes()),
            ("GET", "/api/positions") => {
                let s = self.shared.lock();
                // `after=F`: wait (a while) for a frame newer than F, so that a streamed
                // iterate goes out as soon as it is published, without the page's round
                // trip from the state event.
                let after = query_value(query, "after").and_then(|f| f.parse::<u64>().ok());
                let (s, _) = self
                    .shared
                    .changed
                    .wait_timeout_while(s, FRAME_WAIT, |s| after.is_some_and(|f| s.frame <= f) && !s.shutdown)
                    .unwrap_or_else(|e| e.into_inner());
                match &s.positions {
                    Some(p) => binary(p.to_vec())
                        .with_header("X-Frame", &s.frame.to_string())
                        .with_header("X-Job", &s.job.to_string())
                        .with_header("X-Model", &s.model_id.to_string())
                        .with_header("X-Final", if s.frame_final { "1" } else { "0" }),
                    None => error(404, "no surface yet"),
                }
            }
            ("GET", "/api/normals") => self.finished_bytes(|f| Some(f.normals.clone())),
            ("GET", "/api/features") => self.finished_bytes(|f| f.features.clone()),
            ("GET", "/api/preset") => {
                let name = query_value(query, "name").unwrap_or_default();
                match name.parse::<Preset>() {
                    Ok(p) => json_response(200, &json!(Tuning::preset(p))),
                    Err(e) => error(400, &format!("preset {e}")),
                }
            }
            ("GET", "/api/report") => {
                let s = self.shared.lock();
                match &s.finished {
                    Some(f) => json_response(200, &json!({ "summary": f.summary, "report": f.report })),
                    None => error(404, "no result yet"),
                }
            }
            ("GET", "/api/download") => {
                let ext = query_value(query, "format").unwrap_or_default();
                if !matches!(ext.as_str(), "glb" | "ply" | "obj") {
                    return error(400, &format!("unknown download format '{ext}' (glb, ply or obj)"));
                }
                let level = match query_value(query, "level").map(|k| k.parse::<usize>()) {
                    None => 0,
                    Some(Ok(k)) if k < LEVELS => k,
                    Some(_) => return error(400, &format!("the levels of detail are 0 to {}", LEVELS - 1)),
                };
                let s = self.shared.lock();
                match mesh_file(&s, &ext, level) {
                    Ok(bytes) => {
                        let stem =
                            Path::new(&s.name).file_stem().and_then(|s| s.to_str()).unwrap_or("result");
                        let stem: String = stem
                            .chars()
                            .map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' })
                            .collect();
                        let lod = if level > 0 { format!(".lod{level}") } else { String::new() };
                        binary(bytes).with_header(
                            "Content-Disposition",
                            &format!("attachment; filename=\"{stem}{lod}.{ext}\""),
                        )
                    }
                    Err(e) => error(409, &e),
                }
            }
            ("POST", "/api/solve") => {
                let tuning: Tuning = match serde_json::from_slice(&request.body) {
                    Ok(t) => t,
                    Err(e) => return error(400, &format!("bad parameters: {e}")),
                };
                let s = self.shared.lock();
                if s.model.is_none() {
                    return error(409, "no input to solve: open a file");
                }
                drop(s);
                // Refuse bad values at once, with the library's message; the base
                // parameters only matter for the preset's other fields.
                if let Err(e) = tuning.resolve() {
                    return error(400, &e);
                }
                let job = self.shared.next_job();
                self.send(Job::Solve(tuning, job));
                json_response(202, &json!({ "queued": true, "job": job }))
            }
            ("POST", "/api/edit") => {
                let edit: Edit = match serde_json::from_slice(&request.body) {
                    Ok(e) => e,
                    Err(e) => return error(400, &format!("bad edit: {e}")),
                };
                let s = self.shared.lock();
                let Some(faces) = s.model.as_ref().map(|m| m.faces) else {
                    return error(409, "no input to edit: open a file");
                };
                if edit.model != s.model_id {
                    return error(409, "the surface changed since that click: click again");
                }
                if s.level != 0 {
                    return error(
                        409,
                        "voxel edits apply to the full surface: choose its level (full) first",
                    );
                }
                if edit.face >= faces {
                    return error(400, &format!("no face {} on this surface of {faces} faces", edit.face));
                }
                drop(s);
                if let Some(t) = &edit.tuning {
                    if let Err(e) = t.resolve() {
                        return error(400, &e);
                    }
                }
                let job = self.shared.next_job();
                self.send(Job::Edit(edit, job));
                json_response(202, &json!({ "queued": true, "job": job }))
            }
            ("POST", "/api/level") => {
                let choice: LevelChoice = match serde_json::from_slice(&request.body) {
                    Ok(c) => c,
                    Err(e) => return error(400, &format!("bad level: {e}")),
                };
                if choice.level >= LEVELS {
                    return error(
                        400,
                        &format!("no level {}: the levels of detail are 0 to {}", choice.level, LEVELS - 1),
                    );
                }
                if self.shared.lock().model.is_none() {
                    return error(409, "no surface to simplify: open a file");
                }
                self.shared.update(|s| s.level = choice.level);
                json_response(200, &json!({ "level": choice.level }))
            }
            ("GET", "/api/level") => {
                let k = match query_value(query, "k").map(|k| k.parse::<usize>()) {
                    Some(Ok(k)) if k < LEVELS => k,
                    _ => return error(400, &format!("ask for a level ?k= from 0 to {}", LEVELS - 1)),
                };
                let s = self.shared.lock();
                match (Levels::of(&s).and_then(|l| l.get(k)), &s.model) {
                    (Some(level), Some(model)) => binary(level_bytes(&level.mesh, model, s.palette.as_ref()))
                        .with_header("X-Frame", &s.frame.to_string())
                        .with_header("X-Model", &s.model_id.to_string())
                        .with_header("X-Level", &k.to_string()),
                    _ => error(409, &format!("level {k} is not computed for this result: choose it first")),
                }
            }
            ("POST", "/api/open") => {
                let name = query_value(query, "name").unwrap_or_default();
                match self.open_upload(&request.body, &name) {
                    Ok(()) => json_response(200, &json!({ "opened": name })),
                    Err(e) => error(400, &e),
                }
            }
            #[cfg(test)]
            ("GET", "/api/test-panic") => panic!("a test panic"),
            ("GET", p) => {
                match ASSETS.iter().find(|a| a.path == p || (p == "/index.html" && a.path == "/")) {
                    Some(a) => Reply {
                        status: 200,
                        headers: vec![("Content-Type", a.mime.to_string())],
                        body: a.bytes.to_vec(),
                    },
                    None => error(404, &format!("no such page: {}", printable(p))),
                }
            }
            (m, p) => error(405, &format!("{} {}: not supported", printable(m), printable(p))),
        }
    }

    /// Reads an upload from memory with the loader, and queues it (waiting for the
    /// worker to take it, so that its errors reach the page).
    fn open_upload(&self, body: &[u8], name: &str) -> Result<(), String> {
        let file = Path::new(name).file_name().and_then(|f| f.to_str()).unwrap_or("");
        if file.is_empty() {
            return Err("the upload names no file (?name=FILE)".into());
        }
        let loader = Arc::clone(&self.loader);
        let mut loaded = match catch_unwind(AssertUnwindSafe(|| loader(file, body))) {
            Ok(r) => r?,
            Err(panic) => return Err(format!("{file}: internal error: {}", panic_message(&*panic))),
        };
        loaded.name = file.to_string();
        let (tx, rx) = mpsc::channel();
        let job = self.shared.next_job();
        self.send(Job::Open(Box::new(loaded), Some(tx), job));
        rx.recv().unwrap_or_else(|_| Err(format!("{file}: the solver stopped")))
    }

    fn state_json(&self) -> serde_json::Value {
        let s = self.shared.lock();
        let command = s.tuning.as_ref().map(|t| {
            let stem = Path::new(&s.name).file_stem().and_then(|s| s.to_str()).unwrap_or("result");
            t.command_line(&s.name, &format!("{stem}.glb"))
        });
        json!({
            "version": s.version,
            "model_id": s.model_id,
            "name": s.name,
            "vertices": s.model.as_ref().map(|m| m.vertices),
            "faces": s.model.as_ref().map(|m| m.faces),
            "groups": s.model.as_ref().map(|m| m.groups.clone()),
            "tuning": s.tuning,
            "command": command,
            "frame": s.frame,
            "job": s.job,
            "final": s.frame_final,
            "stage": s.stage,
            "iteration": s.iteration,
            "busy": s.busy,
            "error": s.error,
            "first_frame_ms": s.first_frame_ms,
            "total_ms": s.total_ms,
            "iterations": s.iterations,
            "warm": s.warm,
            "summary": s.finished.as_ref().map(|f| f.summary.clone()),
            "has_features": s.finished.as_ref().is_some_and(|f| f.features.is_some()),
            "superseded": s.superseded,
            "edited": s.edited,
            "edit_ms": s.edit_ms,
            "level": s.level,
            "level_count": LEVELS,
            "level_shown": crate::levels::shown(&s),
            "levels": Levels::of(&s).map(|l| l.iter().map(|l| json!({
                "faces": l.stats.faces,
                "error_bound": l.stats.error_bound,
            })).collect::<Vec<_>>()),
            "levels_busy": s.levels_busy,
            "levels_progress": s.levels_progress,
            "levels_stopped": s.levels_stopped,
            "levels_ms": s.levels.as_ref().filter(|l| l.frame == s.frame).map(|l| l.ms),
        })
    }

    fn model_bytes(&self, f: impl FnOnce(&crate::model::Model) -> Vec<u8>) -> Reply {
        let s = self.shared.lock();
        match &s.model {
            Some(m) => binary(f(m)).with_header("X-Model", &s.model_id.to_string()),
            None => error(404, "no surface yet"),
        }
    }

    fn finished_bytes(&self, f: impl FnOnce(&crate::session::Finished) -> Option<Vec<u8>>) -> Reply {
        let s = self.shared.lock();
        match s.finished.as_ref().and_then(|r| f(r)) {
            Some(bytes) => binary(bytes),
            None => error(404, "not available for this result"),
        }
    }

    /// Server-sent events: the state as JSON each time it changes (at most one event per
    /// change, the latest), until the page goes or the server stops (`once`: after the
    /// first event).
    fn events(&self, w: &mut impl Write, once: bool) {
        // The head goes out with the first event, in one write.
        let mut out = format!(
            "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-cache\r\n{}\
             Connection: close\r\n\r\n",
            COMMON_HEADERS
        );
        let mut sent = u64::MAX;
        loop {
            let version = {
                let s = self.shared.lock();
                let wait = if once { Duration::ZERO } else { KEEP_ALIVE };
                let (s, _) = self
                    .shared
                    .changed
                    .wait_timeout_while(s, wait, |s| s.version == sent && !s.shutdown)
                    .unwrap_or_else(|e| e.into_inner());
                if s.shutdown && !once {
                    return;
                }
                s.version
            };
            if version == sent {
                out.push_str(": keep-alive\n\n");
            } else {
                sent = version;
                out.push_str(&format!("data: {}\n\n", self.state_json()));
            }
            if w.write_all(out.as_bytes()).and_then(|()| w.flush()).is_err() || once {
                return;
            }
            out.clear();
        }
    }
}

/// Headers of every response: no page address leaks in a `Referer`, no content is
/// sniffed as another type, no other site frames the page.
const COMMON_HEADERS: &str =
    "Referrer-Policy: no-referrer\r\nX-Content-Type-Options: nosniff\r\nX-Frame-Options: DENY\r\n";

/// The bytes of `reply`: head and body in one buffer, written in one write (a small body
/// written after the head would wait for the peer's delayed ACK), with `Connection:
/// close` (one request per connection).
fn serialize(reply: &Reply) -> Vec<u8> {
    let reason = match reply.status {
        200 => "OK",
        202 => "Accepted",
        204 => "No Content",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        409 => "Conflict",
        411 => "Length Required",
        413 => "Content Too Large",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        _ => "",
    };
    let mut head = format!("HTTP/1.1 {} {reason}\r\n", reply.status);
    for (name, value) in &reply.headers {
        head.push_str(&format!("{name}: {value}\r\n"));
    }
    head.push_str(&format!(
        "Content-Length: {}\r\n{COMMON_HEADERS}Connection: close\r\n\r\n",
        reply.body.len()
    ));
    let mut out = Vec::with_capacity(head.len() + reply.body.len());
    out.extend_from_slice(head.as_bytes());
    out.extend_from_slice(&reply.body);
    out
}

/// Reads a request head: its length and every byte read so far (the head, then perhaps
/// the body's start); `None` when the peer closed without sending anything.
fn read_head(input: &mut impl Read) -> Result<Option<(usize, Vec<u8>)>, Reply> {
    let mut bytes = Vec::with_capacity(1024);
    let mut chunk = [0u8; 4096];
    loop {
        let n = match input.read(&mut chunk) {
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(_) if bytes.is_empty() => return Ok(None),
            Err(e) => return Err(error(400, &format!("cannot read the request: {e}"))),
        };
        if n == 0 {
            return if bytes.is_empty() { Ok(None) } else { Err(error(400, "an incomplete request head")) };
        }
        let from = bytes.len().saturating_sub(3);
        bytes.extend_from_slice(&chunk[..n]);
        if let Some(end) = bytes[from..].windows(4).position(|w| w == b"\r\n\r\n") {
            let len = from + end + 4;
            if len > MAX_HEAD {
                return Err(error(431, &format!("the request head is over {MAX_HEAD} bytes")));
            }
            return Ok(Some((len, bytes)));
        }
        if bytes.len() > MAX_HEAD {
            return Err(error(431, &format!("the request head is over {MAX_HEAD} bytes")));
        }
    }
}

/// The largest body a route takes: an upload, parameters, an edit or a level; nothing
/// elsewhere.
fn body_limit(method: &str, path: &str) -> u64 {
    match (method, path) {
        ("POST", "/api/open") => MAX_UPLOAD,
        ("POST", "/api/solve" | "/api/edit" | "/api/level") => MAX_FORM,
        _ => 0,
    }
}

/// The level of detail the page chooses (`POST /api/level`): 0 (the full surface) to
/// [`LEVELS`]` - 1`.
#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct LevelChoice {
    level: usize,
}

/// Whether two secrets are equal, in a time that does not depend on where they differ.
fn same_secret(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

/// `text` for a message: control characters (terminal escapes) replaced, at most 100
/// characters.
fn printable(text: &str) -> String {
    text.chars().take(100).map(|c| if c.is_control() { '?' } else { c }).collect()
}

fn binary(bytes: Vec<u8>) -> Reply {
    Reply { status: 200, headers: vec![("Content-Type", "application/octet-stream".into())], body: bytes }
}

fn json_response(status: u16, value: &serde_json::Value) -> Reply {
    Reply {
        status,
        headers: vec![("Content-Type", "application/json".into())],
        body: value.to_string().into_bytes(),
    }
}

fn error(status: u16, message: &str) -> Reply {
    json_response(status, &json!({ "error": message }))
}

/// The percent-decoded value of `key` in a query string.
fn query_value(query: &str, key: &str) -> Option<String> {
    query.split('&').find_map(|kv| {
        let (k, v) = kv.split_once('=')?;
        (k == key).then(|| percent_decode(v))
    })
}

fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match b[i] {
            b'%' if i + 2 < b.len() => match (hex(b[i + 1]), hex(b[i + 2])) {
                (Some(h), Some(l)) => {
                    out.push((h * 16 + l) as u8);
                    i += 3;
                    continue;
                }
                _ => out.push(b'%'),
            },
            b'+' => out.push(b' '),
            c => out.push(c),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

#[cfg(test)]
mod tests;
