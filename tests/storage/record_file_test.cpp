// RecordFile: records read back by position, and many scattered pieces read in runs against
// the same pieces read one by one.
#include "storage/record_file.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <random>
#include <vector>

namespace smr::storage {
namespace {

TEST(RecordFile, ScatteredPiecesReadInRunsAreTheRecordsThemselves) {
  RecordFile<std::uint32_t> file(std::filesystem::temp_directory_path().string());
  const std::uint32_t n = 3'000'000;  // 12 MB: pieces far apart, near, overlapping
  for (std::uint32_t i = 0; i < n; ++i) file.push(i * 2654435761u);
  file.flush();
  std::mt19937 rng(7);
  for (const std::uint32_t spread : {100u, 10'000u, n}) {
    // Pieces in random order, some adjacent or overlapping (runs), some far apart (alone),
    // some longer than a run may be.
    std::vector<RecordFile<std::uint32_t>::Piece> pieces;
    std::size_t total = 0;
    const std::uint64_t base = spread < n ? rng() % (n - spread) : 0;
    for (int i = 0; i < 2000; ++i) {
      const std::size_t count = i % 97 == 0 ? 400'000 : 1 + std::size_t(rng() % 64);
      const std::uint64_t first = std::min<std::uint64_t>(base + rng() % spread, n - count);
      pieces.push_back({first, count, total});
      total += count;
    }
    const std::vector<RecordFile<std::uint32_t>::Piece> asked = pieces;
    std::vector<std::uint32_t> out(total, 0);
    file.read_pieces(pieces, out.data());
    for (const auto& p : asked) {
      for (std::size_t j = 0; j < p.count; ++j) {
        ASSERT_EQ(out[p.to + j], std::uint32_t(p.first + j) * 2654435761u)
            << "spread " << spread << ", piece at " << p.first << ", record " << j;
      }
    }
  }
}

}  // namespace
}  // namespace smr::storage
