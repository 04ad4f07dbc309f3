// The query overlay: click for an elevation, drag for a profile (a small chart), two clicks for a
// line of sight, and contours drawn as lines over the terrain (SERVE_API.md /query/*).
import * as THREE from 'three';

const TOOLS = ['navigate', 'elevation', 'profile', 'los', 'contours'];

export class Overlay {
  constructor(v) {
    this.v = v;
    this.tool = 'navigate';
    this.objects = new THREE.Group(); // model coordinates relative to the origin, like the terrain
    v.group.add(this.objects);
    this.panel = document.getElementById('query');
    this.chart = document.getElementById('chart');
    this.raycaster = new THREE.Raycaster();
    this.losFrom = null;
    this.lift = (0.002 * v.extent) / v.frame.scale[2];
    this.toolbar();
    const el = v.renderer.domElement;
    el.addEventListener('pointerdown', (e) => this.down(e));
    el.addEventListener('pointerup', (e) => this.up(e));
  }

  toolbar() {
    const bar = document.getElementById('tools');
    const zr = this.v.bounds.max[2] - this.v.bounds.min[2];
    const step = Math.pow(10, Math.floor(Math.log10(Math.max(zr, 1e-9) / 8)));
    bar.innerHTML = TOOLS.map((t) => `<button data-tool="${t}">${t}</button>`).join('') +
      ` interval <input id="interval" size="5" value="${step * Math.max(1, Math.round(zr / 8 / step))}">` +
      '<button data-tool="clear">clear</button>';
    bar.addEventListener('click', (e) => {
      const t = e.target.dataset && e.target.dataset.tool;
      if (!t) return;
      if (t === 'clear') return this.clear();
      if (t === 'contours') return this.contours(Number(document.getElementById('interval').value)).catch((err) => this.say(err.message));
      this.setTool(t);
    });
    this.setTool('navigate');
  }

  setTool(t) {
    this.tool = t;
    this.v.controls.enabled = t === 'navigate';
    this.losFrom = null;
    for (const b of document.querySelectorAll('#tools button')) b.classList.toggle('on', b.dataset.tool === t);
  }

  say(html) {
    this.panel.innerHTML = html;
    this.panel.style.display = html ? 'block' : 'none';
  }

  clear() {
    for (const o of [...this.objects.children]) {
      this.objects.remove(o);
      o.geometry.dispose();
    }
    this.say('');
    this.chart.style.display = 'none';
  }

  /** The model point under the pointer, or null. */
  pick(e) {
    const r = this.v.renderer.domElement.getBoundingClientRect();
    const ndc = new THREE.Vector2(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1);
    this.raycaster.setFromCamera(ndc, this.v.camera);
    const targets = [this.v.store.mesh];
    if (this.v.session.morph) targets.push(this.v.session.morph.mesh.mesh);
    for (const m of targets) m.geometry.computeBoundingSphere();
    const hit = this.raycaster.intersectObjects(targets, false)[0];
    return hit ? this.v.frame.toModel(hit.point) : null;
  }

  down(e) {
    this.downAt = { x: e.clientX, y: e.clientY, p: this.tool === 'navigate' ? null : this.pick(e) };
  }

  up(e) {
    const d = this.downAt;
    if (!d || this.tool === 'navigate') return;
    const p = this.pick(e);
    const moved = Math.hypot(e.clientX - d.x, e.clientY - d.y) > 4;
    const run = (promise) => promise.catch((err) => this.say(`error: ${err.message}`));
    if (this.tool === 'elevation' && p && !moved) run(this.elevation(p));
    if (this.tool === 'profile' && d.p && p && moved) run(this.profile(d.p, p));
    if (this.tool === 'los' && p && !moved) {
      if (!this.losFrom) {
        this.losFrom = p;
        this.say('line of sight: click the target');
      } else {
        const a = this.losFrom;
        this.losFrom = null;
        run(this.los(a, p));
      }
    }
  }

  local(x, y, z) {
    const o = this.v.frame.origin;
    return new THREE.Vector3(x - o[0], y - o[1], z - o[2] + this.lift);
  }

