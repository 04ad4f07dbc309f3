// Drawing a progressive session's mesh: the triangles the client holds (a slot buffer keyed by the
// frame's triangle keys) and the frame's morph mesh, geomorphed on the GPU (vertex shader
// mix(start, end, t), Brown ch. 6).
import * as THREE from 'three';

// The geomorph itself; shared by the drawing shader and the GPU read-back (main.js readMorph).
export const MORPH_GLSL = /* glsl */ `
uniform float t;
attribute vec3 start;
attribute vec3 end;
attribute float vflag; // the triangle's flags: bit 0 void at t = 0, bit 1 void at t = 1
vec3 morphPosition() {
  float f = vflag;
  bool voidNow = t < 0.5 ? mod(f, 2.0) >= 1.0 : f >= 2.0;
  return voidNow ? vec3(0.0) : mix(start, end, t); // a void piece collapses to a point
}
`;

const VERTEX = /* glsl */ `
#ifdef MORPH
${MORPH_GLSL}
attribute float group;
varying float vGroup;
#endif
attribute vec3 bary;
uniform float zOrigin;
varying vec3 vView;
varying float vHeight;
varying vec3 vBary;
void main() {
#ifdef MORPH
  vec3 p = morphPosition();
  vGroup = group;
#else
  vec3 p = position;
#endif
  vHeight = p.z + zOrigin;
  vBary = bary;
  vec4 mv = modelViewMatrix * vec4(p, 1.0);
  vView = mv.xyz;
  gl_Position = projectionMatrix * mv;
}
`;

const FRAGMENT = /* glsl */ `
uniform float zMin;
uniform float zMax;
uniform float wire;
uniform float tint;
uniform vec3 sun; // in view space
varying vec3 vView;
varying float vHeight;
varying vec3 vBary;
#ifdef MORPH
varying float vGroup;
#endif
vec3 ramp(float h) {
  vec3 c0 = vec3(0.16, 0.42, 0.22), c1 = vec3(0.55, 0.62, 0.33), c2 = vec3(0.60, 0.48, 0.35),
       c3 = vec3(0.95, 0.95, 0.95);
  if (h < 0.4) return mix(c0, c1, h / 0.4);
  if (h < 0.8) return mix(c1, c2, (h - 0.4) / 0.4);
  return mix(c2, c3, (h - 0.8) / 0.2);
}
void main() {
  vec3 n = normalize(cross(dFdx(vView), dFdy(vView)));
  float h = clamp((vHeight - zMin) / max(zMax - zMin, 1e-6), 0.0, 1.0);
  vec3 c = ramp(h) * (0.35 + 0.65 * max(dot(n, sun), 0.0));
#ifdef MORPH
  vec3 g = 0.5 + 0.5 * cos(6.2831 * (fract(vGroup * 0.618034) + vec3(0.0, 0.33, 0.67)));
  c = mix(c, g, tint);
#endif
  vec3 d = fwidth(vBary);
  vec3 e = smoothstep(vec3(0.0), d * 1.2, vBary);
  float edge = 1.0 - min(min(e.x, e.y), e.z);
  c = mix(c, vec3(0.08), edge * wire * 0.6);
  gl_FragColor = vec4(c, 1.0);
}
`;

/** The uniforms both materials share (one object, so a change reaches both). */
export function makeUniforms() {
  return {
    t: { value: 0 },
    zOrigin: { value: 0 },
    zMin: { value: 0 },
    zMax: { value: 1 },
    wire: { value: 1 },
    tint: { value: 0 },
    sun: { value: new THREE.Vector3(-0.4, 0.5, 0.75).normalize() },
  };
}

function material(uniforms, morph) {
  return new THREE.ShaderMaterial({
    uniforms,
    vertexShader: VERTEX,
    fragmentShader: FRAGMENT,
    defines: morph ? { MORPH: 1 } : {},
    side: THREE.DoubleSide,
  });
}

function baryArray(vertices) {
  const b = new Float32Array(vertices * 3);
  for (let v = 0; v < vertices; ++v) b[3 * v + (v % 3)] = 1;
  return b;
}

/** The triangles the client holds: key -> slot of 9 floats in one growing non-indexed buffer. */
export class TriangleStore {
  constructor(parent, uniforms) {
    this.uniforms = uniforms;
    this.slots = new Map(); // key -> slot (-1: a void triangle, held but not drawn)
    this.free = [];
    this.high = 0;
    this.drawn = 0;
    this.mesh = null;
    this.parent = parent;
    this.allocate(4096);
  }

