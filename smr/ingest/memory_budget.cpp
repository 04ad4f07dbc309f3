#include "smr/ingest/memory_budget.h"

#include <algorithm>

#include "smr/builders/mesh/qem_pm.h"
#include "smr/builders/terrain/block_tin.h"
#include "smr/db/writer.h"

namespace smr {

MemoryShares divide(const MemoryBudget& budget, IngestPath path) {
  const WriteOptions writer;
  const BlockTinOptions tin;
  const BlockPmOptions pm;
  MemoryShares s;
  s.writer_batch_bytes = writer.batch_bytes;
  s.writer_sort_bytes = writer.sort_bytes;
  if (path == IngestPath::kBlockTin) {
    s.assembly_sort_bytes = tin.assembly_sort_bytes;
    s.exact_window_samples = tin.exact_window_samples;
    s.raster_cache_bytes = tin.raster_cache_bytes;
  } else if (path == IngestPath::kBlockPm) {
    s.assembly_sort_bytes = pm.assembly_sort_bytes;
    s.face_sort_bytes = pm.face_sort_bytes;
    s.leaf_triangles = pm.leaf_triangles;
  }
  const std::uint64_t m = budget.total_bytes;
  if (m == 0 || (path != IngestPath::kBlockTin && path != IngestPath::kBlockPm)) return s;
  s.writer_batch_bytes = m / 16;
  s.writer_sort_bytes = m / 4;
  if (path == IngestPath::kBlockTin) {
    s.raster_cache_bytes = m / 8;
    s.exact_window_samples = std::min(s.exact_window_samples, m / 4 / kExactWindowBytesPerSample);
    s.assembly_sort_bytes = std::max<std::uint64_t>(m / 2, std::uint64_t{16} << 20);
    s.record_bytes = m / 2;
    s.assembly_table_bytes = m / 16;
  } else {
    s.face_sort_bytes = m / 8;
    s.assembly_sort_bytes = m / 8;
    s.assembly_table_bytes = m / 8;
    s.leaf_triangles = std::uint64_t{4096};
    while (s.leaf_triangles < 65536 && s.leaf_triangles * 2 * 8192 <= m) s.leaf_triangles *= 2;
  }
  return s;
}

}  // namespace smr
