// The smrdb command line: bad arguments and files give exit code 1 and a message naming what was
// wrong; good runs write the mesh, the picture and JSON statistics.
#include <gtest/gtest.h>

#include "tests/support/process.h"

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <limits>
#include <string>

#include <nlohmann/json.hpp>

#include "smr/io/synthetic.h"
#include "tests/support/test_data.h"

namespace {

namespace fs = std::filesystem;

using CliRun = smr::test::CommandResult;

CliRun smrdb(const std::string& args) {
  return smr::test::run_command(std::string(SMRDB_BIN) + " " + args);
}

class Cli : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("smrdb_cli_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    dem_ = (dir_ / "dem.npy").string();
    smr::write_npy(dem_, smr::make_fbm(65, 65, 3, 100.0));
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string path(const std::string& name) const { return (dir_ / name).string(); }
  void expect_user_error(const std::string& args, const std::string& mention) {
    const CliRun r = smrdb(args);
    EXPECT_EQ(r.code, 1) << args << "\n" << r.out;
    EXPECT_NE(r.out.find(mention), std::string::npos) << args << "\n" << r.out;
    EXPECT_EQ(r.out.find("internal error"), std::string::npos) << r.out;
  }
  fs::path dir_;
  std::string dem_;
};

TEST_F(Cli, BuildsMeshPictureAndJson) {
  const CliRun r = smrdb("build " + dem_ + " --max-error 0.5 --floor 0.4 --aoi 32,32,8,0.99 -o " +
                         path("m.ply") + " --png " + path("m.png") + " --json -q");
  ASSERT_EQ(r.code, 0) << r.out;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_GT(j["crmr"]["ops"].get<int>(), 10);
  EXPECT_GT(j["extraction"]["triangles"].get<int>(), 10);
  EXPECT_LE(j["crmr"]["err_final"].get<double>(), 0.5);
  EXPECT_GT(fs::file_size(path("m.ply")), 100u);
  EXPECT_GT(fs::file_size(path("m.png")), 100u);
}

TEST_F(Cli, ProgressLineOnStderrAndQuietSilencesIt) {
  CliRun r = smrdb("build " + dem_ + " --camera-free -o " + path("x.obj"));
  EXPECT_EQ(r.code, 1);  // unknown option
  r = smrdb("build " + dem_ + " -o " + path("x.obj"));
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_NE(r.out.find("0...10...20...30...40...50...60...70...80...90...100 - done."),
            std::string::npos)
      << r.out;
  r = smrdb("build " + dem_ + " -q -o " + path("x.obj"));
  ASSERT_EQ(r.code, 0);
  EXPECT_EQ(r.out, "");
}

TEST_F(Cli, ScreenSpaceRunWithCamera) {
  const CliRun r =
      smrdb("build " + dem_ +
            " --eye -10,-10,150 --target 32,32,0 --fov 50 --viewport 640x480 --pixel-error 2"
            " --screen-aoi 320,240,50,0.5 --algorithm reduced -o " +
            path("c.obj") + " --json -q --verify");
  ASSERT_EQ(r.code, 0) << r.out;
  EXPECT_EQ(nlohmann::json::parse(r.out)["extraction"]["algorithm"], "reduced");
}

TEST_F(Cli, BadFilesAreUserErrors) {
  expect_user_error("build " + path("missing.tif") + " -o " + path("o.obj"), "missing.tif");
  std::ofstream(path("notes.txt")) << "this is not a raster\n";
  expect_user_error("build " + path("notes.txt") + " -o " + path("o.obj"), "notes.txt");
  std::ofstream(path("empty.npy")).close();
  expect_user_error("build " + path("empty.npy") + " -o " + path("o.obj"), "empty.npy");
  // NaN samples.
  smr::Heightfield h = smr::make_fbm(9, 9, 1);
  h.z[40] = std::numeric_limits<float>::quiet_NaN();
  smr::write_npy(path("nan.npy"), h);
  expect_user_error("build " + path("nan.npy") + " -o " + path("o.obj"), "nan.npy");
  // Zero-size raster: a 0x5 .npy.
  {
    const auto bytes = smr::encode_npy({}, 0, 5);
    std::ofstream(path("zero.npy"), std::ios::binary)
        .write(reinterpret_cast<const char*>(bytes.data()),
               static_cast<std::streamsize>(bytes.size()));
  }
  expect_user_error("build " + path("zero.npy") + " -o " + path("o.obj"), "zero.npy");
  // Multi-band raster (real GeoTIFF from the fetched data cannot be multi-band; make one).
  const std::string multi = path("multi.tif");
  const std::string src = smr::test::data_path("elev.tif");
  if (std::system(("gdal_translate -q -b 1 -b 1 " + src + " " + multi).c_str()) == 0) {
    expect_user_error("build " + multi + " -o " + path("o.obj"), "multi.tif");
  } else {
    ADD_FAILURE() << "gdal_translate (gdal-bin) is needed to make a multi-band raster";
  }
  // Unwritable output.
  const CliRun r = smrdb("build " + dem_ + " -q -o /nonexistent-dir/out.obj");
  EXPECT_EQ(r.code, 1) << r.out;
  EXPECT_NE(r.out.find("/nonexistent-dir/out.obj"), std::string::npos) << r.out;
}

TEST_F(Cli, BadNumbersAreUserErrors) {
  const std::string b = "build " + dem_ + " -o " + path("o.obj") + " ";
  expect_user_error(b + "--floor 1.5", "--floor");
  expect_user_error(b + "--floor=-0.1", "--floor");
  expect_user_error(b + "--aoi 1,2,3", "--aoi");
  expect_user_error(b + "--aoi 1,2,-3,0.5", "--aoi");
  expect_user_error(b + "--aoi 1,2,nan,0.5", "--aoi");
  expect_user_error(b + "--eye 1,2,3 --target 4,5,6 --pixel-error 0", "--pixel-error");
  expect_user_error(b + "--pixel-error 2", "--pixel-error");
  expect_user_error(b + "--eye 1,2,3", "--target");
  expect_user_error(b + "--eye 1,2,3 --target 1,2,3", "--target");
  expect_user_error(b + "--eye 1,2,3 --target 4,5,6 --fov 200", "--fov");
  expect_user_error(b + "--eye 1,2,3 --target 4,5,6 --viewport 640by480", "--viewport");
  expect_user_error(b + "--max-error=-1", "--max-error");
  expect_user_error(b + "--algorithm fastest", "--algorithm");
  expect_user_error(b + "--critical-lines 2", "--critical-lines");
  expect_user_error("build " + dem_ + " -o " + path("o.stl"), "o.stl");
  expect_user_error("build " + dem_ + " -o " + path("o.obj") + " --png " + path("p.jpg"), "p.jpg");
  expect_user_error("synth --size 1 -o " + path("s.tif"), "--size");
  EXPECT_EQ(smrdb("").code, 1);
  EXPECT_EQ(smrdb("build --help").code, 0);
}

}  // namespace
