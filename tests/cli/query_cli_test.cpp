// `smrdb query` end to end on a real GeoTIFF with a CRS and no-data (terra's elev.tif, ingested
// losslessly): elevations equal the raster's samples (and GDAL's gdallocationinfo at the same
// coordinates), batch input from stdin, CSV and GeoJSON gives the same answers, every kind's
// output parses, and bad input exits 1 with a message naming what was wrong and leaves no file.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "smr/io/dem_reader.h"
#include "tests/support/files.h"
#include "tests/support/process.h"
#include "tests/support/test_data.h"

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

smr::test::CommandResult smrdb(const std::string& args) {
  return smr::test::run_command(std::string(SMRDB_BIN) + " " + args);
}

std::string xy(const smr::Heightfield& h, int col, int row) {
  std::ostringstream os;
  os.precision(17);
  os << h.georef.x0 + col * h.georef.dx << ',' << h.georef.y0 + row * h.georef.dy;
  return os.str();
}

class QueryCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() / ("smrdb_query_" + std::to_string(::getpid())));
    fs::create_directories(*dir_);
    const auto r = smrdb("ingest " + tif() + " --max-error 0 -q -o " + db());
    ASSERT_EQ(r.code, 0) << r.out;
    dem_ = new smr::Heightfield(smr::read_dem(tif()));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
    delete dem_;
  }
  static std::string tif() { return smr::test::data_path("elev.tif"); }
  static std::string path(const std::string& name) { return (*dir_ / name).string(); }
  static std::string db() { return path("elev.smrdb"); }
  static json query(const std::string& args) {
    const auto r = smrdb("query " + db() + " " + args + " --json -q");
    EXPECT_EQ(r.code, 0) << args << "\n" << r.out;
    return r.code == 0 ? json::parse(r.out) : json::object();
  }
  static void expect_user_error(const std::string& args, const std::string& mention) {
    const auto r = smrdb("query " + db() + " " + args);
    EXPECT_EQ(r.code, 1) << args << "\n" << r.out;
    EXPECT_NE(r.out.find(mention), std::string::npos) << args << "\n" << r.out;
    EXPECT_EQ(r.out.find("internal error"), std::string::npos) << r.out;
  }
  static inline fs::path* dir_ = nullptr;
  static inline smr::Heightfield* dem_ = nullptr;
};

// Every sample of the raster: its value (a lossless database: bound 0), or "no data".
TEST_F(QueryCli, ElevationAnswersEverySampleFromStdin) {
  const smr::Heightfield& h = *dem_;
  std::string csv = "x,y\n";
  for (int row = 0; row < h.height; ++row)
    for (int col = 0; col < h.width; ++col) csv += xy(h, col, row) + "\n";
  std::ofstream(path("pts.csv")) << csv;
  const auto r = smr::test::run_command("cat " + path("pts.csv") + " | " + SMRDB_BIN + " query " +
                                        db() + " elevation --input - -q");
  ASSERT_EQ(r.code, 0) << r.out;
  std::istringstream in(r.out);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "x,y,z,error");
  std::uint64_t values = 0, nodata = 0;
  for (int row = 0; row < h.height; ++row) {
    for (int col = 0; col < h.width; ++col) {
      ASSERT_TRUE(std::getline(in, line)) << "answers end early at " << col << "," << row;
      std::vector<std::string> f;
      std::stringstream ls(line);
      for (std::string s; std::getline(ls, s, ',');) f.push_back(s);
      ASSERT_EQ(f.size(), 4u) << line;
      if (f[2] == "nodata") {
        ++nodata;
        continue;  // a valid sample may lie outside every data triangle (elevation_test)
      }
      ASSERT_TRUE(h.has_data(col, row)) << "a height on no data at " << col << "," << row;
      EXPECT_NEAR(std::stod(f[2]), h.at(col, row), 1e-3) << col << "," << row;
      EXPECT_EQ(std::stod(f[3]), 0.0);
      ++values;
    }
  }
  EXPECT_GT(values, 3000u);
  EXPECT_GT(nodata, 0u);
}

// gdallocationinfo reads the same raster at the same coordinates (its own CRS).
TEST_F(QueryCli, ElevationAgreesWithGdalLocationInfo) {
  if (!smr::test::run_command("command -v gdallocationinfo").out.size())
    GTEST_SKIP() << "gdallocationinfo (gdal-bin) is not installed";
  const smr::Heightfield& h = *dem_;
  int checked = 0;
  for (int row = 3; row < h.height; row += 11) {
    for (int col = 2; col < h.width; col += 9) {
      if (!h.has_data(col, row)) continue;
      std::string p = xy(h, col, row);
      const json j = query("elevation " + p);
      std::replace(p.begin(), p.end(), ',', ' ');
      const auto g = smr::test::run_command("gdallocationinfo -valonly -geoloc " + tif() + " " + p);
      ASSERT_EQ(g.code, 0) << g.out;
      ASSERT_FALSE(j["answers"][0]["z"].is_null()) << p;
      EXPECT_NEAR(j["answers"][0]["z"].get<double>(), std::stod(g.out), 1e-3) << p;
      ++checked;
    }
  }
  EXPECT_GT(checked, 20);
}

