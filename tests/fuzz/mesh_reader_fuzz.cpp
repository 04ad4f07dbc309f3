// Fuzz target for one mesh reader (smr/io/mesh_reader.h), built once per format with
// SMRDB_FUZZ_FORMAT naming it (tests/fuzz/CMakeLists.txt): mesh_ply_fuzz (ascii and both binary
// byte orders), mesh_obj_fuzz, mesh_off_fuzz, mesh_stl_fuzz (ascii and binary). Every input is
// parsed in that format, with no repair and with every repair: each parse must return a mesh
// that satisfies the documented invariants (checked independently by the driver, mesh_fuzz.h) or
// throw smr::Error of a user kind whose message names the input. The driver holds the seeds,
// the mutator, the smoke mode and the entry points.
#include <string_view>

#include "tests/fuzz/mesh_fuzz.h"

#if !defined(SMRDB_FUZZ_FORMAT) || !defined(SMRDB_FUZZ_NAME)
#error "SMRDB_FUZZ_FORMAT (kPly, kObj, kOff or kStl) and SMRDB_FUZZ_NAME must be defined"
#endif

namespace smr::fuzz {

const Target& target() {
  static const Target t{SMRDB_FUZZ_NAME, MeshFormat::SMRDB_FUZZ_FORMAT,
                        [](std::string_view bytes, Stats& stats) {
                          check_parse(bytes, MeshFormat::SMRDB_FUZZ_FORMAT, stats);
                        }};
  return t;
}

}  // namespace smr::fuzz
