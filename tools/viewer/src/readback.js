// Reading the running morph back from the GPU: the morph mesh's own start/end/vflag attributes
// (the live BufferAttributes, shared) drawn as one point per corner into a float render target by
// a shader that runs the same morphPosition() as the terrain's vertex shader.
import * as THREE from 'three';
import { MORPH_GLSL } from './terrain.js';

const WIDTH = 256;

export function readMorph(v, limit = 4096) {
  const morph = v.session.morph;
  if (!morph) return null;
  const g = morph.mesh.geometry;
  const corners = Math.min(g.attributes.start.count, limit);
  const height = Math.ceil(corners / WIDTH);
  const pg = new THREE.BufferGeometry();
  for (const name of ['start', 'end', 'vflag']) pg.setAttribute(name, g.attributes[name]);
  const index = new Float32Array(g.attributes.start.count);
  for (let i = 0; i < index.length; ++i) index[i] = i;
  pg.setAttribute('corner', new THREE.BufferAttribute(index, 1));
  pg.setAttribute('position', g.attributes.start);
  pg.setDrawRange(0, corners);
  const mat = new THREE.ShaderMaterial({
    uniforms: { t: v.uniforms.t },
    vertexShader: `${MORPH_GLSL}
      attribute float corner;
      varying vec3 vP;
      void main() {
        vP = morphPosition();
        vec2 px = vec2(mod(corner, ${WIDTH}.0), floor(corner / ${WIDTH}.0)) + 0.5;
        gl_Position = vec4(px / vec2(${WIDTH}.0, ${height}.0) * 2.0 - 1.0, 0.0, 1.0);
        gl_PointSize = 1.0;
      }`,
    fragmentShader: `varying vec3 vP; void main() { gl_FragColor = vec4(vP, 1.0); }`,
  });
  const points = new THREE.Points(pg, mat);
  points.frustumCulled = false;
  const scene = new THREE.Scene();
  scene.add(points);
  const rt = new THREE.WebGLRenderTarget(WIDTH, height, {
    type: THREE.FloatType, format: THREE.RGBAFormat, minFilter: THREE.NearestFilter,
    magFilter: THREE.NearestFilter, depthBuffer: false,
  });
  const buf = new Float32Array(WIDTH * height * 4);
  const prev = v.renderer.getRenderTarget();
  v.renderer.setRenderTarget(rt);
  v.renderer.setClearColor(0x000000, 0);
  v.renderer.clear();
  v.renderer.render(scene, new THREE.Camera());
  v.renderer.readRenderTargetPixels(rt, 0, 0, WIDTH, height, buf);
  v.renderer.setRenderTarget(prev);
  v.renderer.setClearColor(0x1b2330, 1);
  rt.dispose();
  mat.dispose();
  const s = g.attributes.start.array, e = g.attributes.end.array, f = g.attributes.vflag.array;
  const out = { t: v.uniforms.t.value, corners, start: [], end: [], gpu: [], flags: [] };
  for (let i = 0; i < corners; ++i) {
    out.start.push([s[3 * i], s[3 * i + 1], s[3 * i + 2]]);
    out.end.push([e[3 * i], e[3 * i + 1], e[3 * i + 2]]);
    out.gpu.push([buf[4 * i], buf[4 * i + 1], buf[4 * i + 2]]);
    out.flags.push(f[i]);
  }
  return out;
}
