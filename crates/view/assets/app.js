// voxreg view: draws the surface the server streams, and sends the panel's parameters.
// State arrives as server-sent events (/api/events); arrays are little-endian binary.
import * as THREE from 'three';
import { OrbitControls } from '/three/OrbitControls.js';

const $ = (id) => document.getElementById(id);
// What the browser test reads.
const view = (window.voxregView = { frames: 0, modelId: 0, state: null, solveAskedAt: null, solveLatencyMs: null, solveFrames: 0, marks: {}, edits: 0, solves: 0, solveJob: null, levelShown: null });
// Milliseconds since navigation of the first time each step happened (the browser test prints them).
const mark = (k, at = performance.now()) => { if (!(k in view.marks)) view.marks[k] = Math.round(at); };
mark('module');
// index.html's first picture (a 2D canvas) comes first: WebGL's start blocks the page for
// a while with software rendering. Not more than 2 s, if the server is slow to answer.
const early = window.voxregEarly ?? {};
await Promise.race([early.preview, new Promise((done) => setTimeout(done, 2000))]);
if (early.previewed) mark('preview drawn', early.previewed);

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
const mesh = new THREE.Mesh(new THREE.BufferGeometry(), material);
const wire = new THREE.LineSegments(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: 0x202020, transparent: true, opacity: 0.5 }));
const arrows = new THREE.LineSegments(new THREE.BufferGeometry(), new THREE.LineBasicMaterial({ color: 0x1060d0 }));
scene.add(mesh, wire, arrows);
mark('webgl');

let model = null; // { quads, faceGroups, faceColors, stair, groups, colors, visible, lo, hi }
// A coarser level of detail of the result, drawn instead of the surface while the server
// says it is the level shown: { level, frame, model, faces, quads, faceGroups, labels, stair, faceColors }
// (its faces are in the surface's groups; `stair` holds its positions).
let lod = null;
let result = null; // latest positions (Float32Array)
let normals = null, features = null;
let frame = -1, loadingModel = 0, fetching = false;

// Every API path with the session's token (index.html read it from the page's address).
const api = window.voxregEarly?.api ?? ((path) => path);

