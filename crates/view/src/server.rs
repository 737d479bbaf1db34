//! The HTTP side: routes, the event stream, the embedded assets, and the rules that keep
//! the server up (loopback peers and hosts only, every request's panic caught, bodies
//! bounded).

use std::io::{Cursor, Read, Write};
use std::net::{SocketAddr, TcpListener};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;
use std::sync::mpsc::{self, Sender};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use serde_json::json;
use tiny_http::{Header, Method, Request, Response, Server};

use crate::session::{mesh_file, panic_message, Edit, Job, Shared};
use voxreg_regularize::Preset;

use crate::tuning::Tuning;
use crate::{Loaded, ViewError};

/// Reads an input file dropped on the page (a temporary copy with the dropped file's
/// name): the command line's reading, with its options.
pub type Loader = dyn Fn(&Path) -> Result<Loaded, String> + Send + Sync;

/// The largest file the page may upload.
const MAX_UPLOAD: u64 = 1 << 30;

/// How often an idle event stream sends a keep-alive comment (and notices a closed page).
const KEEP_ALIVE: Duration = Duration::from_secs(10);

/// The longest a request for a newer frame (`/api/positions?after=F`) waits for one; the
/// page asks again (its requests give up on a stalled connection after 4 s).
const FRAME_WAIT: Duration = Duration::from_secs(2);

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
/// answers requests until [`Viewer::stop`] (from another thread, through a
/// [`StopHandle`]).
pub struct Viewer {
    server: Arc<Server>,
    addr: SocketAddr,
    shared: Arc<Shared>,
    jobs: Mutex<Sender<Job>>,
    loader: Arc<Loader>,
}

/// Stops a serving [`Viewer`] from another thread.
#[derive(Clone)]
pub struct StopHandle {
    server: Arc<Server>,
    shared: Arc<Shared>,
}

impl StopHandle {
    /// Makes [`Viewer::serve`] return and closes the event streams.
    pub fn stop(&self) {
        self.shared.update(|s| s.shutdown = true);
        self.server.unblock();
    }
}

impl Viewer {
    /// Listens on `127.0.0.1:port` (`port` 0: a free port); `loader` reads the files
    /// dropped on the page.
    pub fn bind(port: u16, loader: Box<Loader>) -> Result<Viewer, ViewError> {
        let listener =
            TcpListener::bind(("127.0.0.1", port)).map_err(|e| ViewError::Bind(port, e.to_string()))?;
        let addr = listener.local_addr().map_err(|e| ViewError::Bind(port, e.to_string()))?;
        let server =
            Server::from_listener(listener, None).map_err(|e| ViewError::Bind(port, e.to_string()))?;
        let shared = Arc::new(Shared::default());
        let (tx, rx) = mpsc::channel();
        let worker_shared = Arc::clone(&shared);
        std::thread::Builder::new()
            .name("voxreg-view-solve".into())
            .spawn(move || crate::session::worker(worker_shared, rx))
            .map_err(|e| ViewError::Bind(port, e.to_string()))?;
        Ok(Viewer { server: Arc::new(server), addr, shared, jobs: Mutex::new(tx), loader: Arc::from(loader) })
    }

    /// The page's address, `http://127.0.0.1:PORT/`.
    pub fn url(&self) -> String {
        format!("http://{}/", self.addr)
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
        StopHandle { server: Arc::clone(&self.server), shared: Arc::clone(&self.shared) }
    }

    fn send(&self, job: Job) {
        // The worker only ends when the viewer does.
        let _ = self.jobs.lock().unwrap_or_else(|e| e.into_inner()).send(job);
    }

    /// Answers requests, each on its own thread, until stopped.
    pub fn serve(self) {
        let viewer = Arc::new(self);
        loop {
            let request = match viewer.server.recv() {
                Ok(r) => r,
                Err(_) if viewer.shared.lock().shutdown => break,
                Err(_) => continue,
            };
            if viewer.shared.lock().shutdown {
                let _ = request.respond(Response::from_string("stopping").with_status_code(503));
                break;
            }
            let v = Arc::clone(&viewer);
            let spawned = std::thread::Builder::new()
                .name("voxreg-view-request".into())
                .spawn(move || v.answer(request));
            if spawned.is_err() {
                // No thread to answer with: the request is dropped (its connection closes).
                continue;
            }
        }
    }

    fn answer(&self, mut request: Request) {
        if let Err(why) = self.allowed(&request) {
            respond_whole(request, json_response(403, &json!({ "error": why })));
            return;
        }
        if request.method() == &Method::Get && request.url() == "/api/events" {
            self.events(request);
            return;
        }
        let reply = catch_unwind(AssertUnwindSafe(|| self.route(&mut request)));
        let response = match reply {
            Ok(r) => r,
            Err(panic) => {
                json_response(500, &json!({ "error": format!("internal error: {}", panic_message(&*panic)) }))
            }
        };
        respond_whole(request, response);
    }

