// The web viewer in a real browser during a real scan: facescan-server and facescan-agent (synthetic Kinect, live
// 30 Hz) and `facescan view` run as processes on loopback in a private domain; Debian's headless chromium opens
// the page, waits for the mesh, takes two screenshots a few snapshots apart, checks that the face is drawn and
// that the picture changed, that the console shows no error, that the status says what to do while the subject is
// out of view and that the scan comes back, downloads the GLB and reads it back with three.js' glTF reader, and once
// the scan has finished, that the page draws the finished model with its texture (a screenshot of it). Run by
// viewer_browser_test.sh (which skips when the browser cannot start).
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
  // Some 7 s in, the subject walks out of view for a second and comes back turned: the page must show
  // the advice while the face is lost, and the scan must come back by itself.
  'synthetic:scenario=gap,gap_start=200,frames=600,subject=builtin,seed=3', '--rate', 'real',
  '--wait-for-server', '30'], outDir);
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

  // Every state and status line the page shows, in order (the loss may come while the checks below run).
  await page.addInitScript(() => {
    window.testStatusLines = [];
    document.addEventListener('DOMContentLoaded', () => {
      const [state, detail] = ['state', 'detail'].map((id) => document.getElementById(id));
      new MutationObserver(() => {
        const line = `${state.textContent}: ${detail.textContent}`;
        if (window.testStatusLines.at(-1) !== line) window.testStatusLines.push(line);
      }).observe(detail, { childList: true, characterData: true, subtree: true });
    });
  });
  await page.goto(`${url}?session=${session}`);
  const lostShot = page.waitForFunction(() => document.getElementById('state').textContent === 'LOST', null,
    { timeout: 90000, polling: 50 }).then(() => page.screenshot({ path: path.join(outDir, 'viewer-lost.png') }))
    .catch((error) => error);  // kept for the check below, not an unhandled rejection meanwhile
  const webgl = await page.evaluate(() => {
    const gl = document.createElement('canvas').getContext('webgl2');
    const info = gl && gl.getExtension('WEBGL_debug_renderer_info');
    return gl ? gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER) : null;
  });
  log(`WebGL renderer: ${webgl}`);
  assert.ok(webgl, 'WebGL is not available in this chromium (SwiftShader flags?)');

  // Pixels of the 3D view's centre half (the WebGL canvas keeps its drawing buffer), kept in the page under a
  // name: the share that differs from the background, and later the share that differs between two samples.
  const sample = (name) => page.evaluate((key) => {
    const source = document.getElementById('canvas');
    const copy = document.createElement('canvas');
    copy.width = source.width; copy.height = source.height;
    const ctx = copy.getContext('2d');
    ctx.drawImage(source, 0, 0);
    const x = Math.floor(source.width / 4), y = Math.floor(source.height / 4);
    const { data } = ctx.getImageData(x, y, Math.floor(source.width / 2), Math.floor(source.height / 2));
    (window.testSamples ||= {})[key] = data;
    let face = 0;
    for (let i = 0; i < data.length; i += 4) {
      if (Math.abs(data[i] - 0x16) + Math.abs(data[i + 1] - 0x18) + Math.abs(data[i + 2] - 0x1d) > 24) face++;
    }
    return { name: key, share: face / (data.length / 4) };
  }, name);
  const differs = (p, q) => page.evaluate(([k1, k2]) => {
    const x = window.testSamples[k1], y = window.testSamples[k2];
    let n = 0;
    for (let i = 0; i < x.length; i += 4) {
      if (Math.abs(x[i] - y[i]) + Math.abs(x[i + 1] - y[i + 1]) + Math.abs(x[i + 2] - y[i + 2]) > 24) n++;
    }
    return n / (x.length / 4);
  }, [p.name, q.name]);
  const drawn = () => page.evaluate(() => window.facescanStats.drawn);

  await page.waitForFunction(() => window.facescanStats.drawn >= 1, null, { timeout: 40000 });
  const first = await drawn();
  await sleep(300);
  await page.screenshot({ path: path.join(outDir, 'viewer-1.png') });
  const a = await sample('first');
  // Read after the sample, so the picture holds at most this many triangles.
  const firstTriangles = await page.evaluate(() => window.facescanStats.snapshots.at(-1).triangles);
  log(`snapshot drawn (${first}); face covers ${(100 * a.share).toFixed(1)}% of the view's centre`);
  // The picture must change once the model has: a loaded server may send snapshots of a model that has barely
  // grown (it integrates few frames between them), so a count of snapshots alone proves nothing.
  await page.waitForFunction(([n, t]) => {
    const { drawn, snapshots } = window.facescanStats;
    return drawn >= n + 3 && snapshots.at(-1).triangles >= 1.15 * t;
  }, [first, firstTriangles], { timeout: 60000 });
  await sleep(300);
  await page.screenshot({ path: path.join(outDir, 'viewer-2.png') });
  const b = await sample('second');
  const [later, laterTriangles] = await page.evaluate(() => [window.facescanStats.drawn,
    window.facescanStats.snapshots.at(-1).triangles]);
  const changedShare = await differs(a, b);
  log(`${later - first} snapshots later (${firstTriangles} -> ${laterTriangles} triangles): face covers ` +
      `${(100 * b.share).toFixed(1)}%, ${(100 * changedShare).toFixed(1)}% of the centre changed`);
  assert.ok(a.share > 0.1 && b.share > 0.1, `the face is not drawn: ${a.share}, ${b.share} of the centre`);
  assert.ok(changedShare > 0.005, `the picture did not change between snapshots (${changedShare})`);

  // The view's controls, by a person's gestures: wireframe, turning (drag), zooming (wheel), reset view.
  const settle = () => sleep(250);
  await page.check('#wireframe'); await settle();
  const wire = await sample('wire');
  await page.screenshot({ path: path.join(outDir, 'viewer-wireframe.png') });
  await page.uncheck('#wireframe'); await settle();
  const box = await page.locator('#canvas').boundingBox();
  const cx = box.x + box.width / 2, cy = box.y + box.height / 2;
  const before = await sample('before');
  await page.mouse.move(cx, cy); await page.mouse.down();
  await page.mouse.move(cx + 250, cy, { steps: 10 }); await page.mouse.up(); await settle();
  const turned = await sample('turned');
  const turnedDirection = await page.evaluate(() => window.facescanStats.viewDirection());
  await page.screenshot({ path: path.join(outDir, 'viewer-turned.png') });
  await page.click('#reset-view'); await settle();
  const reset = await sample('reset');
  const resetDirection = await page.evaluate(() => window.facescanStats.viewDirection());
  await page.mouse.move(cx, cy); await page.mouse.wheel(0, -600); await settle();
  const zoomed = await sample('zoomed');
  await page.click('#reset-view'); await settle();
  const [dWire, dTurned] = [await differs(before, wire), await differs(before, turned)];
  const fmt = (v) => v.map((x) => x.toFixed(2)).join(', ');
  log(`controls: wireframe changed ${(100 * dWire).toFixed(0)}%, turning ${(100 * dTurned).toFixed(0)}% ` +
      `(view from ${fmt(turnedDirection)}; after reset ${fmt(resetDirection)}); ` +
      `zoom in: face ${(100 * reset.share).toFixed(0)}% -> ${(100 * zoomed.share).toFixed(0)}%`);
  assert.ok(dWire > 0.05, 'the wireframe toggle changed nothing');
  assert.ok(dTurned > 0.15 && turnedDirection[2] < 0.95, 'dragging did not turn the face');
  assert.ok(resetDirection[2] > 0.999, 'reset view did not bring back the front view');
  assert.ok(zoomed.share > reset.share + 0.05, 'the wheel did not zoom in');

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

  // The face lost for a second: the page said what to do, then the scan came back by itself.
  const lostError = await lostShot;
  assert.ok(!(lostError instanceof Error), `the page never showed the scan as LOST: ${lostError?.message}`);
  await page.waitForFunction(() => {
    const lines = window.testStatusLines;
    const lost = lines.findIndex((line) => line.startsWith('LOST: face lost: come back in front of the camera'));
    return lost >= 0 && lines.slice(lost).some((line) => line.startsWith('SCANNING'));
  }, null, { timeout: 60000 });
  const statusLines = await page.evaluate(() => window.testStatusLines);
  log(`status lines shown: ${statusLines.length}, around the loss: ${JSON.stringify(statusLines.filter(
    (line, i, all) => line.startsWith('LOST') || (i > 0 && all[i - 1].startsWith('LOST'))).slice(0, 4))}`);

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
  // Vertex colours while scanning; the texture once finished (the recording may have ended by now).
  assert.ok(geometry.attributes.color || (meshes[0].material.map && geometry.attributes.uv),
    'the GLB has neither vertex colours (COLOR_0) nor a texture');

  // The recording ends and the server finishes the scan: the page draws the finished model with its texture.
  await page.waitForFunction((id) => window.facescanStats.textured?.session === id, session, { timeout: 90000 });
  await page.click('#reset-view'); await settle();
  await page.screenshot({ path: path.join(outDir, 'viewer-textured.png') });
  const textured = await page.evaluate(() => window.facescanStats.textured);
  const texturedView = await sample('textured');
  log(`finished model drawn textured: ${textured.width} x ${textured.height} texture, ${textured.vertices} ` +
      `vertices, ${(textured.bytes / 1024 / 1024).toFixed(1)} MB fetched and shown in ${textured.ms.toFixed(0)} ms; ` +
      `face covers ${(100 * texturedView.share).toFixed(1)}% of the centre`);
  assert.ok(textured.width >= 64 && textured.height >= 64, `no texture: ${JSON.stringify(textured)}`);
  assert.ok(texturedView.share > 0.1, 'the textured face is not drawn');

  // A URL naming a session nobody scans: the page says so (and offers the list).
  const lost = await browser.newPage();
  lost.on('pageerror', (error) => problems.push(`page error (unknown session page): ${error.message}`));
  await lost.goto(`${url}?session=nobody-${process.pid}`);
  await lost.waitForFunction(() => !document.getElementById('message').hidden, null, { timeout: 10000 });
  const text = await lost.textContent('#message');
  log(`unknown session page: "${text}"`);
  assert.match(text, /Unknown session 'nobody-\d+'/);
  await lost.close();

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
