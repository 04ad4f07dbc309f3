// The browser viewer in a real browser: Debian's chromium, headless, WebGL2 through SwiftShader,
// driven by puppeteer-core. Starts `smrdb serve` on a database ingested from a small real DEM,
// loads tools/viewer/dist, and checks from the page that
//   - the session converges: the triangles the viewer holds are the server's mesh, frame by frame
//     statistics are sane (triangles > 0, update times recorded), frames apply and render;
//   - geomorphs run on the GPU: at t = 0.5 the morph vertices read back from the shader lie
//     strictly between their start and end, at t = 1 they are the end;
//   - the terrain renders: a screenshot covers the view with terrain, matches a committed
//     reference (mean difference bound), and a second render of the same camera after a flight
//     matches the first;
//   - the query overlay answers (elevation, contours);
//   - with --cesium: cesium.html loads the server's quantized-mesh tiles of the DEM as it is.
// Usage: node viewer_test.mjs --smrdb BIN --dem FILE [--warp SRS] [--cesium] --viewer DIST --reference PNG
//        [--update-reference] [--shots DIR]   (or --url URL --db NAME: an already running server)
import { spawn, execFileSync } from 'node:child_process';
import { mkdtempSync, rmSync, readFileSync, writeFileSync, mkdirSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join, resolve } from 'node:path';
import { createRequire } from 'node:module';

const args = Object.fromEntries(
  process.argv.slice(2).reduce((acc, a, i, all) => {
    if (a.startsWith('--')) acc.push([a.slice(2), all[i + 1] && !all[i + 1].startsWith('--') ? all[i + 1] : true]);
    return acc;
  }, []),
);
// puppeteer-core and pngjs are the viewer's devDependencies (tools/viewer/node_modules).
const require = createRequire(resolve(args.viewer || '.', '..', 'package.json'));
const puppeteer = require('puppeteer-core');
const { PNG } = require('pngjs');

