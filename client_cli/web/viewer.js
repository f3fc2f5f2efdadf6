// facescan view: the page's own script. It follows the sessions over one WebSocket, decodes the server's Draco
// snapshots as they are (three.js DRACOLoader, wasm, in a worker) and draws them; the C++ side encodes nothing
// per browser. A finished scan with a texture is then drawn textured (the server's atlas as the material's map);
// live snapshots keep their vertex colours. Measurements for tests and benchmarks are kept in window.facescanStats.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { DRACOLoader } from 'three/addons/loaders/DRACOLoader.js';

const $ = (id) => document.getElementById(id);
const stats = (window.facescanStats = { snapshots: [], drawn: 0, followed: null, wsMessages: 0 });
const nowMs = () => performance.timeOrigin + performance.now();  // epoch ms, sub-ms resolution

// --- the 3D view ------------------------------------------------------------------------------------------------
const canvas = $('canvas');
// Multisampling doubles the cost of a frame on a software renderer (SwiftShader, llvmpipe: a VM, a remote desktop,
// a machine without a GPU) and costs nothing noticeable on a GPU: only there is it on.
function softwareRenderer() {
  const gl = document.createElement('canvas').getContext('webgl2');
  if (!gl) return false;
  // RENDERER is often masked ("WebKit WebGL"); the debug extension gives the real name where it is offered.
  const info = gl.getExtension('WEBGL_debug_renderer_info');
  const name = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
  gl.getExtension('WEBGL_lose_context')?.loseContext();
  return /swiftshader|llvmpipe|software/i.test(name);
}
stats.softwareRenderer = softwareRenderer();
const renderer = new THREE.WebGLRenderer({ canvas, antialias: !stats.softwareRenderer, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x16181d);
const camera = new THREE.PerspectiveCamera(35, 1, 0.01, 20);
camera.position.set(0, 0, 1);
scene.add(camera);
scene.add(new THREE.HemisphereLight(0xffffff, 0x444450, 1.2));
const headlight = new THREE.DirectionalLight(0xffffff, 1.8);  // follows the camera: shading from any angle
headlight.position.set(0.3, 0.5, 1);
camera.add(headlight);
const controls = new OrbitControls(camera, canvas);
const material = new THREE.MeshStandardMaterial({
  vertexColors: true, roughness: 0.85, metalness: 0, side: THREE.DoubleSide,
});
// The server's meshes are in the first camera's frame (y down, z away from the camera): turned 180 degrees about
// x, the face is upright and looks at the viewer, as in the GLB download.
// The finished model's material: its texture (set when one is shown), glTF's convention (v down, no flip).
const texturedMaterial = new THREE.MeshStandardMaterial({ roughness: 0.85, metalness: 0, side: THREE.DoubleSide });
const face = new THREE.Mesh(new THREE.BufferGeometry(), material);
face.rotation.x = Math.PI;
scene.add(face);

let renderPending = false;
let afterDraw = [];
// Renders on demand (a change of view or a new mesh), so an idle page costs nothing.
function requestRender(callback) {
  if (callback) afterDraw.push(callback);
  if (renderPending) return;
  renderPending = true;
  requestAnimationFrame(() => {
    renderPending = false;
    resize();
    const t0 = performance.now();
    renderer.render(scene, camera);
    stats.lastRenderMs = performance.now() - t0;
    const done = afterDraw;
    afterDraw = [];
    // The frame is on screen at the next animation frame: that is when "drawn" is measured.
    if (done.length) requestAnimationFrame(() => done.forEach((fn) => fn(nowMs())));
  });
}
function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== Math.floor(w * renderer.getPixelRatio()) || canvas.height !== Math.floor(h * renderer.getPixelRatio())) {
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
  }
}
controls.addEventListener('change', () => requestRender());
// Where the camera looks from, relative to the point it turns around (tests check turning and reset view with it).
stats.viewDirection = () => camera.position.clone().sub(controls.target).normalize().toArray();
window.addEventListener('resize', () => requestRender());

