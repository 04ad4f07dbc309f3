// The JavaScript tools the tests run with node (tests/js: `npm ci` there installs them;
// scripts/install-deps.sh does). A missing node or module is a test FAILURE naming what to run,
// never a silent skip.
#pragma once

#include <string>
#include <vector>

namespace smr::test {

/// One file's result from the Khronos glTF-Validator (npm gltf-validator).
struct GltfValidation {
  std::string path;
  int errors = -1, warnings = -1, infos = -1;
  std::string messages;   // its errors and warnings, one per line
  std::string validator;  // the validator's version
};

/// Validates every file with tests/js/validate_gltf.mjs in one node run. Adds a gtest failure
/// (and returns what it has) when node or the validator cannot run.
std::vector<GltfValidation> validate_gltf(const std::vector<std::string>& paths);

/// The directory of the JavaScript tools (tests/js in the source tree).
std::string js_tools_dir();

}  // namespace smr::test