// A GET that gives up on a stalled connection after a few seconds and tries a fresh one.
async function get(url) {
  for (let attempt = 0; ; attempt++) {
    const abort = new AbortController();
    const timer = setTimeout(() => abort.abort(), 4000);
    try {
      const r = await fetch(api(url), { signal: abort.signal, cache: 'no-store' });
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

// The arrays of surface `id` (the one fetched as the page opened, if it is that one).
async function surface(id) {
  const first = await early.surface?.catch(() => null);
  if (first?.id === id) return first;
  const { r, body } = await get('/api/surface');
  if (!r.ok) throw new Error(JSON.parse(new TextDecoder().decode(body)).error);
  return early.unpack(body, Number(r.headers.get('X-Model')));
}

async function loadModel(s) {
  const id = s.model_id;
  loadingModel = id;
  const { quads, faceGroups, faceColors, stair, id: got } = await surface(id);
  if (loadingModel !== id) return;
  if (got !== id) { loadingModel = 0; return; } // replaced meanwhile: the next event loads it
  mark('arrays');
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < stair.length; i++) { lo[i % 3] = Math.min(lo[i % 3], stair[i]); hi[i % 3] = Math.max(hi[i % 3], stair[i]); }
  // A voxel edit of the surface shown keeps the view: the camera, and the groups' settings
  // where the groups are the same.
  const previous = s.edited && model && model.groups.map((x) => x.name).join('\n') === s.groups.map((x) => x.name).join('\n') ? model : null;
  lod = null;
  model = { id, quads, faceGroups, faceColors, stair, lo, hi,
    groups: s.groups, colors: s.groups.map((x) => x.color.slice()), visible: s.groups.map(() => true), custom: s.groups.map(() => false) };
  if (previous) Object.assign(model, { colors: previous.colors, visible: previous.visible, custom: previous.custom });
  result = stair; normals = null; features = null;
  if (s.edited) {
    // Drawn first as the shape shown before the edit (the server maps it onto the new surface).
    const { r, body } = await get('/api/positions');
    if (loadingModel !== id) return;
    if (r.ok && body.byteLength === stair.byteLength) result = new Float32Array(body);
  }
  view.modelId = id;
  $('name').textContent = s.name;
  listGroups();
  if (!s.edited) frameCamera();
  rebuild();
  mark(s.edited ? 'edit drawn' : 'staircase drawn');
  // WebGL's picture replaces index.html's in the next frame.
  requestAnimationFrame(() => $('preview')?.remove());
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
    vis.checked = model.visible[i];
    vis.onchange = () => { model.visible[i] = vis.checked; rebuild(); };
    const hex = '#' + model.colors[i].map((x) => x.toString(16).padStart(2, '0')).join('');
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

// The drawn geometry is indexed: one vertex per (surface vertex, face colour) of the visible
// faces, two triangles per quad. Its layout (which vertices, the index, the colours) changes
// with the visible groups and the colours; a streamed iterate refills only the positions and
// the normals, in place. Flat shading is the material's (per-triangle normals in the shader).
let layout = null; // { src: Uint32Array (drawn vertex -> surface vertex), faces: Uint32Array (drawn quads) }
const work = {};
function scratch(name, n) {
  if (!work[name] || work[name].length !== n) work[name] = new Float32Array(n);
  return work[name];
}

// A new layout for the visible faces and the current colours.
function buildLayout() {
  const d = lod ?? model, q = d.quads, m = q.length / 4, fg = d.faceGroups, fc = d.faceColors;
  const showFeatures = $('features').checked && features && !lod;
  let drawn = 0;
  for (let f = 0; f < m; f++) if (model.visible[fg[f]]) drawn++;
  const faces = new Uint32Array(drawn);
  for (let f = 0, j = 0; f < m; f++) if (model.visible[fg[f]]) faces[j++] = f;
  // A drawn vertex per surface vertex and colour: the first copy in `first`, others in `more`.
  const nv = d.stair.length / 3, first = new Int32Array(nv).fill(-1), firstKey = new Int32Array(nv), more = new Map();
  const src = [], keys = [], index = new Uint32Array(6 * drawn), corner = [0, 1, 2, 0, 2, 3];
  const packed = model.colors.map((c) => (c[0] << 16) | (c[1] << 8) | c[2]);
  for (let j = 0; j < drawn; j++) {
    const f = faces[j], g = fg[f];
    const key = showFeatures ? 0 : model.custom[g] ? packed[g] : (fc[3 * f] << 16) | (fc[3 * f + 1] << 8) | fc[3 * f + 2];
    const at = [0, 0, 0, 0];
    for (let k = 0; k < 4; k++) {
      const w = q[4 * f + k];
      let i = first[w];
      if (i < 0) { i = first[w] = src.length; firstKey[w] = key; src.push(w); keys.push(key); }
      else if (firstKey[w] !== key) {
        const mk = w * 16777216 + key;
        i = more.get(mk);
        if (i === undefined) { i = src.length; more.set(mk, i); src.push(w); keys.push(key); }
      }
      at[k] = i;
    }
    for (let k = 0; k < 6; k++) index[6 * j + k] = at[corner[k]];
  }
  const n = src.length, col = new Float32Array(3 * n), lin = (c) => Math.pow(c / 255, 2.2);
  for (let i = 0; i < n; i++) {
    const c = showFeatures ? ramp(features[src[i]]) : [lin(keys[i] >> 16), lin((keys[i] >> 8) & 255), lin(keys[i] & 255)];
    col[3 * i] = c[0]; col[3 * i + 1] = c[1]; col[3 * i + 2] = c[2];
  }
  // A fresh geometry (its buffers sized for this layout); the wireframe's edges share its positions.
  const g = new THREE.BufferGeometry();
  g.setIndex(new THREE.BufferAttribute(index, 1));
  const pos = new THREE.BufferAttribute(new Float32Array(3 * n), 3), nor = new THREE.BufferAttribute(new Float32Array(3 * n), 3);
  for (const a of [pos, nor]) a.setUsage(THREE.DynamicDrawUsage);
  g.setAttribute('position', pos);
  g.setAttribute('normal', nor);
  g.setAttribute('color', new THREE.BufferAttribute(col, 3));
  mesh.geometry.dispose();
  mesh.geometry = g;
  const edges = new Uint32Array(8 * drawn);
  for (let j = 0; j < drawn; j++) {
    const a = index[6 * j], b = index[6 * j + 1], c = index[6 * j + 2], d = index[6 * j + 5];
    edges.set([a, b, b, c, c, d, d, a], 8 * j);
  }
  const wg = new THREE.BufferGeometry();
  wg.setIndex(new THREE.BufferAttribute(edges, 1));
  wg.setAttribute('position', pos);
  wire.geometry.dispose();
  wire.geometry = wg;
  layout = { src: new Uint32Array(src), faces, sphere: false };
}

// Positions blended between the staircase and the latest result, with area-weighted
// vertex normals (the quads' diagonal cross products), into the drawn vertices.
function fillPositions() {
  const d = lod ?? model, t = parseFloat($('blend').value), st = d.stair, n = st.length;
  let x = lod ? lod.stair : result;
  if (t !== 1 && !lod) {
    x = scratch('x', n);
    for (let i = 0; i < n; i++) x[i] = st[i] + (result[i] - st[i]) * t;
  }
  const q = d.quads, m = q.length / 4, vn = scratch('vn', n);
  vn.fill(0);
  for (let f = 0; f < m; f++) {
    const a = 3 * q[4 * f], b = 3 * q[4 * f + 1], c = 3 * q[4 * f + 2], d = 3 * q[4 * f + 3];
    const u0 = x[c] - x[a], u1 = x[c + 1] - x[a + 1], u2 = x[c + 2] - x[a + 2];
    const v0 = x[d] - x[b], v1 = x[d + 1] - x[b + 1], v2 = x[d + 2] - x[b + 2];
    const nx = u1 * v2 - u2 * v1, ny = u2 * v0 - u0 * v2, nz = u0 * v1 - u1 * v0;
    vn[a] += nx; vn[a + 1] += ny; vn[a + 2] += nz;
    vn[b] += nx; vn[b + 1] += ny; vn[b + 2] += nz;
    vn[c] += nx; vn[c + 1] += ny; vn[c + 2] += nz;
    vn[d] += nx; vn[d + 1] += ny; vn[d + 2] += nz;
  }
  const g = mesh.geometry, pa = g.getAttribute('position'), na = g.getAttribute('normal');
  const pos = pa.array, nor = na.array, src = layout.src;
  for (let i = 0; i < src.length; i++) {
    const s = 3 * src[i], o = 3 * i;
    pos[o] = x[s]; pos[o + 1] = x[s + 1]; pos[o + 2] = x[s + 2];
    nor[o] = vn[s]; nor[o + 1] = vn[s + 1]; nor[o + 2] = vn[s + 2];
  }
  pa.needsUpdate = true;
  na.needsUpdate = true;
  // The bounds once per layout: the solve moves vertices by less than a voxel.
  if (!layout.sphere) {
    g.computeBoundingSphere();
    g.boundingSphere.radius += 1;
    wire.geometry.boundingSphere = g.boundingSphere;
    layout.sphere = true;
  }
  return x;
}

// Everything again: the layout (visible faces, colours) and the positions.
function rebuild() {
  layout = null;
  refresh();
}

// Redraws the current layout with the latest positions (what a streamed iterate needs).
function refresh() {
  if (!model) return;
  const started = performance.now();
  if (!layout) buildLayout();
  const x = fillPositions();
  const flat = !$('smooth').checked;
  if (material.flatShading !== flat) { material.flatShading = flat; material.needsUpdate = true; }
  wire.visible = $('wireframe').checked;
  arrows.visible = $('normals').checked && !!normals && !lod;
  if (arrows.visible) {
    const q = model.quads, faces = layout.faces;
    const step = Math.max(1, Math.floor(faces.length / 20000)), len = 0.6;
    const chosen = faces.filter((_, j) => j % step === 0), l = new Float32Array(6 * chosen.length);
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
  if (!layout) return; // nothing to draw yet
  const c = renderer.domElement, w = c.clientWidth, h = c.clientHeight;
  if (c.width !== Math.floor(w * renderer.getPixelRatio()) || c.height !== Math.floor(h * renderer.getPixelRatio())) {
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
  }
  renderer.render(scene, camera);
}
window.addEventListener('resize', draw);

// Frames: while a run is under way (or a re-solve was posted and none of its frames came
// yet), one request for the next frame is always out (/api/positions?after=FRAME, which
// the server answers as soon as a newer frame is published), so a streamed iterate is
// drawn without waiting for the state event that announces it.
let fetchedJob = 0, lastDrawnAt = 0;
// Frames drawn after a change was posted and before its reply named the run's job:
// [job, final, drawn at].
let drawnBeforeReply = [];
const framesWanted = () => {
  const s = view.state;
  return model && s.model_id === model.id && (frame !== s.frame || s.busy || (view.solveJob !== null && fetchedJob < view.solveJob && !s.error));
};
async function fetchPositions() {
  if (fetching) return;
  fetching = true;
  try {
    while (framesWanted()) {
      const asked = performance.now();
      const { r, body } = await get(`/api/positions?after=${frame}`);
      if (!r.ok) break;
      const got = parseInt(r.headers.get('X-Frame')), job = parseInt(r.headers.get('X-Job'));
      if (parseInt(r.headers.get('X-Model')) !== model?.id) break; // a new surface: onState loads it
      if (got === frame) continue; // none came yet: ask again
      view.lastFetchMs = Math.round(performance.now() - asked);
      const final = r.headers.get('X-Final') === '1';
      result = new Float32Array(body);
      [frame, fetchedJob] = [got, job];
      view.frames++;
      if (final) {
        await loadResult();
        // The feature field colours the vertices: a new layout.
        if ($('features').checked) layout = null;
      }
      drawFrame(job, final);
    }
  } finally {
    fetching = false;
  }
}

// Draws the frame just fetched (at once: it is what a change waits for).
function drawFrame(job, final) {
  // A frame of another result: the level drawn belonged to the one before.
  if (lod && lod.frame !== frame) { lod = null; layout = null; }
  refresh();
  lastDrawnAt = performance.now();
  mark(final ? 'result drawn' : 'iterate drawn');
  if (view.editPostedAt != null && view.editDrawnMs == null && view.state.edited) {
    view.editDrawnMs = lastDrawnAt - view.editPostedAt;
  }
  if (view.solveJob !== null && job >= view.solveJob) solveFrameDrawn(final, lastDrawnAt);
  // Before the re-solve's reply names its job, every frame drawn is kept: the first of
  // them that belongs to the posted run is its first frame.
  else if (view.solveAskedAt !== null && view.solveJob === null) drawnBeforeReply.push([job, final, lastDrawnAt]);
}

// A frame of the posted re-solve's run (or a later one's) was drawn: the first one's
// latency from the change, and whether it was a streamed iterate or already the result.
function solveFrameDrawn(final, at) {
  view.solveFrames++;
  if (view.solveAskedAt === null) return;
  if (view.solveLatencyMs === null) {
    view.solveLatencyMs = at - view.solveAskedAt;
    view.firstSolveFrameFinal = final;
  }
  if (final && view.solveDoneMs === null) view.solveDoneMs = at - view.solveAskedAt;
}

async function loadResult() {
  const [n, f, report] = await Promise.all([bytes('/api/normals'), get('/api/features'), get('/api/report')]);
  normals = new Float32Array(n);
  features = f.r.ok ? new Float32Array(f.body) : null;
  $('features').disabled = !features;
  const r = JSON.parse(new TextDecoder().decode(report.body));
  const rep = r.report, times = rep.stages;
  $('report').textContent = [r.summary,
    `normals: ${rep.normals.estimator}`,
    `stages (s): ${Object.entries(times).map(([k, v]) => `${k} ${v.toFixed(3)}`).join(', ')}`,
    `solves: ${rep.solves.length}`].join('\n');
}

// The voxel-art smoothness S is another view of the clamping margin (1 - 0.99 S, the
// library's Params::with_smoothness): the slider and the margin follow each other, and
// the slider's value is sent (the command line then says --smoothness) once it was moved.
let smoothnessSet = false;
function showSmoothness(s) {
  $('smoothness').value = s; $('smoothness-value').textContent = (+s).toFixed(2);
  $('smoothness-row').hidden = $('preset').value !== 'voxel-art';
}
// The panel's state is the library's Overrides: `clamp` is false (off), true (the
// preset's margin) or a margin; with `smoothness` set, the boxes come from it instead.
function setTuning(t) {
  $('preset').value = t.preset; $('estimator').value = t.normals;
  $('alpha').value = t.alpha; $('beta').value = t.beta; $('gamma').value = t.gamma; $('refine').value = t.refine;
  smoothnessSet = t.smoothness != null;
  const margin = typeof t.clamp === 'number' ? t.clamp : smoothnessSet ? +(1 - 0.99 * t.smoothness).toFixed(4) : t.clamp === true ? 0.01 : null;
  $('clamped').checked = margin !== null; if (margin !== null) $('clamp').value = margin;
  $('texture-aware').checked = t.texture_aware;
  showSmoothness(smoothnessSet ? t.smoothness : margin !== null ? Math.min(Math.max((1 - margin) / 0.99, 0.05), 1) : 1);
}

function tuning() {
  const smoothness = smoothnessSet && $('clamped').checked ? parseFloat($('smoothness').value) : null;
  const clamp = smoothness !== null ? null : $('clamped').checked ? parseFloat($('clamp').value) : false;
  return { preset: $('preset').value, normals: $('estimator').value, alpha: parseFloat($('alpha').value),
    beta: parseFloat($('beta').value), gamma: parseFloat($('gamma').value), refine: parseInt($('refine').value) || 0,
    clamp, smoothness, texture_aware: $('texture-aware').checked };
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
  fetchPositions();
  showLevels(s);
  syncLevel(s).catch((err) => showError(`the page could not show the level: ${err}`));
}

// Levels of detail: the control lists the levels with their face counts (once the server
// computed them for the result shown; 1/4^k of the faces is the target before), and the
// level shown, the server's `level_shown`, is fetched (/api/level?k=K) and drawn.
const levelPart = (k) => (k === 0 ? 'full' : `1/${4 ** k}`);
const count = (n) => n.toLocaleString('en');
function showLevels(s) {
  const select = $('level'), n = s.level_count ?? 1;
  while (select.options.length < n) select.add(new Option('', String(select.options.length)));
  for (let k = 0; k < n; k++) {
    const faces = k === 0 ? s.faces : s.levels?.[k]?.faces;
    select.options[k].text = faces != null ? `${levelPart(k)}: ${count(faces)} faces` : `${levelPart(k)} of the faces`;
  }
  if (document.activeElement !== select || select.value === String(s.level)) select.value = String(s.level);
  showLevelInfo();
}

// The level drawn and its face count, and what the chosen one waits for.
function showLevelInfo() {
  const s = view.state;
  if (!s || !model) return;
  const shown = lod ? lod.level : 0, faces = lod ? lod.faces : s.faces;
  let info = `shown: ${shown === 0 ? 'full surface' : `level ${shown} (${levelPart(shown)})`}, ${count(faces)} faces`;
  if (shown > 0 && s.levels_ms != null) info += ` (levels simplified in ${(s.levels_ms / 1000).toFixed(2)} s)`;
  if (s.level !== shown) info += s.busy ? `; level ${s.level} after the run` : s.levels_busy ? `; simplifying for level ${s.level}: ${Math.round(100 * (s.levels_progress || 0))}%` : '';
  $('level-info').textContent = info;
  // The downloads give the level shown.
  for (const f of ['glb', 'ply', 'obj']) $('get-' + f).href = api(`/api/download?format=${f}${shown ? `&level=${shown}` : ''}`);
}

let levelLoading = null;
async function syncLevel(s) {
  const want = s.level_shown ?? 0;
  if (want === 0) {
    if (lod) { lod = null; rebuild(); }
    if (view.state === s && s.model_id === model?.id) view.levelShown = { level: 0, faces: s.faces };
    showLevelInfo();
    return;
  }
  const key = `${s.model_id}/${s.frame}/${want}`;
  if ((lod && `${lod.model}/${lod.frame}/${lod.level}` === key) || levelLoading === key) return;
  levelLoading = key;
  let got;
  try {
    got = await get(`/api/level?k=${want}`);
  } finally {
    if (levelLoading === key) levelLoading = null;
  }
  const { r, body } = got;
  if (!r.ok) return; // replaced meanwhile: a newer state follows
  const now = view.state, frameOf = Number(r.headers.get('X-Frame')), modelOf = Number(r.headers.get('X-Model'));
  if (now.level_shown !== want || now.frame !== frameOf || modelOf !== model?.id) return;
  lod = { level: want, frame: frameOf, model: modelOf, ...unpackLevel(body) };
  rebuild();
  view.levelShown = { level: want, faces: lod.faces };
  showLevelInfo();
}

// The arrays of /api/level (levels.rs, level_bytes).
function unpackLevel(body) {
  const [faces, vertices] = new Uint32Array(body, 0, 2);
  const q = 8, g = q + 16 * faces, l = g + 4 * faces, p = l + 8 * faces, c = p + 12 * vertices;
  return { faces, quads: new Uint32Array(body, q, 4 * faces), faceGroups: new Uint32Array(body, g, faces),
    labels: new Uint32Array(body, l, 2 * faces), stair: new Float32Array(body, p, 3 * vertices), faceColors: new Uint8Array(body, c, 3 * faces) };
}

// The stream index.html opened; its latest event, if one came while this module loaded.
const events = window.voxregEarly?.events ?? new EventSource(api('/api/events'));
events.onmessage = (e) => onState(JSON.parse(e.data)).catch((err) => showError(`the page could not update: ${err}`));
if (window.voxregEarly?.last) events.onmessage(window.voxregEarly.last);
mark('module done');

// A change re-solves at once (a running solve is replaced): inputs fire 'change' when a
// value is committed, not on every keystroke or slider step.
$('tuning').addEventListener('change', async (e) => {
  view.solveAskedAt = performance.now(); view.solveLatencyMs = null; view.solveDoneMs = null; view.solveFrames = 0; view.solveJob = null; view.solves++;
  drawnBeforeReply = [];
  if (e.target.id === 'preset') {
    const r = await fetch(api('/api/preset?name=' + $('preset').value));
    if (r.ok) setTuning(await r.json());
  }
  const r = await fetch(api('/api/solve'), { method: 'POST', body: JSON.stringify(tuning()) });
  if (!r.ok) { view.solveAskedAt = null; showError((await r.json()).error); return; }
  view.solveJob = (await r.json()).job;
  showError(null);
  // Its first frames may have been drawn before the reply came (a busy server answers
  // the post late, not the frames).
  for (const [job, final, at] of drawnBeforeReply) if (job >= view.solveJob) solveFrameDrawn(final, at);
  drawnBeforeReply = [];
  fetchPositions();
});
$('tuning').addEventListener('submit', (e) => e.preventDefault());
$('level').addEventListener('change', async () => {
  const r = await fetch(api('/api/level'), { method: 'POST', body: JSON.stringify({ level: parseInt($('level').value) }) });
  if (!r.ok) showError((await r.json()).error); else showError(null);
});
for (const id of ['blend', 'wireframe', 'smooth', 'normals', 'clip', 'clip-axis', 'clip-at']) $(id).addEventListener('input', refresh);
$('features').addEventListener('input', rebuild);
$('copy').onclick = async () => {
  $('command').select();
  try { await navigator.clipboard.writeText($('command').value); } catch { document.execCommand('copy'); }
};

// Voxel edits: shift+click on a face removes the voxel behind it, alt+click adds the voxel
// in front of it (a click, not a drag of the camera).
const raycaster = new THREE.Raycaster();
let pressed = null;
renderer.domElement.addEventListener('pointerdown', (e) => { pressed = { x: e.clientX, y: e.clientY }; });
renderer.domElement.addEventListener('pointerup', async (e) => {
  const click = pressed && Math.hypot(e.clientX - pressed.x, e.clientY - pressed.y) < 4;
  pressed = null;
  if (!click || !(e.shiftKey || e.altKey) || !model || !layout) return;
  if (lod || view.state?.level) { showError('voxel edits apply to the full surface: choose its level (full) first'); return; }
  const r = renderer.domElement.getBoundingClientRect();
  raycaster.setFromCamera(new THREE.Vector2(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1), camera);
  const clip = $('clip').checked ? clipPlane : null;
  const hit = raycaster.intersectObject(mesh).find((h) => !clip || clip.distanceToPoint(h.point) >= 0);
  if (!hit) return;
  const face = layout.faces[Math.floor(hit.faceIndex / 2)];
  view.editPostedAt = performance.now(); view.editDrawnMs = null; view.edits++;
  const d = raycaster.ray.direction;
  const body = { model: model.id, face, add: e.altKey && !e.shiftKey, toward: [d.x, d.y, d.z], tuning: tuning() };
  const reply = await fetch(api('/api/edit'), { method: 'POST', body: JSON.stringify(body) });
  if (!reply.ok) { view.editPostedAt = null; showError((await reply.json()).error); } else showError(null);
});

async function open(file) {
  $('status').textContent = `opening ${file.name}…`;
  const r = await fetch(api('/api/open?name=' + encodeURIComponent(file.name)), { method: 'POST', body: file });
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
