// Real facescan processes for the browser test and the viewer benchmark: facescan-server, facescan-agent (the
// synthetic Kinect) and `facescan view` on the loopback profile in the caller's private DDS domain, each with its
// output in a log file, all stopped (SIGTERM, then SIGKILL) when the caller is done or dies.
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import path from 'node:path';

const children = new Set();
function stopAll() { for (const child of children) { try { child.kill('SIGKILL'); } catch { /* gone */ } } }
process.on('exit', stopAll);
for (const signal of ['SIGINT', 'SIGTERM']) process.on(signal, () => { stopAll(); process.exit(130); });

export function start(name, program, args, dir) {
  const log = fs.openSync(path.join(dir, `${name}.log`), 'w');
  const child = spawn(program, args, { stdio: ['ignore', log, log] });
  child.logPath = path.join(dir, `${name}.log`);
  children.add(child);
  child.on('exit', () => children.delete(child));
  return child;
}

export async function stop(child) {
  if (child.exitCode !== null || child.signalCode !== null) return;
  const exited = new Promise((resolve) => child.once('exit', resolve));
  child.kill('SIGTERM');
  const timer = setTimeout(() => child.kill('SIGKILL'), 5000);
  await exited;
  clearTimeout(timer);
}

export const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// Waits for `pattern` in a child's log; the match, or throws with the log's tail after `timeoutMs`.
export async function waitForLog(child, pattern, timeoutMs) {
  const deadline = Date.now() + timeoutMs;
  while (Date.now() < deadline) {
    const match = fs.readFileSync(child.logPath, 'utf8').match(pattern);
    if (match) return match;
    if (child.exitCode !== null) break;
    await sleep(50);
  }
  throw new Error(`no ${pattern} in ${child.logPath}:\n${tail(child)}`);
}

export const tail = (child) => fs.readFileSync(child.logPath, 'utf8').split('\n').slice(-15).join('\n');

// The DDS options every program gets.
export const ddsArgs = (domain) => ['--profile', 'loopback', '--domain', String(domain)];

// `facescan view --port 0` and the URL it prints.
export async function startViewer(cli, domain, dir, name = 'view') {
  const viewer = start(name, cli, ['view', '--port', '0', ...ddsArgs(domain)], dir);
  const [, url] = await waitForLog(viewer, /serving (http:\/\/\S+)/, 15000);
  return { viewer, url };
}

// Headless Debian chromium through playwright-core (never a browser of playwright's own). WebGL runs on
// SwiftShader, Chromium's software renderer: the flags that work on a machine without a GPU.
export const chromiumArgs = [
  '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--use-gl=angle',
  '--disable-quic', '--no-first-run', '--disable-background-networking', '--disable-component-update',
  '--disable-sync', '--disable-dev-shm-usage',
];
export async function launchChromium(playwright, executablePath) {
  return playwright.chromium.launch({ executablePath, headless: true, args: chromiumArgs, timeout: 30000 });
}
