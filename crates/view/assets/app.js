// voxreg view: draws the surface the server streams, and sends the panel's parameters.
// State arrives as server-sent events (/api/events); arrays are little-endian binary.
import * as THREE from 'three';
import { OrbitControls } from '/three/OrbitControls.js';

const $ = (id) => document.getElementById(id);
// What the browser test reads.
const view = (window.voxregView = { frames: 0, modelId: 0, state: null, solvePostedAt: null, solveLatencyMs: null, solveFrames: 0, marks: {} });
// Milliseconds since navigation of the first time each step happened (the browser test prints them).
const mark = (k) => { if (!(k in view.marks)) view.marks[k] = Math.round(performance.now()); };
mark('module');

const renderer = new THREE.WebGLRenderer({ canvas: $('canvas'), antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
renderer.localClippingEnabled = true;
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xf4f4f4);
const camera = new THREE.PerspectiveCamera(35, 1, 0.01, 1e5);
const controls = new OrbitControls(camera, renderer.domElement);
controls.addEventListener('change', draw);
scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8a8a, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
sun.position.set(0.4, 0.7, 1);
camera.add(sun);
scene.add(camera);
const clipPlane = new THREE.Plane(new THREE.Vector3(0, 0, -1), 0);
const material = new THREE.MeshLambertMaterial({ vertexColors: true, side: THREE.DoubleSide });
const geometry = new THREE.BufferGeometry();
const mesh = new THREE.Mesh(geometry, material);
const wire = new THREE.LineSegments(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: 0x202020, transparent: true, opacity: 0.5 }));
const arrows = new THREE.LineSegments(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: 0x1060d0 }));
scene.add(mesh, wire, arrows);
// Compile the surface's shaders while the first state and arrays are on their way (with
// KHR_parallel_shader_compile, off the page's thread): a placeholder triangle with the
// attributes the surface will have, so the program is the one it draws with.
if (!location.search.includes('nowarm')) {
  for (const [name, n] of [['position', 3], ['normal', 3], ['color', 3]]) geometry.setAttribute(name, new THREE.BufferAttribute(new Float32Array(9), n));
  renderer.compileAsync(mesh, camera, scene).then(() => mark('compiled'));
}

let model = null; // { quads, faceGroups, faceColors, stair, groups, colors, visible, lo, hi }
let result = null; // latest positions (Float32Array)
let normals = null, features = null;
let frame = -1, loadingModel = 0, fetching = false;

// A GET that gives up on a stalled connection after a few seconds and tries a fresh one.
async function get(url) {
  for (let attempt = 0; ; attempt++) {
    const abort = new AbortController();
    const timer = setTimeout(() => abort.abort(), 4000);
    try {
      const r = await fetch(url, { signal: abort.signal, cache: 'no-store' });
      const body = await r.arrayBuffer();
      return { r, body };
    } catch (e) {
      if (attempt >= 4) throw e;
    } finally {
      clearTimeout(timer);
    }
  }
}

async function bytes(url) {
  const { r, body } = await get(url);
  if (!r.ok) throw new Error(JSON.parse(new TextDecoder().decode(body)).error);
  return body;
}

function showError(message) {
  $('error').hidden = !message;
  $('error').textContent = message || '';
}

async function loadModel(s) {
  const id = s.model_id;
  loadingModel = id;
  const early = window.voxregEarly?.arrays;
  let arrays = early && early.id === id ? await early.bytes.catch(() => null) : null;
  if (!arrays || arrays.includes(null)) arrays = await Promise.all(['quads', 'face-groups', 'face-colors', 'staircase'].map((n) => bytes('/api/' + n)));
  const [q, g, c, p] = arrays;
  if (loadingModel !== id) return;
  mark('arrays');
  const stair = new Float32Array(p);
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < stair.length; i++) { lo[i % 3] = Math.min(lo[i % 3], stair[i]); hi[i % 3] = Math.max(hi[i % 3], stair[i]); }
  model = { id, quads: new Uint32Array(q), faceGroups: new Uint32Array(g), faceColors: new Uint8Array(c), stair, lo, hi,
    groups: s.groups, colors: s.groups.map((x) => x.color.slice()), visible: s.groups.map(() => true), custom: s.groups.map(() => false) };
  result = stair; normals = null; features = null;
  view.modelId = id;
  $('name').textContent = s.name;
  listGroups();
  frameCamera();
  rebuild();
  mark('staircase drawn');
}

function frameCamera() {
  const c = model.lo.map((l, i) => (l + model.hi[i]) / 2);
  const size = Math.max(...model.hi.map((h, i) => h - model.lo[i]), 1);
  controls.target.set(c[0], c[1], c[2]);
  camera.position.set(c[0] + 1.3 * size, c[1] + 1.0 * size, c[2] + 1.6 * size);
  camera.up.set(0, 0, 1);
  camera.near = size / 100; camera.far = size * 100;
  camera.updateProjectionMatrix();
  controls.update();
}

