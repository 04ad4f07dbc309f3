// A stand-in for `smrdb serve` for developing the viewer without the C++ server: one synthetic
// terrain whose session refines a regular grid one level per update (morphs included), following
// SERVE_API.md's frame format. Usage: node dev/mock_server.mjs [PORT]  (serves dist/ at /).
import { createServer } from 'node:http';
import { readFileSync, existsSync } from 'node:fs';
import { dirname, join, normalize } from 'node:path';
import { fileURLToPath } from 'node:url';

const dist = join(dirname(fileURLToPath(import.meta.url)), '..', 'dist');
const SIZE = 1000, LEVELS = 6;
const height = (x, y) => 120 * Math.sin(x / 170) * Math.cos(y / 230) + 60 * Math.sin((x + y) / 90) + 200;
const origin = [SIZE / 2, SIZE / 2, 200];

// Level L: a (2^L x 2^L) grid of squares, two triangles each; key (L, 0, index).
function level(L) {
  const n = 1 << L, s = SIZE / n, tris = [];
  for (let j = 0; j < n; ++j)
    for (let i = 0; i < n; ++i) {
      const p = (a, b) => [(i + a) * s, (j + b) * s];
      tris.push([p(0, 0), p(1, 0), p(1, 1)], [p(0, 0), p(1, 1), p(0, 1)]);
    }
  return tris;
}
// Height of the level-L surface at (x, y): interpolated on the triangle that holds it.
function surface(L, x, y) {
  const n = 1 << L, s = SIZE / n;
  const i = Math.min(n - 1, Math.floor(x / s)), j = Math.min(n - 1, Math.floor(y / s));
  const u = x / s - i, v = y / s - j;
  const h = (a, b) => height((i + a) * s, (j + b) * s);
  return u >= v ? h(0, 0) + u * (h(1, 0) - h(0, 0)) + v * (h(1, 1) - h(1, 0))
                : h(0, 0) + v * (h(0, 1) - h(0, 0)) + u * (h(1, 1) - h(0, 1));
}

function frame(session, f, outL, inL) {
  const out = outL === null ? [] : level(outL), inn = level(inL);
  const morph = outL === null ? [] : level(Math.max(outL, inL)); // the finer level refines both
  const header = { session, frame: f, n_out: out.length, n_in: inn.length, n_mv: morph.length * 3, n_mt: morph.length, origin,
    stats: { complete: inL >= LEVELS || inL < outL, triangles: inn.length, triangles_in: inn.length, triangles_out: out.length,
      morph_groups: morph.length ? 1 : 0, seconds: 0.001, pages_read: inn.length >> 6 } };
  let json = Buffer.from(JSON.stringify(header));
  const pad = (n) => (n + 3) & ~3;
  const parts = [];
  const head = Buffer.alloc(12); head.write('SMRF'); head.writeUInt32LE(1, 4); head.writeUInt32LE(json.length, 8);
  parts.push(head, json, Buffer.alloc(pad(json.length) - json.length));
  const u32 = (arr) => Buffer.from(new Uint32Array(arr).buffer);
  const f32 = (arr) => Buffer.from(new Float32Array(arr).buffer);
  const u8 = (arr) => { const b = Buffer.alloc(pad(arr.length)); arr.forEach((x, i) => (b[i] = x)); return b; };
  const rel = (p, z) => [p[0] - origin[0], p[1] - origin[1], z - origin[2]];
  parts.push(u32(out.flatMap((_, i) => [i, outL, i])), u32(inn.flatMap((_, i) => [i, inL, i])));
  parts.push(f32(inn.flatMap((t) => t.flatMap((p) => rel(p, height(p[0], p[1]))))), u8(inn.map(() => 0)));
  parts.push(f32(morph.flatMap((t) => t.flatMap((p) => rel(p, surface(outL, p[0], p[1]))))));
  parts.push(f32(morph.flatMap((t) => t.flatMap((p) => rel(p, surface(inL, p[0], p[1]))))));
  parts.push(u32(morph.flatMap(() => [0, 0, 0])), u32(morph.flatMap((_, i) => [3 * i, 3 * i + 1, 3 * i + 2])), u8(morph.map(() => 0)));
  return Buffer.concat(parts);
}

const sessions = new Map();
const info = { kind: 'terrain', origin, bounds: { min: [0, 0, 20], max: [SIZE, SIZE, 380] } };
const server = createServer((req, res) => {
  const url = new URL(req.url, 'http://x');
  const send = (code, type, body) => { res.writeHead(code, { 'Content-Type': type }); res.end(body); };
  const json = (o) => send(200, 'application/json', JSON.stringify(o));
  let m;
  if (url.pathname === '/v1/databases') return json([{ name: 'mock', kind: 'terrain' }]);
  if (url.pathname === '/v1/mock/info') return json(info);
  if (url.pathname === '/v1/mock/session' && req.method === 'POST') {
    const id = `s${sessions.size + 1}`;
    sessions.set(id, { f: 0, L: 0 });
    return send(200, 'application/octet-stream', frame(id, 0, null, 0));
  }
  if ((m = url.pathname.match(/^\/v1\/mock\/session\/(\w+)\/update$/))) {
    const s = sessions.get(m[1]);
    if (!s) return send(404, 'application/json', '{"error":"no such session"}');
    const outL = s.L;
    s.L = s.L === LEVELS ? LEVELS - 2 : s.L + 1; s.f += 1; // at the finest level a move coarsens (to show morphs)
    const body = outL === s.L ? frame(m[1], s.f, null, 0).subarray(0, 0) : frame(m[1], s.f, outL, s.L);
    if (outL === s.L) { // nothing to do: an empty frame
      const h = { session: m[1], frame: s.f, n_out: 0, n_in: 0, n_mv: 0, n_mt: 0, origin, stats: { complete: true, triangles: 2 << (2 * s.L) } };
      const j = Buffer.from(JSON.stringify(h)), head = Buffer.alloc(12);
      head.write('SMRF'); head.writeUInt32LE(1, 4); head.writeUInt32LE(j.length, 8);
      return send(200, 'application/octet-stream', Buffer.concat([head, j, Buffer.alloc(((j.length + 3) & ~3) - j.length)]));
    }
    return send(200, 'application/octet-stream', body);
  }
  if (url.pathname.startsWith('/v1/mock/query/elevation')) {
    const x = +url.searchParams.get('x'), y = +url.searchParams.get('y');
    return json({ x, y, z: height(x, y) });
  }
  const file = normalize(join(dist, url.pathname === '/' ? 'index.html' : url.pathname));
  if (file.startsWith(dist) && existsSync(file)) return send(200, file.endsWith('.html') ? 'text/html' : 'text/javascript', readFileSync(file));
  send(404, 'application/json', '{"error":"not found"}');
});
server.listen(Number(process.argv[2] || 8099), '127.0.0.1', () => console.log(`mock smrdb serve on http://127.0.0.1:${server.address().port}/`));
