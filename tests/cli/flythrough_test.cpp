// smrdb flythrough from the outside, on a database of a real DEM (jacksboro, its samples put on a
// metric grid so that the camera flies in one unit): every complete frame's mesh is the fresh
// extraction's, no work is pending without a period, a tiny period leaves work pending that an
// unbudgeted update then finishes, path files are replayed as given, and bad input is exit 1
// naming the file or option.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "smr/io/dem_reader.h"
#include "smr/io/gdal_raster.h"
#include "tests/support/files.h"
#include "tests/support/process.h"
#include "tests/support/test_data.h"

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

smr::test::CommandResult smrdb(const std::string& args) {
  return smr::test::run_command(std::string(SMRDB_BIN) + " " + args);
}

class Flythrough : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("smrdb_flythrough_" + std::to_string(::getpid())));
    fs::create_directories(*dir_);
    // Jacksboro's 403 x 344 samples at its spacing in metres (3 arc-seconds at 36.6 N).
    smr::Heightfield h = smr::read_dem(smr::test::data_path("jacksboro_fault_dem.npz"));
    h.georef = smr::Georef{0.0, 0.0, 74.4, 92.7, "", false};
    smr::write_geotiff(path("jacksboro_m.tif"), h);
    const auto r = smrdb("ingest " + path("jacksboro_m.tif") + " -q -o " + db());
    ASSERT_EQ(r.code, 0) << r.out;
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static std::string path(const std::string& name) { return (*dir_ / name).string(); }
  static std::string db() { return path("jacksboro.smrdb"); }

  // Runs flythrough with `args` and --json; the report.
  static json fly(const std::string& args) {
    const auto r = smrdb("flythrough " + db() + " --json -q " + args);
    EXPECT_EQ(r.code, 0) << args << "\n" << r.out;
    return r.code == 0 ? json::parse(r.out) : json::object();
  }
  static void expect_user_error(const std::string& args, const std::string& mention) {
    const auto r = smrdb("flythrough " + db() + " " + args);
    EXPECT_EQ(r.code, 1) << args << "\n" << r.out;
    EXPECT_NE(r.out.find(mention), std::string::npos) << args << "\n" << r.out;
    EXPECT_EQ(r.out.find("internal error"), std::string::npos) << r.out;
  }
  static inline fs::path* dir_ = nullptr;
};

// jacksboro_m spans about 30 x 32 km, 236 to 1076 m.
const std::string kLine = "--line 2000,2000,2500:28000,30000,2000";

TEST_F(Flythrough, UnbudgetedFramesAreTheFreshExtraction) {
  for (const std::string& flight : {kLine, std::string("--orbit")}) {
    const json j = fly(flight + " --frames 24 --compare-fresh --verify");
    ASSERT_EQ(j["frames"].size(), 24u) << flight;
    std::uint64_t coarsened = 0, refined = 0, smallest = ~0ull, largest = 0;
    for (const json& f : j["frames"]) {
      EXPECT_TRUE(f["complete"].get<bool>()) << flight << " frame " << f["frame"];
      EXPECT_EQ(f["pending_coarsenings"], 0) << flight << " frame " << f["frame"];
      EXPECT_EQ(f["pending_refinings"], 0) << flight << " frame " << f["frame"];
      EXPECT_TRUE(f["fresh_match"].get<bool>()) << flight << " frame " << f["frame"];
      EXPECT_EQ(f["triangles"], f["fresh_triangles"]) << flight << " frame " << f["frame"];
      EXPECT_EQ(f["x"], f["fresh_x"]) << flight << " frame " << f["frame"];
      EXPECT_EQ(f["local_morphs"].get<std::uint64_t>(),
                f["coarsenings"].get<std::uint64_t>() + f["refinings"].get<std::uint64_t>());
      if (f["frame"] != 0) coarsened += f["coarsenings"].get<std::uint64_t>();
      if (f["frame"] != 0) refined += f["refinings"].get<std::uint64_t>();
      smallest = std::min(smallest, f["triangles"].get<std::uint64_t>());
      largest = std::max(largest, f["triangles"].get<std::uint64_t>());
    }
    // The camera moved: later frames coarsened and refined, the mesh is not one mesh throughout.
    EXPECT_GT(coarsened, 0u) << flight;
    EXPECT_GT(refined, 0u) << flight;
    EXPECT_LT(smallest, largest) << flight;
    EXPECT_GT(smallest, 2u) << flight;  // more than the base mesh
    EXPECT_EQ(j["summary"]["fresh_mismatches"], 0) << flight;
    EXPECT_EQ(j["summary"]["incomplete_frames"], 0) << flight;
    EXPECT_EQ(j["summary"]["frames"], 24) << flight;
  }
}

