// Camera paths (model coordinates, the format of `smrdb flythrough --path`:
// [{"eye": [x, y, z], "target": [x, y, z], "fov": deg}, ...]).

/**
 * One turn around the model (a camera per degree), like `smrdb flythrough --orbit` but measured in
 * display metres (a geographic raster's degrees converted) and farther out, so that the whole
 * terrain is in view: at 0.6 of the horizontal extent from the centre and 0.45 of it above the
 * highest point.
 */
export function orbitPath(info, bounds, fov) {
  const lo = bounds.min, hi = bounds.max;
  const c = [0, 1, 2].map((i) => 0.5 * (lo[i] + hi[i]));
  const g = info.georef || (info.meta && info.meta.model && info.meta.model.georef);
  const sx = g && g.geographic ? 111320 * Math.cos((c[1] * Math.PI) / 180) : 1;
  const sy = g && g.geographic ? 110574 : 1;
  const e = Math.max((hi[0] - lo[0]) * sx, (hi[1] - lo[1]) * sy);
  const terrain = (info.kind || (info.meta && info.meta.model && info.meta.model.kind)) !== 'mesh';
  let radius = 0.6 * e, height = hi[2] + 0.45 * e;
  if (!terrain) {
    const d = (1.2 * 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2])) / Math.sin((fov * Math.PI) / 360);
    radius = d * Math.cos(Math.PI / 9);
    height = c[2] + d * Math.sin(Math.PI / 9);
  }
  const cams = [];
  for (let deg = 0; deg <= 360; ++deg) {
    const a = (deg * Math.PI) / 180;
    cams.push({ eye: [c[0] + (radius * Math.cos(a)) / sx, c[1] + (radius * Math.sin(a)) / sy, height], target: c, fov });
  }
  return cams;
}

const lerp = (a, b, u) => a.map((x, i) => x + (b[i] - x) * u);

/** The camera at u in [0, 1] along the path (linear between consecutive cameras, by index). */
export function samplePath(cams, u) {
  if (cams.length === 1) return cams[0];
  const s = Math.min(Math.max(u, 0), 1) * (cams.length - 1);
  const i = Math.min(Math.floor(s), cams.length - 2), f = s - i;
  const a = cams[i], b = cams[i + 1];
  return { eye: lerp(a.eye, b.eye, f), target: lerp(a.target, b.target, f), fov: a.fov && b.fov ? a.fov + (b.fov - a.fov) * f : a.fov || b.fov };
}

function validate(cams, where) {
  if (!Array.isArray(cams) || cams.length === 0) throw new Error(`path ${where}: expected a non-empty JSON list of cameras`);
  cams.forEach((c, i) => {
    for (const k of ['eye', 'target'])
      if (!Array.isArray(c[k]) || c[k].length !== 3 || !c[k].every(Number.isFinite))
        throw new Error(`path ${where}: camera ${i} needs "${k}": [x, y, z] of finite numbers`);
  });
  return cams;
}

/** ?path=orbit, ?path=[...] (JSON in the URL) or ?path=URL of a JSON file. */
export async function loadPath(path, info, bounds, fov) {
  if (path === 'orbit') return orbitPath(info, bounds, fov);
  if (path.trim().startsWith('[')) return validate(JSON.parse(path), '(inline)');
  const res = await fetch(path);
  if (!res.ok) throw new Error(`path ${path}: ${res.status} ${res.statusText}`);
  return validate(await res.json(), path);
}
