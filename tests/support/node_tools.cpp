#include "tests/support/node_tools.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <sstream>

#include <nlohmann/json.hpp>

#include "tests/support/process.h"

namespace smr::test {

std::string js_tools_dir() {
  return SMRDB_TESTS_JS_DIR;
}

std::vector<GltfValidation> validate_gltf(const std::vector<std::string>& paths) {
  std::vector<GltfValidation> out;
  const std::string dir = js_tools_dir();
  if (run_command("node --version").code != 0) {
    ADD_FAILURE() << "node is not installed: the glTF tests need it (scripts/install-deps.sh)";
    return out;
  }
  if (!std::filesystem::exists(dir + "/node_modules/gltf-validator/package.json")) {
    ADD_FAILURE() << "the Khronos glTF-Validator is not installed in " << dir
                  << "/node_modules: run `npm ci` there (scripts/install-deps.sh does)";
    return out;
  }
  std::string cmd = "node '" + dir + "/validate_gltf.mjs'";
  for (const auto& p : paths) cmd += " '" + p + "'";
  const CommandResult r = run_command(cmd);
  std::istringstream lines(r.out);
  std::string line;
  while (std::getline(lines, line)) {
    const auto j = nlohmann::json::parse(line, nullptr, false);
    if (!j.is_object() || !j.contains("path")) {
      ADD_FAILURE() << "validate_gltf.mjs printed: " << line;
      continue;
    }
    GltfValidation v;
    v.path = j["path"];
    v.errors = j["errors"];
    v.warnings = j["warnings"];
    v.infos = j["infos"];
    v.validator = j["validator"];
    for (const auto& m : j["messages"]) v.messages += m.get<std::string>() + "\n";
    out.push_back(std::move(v));
  }
  if (out.size() != paths.size())
    ADD_FAILURE() << "the validator answered for " << out.size() << " of " << paths.size()
                  << " files (exit " << r.code << "):\n"
                  << r.out;
  return out;
}

}  // namespace smr::test