TEST_F(Flythrough, PeriodLeavesWorkPendingThatAnUnbudgetedUpdateFinishes) {
  const json j = fly(kLine + " --frames 12 --max-period 0.001 --settle --compare-fresh --verify");
  ASSERT_EQ(j["frames"].size(), 12u);
  int cut = 0;
  for (const json& f : j["frames"]) {
    if (f["complete"].get<bool>()) {
      EXPECT_TRUE(f["fresh_match"].get<bool>()) << "frame " << f["frame"];
      continue;
    }
    EXPECT_FALSE(f.contains("fresh_match")) << "frame " << f["frame"];
    // A period over before the refining began (stop_resolution 0) leaves its work unknown.
    if (f["stop_resolution"].get<double>() > 0.0) {
      EXPECT_GT(f["pending_coarsenings"].get<std::uint64_t>() +
                    f["pending_refinings"].get<std::uint64_t>(),
                0u)
          << "frame " << f["frame"];
    }
    if (f["triangles"] != f["fresh_triangles"]) ++cut;  // the period really stopped work
  }
  EXPECT_GT(cut, 0);
  EXPECT_GT(j["summary"]["incomplete_frames"].get<int>(), 0);
  const json& settle = j["settle"];
  EXPECT_TRUE(settle["complete"].get<bool>());
  EXPECT_EQ(settle["pending_coarsenings"], 0);
  EXPECT_EQ(settle["pending_refinings"], 0);
  EXPECT_TRUE(settle["fresh_match"].get<bool>());
  EXPECT_EQ(settle["triangles"], settle["fresh_triangles"]);
  // The unbudgeted update reached the same mesh as a whole unbudgeted flight's last frame.
  const json whole = fly(kLine + " --frames 12");
  EXPECT_EQ(settle["triangles"], whole["frames"].back()["triangles"]);
  EXPECT_EQ(settle["x"], whole["frames"].back()["x"]);
}

TEST_F(Flythrough, ReplaysPathFiles) {
  smr::test::write_file(path("cams.json"),
                        R"([{"eye": [3000, 3000, 3000], "target": [15000, 15000, 600]},
                            {"eye": [9000, 3000, 3000], "target": [15000, 15000, 600], "fov": 40},
                            {"eye": [9000, 9000, 2500], "target": [15000, 15000, 600]}])");
  const json keys = fly("--path " + path("cams.json") + " --keyframes --compare-fresh");
  ASSERT_EQ(keys["frames"].size(), 3u);
  EXPECT_EQ(keys["frames"][1]["eye"], json::parse("[9000.0, 3000.0, 3000.0]"));
  // Interpolated: 7 frames span the whole path, from the first eye to the last.
  const json seven = fly("--path " + path("cams.json") + " --frames 7 --compare-fresh --png-dir " +
                         path("png") + " --png-every 3");
  ASSERT_EQ(seven["frames"].size(), 7u);
  EXPECT_EQ(seven["frames"][0]["eye"], json::parse("[3000.0, 3000.0, 3000.0]"));
  EXPECT_EQ(seven["frames"][6]["eye"], json::parse("[9000.0, 9000.0, 2500.0]"));
  for (const json& f : seven["frames"]) EXPECT_TRUE(f["fresh_match"].get<bool>());
  EXPECT_EQ(seven["summary"]["fresh_mismatches"], 0);
  EXPECT_TRUE(fs::exists(path("png/frame_0000.png")));
  EXPECT_TRUE(fs::exists(path("png/frame_0006.png")));
  EXPECT_FALSE(fs::exists(path("png/frame_0001.png")));
}

TEST_F(Flythrough, BadInputIsExitOneNamingIt) {
  smr::test::write_file(path("broken.json"), R"([{"eye": [1, 2, 3], "target": )");
  expect_user_error("--path " + path("broken.json"), "broken.json");
  smr::test::write_file(path("empty.json"), "[]");
  expect_user_error("--path " + path("empty.json"), "empty.json");
  smr::test::write_file(path("same.json"), R"([{"eye": [1, 2, 3], "target": [1, 2, 3]}])");
  expect_user_error("--path " + path("same.json"), "same.json");
  smr::test::write_file(path("short.json"), R"([{"eye": [1, 2], "target": [1, 2, 3]}])");
  expect_user_error("--path " + path("short.json"), "short.json");
  expect_user_error("--path " + path("missing.json"), "missing.json");
  expect_user_error("--line 1,2,3:4,5", "--line");
  expect_user_error("--line 1,2,3:1,2,9", "--line");
  expect_user_error("--orbit --fps 0", "--fps");
  expect_user_error("--orbit --speed=-2", "--speed");
  expect_user_error("--orbit --max-period=-1", "--max-period");
  expect_user_error("--orbit --pixel-error 0", "--pixel-error");
  expect_user_error("--orbit --viewport 640by480", "--viewport");
  expect_user_error("--orbit --line 1,2,3:4,5,6", "--orbit");
  expect_user_error("--frames 3", "--path");
  expect_user_error("--orbit --keyframes", "--keyframes");
  const auto r = smrdb("flythrough " + path("nothere.smrdb") + " --orbit");
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_NE(r.out.find("nothere.smrdb"), std::string::npos) << r.out;
}

}  // namespace
