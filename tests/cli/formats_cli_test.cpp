// The delivery formats from the command line (issue 37, item 1): `extract -o out.glb|out.gltf`
// with and without --compress passes the Khronos glTF-Validator on a real DEM's database, `tiles`
// writes a quantized-mesh pyramid with its layer.json, and bad arguments are exit code 1 with a
// message naming them and no output left behind.
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "tests/support/files.h"
#include "tests/support/node_tools.h"
#include "tests/support/process.h"
#include "tests/support/test_data.h"

namespace {

namespace fs = std::filesystem;
using smr::test::CommandResult;

CommandResult smrdb(const std::string& args) {
  return smr::test::run_command(std::string(SMRDB_BIN) + " " + args);
}

class FormatsCli : public ::testing::Test {
 protected:
  // The jacksboro DEM's database (geographic), built once for the suite.
  static void SetUpTestSuite() {
    dir_ = new smr::test::TempDir("smrdb-formats-cli");
    const CommandResult r = smrdb("ingest " + smr::test::data_path("jacksboro_fault_dem.npz") +
                                  " --max-error 2 -q -o " + db());
    ASSERT_EQ(r.code, 0) << r.out;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static std::string db() { return dir_->file("jacksboro.smrdb"); }
  static std::string file(const std::string& name) { return dir_->file(name); }
  static void expect_user_error(const std::string& args, const std::string& mention,
                                const std::string& no_output) {
    const CommandResult r = smrdb(args);
    EXPECT_EQ(r.code, 1) << args << "\n" << r.out;
    EXPECT_NE(r.out.find(mention), std::string::npos) << args << "\n" << r.out;
    EXPECT_FALSE(fs::exists(no_output)) << args;
  }
  static smr::test::TempDir* dir_;
};
smr::test::TempDir* FormatsCli::dir_ = nullptr;

TEST_F(FormatsCli, ExtractWritesValidGltf) {
  std::vector<std::string> files;
  for (const std::string compress : {"", "draco", "meshopt"}) {
    for (const std::string ext : {".glb", ".gltf"}) {
      const std::string out = file("out" + (compress.empty() ? "" : "-" + compress) + ext);
      const CommandResult r = smrdb("extract " + db() + " --floor 0.9 -o " + out + " --json -q" +
                                    (compress.empty() ? "" : " --compress " + compress));
      ASSERT_EQ(r.code, 0) << r.out;
      const auto report = nlohmann::json::parse(r.out);
      EXPECT_EQ(report["output"]["compression"], compress.empty() ? "none" : compress);
      EXPECT_EQ(report["output"]["bytes"], fs::file_size(out));
      EXPECT_GT(report["output"]["triangles"].get<int>(), 1000);
      files.push_back(out);
    }
  }
  // Compression shrinks the file (meshopt less: its bytes are meant to be gzipped as well).
  EXPECT_LT(double(fs::file_size(file("out-draco.glb"))),
            0.5 * double(fs::file_size(file("out.glb"))));
  EXPECT_LT(double(fs::file_size(file("out-meshopt.glb"))),
            0.65 * double(fs::file_size(file("out.glb"))));
  for (const auto& v : smr::test::validate_gltf(files)) {
    EXPECT_EQ(v.errors, 0) << v.path << "\n" << v.messages;
    EXPECT_EQ(v.warnings, 0) << v.path << "\n" << v.messages;
  }
  // The georeference is recorded: the raster is geographic, its CRS and lattice are there.
  const auto doc = nlohmann::json::parse(smr::test::read_file(file("out.gltf")));
  const auto& x = doc["asset"]["extras"]["smrdb"];
  EXPECT_EQ(x["georef"]["geographic"], true);
  EXPECT_EQ(x["kind"], "terrain");
  EXPECT_TRUE(x.contains("rcf"));
  EXPECT_NEAR(x["data_to_gltf"]["scale"][0].get<double>(), 89000.0, 1000.0);  // at 36.6 N
}

TEST_F(FormatsCli, BadGltfArgumentsAreUserErrors) {
  expect_user_error("extract " + db() + " --floor 0.5 -o " + file("x.obj") + " --compress draco",
                    "--compress draco: only glTF outputs", file("x.obj"));
  expect_user_error("extract " + db() + " --floor 0.5 -o " + file("x.glb") + " --compress zip",
                    "--compress must be 'draco' or 'meshopt', got 'zip'", file("x.glb"));
  expect_user_error("extract " + db() + " --floor 0.5 -o " + file("x.gltfx"),
                    "must end in .obj, .ply, .glb or .gltf", file("x.gltfx"));
}

TEST_F(FormatsCli, TilesWritesAPyramid) {
  const std::string out = file("tiles");
  const CommandResult r = smrdb("tiles " + db() + " -o " + out + " --max-zoom 11 --json -q");
  ASSERT_EQ(r.code, 0) << r.out;
  const auto report = nlohmann::json::parse(r.out);
  EXPECT_EQ(report["projection"], "EPSG:4326");
  EXPECT_EQ(report["max_zoom"], 11);
  const auto layer = nlohmann::json::parse(smr::test::read_file(out + "/layer.json"));
  EXPECT_EQ(layer["maxzoom"], 11);
  std::uint64_t files = 0;
  for (const auto& e : fs::recursive_directory_iterator(out))
    files += e.path().extension() == ".terrain";
  EXPECT_EQ(files, report["tiles"].get<std::uint64_t>());
  EXPECT_TRUE(fs::exists(out + "/0/0/0.terrain"));  // jacksboro is in the western hemisphere
  // An existing output needs --force.
  expect_user_error("tiles " + db() + " -o " + out + " --max-zoom 3", "exists (pass --force",
                    out + "/3/../none");
  EXPECT_TRUE(fs::exists(out + "/11"));
  EXPECT_EQ(smrdb("tiles " + db() + " -o " + out + " --max-zoom 3 --force -q").code, 0);
  EXPECT_FALSE(fs::exists(out + "/11"));
}

TEST_F(FormatsCli, BadTilesArgumentsAreUserErrors) {
  const std::string out = file("bad-tiles");
  expect_user_error("tiles " + db() + " -o " + out + " --max-zoom 25",
                    "--max-zoom must be in [0, 24], got 25", out);
  expect_user_error("tiles " + db() + " -o " + out + " --max-zoom -1",
                    "--max-zoom must be in [0, 24], got -1", out);
  expect_user_error("tiles " + db() + " -o " + out + " --max-zoom many", "--max-zoom", out);
  expect_user_error("tiles " + file("missing.smrdb") + " -o " + out, "missing.smrdb", out);
  // A 3-D mesh database has no tiles.
  const std::string mesh_db = file("mesh.smrdb");
  ASSERT_EQ(
      smrdb("ingest " + smr::test::data_path("meshes/blobby_3cc.off") + " -q -o " + mesh_db).code,
      0);
  expect_user_error("tiles " + mesh_db + " -o " + out, "tiles need a terrain database", out);
  for (const auto& e : fs::directory_iterator(dir_->path()))
    EXPECT_EQ(e.path().string().find(".tmp-"), std::string::npos) << e.path();
}

}  // namespace