let passed = 0, failed = 0;
function check(ok, what) {
  if (ok) ++passed;
  else ++failed;
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${what}`);
}

function startServer(dir) {
  const db = join(dir, 'terrain.smrdb');
  let dem = args.dem;
  if (args.warp) {
    // The camera RCF works in model coordinates: on a geographic raster (x, y in degrees, z in
    // metres) every view looks straight down to it and nothing refines. A projected copy of the
    // real DEM (GDAL, metres) gives the session work to do.
    dem = join(dir, 'dem.tif');
    execFileSync('gdalwarp', ['-q', '-t_srs', args.warp, '-r', 'bilinear', args.dem, dem], { stdio: 'inherit' });
  }
  execFileSync(args.smrdb, ['ingest', dem, '-o', db, '--force'], { stdio: ['ignore', 'ignore', 'inherit'] });
  const dbs = [`terrain=${db}`];
  if (args.cesium) {
    // CesiumJS needs the geographic (EPSG:4326) tiling: the DEM as it is.
    execFileSync(args.smrdb, ['ingest', args.dem, '-o', join(dir, 'geo.smrdb'), '--force'], { stdio: ['ignore', 'ignore', 'inherit'] });
    dbs.push(`geo=${join(dir, 'geo.smrdb')}`);
  }
  const proc = spawn(args.smrdb, ['serve', ...dbs, '--port', '0', '--viewer', args.viewer], { stdio: ['ignore', 'pipe', 'inherit'] });
  return new Promise((resolve, reject) => {
    let out = '';
    const timer = setTimeout(() => reject(new Error(`smrdb serve printed no URL: ${out}`)), 15000);
    proc.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/listening on (http:\/\/\S+)/);
      if (m) {
        clearTimeout(timer);
        resolve({ proc, url: m[1].endsWith('/') ? m[1] : `${m[1]}/`, db: 'terrain' });
      }
    });
    proc.on('exit', (code) => reject(new Error(`smrdb serve exited with ${code}: ${out}`)));
  });
}

function decode(buf) {
  return PNG.sync.read(buf);
}

/** Fraction of pixels that differ from the background colour, and the mean |difference| of two images. */
function coverage(img, bg = [0x1b, 0x23, 0x30]) {
  let n = 0;
  for (let i = 0; i < img.data.length; i += 4)
    if (Math.abs(img.data[i] - bg[0]) + Math.abs(img.data[i + 1] - bg[1]) + Math.abs(img.data[i + 2] - bg[2]) > 12) ++n;
  return n / (img.width * img.height);
}
function meanDiff(a, b) {
  if (a.width !== b.width || a.height !== b.height) return Infinity;
  let s = 0;
  for (let i = 0; i < a.data.length; i += 4)
    s += Math.abs(a.data[i] - b.data[i]) + Math.abs(a.data[i + 1] - b.data[i + 1]) + Math.abs(a.data[i + 2] - b.data[i + 2]);
  return s / (3 * a.width * a.height);
}

async function geomorph(page) {
  // Hold t, move the camera closer so that the session refines, and read the morph back.
  const r = await page.evaluate(async () => {
    const v = window.smrdbViewer;
    v.holdMorph(0.5);
    const c = v.camera(), k = 0.5;
    v.setView({ eye: c.eye.map((e, i) => c.target[i] + (e - c.target[i]) * k), target: c.target });
    const t0 = performance.now();
    while (!v.hasMorph() && performance.now() - t0 < 15000) await new Promise((s) => setTimeout(s, 20));
    if (!v.hasMorph()) return null;
    v.render();
    const mid = v.readMorph(20000);
    v.holdMorph(1);
    v.render();
    const end = v.readMorph(20000);
    v.holdMorph(null);
    await v.waitIdle(20000);
    return { mid, end };
  });
  check(r !== null, 'a camera move closer produces a frame with a morph');
  if (!r) return;
  let moving = 0, between = 0, atMix = 0, atEnd = 0, corners = 0;
  const close = (a, b) => Math.abs(a - b) <= 1e-4 * (1 + Math.abs(b));
  for (let i = 0; i < r.mid.corners; ++i) {
    if (r.mid.flags[i] !== 0) continue; // void pieces collapse; not drawn
    ++corners;
    const s = r.mid.start[i], e = r.mid.end[i], g = r.mid.gpu[i], ge = r.end.gpu[i];
    if (e.every((x, k) => close(ge[k], x))) ++atEnd;
    if (g.every((x, k) => close(x, 0.5 * (s[k] + e[k])))) ++atMix;
    const k = [0, 1, 2].reduce((best, j) => (Math.abs(e[j] - s[j]) > Math.abs(e[best] - s[best]) ? j : best), 0);
    if (Math.abs(e[k] - s[k]) > 1e-3 * (1 + Math.abs(e[k]))) {
      ++moving;
      if (g[k] > Math.min(s[k], e[k]) && g[k] < Math.max(s[k], e[k])) ++between;
    }
  }
  console.log(`     morph: ${r.mid.corners} corners read back, ${moving} moving, t=${r.mid.t} then ${r.end.t}`);
  check(moving > 0, 'the morph moves some vertices (start != end)');
  check(moving > 0 && between === moving, `at t = 0.5 every moving vertex lies strictly between start and end (${between}/${moving})`);
  check(corners > 0 && atMix === corners, `at t = 0.5 the GPU position is mix(start, end, 0.5) (${atMix}/${corners})`);
  check(corners > 0 && atEnd === corners, `at t = 1 the GPU position equals end (${atEnd}/${corners})`);
}

async function snapshot(page) {
  await page.evaluate(() => {
    for (const id of ['hud', 'tools', 'query', 'chart']) document.getElementById(id).style.visibility = 'hidden';
    window.smrdbViewer.render();
  });
  const png = await page.screenshot({ type: 'png' });
  await page.evaluate(() => {
    for (const id of ['hud', 'tools', 'query', 'chart']) document.getElementById(id).style.visibility = '';
  });
  return png;
}

async function run(url, db) {
  const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    headless: true,
    args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist', '--no-sandbox', '--disable-dev-shm-usage'],
  });
  try {
    const page = await browser.newPage();
    page.on('pageerror', (e) => console.log(`page error: ${e.message}`));
    page.on('console', (m) => m.type() === 'error' && !m.text().includes('favicon') && console.log(`page console: ${m.text()}`));
    await page.setViewport({ width: 480, height: 320 });
    await page.goto(`${url}index.html?db=${db}&morph_ms=200&px=2`);
    await page.waitForFunction('window.smrdbViewer && (window.smrdbViewer.ready || window.smrdbViewer.error)', { timeout: 20000 });
    const err = await page.evaluate(() => window.smrdbViewer.error || null);
    check(!err, `the viewer opens the database${err ? `: ${err}` : ''}`);
    if (err) return;
    const webgl2 = await page.evaluate(() => window.smrdbViewer.viewer.renderer.capabilities.isWebGL2);
    check(webgl2, 'WebGL2 is available (SwiftShader)');
    const home = await page.evaluate(async () => {
      const v = window.smrdbViewer;
      const c = v.orbit(8)[0];
      await v.flyPath([c]);
      return c;
    });
    const first = decode(await snapshot(page));
    await geomorph(page);
    const fly = await page.evaluate(async (homeCam) => {
      const v = window.smrdbViewer;
      const n0 = v.stats.length;
      const path = v.orbit(8).slice(1);
      await v.flyPath(path);
      await v.flyPath([homeCam]);
      const last = v.stats[v.stats.length - 1];
      return { frames: v.stats.slice(n0), all: v.stats.length, held: v.held(), last, fps: v.fps };
    }, home);
    const frames = fly.frames;
    console.log(`     flight: ${frames.length} frames, last ${fly.last.triangles} triangles, ${fly.held.drawn} drawn, ${fly.fps} fps`);
    check(frames.length >= 8, `the flight applied frames (${frames.length} for 8 cameras)`);
    check(frames.every((f) => f.triangles > 0), 'every frame has triangles > 0');
    check(frames.every((f) => Number.isFinite(f.update_ms) && f.update_ms > 0), 'every frame records its update time');
    check(frames.some((f) => f.morph_groups > 0), 'some frames geomorph (morph_groups > 0)');
    check(fly.held.held === fly.last.triangles, `the viewer holds the server's mesh (${fly.held.held} = ${fly.last.triangles} triangles)`);
    check(fly.held.drawn > 0, 'the viewer draws triangles');
    const againPng = await snapshot(page);
    const again = decode(againPng);
    const cov = coverage(first);
    check(cov > 0.3, `the render shows terrain (${(100 * cov).toFixed(1)} % of pixels not background)`);
    const d2 = meanDiff(first, again);
    check(d2 < 2, `a second render of the same camera after the flight matches the first (mean diff ${d2.toFixed(2)})`);
    if (args['update-reference']) writeFileSync(args.reference, againPng);
    const ref = decode(readFileSync(args.reference));
    const dr = meanDiff(again, ref);
    check(dr < 12, `the render matches the reference ${args.reference} (mean diff ${dr.toFixed(2)} of 255)`);
    const q = await page.evaluate(async () => {
      const v = window.smrdbViewer.viewer, o = v.frame.origin;
      const e = await v.overlay.elevation([o[0], o[1]]);
      const c = await v.overlay.contours(Number(document.getElementById('interval').value));
      // A profile across the middle and a sight line from high above to the centre.
      const w = 0.25 * (v.bounds.max[0] - v.bounds.min[0]);
      const p = await v.overlay.profile([o[0] - w, o[1]], [o[0] + w, o[1]]);
      const s = await v.overlay.los([o[0], o[1], v.bounds.max[2] + 1000], [o[0] + w, o[1], e.z]);
      const chart = document.getElementById('chart').style.display;
      return { z: e.z, lines: c.lines, lo: v.bounds.min[2], hi: v.bounds.max[2], profile: p.points.length, chart,
               overlay: v.overlay.objects.children.length, sight: typeof s.visible };
    });
    check(Number.isFinite(q.z) && q.z >= q.lo - 1 && q.z <= q.hi + 1, `elevation at the centre is within the bounds (${q.z})`);
    check(q.lines > 0, `contours draw lines (${q.lines})`);
    check(q.profile > 2 && q.chart === 'block', `a profile is charted (${q.profile} points)`);
    check(q.sight === 'boolean' && q.overlay >= 4, `a line of sight is answered and drawn (${q.overlay} overlay objects)`);
    if (args.shots) await shots(page, args.shots);
    if (args.cesium) await cesium(browser, url);
  } finally {
    await browser.close();
  }
}

