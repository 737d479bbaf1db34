// Times the first picture of `voxreg view`, interleaving two builds (a benchmark, not a test):
//   node tests/browser/first-picture.mjs --voxreg A [--against B] [--input FILE] [--runs N]
// Each run starts `voxreg view INPUT` (default data/chr_army1.vox), opens the page in a fresh
// headless Chromium (software WebGL) and prints the milliseconds from opening the page to the
// first frame of positions drawn, and the page's own steps (`voxregView.marks`, where the page
// has them). With --against, the runs alternate A, B, A, B... so that load drifts hit both.
import { spawn } from 'node:child_process';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

const root = resolve(dirname(fileURLToPath(import.meta.url)), '../..');
const arg = (name, fallback) => {
  const i = process.argv.indexOf(name);
  return i > 0 ? process.argv[i + 1] : fallback;
};
const builds = [arg('--voxreg', join(root, 'target/release/voxreg')), arg('--against', null)].filter(Boolean).map((b) => resolve(b));
const input = resolve(root, arg('--input', 'data/chr_army1.vox'));
const runs = parseInt(arg('--runs', '6'));
const browserPath = process.env.CHROMIUM ?? '/usr/bin/chromium';

async function once(voxreg) {
  const server = spawn(voxreg, ['view', input], { stdio: ['ignore', 'ignore', 'pipe'] });
  let log = '';
  const url = await new Promise((res, rej) => {
    server.stderr.on('data', (d) => {
      log += d;
      const m = log.match(/http:\/\/127\.0\.0\.1:\d+\//);
      if (m) res(m[0]);
    });
    server.on('exit', (code) => rej(new Error(`voxreg view exited (${code}): ${log}`)));
  });
  const browser = await chromium.launch({
    executablePath: browserPath,
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'],
  });
  try {
    const page = await browser.newPage({ viewport: { width: 1200, height: 720 } });
    const t0 = Date.now();
    await page.goto(url);
    await page.waitForFunction(() => window.voxregView?.frames > 0, null, { timeout: 60000, polling: 5 });
    const ms = Date.now() - t0;
    return { ms, marks: await page.evaluate(() => window.voxregView.marks ?? null) };
  } finally {
    await browser.close();
    server.kill();
  }
}

const times = builds.map(() => []);
for (let r = 0; r < runs; r++) {
  for (const [i, b] of builds.entries()) {
    const { ms, marks } = await once(b);
    times[i].push(ms);
    console.log(`${b}: first frame drawn ${ms} ms ${marks ? JSON.stringify(marks) : ''}`);
  }
}
for (const [i, b] of builds.entries()) {
  const t = times[i].slice().sort((x, y) => x - y);
  console.log(`${b}: min ${t[0]} median ${t[Math.floor(t.length / 2)]} max ${t[t.length - 1]} ms over ${t.length} runs`);
}
