// The block mesh builder's input, out of core (block_input.h).
#include "smr/builders/mesh/block_input.h"

#include <algorithm>
#include <cmath>
#include <list>
#include <span>
#include <unordered_map>
#include <unordered_set>

#include "base/error.h"
#include "smr/builders/mesh/morton_order.h"

namespace smr::qem {
namespace {

// The vertex file's pages, least recently used out first, within a byte budget.
class VertexPages {
 public:
  static constexpr std::uint64_t kPageVertices = 2048;  // 48 KiB

  VertexPages(const storage::RecordFile<Vec3>& file, std::uint64_t count, std::uint64_t bytes)
      : file_(file),
        count_(count),
        capacity_(std::max<std::uint64_t>(4, bytes / (kPageVertices * sizeof(Vec3)))) {}

  const Vec3& get(std::uint32_t v) {
    const std::uint64_t page = v / kPageVertices;
    if (page != last_page_) {
      last_ = &load(page);
      last_page_ = page;
    }
    return (*last_)[v % kPageVertices];
  }
  std::uint64_t reads() const { return reads_; }

 private:
  struct Page {
    std::vector<Vec3> pos;
    std::list<std::uint64_t>::iterator use;
  };

  const std::vector<Vec3>& load(std::uint64_t page) {
    auto it = pages_.find(page);
    if (it != pages_.end()) {
      use_.splice(use_.begin(), use_, it->second.use);
      return it->second.pos;
    }
    std::vector<Vec3> pos;
    if (pages_.size() >= capacity_) {  // the least recently used page's buffer is reused
      auto old = pages_.find(use_.back());
      pos.swap(old->second.pos);
      pages_.erase(old);
      use_.pop_back();
    }
    const std::uint64_t first = page * kPageVertices;
    pos.resize(static_cast<std::size_t>(std::min(kPageVertices, count_ - first)));
    file_.read(first, pos);
    ++reads_;
    use_.push_front(page);
    Page& p = pages_[page];
    p.pos = std::move(pos);
    p.use = use_.begin();
    return p.pos;
  }

  const storage::RecordFile<Vec3>& file_;
  const std::uint64_t count_, capacity_;
  std::unordered_map<std::uint64_t, Page> pages_;
  std::list<std::uint64_t> use_;  // most recent first
  std::uint64_t last_page_ = ~std::uint64_t{0};
  const std::vector<Vec3>* last_ = nullptr;
  std::uint64_t reads_ = 0;
};

}  // namespace

BlockInput::BlockInput(const MeshStream& mesh, const BlockInputOptions& options)
    : mesh_(mesh), options_(options), dir_(storage::scratch_dir(options.tmp_dir)) {
  read_vertices();
  {
    CornerSorter corners(dir_, options_.sort_bytes);
    sort_faces(corners);
    distribute(corners);
    spilled_ += corners.spilled_bytes();
  }
  more_faces_ = faces_->next(face_);
  more_verts_ = verts_->next(vert_);
}

BlockInput::~BlockInput() = default;

std::uint64_t BlockInput::temp_bytes() const {
  return spilled_ + (positions_ ? positions_->bytes() : 0) +
         (faces_ ? faces_->spilled_bytes() : 0) + (verts_ ? verts_->spilled_bytes() : 0);
}

void BlockInput::read_vertices() {
  positions_ = std::make_unique<storage::RecordFile<Vec3>>(dir_);
  mesh_.vertices([&](std::span<const Vec3> batch) {
    for (const Vec3& p : batch) {
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z))
        throw_input("mesh '" + mesh_.name() + "': vertex " + std::to_string(vertices_) +
                    " has a coordinate that is not finite");
      box_.add(p);
      ++vertices_;
    }
    // In pieces: the file's buffer flushes past 4 MiB, and a batch may be the whole mesh.
    for (std::size_t at = 0; at < batch.size(); at += 4096)
      positions_->append(batch.data() + at, std::min<std::size_t>(4096, batch.size() - at));
  });
  positions_->flush();
  if (vertices_ >= 0xffffffffu) throw_input("mesh '" + mesh_.name() + "': too many vertices");
}