function frameFace() {
  const geometry = face.geometry;
  if (!geometry.attributes.position) return;
  geometry.computeBoundingSphere();
  const sphere = geometry.boundingSphere.clone().applyMatrix4(face.matrixWorld);
  const distance = sphere.radius / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2)) * 1.1;
  controls.target.copy(sphere.center);
  camera.position.copy(sphere.center).add(new THREE.Vector3(0, 0, distance));
  camera.near = distance / 50;
  camera.far = distance * 50;
  camera.updateProjectionMatrix();
  controls.update();
  requestRender();
}
$('reset-view').addEventListener('click', frameFace);
$('wireframe').addEventListener('change', (e) => {
  material.wireframe = texturedMaterial.wireframe = e.target.checked;
  requestRender();
});

// --- decoding: the latest snapshot wins ------------------------------------------------------------------------
const draco = new DRACOLoader();
draco.setDecoderPath({ js: '/vendor/draco/draco_wasm_wrapper.js', wasm: '/vendor/draco/draco_decoder.wasm' });
draco.preload();
let decoding = false;
let pending = null;  // a snapshot that arrived while another was decoding
let framedSession = null;
const erasedSessions = new Set();  // deleted while this page was open: never drawn again

let texturedSession = null;  // the session whose finished model is drawn textured: its snapshots are not drawn
const texturesTried = new Set();

function onSnapshot(header, bytes) {
  if (header.session !== stats.followed || erasedSessions.has(header.session)) return;
  if (header.session === texturedSession) return;
  const received = nowMs();
  // The size is kept now: decoding hands the buffer to the decoder's worker.
  const snap = { header, bytes, size: bytes.byteLength, received };
  if (decoding) { pending = snap; return; }
  decode(snap);
}
function decode(snap) {
  decoding = true;
  const t0 = performance.now();
  draco.parse(snap.bytes, (geometry) => {
    const decodeMs = performance.now() - t0;
    if (erasedSessions.has(snap.header.session) || snap.header.session === texturedSession) {
      geometry.dispose(); finishDecode(); return;
    }
    if (!geometry.attributes.normal) geometry.computeVertexNormals();  // snapshots may come without normals
    const old = face.geometry;
    face.geometry = geometry;
    old.dispose();
    $('overlay').hidden = true;
    if (framedSession !== snap.header.session) { framedSession = snap.header.session; face.updateMatrixWorld(); frameFace(); }
    requestRender((drawnMs) => {
      const record = {
        seq: snap.header.seq, bytes: snap.size, vertices: snap.header.vertex_count,
        triangles: snap.header.triangle_count, created_ms: snap.header.created_ms, received_ms: snap.received,
        decode_ms: decodeMs, render_ms: stats.lastRenderMs, drawn_ms: drawnMs,
        latency_ms: drawnMs - snap.header.created_ms,
      };
      stats.snapshots.push(record);
      stats.drawn = stats.snapshots.length;
      $('snapshot').textContent = `#${record.seq} (${(record.bytes / 1024).toFixed(0)} kB Draco)`;
      $('mesh-size').textContent = `${record.vertices.toLocaleString()} vertices, ${record.triangles.toLocaleString()} triangles`;
      $('latency').textContent = `${record.latency_ms.toFixed(0)} ms`;
      $('decode').textContent = `${record.decode_ms.toFixed(1)} ms`;
    });
    finishDecode();
  }, (error) => {
    console.error('facescan: snapshot', snap.header.seq, 'cannot be decoded:', error);
    finishDecode();
  });
}
function finishDecode() {
  decoding = false;
  if (pending) { const next = pending; pending = null; decode(next); }
}