/** cesium.html: CesiumJS's own CesiumTerrainProvider loads the server's quantized-mesh tiles. */
async function cesium(browser, url) {
  const page = await browser.newPage();
  await page.setViewport({ width: 480, height: 320 });
  await page.goto(`${url}cesium.html?db=geo`, { waitUntil: "domcontentloaded", timeout: 90000 });
  const done = 'window.smrdbCesium && (window.smrdbCesium.failed || window.smrdbCesium.errors.length > 0 || ' +
    '(window.smrdbCesium.ready && window.smrdbCesium.tilesLoaded > 0))';
  await page.waitForFunction(done, { timeout: 90000 }).catch(() => {});
  const r = await page.evaluate(() => ({ loaded: window.smrdbCesium.tilesLoaded, errors: window.smrdbCesium.errors }));
  check(r.loaded > 0 && r.errors.length === 0, `CesiumJS loads the tiles (${r.loaded} tiles${r.errors.length ? `; ${r.errors[0]}` : ''})`);
  await page.close();
}

/** Writes a screenshot with 4 bits per channel (smaller files for the results directory). */
function small(png, path) {
  const img = decode(png);
  for (let i = 0; i < img.data.length; ++i) if (i % 4 !== 3) img.data[i] &= 0xf0;
  writeFileSync(path, PNG.sync.write(img, { colorType: 2 }));
}

