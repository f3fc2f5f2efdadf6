// The web viewer's figures, every process on this machine over loopback DDS in a private domain:
//  1. a live scan (30 Hz synthetic Kinect) watched by one headless chromium: snapshot-to-screen latency (the
//     snapshot's created_ns, stamped by the server when it publishes, to the browser's next animation frame after
//     drawing it), split into wire (to the WebSocket message) and decode + draw; Draco decode ms in the browser;
//     the page's transfer size on first load;
//  2. the scan's fps with 0 and with N watchers: a recording (--rate max: every frame processed, as fast as the
//     server can), its fps from the server's summary.json, with no viewer, with the viewer and N WebSocket clients
//     (the viewer's own cost), and with the viewer and N chromium pages (the browsers share these 2 cores with the
//     server, so this also counts their rendering); rounds alternate the variants.
// Usage (through viewer_bench.sh): node viewer_bench.mjs OUT_DIR DOMAIN [FRAMES=300] [ROUNDS=2] [WATCHERS=10]
import fs from 'node:fs';
import { createRequire } from 'node:module';
import os from 'node:os';
import path from 'node:path';
import { ddsArgs, launchChromium, sleep, start, startViewer, stop } from '../integration/browser/scan_processes.mjs';

const [outDir, domain, framesArg = '300', roundsArg = '2', watchersArg = '10'] = process.argv.slice(2);
const frames = Number(framesArg), rounds = Number(roundsArg), watchers = Number(watchersArg);
const env = process.env;
const require = createRequire(path.join(env.FACESCAN_WEB_NODE_MODULES, 'noop.js'));
const playwright = require('playwright-core');
fs.mkdirSync(outDir, { recursive: true });
const load = () => os.loadavg().map((x) => x.toFixed(2)).join(' ');
const quantile = (values, q) => {
  const v = [...values].sort((a, b) => a - b);
  return v.length ? v[Math.min(v.length - 1, Math.floor(q * v.length))] : NaN;
};
const results = {};

async function waitForFile(file, timeoutMs) {
  const deadline = Date.now() + timeoutMs;
  while (Date.now() < deadline) { if (fs.existsSync(file)) return true; await sleep(100); }
  return false;
}

