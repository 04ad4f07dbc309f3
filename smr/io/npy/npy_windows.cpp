// A plain .npy elevation array read by windows (open_npy, smr/io/dem_reader.h): the header is
// parsed once (npy_format.cpp), then each window's rows (or, in Fortran order, columns) are read
// with pread, converted and checked like read_npy's whole array, so no more than a window of the
// file is ever in memory. pread keeps reads from several threads independent.
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <memory>
#include <tuple>

#include "base/error.h"
#include "smr/io/dem_reader.h"
#include "smr/io/io_util.h"
#include "smr/io/npy.h"
#include "smr/io/npy/npy_internal.h"

namespace smr {

namespace {

using npy_io::check_data_size;
using npy_io::check_finite;
using npy_io::element;
using npy_io::grid_shape;
using npy_io::load_le;
using npy_io::native_float32;
using npy_io::parse_npy_header;

// is ever in memory. pread keeps reads from several threads independent.
class NpyWindows final : public RasterWindows {
 public:
  explicit NpyWindows(const std::string& path) : path_(path) {
    io_util::check_is_file(path, "a file");
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw_io("cannot open '" + path + "': " + std::strerror(errno));
    try {
      open_header();
    } catch (...) {
      ::close(fd_);
      throw;
    }
  }
  ~NpyWindows() override { ::close(fd_); }
  NpyWindows(const NpyWindows&) = delete;
  NpyWindows& operator=(const NpyWindows&) = delete;

  int width() const override { return static_cast<int>(cols_); }
  int height() const override { return static_cast<int>(rows_); }
  const Georef& georef() const override { return georef_; }  // a plain .npy has none
  const std::string& source() const override { return path_; }

  bool random_access() const override { return true; }

  Heightfield read(int col0, int row0, int w, int h) const override {
    Heightfield out;
    read_into(out, col0, row0, w, h);
    return out;
  }

  void read_into(Heightfield& out, int col0, int row0, int w, int h) const override {
    if (col0 < 0 || row0 < 0 || w <= 0 || h <= 0 || col0 > width() - w || row0 > height() - h) {
      throw_input("window " + std::to_string(w) + " x " + std::to_string(h) + " at (" +
                  std::to_string(col0) + ", " + std::to_string(row0) + ") is outside '" + path_ +
                  "' (" + std::to_string(cols_) + " x " + std::to_string(rows_) + ")");
    }
    set_window_header(out, georef_, path_, col0, row0, w, h);  // its pages, already faulted in
    out.valid.clear();  // a plain .npy has no no-data samples
    const auto c0 = static_cast<std::size_t>(col0), r0 = static_cast<std::size_t>(row0);
    const auto ww = static_cast<std::size_t>(w), hh = static_cast<std::size_t>(h);
    out.z.resize(ww * hh);
    const auto n = static_cast<std::size_t>(array_.item_size);
    if (!array_.fortran_order) {  // row by row
      std::vector<std::uint8_t> row(native_float32(array_) ? 0 : ww * n);
      for (std::size_t r = 0; r < hh; ++r) {
        const std::size_t at = ((r0 + r) * cols_ + c0) * n;
        float* z = out.z.data() + r * ww;
        if (row.empty()) {
          read_exactly(reinterpret_cast<std::uint8_t*>(z), ww * n, at);
          check_finite({z, ww}, r0 + r, c0, ww, path_);
          continue;
        }
        read_exactly(row.data(), row.size(), at);
        for (std::size_t c = 0; c < ww; ++c) {
          z[c] = element(array_, row.data() + c * n, path_, r0 + r, c0 + c);
        }
      }
    } else {  // column by column
      std::vector<std::uint8_t> column(hh * n);
      for (std::size_t c = 0; c < ww; ++c) {
        read_exactly(column.data(), column.size(), ((c0 + c) * rows_ + r0) * n);
        for (std::size_t r = 0; r < hh; ++r) {
          out.z[r * ww + c] = element(array_, column.data() + r * n, path_, r0 + r, c0 + c);
        }
      }
    }
  }

 private:
  void open_header() {
    struct stat st {};
    if (::fstat(fd_, &st) != 0) throw_io("cannot stat '" + path_ + "': " + std::strerror(errno));
    file_size_ = static_cast<std::uint64_t>(st.st_size);
    // The preamble, then the header whose length it gives (parse_npy_header reports a header
    // longer than the file).
    std::vector<std::uint8_t> head(std::min<std::uint64_t>(12, file_size_));
    read_at(head.data(), head.size(), 0);
    std::size_t need = head.size();
    if (head.size() >= 10 && head[6] == 1) {
      need = 10 + static_cast<std::size_t>(load_le(&head[8], 2));
    } else if (head.size() >= 12 && (head[6] == 2 || head[6] == 3)) {
      need = 12 + static_cast<std::size_t>(load_le(&head[8], 4));
    }
    head.resize(std::min<std::uint64_t>(need, file_size_));
    read_at(head.data(), head.size(), 0);
    auto [a, data_start] = parse_npy_header(head, path_);
    array_ = std::move(a);
    std::tie(rows_, cols_) = grid_shape(array_, path_);
    check_data_size(array_, file_size_ - data_start, path_);
    data_start_ = data_start;
  }

  // Reads n bytes at byte `at` of the file; the file ending first is an error.
  void read_at(std::uint8_t* out, std::size_t n, std::uint64_t at) const {
    for (std::size_t done = 0; done < n;) {
      const ssize_t got = ::pread(fd_, out + done, n - done, static_cast<off_t>(at + done));
      if (got < 0 && errno == EINTR) continue;
      if (got < 0) throw_io("cannot read '" + path_ + "': " + std::strerror(errno));
      if (got == 0) {
        throw_io("'" + path_ + "' ended at byte " + std::to_string(at + done) +
                 " while it was read (was it truncated meanwhile?)");
      }
      done += static_cast<std::size_t>(got);
    }
  }

  void read_exactly(std::uint8_t* out, std::size_t n, std::uint64_t data_offset) const {
    read_at(out, n, data_start_ + data_offset);
  }

  std::string path_;
  int fd_ = -1;
  std::uint64_t file_size_ = 0;
  NpyArray array_;
  std::size_t rows_ = 0, cols_ = 0, data_start_ = 0;
  Georef georef_;
};

}  // namespace

std::unique_ptr<RasterWindows> open_npy(const std::string& path) {
  return std::make_unique<NpyWindows>(path);
}

}  // namespace smr
