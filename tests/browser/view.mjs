// The browser test of `voxreg view` (run by .ci/run after the release build):
//   node tests/browser/view.mjs [--voxreg PATH] [--screenshot PATH] [--input FILE] [--measure]
// Starts `voxreg view INPUT` (default data/chr_army1.vox), drives headless Chromium
// (/usr/bin/chromium, or $CHROMIUM) through playwright-core, and checks that
//   1. the page shows the model (pixels other than the background): first its staircase
//      drawn without WebGL, within FIRST_PICTURE_MS, then WebGL's,
//   2. a parameter change re-solves and a new mesh arrives, and the level-of-detail control
//      shows a coarser level of the result (fewer faces, said on the page) and the full one again,
//   3. the GLB download passes the Khronos validator (tools/gltf-validate),
//   4. a corrupt dropped file shows the reader's error and the server keeps serving,
//   5. the voxel-art smoothness slider re-solves with --smoothness in the command line,
//   6. a shift+click on the model removes a voxel: a new surface, re-solved,
//   7. on bunny-128 (opened from the page), a parameter change re-solves from the last
//      result: fewer iterations, and a streamed iterate before the final result, leaving
//      the server and drawn within bounds (the best of three changes);
// and saves a screenshot (default docs/figures/view.png). Prints the timings it saw.
// With --measure, it only prints the timings (no screenshot, no time bounds).
import { execFileSync } from 'node:child_process';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { apiUrl, arg, launchBrowser, root, startView } from './common.mjs';

const measure = process.argv.includes('--measure');
const voxreg = resolve(arg('--voxreg', process.env.VOXREG ?? join(root, 'target/release/voxreg')));
const input = resolve(root, arg('--input', 'data/chr_army1.vox'));
const screenshot = measure ? null : resolve(root, arg('--screenshot', 'docs/figures/view.png'));
// Milliseconds from opening the page (docs/performance.md, "Viewer", has the figures). The
// first picture's target is 1 s: its bound is what the 2-core machine met at load 9 with
// margin, and what the WebGL picture (the first picture before) often misses there; WebGL's
// picture only has to come (a stalled request waited 4 s for the page's retry).
const FIRST_PICTURE_MS = 1500;
const WEBGL_PICTURE_MS = 10000;
// bunny-128, a parameter change: its first streamed iterate leaves the server, and is drawn
// on the page, within these (the best of three re-solves), counted from the change. The
// target is 200 ms drawn; these bounds are what the 2-core machine met at load 9 with margin,
// and what a re-solve that rebuilt the surface or its solver, a page that waits for a state
// event to ask for the frame, or a replaced run that finishes its stage, misses there.
const SERVER_FIRST_ITERATE_MS = 500;
const PAGE_FIRST_ITERATE_MS = 1000;

function fail(message) {
  console.error(`browser test FAILED: ${message}`);
  process.exitCode = 1;
  throw new Error(message);
}
function check(ok, message) { if (!ok) fail(message); }

// The server: its URL is the first line it prints.
const { server, url } = await startView(voxreg, input, { stdout: 'inherit', timeoutMs: 30000 });

