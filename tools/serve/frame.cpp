// Frame encoding for smrdb serve (frame.h).
#include "tools/serve/frame.h"

#include <cstring>

namespace smr::serve {

namespace {

class Writer {
 public:
  explicit Writer(std::string& out) : out_(out) {}
  template <class T>
  void put(T v) {
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));  // little-endian machines only (x86-64, arm64)
    out_.append(b, sizeof(T));
  }
  void f32(double v) { put(static_cast<float>(v)); }
  void vec(const Vec3& p, const Vec3& origin) {
    f32(p.x - origin.x);
    f32(p.y - origin.y);
    f32(p.z - origin.z);
  }
  void pad4() {
    while (out_.size() % 4 != 0) out_.push_back('\0');
  }
  void bytes(const std::string& s) { out_ += s; }

 private:
  std::string& out_;
};

void keys(Writer& w, std::span<const TriRef> tris) {
  for (const TriRef& t : tris) {
    w.put(static_cast<std::uint32_t>(t.op.value & 0xffffffffu));
    w.put(static_cast<std::uint32_t>(t.op.value >> 32));
    w.put(t.index);
  }
}

}  // namespace

std::string encode_frame(const OpSource& source, const Vec3& origin, nlohmann::json header,
                         std::span<const TriRef> out, std::span<const TriRef> in,
                         const MorphMesh* morph) {
  const MorphMesh empty;
  const MorphMesh& m = morph != nullptr ? *morph : empty;
  header["n_out"] = out.size();
  header["n_in"] = in.size();
  header["n_mv"] = m.start.size();
  header["n_mt"] = m.triangles.size();
  header["origin"] = {origin.x, origin.y, origin.z};
  const std::string json = header.dump();
  std::string bytes;
  bytes.reserve(16 + json.size() + out.size() * 12 + in.size() * 49 + m.start.size() * 28 +
                m.triangles.size() * 13);
  Writer w(bytes);
  w.bytes("SMRF");
  w.put(kFrameVersion);
  w.put(static_cast<std::uint32_t>(json.size()));
  w.bytes(json);
  w.pad4();
  keys(w, out);
  keys(w, in);
  std::string flags;
  flags.reserve(in.size());
  OpRef op;
  for (const TriRef& t : in) {  // ascending: consecutive triangles share their op
    if (!op || op->id != t.op) op = source.op(t.op);
    const FragmentTriangle& tri = op->fragment[t.index];
    for (int k = 0; k < 3; ++k) w.vec(op->position(tri, k), origin);
    flags.push_back(tri.is_void() ? '\1' : '\0');
  }
  w.bytes(flags);
  w.pad4();
  for (const Vec3& p : m.start) w.vec(p, origin);
  for (const Vec3& p : m.end) w.vec(p, origin);
  for (const std::uint32_t g : m.group) w.put(g);
  for (const auto& t : m.triangles)
    for (const std::uint32_t v : t) w.put(v);
  for (const std::uint8_t f : m.flags) w.put(f);
  w.pad4();
  return bytes;
}

}  // namespace smr::serve
