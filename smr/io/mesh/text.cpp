// Tokenizing and number parsing shared by the mesh readers (smr/io/mesh/text.h).
#include "smr/io/mesh/text.h"

#include <charconv>

namespace smr::mesh_io {

std::string num(double v) {
  char tmp[32];
  const auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
  return std::string(tmp, r.ptr);
}

std::string num(std::uint64_t v) {
  return std::to_string(v);
}

std::string pos_text(const Vec3& p) {
  // Built piecewise: GCC 12 reports a false -Wrestrict on "(" + std::string(...).
  std::string s = "(";
  s += num(p.x);
  s += ", ";
  s += num(p.y);
  s += ", ";
  s += num(p.z);
  s += ")";
  return s;
}

std::string at_line(std::size_t line) {
  return "line " + num(std::uint64_t{line});
}

}  // namespace smr::mesh_io