TEST_F(QueryCli, GeoJsonPointsGiveTheSameAnswers) {
  const smr::Heightfield& h = *dem_;
  const std::string a = xy(h, 40, 50), b = xy(h, 60, 30);
  const json csv = query("elevation " + a + " " + b);
  std::ofstream(path("pts.geojson"))
      << "{\"type\":\"FeatureCollection\",\"features\":[{\"type\":\"Feature\",\"properties\":{},"
         "\"geometry\":{\"type\":\"MultiPoint\",\"coordinates\":[["
      << a << "],[" << b << "]]}}]}";
  const json geo = query("elevation --input " + path("pts.geojson"));
  EXPECT_EQ(csv["answers"], geo["answers"]);
  // The same points as a list after blanks, and as a CSV with a BOM, spaces and a late header.
  std::ofstream(path("list.json")) << "  \n[{\"type\":\"Point\",\"coordinates\":[" << a
                                   << "]},{\"type\":\"Point\",\"coordinates\":[" << b << "]}]";
  EXPECT_EQ(query("elevation --input " + path("list.json"))["answers"], csv["answers"]);
  const auto with = [](const std::string& p, const std::string& separator) {
    const std::size_t k = p.find(',');
    return p.substr(0, k) + separator + p.substr(k + 1);
  };
  const std::string sa = with(a, " , "), sb = with(b, "\t");
  std::ofstream(path("odd.csv")) << "\xEF\xBB\xBF# points\n\nlon lat\n"
                                 << sa << "\r\n"
                                 << sb << "\n";
  EXPECT_EQ(query("elevation --input " + path("odd.csv"))["answers"], csv["answers"]);
  // Within an error: bounded, and no more ops read.
  const json coarse = query("elevation " + a + " " + b + " --max-error 50");
  for (const json& ans : coarse["answers"]) EXPECT_LE(ans["error"].get<double>(), 50.0);
  EXPECT_LE(coarse["ops_read"].get<std::uint64_t>(), csv["ops_read"].get<std::uint64_t>());
}

TEST_F(QueryCli, EveryKindWritesWhatItSays) {
  const smr::Heightfield& h = *dem_;
  const json los = query("los " + xy(h, 40, 50) + ",+5 " + xy(h, 60, 30) + ",+5");
  EXPECT_TRUE(los["answer"] == "visible" || los["answer"] == "blocked") << los.dump();
  EXPECT_EQ(los["error_bound"], 0.0);  // lossless, finest: exact

  const auto prof = smrdb("query " + db() + " profile " + xy(h, 40, 50) + " " + xy(h, 60, 30) +
                          " " + xy(h, 70, 60) + " -q");
  ASSERT_EQ(prof.code, 0) << prof.out;
  EXPECT_EQ(prof.out.rfind("distance,x,y,z,error\n", 0), 0u);
  EXPECT_GT(std::count(prof.out.begin(), prof.out.end(), '\n'), 10);

  const json c = query("contours --interval 50 -o " + path("c.geojson"));
  EXPECT_GT(c["lines"].get<std::uint64_t>(), 0u);
  const json g = json::parse(std::ifstream(path("c.geojson")));
  EXPECT_EQ(g["type"], "FeatureCollection");
  EXPECT_EQ(g["features"].size(), c["lines"].get<std::size_t>());
  EXPECT_EQ(std::fmod(g["features"][0]["properties"]["elev"].get<double>(), 50.0), 0.0);
  EXPECT_TRUE(g.contains("crs") || g.contains("crs_wkt"));

  const json w =
      query("window " + xy(h, 20, 20) + "," + xy(h, 40, 35) + " --clip -o " + path("w.ply"));
  EXPECT_GT(w["triangles_meeting_window"].get<std::uint64_t>(), 0u);
  EXPECT_EQ(w["output"]["triangles"], w["triangles_meeting_window"]);
  EXPECT_TRUE(fs::exists(path("w.ply")));
}

TEST_F(QueryCli, BadInputExitsOneAndLeavesNoFile) {
  const smr::Heightfield& h = *dem_;
  expect_user_error("elevation 1,2", "outside the database's domain");
  expect_user_error("elevation " + xy(h, 3, 3) + ",7", "expects X,Y");
  expect_user_error("elevation 5.9,x", "is not a finite number");
  expect_user_error("window " + xy(h, 40, 35) + "," + xy(h, 20, 20), "is empty");
  expect_user_error("window 100,100,101,101", "outside the database's domain");
  expect_user_error("contours", "--levels");
  expect_user_error("contours --interval -5", "interval");
  expect_user_error("los " + xy(h, 1, 1) + ",500", "two points");
  expect_user_error("los " + xy(h, 1, 1) + ",500 " + xy(h, 9, 9), "X,Y,Z");
  expect_user_error("profile " + xy(h, 1, 1), "at least two");
  expect_user_error("elevation --input " + path("missing.csv"), "missing.csv");
  expect_user_error("elevation --input " + dir_->string(), "not a readable file");
  std::ofstream(path("feature.json")) << "{\"type\":\"Feature\"}";
  expect_user_error("elevation --input " + path("feature.json"), "\"geometry\"");
  expect_user_error("contours --interval 0.001 -o " + path("c.geojson"), "at most 100000");
  expect_user_error("window " + xy(h, 20, 20) + "," + xy(h, 40, 35), "-o FILE");
  // A bad record in the middle of a batch: the message names the line; no partial output.
  std::ofstream(path("bad.csv")) << xy(h, 40, 50) << "\n" << xy(h, 41, 50) << "\nnot,a point\n";
  expect_user_error("elevation --input " + path("bad.csv") + " -o " + path("out.csv"), "line 3");
  EXPECT_FALSE(fs::exists(path("out.csv")));
  const auto r = smrdb("query " + path("nothing.smrdb") + " elevation 1,2");
  EXPECT_EQ(r.code, 1) << r.out;
}

}  // namespace
