// Parsing the server's binary progressive-session frame (SERVE_API.md, "Frame"):
// "SMRF", u32 version, u32 json_bytes, JSON padded to 4 bytes, then the sections
// out_keys, in_keys, in_pos, in_flags, m_start, m_end, m_group, m_tris, m_flags.

const MAGIC = 0x46524d53; // "SMRF" read as a little-endian u32

function pad4(n) {
  return (n + 3) & ~3;
}

/** Parses one frame; throws an Error naming what is wrong with a malformed buffer. */
export function parseFrame(buffer) {
  const view = new DataView(buffer);
  if (buffer.byteLength < 12 || view.getUint32(0, true) !== MAGIC)
    throw new Error('frame: expected the magic "SMRF" at byte 0');
  const version = view.getUint32(4, true);
  if (version !== 1) throw new Error(`frame: version ${version}, expected 1`);
  const jsonBytes = view.getUint32(8, true);
  if (12 + jsonBytes > buffer.byteLength) throw new Error('frame: JSON header runs past the end');
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 12, jsonBytes)));
  const nOut = header.n_out | 0, nIn = header.n_in | 0, nMv = header.n_mv | 0, nMt = header.n_mt | 0;
  let off = 12 + pad4(jsonBytes);
  const take = (Ctor, count, padTo4 = false) => {
    const bytes = count * Ctor.BYTES_PER_ELEMENT;
    if (off + bytes > buffer.byteLength)
      throw new Error(`frame ${header.frame}: section at byte ${off} runs past the end`);
    const a = new Ctor(buffer, off, count);
    off += padTo4 ? pad4(bytes) : bytes;
    return a;
  };
  const frame = {
    header,
    outKeys: take(Uint32Array, nOut * 3),
    inKeys: take(Uint32Array, nIn * 3),
    inPos: take(Float32Array, nIn * 9),
    inFlags: take(Uint8Array, nIn, true),
    mStart: take(Float32Array, nMv * 3),
    mEnd: take(Float32Array, nMv * 3),
    mGroup: take(Uint32Array, nMv),
    mTris: take(Uint32Array, nMt * 3),
    mFlags: take(Uint8Array, nMt, true),
    bytes: buffer.byteLength,
  };
  for (let i = 0; i < frame.mTris.length; ++i)
    if (frame.mTris[i] >= nMv)
      throw new Error(`frame ${header.frame}: morph triangle ${(i / 3) | 0} indexes vertex ${frame.mTris[i]} of ${nMv}`);
  return frame;
}

/** The map key of triangle i of a key section (op id low, op id high, triangle index). */
export function keyAt(keys, i) {
  return `${keys[3 * i]}:${keys[3 * i + 1]}:${keys[3 * i + 2]}`;
}
