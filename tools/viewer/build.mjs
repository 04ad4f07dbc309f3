// Builds dist/: index.html and bundle.js (three.js and the viewer, one minified IIFE).
import * as esbuild from 'esbuild';
import { copyFileSync, cpSync, mkdirSync } from 'node:fs';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const dist = join(here, 'dist');
mkdirSync(dist, { recursive: true });
await esbuild.build({
  entryPoints: [join(here, 'src/main.js')],
  bundle: true,
  minify: true,
  sourcemap: true,
  format: 'iife',
  target: 'es2020',
  outfile: join(dist, 'bundle.js'),
  logLevel: 'warning',
});
copyFileSync(join(here, 'index.html'), join(dist, 'index.html'));
// The CesiumJS page: Cesium's own prebuilt Build/Cesium (workers, assets) copied as it is.
copyFileSync(join(here, 'cesium.html'), join(dist, 'cesium.html'));
copyFileSync(join(here, 'src/cesium-page.js'), join(dist, 'cesium-page.js'));
cpSync(join(here, 'node_modules/cesium/Build/Cesium'), join(dist, 'cesium'), { recursive: true });
console.log(`viewer built in ${dist}`);
