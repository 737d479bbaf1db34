// Times a parameter change in `voxreg view` against a whole CLI run (a benchmark, not a test):
//   node tests/browser/re-solve.mjs [--voxreg PATH] [--input FILE] [--runs N] [--replace MS]
// Starts `voxreg view INPUT` (default data/bunny-128.vol), opens it in headless Chromium
// (software WebGL), waits for the first result, then N times (default 6) changes gamma
// (x1.2 and /1.2 alternately) on the page and waits for the converged result. Prints for
// each change, in milliseconds from the change: its first streamed iterate drawn on the
// page and leaving the server, its result drawn on the page and done on the server, and
// its iterations. Between changes it runs `voxreg regularize INPUT -o OUT.glb` (a whole CLI
// run, the viewer idle) and prints its wall time. With --replace MS, each change is made
// MS milliseconds after another one, which it replaces while it runs.
import { spawnSync } from 'node:child_process';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { arg, launchBrowser, root, startView } from './common.mjs';

const voxreg = resolve(arg('--voxreg', join(root, 'target/release/voxreg')));
const input = resolve(root, arg('--input', 'data/bunny-128.vol'));
const runs = parseInt(arg('--runs', '6'));
const replace = arg('--replace', null);

const { server, url } = await startView(voxreg, input);
const work = mkdtempSync(join(tmpdir(), 'voxreg-re-solve-'));
const browser = await launchBrowser();
const rows = { first: [], server: [], done: [], total: [], cli: [] };
try {
  const page = await browser.newPage({ viewport: { width: 1200, height: 720 } });
  await page.goto(url);
  await page.waitForFunction(() => window.voxregView?.state?.final && !window.voxregView.state.busy, null, { timeout: 120000 });
  let gamma = await page.evaluate(() => window.voxregView.state.tuning.gamma);
  const change = async (g) => {
    await page.fill('#gamma', String(g));
    await page.dispatchEvent('#gamma', 'change');
  };
  for (let k = 0; k < runs; k++) {
    const t = performance.now();
    const cli = spawnSync(voxreg, ['regularize', input, '-q', '-o', join(work, 'out.glb')]);
    if (cli.status !== 0) throw new Error(`voxreg regularize: ${cli.stderr}`);
    rows.cli.push(performance.now() - t);
    gamma *= k % 2 === 0 ? 1.2 : 1 / 1.2;
    if (replace !== null) {
      await change(gamma * 1.1);
      await page.waitForTimeout(parseInt(replace));
    }
    const posted = await page.evaluate(() => window.voxregView.solves);
    await change(gamma);
    await page.waitForFunction((n) => {
      const v = window.voxregView;
      return v.solves > n && v.solveDoneMs != null && !v.state.busy && v.state.job >= v.solveJob;
    }, posted, { timeout: 120000, polling: 50 });
    const r = await page.evaluate(() => {
      const v = window.voxregView;
      return { first: v.solveLatencyMs, server: v.state.first_frame_ms, done: v.solveDoneMs, total: v.state.total_ms, iterations: v.state.iterations };
    });
    for (const key of ['first', 'server', 'done', 'total']) rows[key].push(r[key]);
    console.log(`change ${k + 1}: first iterate drawn ${r.first.toFixed(0)} ms (server ${r.server.toFixed(0)} ms), ` +
      `result drawn ${r.done.toFixed(0)} ms (server ${r.total.toFixed(0)} ms), ${r.iterations} iterations; ` +
      `CLI run before it ${rows.cli[k].toFixed(0)} ms`);
  }
} finally {
  await browser.close();
  server.kill();
  rmSync(work, { recursive: true, force: true });
}
const summary = (xs) => {
  const t = xs.slice().sort((x, y) => x - y);
  return `min ${t[0].toFixed(0)} median ${t[Math.floor(t.length / 2)].toFixed(0)} max ${t[t.length - 1].toFixed(0)}`;
};
console.log(`first iterate drawn: ${summary(rows.first)}; leaving the server: ${summary(rows.server)}`);
console.log(`result drawn: ${summary(rows.done)}; done on the server: ${summary(rows.total)}; CLI run: ${summary(rows.cli)} ms`);
