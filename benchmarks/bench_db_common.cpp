#include "benchmarks/bench_db_common.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <vector>

#include "base/error.h"
#include "benchmarks/bench_common.h"

namespace smr::bench {

std::uint64_t resident_bytes(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) return 0;
  struct stat st {};
  std::uint64_t resident = 0;
  if (::fstat(fd, &st) == 0 && st.st_size > 0) {
    const auto size = static_cast<std::size_t>(st.st_size);
    void* map = ::mmap(nullptr, size, PROT_READ, MAP_SHARED, fd, 0);
    if (map != MAP_FAILED) {
      const std::size_t page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
      std::vector<unsigned char> in((size + page - 1) / page);
      if (::mincore(map, size, in.data()) == 0) {
        for (unsigned char c : in) resident += (c & 1u) ? page : 0;
      }
      ::munmap(map, size);
    }
  }
  ::close(fd);
  return std::min<std::uint64_t>(resident, static_cast<std::uint64_t>(st.st_size));
}

std::uint64_t drop_from_page_cache(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw_input(path + ": cannot open");
  (void)::posix_fadvise(fd, 0, 0, POSIX_FADV_DONTNEED);
  ::close(fd);
  return resident_bytes(path);
}

std::uint64_t warm_page_cache(const std::string& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) throw_input(path + ": cannot open");
  std::vector<char> buffer(std::size_t{4} << 20);
  std::uint64_t total = 0;
  for (;;) {
    const ssize_t n = ::read(fd, buffer.data(), buffer.size());
    if (n <= 0) break;
    total += static_cast<std::uint64_t>(n);
  }
  ::close(fd);
  return total;
}

Camera named_camera(const std::string& name, const Box3& b) {
  const double lx = b.hi.x - b.lo.x, ly = b.hi.y - b.lo.y, zr = b.hi.z - b.lo.z;
  const double l = std::max(lx, ly);
  Camera cam;
  if (name == "oblique") {
    cam.eye = {b.lo.x + 0.25 * lx, b.lo.y + 0.15 * ly, b.hi.z + 0.02 * l};
    cam.target = {b.lo.x + 0.6 * lx, b.lo.y + 0.75 * ly, b.lo.z + 0.3 * zr};
  } else if (name == "overview") {
    cam.eye = {b.lo.x + 0.5 * lx, b.lo.y + 0.2 * ly, b.hi.z + 1.0 * l};
    cam.target = {b.lo.x + 0.5 * lx, b.lo.y + 0.5 * ly, b.lo.z};
  } else {
    throw_input("--view must be oblique or overview, got '" + name + "'");
  }
  return cam;
}

Vec3 parse_vec3(const std::string& text, const char* what) {
  const std::vector<double> v = parse_doubles(text);
  if (v.size() != 3) throw_input(std::string(what) + " expects x,y,z, got '" + text + "'");
  return {v[0], v[1], v[2]};
}

nlohmann::json camera_json(const Camera& c) {
  return {{"eye", vec3_json(c.eye)},
          {"target", vec3_json(c.target)},
          {"fov_y_deg", c.fov_y_deg},
          {"viewport", {c.viewport_w, c.viewport_h}},
          {"far", c.far_distance}};
}

}  // namespace smr::bench
