// The viewer's login in a real browser: `facescan view --tls` with a certificate and a login that the real
// deploy/security/site.sh made; Debian's headless chromium trusts that certificate only (its key's SPKI hash, as a
// browser that imported the site's CA would accept it), and a second one that does not trust it cannot open the
// page at all. Without a login the page is the login form and the API answers 401; a wrong password is refused;
// with the right one the viewer's page loads, its API answers and its WebSocket (WSS) delivers the sessions; the
// session cookie is HttpOnly, Secure and SameSite=Strict. Run by viewer_browser_test.sh viewer_login_browser_test.mjs.
// Usage: node viewer_login_browser_test.mjs OUT_DIR DOMAIN   (env: FACESCAN_CLI, FACESCAN_SITE,
//        FACESCAN_WEB_NODE_MODULES, CHROMIUM)
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import fs from 'node:fs';
import { createRequire } from 'node:module';
import path from 'node:path';
import { chromiumArgs, ddsArgs, start, stop, tail, waitForLog } from './scan_processes.mjs';

const [outDir, domain] = process.argv.slice(2);
const env = process.env;
const require = createRequire(path.join(env.FACESCAN_WEB_NODE_MODULES, 'noop.js'));
const playwright = require('playwright-core');
fs.rmSync(outDir, { recursive: true, force: true });
fs.mkdirSync(outDir, { recursive: true });
const password = 'correct horse battery';
const site = path.join(outDir, 'site');
const run = (args, input) => execFileSync(env.FACESCAN_SITE, args, { input, encoding: 'utf8' });
run(['init', site]);
run(['web', site, 'viewer', '--host', 'localhost']);
run(['login', site, 'viewer', 'alice'], `${password}\n`);
// What a browser that trusts the site's CA accepts, pinned: the SHA-256 of the certificate's public key.
const spki = execFileSync('sh', ['-c', `openssl x509 -in '${site}/viewer/web.crt' -pubkey -noout | ` +
  'openssl pkey -pubin -outform der | openssl dgst -sha256 -binary | base64'], { encoding: 'utf8' }).trim();

const viewer = start('view', env.FACESCAN_CLI, ['view', '--port', '0', '--tls', path.join(site, 'viewer'),
  '--audit', path.join(outDir, 'view-audit.log'), ...ddsArgs(domain)], outDir);
const [, port] = await waitForLog(viewer, /serving https:\/\/\S+:(\d+)\//, 15000);
const url = `https://localhost:${port}/`;
console.log(`viewer at ${url}`);

const launch = (extra) => playwright.chromium.launch({ executablePath: env.CHROMIUM, headless: true,
  args: [...chromiumArgs, ...extra], timeout: 30000 });
const trusting = await launch([`--ignore-certificate-errors-spki-list=${spki}`]);
const stranger = await launch([]);
let failed = true;
try {
  // A browser that does not trust the certificate gets no page at all.
  const untrusted = await (await stranger.newContext()).newPage();
  const refused = await untrusted.goto(url).then(() => 'loaded', (error) => error.message);
  assert.match(refused, /ERR_CERT/, 'a browser without the site CA must refuse the certificate');

  const context = await trusting.newContext();
  const page = await context.newPage();
  await page.goto(url);
  assert.equal(new URL(page.url()).pathname, '/login', 'without a login, the page is the login form');
  // (The login page's own policy lets no script fetch anything: the API is asked by the browser itself.)
  const anonymous = await page.goto(`${url}api/sessions`);
  assert.equal(anonymous.status(), 401, 'the API without a login');
  assert.doesNotMatch(await anonymous.text(), /"sessions"/);
  await page.goto(url);

  await page.fill('input[name=user]', 'alice');
  await page.fill('input[name=password]', 'not the password');
  await Promise.all([page.waitForLoadState('load'), page.click('button[type=submit]')]);
  assert.match(await page.textContent('body'), /wrong user or password/);
  assert.equal((await context.cookies()).length, 0, 'no cookie for a wrong password');

  await page.fill('input[name=user]', 'alice');
  await page.fill('input[name=password]', password);
  await Promise.all([page.waitForURL(url), page.click('button[type=submit]')]);
  await page.waitForSelector('#state', { state: 'attached', timeout: 15000 });  // the viewer's page
  const [cookie] = await context.cookies();
  assert.equal(cookie.name, '__Host-facescan_session');
  assert.ok(cookie.httpOnly && cookie.secure && cookie.sameSite === 'Strict', JSON.stringify(cookie));
  assert.equal(await page.evaluate(() => document.cookie), '', 'no script reads the session cookie');
  const api = await page.evaluate(async () => { const r = await fetch('/api/sessions'); return [r.status, await r.json()]; });
  assert.equal(api[0], 200);
  assert.equal(api[1].type, 'sessions');
  const ws = await page.evaluate(() => new Promise((resolve) => {
    const socket = new WebSocket(`wss://${location.host}/ws`);
    socket.onmessage = (event) => { resolve(String(event.data)); socket.close(); };
    socket.onerror = () => resolve('error');
  }));
  assert.match(ws, /"type":"sessions"/, 'the WebSocket over TLS delivers the sessions');

  // Logging out ends it: the API refuses the same browser again.
  await page.evaluate(async () => { await fetch('/logout', { method: 'POST' }); });
  assert.equal(await page.evaluate(async () => (await fetch('/api/sessions')).status), 401);
  const audit = fs.readFileSync(path.join(outDir, 'view-audit.log'), 'utf8');
  assert.match(audit, /\tlogin\t\tlogin alice\terror: wrong user or password/);
  assert.match(audit, /\tlogin\t\tlogin alice\tok \(from 127\.0\.0\.1\)/);
  failed = false;
  console.log('viewer_login_browser_test: ok');
} finally {
  await trusting.close();
  await stranger.close();
  await stop(viewer);
  if (failed) console.log(`--- view.log:\n${tail(viewer)}`);
}