function listGroups() {
  const ul = $('groups');
  ul.replaceChildren();
  model.groups.forEach((g, i) => {
    const li = document.createElement('li');
    const vis = Object.assign(document.createElement('input'), { type: 'checkbox', checked: true });
    vis.onchange = () => { model.visible[i] = vis.checked; rebuild(); };
    const hex = '#' + g.color.map((x) => x.toString(16).padStart(2, '0')).join('');
    const col = Object.assign(document.createElement('input'), { type: 'color', value: hex });
    col.oninput = () => { const v = parseInt(col.value.slice(1), 16); model.colors[i] = [v >> 16, (v >> 8) & 255, v & 255]; model.custom[i] = true; rebuild(); };
    li.append(vis, col, `${g.name} (${g.faces})`);
    ul.append(li);
  });
}

function ramp(v) { // the CLI's feature ramp: dark red 0, amber 0.5, light grey 1
  const t = Math.min(Math.max(v, 0), 1);
  const a = [0.45, 0.05, 0.05], b = [1.0, 0.65, 0.1], c = [0.85, 0.85, 0.85];
  const [u, w, s] = t < 0.5 ? [a, b, t * 2] : [b, c, t * 2 - 1];
  return u.map((x, i) => x + (w[i] - x) * s);
}

// Positions blended between the staircase and the latest result; flat or smooth normals;
// only the faces of visible groups.
// The work arrays, kept while their sizes do not change (a streamed iterate refills them).
const work = {};
function scratch(name, n) {
  if (!work[name] || work[name].length !== n) work[name] = new Float32Array(n);
  return work[name];
}
// `geometry`'s attribute `name` over `array`: refilled in place when it is the same array.
function attribute(g, name, array) {
  const a = g.getAttribute(name);
  if (a && a.array === array) a.needsUpdate = true;
  else g.setAttribute(name, new THREE.BufferAttribute(array, 3));
}

function rebuild() {
  if (!model) return;
  const started = performance.now();
  const t = parseFloat($('blend').value), st = model.stair, n = st.length;
  const x = scratch('x', n);
  for (let i = 0; i < n; i++) x[i] = st[i] + (result[i] - st[i]) * t;
  const q = model.quads, m = q.length / 4;
  const fn = scratch('fn', 3 * m), vn = scratch('vn', n);
  vn.fill(0);
  for (let f = 0; f < m; f++) {
    const [a, b, c, d] = [q[4 * f], q[4 * f + 1], q[4 * f + 2], q[4 * f + 3]];
    const u = [0, 1, 2].map((k) => x[3 * c + k] - x[3 * a + k]), v = [0, 1, 2].map((k) => x[3 * d + k] - x[3 * b + k]);
    const nx = u[1] * v[2] - u[2] * v[1], ny = u[2] * v[0] - u[0] * v[2], nz = u[0] * v[1] - u[1] * v[0];
    fn[3 * f] = nx; fn[3 * f + 1] = ny; fn[3 * f + 2] = nz;
    for (const w of [a, b, c, d]) { vn[3 * w] += nx; vn[3 * w + 1] += ny; vn[3 * w + 2] += nz; }
  }
  const smooth = $('smooth').checked, showFeatures = $('features').checked && features;
  const drawn = [];
  for (let f = 0; f < m; f++) if (model.visible[model.faceGroups[f]]) drawn.push(f);
  const pos = scratch('pos', 18 * drawn.length), nor = scratch('nor', 18 * drawn.length), col = scratch('col', 18 * drawn.length);
  const corner = [0, 1, 2, 0, 2, 3];
  drawn.forEach((f, j) => {
    const g = model.faceGroups[f];
    const fc = model.custom[g] ? model.colors[g] : [model.faceColors[3 * f], model.faceColors[3 * f + 1], model.faceColors[3 * f + 2]];
    const lin = fc.map((c) => Math.pow(c / 255, 2.2));
    for (let k = 0; k < 6; k++) {
      const w = q[4 * f + corner[k]], o = 18 * j + 3 * k;
      const c = showFeatures ? ramp(features[w]) : lin;
      for (let e = 0; e < 3; e++) {
        pos[o + e] = x[3 * w + e];
        nor[o + e] = smooth ? vn[3 * w + e] : fn[3 * f + e];
        col[o + e] = c[e];
      }
    }
  });
  attribute(geometry, 'position', pos);
  attribute(geometry, 'normal', nor);
  attribute(geometry, 'color', col);
  geometry.normalizeNormals();
  geometry.computeBoundingSphere();
  wire.visible = $('wireframe').checked;
  if (wire.visible) {
    const l = new Float32Array(24 * drawn.length);
    drawn.forEach((f, j) => {
      for (let k = 0; k < 4; k++) for (const [s, w] of [[0, q[4 * f + k]], [1, q[4 * f + (k + 1) % 4]]])
        for (let e = 0; e < 3; e++) l[24 * j + 6 * k + 3 * s + e] = x[3 * w + e];
    });
    wire.geometry.setAttribute('position', new THREE.BufferAttribute(l, 3));
    wire.geometry.computeBoundingSphere();
  }
  arrows.visible = $('normals').checked && !!normals;
  if (arrows.visible) {
    const step = Math.max(1, Math.floor(drawn.length / 20000)), len = 0.6;
    const chosen = drawn.filter((_, j) => j % step === 0), l = new Float32Array(6 * chosen.length);
    chosen.forEach((f, j) => {
      for (let e = 0; e < 3; e++) {
        let c = 0;
        for (let k = 0; k < 4; k++) c += x[3 * q[4 * f + k] + e] / 4;
        l[6 * j + e] = c; l[6 * j + 3 + e] = c + len * normals[3 * f + e];
      }
    });
    arrows.geometry.setAttribute('position', new THREE.BufferAttribute(l, 3));
    arrows.geometry.computeBoundingSphere();
  }
  const clip = $('clip').checked ? [clipPlane] : [];
  if (clip.length) {
    const axis = 'xyz'.indexOf($('clip-axis').value), at = parseFloat($('clip-at').value);
    const normal = [0, 0, 0]; normal[axis] = -1;
    clipPlane.normal.set(...normal);
    clipPlane.constant = model.lo[axis] + at * (model.hi[axis] - model.lo[axis]);
  }
  for (const o of [mesh, wire, arrows]) o.material.clippingPlanes = clip;
  const built = performance.now();
  draw();
  view.lastRebuildMs = { build: Math.round(built - started), draw: Math.round(performance.now() - built) };
}