  allocate(capacity) {
    const positions = new Float32Array(capacity * 9);
    if (this.mesh) {
      positions.set(this.positions.subarray(0, this.high * 9));
      this.parent.remove(this.mesh);
      this.mesh.geometry.dispose();
    }
    this.capacity = capacity;
    this.positions = positions;
    this.dirtyLo = Infinity; // a new buffer uploads whole
    this.dirtyHi = -1;
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    g.setAttribute('bary', new THREE.BufferAttribute(baryArray(capacity * 3), 3));
    this.mesh = new THREE.Mesh(g, this.material || (this.material = material(this.uniforms, false)));
    this.mesh.frustumCulled = false;
    this.parent.add(this.mesh);
  }

  get size() {
    return this.slots.size;
  }

  add(key, pos, offset, isVoid) {
    if (this.slots.has(key)) throw new Error(`triangle ${key} is already held`);
    if (isVoid) {
      this.slots.set(key, -1);
      return;
    }
    let slot = this.free.pop();
    if (slot === undefined) {
      if (this.high === this.capacity) this.allocate(this.capacity * 2);
      slot = this.high++;
    }
    this.positions.set(pos.subarray(offset, offset + 9), slot * 9);
    this.touch(slot);
    this.slots.set(key, slot);
    ++this.drawn;
  }

  remove(key) {
    const slot = this.slots.get(key);
    if (slot === undefined) throw new Error(`frame removes triangle ${key}, which is not held`);
    this.slots.delete(key);
    if (slot < 0) return;
    this.positions.fill(0, slot * 9, slot * 9 + 9); // degenerate: draws nothing
    this.touch(slot);
    this.free.push(slot);
    --this.drawn;
  }

  touch(slot) {
    this.dirtyLo = Math.min(this.dirtyLo, slot);
    this.dirtyHi = Math.max(this.dirtyHi, slot);
  }

  /** Uploads the slots changed since the last flush (one range) and sets the draw range. */
  flush() {
    const g = this.mesh.geometry, attr = g.attributes.position;
    if (this.dirtyHi >= this.dirtyLo) {
      attr.clearUpdateRanges();
      attr.addUpdateRange(this.dirtyLo * 9, (this.dirtyHi - this.dirtyLo + 1) * 9);
      attr.needsUpdate = true;
    }
    this.dirtyLo = Infinity;
    this.dirtyHi = -1;
    g.setDrawRange(0, this.high * 3);
  }
}

/** A frame's morph mesh, non-indexed (one vertex per triangle corner, attributes start/end). */
export class MorphMesh {
  constructor(parent, uniforms, frame) {
    const n = frame.mTris.length / 3;
    const start = new Float32Array(n * 9), end = new Float32Array(n * 9);
    const vflag = new Float32Array(n * 3), group = new Float32Array(n * 3);
    this.vertexOf = new Uint32Array(n * 3); // corner -> morph vertex of the frame
    for (let c = 0; c < n * 3; ++c) {
      const v = frame.mTris[c];
      this.vertexOf[c] = v;
      for (let k = 0; k < 3; ++k) {
        start[3 * c + k] = frame.mStart[3 * v + k];
        end[3 * c + k] = frame.mEnd[3 * v + k];
      }
      vflag[c] = frame.mFlags[(c / 3) | 0];
      group[c] = frame.mGroup[v];
    }
    const g = new THREE.BufferGeometry();
    g.setAttribute('start', new THREE.BufferAttribute(start, 3));
    g.setAttribute('end', new THREE.BufferAttribute(end, 3));
    g.setAttribute('vflag', new THREE.BufferAttribute(vflag, 1));
    g.setAttribute('group', new THREE.BufferAttribute(group, 1));
    g.setAttribute('bary', new THREE.BufferAttribute(baryArray(n * 3), 3));
    // three.js needs a position attribute for the draw count; the shader ignores it.
    g.setAttribute('position', new THREE.BufferAttribute(end, 3));
    this.mesh = new THREE.Mesh(g, material(uniforms, true));
    this.mesh.frustumCulled = false;
    this.parent = parent;
    parent.add(this.mesh);
  }

  get geometry() {
    return this.mesh.geometry;
  }

  dispose() {
    this.parent.remove(this.mesh);
    this.mesh.geometry.dispose();
    this.mesh.material.dispose();
  }
}