/** A fly-through's screenshots for benchmarks/results/viewer: two orbit cameras, and one move
 *  closer held at t = 0.5 with the morph groups tinted. */
async function shots(page, dir) {
  mkdirSync(dir, { recursive: true });
  await page.setViewport({ width: 360, height: 225 });
  await page.evaluate(() => {
    window.smrdbViewer.viewer.overlay.clear();
    for (const id of ['tools', 'query', 'chart']) document.getElementById(id).style.visibility = 'hidden';
  });
  // Two orbit cameras pulled back to see the whole terrain.
  const cams = await page.evaluate(() =>
    window.smrdbViewer.orbit(2).map((c) => ({ ...c, eye: c.eye.map((e, k) => c.target[k] + 1.6 * (e - c.target[k])) })));
  for (let i = 0; i < 2; ++i) {
    await page.evaluate(async (c) => window.smrdbViewer.flyPath([c]), cams[i]);
    await new Promise((r) => setTimeout(r, 300)); // the HUD refreshes every 200 ms
    await page.evaluate(() => window.smrdbViewer.render());
    small(await page.screenshot({ type: 'png' }), join(dir, `flythrough_${i}.png`));
  }
  const held = await page.evaluate(async () => {
    const v = window.smrdbViewer;
    v.viewer.uniforms.tint.value = 0.6;
    v.holdMorph(0.5);
    const c = v.camera();
    v.setView({ eye: c.eye.map((e, i) => c.target[i] + (e - c.target[i]) * 0.4), target: c.target });
    const t0 = performance.now();
    while (!v.hasMorph() && performance.now() - t0 < 15000) await new Promise((r) => setTimeout(r, 20));
    await new Promise((r) => setTimeout(r, 300)); // the HUD refreshes every 200 ms
    v.render();
    return v.hasMorph();
  });
  if (held) small(await page.screenshot({ type: 'png' }), join(dir, 'geomorph_t0.5.png'));
  await page.evaluate(() => window.smrdbViewer.holdMorph(null));
}

async function main() {
  const t0 = Date.now();
  let server = null, dir = null;
  try {
    let url = args.url, db = args.db;
    if (!url) {
      dir = mkdtempSync(join(tmpdir(), 'smrdb-viewer-'));
      server = await startServer(dir);
      ({ url, db } = server);
    }
    await run(url, db);
  } catch (e) {
    check(false, `unexpected error: ${e.stack || e}`);
  } finally {
    if (server) server.proc.kill('SIGTERM');
    if (dir) rmSync(dir, { recursive: true, force: true });
  }
  console.log(`viewer test: ${((Date.now() - t0) / 1000).toFixed(1)} s`);
  console.log(`${passed} passed, ${failed} failed`);
  process.exit(failed === 0 && passed > 0 ? 0 : 1);
}

main();
