// Times the first picture of `voxreg view`, interleaving builds (a benchmark, not a test):
//   node tests/browser/first-picture.mjs --voxreg A [--against B] [--input FILE] [--runs N] [--running]
// Each run starts `voxreg view INPUT` (default data/chr_army1.vox), opens the page in a fresh
// headless Chromium (software WebGL) and prints, in milliseconds from opening the page (the
// page's own marks, `voxregView.marks`): the first picture (the staircase drawn without WebGL
// where the page has it, else WebGL's), WebGL's picture, and the first frame of positions
// drawn. With --running, the browser first shows a blank page for a second (a browser
// already running, as a user's is, rather than one starting with the page). With
// --against, the runs alternate A, B, A, B... so that load drifts hit both.
import { join, resolve } from 'node:path';
import { arg, launchBrowser, root, startView } from './common.mjs';

const builds = [arg('--voxreg', join(root, 'target/release/voxreg')), arg('--against', null)].filter(Boolean).map((b) => resolve(b));
const input = resolve(root, arg('--input', 'data/chr_army1.vox'));
const runs = parseInt(arg('--runs', '6'));
const running = process.argv.includes('--running');

async function once(voxreg) {
  const { server, url } = await startView(voxreg, input);
  const browser = await launchBrowser();
  try {
    const page = await browser.newPage({ viewport: { width: 1200, height: 720 } });
    if (running) {
      await page.goto('about:blank');
      await page.waitForTimeout(1000);
    }
    await page.goto(url);
    // Polled once per animation frame: reading pixels meanwhile would stall the page.
    await page.waitForFunction(() => {
      const m = window.voxregView?.marks;
      return m && m['staircase drawn'] && (m['iterate drawn'] || m['result drawn']);
    }, null, { timeout: 60000, polling: 'raf' });
    const marks = await page.evaluate(() => ({ ...window.voxregView.marks, preview: window.voxregEarly?.previewed }));
    const webgl = marks['staircase drawn'];
    const frame = marks['iterate drawn'] ?? marks['result drawn'];
    return { first: Math.round(Math.min(marks.preview ?? Infinity, webgl)), webgl, frame, marks };
  } finally {
    await browser.close();
    server.kill();
  }
}

const times = builds.map(() => []);
for (let r = 0; r < runs; r++) {
  for (const [i, b] of builds.entries()) {
    const t = await once(b);
    times[i].push(t);
    console.log(`${b}: first picture ${t.first} ms, WebGL's ${t.webgl} ms, first frame ${t.frame} ms ${JSON.stringify(t.marks)}`);
  }
}
const summary = (xs) => {
  const t = xs.slice().sort((x, y) => x - y);
  return `min ${t[0]} median ${t[Math.floor(t.length / 2)]} max ${t[t.length - 1]}`;
};
for (const [i, b] of builds.entries()) {
  const t = times[i];
  console.log(`${b} over ${t.length} runs: first picture ${summary(t.map((x) => x.first))}; ` +
    `WebGL's ${summary(t.map((x) => x.webgl))}; first frame ${summary(t.map((x) => x.frame))} ms`);
}
