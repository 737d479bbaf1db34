// What the browser scripts share: the repository root, their command-line options, a
// `voxreg view` server and a headless Chromium with software WebGL.
import { spawn } from 'node:child_process';
import { dirname, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { chromium } from 'playwright-core';

export const root = resolve(dirname(fileURLToPath(import.meta.url)), '../..');

/** The value after `name` on the command line, or `fallback`. */
export function arg(name, fallback) {
  const i = process.argv.indexOf(name);
  return i > 0 ? process.argv[i + 1] : fallback;
}

/**
 * Starts `voxreg view input` and resolves to `{ server, url }` once the server prints its
 * address (with the session's token: `http://127.0.0.1:PORT/?token=...`); rejects if it exits first or, with `timeoutMs`, prints none in time. `stdout` is
 * the child's standard output ('ignore' or 'inherit').
 */
export async function startView(voxreg, input, { stdout = 'ignore', timeoutMs = null } = {}) {
  const server = spawn(voxreg, ['view', input], { stdio: ['ignore', stdout, 'pipe'] });
  let log = '';
  const url = await new Promise((res, rej) => {
    server.stderr.on('data', (d) => {
      log += d;
      const m = log.match(/http:\/\/127\.0\.0\.1:\d+\/\?token=[0-9a-f]+/);
      if (m) res(m[0]);
    });
    server.on('exit', (code) => rej(new Error(`voxreg view exited (${code}): ${log}`)));
    if (timeoutMs !== null) setTimeout(() => rej(new Error(`no URL from voxreg view: ${log}`)), timeoutMs);
  });
  return { server, url };
}

/** The address of an API `path` of the server at `url` (the page's), with its token. */
export function apiUrl(url, path) {
  const page = new URL(url);
  const target = new URL(path, page);
  target.searchParams.set('token', page.searchParams.get('token'));
  return target.href;
}

/** Headless Chromium (/usr/bin/chromium, or $CHROMIUM) with software WebGL. */
export function launchBrowser() {
  return chromium.launch({
    executablePath: process.env.CHROMIUM ?? '/usr/bin/chromium',
    args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'],
  });
}
