// The HTTP API of smrdb serve (SERVE_API.md): JSON endpoints, the session and its frames.
import { parseFrame } from './frame.js';

async function failure(res, what) {
  let msg = `${res.status} ${res.statusText}`;
  try {
    const body = await res.json();
    if (body && body.error) msg += `: ${body.error}`;
  } catch {
    /* not JSON */
  }
  const e = new Error(`${what}: ${msg}`);
  e.status = res.status;
  return e;
}

export async function getJson(url) {
  const res = await fetch(url);
  if (!res.ok) throw await failure(res, url);
  return res.json();
}

async function getFrame(url, init) {
  const res = await fetch(url, init);
  if (!res.ok) throw await failure(res, url);
  const buf = await res.arrayBuffer();
  return parseFrame(buf);
}

const list = (v) => v.map((x) => String(x)).join(',');

/** The query string of a camera (model coordinates) for /update and /extract. */
export function cameraQuery(cam) {
  return (
    `eye=${list(cam.eye)}&target=${list(cam.target)}&fov=${cam.fov}` +
    `&viewport=${cam.viewport[0]}x${cam.viewport[1]}&px=${cam.px}` +
    (cam.up ? `&up=${list(cam.up)}` : '')
  );
}

export class Api {
  constructor(base, db) {
    this.base = base.replace(/\/$/, '');
    this.db = db;
    this.root = `${this.base}/v1/${encodeURIComponent(db)}`;
  }
  static databases(base) {
    return getJson(`${base.replace(/\/$/, '')}/v1/databases`);
  }
  info() {
    return getJson(`${this.root}/info`);
  }
  openSession() {
    return getFrame(`${this.root}/session`, { method: 'POST' });
  }
  update(session, cam, extra = '') {
    return getFrame(`${this.root}/session/${encodeURIComponent(session)}/update?${cameraQuery(cam)}${extra}`);
  }
  closeSession(session) {
    return fetch(`${this.root}/session/${encodeURIComponent(session)}`, { method: 'DELETE', keepalive: true }).catch(() => {});
  }
  elevation(x, y) {
    return getJson(`${this.root}/query/elevation?x=${x}&y=${y}`);
  }
  profile(a, b, samples = 128) {
    return getJson(`${this.root}/query/profile?from=${a[0]},${a[1]}&to=${b[0]},${b[1]}&samples=${samples}`);
  }
  los(a, b) {
    return getJson(`${this.root}/query/los?from=${list(a)}&to=${list(b)}`);
  }
  contours(interval, bbox) {
    return getJson(`${this.root}/query/contours?interval=${interval}` + (bbox ? `&bbox=${list(bbox)}` : ''));
  }
}
