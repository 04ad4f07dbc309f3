// The Continuous Resolution Model Representation (Brown 4.4, 4.5): a base mesh R^0 and
// refinement operations R^1..R^m in non-decreasing birth_res order, with the DAG and Hypermesh
// links stored in the ops themselves. Read access to one, in memory or on disk, is an OpSource
// (op_source.h, where resolution is tied to error).
#pragma once

#include <cstdint>
#include <memory>
#include <span>
#include <string>
#include <vector>

#include "smr/core/op.h"
#include "smr/core/op_source.h"

namespace smr {

class Crmr final : public OpSource {
 public:
  CrmrInfo header;
  std::vector<Op> ops;  // ops[0] = R^0

  const CrmrInfo& info() const override { return header; }
  std::uint64_t op_count() const override { return ops.size(); }
  OpRef op(OpId id) const override;
  std::uint64_t triangle_count() const;  // over all fragments
};

/// Receives a CRMR op by op, so that a builder never holds the whole DAG (docs/design.md section 4;
/// STYLE.md, tippecanoe: "the builder streams ops to the writer"). begin() is called once with
/// the model's header (bounds, err0 and err_final final) and the number of ops to come (0 if not
/// known; sinks size their records with it), then add() with ops 0 (R^0), 1, 2, ...
/// in id order, each complete: links, pre_tris and compute_op_bounds() done. ROIs and subtree
/// cones need the children's and are the sink's to derive (compute_rois' rule, children last).
class OpSink {
 public:
  virtual ~OpSink() = default;
  virtual void begin(const CrmrInfo& header, std::uint64_t op_count) = 0;
  virtual void add(Op&& op) = 0;

  /// A sink that keeps ops as bytes (a database writer's spool) may split add() in two, so a
  /// builder that makes ops on several threads does the op's own share there and add(), which
  /// runs in id order on one thread, is left the rest: encode() (after begin(); from any thread,
  /// for several ops at once, in any order) turns an op into bytes appended to `out`, computing
  /// the op's bounds itself (the builder need not), and add_encoded() takes one op's bytes, in
  /// id order. The op is then freed by the thread that made it, not by the sink's. A builder
  /// uses the pair when encodes() is true, for every op instead of add().
  virtual bool encodes() const { return false; }
  virtual void encode(Op& op, std::vector<std::uint8_t>& out) const;
  virtual void add_encoded(std::span<const std::uint8_t> op);
};

/// The in-memory sink: collects the ops into a Crmr; take() computes the ROIs and returns it.
class CrmrCollector final : public OpSink {
 public:
  void begin(const CrmrInfo& header, std::uint64_t op_count) override {
    crmr_.header = header;
    crmr_.ops.reserve(op_count);
  }
  void add(Op&& op) override;
  Crmr take();

 private:
  Crmr crmr_;
};

/// Sets op.box, op.sphere and op.cone from the op's own record: the corners and normals of F
/// then of PreF (via pre_tris), in that order. Deterministic, so the store recomputes them.
void compute_op_bounds(Op& op);
struct OpBounds {
  Box3 box;
  Sphere sphere;
  NormalCone cone;
};
/// compute_op_bounds' values for any op, an Op or a paged one.
OpBounds op_bounds(const OpView& op);

/// A fragment's in-fragment neighbours, into `nbr` (one entry per triangle): across edge k of
/// triangle i, the triangle that has the reversed edge (FragmentTriangle::kNoNeighbour if none).
/// Fragments do not keep them: every reader that needs them derives them.
void fragment_neighbours(std::span<const FragmentTriangle> fragment,
                         std::vector<std::array<std::int32_t, 3>>& nbr);

/// ROI of every op = its box united with its children's ROIs (children have larger ids).
void compute_rois(Crmr& crmr);

/// Derives parents/children from PreF, killer/death_res of every triangle, pre_tris, the bounds
/// (compute_op_bounds) and ROIs (children before parents). Builders call it once all ops exist.
/// Throws on dangling references.
void link_dag(Crmr& crmr);

}  // namespace smr
