// smrdb viewer: opens a database served by `smrdb serve`, refines it progressively through a
// session as the camera moves, geomorphs every change on the GPU, and overlays queries.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { Api } from './api.js';
import { SessionClient } from './session.js';
import { TriangleStore, makeUniforms } from './terrain.js';
import { Overlay } from './overlay.js';
import { orbitPath, samplePath, loadPath } from './paths.js';
import { readMorph } from './readback.js';
import { Hud } from './hud.js';

const params = new URLSearchParams(location.search);
const num = (name, dflt) => (params.has(name) ? Number(params.get(name)) : dflt);

/** Model <-> display frame: display = S * (model - origin); S converts degrees to metres. */
export class Frame {
  constructor(info, exaggeration) {
    this.origin = info.origin;
    const g = info.georef || (info.meta && info.meta.model && info.meta.model.georef);
    this.geographic = !!(g && g.geographic);
    const lat = (this.origin[1] * Math.PI) / 180;
    this.scale = this.geographic
      ? [111320 * Math.cos(lat), 110574, exaggeration]
      : [1, 1, exaggeration];
  }
  toDisplay(m) {
    return new THREE.Vector3(...m.map((v, i) => (v - this.origin[i]) * this.scale[i]));
  }
  toModel(d) {
    return [d.x, d.y, d.z].map((v, i) => this.origin[i] + v / this.scale[i]);
  }
}

function boundsOf(info) {
  const b = info.bounds || {};
  const m = info.meta && info.meta.model && info.meta.model.bounds;
  return { min: b.min || (m && m.lo), max: b.max || (m && m.hi) };
}

class Viewer {
  constructor(api, info, canvasParent) {
    this.api = api;
    this.info = info;
    this.bounds = boundsOf(info);
    this.frame = new Frame(info, num('exag', 1));
    this.px = num('px', 2);
    this.renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer.setClearColor(0x1b2330);
    canvasParent.appendChild(this.renderer.domElement);
    this.scene = new THREE.Scene();
    this.group = new THREE.Group(); // model-relative coordinates, scaled to display metres
    this.group.scale.set(...this.frame.scale);
    this.scene.add(this.group);
    this.uniforms = makeUniforms();
    this.uniforms.zOrigin.value = this.frame.origin[2];
    this.uniforms.zMin.value = this.bounds.min[2];
    this.uniforms.zMax.value = this.bounds.max[2];
    const lo = this.frame.toDisplay(this.bounds.min), hi = this.frame.toDisplay(this.bounds.max);
    this.extent = Math.max(hi.x - lo.x, hi.y - lo.y, hi.z - lo.z);
    this.camera = new THREE.PerspectiveCamera(num('fov', 45), 1, this.extent * 1e-4, this.extent * 20);
    this.camera.up.set(0, 0, 1);
    this.controls = new OrbitControls(this.camera, this.renderer.domElement);
    this.controls.enableDamping = false;
    this.setView(orbitPath(info, this.bounds, this.camera.fov)[225]);
    this.store = new TriangleStore(this.group, this.uniforms);
    this.session = new SessionClient(api, this.store, this.group, this.uniforms, {
      morphMs: num('morph_ms', 600),
      extra: (params.has('max_ms') ? `&max_ms=${params.get('max_ms')}` : '') +
        (params.has('max_triangles') ? `&max_triangles=${params.get('max_triangles')}` : ''),
    });
    this.fps = 0;
    this.renderTimes = [];
    this.hud = new Hud(this);
    this.overlay = new Overlay(this);
    this.keys = new Set();
    this.flight = null;
    window.addEventListener('resize', () => this.resize());
    window.addEventListener('keydown', (e) => this.key(e, true));
    window.addEventListener('keyup', (e) => this.key(e, false));
    window.addEventListener('beforeunload', () => this.session.close());
    this.resize();
  }

  resize() {
    const w = window.innerWidth, h = window.innerHeight;
    this.renderer.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
  }

  /** Places the camera at a path camera (model coordinates). */
  setView(c) {
    this.camera.position.copy(this.frame.toDisplay(c.eye));
    this.controls.target.copy(this.frame.toDisplay(c.target));
    if (c.fov && c.fov !== this.camera.fov) {
      this.camera.fov = c.fov;
      this.camera.updateProjectionMatrix();
    }
    this.camera.lookAt(this.controls.target);
    this.controls.update();
  }

  /** The camera as the server wants it (model coordinates). */
  modelCamera() {
    const size = new THREE.Vector2();
    this.renderer.getDrawingBufferSize(size);
    return {
      eye: this.frame.toModel(this.camera.position),
      target: this.frame.toModel(this.controls.target),
      up: [0, 0, 1],
      fov: Math.round(this.camera.fov * 1000) / 1000,
      viewport: [Math.min(8192, size.x), Math.min(8192, size.y)],
      px: this.px,
      tolerance: 1e-9 * this.extent,
    };
  }

  key(e, down) {
    if (e.target && e.target.tagName === 'INPUT') return;
    if (down) {
      if (e.key === 'm') this.uniforms.wire.value = 1 - this.uniforms.wire.value;
      if (e.key === 'g') this.uniforms.tint.value = this.uniforms.tint.value > 0 ? 0 : 0.6;
      if (e.key === 'p') this.toggleOrbit();
    }
    const k = e.key.toLowerCase();
    if ('wasdqe'.includes(k) && k.length === 1) down ? this.keys.add(k) : this.keys.delete(k);
  }