function draw() {
  const c = renderer.domElement, w = c.clientWidth, h = c.clientHeight;
  if (c.width !== Math.floor(w * renderer.getPixelRatio()) || c.height !== Math.floor(h * renderer.getPixelRatio())) {
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
  }
  renderer.render(scene, camera);
}
window.addEventListener('resize', draw);

async function fetchPositions(s) {
  if (fetching) return;
  fetching = true;
  try {
    while (frame !== view.state.frame && model && view.state.model_id === model.id) {
      const want = view.state;
      const asked = performance.now();
      const { r, body } = await get('/api/positions');
      if (!r.ok) break;
      view.lastFetchMs = Math.round(performance.now() - asked);
      const got = parseInt(r.headers.get('X-Frame'));
      result = new Float32Array(body);
      frame = got;
      view.frames++;
      if (want.final && got === want.frame) {
        await loadResult(want);
      }
      rebuild();
      mark(want.final ? 'result drawn' : 'iterate drawn');
      if (view.solvePostedAt !== null) {
        // The first frame drawn after a re-solve was posted: its latency, and whether it
        // was an iterate (streamed) or already the final result.
        view.solveFrames++;
        if (view.solveLatencyMs === null) {
          view.solveLatencyMs = performance.now() - view.solvePostedAt;
          view.firstSolveFrameFinal = want.final;
        }
      }
    }
  } finally {
    fetching = false;
  }
}

async function loadResult(s) {
  normals = new Float32Array(await bytes('/api/normals'));
  features = s.has_features ? new Float32Array(await bytes('/api/features')) : null;
  $('features').disabled = !features;
  const r = JSON.parse(new TextDecoder().decode((await get('/api/report')).body));
  const rep = r.report, times = rep.stages;
  $('report').textContent = [r.summary,
    `normals: ${rep.normals.estimator}`,
    `stages (s): ${Object.entries(times).map(([k, v]) => `${k} ${v.toFixed(3)}`).join(', ')}`,
    `solves: ${rep.solves.length}`,
    s.total_ms !== null ? `last solve on the page: ${(s.total_ms / 1000).toFixed(2)} s` : ''].join('\n');
}