  line(points, color, segments = false) {
    const g = new THREE.BufferGeometry().setFromPoints(points);
    const m = new THREE.LineBasicMaterial({ color, depthTest: true });
    const l = segments ? new THREE.LineSegments(g, m) : new THREE.Line(g, m);
    l.frustumCulled = false;
    this.objects.add(l);
    return l;
  }

  marker(x, y, z, color) {
    const h = (0.03 * this.v.extent) / this.v.frame.scale[2];
    this.line([this.local(x, y, z), this.local(x, y, z + h)], color);
  }

  async elevation(p) {
    const r = await this.v.api.elevation(p[0], p[1]);
    if (r.z !== null && r.z !== undefined) this.marker(r.x, r.y, r.z, 0xffee44);
    this.say(`elevation at ${r.x.toFixed(5)}, ${r.y.toFixed(5)}: <b>${r.z === null ? 'no data' : r.z.toFixed(2)}</b>`);
    return r;
  }

  async profile(a, b) {
    const r = await this.v.api.profile(a, b);
    const pts = r.points.filter((q) => q[3] !== null && q[3] !== undefined);
    this.line(pts.map((q) => this.local(q[1], q[2], q[3])), 0xff66cc);
    this.drawChart(pts);
    this.say(`profile: ${r.points.length} samples over ${r.points.length ? r.points[r.points.length - 1][0].toPrecision(4) : 0}`);
    return r;
  }

  drawChart(pts) {
    const c = this.chart, ctx = c.getContext('2d');
    c.style.display = 'block';
    ctx.fillStyle = 'rgba(10,14,20,0.85)';
    ctx.fillRect(0, 0, c.width, c.height);
    if (pts.length < 2) return;
    const d0 = pts[0][0], d1 = pts[pts.length - 1][0] || 1;
    const zs = pts.map((q) => q[3]), z0 = Math.min(...zs), z1 = Math.max(...zs);
    const X = (d) => 30 + ((d - d0) / (d1 - d0 || 1)) * (c.width - 40);
    const Y = (z) => c.height - 15 - ((z - z0) / (z1 - z0 || 1)) * (c.height - 30);
    ctx.strokeStyle = '#ff66cc';
    ctx.beginPath();
    pts.forEach((q, i) => (i ? ctx.lineTo(X(q[0]), Y(q[3])) : ctx.moveTo(X(q[0]), Y(q[3]))));
    ctx.stroke();
    ctx.fillStyle = '#ccc';
    ctx.font = '10px monospace';
    ctx.fillText(z1.toFixed(0), 2, 12);
    ctx.fillText(z0.toFixed(0), 2, c.height - 15);
  }

  async los(a, b, height = 2) {
    const from = [a[0], a[1], a[2] + height], to = [b[0], b[1], b[2] + height];
    const r = await this.v.api.los(from, to);
    const A = this.local(...from), B = this.local(...to);
    if (r.visible || !r.blocked_at) this.line([A, B], 0x44ff66);
    else {
      const K = this.local(...r.blocked_at);
      this.line([A, K], 0x44ff66);
      this.line([K, B], 0xff4444);
    }
    this.say(`line of sight: <b>${r.visible ? 'visible' : 'blocked'}</b>` +
      (r.blocked_at ? ` at ${r.blocked_at.map((x) => x.toFixed(4)).join(', ')}` : ''));
    return r;
  }

  async contours(interval) {
    if (!(interval > 0)) throw new Error('contours: the interval must be a positive number');
    const fc = await this.v.api.contours(interval);
    const seg = [];
    let lines = 0;
    for (const f of fc.features || []) {
      const p = f.properties || {}, g = f.geometry || {};
      const parts = g.type === 'MultiLineString' ? g.coordinates : g.type === 'LineString' ? [g.coordinates] : [];
      for (const part of parts) {
        ++lines;
        for (let i = 1; i < part.length; ++i) {
          const z = (q) => (q.length > 2 ? q[2] : p.elev ?? p.elevation ?? p.level ?? 0);
          seg.push(this.local(part[i - 1][0], part[i - 1][1], z(part[i - 1])), this.local(part[i][0], part[i][1], z(part[i])));
        }
      }
    }
    if (seg.length) this.line(seg, 0x1a1a1a, true);
    this.say(`contours every ${interval}: ${lines} lines`);
    return { lines, segments: seg.length / 2 };
  }
}