// --- 1. latency, decode, transfer size ----------------------------------------------------------------------------
{
  const dir = path.join(outDir, 'live');
  fs.mkdirSync(dir, { recursive: true });
  const session = `bench-live-${process.pid}`;
  const server = start('server', env.FACESCAN_SERVER, [...ddsArgs(domain), '--data-dir', path.join(dir, 'data')], dir);
  const { viewer, url } = await startViewer(env.FACESCAN_CLI, domain, dir);
  const browser = await launchChromium(playwright, env.CHROMIUM);
  const page = await browser.newPage({ viewport: { width: 1100, height: 700 } });
  await page.goto(`${url}?session=${session}`, { waitUntil: 'networkidle' });
  const transfer = await page.evaluate(() => {
    const entries = [...performance.getEntriesByType('navigation'), ...performance.getEntriesByType('resource')];
    return { requests: entries.length, bytes: entries.reduce((sum, e) => sum + e.transferSize, 0),
             body_bytes: entries.reduce((sum, e) => sum + e.encodedBodySize, 0),
             files: entries.map((e) => [e.name.replace(/^https?:\/\/[^/]+/, ''), e.transferSize]) };
  });
  const agent = start('agent', env.FACESCAN_AGENT, [...ddsArgs(domain), '--session', session, '--source',
    `synthetic:frames=${frames},subject=scan,seed=1`, '--rate', 'real', '--wait-for-server', '30'], dir);
  await new Promise((resolve) => agent.once('exit', resolve));
  await waitForFile(path.join(dir, 'data', session, 'summary.json'), 30000);
  await sleep(1500);  // the final snapshot
  const snaps = await page.evaluate(() => window.facescanStats.snapshots);
  const software = await page.evaluate(() => window.facescanStats.softwareRenderer);
  fs.writeFileSync(path.join(dir, 'snapshots.json'), JSON.stringify(snaps, null, 1));
  await browser.close();
  await stop(viewer);
  await stop(server);
  const lat = snaps.map((s) => s.latency_ms);
  results.live = {
    snapshots: snaps.length, load: load(),
    latency_ms: { p50: quantile(lat, 0.5), p95: quantile(lat, 0.95), max: Math.max(...lat) },
    wire_ms_p50: quantile(snaps.map((s) => s.received_ms - s.created_ms), 0.5),
    decode_ms: { p50: quantile(snaps.map((s) => s.decode_ms), 0.5), p95: quantile(snaps.map((s) => s.decode_ms), 0.95) },
    draw_ms_p50: quantile(snaps.map((s) => s.drawn_ms - s.received_ms - s.decode_ms), 0.5),
    render_ms_p50: quantile(snaps.map((s) => s.render_ms), 0.5),
    snapshot_kb_p50: quantile(snaps.map((s) => s.bytes / 1024), 0.5),
    triangles_last: snaps.length ? snaps[snaps.length - 1].triangles : 0,
    transfer, software_renderer: software,
  };
  console.log(`live scan, ${frames} frames at 30 Hz, 1 browser (${software ? 'software WebGL: no multisampling' : 'GPU'}; ` +
              `load ${results.live.load}):`);
  console.log(`  snapshots drawn ${snaps.length}; snapshot-to-screen latency p50 ${results.live.latency_ms.p50.toFixed(0)} ms, ` +
              `p95 ${results.live.latency_ms.p95.toFixed(0)} ms, max ${results.live.latency_ms.max.toFixed(0)} ms`);
  console.log(`  of which server->browser (DDS, viewer, WebSocket) p50 ${results.live.wire_ms_p50.toFixed(1)} ms, ` +
              `Draco decode p50 ${results.live.decode_ms.p50.toFixed(1)} ms (p95 ${results.live.decode_ms.p95.toFixed(1)}), ` +
              `draw to next frame p50 ${results.live.draw_ms_p50.toFixed(1)} ms ` +
              `(of which WebGL render call p50 ${results.live.render_ms_p50.toFixed(1)} ms, SwiftShader)`);
  console.log(`  snapshots ${results.live.snapshot_kb_p50.toFixed(0)} kB Draco (p50), ${results.live.triangles_last} triangles in the last`);
  console.log(`  first load: ${transfer.requests} requests, ${(transfer.bytes / 1024).toFixed(0)} kB transferred ` +
              `(${(transfer.body_bytes / 1024).toFixed(0)} kB bodies), before the first snapshot`);
}