// The voxel-art smoothness S is another view of the clamping margin (1 - 0.99 S, the
// library's Params::with_smoothness): the slider and the margin follow each other, and
// the slider's value is sent (the command line then says --smoothness) once it was moved.
let smoothnessSet = false;
function showSmoothness(s) {
  $('smoothness').value = s; $('smoothness-value').textContent = (+s).toFixed(2);
  $('smoothness-row').hidden = $('preset').value !== 'voxel-art';
}
function setTuning(t) {
  $('preset').value = t.preset; $('estimator').value = t.estimator;
  $('alpha').value = t.alpha; $('beta').value = t.beta; $('gamma').value = t.gamma; $('refine').value = t.refine;
  $('clamped').checked = t.clamp !== null; if (t.clamp !== null) $('clamp').value = t.clamp;
  $('texture-aware').checked = t.texture_aware;
  smoothnessSet = t.smoothness != null;
  showSmoothness(smoothnessSet ? t.smoothness : t.clamp !== null ? Math.min(Math.max((1 - t.clamp) / 0.99, 0.05), 1) : 1);
}

function tuning() {
  const smoothness = smoothnessSet && $('clamped').checked ? parseFloat($('smoothness').value) : null;
  return { preset: $('preset').value, estimator: $('estimator').value, alpha: parseFloat($('alpha').value),
    beta: parseFloat($('beta').value), gamma: parseFloat($('gamma').value), refine: parseInt($('refine').value) || 0,
    clamp: $('clamped').checked ? parseFloat($('clamp').value) : null, smoothness, texture_aware: $('texture-aware').checked };
}
$('smoothness').addEventListener('input', () => {
  const s = parseFloat($('smoothness').value);
  smoothnessSet = true;
  $('clamped').checked = true;
  $('clamp').value = +(1 - 0.99 * s).toFixed(4);
  showSmoothness(s);
});
for (const id of ['clamp', 'clamped']) $(id).addEventListener('input', () => {
  smoothnessSet = false;
  const c = parseFloat($('clamp').value);
  if (c > 0 && c < 1) showSmoothness(Math.min(Math.max((1 - c) / 0.99, 0.05), 1));
});

let tuned = -1;
async function onState(s) {
  mark('state');
  view.state = s;
  const busy = s.busy ? `${s.stage}${s.iteration != null ? ' iteration ' + s.iteration : ''}…` : 'ready';
  $('status').textContent = `${s.name || ''}: ${busy}${s.total_ms != null && !s.busy ? ` (${(s.total_ms / 1000).toFixed(2)} s)` : ''}`;
  if (s.error) showError(s.error);
  if (s.command) $('command').value = s.command;
  if (s.tuning && tuned !== s.model_id) { setTuning(s.tuning); tuned = s.model_id; }
  if (s.model_id && (!model || model.id !== s.model_id)) {
    if (loadingModel !== s.model_id) {
      try {
        await loadModel(s);
      } catch (e) {
        loadingModel = 0; // the next event tries again
        throw e;
      }
      frame = -1;
    } else return;
  }
  fetchPositions(s);
}

// The stream index.html opened; its latest event, if one came while this module loaded.
const events = window.voxregEarly?.events ?? new EventSource('/api/events');
events.onmessage = (e) => onState(JSON.parse(e.data)).catch((err) => showError(`the page could not update: ${err}`));
if (window.voxregEarly?.last) events.onmessage(window.voxregEarly.last);
mark('module done');

let pending = null;
async function solve() {
  view.solvePostedAt = performance.now(); view.solveLatencyMs = null; view.solveFrames = 0;
  const r = await fetch('/api/solve', { method: 'POST', body: JSON.stringify(tuning()) });
  if (!r.ok) { view.solvePostedAt = null; showError((await r.json()).error); return; }
  showError(null);
}
$('tuning').addEventListener('change', async (e) => {
  if (e.target.id === 'preset') {
    const r = await fetch('/api/preset?name=' + $('preset').value);
    if (r.ok) setTuning(await r.json());
  }
  clearTimeout(pending);
  pending = setTimeout(solve, 100);
});
$('tuning').addEventListener('submit', (e) => e.preventDefault());
for (const id of ['blend', 'wireframe', 'smooth', 'features', 'normals', 'clip', 'clip-axis', 'clip-at']) $(id).addEventListener('input', rebuild);
$('copy').onclick = async () => {
  $('command').select();
  try { await navigator.clipboard.writeText($('command').value); } catch { document.execCommand('copy'); }
};

async function open(file) {
  $('status').textContent = `opening ${file.name}…`;
  const r = await fetch('/api/open?name=' + encodeURIComponent(file.name), { method: 'POST', body: file });
  if (!r.ok) showError((await r.json()).error); else showError(null);
}
$('open').onchange = () => $('open').files[0] && open($('open').files[0]);
document.addEventListener('dragover', (e) => { e.preventDefault(); $('drop').hidden = false; });
document.addEventListener('dragleave', (e) => { if (!e.relatedTarget) $('drop').hidden = true; });
document.addEventListener('drop', (e) => {
  e.preventDefault();
  $('drop').hidden = true;
  const f = e.dataTransfer.files[0];
  if (f) open(f);
});