// Leaf cells: the bounding cube split 2^levels_ times per axis, about leaf_triangles each.
void BlockInput::sort_faces(CornerSorter& corners) {
  const std::uint64_t nt = mesh_.triangle_count();
  if (nt == 0) throw_input("mesh '" + mesh_.name() + "' has no triangles");
  while (levels_ < 20 && (std::uint64_t{1} << (3 * levels_)) * options_.leaf_triangles < nt)
    ++levels_;
  const Vec3 ext = box_.hi - box_.lo;
  side_ = std::max({ext.x, ext.y, ext.z, 1e-300});
  const double cells = double(std::uint64_t{1} << levels_);
  faces_ = std::make_unique<storage::ExternalSorter<FaceRecord>>(dir_, options_.sort_bytes);
  std::unordered_set<std::uint32_t> cells_seen;  // non-empty leaf cells (about nt / leaf_triangles)
  std::uint32_t last_code = 0;
  VertexPages pages(*positions_, vertices_, options_.vertex_cache_bytes);
  mesh_.triangles([&](std::span<const std::array<std::uint32_t, 3>> batch) {
    for (const auto& t : batch) {
      for (std::uint32_t v : t) {
        if (v >= vertices_)
          throw_input("mesh '" + mesh_.name() + "': triangle " + std::to_string(triangles_) +
                      " names vertex " + std::to_string(v) + ", past the last (" +
                      std::to_string(vertices_) + " vertices)");
      }
      const Vec3 c = (pages.get(t[0]) + pages.get(t[1]) + pages.get(t[2])) / 3.0;
      std::uint32_t code = 0;
      for (int a = 0; a < 3; ++a) {
        const double u = (c[a] - box_.lo[a]) / side_ * cells;
        const auto k = static_cast<std::uint64_t>(std::clamp(u, 0.0, cells - 1.0));
        code |= static_cast<std::uint32_t>(spread3(k) << a);
      }
      faces_->add({code, t});
      for (std::uint32_t v : t) corners.add({v, code});
      if (triangles_ == 0 || code != last_code) cells_seen.insert(code);  // runs share a cell
      last_code = code;
      ++triangles_;
    }
  });
  page_reads_ = pages.reads();
  leaf_cells_ = cells_seen.size();
}

// Each vertex's corners (by cell) and its position (the vertex file, read in order): its span,
// and one record per distinct cell.
void BlockInput::distribute(CornerSorter& corners) {
  verts_ = std::make_unique<VertexSorter>(dir_, options_.sort_bytes);
  std::vector<Vec3> chunk;
  std::uint64_t chunk_at = 0;
  auto position = [&](std::uint32_t v) -> const Vec3& {
    if (v >= chunk_at + chunk.size()) {
      chunk_at = v;
      chunk.resize(static_cast<std::size_t>(std::min<std::uint64_t>(1 << 16, vertices_ - v)));
      positions_->read(chunk_at, chunk);
    }
    return chunk[v - chunk_at];
  };
  std::vector<std::uint32_t> cells;
  Corner c;
  bool more = corners.next(c);
  while (more) {
    const std::uint32_t v = c.v;
    cells.clear();
    for (; more && c.v == v; more = corners.next(c)) {
      if (cells.empty() || cells.back() != c.cell) cells.push_back(c.cell);
    }
    const Vec3& p = position(v);
    referenced_box_.add(p);
    ++referenced_;
    for (std::uint32_t cell : cells) verts_->add({cell, v, p, cells.front(), cells.back()});
  }
  verts_->seal();
  faces_->seal();
  spilled_ += positions_->bytes();
  positions_.reset();  // every position now rides with its records
}

bool BlockInput::next_leaf(LeafInput& out) {
  if (!more_faces_) return false;
  out.cell = face_.cell;
  out.faces.clear();
  out.verts.clear();
  for (; more_faces_ && face_.cell == out.cell; more_faces_ = faces_->next(face_))
    out.faces.push_back(face_.v);
  for (; more_verts_ && vert_.cell == out.cell; more_verts_ = verts_->next(vert_))
    out.verts.push_back(vert_);
  return true;
}

}  // namespace smr::qem
