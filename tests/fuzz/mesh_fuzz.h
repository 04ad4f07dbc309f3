// The shared driver of the mesh reader fuzz targets: mesh_reader_fuzz.cpp (built once per
// format: mesh_ply_fuzz, mesh_obj_fuzz, mesh_off_fuzz, mesh_stl_fuzz) and mesh_stream_fuzz.cpp
// (the streamed PLY path the block builder reads, smr::open_mesh_stream). A target defines
// target(): its check of one input; the driver holds what they share: the independent check of
// validate_mesh's invariants, the seeds, the mutator, the smoke mode and the entry points.
//
// Built with -DSMRDB_LIBFUZZER=ON (clang, -fsanitize=fuzzer) each target is a libFuzzer target.
// Otherwise its main() runs the deterministic smoke mode registered with ctest
// (<target>_smoke): the generated seeds in the target's format (small valid and topologically
// broken files in every encoding of it), the real meshes in it under $SMRDB_DATA_DIR/meshes, and
// the smallest real mesh re-encoded in it, then mutations with a fixed-seed RNG (bit flips,
// interesting bytes, insertions, deletions, truncations, chunk copies, splices from the seeds of
// every format, numeric tokens replaced by huge / negative / NaN values, binary words
// overwritten).
//   <target> [iterations]      smoke mode (default Target::iterations; or
//                              $SMRDB_FUZZ_ITERATIONS; $SMRDB_FUZZ_SEED changes the RNG)
//   <target> FILE...           run the given inputs (to reproduce a failure)
#pragma once

#include <cstddef>
#include <functional>
#include <string>
#include <string_view>

#include "base/error.h"
#include "smr/io/mesh_reader.h"

namespace smr::fuzz {

/// The name inputs are parsed under (parse_mesh's `name`): every error message must contain it.
inline constexpr const char* kName = "fuzz-input";

struct Stats {
  std::size_t inputs = 0, parses = 0, valid = 0, errors = 0;
  std::size_t repaired = 0;  // valid meshes that needed a repair
};

/// Prints `why` and the input's first bytes, then aborts: a crash for libFuzzer and ctest alike.
[[noreturn]] void fail(const std::string& why, std::string_view input);

/// validate_mesh's documented invariants, checked independently (sorting and a union-find of its
/// own): indices in range, no degenerate or duplicate faces, every edge on one or two faces
/// traversed in opposite directions, one fan per vertex, every vertex referenced, finite
/// coordinates, a report that matches. Empty when they hold, else what is wrong.
std::string check_mesh(const TriangleMesh& m, const MeshReport& rep);

/// Fails unless `e`, thrown while reading `input`, is of a user kind (not kInternal) and its
/// message names `name`; `context` says what was being read.
void expect_user_error(const Error& e, std::string_view name, std::string_view input,
                       const std::string& context);

/// Parses `bytes` as `format` with no repair and with every repair: each parse gives a mesh that
/// passes check_mesh (no repair made unless asked) or throws a user smr::Error naming the input.
/// Anything else (another exception type, std::bad_alloc from a trusted count included,
/// kInternal, a crash, a sanitizer report) fails.
void check_parse(std::string_view bytes, MeshFormat format, Stats& stats);

struct Target {
  const char* name;   // e.g. "mesh_ply_fuzz", for messages
  MeshFormat format;  // the seeds: generated ones and real meshes in this format
  std::function<void(std::string_view bytes, Stats& stats)> run;  // checks one input
  std::size_t iterations = 10000;  // mutated inputs of a smoke run (about a second, release)
};

/// The target, defined by each target's source file. The driver defines main() (without
/// libFuzzer: the smoke mode or the given files, see above) and LLVMFuzzerTestOneInput, which
/// run it.
const Target& target();

}  // namespace smr::fuzz
