// The client side of a progressive session (Brown 8.2; SERVE_API.md): one outstanding update at a
// time; a frame deletes its out keys, geomorphs its morph mesh over the period, then draws its in
// triangles. A frame that arrives while a morph runs waits for it to finish.
import { keyAt } from './frame.js';
import { MorphMesh } from './terrain.js';

export class SessionClient {
  constructor(api, store, parent, uniforms, options) {
    this.api = api;
    this.store = store;
    this.parent = parent;
    this.uniforms = uniforms;
    this.morphMs = options.morphMs;
    this.extra = options.extra || '';
    this.id = null;
    this.inFlight = false;
    this.queued = null; // a frame waiting for the running morph
    this.morph = null; // {mesh, frame, startedAt}
    this.paused = false; // tests: t held where setT put it
    this.lastSent = null;
    this.lastComplete = true;
    this.stats = []; // one record per applied frame
    this.pagesTotal = 0;
    this.error = null;
    this.onFrame = () => {};
  }

  async open() {
    const t0 = performance.now();
    const frame = await this.api.openSession();
    this.id = frame.header.session;
    this.receive(frame, t0, performance.now());
  }

  close() {
    if (this.id) this.api.closeSession(this.id);
  }

  /** Whether there is nothing left to do for `cam`: no request, no morph, the last frame complete. */
  idleFor(cam) {
    return !this.inFlight && !this.queued && !this.morph && this.lastComplete && this.sameCamera(cam);
  }

  sameCamera(cam) {
    const a = this.lastSent;
    if (!a) return false;
    const eq = (u, v, tol) => u.every((x, i) => Math.abs(x - v[i]) <= tol);
    const tol = cam.tolerance || 0;
    return eq(a.eye, cam.eye, tol) && eq(a.target, cam.target, tol) && a.fov === cam.fov &&
      a.viewport[0] === cam.viewport[0] && a.viewport[1] === cam.viewport[1] && a.px === cam.px;
  }

  /** Called every animation frame with the current camera (model coordinates). */
  tick(now, cam) {
    this.animate(now);
    if (!this.id || this.inFlight || this.queued) return;
    if (this.sameCamera(cam) && this.lastComplete) return;
    this.send(cam);
  }

  async send(cam) {
    this.inFlight = true;
    this.lastSent = { ...cam, eye: [...cam.eye], target: [...cam.target], viewport: [...cam.viewport] };
    const t0 = performance.now();
    try {
      const frame = await this.api.update(this.id, cam, this.extra);
      this.receive(frame, t0, performance.now());
    } catch (e) {
      this.error = e;
      console.error(e);
      if (e.status === 404) this.reopen();
    } finally {
      this.inFlight = false;
    }
  }

  async reopen() {
    for (const key of [...this.store.slots.keys()]) this.store.remove(key);
    this.store.flush();
    if (this.morph) this.morph.mesh.dispose();
    this.morph = null;
    this.queued = null;
    this.id = null;
    await this.open();
  }

  receive(frame, t0, t1) {
    frame.updateMs = t1 - t0;
    if (this.morph) this.queued = frame;
    else this.apply(frame, performance.now());
  }

  apply(frame, now) {
    const h = frame.header, s = h.stats || {};
    const nOut = frame.outKeys.length / 3;
    for (let i = 0; i < nOut; ++i) this.store.remove(keyAt(frame.outKeys, i));
    this.store.flush();
    this.lastComplete = s.complete !== false;
    this.pagesTotal += s.pages_read || 0;
    const rec = {
      frame: h.frame, triangles: s.triangles, held: 0, drawn: 0, triangles_in: s.triangles_in,
      triangles_out: s.triangles_out, morph_groups: s.morph_groups || 0,
      morph_vertices: frame.mStart.length / 3, morph_triangles: frame.mTris.length / 3,
      pages_read: s.pages_read || 0, server_ms: s.update_ms ?? (s.seconds || 0) * 1000, update_ms: frame.updateMs,
      bytes: frame.bytes, complete: this.lastComplete, applied_at: now,
    };
    this.stats.push(rec);
    if (frame.mTris.length > 0) {
      const mesh = new MorphMesh(this.parent, this.uniforms, frame);
      this.morph = { mesh, frame, startedAt: now, rec };
      if (!this.paused) this.uniforms.t.value = 0;
    } else {
      this.finish(frame, rec);
    }
  }

  animate(now) {
    if (!this.morph) return;
    if (!this.paused)
      this.uniforms.t.value = this.morphMs > 0 ? Math.min(1, (now - this.morph.startedAt) / this.morphMs) : 1;
    if (this.uniforms.t.value >= 1 && !this.paused) this.endMorph(now);
  }

  endMorph(now) {
    const { mesh, frame, rec } = this.morph;
    mesh.dispose();
    this.morph = null;
    this.finish(frame, rec);
    if (this.queued) {
      const q = this.queued;
      this.queued = null;
      this.apply(q, now);
    }
  }

  finish(frame, rec) {
    const nIn = frame.inKeys.length / 3;
    for (let i = 0; i < nIn; ++i)
      this.store.add(keyAt(frame.inKeys, i), frame.inPos, 9 * i, (frame.inFlags[i] & 1) !== 0);
    this.store.flush();
    rec.held = this.store.size;
    rec.drawn = this.store.drawn;
    this.onFrame(rec);
  }
}
