// The pictures of docs/images, from a real scan (run by deploy/docs-images.sh, which checks the tools first):
// the viewer part-way through a live scan, and the finished face from three sides in the same viewer.
// Usage: node docs_images.mjs WORK_DIR DOMAIN OUT_DIR   (env: FACESCAN_SERVER, FACESCAN_AGENT, FACESCAN_CLI,
//        FACESCAN_WEB_NODE_MODULES, CHROMIUM)
import fs from 'node:fs';
import { createRequire } from 'node:module';
import path from 'node:path';
import { ddsArgs, launchChromium, sleep, start, startViewer, stop } from '../tests/integration/browser/scan_processes.mjs';

const [work, domain, out] = process.argv.slice(2);
const env = process.env;
const require = createRequire(path.join(env.FACESCAN_WEB_NODE_MODULES, 'noop.js'));
const playwright = require('playwright-core');
const log = (text) => console.log(`docs-images: ${text}`);

const session = 'face-demo';
const frames = 240;  // 8 s at 30 Hz: the gentle turn, left and right
const server = start('server', env.FACESCAN_SERVER, [...ddsArgs(domain), '--data-dir', path.join(work, 'data'),
  '--snapshot-hz', '2'], work);
const agent = start('agent', env.FACESCAN_AGENT, [...ddsArgs(domain), '--session', session, '--source',
  `synthetic:scenario=gentle,frames=${frames},subject=auto,seed=1`, '--rate', 'real', '--wait-for-server', '30'], work);
const { viewer, url } = await startViewer(env.FACESCAN_CLI, domain, work);
const browser = await launchChromium(playwright, env.CHROMIUM);
try {
  const page = await browser.newPage({ viewport: { width: 1000, height: 600 } });
  await page.goto(`${url}?session=${session}`);

  // Mid-scan: a few snapshots in, while the head turns.
  await page.waitForFunction(() => window.facescanStats.drawn >= 6, null, { timeout: 60000 });
  await sleep(300);
  await page.screenshot({ path: path.join(out, 'viewer-mid-scan.png') });
  log(`viewer-mid-scan.png: ${await page.textContent('#state')}, ${await page.textContent('#integrated')} integrated`);

  // Finished: the last snapshot stays in the view; turn it with the mouse as a person would (OrbitControls turns
  // 2 pi per canvas height of drag), to 50 degrees each side.
  await page.waitForFunction(() => document.getElementById('state').textContent === 'FINISHED', null,
    { timeout: 120000, polling: 200 });
  await sleep(1500);  // the final snapshot drawn
  const canvas = page.locator('#canvas');
  const box = await canvas.boundingBox();
  const cx = box.x + box.width / 2, cy = box.y + box.height / 2;
  const turn = async (degrees) => {
    await page.click('#reset-view');
    const dx = (degrees / 360) * box.height;
    await page.mouse.move(cx, cy); await page.mouse.down();
    await page.mouse.move(cx + dx, cy, { steps: 10 }); await page.mouse.up();
    await sleep(400);
    const direction = await page.evaluate(() => window.facescanStats.viewDirection());
    // The toolbar and the hint float over the canvas: left out of the picture.
    const shot = await canvas.screenshot({ style: '.toolbar, .hint { visibility: hidden; }' });
    return { shot: shot.toString('base64'), direction };
  };
  const views = [await turn(50), await turn(0), await turn(-50)];
  log(`view directions: ${views.map((v) => v.direction.map((x) => x.toFixed(2)).join(',')).join(' | ')}`);
  // The three views side by side, each cropped to the middle of the canvas where the face is.
  const composed = await browser.newPage({ viewport: { width: 1200, height: 500 } });
  await composed.setContent(`<body style="margin:0;background:#16181d;display:flex">${views.map((v) =>
    `<div style="width:400px;height:500px;overflow:hidden;display:flex;justify-content:center;align-items:center">` +
    `<img src="data:image/png;base64,${v.shot}" style="height:${Math.round(box.height * 1.0)}px"></div>`).join('')}</body>`);
  await composed.screenshot({ path: path.join(out, 'face-three-sides.png') });
  log('face-three-sides.png written');
} finally {
  await browser.close();
  await stop(viewer);
  await stop(agent);
  await stop(server);
}
for (const name of ['viewer-mid-scan.png', 'face-three-sides.png']) {
  log(`${name}: ${(fs.statSync(path.join(out, name)).size / 1024).toFixed(0)} kB`);
}