// --- the finished model with its texture: [u32 header length][{"texture_bytes": N}][PNG][Draco with TEX_COORD] ---
async function loadTextured(id) {
  texturesTried.add(id);
  const t0 = performance.now();
  try {
    const response = await fetch(`/api/sessions/${encodeURIComponent(id)}/textured`);
    if (!response.ok) return;  // no texture (scanned without colour): the vertex colours stay
    const body = await response.arrayBuffer();
    const headerLength = new DataView(body).getUint32(0, true);
    const header = JSON.parse(new TextDecoder().decode(new Uint8Array(body, 4, headerLength)));
    const pngStart = 4 + headerLength;
    const image = await createImageBitmap(new Blob([body.slice(pngStart, pngStart + header.texture_bytes)],
      { type: 'image/png' }));
    const geometry = await new Promise((resolve, reject) => draco.parse(body.slice(pngStart + header.texture_bytes),
      resolve, reject));
    if (stats.followed !== id || erasedSessions.has(id) || !geometry.attributes.uv) {
      geometry.dispose(); image.close(); return;
    }
    if (!geometry.attributes.normal) geometry.computeVertexNormals();
    const texture = new THREE.Texture(image);
    texture.flipY = false;
    texture.colorSpace = THREE.SRGBColorSpace;
    texture.anisotropy = renderer.capabilities.getMaxAnisotropy();
    texture.needsUpdate = true;
    texturedMaterial.map?.dispose();
    texturedMaterial.map = texture;
    texturedMaterial.needsUpdate = true;
    texturedSession = id;
    pending = null;
    const old = face.geometry;
    face.geometry = geometry;
    face.material = texturedMaterial;
    old.dispose();
    $('overlay').hidden = true;
    if (framedSession !== id) { framedSession = id; face.updateMatrixWorld(); frameFace(); }
    const vertices = geometry.attributes.position.count;
    const triangles = (geometry.index ? geometry.index.count : vertices) / 3;
    $('snapshot').textContent = `final model, textured (${image.width} × ${image.height} texture, ` +
      `${(body.byteLength / 1024 / 1024).toFixed(1)} MB)`;
    $('mesh-size').textContent = `${vertices.toLocaleString()} vertices, ${triangles.toLocaleString()} triangles`;
    requestRender((drawnMs) => {
      stats.textured = { session: id, width: image.width, height: image.height, bytes: body.byteLength, vertices,
        triangles, ms: performance.now() - t0, drawn_ms: drawnMs };
    });
  } catch (error) {
    console.warn('facescan: the textured model of', id, 'cannot be shown; the vertex colours stay:', error);
  }
}

// --- sessions and progress -------------------------------------------------------------------------------------
let sessions = [];
const wanted = new URLSearchParams(location.search).get('session');
let unknownWanted = false;

function follow(id) {
  if (stats.followed === id) return;
  stats.followed = id;
  pending = null;
  const url = new URL(location.href);
  url.searchParams.set('session', id);
  history.replaceState(null, '', url);
  $('overlay').hidden = false;
  $('overlay').textContent = 'Waiting for the first snapshot…';
  $('snapshot').textContent = 'none yet';
  face.geometry.dispose();
  face.geometry = new THREE.BufferGeometry();
  face.material = material;
  texturedSession = null;
  texturesTried.delete(id);
  requestRender();
  if (socket && socket.readyState === WebSocket.OPEN) socket.send(`follow ${id}`);
  showSessions();
}

function showSessions() {
  const body = $('sessions').tBodies[0];
  body.replaceChildren(...sessions.map((s) => {
    const row = document.createElement('tr');
    row.className = (s.session === stats.followed ? 'followed ' : '') + (s.alive ? '' : 'gone');
    for (const text of [s.session, s.state, s.frames_integrated.toLocaleString(), s.fps.toFixed(1), s.server]) {
      const cell = document.createElement('td');
      cell.textContent = text;
      cell.title = text;
      row.append(cell);
    }
    row.addEventListener('click', () => follow(s.session));
    return row;
  }));
  $('no-sessions').hidden = sessions.length > 0;
  const s = sessions.find((x) => x.session === stats.followed);
  $('session-panel').hidden = !stats.followed;
  if (unknownWanted && !s) {
    showMessage(`Unknown session '${wanted}': pick one from the list.`);
  } else {
    showMessage(null);
  }
  if (!s) return;
  $('session-title').textContent = s.session;
  $('state').textContent = s.alive ? s.state : `${s.state} (server gone)`;
  $('state').className = `state ${s.state}`;
  $('detail').textContent = s.detail;
  $('integrated').textContent = s.frames_integrated.toLocaleString() +
    (s.frames_tracked_only ? ` (+${s.frames_tracked_only.toLocaleString()} tracked only)` : '');
  $('received').textContent = s.frames_received.toLocaleString();
  $('rejected').textContent = s.frames_rejected.toLocaleString();
  $('dropped').textContent = (s.frames_dropped + s.frames_skipped).toLocaleString() + (s.frames_skipped ? ' (skipped to stay live)' : '');
  $('fps').textContent = s.fps.toFixed(1);
  $('server').textContent = s.server || '–';
  if (s.state === 'FINISHED' && !texturesTried.has(s.session)) loadTextured(s.session);
}

