// kClients receivers for the candidate prototypes (node 20: --experimental-websocket). Mode ws: binary frames;
// mode sse: an event stream, and a GET of the snapshot bytes per event (latest only, as a browser would).
const [mode, port, clients = '10', messages = '40'] = process.argv.slice(2);
const base = `127.0.0.1:${port}`;
const n = Number(clients), want = Number(messages);
let bytes = 0, first = 0, last = 0, done = 0, count = 0;
const t0 = performance.now();
function finish() {
  if (++done < n) return;
  const ms = last - first;
  console.log(`clients: ${n} clients got ${count} snapshots (${want} sent each; slow ones get the latest), ${(bytes / 1e6).toFixed(1)} MB in ${ms.toFixed(0)} ms = ` +
              `${(bytes / 1e6 / (ms / 1000)).toFixed(0)} MB/s`);
  process.exit(0);
}
for (let i = 0; i < n; ++i) {
  if (mode === 'ws') {
    const ws = new WebSocket(`ws://${base}/ws`);
    ws.binaryType = 'arraybuffer';
    let got = 0, idle;
    ws.onmessage = (e) => {
      if (!first) first = performance.now();
      last = performance.now();
      bytes += e.data.byteLength; ++count;
      clearTimeout(idle);
      if (++got === want) finish(); else idle = setTimeout(finish, 1000);  // a latest-wins server skips some
    };
  } else {
    (async () => {
      const res = await fetch(`http://${base}/events`);
      const reader = res.body.getReader();
      let got = 0, text = '';
      while (got < want) {
        const { value, done: end } = await reader.read();
        if (end) break;
        text += new TextDecoder().decode(value);
        const events = text.split('\n\n'); text = events.pop();
        if (!events.length) continue;
        if (!first) first = performance.now();
        const seq = Number(events.at(-1).slice(6));
        const snap = await (await fetch(`http://${base}/snap`)).arrayBuffer();
        bytes += snap.byteLength; ++count; last = performance.now();
        got = seq;  // the latest wins: skipped announcements are not fetched
      }
      finish();
    })();
  }
}
setTimeout(() => { console.log(`clients: timeout, ${done} of ${n} done`); process.exit(1); }, 30000);