  /** WASD moves the eye and target over the ground, Q/E down and up. */
  walk(dt) {
    if (this.keys.size === 0) return;
    const step = this.extent * 0.15 * dt;
    const fwd = new THREE.Vector3().subVectors(this.controls.target, this.camera.position);
    fwd.z = 0;
    fwd.normalize();
    const right = new THREE.Vector3(fwd.y, -fwd.x, 0);
    const move = new THREE.Vector3();
    if (this.keys.has('w')) move.add(fwd);
    if (this.keys.has('s')) move.sub(fwd);
    if (this.keys.has('d')) move.add(right);
    if (this.keys.has('a')) move.sub(right);
    if (this.keys.has('e')) move.z += 1;
    if (this.keys.has('q')) move.z -= 1;
    move.multiplyScalar(step);
    this.camera.position.add(move);
    this.controls.target.add(move);
    this.controls.update();
  }

  toggleOrbit() {
    if (this.flight) this.flight = null;
    else this.fly(orbitPath(this.info, this.bounds, this.camera.fov), num('seconds', 60), true);
  }

  /** Flies along `cams` in `seconds` (interpolated), looping when `loop`. */
  fly(cams, seconds, loop) {
    this.flight = { cams, seconds, loop, start: performance.now() };
  }

  stepFlight(now) {
    const f = this.flight;
    if (!f) return;
    let u = (now - f.start) / (f.seconds * 1000);
    if (u >= 1) {
      if (f.loop) u %= 1;
      else {
        u = 1;
        this.flight = null;
      }
    }
    this.setView(samplePath(f.cams, u));
  }

  /** Tests: visit each camera in turn, waiting at each until the session has caught up. */
  async flyPath(cams, { timeoutMs = 20000 } = {}) {
    this.flight = null;
    for (const c of cams) {
      this.setView(c);
      await this.waitIdle(timeoutMs);
    }
    return this.session.stats.length;
  }

  waitIdle(timeoutMs = 20000) {
    const until = performance.now() + timeoutMs;
    return new Promise((resolve, reject) => {
      const check = () => {
        if (this.session.error) return reject(this.session.error);
        if (this.session.idleFor(this.modelCamera())) return resolve();
        if (performance.now() > until) return reject(new Error('viewer: the session did not settle in time'));
        setTimeout(check, 20);
      };
      check();
    });
  }

  loop(now) {
    const dt = this.lastNow ? Math.min(0.1, (now - this.lastNow) / 1000) : 0;
    this.lastNow = now;
    this.stepFlight(now);
    this.walk(dt);
    this.session.tick(now, this.modelCamera());
    this.renderer.render(this.scene, this.camera);
    this.renderTimes.push(now);
    while (this.renderTimes.length && now - this.renderTimes[0] > 1000) this.renderTimes.shift();
    this.fps = this.renderTimes.length;
    this.hud.update();
    requestAnimationFrame((t) => this.loop(t));
  }

  async start() {
    await this.session.open();
    requestAnimationFrame((t) => this.loop(t));
    const path = params.get('path');
    if (path) this.fly(await loadPath(path, this.info, this.bounds, this.camera.fov), num('seconds', 60), path === 'orbit');
  }
}

/** What tests (and the console) use: statistics, paths, the morph read back from the GPU. */
function expose(v) {
  window.smrdbViewer = {
    viewer: v,
    info: v.info,
    get stats() {
      return v.session.stats;
    },
    get fps() {
      return v.fps;
    },
    orbit: (n = 8) => orbitPath(v.info, v.bounds, v.camera.fov).filter((_, i) => i % Math.round(360 / n) === 0),
    flyPath: (cams, opts) => v.flyPath(cams, opts),
    waitIdle: (ms) => v.waitIdle(ms),
    setView: (c) => v.setView(c),
    camera: () => v.modelCamera(),
    /** Holds t at `t` (null: the morph clock runs again). */
    holdMorph(t) {
      v.session.paused = t !== null && t !== undefined;
      if (v.session.paused) v.uniforms.t.value = t;
    },
    hasMorph: () => !!v.session.morph,
    /** The running morph's vertices at the current t: start, end, and the GPU's mix. */
    readMorph: (limit) => readMorph(v, limit),
    render: () => v.renderer.render(v.scene, v.camera),
    held: () => ({ held: v.store.size, drawn: v.store.drawn }),
    ready: true,
  };
}

async function pickDatabase(base) {
  const dbs = await Api.databases(base);
  if (dbs.length === 1) return dbs[0].name;
  const div = document.getElementById('picker');
  div.innerHTML = '<h2>smrdb: choose a database</h2>' +
    dbs.map((d) => `<p><a href="?db=${encodeURIComponent(d.name)}">${d.name}</a> (${d.kind})</p>`).join('');
  div.style.display = 'block';
  return null;
}

async function main() {
  const base = params.get('server') || '';
  try {
    const db = params.get('db') || (await pickDatabase(base));
    if (!db) return;
    const api = new Api(base, db);
    const info = await api.info();
    const v = new Viewer(api, info, document.body);
    expose(v);
    await v.start();
  } catch (e) {
    console.error(e);
    const div = document.getElementById('error');
    div.textContent = String(e.message || e);
    div.style.display = 'block';
    window.smrdbViewer = { error: String(e.message || e) };
  }
}

main();