const work = mkdtempSync(join(tmpdir(), 'voxreg-view-'));
const browser = await launchBrowser();
try {
  const page = await browser.newPage({ viewport: { width: 1200, height: 720 }, acceptDownloads: true });
  const pageErrors = [];
  page.on('pageerror', (e) => pageErrors.push(String(e)));

  // Pixels that differ from the background on the canvas shown: the first picture while it
  // is there, else WebGL's (the page keeps its drawing buffer).
  const drawnPixels = () => page.evaluate(() => {
    const c = document.getElementById('preview') ?? document.getElementById('canvas');
    const t = Object.assign(document.createElement('canvas'), { width: c.width, height: c.height });
    const g = t.getContext('2d');
    g.drawImage(c, 0, 0);
    const d = g.getImageData(0, 0, t.width, t.height).data;
    let n = 0;
    for (let i = 0; i < d.length; i += 4) if (Math.abs(d[i] - 244) + Math.abs(d[i + 1] - 244) + Math.abs(d[i + 2] - 244) > 30) n++;
    return n;
  });

  // 1. First picture: the page's own marks (milliseconds from opening it), waited for
  // without reading pixels meanwhile (a read stalls a page that starts WebGL), then the
  // pixels of the picture shown.
  await page.goto(url);
  const marks = () => page.evaluate(() => ({ ...window.voxregView?.marks, preview: window.voxregEarly?.previewed }));
  await page.waitForFunction(() => window.voxregEarly?.previewed || window.voxregView?.marks['staircase drawn'],
    null, { timeout: 60000, polling: 'raf' });
  const shown = await drawnPixels();
  const first = await marks();
  const firstPicture = Math.round(Math.min(first.preview ?? Infinity, first['staircase drawn'] ?? Infinity));
  check(shown > 1000, `the page shows no model (${shown} non-background pixels): ${pageErrors.join('; ')}`);
  await page.waitForFunction(() => window.voxregView?.marks['staircase drawn'], null, { timeout: 60000 });
  const webgl = (await marks())['staircase drawn'];
  check(await drawnPixels() > 1000, `WebGL shows no model: ${pageErrors.join('; ')}`);
  console.log(`first picture: ${firstPicture} ms after opening the page (${shown} model pixels), WebGL's ${webgl} ms; ` +
    `page steps (ms): ${JSON.stringify(await marks())}`);
  // Surfaces of up to 200,000 quads (index.html's MAX_QUADS) get the picture without WebGL.
  if ((await page.evaluate(() => window.voxregView.state.faces)) <= 200000) check(first.preview !== undefined, 'no first picture without WebGL');
  if (!measure) {
    check(firstPicture <= FIRST_PICTURE_MS, `the first picture took ${firstPicture} ms (at most ${FIRST_PICTURE_MS})`);
    check(webgl <= WEBGL_PICTURE_MS, `WebGL's picture took ${webgl} ms (at most ${WEBGL_PICTURE_MS})`);
  }
  const t0 = Date.now() - Math.round(await page.evaluate(() => performance.now()));
  await page.waitForFunction(() => window.voxregView.state?.final && !window.voxregView.state.busy, null, { timeout: 120000 });
  console.log(`first result: ${Date.now() - t0} ms after opening the page`);

  // 2. A parameter change: a new mesh arrives.
  const before = await page.evaluate(() => window.voxregView.state.frame);
  await page.fill('#gamma', '1.5');
  await page.dispatchEvent('#gamma', 'change');
  await page.waitForFunction((f) => {
    const v = window.voxregView;
    return v.solveLatencyMs !== null && v.state.final && !v.state.busy && v.state.frame > f && v.state.tuning.gamma === 1.5;
  }, before, { timeout: 120000 });
  const solved = await page.evaluate(() => ({ latency: window.voxregView.solveLatencyMs, frames: window.voxregView.solveFrames,
    finalFirst: window.voxregView.firstSolveFrameFinal, first: window.voxregView.state.first_frame_ms, total: window.voxregView.state.total_ms }));
  console.log(`re-solve: first frame on the page after ${solved.latency.toFixed(0)} ms (${solved.finalFirst ? 'the final result' : 'a streamed iterate'}; ` +
    `server: first iterate ${solved.first?.toFixed(0)} ms, done ${solved.total?.toFixed(0)} ms), ${solved.frames} frames`);
  check((await page.inputValue('#command')).includes('--gamma 1.5'), 'the command line does not follow the panel');
  check(await drawnPixels() > 1000, 'the re-solved model is not drawn');

  // 2b. Levels of detail: level 1 chosen in the control, then the full surface again.
  {
    const full = await page.evaluate(() => window.voxregView.state.faces);
    const infoFull = await page.textContent('#level-info');
    check(infoFull.includes(full.toLocaleString('en')), `the level shown does not give the full face count ${full}: "${infoFull}"`);
    const frame = await page.evaluate(() => window.voxregView.state.frame);
    const asked = Date.now();
    await page.selectOption('#level', '1');
    await page.waitForFunction(() => window.voxregView.levelShown?.level === 1, null, { timeout: 60000 });
    const shownMs = Date.now() - asked;
    const level = await page.evaluate(() => ({ shown: window.voxregView.levelShown, state: window.voxregView.state }));
    const info = await page.textContent('#level-info');
    const options = await page.$$eval('#level option', (o) => o.map((x) => x.textContent));
    check(level.state.frame === frame, 'choosing a level re-solved');
    check(level.shown.faces === level.state.levels[1].faces && level.shown.faces < full,
      `level 1 drew ${level.shown.faces} faces (the server's level 1: ${level.state.levels[1].faces}, full: ${full})`);
    check(info !== infoFull && info.includes(level.shown.faces.toLocaleString('en')), `the page says "${info}" for level 1`);
    check(options.length === 4 && options.every((o, k) => o.includes(level.state.levels[k].faces.toLocaleString('en'))),
      `the control does not list each level's faces: ${options.join(' | ')}`);
    check(await drawnPixels() > 1000, 'level 1 is not drawn');
    console.log(`levels of detail: ${options.join(' | ')}; level 1 drawn ${shownMs} ms after the choice ("${info}")`);
    await page.selectOption('#level', '0');
    await page.waitForFunction(() => window.voxregView.levelShown?.level === 0, null, { timeout: 60000 });
    const back = await page.textContent('#level-info');
    check(back.includes(full.toLocaleString('en')), `back to the full surface, the page says "${back}"`);
  }

  if (!measure) {
    // 3. The GLB download, validated.
    const [download] = await Promise.all([page.waitForEvent('download'), page.click('#get-glb')]);
    const glb = join(work, download.suggestedFilename());
    await download.saveAs(glb);
    check(glb.endsWith('.glb'), `download named ${glb}`);
    const validator = join(root, 'tools/gltf-validate/validate.mjs');
    try {
      console.log(execFileSync('node', [validator, glb], { encoding: 'utf8' }).trim());
    } catch (e) {
      fail(`the downloaded GLB does not validate: ${e.stdout}`);
    }

    // The screenshot the README shows: the result with its wireframe.
    await page.check('#wireframe');
    await page.waitForTimeout(100);
    await page.screenshot({ path: screenshot });
    await page.uncheck('#wireframe');
    console.log(`screenshot: ${screenshot}`);

    // 4. A corrupt file dropped on the page: the reader's error, and the server serves on.
    await page.evaluate(() => {
      const dt = new DataTransfer();
      dt.items.add(new File([new Uint8Array([86, 79, 88, 32, 1, 2, 3])], 'corrupt.vox'));
      document.dispatchEvent(new DragEvent('drop', { dataTransfer: dt, bubbles: true, cancelable: true }));
    });
    await page.waitForSelector('#error:not([hidden])', { timeout: 30000 });
    const message = await page.textContent('#error');
    check(message.includes('corrupt.vox'), `the error does not name the file: ${message}`);
    console.log(`corrupt file: "${message}"`);
    const state = await (await page.request.get(apiUrl(url, '/api/state'))).json();
    // Without the session's token (another user, another site), the API refuses.
    const untokened = await page.request.get(new URL('/api/state', url).href);
    check(untokened.status() === 403, `the state is served without the token (${untokened.status()})`);
    check(state.name === 'chr_army1.vox' || state.name === input.split('/').pop(), `the surface changed: ${state.name}`);
    check(await drawnPixels() > 1000, 'the model is gone after the error');
  }
  // 5. The voxel-art smoothness slider (a .vox input): a re-solve with smaller boxes.
  if ((await page.evaluate(() => window.voxregView.state.tuning.preset)) === 'voxel-art') {
  check(await page.isVisible('#smoothness'), 'no smoothness slider for a voxel-art input');
  const framed = await page.evaluate(() => window.voxregView.state.frame);
  await page.fill('#smoothness', '0.3');
  await page.dispatchEvent('#smoothness', 'change');
  await page.waitForFunction((f) => {
    const s = window.voxregView.state;
    return s.final && !s.busy && s.frame > f && s.tuning.smoothness === 0.3;
  }, framed, { timeout: 120000 });
  const command = await page.inputValue('#command');
  check(command.includes('--smoothness 0.3') && !command.includes('--clamp'), `the command line: ${command}`);
  check(await drawnPixels() > 1000, 'the smoothed model is not drawn');
  console.log(`smoothness 0.3: ${command}`);
  }

  // 6. A voxel edit: shift+click on the model removes the voxel behind the face clicked;
  // the server rebuilds the surface and re-solves from the shape shown.
  {
    const before = await page.evaluate(() => ({ id: window.voxregView.modelId, faces: window.voxregView.state.faces, edits: window.voxregView.edits }));
    const box = await page.locator('#canvas').boundingBox();
    for (const [dx, dy] of [[0, 0], [0, 0.05], [0, -0.05], [0.05, 0], [-0.05, 0], [0, 0.15], [0, -0.15]]) {
      await page.keyboard.down('Shift');
      await page.mouse.click(box.x + box.width * (0.5 + dx), box.y + box.height * (0.5 + dy));
      await page.keyboard.up('Shift');
      if (await page.evaluate((n) => window.voxregView.edits > n, before.edits)) break;
    }
    check(await page.evaluate((n) => window.voxregView.edits > n, before.edits), 'no shift+click hit the model');
    await page.waitForFunction((id) => {
      const v = window.voxregView;
      return v.modelId > id && v.state.edited && v.state.final && !v.state.busy && v.editDrawnMs != null;
    }, before.id, { timeout: 60000 });
    const edited = await page.evaluate(() => ({ state: window.voxregView.state, drawn: window.voxregView.editDrawnMs }));
    check(edited.state.error === null, `the edit failed: ${edited.state.error}`);
    check(edited.state.faces !== before.faces, `the edit left ${edited.state.faces} faces`);
    check(await drawnPixels() > 1000, 'the edited model is not drawn');
    console.log(`voxel edit: ${before.faces} -> ${edited.state.faces} faces; new surface built in ${edited.state.edit_ms?.toFixed(0)} ms, ` +
      `first frame on the page after ${edited.drawn.toFixed(0)} ms, solved in ${edited.state.total_ms?.toFixed(0)} ms (warm: ${edited.state.warm})`);
  }

  // 7. bunny-128, opened from the page: a parameter change starts from the last result.
  const bunny = resolve(root, 'data/bunny-128.vol');
  const opened = await page.evaluate(() => window.voxregView.modelId);
  await page.setInputFiles('#open', bunny);
  await page.waitForFunction((id) => {
    const v = window.voxregView;
    return v.modelId > id && v.state.final && !v.state.busy && v.state.name === 'bunny-128.vol';
  }, opened, { timeout: 120000 });
  check(!(await page.isVisible('#smoothness')), 'the smoothness slider shows for the default preset');
  const cold = await page.evaluate(() => window.voxregView.state);
  // Three gamma changes: the first runs to its end (warm, fewer iterations), the next two
  // only until their first frame is drawn (each replaces the run before it).
  const resolves = [];
  let gamma = cold.tuning.gamma;
  for (let k = 0; k < 3; k++) {
    const posted = await page.evaluate(() => window.voxregView.solves);
    gamma *= 1.2;
    await page.fill('#gamma', String(gamma));
    await page.dispatchEvent('#gamma', 'change');
    const whole = k === 0 || k === 2;
    // Frames of this change's run only (the page counts the frames of its job).
    await page.waitForFunction(([n, whole]) => {
      const v = window.voxregView;
      return v.solves > n && v.solveLatencyMs !== null && (!whole || (v.state.final && !v.state.busy && v.state.job >= v.solveJob));
    }, [posted, whole], { timeout: 120000 });
    const r = await page.evaluate(() => ({ state: window.voxregView.state, latency: window.voxregView.solveLatencyMs,
      finalFirst: window.voxregView.firstSolveFrameFinal, frames: window.voxregView.solveFrames, rebuild: window.voxregView.lastRebuildMs }));
    // The server's figure of this run: its state once its first iterate left.
    r.server = r.state.first_frame_ms;
    resolves.push(r);
    console.log(`bunny-128 re-solve ${k + 1}: first frame on the page after ${r.latency.toFixed(0)} ms ` +
      `(${r.finalFirst ? 'the final result' : 'a streamed iterate'}; server: first iterate ${r.server?.toFixed(0)} ms; ` +
      `last frame built in ${r.rebuild?.build} ms, drawn in ${r.rebuild?.draw} ms)` +
      (whole ? `; ${r.state.iterations} iterations (warm: ${r.state.warm}) in ${r.state.total_ms.toFixed(0)} ms` : ''));
  }
  const warm = resolves[0];
  console.log(`bunny-128: cold ${cold.iterations} iterations in ${cold.total_ms.toFixed(0)} ms; re-solve ${warm.state.iterations} iterations`);
  check(warm.state.warm === true, 'the bunny re-solve did not start from the last result');
  check(warm.state.iterations < cold.iterations, `the warm re-solve took ${warm.state.iterations} iterations, the cold run ${cold.iterations}`);
  // Two of three, like the timings below: on a loaded machine the page may draw a short
  // run's result before any of its iterates.
  const streamed = resolves.filter((r) => !r.finalFirst).length;
  check(streamed >= 2, `a streamed iterate before the final result in ${streamed} of 3 re-solves`);
  // The best of three, against the machine's noise.
  const best = (f) => Math.min(...resolves.map(f));
  console.log(`bunny-128: first iterate at best ${best((r) => r.server).toFixed(0)} ms on the server, ` +
    `${best((r) => r.latency).toFixed(0)} ms on the page`);
  if (!measure) {
    check(best((r) => r.server) <= SERVER_FIRST_ITERATE_MS,
      `the first iterate left the server after ${best((r) => r.server).toFixed(0)} ms at best (at most ${SERVER_FIRST_ITERATE_MS})`);
    check(best((r) => r.latency) <= PAGE_FIRST_ITERATE_MS,
      `the first iterate was drawn after ${best((r) => r.latency).toFixed(0)} ms at best (at most ${PAGE_FIRST_ITERATE_MS})`);
  }
  check(await drawnPixels() > 1000, 'the bunny is not drawn');

  check(pageErrors.length === 0, `errors on the page: ${pageErrors.join('; ')}`);
  console.log('browser test passed');
} finally {
  await browser.close();
  server.kill();
  rmSync(work, { recursive: true, force: true });
}
