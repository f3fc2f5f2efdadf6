// The web viewer in a real browser during a real scan: facescan-server and facescan-agent (synthetic Kinect, live
// 30 Hz) and `facescan view` run as processes on loopback in a private domain; Debian's headless chromium opens
// the page, waits for the mesh, takes two screenshots a few snapshots apart, checks that the face is drawn and
// that the picture changed, that the console shows no error, downloads the GLB and reads it back with three.js'
// glTF reader. Run by viewer_browser_test.sh (which skips when the browser cannot start).
// Usage: node viewer_browser_test.mjs OUT_DIR DOMAIN   (env: FACESCAN_SERVER, FACESCAN_AGENT, FACESCAN_CLI,
//        FACESCAN_WEB_NODE_MODULES, CHROMIUM)
import assert from 'node:assert/strict';
import fs from 'node:fs';
import { createRequire } from 'node:module';
import path from 'node:path';
import { pathToFileURL } from 'node:url';
import { ddsArgs, launchChromium, sleep, start, startViewer, stop, tail } from './scan_processes.mjs';

const [outDir, domain] = process.argv.slice(2);
const env = process.env;
const modules = env.FACESCAN_WEB_NODE_MODULES;
const require = createRequire(path.join(modules, 'noop.js'));
const playwright = require('playwright-core');
fs.mkdirSync(outDir, { recursive: true });
const t0 = Date.now();
const log = (text) => console.log(`[${((Date.now() - t0) / 1000).toFixed(1)} s] ${text}`);

const session = `browser-${process.pid}`;
const server = start('server', env.FACESCAN_SERVER, [...ddsArgs(domain), '--data-dir', path.join(outDir, 'data'),
  '--snapshot-hz', '2'], outDir);
const agent = start('agent', env.FACESCAN_AGENT, [...ddsArgs(domain), '--session', session, '--source',
  'synthetic:frames=600,subject=builtin,seed=3', '--rate', 'real', '--wait-for-server', '30'], outDir);
const { viewer, url } = await startViewer(env.FACESCAN_CLI, domain, outDir);
log(`viewer at ${url}`);