// --- 2. fps with 0 and N watchers -------------------------------------------------------------------------------
async function recording(variant, round) {
  const dir = path.join(outDir, `${variant}-${round}`);
  fs.mkdirSync(dir, { recursive: true });
  const session = `bench-${variant}-${round}-${process.pid}`;
  const server = start('server', env.FACESCAN_SERVER, [...ddsArgs(domain), '--data-dir', path.join(dir, 'data')], dir);
  let viewer = null, browser = null;
  const sockets = [];
  if (variant !== 'none') {
    const started = await startViewer(env.FACESCAN_CLI, domain, dir);
    viewer = started.viewer;
    if (variant === 'ws') {
      for (let i = 0; i < watchers; ++i) {
        const ws = new WebSocket(started.url.replace('http', 'ws') + 'ws');
        ws.binaryType = 'arraybuffer';
        ws.onopen = () => ws.send(`follow ${session}`);
        ws.received = 0;
        ws.onmessage = (e) => { if (typeof e.data !== 'string') ws.received++; };
        sockets.push(ws);
      }
    } else {
      browser = await launchChromium(playwright, env.CHROMIUM);
      const context = await browser.newContext({ viewport: { width: 1000, height: 650 } });
      for (let i = 0; i < watchers; ++i) await (await context.newPage()).goto(`${started.url}?session=${session}`);
    }
  }
  const t0 = Date.now();
  const agent = start('agent', env.FACESCAN_AGENT, [...ddsArgs(domain), '--session', session, '--source',
    `synthetic:frames=${frames},subject=scan,seed=1`, '--rate', 'max', '--wait-for-server', '30'], dir);
  await new Promise((resolve) => agent.once('exit', resolve));
  const summaryPath = path.join(dir, 'data', session, 'summary.json');
  await waitForFile(summaryPath, 60000);
  const wall_s = (Date.now() - t0) / 1000;
  const summary = JSON.parse(fs.readFileSync(summaryPath, 'utf8'));
  // The server's CPU time (user + system, clock ticks of 10 ms): what watching adds to the server's own work,
  // unlike fps, which on a shared machine also counts what the watchers take from it.
  const stat = fs.readFileSync(`/proc/${server.pid}/stat`, 'utf8').split(') ')[1].split(' ');
  const server_cpu_s = (Number(stat[11]) + Number(stat[12])) / 100;
  let drawn = null;
  if (browser) {
    drawn = [];
    for (const page of browser.contexts()[0].pages()) drawn.push(await page.evaluate(() => window.facescanStats.drawn));
    await browser.close();
  }
  const wsReceived = sockets.map((ws) => ws.received);
  for (const ws of sockets) ws.close();
  if (viewer) await stop(viewer);
  await stop(server);
  return { fps: summary.fps, wall_s, load: load(), drawn, wsReceived, cpu_ms_per_frame: 1000 * server_cpu_s / frames };
}

const variants = ['none', 'ws', 'browsers'];
const fps = Object.fromEntries(variants.map((v) => [v, []]));
const cpu = Object.fromEntries(variants.map((v) => [v, []]));
console.log(`\nrecording of ${frames} frames (--rate max: every frame, as fast as the server goes), ${rounds} rounds:`);
for (let round = 1; round <= rounds; ++round) {
  for (const variant of round % 2 ? variants : [...variants].reverse()) {
    const r = await recording(variant, round);
    fps[variant].push(r.fps);
    cpu[variant].push(r.cpu_ms_per_frame);
    const watchersText = variant === 'none' ? 'no viewer' : variant === 'ws' ? `viewer + ${watchers} WebSocket clients`
      : `viewer + ${watchers} chromium pages`;
    const extra = r.drawn ? `, snapshots drawn per page ${r.drawn.join('/')}` :
      r.wsReceived.length ? `, snapshots received per client ${r.wsReceived.join('/')}` : '';
    console.log(`  round ${round} ${watchersText.padEnd(32)} fps ${r.fps.toFixed(2)}, server CPU ${r.cpu_ms_per_frame.toFixed(1)} ms/frame ` +
                `(wall ${r.wall_s.toFixed(1)} s, load ${r.load})${extra}`);
  }
}
const mean = (v) => v.reduce((a, b) => a + b, 0) / v.length;
results.fps = Object.fromEntries(variants.map((v) => [v, mean(fps[v])]));
results.server_cpu_ms_per_frame = Object.fromEntries(variants.map((v) => [v, mean(cpu[v])]));
console.log(`  mean fps: none ${results.fps.none.toFixed(2)}, ${watchers} ws ${results.fps.ws.toFixed(2)} ` +
            `(${(100 * results.fps.ws / results.fps.none).toFixed(0)}%), ${watchers} browsers ${results.fps.browsers.toFixed(2)} ` +
            `(${(100 * results.fps.browsers / results.fps.none).toFixed(0)}%)`);
const c = results.server_cpu_ms_per_frame;
console.log(`  mean server CPU per frame: none ${c.none.toFixed(1)} ms, ${watchers} ws ${c.ws.toFixed(1)} ms, ` +
            `${watchers} browsers ${c.browsers.toFixed(1)} ms`);
console.log(JSON.stringify(results));