function onSessions(list) {
  // A session leaves the list only when it was erased (facescan delete): its mesh goes from the page too.
  if (stats.followed && sessions.some((s) => s.session === stats.followed) &&
      !list.some((s) => s.session === stats.followed)) {
    erasedSessions.add(stats.followed);
    pending = null;
    face.geometry.dispose();
    face.geometry = new THREE.BufferGeometry();
    face.material = material;
    texturedMaterial.map?.dispose();
    texturedMaterial.map = null;
    texturedSession = null;
    requestRender();
    $('overlay').hidden = false;
    $('overlay').textContent = `Scan ${stats.followed} was deleted: nothing of it is shown any more.`;
    $('snapshot').textContent = 'deleted';
  }
  sessions = list;
  if (!stats.followed) {
    if (wanted && list.some((s) => s.session === wanted)) {
      unknownWanted = false;
      follow(wanted);
    } else {
      unknownWanted = Boolean(wanted);
      // The newest live scan: not finished, its server alive, the fewest frames (it started last).
      const live = list.filter((s) => s.alive && s.state !== 'FINISHED').sort((a, b) => a.frames_received - b.frames_received);
      const pick = live[0] || list[list.length - 1];
      if (pick && !wanted) follow(pick.session);
    }
  }
  showSessions();
}

function showMessage(text) {
  $('message').hidden = !text;
  $('message').textContent = text || '';
}

// --- downloads: fetched first, so an error shows as a message instead of a broken file ---------------------------
for (const button of document.querySelectorAll('.downloads button')) {
  button.addEventListener('click', async () => {
    const id = stats.followed;
    const format = button.dataset.format;
    const status = $('download-status');
    status.textContent = `Fetching the ${format.toUpperCase()} from the server…`;
    button.disabled = true;
    try {
      const response = await fetch(`/api/sessions/${encodeURIComponent(id)}/mesh.${format}`);
      if (!response.ok) {
        const reason = await response.json().catch(() => ({ error: response.statusText }));
        status.textContent = `No ${format.toUpperCase()}: ${reason.error}`;
        return;
      }
      const blob = await response.blob();
      const link = document.createElement('a');
      link.href = URL.createObjectURL(blob);
      link.download = `${id}.${format}`;
      document.body.append(link);
      link.click();
      link.remove();
      setTimeout(() => URL.revokeObjectURL(link.href), 60000);
      status.textContent = `${id}.${format}: ${(blob.size / 1024 / 1024).toFixed(1)} MB`;
    } catch (error) {
      status.textContent = `Download failed: ${error.message}`;
    } finally {
      button.disabled = false;
    }
  });
}

// --- the WebSocket, reconnected when the viewer restarts ----------------------------------------------------------
let socket = null;
function connect() {
  socket = new WebSocket(`${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws`);
  socket.binaryType = 'arraybuffer';
  socket.onopen = () => {
    $('connection').textContent = 'live';
    $('connection').className = 'connection ok';
    if (stats.followed) socket.send(`follow ${stats.followed}`);
  };
  socket.onmessage = (event) => {
    stats.wsMessages++;
    if (typeof event.data === 'string') {
      const message = JSON.parse(event.data);
      if (message.type === 'sessions') onSessions(message.sessions);
      else if (message.type === 'error') showMessage(message.message);
      return;
    }
    // [u32 header length, little-endian][JSON header][Draco bytes]
    const view = new DataView(event.data);
    const headerLength = view.getUint32(0, true);
    const header = JSON.parse(new TextDecoder().decode(new Uint8Array(event.data, 4, headerLength)));
    onSnapshot(header, event.data.slice(4 + headerLength));
  };
  socket.onclose = () => {
    $('connection').textContent = 'viewer unreachable: reconnecting…';
    $('connection').className = 'connection bad';
    setTimeout(connect, 1000);
  };
}
connect();
requestRender();
