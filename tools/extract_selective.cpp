// smrdb extract --algorithm selective: Kim & Lee's truly selective refinement of a mesh database
// (smr/extract/selective.h), read through the database's page cache.
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "smr/extract/selective.h"
#include "tools/commands.h"
#include "tools/report_json.h"

namespace smr::tools {

namespace {

// --selective-criterion vertex or vdpm: Hoppe 1997's per-vertex tests from the camera alone.
NodeCriterion node_criterion(const RcfSpec& spec, const std::string& name) {
  const std::string option = "--selective-criterion " + name;
  if (!spec.camera) throw_input(option + " needs a camera (--eye and --target)");
  if (spec.screen_aoi || spec.floor || !spec.aois.empty() || !spec.discs.empty() ||
      !spec.volumes.empty() || spec.frustum_level || spec.centre_cone || spec.critical_level)
    throw_input(option + " reads only the camera, --pixel-error and --no-cull");
  NodeCriterion c{*spec.camera, spec.cull, spec.cull, spec.pixel_error.value_or(0.0)};
  c.backface_over_sphere = name == "vertex";
  c.vertex_normal_cones = name == "vdpm";
  return c;
}

}  // namespace

nlohmann::json run_selective(const Database& db, const RcfSpec& spec, const Rcf& rcf,
                             const ExtractArgs& a) {
  nlohmann::json report;
  const bool by_rcf = a.selective_criterion.empty() || a.selective_criterion == "rcf";
  const std::optional<NodeCriterion> node =
      by_rcf ? std::nullopt : std::optional(node_criterion(spec, a.selective_criterion));
  // The hierarchy and the fundamental cut vertices: one pass over every op (selective.h).
  const std::shared_ptr<const SelectiveIndex> index =
      SelectiveIndex::build(db, {.vertex_cones = node && node->vertex_normal_cones});
  const SplitScheme scheme =
      a.split_scheme.empty() ? SplitScheme::kTrulySelective
                             : SelectiveRefinement::parse_scheme(a.split_scheme, "--split-scheme");
  const SelectiveExtraction e = node ? extract_selective(db, index, *node, scheme)
                                     : extract_selective(db, index, rcf, scheme);
  if (by_rcf) report["rcf"] = rcf.describe();
  report["selective_criterion"] = by_rcf ? "rcf" : a.selective_criterion;
  report["selective"] = e.stats;
  report["selective"]["scheme"] = SelectiveRefinement::scheme_name(scheme);
  report["selective"]["index"] = index->stats();
  report["selective"]["error_bound"] =
      "each output triangle is a source triangle with its corners moved to their active "
      "ancestors: it and its source triangle are within displacement_bound of each other "
      "(two-sided); the ops' own Hausdorff bounds do not carry over";
  // What the CLI's summary line reads: X is the splits made.
  report["extraction"] = {{"algorithm", "selective"}, {"x", e.stats.splits}};
  report["io"] = db.stats();
  write_output(db, e.mesh, a, report);
  return report;
}

}  // namespace smr::tools