const browser = await launchChromium(playwright, env.CHROMIUM);
let failed = true;
try {
  const page = await browser.newPage({ viewport: { width: 1100, height: 700 }, acceptDownloads: true });
  const problems = [];
  page.on('console', (message) => { if (message.type() === 'error') problems.push(`console: ${message.text()}`); });
  page.on('pageerror', (error) => problems.push(`page error: ${error.message}`));
  page.on('requestfailed', (request) => problems.push(`request failed: ${request.url()} ${request.failure()?.errorText}`));

  await page.goto(`${url}?session=${session}`);
  const webgl = await page.evaluate(() => {
    const gl = document.createElement('canvas').getContext('webgl2');
    const info = gl && gl.getExtension('WEBGL_debug_renderer_info');
    return gl ? gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER) : null;
  });
  log(`WebGL renderer: ${webgl}`);
  assert.ok(webgl, 'WebGL is not available in this chromium (SwiftShader flags?)');

  // Pixels of the 3D view's centre half (the WebGL canvas keeps its drawing buffer): how many differ from the
  // background, and a copy to compare later pictures with.
  const sample = () => page.evaluate(() => {
    const source = document.getElementById('canvas');
    const copy = document.createElement('canvas');
    copy.width = source.width; copy.height = source.height;
    const ctx = copy.getContext('2d');
    ctx.drawImage(source, 0, 0);
    const x = Math.floor(source.width / 4), y = Math.floor(source.height / 4);
    const { data } = ctx.getImageData(x, y, Math.floor(source.width / 2), Math.floor(source.height / 2));
    const bg = [0x16, 0x18, 0x1d];
    let face = 0;
    const pixels = [];
    for (let i = 0; i < data.length; i += 4) {
      const differs = Math.abs(data[i] - bg[0]) + Math.abs(data[i + 1] - bg[1]) + Math.abs(data[i + 2] - bg[2]) > 24;
      if (differs) face++;
      pixels.push(data[i], data[i + 1], data[i + 2]);
    }
    return { share: face / (data.length / 4), pixels };
  });
  const drawn = () => page.evaluate(() => window.facescanStats.drawn);

  await page.waitForFunction(() => window.facescanStats.drawn >= 1, null, { timeout: 40000 });
  const first = await drawn();
  await sleep(300);
  await page.screenshot({ path: path.join(outDir, 'viewer-1.png') });
  const a = await sample();
  log(`snapshot drawn (${first}); face covers ${(100 * a.share).toFixed(1)}% of the view's centre`);
  await page.waitForFunction((n) => window.facescanStats.drawn >= n + 3, first, { timeout: 30000 });
  await sleep(300);
  await page.screenshot({ path: path.join(outDir, 'viewer-2.png') });
  const b = await sample();
  let changed = 0;
  for (let i = 0; i < a.pixels.length; i += 3) {
    const d = Math.abs(a.pixels[i] - b.pixels[i]) + Math.abs(a.pixels[i + 1] - b.pixels[i + 1]) + Math.abs(a.pixels[i + 2] - b.pixels[i + 2]);
    if (d > 24) changed++;
  }
  const changedShare = changed / (a.pixels.length / 3);
  log(`3 snapshots later: face covers ${(100 * b.share).toFixed(1)}%, ${(100 * changedShare).toFixed(1)}% of the centre changed`);
  assert.ok(a.share > 0.1 && b.share > 0.1, `the face is not drawn: ${a.share}, ${b.share} of the centre`);
  assert.ok(changedShare > 0.005, `the picture did not change between snapshots (${changedShare})`);

  const progress = await page.evaluate(() => ({
    state: document.getElementById('state').textContent,
    integrated: document.getElementById('integrated').textContent,
    server: document.getElementById('server').textContent,
    rows: document.querySelectorAll('#sessions tbody tr').length,
  }));
  log(`progress: ${JSON.stringify(progress)}`);
  assert.match(progress.state, /SCANNING|LOST|FINISHED/);
  assert.ok(Number(progress.integrated.replace(/\D/g, '')) > 0, 'no frames integrated shown');
  assert.notEqual(progress.server, '–', 'the session\'s server is not shown');
  assert.equal(progress.rows, 1);

  // The GLB download, read back with three.js' own glTF reader.
  const [download] = await Promise.all([page.waitForEvent('download', { timeout: 30000 }),
    page.click('.downloads button[data-format="glb"]')]);
  const glbPath = path.join(outDir, download.suggestedFilename());
  await download.saveAs(glbPath);
  const glb = fs.readFileSync(glbPath);
  assert.equal(glb.toString('latin1', 0, 4), 'glTF');
  const { GLTFLoader } = await import(pathToFileURL(path.join(modules, 'three/examples/jsm/loaders/GLTFLoader.js')));
  const gltf = await new GLTFLoader().parseAsync(glb.buffer.slice(glb.byteOffset, glb.byteOffset + glb.length), '');
  const meshes = [];
  gltf.scene.traverse((object) => { if (object.isMesh) meshes.push(object); });
  assert.equal(meshes.length, 1);
  const geometry = meshes[0].geometry;
  log(`GLB ${download.suggestedFilename()}: ${glb.length} bytes, ${geometry.attributes.position.count} vertices, ` +
      `${geometry.index.count / 3} triangles, colours: ${Boolean(geometry.attributes.color)}`);
  assert.ok(geometry.attributes.position.count > 1000);
  assert.ok(geometry.attributes.color, 'the GLB has no vertex colours (COLOR_0)');

  const stats = await page.evaluate(() => window.facescanStats.snapshots);
  fs.writeFileSync(path.join(outDir, 'stats.json'), JSON.stringify(stats, null, 1));
  const latencies = stats.map((s) => s.latency_ms).sort((x, y) => x - y);
  log(`${stats.length} snapshots drawn; latency median ${latencies[Math.floor(latencies.length / 2)].toFixed(0)} ms, ` +
      `decode median ${stats.map((s) => s.decode_ms).sort((x, y) => x - y)[Math.floor(stats.length / 2)].toFixed(1)} ms`);
  assert.deepEqual(problems, [], `the browser reported problems:\n${problems.join('\n')}`);
  failed = false;
} finally {
  await browser.close();
  await stop(viewer);
  await stop(agent);
  await stop(server);
  if (failed) for (const child of [viewer, agent, server]) console.log(`--- ${child.logPath}\n${tail(child)}`);
}
log('passed');