    /// Only loopback peers, and only this server's own host names (a page on another
    /// site cannot reach it through DNS rebinding).
    fn allowed(&self, request: &Request) -> Result<(), String> {
        if !request.remote_addr().is_some_and(|a| a.ip().is_loopback()) {
            return Err("only loopback connections are served".into());
        }
        let port = self.addr.port();
        let host = request.headers().iter().find(|h| h.field.equiv("Host")).map(|h| h.value.as_str());
        let ok = [format!("127.0.0.1:{port}"), format!("localhost:{port}")];
        match host {
            Some(h) if ok.iter().any(|o| o == h) => Ok(()),
            Some(h) => Err(format!("unexpected Host '{h}'")),
            None => Err("no Host header".into()),
        }
    }

    fn route(&self, request: &mut Request) -> Response<Cursor<Vec<u8>>> {
        let url = request.url().to_string();
        let (path, query) = url.split_once('?').unwrap_or((&url, ""));
        let method = request.method().clone();
        match (&method, path) {
            (Method::Get, "/favicon.ico") => Response::from_data(Vec::new()).with_status_code(204),
            (Method::Get, "/api/state") => json_response(200, &self.state_json()),
            (Method::Get, "/api/surface") => self.model_bytes(|m| m.surface_bytes()),
            (Method::Get, "/api/positions") => {
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
                        .with_header(header("X-Frame", &s.frame.to_string()))
                        .with_header(header("X-Job", &s.job.to_string()))
                        .with_header(header("X-Model", &s.model_id.to_string()))
                        .with_header(header("X-Final", if s.frame_final { "1" } else { "0" })),
                    None => error(404, "no surface yet"),
                }
            }
            (Method::Get, "/api/normals") => self.finished_bytes(|f| Some(f.normals.clone())),
            (Method::Get, "/api/features") => self.finished_bytes(|f| f.features.clone()),
            (Method::Get, "/api/preset") => {
                let name = query_value(query, "name").unwrap_or_default();
                match name.parse::<Preset>() {
                    Ok(p) => json_response(200, &json!(Tuning::preset(p))),
                    Err(e) => error(400, &format!("preset {e}")),
                }
            }
            (Method::Get, "/api/report") => {
                let s = self.shared.lock();
                match &s.finished {
                    Some(f) => json_response(200, &json!({ "summary": f.summary, "report": f.report })),
                    None => error(404, "no result yet"),
                }
            }
            (Method::Get, "/api/download") => {
                let ext = query_value(query, "format").unwrap_or_default();
                if !matches!(ext.as_str(), "glb" | "ply" | "obj") {
                    return error(400, &format!("unknown download format '{ext}' (glb, ply or obj)"));
                }
                let s = self.shared.lock();
                match mesh_file(&s, &ext) {
                    Ok(bytes) => {
                        let stem =
                            Path::new(&s.name).file_stem().and_then(|s| s.to_str()).unwrap_or("result");
                        let stem: String = stem
                            .chars()
                            .map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' })
                            .collect();
                        binary(bytes).with_header(header(
                            "Content-Disposition",
                            &format!("attachment; filename=\"{stem}.{ext}\""),
                        ))
                    }
                    Err(e) => error(409, &e),
                }
            }
            (Method::Post, "/api/solve") => {
                let body = match read_body(request, 1 << 16) {
                    Ok(b) => b,
                    Err(e) => return error(400, &e),
                };
                let tuning: Tuning = match serde_json::from_slice(&body) {
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
            (Method::Post, "/api/edit") => {
                let body = match read_body(request, 1 << 16) {
                    Ok(b) => b,
                    Err(e) => return error(400, &e),
                };
                let edit: Edit = match serde_json::from_slice(&body) {
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
            (Method::Post, "/api/open") => {
                let name = query_value(query, "name").unwrap_or_default();
                match self.open_upload(request, &name) {
                    Ok(()) => json_response(200, &json!({ "opened": name })),
                    Err(e) => error(400, &e),
                }
            }
            #[cfg(test)]
            (Method::Get, "/api/test-panic") => panic!("a test panic"),
            (Method::Get, p) => match ASSETS
                .iter()
                .find(|a| a.path == p || (p == "/index.html" && a.path == "/"))
            {
                Some(a) => Response::from_data(a.bytes.to_vec()).with_header(header("Content-Type", a.mime)),
                None => error(404, &format!("no such page: {p}")),
            },
            (m, p) => error(405, &format!("{m} {p}: not supported")),
        }
    }

    fn open_upload(&self, request: &mut Request, name: &str) -> Result<(), String> {
        let file = Path::new(name).file_name().and_then(|f| f.to_str()).unwrap_or("");
        if file.is_empty() {
            return Err("the upload names no file (?name=FILE)".into());
        }
        let body = read_body(request, MAX_UPLOAD)?;
        let dir = tempfile::tempdir().map_err(|e| format!("cannot create a temporary directory: {e}"))?;
        let path = dir.path().join(file);
        std::fs::write(&path, &body).map_err(|e| format!("{file}: cannot store the upload: {e}"))?;
        let loader = Arc::clone(&self.loader);
        let mut loaded = match catch_unwind(AssertUnwindSafe(|| loader(&path))) {
            // Name the file as dropped, not its temporary copy.
            Ok(r) => r.map_err(|e| e.replace(&format!("{}/", dir.path().display()), ""))?,
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
        })
    }

    fn model_bytes(&self, f: impl FnOnce(&crate::model::Model) -> Vec<u8>) -> Response<Cursor<Vec<u8>>> {
        let s = self.shared.lock();
        match &s.model {
            Some(m) => binary(f(m)).with_header(header("X-Model", &s.model_id.to_string())),
            None => error(404, "no surface yet"),
        }
    }

    fn finished_bytes(
        &self,
        f: impl FnOnce(&crate::session::Finished) -> Option<Vec<u8>>,
    ) -> Response<Cursor<Vec<u8>>> {
        let s = self.shared.lock();
        match s.finished.as_ref().and_then(|r| f(r)) {
            Some(bytes) => binary(bytes),
            None => error(404, "not available for this result"),
        }
    }

    /// Server-sent events: the state as JSON each time it changes (at most one event per
    /// change, the latest), until the page goes or the server stops.
    fn events(&self, request: Request) {
        let mut w = request.into_writer();
        // The head goes out with the first event, in one write (see `respond_whole`).
        let mut out = "HTTP/1.1 200 OK\r\nContent-Type: text/event-stream\r\nCache-Control: no-cache\r\n\
                       Connection: close\r\n\r\n"
            .to_string();
        let mut sent = u64::MAX;
        loop {
            let version = {
                let s = self.shared.lock();
                let (s, _) = self
                    .shared
                    .changed
                    .wait_timeout_while(s, KEEP_ALIVE, |s| s.version == sent && !s.shutdown)
                    .unwrap_or_else(|e| e.into_inner());
                if s.shutdown {
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
            if w.write_all(out.as_bytes()).and_then(|()| w.flush()).is_err() {
                return;
            }
            out.clear();
        }
    }
}

/// Sends `response` as one write, with `Connection: close`.
///
/// One write: tiny_http writes the head and the body separately, and a small body written
/// while the head is unacknowledged waits for the peer's delayed ACK (Nagle's algorithm:
/// about 40 ms per request on Linux loopback; tiny_http gives no access to the accepted
/// sockets' `TCP_NODELAY`).
///
/// Closed: tiny_http runs each connection as one task of its thread pool for as long as
/// the connection lives, and its pool can miss a wake-up when connections arrive in a
/// burst (a page load), leaving a new connection queued until another task ends. With
/// kept-alive connections that was seconds (the page's first picture waited up to 4 s
/// for one of its arrays); closed connections end within a request.
fn respond_whole(request: Request, response: Response<Cursor<Vec<u8>>>) {
    let mut message = Vec::with_capacity(response.data_length().unwrap_or(0) + 512);
    let head_only = request.method() == &Method::Head;
    let version = request.http_version().clone();
    if response.raw_print(&mut message, version, request.headers(), head_only, None).is_err() {
        return;
    }
    // After the status line (tiny_http's `Response` refuses a `Connection` header).
    if let Some(end) = message.windows(2).position(|w| w == b"\r\n") {
        message.splice(end + 2..end + 2, b"Connection: close\r\n".iter().copied());
    }
    let mut w = request.into_writer();
    let _ = w.write_all(&message).and_then(|()| w.flush());
}

fn header(name: &str, value: &str) -> Header {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("ASCII header")
}

fn binary(bytes: Vec<u8>) -> Response<Cursor<Vec<u8>>> {
    Response::from_data(bytes).with_header(header("Content-Type", "application/octet-stream"))
}

fn json_response(status: u16, value: &serde_json::Value) -> Response<Cursor<Vec<u8>>> {
    Response::from_data(value.to_string().into_bytes())
        .with_status_code(status)
        .with_header(header("Content-Type", "application/json"))
}

fn error(status: u16, message: &str) -> Response<Cursor<Vec<u8>>> {
    json_response(status, &json!({ "error": message }))
}

fn read_body(request: &mut Request, limit: u64) -> Result<Vec<u8>, String> {
    if request.body_length().is_some_and(|n| n as u64 > limit) {
        return Err(format!("the request body is over {limit} bytes"));
    }
    let mut body = Vec::new();
    request
        .as_reader()
        .take(limit + 1)
        .read_to_end(&mut body)
        .map_err(|e| format!("cannot read the request: {e}"))?;
    if body.len() as u64 > limit {
        return Err(format!("the request body is over {limit} bytes"));
    }
    Ok(body)
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
