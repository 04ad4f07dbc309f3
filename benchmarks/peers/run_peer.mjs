#!/usr/bin/env node
// Runs a peer terrain triangulator on a float32 .npy DEM (written by smr::write_npy: shape
// (rows, cols), row 0 first, C order) at a given max vertical error, and reports
// {peer, seconds, vertices, triangles, rss_mb, ...} as JSON on stdout. With --out-mesh it also
// writes the mesh in the SMRGRID1 format of benchmarks/bench_common.h, so that bench_check can
// verify the peer's error bound on every sample with the same exact checker as ours.
//
//   node run_peer.mjs --peer delatin|martini --npy dem.npy --max-error 1.6 [--out-mesh m.bin]
//                     [--repeat N]
//
// Peers (APIs as in node_modules/<peer>/index.js):
//   delatin          new Delatin(data, width, height); tin.run(maxError): greedy Delaunay
//                    insertion (Garland & Heckbert 1995), a port of fogleman/hmm; refines while
//                    its max error > maxError. Output tin.coords (x, y pairs), tin.triangles.
//   @mapbox/martini  new Martini(size).createTile(terrain).getMesh(maxError): right-triangulated
//                    irregular network (Evans et al. 1997) on a (2^k+1)^2 grid. Its error measure
//                    is the RTIN midpoint error accumulated over the hierarchy, not the exact max
//                    over the final triangles' samples; bench_check measures the latter.
// Timing covers only the triangulation: not reading the file, not writing the dump.
// `seconds` is delatin's constructor + run, or martini's createTile + getMesh; martini's
// per-grid-size constructor (reusable across tiles) is reported separately as setup_seconds.
//
// --repeat N (martini only): getMesh runs N times on the same tile in this process, as a tile
// server extracts meshes from a tile it has prepared. get_mesh_seconds stays the first call (the
// JIT cold); get_mesh_seconds_all has every call, get_mesh_warm_median / get_mesh_warm_min are over
// the calls after the first (the first alone when N = 1), get_mesh_triangles_per_second is
// triangles / get_mesh_warm_median, and create_tile_seconds is the preprocessing (the error map)
// done once per tile.
import { readFileSync, writeFileSync } from 'node:fs';
import { performance } from 'node:perf_hooks';
import process from 'node:process';

function parseArgs(argv) {
  const args = {};
  for (let i = 2; i < argv.length; i++) {
    const a = argv[i];
    if (!a.startsWith('--')) throw new Error(`unexpected argument ${a}`);
    const key = a.slice(2);
    const value = argv[i + 1];
    if (value === undefined || value.startsWith('--')) throw new Error(`--${key} needs a value`);
    args[key] = value;
    i++;
  }
  return args;
}

function readNpyFloat32(path) {
  const buf = readFileSync(path);
  const magic = buf.subarray(0, 6).toString('latin1');
  if (magic !== '\x93NUMPY') throw new Error(`${path}: not a .npy file`);
  const major = buf[6];
  let headerLen, offset;
  if (major === 1) {
    headerLen = buf.readUInt16LE(8);
    offset = 10;
  } else {
    headerLen = buf.readUInt32LE(8);
    offset = 12;
  }
  const header = buf.subarray(offset, offset + headerLen).toString('latin1');
  const descr = /'descr':\s*'([^']+)'/.exec(header);
  const fortran = /'fortran_order':\s*(True|False)/.exec(header);
  const shape = /'shape':\s*\((\d+),\s*(\d+),?\s*\)/.exec(header);
  if (!descr || descr[1] !== '<f4') throw new Error(`${path}: expected dtype <f4, header ${header}`);
  if (!fortran || fortran[1] !== 'False') throw new Error(`${path}: expected C order`);
  if (!shape) throw new Error(`${path}: expected a 2-D array, header ${header}`);
  const rows = Number(shape[1]);
  const cols = Number(shape[2]);
  const start = offset + headerLen;
  if (buf.length - start < rows * cols * 4) throw new Error(`${path}: truncated data`);
  // Copy into an aligned buffer (the data offset need not be a multiple of 4).
  const data = new Float32Array(rows * cols);
  new Uint8Array(data.buffer).set(buf.subarray(start, start + rows * cols * 4));
  return { data, rows, cols };
}

function median(v) {
  const s = [...v].sort((a, b) => a - b);
  const n = s.length;
  return n % 2 === 1 ? s[(n - 1) / 2] : (s[n / 2 - 1] + s[n / 2]) / 2;
}

