// The heads-up display: triangles, pages read, update time, frame rate, morph groups.
export class Hud {
  constructor(v) {
    this.v = v;
    this.el = document.getElementById('hud');
    this.last = 0;
  }
  update() {
    const now = performance.now();
    if (now - this.last < 200) return;
    this.last = now;
    const v = this.v, s = v.session, st = s.stats[s.stats.length - 1] || {};
    const f = (x, d = 1) => (x === undefined ? '-' : Number(x).toFixed(d));
    this.el.textContent = [
      `${v.api.db}  frame ${st.frame ?? '-'}${st.complete === false ? ' (pending)' : ''}`,
      `triangles   ${s.store.drawn} drawn / ${st.triangles ?? '-'} in session`,
      `last frame  +${st.triangles_in ?? 0} -${st.triangles_out ?? 0}, ${f(st.bytes / 1024)} KiB`,
      `pages read  ${st.pages_read ?? 0} (total ${s.pagesTotal})`,
      `update      ${f(st.update_ms)} ms (server ${f(st.server_ms)} ms)`,
      `morph       ${st.morph_groups ?? 0} groups, ${st.morph_triangles ?? 0} tris, t=${f(v.uniforms.t.value, 2)}`,
      `frame rate  ${v.fps} fps`,
      s.error ? `error: ${s.error.message}` : '',
    ].join('\n');
  }
}