function writeMesh(path, coords, triangles) {
  // SMRGRID1: magic, uint32 V, uint32 T, V x (col, row), T x (a, b, c); little-endian.
  const nv = coords.length / 2;
  const nt = triangles.length / 3;
  const out = Buffer.alloc(16 + nv * 8 + nt * 12);
  out.write('SMRGRID1', 0, 'latin1');
  out.writeUInt32LE(nv, 8);
  out.writeUInt32LE(nt, 12);
  const body = new Uint32Array(out.buffer, out.byteOffset + 16, nv * 2 + nt * 3);
  for (let i = 0; i < nv * 2; i++) body[i] = coords[i];
  for (let i = 0; i < nt * 3; i++) body[nv * 2 + i] = triangles[i];
  writeFileSync(path, out);
}

async function main() {
  const args = parseArgs(process.argv);
  const peer = args.peer;
  const maxError = Number(args['max-error']);
  const repeat = Number(args.repeat ?? 1);
  if (!args.npy || !(maxError >= 0) || !(Number.isInteger(repeat) && repeat >= 1)) {
    throw new Error('usage: --peer delatin|martini --npy dem.npy --max-error M [--out-mesh m.bin] [--repeat N]');
  }
  if (repeat > 1 && peer !== 'martini') throw new Error('--repeat is for martini only (delatin runs once per instance)');
  const tRead = performance.now();
  const { data, rows, cols } = readNpyFloat32(args.npy);
  const readSeconds = (performance.now() - tRead) / 1000;

  const result = { peer, npy: args.npy, width: cols, height: rows, max_error: maxError, read_seconds: readSeconds };
  let coords, triangles;
  if (peer === 'delatin') {
    const { default: Delatin } = await import('delatin');
    const t0 = performance.now();
    const tin = new Delatin(data, cols, rows);
    tin.run(maxError);
    result.seconds = (performance.now() - t0) / 1000;
    result.reported_max_error = tin.getMaxError();
    coords = tin.coords;
    triangles = tin.triangles;
    result.version = JSON.parse(readFileSync(new URL('./node_modules/delatin/package.json', import.meta.url))).version;
  } else if (peer === 'martini') {
    const { default: Martini } = await import('@mapbox/martini');
    if (rows !== cols || ((rows - 1) & (rows - 2)) !== 0) {
      throw new Error(`martini needs a (2^k+1) x (2^k+1) grid, got ${cols} x ${rows}`);
    }
    const t0 = performance.now();
    const martini = new Martini(rows);
    const t1 = performance.now();
    const tile = martini.createTile(data);
    const t2 = performance.now();
    const mesh = tile.getMesh(maxError);
    const t3 = performance.now();
    const calls = [(t3 - t2) / 1000];
    for (let i = 1; i < repeat; i++) {
      const s = performance.now();
      const again = tile.getMesh(maxError);
      calls.push((performance.now() - s) / 1000);
      if (again.triangles.length !== mesh.triangles.length) throw new Error('getMesh is not deterministic');
    }
    result.setup_seconds = (t1 - t0) / 1000;
    result.create_tile_seconds = (t2 - t1) / 1000;
    result.get_mesh_seconds = (t3 - t2) / 1000;
    result.seconds = (t3 - t1) / 1000;
    const warm = calls.length > 1 ? calls.slice(1) : calls;
    result.get_mesh_repeat = repeat;
    result.get_mesh_seconds_all = calls;
    result.get_mesh_warm_median = median(warm);
    result.get_mesh_warm_min = Math.min(...warm);
    result.get_mesh_triangles_per_second = mesh.triangles.length / 3 / result.get_mesh_warm_median;
    coords = mesh.vertices;
    triangles = mesh.triangles;
    result.version = JSON.parse(readFileSync(new URL('./node_modules/@mapbox/martini/package.json', import.meta.url))).version;
  } else {
    throw new Error(`--peer must be delatin or martini, got ${peer}`);
  }
  result.vertices = coords.length / 2;
  result.triangles = triangles.length / 3;
  const usage = process.resourceUsage();
  result.rss_mb = usage.maxRSS / 1024; // peak, KiB -> MiB (includes the loaded DEM)
  result.node = process.version;
  if (args['out-mesh']) {
    writeMesh(args['out-mesh'], coords, triangles);
    result.mesh_dump = args['out-mesh'];
  }
  process.stdout.write(JSON.stringify(result, null, 2) + '\n');
}

main().catch((e) => {
  process.stderr.write(`run_peer: ${e.message}\n`);
  process.exit(1);
});
